"""Metropolis-adjusted Lie–Poisson sampler: exactly ``exp(−βh)`` on the orbit at any step size.

A BlackJAX-shaped module (``State``/``Info``, ``init``, ``build_kernel``, ``as_top_level_api``),
the orbit analogue of MALA. One step proposes the coadjoint Lie–Euler move of the
noise + dissipation part of the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq`` and
``eq:lie-poisson-langevin``) and accepts it with a
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
(:func:`check_linear_noise`). Ergodicity needs the ``ξ_i`` and their brackets to span the
orbit's tangent directions, which holds for the systems above and for Zeitlin's model with
``noise_degree ≥ 2`` (:func:`liesample.systems.zeitlin.zeitlin_euler` refuses
``noise_degree=1``: rigid rotations alone keep ``h`` fixed).

**Cost per step.** One coadjoint move (``algebra.coadjoint_exp``: a group element and two
products, for Zeitlin's ``u(N)`` an exponential by products alone,
:class:`liesample.systems.zeitlin.SkewHermitianUnitary`), one gradient of ``h`` and one
bracket ``ad*_{∇h}μ``. The Casimir drift in the Info is the system's ``step_casimir_error``
where it declares one (a cheap invariant), so no eigenvalue problem is solved per step.

The Hamiltonian drift is not part of the move: it preserves ``exp(−βh)`` by itself but is not
reversible, and alone the noise + dissipation dynamics already has ``exp(−βh)`` as its
reversible invariant law (its generator is self-adjoint in ``L²(exp(−βh))``; paper,
``eq:lie-poisson-gibbs-measure``).
As ``dt → 0`` the acceptance rate tends to 1 and the chain is the unadjusted Lie–Euler chain of
that scene; at large ``dt`` rejections remove the bias instead of leaving it in the averages.

**Step size.** Any step is exact, but a too large one is rejected nearly always (a *stuck*
chain, which :func:`liesample.sample` reports). Without ``step_size`` the step is
``κ = 1.3 m^{−1/3}`` in units of the stiffness (``κ = dt·θ·max|h''|``,
:mod:`liesample.integrators.stability`; ``m`` noise directions), MALA's optimal scaling for a
near-Gaussian target: on the orbit of the system's default position when the sampler is built,
on the orbit of the first start in :func:`liesample.sample`. The sampler declares its step
tunable by dual averaging (``adaptation``, :class:`liesample.samplers.contract.Tunable`):
under ``liesample.sample(..., num_warmup=N)`` the warm-up of :mod:`liesample.tuning` tunes it
(Hoffman & Gelman 2014, as in ``blackjax.window_adaptation``) so that the mean acceptance rate
over the chains reaches ``target_acceptance_rate`` (default 0.574, MALA's optimal rate, Roberts
& Rosenthal 1998). ``step`` itself never changes the step size.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.dynamics.poisson_langevin import PoissonLangevin, Scene
from liesample.dynamics.system import LiePoissonSystem, checked_beta
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.validation import concrete_array, finite_float
from liesample.integrators.chain_loop import DEFAULT_NOISE_BLOCK_SIZE, NoiseBlocks, check_block_size
from liesample.integrators.stability import check_precision, stiffness
from liesample.samplers.contract import (
    Recipe,
    Sampler,
    Structure,
    Tunable,
    sampling_api,
    step_key,
)
from liesample.samplers.orbit._starts import (
    check_orbit_starts,
    check_start_energy,
    distinct_orbits,
    orbit_groups,
    orbit_init_fn,
    orbit_settings,
    plain_init_fn,
)

__all__ = [
    "DEFAULT_TARGET_ACCEPTANCE_RATE",
    "AdjustedLiePoissonInfo",
    "AdjustedLiePoissonState",
    "adjusted_lie_poisson",
    "as_top_level_api",
    "build_kernel",
    "build_noise_kernel",
    "check_linear_noise",
    "init",
    "involution",
]

# Noise and dissipation only (the reversible part of the SDE; see the module docstring).
_NOISE_SCENE = Scene(hamiltonian=False, dissipation=True, noise=True)

DEFAULT_TARGET_ACCEPTANCE_RATE = 0.574
"""Mean acceptance rate the warm-up's dual averaging aims at (MALA's optimum)."""


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
    """What one step did (the Info contract of :mod:`liesample.samplers.contract`).

    is_divergent : the proposal (or its energy, drift or ratio) was NaN/inf; it was rejected.
    acceptance_rate : ``min(1, exp(L))`` of the proposal (0 for a divergent one).
    energy : ``h`` at the chain's state after the step.
    is_accepted : whether the chain moved.
    casimir_error : relative Casimir drift of the new state (``LiePoissonSystem.casimir_error``,
        or the system's cheaper ``step_casimir_error`` where it declares one).
    """

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    is_accepted: jax.Array
    casimir_error: jax.Array


def check_linear_noise(system: LiePoissonSystem) -> None:
    """Raise ``ValueError`` unless the noise Hamiltonians have constant gradients.

    The derivatives of ``ĥ`` along two fixed random directions are compared at the default
    position and at two other fixed points (relative tolerance 1e-9); a non-linear noise (point
    vortices) changes them. Directional derivatives (one JVP each) rather than the whole
    Jacobian keep the check at ``O(m + d)`` memory for many noise directions.
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    base = np.asarray(system.default_position, dtype=float)
    rng = np.random.default_rng(0)
    points = [base, base + 0.3 * rng.normal(size=base.shape), rng.normal(size=base.shape)]
    probes = [rng.normal(size=base.shape) for _ in range(2)]
    slopes = functools.partial(_noise_slopes, system=system)
    jacobians = np.asarray(evaluate(slopes, np.stack(points), np.stack(probes)))
    scale = max(1.0, float(np.max(np.abs(jacobians[0]))))
    for jacobian in jacobians[1:]:
        if not np.allclose(jacobian, jacobians[0], rtol=0.0, atol=1e-9 * scale):
            raise ValueError(
                f"adjusted_lie_poisson needs noise Hamiltonians with constant gradients (linear "
                f"noise ĥ_i = ⟨μ, ξ_i⟩, e.g. rigid body, spins, heavy top); the {system.name}'s "
                "gradients change with μ, so the proposal is not an involution. Use the "
                "unadjusted liesample.lie_poisson_langevin for this system."
            )


@functools.partial(jit, static_argnames="system")
def _noise_slopes(points, probes, *, system):
    """``[point, probe]``: the derivative of ``ĥ`` at each point along each probe, one program
    per system value (:mod:`liesample.foundation.identity`)."""

    def slopes(point):
        return jax.vmap(lambda v: jax.jvp(system.noise_hamiltonians, (point,), (v,))[1])(probes)

    return jax.vmap(slopes)(points)


def _energy_and_brackets(dynamics: PoissonLangevin, position):
    energy, grad_h = jax.value_and_grad(dynamics.system.hamiltonian)(position)
    return energy, dynamics.brackets_with_noise(position, grad_h)


def _dynamics(system, sigma, beta):
    return PoissonLangevin(system, sigma=sigma, theta=0.5 * beta * sigma**2, scene=_NOISE_SCENE)


def init(position, system: LiePoissonSystem, rng_key=None) -> AdjustedLiePoissonState:
    """Initial state on the orbit through ``position`` (no key needed; ``rng_key`` is ignored).

    Raises ``ValueError`` for a bad start and, when ``position`` is concrete, for a start where
    the energy ``h`` is not finite.
    """
    del rng_key
    system.check_position(position)
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    dynamics = PoissonLangevin(system, sigma=1.0, theta=1.0, scene=_NOISE_SCENE)
    energy, brackets = _energy_and_brackets(dynamics, position)
    value = concrete_array(energy)
    if value is not None:
        check_start_energy(system, position, value)
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


def build_noise_kernel(system: LiePoissonSystem):
    """Build ``kernel(noise, state, step_size, sigma, beta) -> (state, info)``, the step as a
    function of its draws: ``m + 1`` standard normals, ``W = noise[:m]`` for the proposal and
    ``z = noise[m]`` for the acceptance test, which accepts when ``log Φ(z) < L`` (``Φ(z)`` is
    uniform on ``(0, 1)``, so one normal draw serves both).

    What :func:`build_kernel` draws per step and :mod:`liesample.integrators.chain_loop` in blocks.
    Raises ``ValueError`` for a system whose noise gradients depend on ``μ``
    (:func:`check_linear_noise`).
    """
    check_linear_noise(system)
    return _noise_kernel(system)


def _noise_kernel(system: LiePoissonSystem):
    """:func:`build_noise_kernel` of a system already checked (the sampler checks it once when
    it is built, not again in each program that traces its step)."""
    casimir_error = system.step_casimir_error

    def kernel(noise, state: AdjustedLiePoissonState, step_size, sigma, beta):
        normals, accept = noise[:-1], noise[-1]
        position = state.position
        proposal, reverse_noise, energy, brackets = involution(
            system, position, normals, step_size, sigma, beta, state.brackets
        )
        log_ratio = (
            -beta * (energy - state.energy)
            - 0.5 * jnp.sum(reverse_noise**2)
            + 0.5 * jnp.sum(normals**2)
        )
        nonfinite = ~(
            jnp.all(jnp.isfinite(proposal))
            & jnp.isfinite(energy)
            & jnp.all(jnp.isfinite(brackets))
            & jnp.isfinite(log_ratio)
        )
        log_ratio = jnp.where(nonfinite, -jnp.inf, log_ratio)
        acceptance_rate = jnp.exp(jnp.minimum(log_ratio, 0.0))
        is_accepted = jax.scipy.special.log_ndtr(accept) < log_ratio
        new_state = AdjustedLiePoissonState(
            jnp.where(is_accepted, proposal, position),
            state.reference_casimirs,
            jnp.where(is_accepted, energy, state.energy),
            jnp.where(is_accepted, brackets, state.brackets),
        )
        info = AdjustedLiePoissonInfo(
            nonfinite,
            acceptance_rate,
            new_state.energy,
            is_accepted,
            casimir_error(new_state.position, state.reference_casimirs),
        )
        return new_state, info

    return kernel


def _draw_noise(system, rng_key, shape, dtype):
    """The draws of ``shape`` steps: standard normals ``(*shape, m + 1)`` (proposal,
    acceptance)."""
    return jax.random.normal(rng_key, (*shape, system.num_noises + 1), dtype=dtype)


def build_kernel(system: LiePoissonSystem):
    """Build ``kernel(rng_key, state, step_size, sigma, beta) -> (state, info)``.

    ``step_size``, ``sigma`` and ``beta`` may be traced. Raises ``ValueError`` for a system
    whose noise gradients depend on ``μ`` (:func:`check_linear_noise`).
    """
    return _keyed(system, build_noise_kernel(system))


def _keyed(system, noise_kernel):
    """The kernel of ``noise_kernel`` that draws its own noise from ``rng_key``."""

    def kernel(rng_key, state: AdjustedLiePoissonState, step_size, sigma, beta):
        noise = _draw_noise(system, rng_key, (), state.position.dtype)
        return noise_kernel(noise, state, step_size, sigma, beta)

    return kernel


_DEFAULT_SOURCE = "default: kappa = 1.3 m^(-1/3) (no warm-up adaptation)"
_ON_DEFAULT = "; on the orbit of the system's default position"


MAX_STEP_FACTOR = 100.0
"""The warm-up's step is at most this many times the construction's step (given, or the
rule's on the default position)."""


def _default_step_size(system, beta, sigma, position) -> float:
    """``κ = 1.3 m^{−1/3}`` in units of the stiffness on the orbit of ``position`` (module
    docstring), or ``0.4/σ²`` where ``h`` is flat along the noise (no stiffness)."""
    theta = 0.5 * beta * sigma**2
    stiff = stiffness(system, theta, np.asarray(position)) if system.curvature_bound else 0.0
    if stiff == 0.0:
        return 0.4 / sigma**2
    return 1.3 * system.num_noises ** (-1.0 / 3.0) / stiff


def as_top_level_api(
    system: LiePoissonSystem,
    *,
    beta: float,
    sigma: float = 1.0,
    step_size: float | None = None,
    target_acceptance_rate: float = DEFAULT_TARGET_ACCEPTANCE_RATE,
    noise_block_size: int = DEFAULT_NOISE_BLOCK_SIZE,
) -> Sampler:
    """Metropolis-adjusted Lie–Poisson sampler of ``exp(−βh)`` on the orbit of the initial
    state, exact at every step size (module notes).

    Parameters
    ----------
    system : LiePoissonSystem
        With linear noise Hamiltonians (rigid body, heavy top, spins).
    beta : float
        Inverse temperature, finite (and admissible for the system).
    sigma : float
        Noise strength ``σ > 0`` (default 1). Only ``σ²·step_size`` matters for the move (there
        is no Hamiltonian drift), so ``σ`` and ``step_size`` are one knob: the rotation angle
        per step.
    step_size : float or None
        Time step ``dt > 0``; any value gives the exact law, larger ones lower acceptance.
        ``None`` (default): tuned in the warm-up of ``liesample.sample(..., num_warmup=N)`` by
        dual averaging to ``target_acceptance_rate``; without warm-up, ``κ = 1.3 m^{−1/3}`` in
        units of the stiffness on the first start's orbit, and used directly (``init``,
        ``step``) on the orbit of the system's default position, chosen when the sampler is
        built (module docstring). A given step is kept unless
        ``liesample.sample(..., adapt=True)``.
    target_acceptance_rate : float in (0, 1)
        What the warm-up's dual averaging aims at (default 0.574).
    noise_block_size : int
        Steps whose draws are made at once, in the warm-up too (default 32); as for
        :func:`liesample.samplers.orbit.lie_poisson_langevin.as_top_level_api`.

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position)`` and ``step(rng_key, state) -> (state, info)`` (``info``: the Info
        contract plus ``is_accepted`` and ``casimir_error``); ``rng_key`` may be
        ``jax.random.key`` or ``jax.random.PRNGKey``. It declares ``adaptation`` (dual averaging)
        and ``noise_blocks``.

    Examples
    --------
    One step on the rigid body's orbit ``|μ| = 1.5``; the state stays on it:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> sampler = liesample.adjusted_lie_poisson(system, beta=3.0, step_size=0.1)
    >>> state = sampler.init(jnp.array([1.5, 0.0, 0.0]))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> bool(jnp.isclose(jnp.linalg.norm(state.position), 1.5)), bool(info.is_divergent)
    (True, False)
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    beta = checked_beta(system, beta)
    system.check_noise()
    sigma = finite_float("sigma", sigma, positive=True)
    if step_size is not None:
        step_size = finite_float("step_size", step_size, positive=True)
    target = finite_float("target_acceptance_rate", target_acceptance_rate, rate=True)
    noise_block_size = check_block_size(noise_block_size)
    return _sampler(system, beta, sigma, step_size, target, noise_block_size)


_STUCK_ADVICE = (
    "Give a smaller step_size, or leave it unset with num_warmup > 0 (liesample.sample's "
    "warm-up then tunes it by dual averaging), or pass adapt=True with num_warmup > 0 to tune "
    "a given one."
)


def _choose(system, beta, sigma, positions, rng_key=None):
    """The rule's step on the orbit of the first start (no pilot run, so no key)."""
    del rng_key
    first = np.asarray(positions, dtype=jnp.result_type(float))[0]
    return _default_step_size(system, beta, sigma, first), _DEFAULT_SOURCE


def _check_orbits(system, beta, sigma, positions, representatives):
    for chain in representatives:
        position = positions[chain]
        check_precision(system, beta, 0.5 * beta * sigma**2, position, position.dtype)


def _check_positions(system, check_orbits, positions, *, step_size_checks=True):
    positions = np.asarray(positions, dtype=jnp.result_type(float))
    casimirs = check_orbit_starts(system, positions)
    if step_size_checks:
        check_orbits(positions, distinct_orbits(casimirs))


@dataclass(frozen=True)
class _Stepper:
    """What decides the compiled step (the :class:`Structure`'s ``build``, which the warm-up
    steps too): called with the ``step_size``, ``sigma`` and ``beta`` (floats, or traced), the
    sampler with ``hooks``."""

    system: LiePoissonSystem
    noise_block_size: int

    def __call__(self, step_size, sigma, beta, init_fn=None, **hooks) -> Sampler:
        system, size = self.system, self.noise_block_size
        noise_kernel = _noise_kernel(system)
        kernel = _keyed(system, noise_kernel)

        def step_fn(rng_key, state):
            return kernel(step_key(rng_key), state, step_size, sigma, beta)

        def block_step(noise, state):
            return noise_kernel(noise, state, step_size, sigma, beta)

        def draw_block(rng_key, state):
            return _draw_noise(system, rng_key, (size,), state.position.dtype)

        return Sampler(
            init_fn or plain_init_fn(init, system),
            step_fn,
            noise_blocks=NoiseBlocks(size, draw_block, block_step),
            law_groups=orbit_groups(system),
            stuck_advice=_STUCK_ADVICE,
            **hooks,
        )


def _sampler(system, beta, sigma, step_size, target, noise_block_size) -> Sampler:
    """The sampler of the checked arguments: its settings, and the step size it declares
    tunable by dual averaging (:class:`liesample.samplers.contract.Tunable`)."""
    check_linear_noise(system)
    settings = orbit_settings(
        "adjusted_lie_poisson", system, beta, sigma=sigma, step_size=step_size,
        step_size_source="given", target_acceptance_rate=target,
        noise_block_size=noise_block_size,
    )  # fmt: skip
    given = step_size is not None
    if not given:
        step_size = _default_step_size(system, beta, sigma, system.default_position)
        settings.update(step_size=step_size, step_size_source=_DEFAULT_SOURCE + _ON_DEFAULT)

    options = {"beta": beta, "sigma": sigma, "target_acceptance_rate": target,
               "noise_block_size": noise_block_size}  # fmt: skip
    check_orbits = functools.partial(_check_orbits, system, beta, sigma)
    at = _Stepper(system, noise_block_size)
    tunable = Tunable(
        "dual_averaging",
        given,
        functools.partial(_choose, system, beta, sigma),
        target_acceptance_rate=target,
        # beyond this the noise alone crosses the orbit many times per step; at β = 0 every
        # proposal is accepted and dual averaging would grow the step without bound
        max_step_size=MAX_STEP_FACTOR * step_size,
    )
    return at(
        step_size,
        sigma,
        beta,
        init_fn=orbit_init_fn(init, system, check_orbits),
        settings=settings,
        check_positions=functools.partial(_check_positions, system, check_orbits),
        adaptation=tunable,
        structure=Structure(at, {"step_size": step_size, "sigma": sigma, "beta": beta}),
        recipe=Recipe(as_top_level_api, (system,), options, {"step_size": step_size}),
    )


adjusted_lie_poisson = sampling_api(
    as_top_level_api, init, build_kernel, "adjusted_lie_poisson", __name__
)
