"""Stratonovich integrators for the Poisson–Langevin dynamics, built from one move.

Each integrator consumes generators ``ζ ∈ g`` from :meth:`PoissonLangevin.generator` and, except
for the ambient baseline, moves only by ``Ad*_{exp ζ}`` (``coadjoint_exp``), so the state stays on
its coadjoint orbit to round-off (MATH.md §2). All read the SDE in the Stratonovich sense; none
adds an Itô correction. ``weak_order`` is the order of the bias of ergodic averages in the step
size, measured in ``tests/test_sampling.py`` and ``benchmarks/``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp

from liesample.dynamics import PoissonLangevin, Scene


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
    """

    name: str
    weak_order: int
    preserves_orbit: bool
    step: Callable
    description: str

    def __call__(self, dynamics: PoissonLangevin, mu, dt, dW=None):
        return self.step(dynamics, mu, dt, dW)


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
    derived dissipation (MATH.md §1: the generator is a sum over ``i`` of
    operators self-adjoint in ``L²(exp(−βh))``). Each piece is advanced by Heun on the group,
    which has one-step weak error ``O(dt³)`` against its exact, ``π``-preserving flow: along a
    single noise direction the noise is additive in the group coordinate. So every piece
    preserves ``π`` up to ``O(dt³)`` per step and the composition's invariant law is within
    ``O(dt²)`` of ``π`` — unlike Heun on the joint generator, whose non-commuting noise
    directions leave an ``O(dt)`` bias. The ``dt³`` term is large and of opposite sign: on the
    rigid body at ``β = 3`` the observed slope is ~1.3–1.7 for ``dt ≥ 0.1`` and reaches 2 below
    (``tests/test_sampling.py::test_splitting_bias_is_second_order``, ``benchmarks/RESULTS.md``).
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


INTEGRATORS: dict[str, Integrator] = {
    integrator.name: integrator
    for integrator in (
        Integrator(
            "rkmk_heun",
            weak_order=1,
            preserves_orbit=True,
            step=_rkmk_heun,
            description="Heun (RKMK2) on the joint generator: second order without noise, first "
            "order with non-commuting noise",
        ),
        Integrator(
            "splitting",
            weak_order=2,
            preserves_orbit=True,
            step=_splitting,
            description="Hamiltonian | each noise direction, Heun on the group: second order "
            "(default)",
        ),
        Integrator(
            "lie_euler",
            weak_order=1,
            preserves_orbit=True,
            step=_lie_euler,
            description="coadjoint Lie–Euler: first order, orbit-preserving",
        ),
        Integrator(
            "euler_heun",
            weak_order=1,
            preserves_orbit=False,
            step=_euler_heun,
            description="ambient Euler–Heun: baseline for comparison, drifts off the orbit",
        ),
    )
}

DEFAULT_INTEGRATOR = "splitting"


def get_integrator(integrator) -> Integrator:
    """Look up an integrator by name (or pass an :class:`Integrator` through)."""
    if isinstance(integrator, Integrator):
        return integrator
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {sorted(INTEGRATORS)}, got {integrator!r}")
    return INTEGRATORS[integrator]
