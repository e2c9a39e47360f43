"""Metropolis-adjusted Lie–Poisson sampler: exactly ``exp(−βh)`` on the orbit at any step size.

A BlackJAX-shaped module (``State``/``Info``, ``init``, ``build_kernel``, ``as_top_level_api``),
the orbit analogue of MALA. One step proposes the coadjoint Lie–Euler move of the
noise + dissipation part of the Poisson–Langevin SDE (MATH.md §1–§2) and accepts it with a
Metropolis–Hastings ratio, so the chain's stationary law is the Gibbs law on the orbit of the
initial state with no discretisation bias.

**The move as an involution.** From ``μ`` draw ``W ~ N(0, I_m)`` and set

    c_i = −θ {h, ĥ_i}(μ) dt + σ √dt W_i,      ξ(c) = Σ_i c_i ξ_i,      μ' = Ad*_{exp ξ(c)} μ,

with ``θ = βσ²/2`` and ``ξ_i = ∇ĥ_i`` the (constant) gradients of the unit-strength noise
Hamiltonians. The map ``Φ(μ, c) = (μ', −c)`` is an involution of ``orbit × R^m``
(``Ad*_{exp(−ξ)} Ad*_{exp ξ} = id`` and ``ξ(−c) = −ξ(c)``), and its Jacobian has unit
determinant: it is block triangular, ``∂c'/∂c = −I`` and, for fixed ``c``, ``μ ↦ Ad*_g μ`` is a
symplectomorphism of the orbit, so it preserves the Liouville measure. With the auxiliary law
``q(c | μ) = N(−θ {h, ĥ}(μ) dt, σ² dt I)``, the acceptance probability of ``Φ`` for
``π(μ) q(c | μ)`` is ``min(1, exp(L))`` with

    L = −β (h(μ') − h(μ)) − ½|W'|² + ½|W|²,      W' = (−c + θ {h, ĥ}(μ') dt) / (σ √dt),

the MALA ratio with Gaussian densities. The construction needs ``ξ_i`` independent of ``μ``
(linear noise ``ĥ_i = ⟨μ, ξ_i⟩``: rigid body, spins, the heavy top's six); with ``μ``-dependent
gradients ``Φ`` is no longer an involution, so such systems are refused with a clear error
(:func:`check_linear_noise`). Ergodicity needs the ``ξ_i`` to span the orbit's tangent
directions, which holds for the systems above.

The Hamiltonian drift is not part of the move: it preserves ``exp(−βh)`` by itself but is not
reversible, and alone the noise + dissipation dynamics already has ``exp(−βh)`` as its
reversible invariant law (its generator is self-adjoint in ``L²(exp(−βh))``, MATH.md §1).
As ``dt → 0`` the acceptance rate tends to 1 and the chain is the unadjusted Lie–Euler chain of
that scene; at large ``dt`` rejections remove the bias instead of leaving it in the averages.
"""

from __future__ import annotations

from typing import NamedTuple

import blackjax
import jax
import jax.numpy as jnp
import numpy as np

from liesample._validation import finite_float
from liesample.dynamics import PoissonLangevin, Scene
from liesample.systems.base import LiePoissonSystem

__all__ = [
    "AdjustedLiePoissonInfo",
    "AdjustedLiePoissonState",
    "as_top_level_api",
    "build_kernel",
    "check_linear_noise",
    "init",
    "involution",
]

# Noise and dissipation only (the reversible part of the SDE; see the module docstring).
_NOISE_SCENE = Scene(hamiltonian=False, dissipation=True, noise=True)


class AdjustedLiePoissonState(NamedTuple):
    """State of a chain.

    position : the point ``μ`` on the orbit.
    reference_casimirs : Casimirs of the initial point, against which drift is measured.
    energy : ``h(μ)``, cached for the next acceptance ratio.
    brackets : ``{h, ĥ_i}(μ)``, shape ``(m,)``, cached (the drift of the next proposal).
    """

    position: jax.Array
    reference_casimirs: jax.Array
    energy: jax.Array
    brackets: jax.Array


class AdjustedLiePoissonInfo(NamedTuple):
    """What one step did.

    acceptance_rate : ``min(1, exp(L))`` of the proposal (0 for a non-finite one).
    is_accepted : whether the chain moved.
    energy : ``h`` at the new state.
    casimir_error : relative Casimir drift of the new state (``LiePoissonSystem.casimir_error``).
    nonfinite : the proposal (or its energy, drift or ratio) was NaN/inf; it was rejected.
    """

    acceptance_rate: jax.Array
    is_accepted: jax.Array
    energy: jax.Array
    casimir_error: jax.Array
    nonfinite: jax.Array


