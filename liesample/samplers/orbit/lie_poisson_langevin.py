"""The Lie–Poisson–Langevin sampler: Gibbs-exact sampling on a coadjoint orbit.

A BlackJAX-shaped module (``State``/``Info``, ``init``, ``build_kernel``, ``as_top_level_api``).
The chain is the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``) with ``θ = βσ²/2``
(paper, ``eq:lie-poisson-langevin``), whose invariant law on the orbit of the initial state is
``∝ exp(−βh)``; the discretisation bias is that of the chosen integrator.

Safe defaults: a step size beyond the measured stability bound
(:mod:`liesample.integrators.stability`) is refused, and without a step size the sampler picks
one below the bound whose predicted bias is at most :data:`DEFAULT_BIAS_TOLERANCE` posterior
standard deviations (:func:`liesample.integrators.accuracy.default_step_size`). The sampler
declares that choice as its ``adaptation`` (method ``"rule"``,
:class:`liesample.samplers.contract.Tunable`), which :func:`liesample.sample` runs on the
run's starts (:mod:`liesample.tuning.warmup`); ``step`` never changes the step size.

The Brownian increments of a run are drawn in blocks of ``noise_block_size`` steps
(:mod:`liesample.integrators.chain_loop`); ``step(rng_key, state)`` alone draws one step's
increments from ``rng_key``. The state carries ``h(μ)``, so a step evaluates ``h`` once (at the
proposal, for the divergence test).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.dynamics.poisson_langevin import PoissonLangevin, Scene, make_dynamics
from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.compile import evaluate
from liesample.foundation.validation import concrete_array, finite_float
from liesample.integrators import accuracy
from liesample.integrators.chain_loop import DEFAULT_NOISE_BLOCK_SIZE, NoiseBlocks, check_block_size
from liesample.integrators.orbit import DEFAULT_INTEGRATOR, Integrator, get_integrator
from liesample.integrators.stability import (
    STABILITY_MODES,
    check_precision,
    check_step_size,
    stiffness_on_orbits,
)
from liesample.samplers.contract import (
    Recipe,
    Sampler,
    Structure,
    Tunable,
    sampling_api,
    step_key,
)
from liesample.samplers.orbit import _starts
from liesample.samplers.orbit.vortex_metropolis import warn_if_unmixing

__all__ = [
    "DEFAULT_BIAS_TOLERANCE",
    "LiePoissonInfo",
    "LiePoissonState",
    "as_top_level_api",
    "build_kernel",
    "build_noise_kernel",
    "init",
    "lie_poisson_langevin",
    "make_dynamics",
]

DEFAULT_BIAS_TOLERANCE = accuracy.DEFAULT_RELATIVE_TOLERANCE
"""Default bias tolerance of the automatic step size, in posterior standard deviations of the
state's coordinates."""


class LiePoissonState(NamedTuple):
    """State of a chain.

    position : the point ``μ`` on the orbit.
    reference_casimirs : the Casimirs of the initial point, against which drift is measured.
    energy : ``h(μ)``, cached (the step's ``info.energy`` when the proposal is rejected).
    """

    position: jax.Array
    reference_casimirs: jax.Array
    energy: jax.Array


class LiePoissonInfo(NamedTuple):
    """What one step did (the Info contract of :mod:`liesample.samplers.contract`).

    is_divergent : the proposed state or its energy was NaN/inf; the step was rejected and the
        chain kept its previous state.
    acceptance_rate : 1.0 for a step taken, 0.0 for a divergent (rejected) one; the sampler is
        unadjusted, so there is no other test.
    energy : ``h`` at the chain's state after the step.
    casimir_error : largest relative drift ``|C − C₀|/|C₀|`` of the Casimirs; for systems that
        declare a ``casimir_scale`` (a Casimir may be zero, e.g. the heavy top's ``Π·Γ``) the
        denominator is ``max(|C₀|, scale(μ))`` (``LiePoissonSystem.casimir_error``). With an
        integrator that moves along the orbit (``preserves_orbit``) it is the system's cheaper
        per-step drift where it declares one (``step_casimir_error``: Zeitlin's ``‖W‖²``).
    """

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    casimir_error: jax.Array


