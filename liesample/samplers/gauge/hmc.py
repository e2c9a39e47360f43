"""HMC and SMD on the links: :func:`liesample.geometric_hmc` on the system's space, with the
leapfrog's stability limit of the Wilson action checked.

The ``T*G`` Hamiltonian is ``H = β S/β(U) + ½|p|²`` with ``p`` in algebra coordinates; the drift
``U ← U exp(εp̂)`` is the exact group exponential (:mod:`liesample.geometry.spaces`). With
``momentum_persistence = α > 0`` the momentum is refreshed partially, ``p ← αp + √(1−α²)ξ``,
which is generalised HMC (Horowitz 1991) and, with one leapfrog step per update, the stochastic
molecular dynamics (SMD) of Lüscher & Schaefer (2011): the ``O`` step of the stochastic-dissipative
``T*G`` dynamics (friction ``γ`` with ``α = e^{−γε}``) followed by a Metropolis-adjusted ``BAB``.

Stability. Near the identity (the weak-coupling region, where the stiffest modes live) the action
is the quadratic form ``β c |d a|²`` of the link algebra coordinates ``a`` (``c = ½`` for U(1)
angles, ``1/N`` for SU(N)), ``d`` the lattice curl; its largest eigenvalue on a torus with even
extents is ``4d`` (the staggered mode). The leapfrog is unstable on that mode when
``ε ω ≥ 2``, ``ω² = 2 c β · 4d``; such a step is refused. With an anisotropy ``ξ`` the planes
carry the weights ``w_P`` (``1/ξ`` spatial, ``ξ`` temporal) and the staggered mode's eigenvalue
is ``4 max(dξ, (d−1)/ξ + ξ)`` (the second only for ``d ≥ 3``: the largest eigenvalue of the
weighted Laplacian of the complete graph on the ``d`` directions, four times), ``4d`` at
``ξ = 1``. Below the limit the quadratic part
is stable, but the non-linear couplings still heat a long trajectory from an ordered field at
``0.8`` of the limit; useful steps are about half the limit or less.

``β < 0`` is a normalisable law on the compact links (it favours plaquettes far from the
identity). For U(1) the action's Hessian is ``β Σ_P cos θ_P g_P g_Pᵀ`` (``g_P`` the
plaquette's incidence vector), bounded by ``|β|`` times the quadratic form above at every field;
the check uses ``|β|`` for every group.
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp

from liesample.foundation.validation import finite_float
from liesample.samplers.contract import Sampler
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["WilsonLogDensity", "gauge_hmc", "stability_limit"]


def stability_limit(system: WilsonGauge, beta) -> float:
    """The leapfrog step ``2/ω`` beyond which the stiffest weak-coupling mode is unstable
    (``ω² = 2c|β|·4d``, or the anisotropic eigenvalue of the module notes; ``inf`` at
    ``β = 0``)."""
    if not isinstance(system, WilsonGauge):
        raise TypeError(f"system must be a wilson_gauge(...) system, got {type(system).__name__}")
    beta = finite_float("beta", beta)
    c = 0.5 if system.abelian else 1.0 / system.n
    omega = math.sqrt(2.0 * c * abs(beta) * _stiffest_eigenvalue(system))
    return math.inf if omega == 0 else 2.0 / omega


def _stiffest_eigenvalue(system: WilsonGauge) -> float:
    """The largest eigenvalue of the weighted curl form ``Σ_P w_P |d a|_P²`` (module notes)."""
    d, xi = system.dim, system.anisotropy
    if xi == 1.0:
        return 4.0 * d
    spatial = (d - 1) / xi + xi if d >= 3 else 0.0
    return 4.0 * max(d * xi, spatial)


@dataclasses.dataclass(frozen=True)
class WilsonLogDensity:
    """``(links, β) ↦ −β S/β`` (:meth:`WilsonGauge.logdensity`) with ``β`` an argument: one
    value per lattice, so that every ``β`` of a sweep is a number of one compiled program
    (``geometric_hmc``'s ``model_args``)."""

    system: WilsonGauge

    def __call__(self, links, beta):
        action = self.system.action(links)
        return -jnp.asarray(beta, action.dtype) * action


def gauge_hmc(
    system: WilsonGauge,
    *,
    beta,
    step_size,
    num_integration_steps: int,
    momentum_persistence: float = 0.0,
    **options,
) -> Sampler:
    """:func:`liesample.geometric_hmc` of ``exp(−β S/β)`` on ``system.space`` (HMC; with
    ``momentum_persistence > 0`` generalised HMC / SMD), the step checked against
    :func:`stability_limit`; ``beta`` any finite real (``β < 0`` too, module notes).
    ``options`` go to :func:`liesample.geometric_hmc`."""
    if not isinstance(system, WilsonGauge):
        raise TypeError(f"system must be a wilson_gauge(...) system, got {type(system).__name__}")
    beta = finite_float("beta", beta)
    step_size = finite_float("step_size", step_size, positive=True)
    limit = stability_limit(system, beta)
    if step_size >= limit:
        raise ValueError(
            f"step_size = {float(step_size):g} is past the leapfrog's stability limit "
            f"{limit:.4g} for {system.group} at beta = {beta:g} in {system.dim} dimensions "
            "(the stiffest weak-coupling mode); use a step_size below it, e.g. "
            f"{0.5 * limit:.3g}"
        )
    sampler = geometric_hmc(
        WilsonLogDensity(system),
        system.space,
        step_size,
        num_integration_steps,
        momentum_persistence=momentum_persistence,
        model_args=(beta,),
        **options,
    )
    sampler.settings.update({"system": repr(system), "beta": beta})
    return sampler