def check_linear_noise(system: LiePoissonSystem) -> None:
    """Raise ``ValueError`` unless the noise Hamiltonians have constant gradients.

    The gradients ``∇ĥ_i`` are compared at the default position and at two other fixed points
    (relative tolerance 1e-9); a non-linear noise (point vortices) changes them.
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    base = np.asarray(system.default_position, dtype=float)
    rng = np.random.default_rng(0)
    points = [base, base + 0.3 * rng.normal(size=base.shape), rng.normal(size=base.shape)]
    with jax.ensure_compile_time_eval():
        jacobians = [np.asarray(jax.jacfwd(system.noise_hamiltonians)(p)) for p in points]
    scale = max(1.0, float(np.max(np.abs(jacobians[0]))))
    for jacobian in jacobians[1:]:
        if not np.allclose(jacobian, jacobians[0], rtol=0.0, atol=1e-9 * scale):
            raise ValueError(
                f"adjusted_lie_poisson needs noise Hamiltonians with constant gradients (linear "
                f"noise ĥ_i = ⟨μ, ξ_i⟩, e.g. rigid body, spins, heavy top); the {system.name}'s "
                "gradients change with μ, so the proposal is not an involution. Use the "
                "unadjusted liesample.lie_poisson_langevin for this system."
            )


def _energy_and_brackets(dynamics: PoissonLangevin, position):
    energy, grad_h = jax.value_and_grad(dynamics.system.hamiltonian)(position)
    return energy, dynamics.brackets_with_noise(position, grad_h)


def _dynamics(system, sigma, beta):
    return PoissonLangevin(system, sigma=sigma, theta=0.5 * beta * sigma**2, scene=_NOISE_SCENE)


def init(position, system: LiePoissonSystem, rng_key=None) -> AdjustedLiePoissonState:
    """Initial state on the orbit through ``position`` (no key needed; ``rng_key`` is ignored)."""
    del rng_key
    system.check_position(position)
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    dynamics = PoissonLangevin(system, sigma=1.0, theta=1.0, scene=_NOISE_SCENE)
    energy, brackets = _energy_and_brackets(dynamics, position)
    return AdjustedLiePoissonState(position, system.casimirs(position), energy, brackets)


def involution(system: LiePoissonSystem, position, noise, step_size, sigma, beta, brackets=None):
    """``(μ, W) ↦ (μ', W')``: the proposal map in noise coordinates; applying it twice is the
    identity (to round-off).

    Returns ``(proposal, reverse_noise, energy, brackets)`` with the last two at the proposal.
    ``brackets`` (``{h, ĥ_i}(μ)``) may be passed when already known.
    """
    dynamics = _dynamics(system, sigma, beta)
    if brackets is None:
        _, brackets = _energy_and_brackets(dynamics, position)
    drift = dynamics.theta * step_size
    scale = sigma * jnp.sqrt(step_size)
    coefficients = -drift * brackets + scale * noise
    proposal = system.algebra.coadjoint_exp(
        dynamics.noise_generator(position, coefficients), position
    )
    energy, new_brackets = _energy_and_brackets(dynamics, proposal)
    reverse_noise = (-coefficients + drift * new_brackets) / scale
    return proposal, reverse_noise, energy, new_brackets


def build_kernel(system: LiePoissonSystem):
    """Build ``kernel(rng_key, state, step_size, sigma, beta) -> (state, info)``.

    ``step_size``, ``sigma`` and ``beta`` may be traced. Raises ``ValueError`` for a system
    whose noise gradients depend on ``μ`` (:func:`check_linear_noise`).
    """
    check_linear_noise(system)

    def kernel(rng_key, state: AdjustedLiePoissonState, step_size, sigma, beta):
        key_noise, key_accept = jax.random.split(rng_key)
        position = state.position
        noise = jax.random.normal(key_noise, (system.num_noises,), dtype=position.dtype)
        proposal, reverse_noise, energy, brackets = involution(
            system, position, noise, step_size, sigma, beta, state.brackets
        )
        log_ratio = (
            -beta * (energy - state.energy)
            - 0.5 * jnp.sum(reverse_noise**2)
            + 0.5 * jnp.sum(noise**2)
        )
        nonfinite = ~(
            jnp.all(jnp.isfinite(proposal))
            & jnp.isfinite(energy)
            & jnp.all(jnp.isfinite(brackets))
            & jnp.isfinite(log_ratio)
        )
        log_ratio = jnp.where(nonfinite, -jnp.inf, log_ratio)
        acceptance_rate = jnp.exp(jnp.minimum(log_ratio, 0.0))
        is_accepted = jnp.log(jax.random.uniform(key_accept, dtype=position.dtype)) < log_ratio
        new_state = AdjustedLiePoissonState(
            jnp.where(is_accepted, proposal, position),
            state.reference_casimirs,
            jnp.where(is_accepted, energy, state.energy),
            jnp.where(is_accepted, brackets, state.brackets),
        )
        info = AdjustedLiePoissonInfo(
            acceptance_rate,
            is_accepted,
            new_state.energy,
            system.casimir_error(new_state.position, state.reference_casimirs),
            nonfinite,
        )
        return new_state, info

    return kernel


def as_top_level_api(
    system: LiePoissonSystem, *, beta, sigma=1.0, step_size
) -> blackjax.base.SamplingAlgorithm:
    """Metropolis-adjusted Lie–Poisson sampler of ``exp(−βh)`` on the orbit of the initial state.

    Parameters
    ----------
    system : LiePoissonSystem
        With linear noise Hamiltonians (rigid body, heavy top, spins).
    beta : float
        Inverse temperature, finite (and admissible for the system).
    sigma : float
        Noise strength ``σ > 0``. Only ``σ²·step_size`` matters for the move (there is no
        Hamiltonian drift), so ``σ`` and ``step_size`` are one knob: the rotation angle per step.
    step_size : float
        Time step ``dt > 0``; any value gives the exact law, larger ones lower acceptance.

    Returns
    -------
    blackjax.base.SamplingAlgorithm
        ``init(position)`` and ``step(rng_key, state) -> (state, info)``.
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    beta = finite_float("beta", beta)
    if system.check_beta is not None:
        system.check_beta(beta)
    sigma = finite_float("sigma", sigma, positive=True)
    step_size = finite_float("step_size", step_size, positive=True)
    kernel = build_kernel(system)

    def init_fn(position, rng_key=None):
        return init(position, system, rng_key)

    def step_fn(rng_key, state):
        return kernel(rng_key, state, step_size, sigma, beta)

    return blackjax.base.SamplingAlgorithm(init_fn, step_fn)


adjusted_lie_poisson = blackjax.GenerateSamplingAPI(as_top_level_api, init, build_kernel)