def init(position, system: LiePoissonSystem, rng_key=None) -> LiePoissonState:
    """Initial state on the orbit through ``position`` (no key needed; ``rng_key`` is ignored).

    Raises ``ValueError`` for a bad start (shape, non-finite, degenerate orbit) and, when
    ``position`` is concrete, for a start where the energy ``h`` is not finite.
    """
    del rng_key
    system.check_position(position)
    value = concrete_array(position)
    if value is not None:
        energy = concrete_array(
            evaluate(system.hamiltonian, np.asarray(value, jnp.result_type(float)))
        )
        if energy is not None:  # None when staged out: the runner checks every start itself
            _starts.check_start_energy(system, value, energy)
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    return LiePoissonState(position, system.casimirs(position), system.hamiltonian(position))


def build_noise_kernel(
    system: LiePoissonSystem, integrator=DEFAULT_INTEGRATOR, scene: Scene | None = None
):
    """Build ``kernel(noise, state, step_size, sigma, theta) -> (state, info)``, the step as a
    function of its standard normal draws ``noise`` (shape ``(m,)``; ``dW = √dt · noise``), or
    ``None`` when the scene has no noise.

    What :func:`build_kernel` draws per step and :mod:`liesample.integrators.chain_loop` in blocks.
    """
    integrator = get_integrator(integrator)
    scene = Scene() if scene is None else scene
    # a coadjoint move changes the Casimirs only by round-off, which the cheap check sees
    casimir_error = (
        system.step_casimir_error if integrator.preserves_orbit else system.casimir_error
    )

    def kernel(noise, state: LiePoissonState, step_size, sigma, theta):
        dynamics = PoissonLangevin(system, sigma=sigma, theta=theta, scene=scene)
        dW = None if noise is None else jnp.sqrt(step_size) * noise
        proposal = integrator(dynamics, state.position, step_size, dW)
        energy = system.hamiltonian(proposal)
        divergent = ~(jnp.all(jnp.isfinite(proposal)) & jnp.isfinite(energy))
        position = jnp.where(divergent, state.position, proposal)
        energy = jnp.where(divergent, state.energy, energy)
        info = LiePoissonInfo(
            divergent,
            jnp.where(divergent, 0.0, 1.0).astype(position.dtype),
            energy,
            casimir_error(position, state.reference_casimirs),
        )
        return LiePoissonState(position, state.reference_casimirs, energy), info

    return kernel


def _draw_noise(system, scene, rng_key, shape, dtype):
    """Standard normals of shape ``(*shape, m)``, or ``None`` without noise (no bits drawn)."""
    if not scene.noise:
        return None
    return jax.random.normal(rng_key, (*shape, system.num_noises), dtype=dtype)


def build_kernel(
    system: LiePoissonSystem, integrator=DEFAULT_INTEGRATOR, scene: Scene | None = None
):
    """Build ``kernel(rng_key, state, step_size, sigma, theta) -> (state, info)``.

    The scene and integrator are structural (they decide what is traced); ``step_size``,
    ``sigma`` and ``theta`` may be traced values. ``rng_key`` may be either key style.
    """
    scene = Scene() if scene is None else scene
    noise_kernel = build_noise_kernel(system, integrator, scene)

    def kernel(rng_key, state: LiePoissonState, step_size, sigma, theta):
        noise = _draw_noise(system, scene, rng_key, (), state.position.dtype)
        return noise_kernel(noise, state, step_size, sigma, theta)

    return kernel


_UNCHOSEN = (
    "automatic: the bias model, on the starts in liesample.sample, else on the orbit of the "
    "system's default position"
)


def _source(choice) -> str:
    return (
        f"predicted |bias| <= {choice.relative_tolerance:g} posterior sd for the mean of each "
        f"coordinate, and its sd within {choice.relative_tolerance:g} of itself "
        "(liesample.integrators.accuracy.default_step_size)"
    )


