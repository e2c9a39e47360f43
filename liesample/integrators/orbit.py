"""Stratonovich integrators for the Poisson–Langevin dynamics, built from one move.

Each integrator consumes generators ``ζ ∈ g`` from :meth:`PoissonLangevin.generator` and, except
for the ambient baseline, moves only by ``Ad*_{exp ζ}`` (``coadjoint_exp``), so the state stays on
its coadjoint orbit to round-off (paper, ``rmk:symplectic-leaf-preservation``). All read the SDE in
the Stratonovich sense; none adds an Itô correction. Each :class:`Integrator` declares what it
guarantees — its weak order (the order of the bias of ergodic averages in the step size), whether
that order needs linear noise Hamiltonians, whether it preserves the orbit, its stability limit and
its stochastic form — and :mod:`liesample.integrators.stability`, the samplers and the benchmark
report read these attributes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import jax
import jax.numpy as jnp

from liesample.dynamics.poisson_langevin import PoissonLangevin, Scene
from liesample.foundation.schemes import Schemes

FORMS = ("stratonovich", "ito")


type Step = Callable[[PoissonLangevin, jax.Array, jax.Array | float, jax.Array | None], jax.Array]
"""A one-step map ``(dynamics, μ, dt, dW) ↦ μ'`` (``dW`` is ``None`` without noise)."""


@dataclass(frozen=True)
class Integrator:
    """A one-step map ``(dynamics, μ, dt, dW) ↦ μ'`` and what it guarantees.

    ``dW`` holds the Brownian increments of the step (shape ``(m,)``), or ``None`` when the
    scene has no noise; passing them in (rather than a key) keeps the integrator independent of
    how the driving noise is generated.

    Attributes
    ----------
    name : str
    weak_order : int
        Order of the bias of ergodic averages in ``dt``.
    preserves_orbit : bool
        Whether Casimirs are preserved to round-off (moves by the coadjoint action only).
    step : callable
    description : str
    linear_noise_only : bool
        ``True`` when ``weak_order`` holds only for noise Hamiltonians linear in ``μ``
        (constant ``∇ĥ_i``): the scheme evaluates the noise generator once, at the start of the
        step, so with non-linear ``ĥ_i`` it misses the Stratonovich correction and is
        inconsistent (it converges to another SDE).
    stability_limit : float or None
        Largest stable stability number ``κ = dt·θ·max_i |h''_i|``
        (:mod:`liesample.integrators.stability`), or ``None`` where no bound is claimed (the check
        is skipped).
    form : {"stratonovich", "ito"}
        The reading of the noise that the one-step map is consistent with.

    Examples
    --------
    Integrators are chosen by name or passed as objects:

    >>> from liesample.systems import isospectral_midpoint
    >>> isospectral_midpoint.preserves_orbit, isospectral_midpoint.weak_order
    (True, 1)
    >>> system = liesample.systems.zeitlin_euler(3)
    >>> sampler = liesample.lie_poisson_langevin(system, beta=1.0, step_size=0.01,
    ...                                          integrator=isospectral_midpoint)
    """

    name: str
    weak_order: int
    preserves_orbit: bool
    step: Step
    description: str
    linear_noise_only: bool = False
    stability_limit: float | None = None
    form: str = "stratonovich"

    def __post_init__(self):
        if self.form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, got {self.form!r}")
        if isinstance(self.weak_order, bool) or not isinstance(self.weak_order, int):
            raise TypeError(f"weak_order must be an int, got {self.weak_order!r}")
        if self.stability_limit is not None and not self.stability_limit > 0:
            raise ValueError(f"stability_limit must be > 0 or None, got {self.stability_limit!r}")

    def __call__(
        self,
        dynamics: PoissonLangevin,
        mu: jax.Array,
        dt: jax.Array | float,
        dW: jax.Array | None = None,
    ) -> jax.Array:
        return self.step(dynamics, mu, dt, dW)

    def wrapping(self, step: Step, name: str, description: str, **changes: Any) -> Integrator:
        """An integrator built on this one (substeps, another dissipation, …): it inherits this
        one's declarations unless ``changes`` overrides them."""
        return replace(self, name=name, step=step, description=description, **changes)


def _lie_euler(dynamics, mu, dt, dW):
    """``μ' = Ad*_{exp ζ(μ)} μ``: the coadjoint Lie–Euler step."""
    return dynamics.algebra.coadjoint_exp(dynamics.generator(mu, dt, dW), mu)


def _rkmk_heun(dynamics, mu, dt, dW):
    """Heun on the group (RKMK2): average the generators at ``μ`` and at the Lie–Euler predictor.

    The same Brownian increments feed both stages, which makes the scheme consistent with the
    Stratonovich reading; the commutator term of ``dexp⁻¹`` is third order and omitted.
    """
    return _heun_on_group(
        dynamics.algebra.coadjoint_exp, lambda m: dynamics.generator(m, dt, dW), mu
    )


def _heun_on_group(move, generator, mu):
    """``Ad*_{exp ½(ζ(μ) + ζ(μ̃))} μ`` with the predictor ``μ̃ = Ad*_{exp ζ(μ)} μ``."""
    zeta_start = generator(mu)
    return move(0.5 * (zeta_start + generator(move(zeta_start, mu))), mu)