def as_top_level_api(
    system: LiePoissonSystem,
    *,
    beta: float | None = None,
    sigma: float = 1.0,
    step_size: float | None = None,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    theta: float | None = None,
    hamiltonian: bool = True,
    stability: str = "raise",
    bias_tolerance: float = DEFAULT_BIAS_TOLERANCE,
    noise_block_size: int = DEFAULT_NOISE_BLOCK_SIZE,
) -> Sampler:
    """Lie–Poisson–Langevin sampler of ``exp(−βh)`` on the orbit of the initial state.

    Parameters
    ----------
    system : LiePoissonSystem
        E.g. :func:`liesample.systems.rigid_body`.
    beta : float
        Inverse temperature; any finite value (``β < 0`` samples a negative temperature where
        the orbit is compact). Required when ``sigma > 0``.
    sigma : float
        Noise strength ``σ ≥ 0`` (default 1): trades mixing against stiffness at fixed ``β``.
    step_size : float or None
        Time step ``dt > 0``. ``None`` (default): chosen below the stability bound from the bias
        model of :func:`liesample.integrators.accuracy.default_step_size` (short coupled pilot
        runs), so that the predicted bias of the mean of every coordinate of ``μ`` is at most
        ``bias_tolerance`` posterior standard deviations, and of its sd at most
        ``bias_tolerance`` of itself. :func:`liesample.sample` chooses it from the run's starts
        (in the warm-up under ``num_warmup=N``, with a key of the run) and records it in the
        run's attributes; used directly (``init``, ``step``), the sampler chooses it once, on
        the orbit of the system's default position. Every step's stationary sd error along the
        stiffest noise direction, linearised at its stability number
        (:func:`liesample.integrators.accuracy.linear_sd_bias`, no pilot run), is recorded as
        ``linear_sd_bias``; a given step whose error exceeds ``bias_tolerance`` warns, naming
        a step within it.
    integrator : str or Integrator
        One of ``liesample.integrators.INTEGRATORS``; default ``"splitting"``.
    theta : float, optional
        Dissipation strength for a noise-free flow (``sigma = 0``) only.
    hamiltonian : bool
        Whether the scene has the Hamiltonian drift (it does not change the invariant law).
    stability : {"raise", "warn", "off"}
        What happens when ``step_size`` is beyond the integrator's stable bound on the orbit of
        a start, ``κ = step_size·θ·max_i |h''_i| > 2`` (:mod:`liesample.integrators.stability`;
        rigid body: ``θ·step_size·r²(1/I_min − 1/I_max) ≤ 2``): ``"raise"`` (default) a
        ``ValueError`` naming the largest allowed step; ``"warn"`` a ``UserWarning`` (the chain
        then samples a wrong law); ``"off"`` no check. The mode is recorded in the run's attributes.
    bias_tolerance : float
        Relative bias tolerance of the automatic step size, and of a given step's
        ``linear_sd_bias`` (default :data:`DEFAULT_BIAS_TOLERANCE` = 0.05 posterior sd).
    noise_block_size : int
        Steps whose Brownian increments are drawn at once in :func:`liesample.sample` and the
        other drivers (default 32; :mod:`liesample.integrators.chain_loop`). Block ``b`` of chain
        ``c`` is drawn from ``fold_in(key_c, b)``, so the draws do not depend on how a run is
        chunked; another block size gives other draws of the same law.

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position)`` and ``step(rng_key, state) -> (state, info)`` (``info``: the Info
        contract, plus ``casimir_error``); ``rng_key`` may be ``jax.random.key`` or
        ``jax.random.PRNGKey``.

    Examples
    --------
    The README's sampler: one step of the unadjusted scheme, which keeps the orbit ``|μ| = 1.5``:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, sigma=1.0, step_size=0.05)
    >>> state = sampler.init(jnp.array([1.5, 0.0, 0.0]))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> bool(jnp.isclose(jnp.linalg.norm(state.position), 1.5)), bool(info.is_divergent)
    (True, False)
    """
    plan = _plan(system, beta, sigma, step_size, integrator, theta, hamiltonian, stability,
                 bias_tolerance, noise_block_size)  # fmt: skip
    return _sampler(plan, _automatic_step(plan))


class _Plan(NamedTuple):
    """The checked arguments of :func:`as_top_level_api` (``options``: what its
    :class:`Recipe` passes back to it, with the step)."""

    system: LiePoissonSystem
    integrator: Integrator
    scene: Scene
    beta: float | None  # None: no noise (the deterministic scene)
    sigma: float
    theta: float
    stability: str
    bias_tolerance: float
    noise_block_size: int
    step_size: float | None  # given, or None (the bias model's)
    options: dict


def _plan(system, beta, sigma, step_size, integrator, theta, hamiltonian, stability,
          bias_tolerance, noise_block_size) -> _Plan:  # fmt: skip
    """:func:`as_top_level_api`'s arguments checked, each error naming its parameter."""
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    if step_size is not None:
        step_size = finite_float("step_size", step_size, positive=True)
    bias_tolerance = finite_float("bias_tolerance", bias_tolerance, positive=True)
    noise_block_size = check_block_size(noise_block_size)
    sigma, theta, scene = make_dynamics(
        system, beta=beta, sigma=sigma, theta=theta, hamiltonian=hamiltonian
    )
    warn_if_unmixing(system, beta if sigma > 0.0 else None, "lie_poisson_langevin")
    if step_size is None and sigma == 0.0:
        raise ValueError(
            "step_size is required when sigma = 0: the automatic choice bounds the bias of a "
            "sampled law, and a noise-free flow samples none"
        )
    if stability not in STABILITY_MODES:
        raise ValueError(f"stability must be one of {STABILITY_MODES}, got {stability!r}")
    integrator = get_integrator(integrator)
    options = {
        "beta": beta,
        "sigma": sigma,
        "integrator": integrator,
        "theta": None if sigma > 0 else theta,
        "hamiltonian": hamiltonian,
        "stability": stability,
        "bias_tolerance": bias_tolerance,
        "noise_block_size": noise_block_size,
    }
    return _Plan(system, integrator, scene, beta, sigma, theta, stability, bias_tolerance,
                 noise_block_size, step_size, options)  # fmt: skip


def _choose(plan: _Plan, positions, rng_key=None):
    """The bias model's step for the starts ``positions``: without a key (no warm-up) on one
    start per distinct orbit with ``key(0)``, with a key (warm-up) on all of them."""
    positions = np.asarray(positions)
    if rng_key is None:
        positions = positions.astype(jnp.result_type(float))
        orbits = _starts.distinct_orbits(_starts.check_orbit_starts(plan.system, positions))
        positions = positions[np.asarray(orbits)]
    choice = accuracy.default_step_size(
        plan.system,
        cast(float, plan.beta),  # a step is chosen for the noise, which needs beta
        sigma=plan.sigma,
        integrator=plan.integrator,
        initial_positions=positions,
        rng_key=rng_key,  # None: key(0)
        relative_tolerance=plan.bias_tolerance,
    )
    return choice.step_size, "bias model: " + _source(choice)


def _automatic_step(plan: _Plan):
    """``() -> step``: the given step, or the one used directly without ``liesample.sample``
    (the bias model on the orbit of the system's default position, a function of the
    construction arguments only, computed when first needed)."""
    if plan.step_size is not None:
        return lambda: plan.step_size
    default = np.asarray(plan.system.default_position)[None]
    return functools.cache(lambda: _choose(plan, default)[0])


def _check_orbits(plan: _Plan, current_step, settings, positions, representatives,
                  prefix=False):  # fmt: skip
    """Stability (one vectorised stiffness call for all orbits) and precision checks; records
    the stability number and the step's linear sd bias in ``settings``."""
    system, integrator, theta = plan.system, plan.integrator, plan.theta
    representatives = np.asarray(representatives)
    dt = current_step()
    limit = integrator.stability_limit
    if plan.stability != "off" and limit is not None and theta != 0.0 and system.curvature_bound:
        kappas = dt * stiffness_on_orbits(system, theta, positions[representatives])
        beyond = np.flatnonzero(kappas > limit)
        if beyond.size:  # the first such chain: its message (raise or warn) from the check
            chain = int(representatives[beyond[0]])
            try:
                check_step_size(system, integrator, dt, theta, positions[chain], plan.stability)
            except ValueError as error:
                if not prefix:
                    raise
                raise ValueError(f"initial_positions[{chain}]: {error}") from None
        kappa = float(np.max(kappas))
        settings["stability_number"] = kappa
        settings["stability_limit"] = limit
        # a given step's bias, from the linear model at κ (no pilot run)
        settings["linear_sd_bias"] = (
            accuracy.warn_given_step(integrator, dt, kappa, plan.bias_tolerance)
            if settings["step_size_source"] == "given"
            else accuracy.linear_sd_bias(integrator, kappa)
        )
    for chain in representatives:
        check_precision(system, plan.beta, theta, positions[chain], positions.dtype)