def _splitting(dynamics, mu, dt, dW):
    """Lie–Trotter splitting into pieces that each leave ``exp(−βh)`` invariant.

    The pieces are the Hamiltonian flow and, one after another, each group of noise directions
    (by default each direction; ``LiePoissonSystem.noise_groups``) with its own share of the
    derived dissipation (paper, ``eq:poisson-langevin-eq``: the generator is a sum over ``i``
    of operators self-adjoint in ``L²(exp(−βh))``). Each piece is advanced by Heun on the group,
    which has one-step weak error ``O(dt³)`` against its exact, ``π``-preserving flow: along a
    single noise direction the noise is additive in the group coordinate. So every piece
    preserves ``π`` up to ``O(dt³)`` per step and the composition's invariant law is within
    ``O(dt²)`` of ``π`` — unlike Heun on the joint generator, whose non-commuting noise
    directions leave an ``O(dt)`` bias. The ``dt³`` term is large and of opposite sign, so the
    second order shows only once the step is small enough.
    """
    move = dynamics.algebra.coadjoint_exp
    scene = dynamics.scene
    if scene.hamiltonian:
        mu = _hamiltonian_flow(dynamics, mu, dt)
    if not (scene.noise or scene.dissipation):
        return mu

    def one_group(mu, group):
        return _heun_on_group(move, lambda m: dynamics.group_generator(m, group, dt, dW), mu), None

    mu, _ = jax.lax.scan(one_group, mu, jnp.arange(dynamics.system.num_noise_groups))
    return mu


def _hamiltonian_flow(dynamics, mu, dt):
    """The ``X_h`` piece of :func:`_splitting`: Heun on the group, or, where the system declares
    ``hamiltonian_pieces`` (each exactly solved by one coadjoint move), the Strang composition
    ``A(dt/2) … Y(dt/2) Z(dt) Y(dt/2) … A(dt/2)`` of their exact flows (second order, and a
    Poisson map that keeps every momentum map the pieces share)."""
    move = dynamics.algebra.coadjoint_exp
    pieces = dynamics.system.hamiltonian_pieces
    if pieces is None:
        flow = replace(dynamics, scene=Scene(hamiltonian=True, dissipation=False, noise=False))
        return _heun_on_group(move, lambda m: flow.generator(m, dt), mu)

    def piece_flow(mu, piece, fraction):
        return move(jax.grad(piece)(mu) * (fraction * dt), mu)

    *outer, middle = pieces
    for piece in outer:
        mu = piece_flow(mu, piece, 0.5)
    mu = piece_flow(mu, middle, 1.0)
    for piece in reversed(outer):
        mu = piece_flow(mu, piece, 0.5)
    return mu


def _euler_heun(dynamics, mu, dt, dW):
    """Ambient stochastic Heun in ``R^d`` (baseline only: drifts off the orbit)."""
    increment_start = dynamics.vector_field(mu, dt, dW)
    increment_end = dynamics.vector_field(mu + increment_start, dt, dW)
    return mu + 0.5 * (increment_start + increment_end)


# Euler and Heun applied to y' = −λy are stable iff λ dt ≤ 2 (liesample.integrators.stability).
_EULER_HEUN_STABILITY = 2.0

_ORBIT_INTEGRATORS = {
    integrator.name: integrator
    for integrator in (
        Integrator(
            "rkmk_heun",
            weak_order=1,
            preserves_orbit=True,
            step=_rkmk_heun,
            description="Heun (RKMK2) on the joint generator: second order without noise, first "
            "order with non-commuting noise",
            stability_limit=_EULER_HEUN_STABILITY,
        ),
        Integrator(
            "splitting",
            weak_order=2,
            preserves_orbit=True,
            step=_splitting,
            description="Hamiltonian | each noise direction, Heun on the group: second order "
            "(default)",
            stability_limit=_EULER_HEUN_STABILITY,
        ),
        Integrator(
            "lie_euler",
            weak_order=1,
            preserves_orbit=True,
            step=_lie_euler,
            description="coadjoint Lie–Euler: first order, orbit-preserving; consistent only "
            "for linear noise Hamiltonians",
            linear_noise_only=True,
            stability_limit=_EULER_HEUN_STABILITY,
        ),
        Integrator(
            "euler_heun",
            weak_order=1,
            preserves_orbit=False,
            step=_euler_heun,
            description="ambient Euler–Heun: baseline for comparison, drifts off the orbit",
            stability_limit=None,  # its orbit radius drifts, and κ with it: no bound claimed
        ),
    )
}
INTEGRATORS = Schemes(
    "a coadjoint orbit",
    _ORBIT_INTEGRATORS,
    {name: integrator.description for name, integrator in _ORBIT_INTEGRATORS.items()},
)
"""The orbit samplers' integrators by name (:class:`liesample.foundation.schemes.Schemes`)."""

DEFAULT_INTEGRATOR = "splitting"


def get_integrator(integrator: str | Integrator) -> Integrator:
    """Look up an integrator by name (or pass an :class:`Integrator` through)."""
    if isinstance(integrator, Integrator):
        return integrator
    return INTEGRATORS.lookup(integrator)