def _check_positions(plan: _Plan, check_orbits, positions, *, step_size_checks=True):
    positions = np.asarray(positions)
    casimirs = _starts.check_orbit_starts(plan.system, positions)
    if step_size_checks:
        dtype = jnp.result_type(float)
        check_orbits(np.asarray(positions, dtype), _starts.distinct_orbits(casimirs), prefix=True)


@dataclass(frozen=True)
class _Stepper:
    """What decides the compiled step of a sampler (its :class:`Structure`'s ``build``): called
    with ``step_size`` (a value, possibly traced, or a function giving it when first needed),
    ``sigma`` and ``theta``, the sampler with ``hooks``."""

    system: LiePoissonSystem
    integrator: Integrator
    scene: Scene
    noise_block_size: int

    def __call__(self, step_size, sigma, theta, init_fn=None, **hooks) -> Sampler:
        system, integrator, scene = self.system, self.integrator, self.scene
        dt = step_size if callable(step_size) else (lambda: step_size)
        kernel = build_kernel(system, integrator, scene)
        noise_kernel = build_noise_kernel(system, integrator, scene)

        def step_fn(rng_key, state):
            return kernel(step_key(rng_key), state, dt(), sigma, theta)

        def block_step(noise, state):
            return noise_kernel(noise, state, dt(), sigma, theta)

        size = self.noise_block_size

        def draw_block(rng_key, state):
            return _draw_noise(system, scene, rng_key, (size,), state.position.dtype)

        blocks = NoiseBlocks(size, draw_block, block_step)
        return Sampler(
            init_fn or _starts.plain_init_fn(init, system),
            step_fn,
            # Without noise nothing is drawn: the per-step loop is already lean.
            noise_blocks=blocks if scene.noise else None,
            **hooks,
        )


def _sampler(plan: _Plan, current_step) -> Sampler:
    """The sampler of ``plan`` stepping with ``current_step()``: its kernels, start checks,
    settings and declarations; a given step makes it a :class:`Structure` (one compiled program
    for every ``β``, ``σ`` and step)."""
    system, sigma, theta = plan.system, plan.sigma, plan.theta
    given = plan.step_size is not None
    settings = _starts.orbit_settings(
        "lie_poisson_langevin", system, plan.beta, sigma=sigma, theta=theta,
        integrator=plan.integrator.name, stability=plan.stability, step_size=plan.step_size,
        step_size_source="given" if given else _UNCHOSEN, noise_block_size=plan.noise_block_size,
    )  # fmt: skip
    check_orbits = functools.partial(_check_orbits, plan, current_step, settings)
    stepper = _Stepper(system, plan.integrator, plan.scene, plan.noise_block_size)
    values = {"step_size": plan.step_size, "sigma": sigma, "theta": theta}
    return stepper(
        current_step,
        sigma,
        theta,
        init_fn=_starts.orbit_init_fn(init, system, check_orbits),
        settings=settings,
        check_positions=functools.partial(_check_positions, plan, check_orbits),
        adaptation=Tunable("rule", given, functools.partial(_choose, plan)),
        recipe=Recipe(as_top_level_api, (system,), plan.options, {"step_size": plan.step_size}),
        law_groups=_starts.orbit_groups(system),
        stuck_advice="Give a smaller step_size, or leave it unset: liesample.sample then "
        "chooses it from the starts by the bias model.",
        structure=Structure(stepper, values) if given else None,
    )


lie_poisson_langevin = sampling_api(
    as_top_level_api, init, build_kernel, "lie_poisson_langevin", __name__
)
