"""The charged Brownian particle in a magnetic field (paper, ``sec:brownian-particle``).

On ``T*Rⁿ`` with ``J(q) = [[0, I], [−I, G(q)]]``
(:class:`liesample.geometry.poisson.CanonicalStructure`), ``h = |p|²/2m + V(q)`` and unit noise
Hamiltonians ``ĥ_i = −q_i`` (noise ``σ ĥ_i``), the generic Poisson–Langevin SDE
(:class:`liesample.dynamics.sde.PoissonLangevinSDE`) is

    dq = p/m dt,     dp = (−∇V + G(q) p/m − θ p/m) dt + σ dW,       θ = βσ²/2,

the friction ``−θ p/m`` being the *derived* dissipation ``−θ Σ {h, ĥ_i} X_{ĥ_i}``. The invariant
law is ``∝ exp(−βV(q) − β|p|²/2m)`` whatever ``G`` is; with ``V = −log π / β`` the ``q``-marginal
is ``π``.

The system runs as a simulation (:func:`charged_particle_path`, or
:func:`charged_particle_dynamics` for a pure, vmappable step). Integrators:

- ``"baoab"`` (default): Strang splitting ``B(ε/2) A(ε/2) O(ε) A(ε/2) B(ε/2)``, the scheme
  :data:`liesample.geometry.cotangent.BAOAB` of the one-effect steps the samplers use: ``B`` the
  potential kick, ``A`` the kinetic + magnetic flow (exact ``e^{εG/m}`` rotation and ``φ₁``
  displacement for a constant field; implicit midpoint, solved by fixed-point iteration, for
  ``G(q)``, which conserves ``|p|`` to the solver tolerance), ``O`` the exact Ornstein–Uhlenbeck
  flow of the derived dissipation plus noise. Weak order 2.
- ``"heun"``: stochastic Heun on the structure-agnostic SDE (baseline; weak order 1).

Which effects exist is a :class:`MagneticScene` (the flags of :class:`liesample.dynamics.Scene` plus
a ``magnetic`` flag); a disabled effect is never traced and draws no random numbers.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.poisson_langevin import Scene, make_dynamics
from liesample.dynamics.sde import PoissonLangevinSDE, stratonovich_heun_step
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.identity import ValueIdentity, by_value
from liesample.foundation.schemes import Schemes
from liesample.foundation.validation import concrete_array, finite_float, float_array
from liesample.geometry.cotangent import (
    BAOAB,
    PhasePoint,
    compose,
    cotangent_bundle,
    drift,
    fractions,
    kick,
    ornstein_uhlenbeck,
)
from liesample.geometry.poisson import CanonicalStructure, canonical_structure, magnetic_structure
from liesample.geometry.spaces import Euclidean

INTEGRATORS = Schemes(
    "the charged particle's T*Rⁿ",
    {"baoab": "baoab", "heun": "heun"},
    {
        "baoab": "splitting: kick, exact magnetic drift, Ornstein–Uhlenbeck, drift, kick",
        "heun": "the generic SDE's Stratonovich Heun step",
    },
)
"""The schemes of :func:`charged_particle_dynamics`
(:class:`liesample.foundation.schemes.Schemes`)."""

# Implicit midpoint for a position-dependent field: iterate until the update is below this
# (relative to 1 + |z|), i.e. a few ulp in float64; the map contracts by ~ε|G|/2m per sweep.
_MIDPOINT_TOLERANCE = 1e-14
_MIDPOINT_MAX_ITERATIONS = 100


@dataclass(frozen=True)
class MagneticScene(Scene):
    """The effects of :class:`liesample.dynamics.poisson_langevin.Scene` plus a ``magnetic``
    flag (checked and listed in ``effects`` by the base class).

    ``magnetic=False`` drops ``G`` from the Poisson tensor (the canonical structure): the field
    is never evaluated. ``G`` enters only through ``X_h``, so it acts only with ``hamiltonian``.
    """

    magnetic: bool = True


@dataclass(frozen=True, eq=False)
class ChargedParticleSystem(ValueIdentity):
    """What :func:`charged_particle` declares: the structure, ``h`` and the noise.

    Attributes
    ----------
    structure : CanonicalStructure
        ``T*Rⁿ`` with the magnetic term ``G = e F`` (or none).
    dimension : int
        ``n``; states ``z = (q, p)`` have shape ``(2n,)``.
    mass, charge : float
    potential_fn, logdensity_fn : callable or None
        Exactly one is set; ``V = potential_fn`` or ``V = −logdensity_fn / β``.
    """

    name: str
    structure: CanonicalStructure
    dimension: int
    mass: float
    charge: float
    potential_fn: Callable[[jax.Array], jax.Array] | None
    logdensity_fn: Callable[[jax.Array], jax.Array] | None
    params: dict

    num_noises = property(lambda self: self.dimension)
    check_beta = None  # every finite β is admissible as far as the system knows
    check_noise = None  # the noise acts on every momentum: it reaches every point

    @property
    def event_shape(self) -> tuple[int]:
        return (2 * self.dimension,)

    def potential(self, q: jax.Array, beta: float | None = None) -> jax.Array:
        """``V(q)``; for a log-density, ``−log π(q)/β`` (``β = 1`` when there is no noise)."""
        if self.potential_fn is not None:
            return self.potential_fn(q)
        logdensity_fn = cast(Callable[[jax.Array], jax.Array], self.logdensity_fn)  # the other
        return -logdensity_fn(q) / (1.0 if beta is None else beta)

    def hamiltonian_fn(self, beta: float | None = None) -> Callable[[jax.Array], jax.Array]:
        """``z ↦ h(z) = |p|²/2m + V(q)``."""

        def hamiltonian(z: jax.Array) -> jax.Array:
            q, p = self.structure.split(z)
            return 0.5 * jnp.sum(p * p) / self.mass + self.potential(q, beta)

        return hamiltonian

    def noise_hamiltonians(self, z: jax.Array) -> jax.Array:
        """``ĥ_i = −q_i``: ``X_{ĥ_i} = (0, e_i)``, a random force on every coordinate."""
        return -self.structure.split(z)[0]

    def check_state(self, state: ArrayLike, name: str = "initial_state") -> None:
        shape = tuple(jnp.shape(state))
        if shape != self.event_shape:
            raise ValueError(
                f"{name} must have shape {self.event_shape} (z = (q, p) with n = "
                f"{self.dimension}), got {shape}"
            )
        value = concrete_array(state)
        if value is not None and not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite, got {value}")


@by_value
def charged_particle(
    potential_fn: Callable[[jax.Array], jax.Array] | None = None,
    logdensity_fn: Callable[[jax.Array], jax.Array] | None = None,
    *,
    magnetic_field: ArrayLike | None = None,
    vector_potential: Callable[[jax.Array], jax.Array] | None = None,
    mass: float = 1.0,
    charge: float = 1.0,
    dimension: int | None = None,
) -> ChargedParticleSystem:
    """A charged particle on ``T*Rⁿ`` in a magnetic field (paper, ``sec:brownian-particle``).

    Parameters
    ----------
    potential_fn, logdensity_fn : callable
        Exactly one: ``q ↦ V(q)`` (a scalar), or ``q ↦ log π(q)`` with ``V = −log π / β``.
    magnetic_field : array, optional
        A constant field: a 3-vector ``B`` (``n = 3``; force ``e (p/m) × B``) or an
        antisymmetric ``(n, n)`` matrix ``F`` (force ``e F p/m``).
    vector_potential : callable, optional
        ``q ↦ A(q) ∈ Rⁿ`` for a position-dependent field ``F = dA`` (``B = curl A`` in R³),
        by autodiff. At most one of ``magnetic_field`` and ``vector_potential``; neither gives
        the plain underdamped Langevin particle.
    mass : float
        ``m > 0``.
    charge : float
        ``e`` (finite; its sign orients the gyration).
    dimension : int, optional
        ``n``; inferred from a constant ``magnetic_field``, otherwise required.

    Examples
    --------
    A particle in a harmonic well and a constant field along ``e_z``:

    >>> from liesample.systems import charged_particle
    >>> system = charged_particle(potential_fn=lambda q: 0.5 * q @ q,
    ...                           magnetic_field=jnp.array([0.0, 0.0, 1.0]))
    >>> system.dimension
    3
    """
    if (potential_fn is None) == (logdensity_fn is None):
        raise ValueError("give exactly one of potential_fn (V(q)) or logdensity_fn (log pi(q))")
    given_name, given = (
        ("potential_fn", potential_fn)
        if potential_fn is not None
        else ("logdensity_fn", logdensity_fn)
    )
    if not callable(given):
        raise TypeError(f"{given_name} must be a callable q -> scalar, got {given!r}")
    mass = finite_float("mass", mass, positive=True)
    charge = finite_float("charge", charge)
    if magnetic_field is not None and vector_potential is not None:
        raise ValueError("give at most one of magnetic_field (constant) or vector_potential")
    if magnetic_field is not None and not callable(magnetic_field):
        float_array(magnetic_field, "magnetic_field must be a real array (B or G)", TypeError)
    if magnetic_field is None and vector_potential is None:
        if dimension is None:
            raise ValueError("dimension is required without a magnetic field (q lives in R^n)")
        structure = canonical_structure(dimension)
    else:
        structure = magnetic_structure(
            magnetic_field=magnetic_field,
            vector_potential=vector_potential,
            charge=charge,
            dimension=dimension,
        )
    n = structure.dimension
    probe = jax.eval_shape(given, jax.ShapeDtypeStruct((n,), jnp.float64))
    if getattr(probe, "shape", None) != ():
        raise ValueError(
            f"{given_name} must map a position of shape ({n},) to a scalar, got "
            f"{getattr(probe, 'shape', probe)}"
        )
    if probe.dtype.kind != "f":
        raise TypeError(f"{given_name} must return a real floating scalar, got dtype {probe.dtype}")
    field = "none"
    if magnetic_field is not None:
        field = np.asarray(magnetic_field, dtype=float).tolist()
    elif vector_potential is not None:
        field = "vector potential"
    return ChargedParticleSystem(
        name="charged particle",
        structure=structure,
        dimension=n,
        mass=mass,
        charge=charge,
        potential_fn=potential_fn,
        logdensity_fn=logdensity_fn,
        params={"mass": mass, "charge": charge, "dimension": n, "magnetic_field": field},
    )


class ChargedParticlePath(NamedTuple):
    """A simulated path: ``states`` of shape ``(num_steps // thinning + 1, 2n)`` (the start
    first); ``nonfinite`` flags a state that became NaN/inf; ``converged`` is ``False`` when an
    implicit-midpoint solve hit its iteration cap."""

    states: jax.Array
    nonfinite: jax.Array
    converged: jax.Array


@dataclass(frozen=True, eq=False)
class ChargedParticleDynamics:
    """The charged particle's Poisson–Langevin SDE in one scene, and its integrator.

    Build with :func:`charged_particle_dynamics` (which validates). :meth:`path` is pure:
    ``jax.jit`` and ``jax.vmap`` it over keys and initial states.
    """

    system: ChargedParticleSystem
    sde: PoissonLangevinSDE
    scene: MagneticScene
    beta: float | None
    integrator: str
    friction_rate: float  # γ of the derived dissipation −γ p (= θ/m), read off the generic formula

    @property
    def structure(self) -> CanonicalStructure:
        return cast(CanonicalStructure, self.sde.structure)  # charged_particle_dynamics builds it

    def make_step(self, step_size: float) -> Callable:
        """``step(rng_key, z) -> (z', converged)`` for a fixed ``step_size`` (matrices built
        once)."""
        if self.integrator == "heun":
            return self._heun_step(step_size)
        return self._baoab_step(step_size)

    def path(
        self,
        rng_key: jax.Array,
        initial_state: ArrayLike,
        step_size: float,
        num_steps: int,
        thinning: int = 1,
    ) -> ChargedParticlePath:
        """Simulate ``num_steps`` steps, keeping every ``thinning``-th state (and the start)."""
        if num_steps % thinning:
            raise ValueError(f"num_steps ({num_steps}) must be a multiple of thinning ({thinning})")
        step = self.make_step(step_size)
        z0 = jnp.asarray(initial_state)

        def one(carry, key):
            z, converged = carry
            z, ok = step(key, z)
            return (z, converged & ok), None

        def block(carry, keys):
            carry, _ = jax.lax.scan(one, carry, keys)
            return carry, carry[0]

        keys = jax.random.split(rng_key, num_steps).reshape((num_steps // thinning, thinning))
        (_, converged), states = jax.lax.scan(block, (z0, jnp.array(True)), keys)
        states = jnp.concatenate([z0[None], states])
        return ChargedParticlePath(states, ~jnp.all(jnp.isfinite(states)), converged)

    # -- integrators ----------------------------------------------------------------------------

    def _heun_step(self, step_size):
        sde, n = self.sde, self.system.dimension

        def step(rng_key, z):
            dW = None
            if self.scene.noise:
                dW = jnp.sqrt(step_size) * jax.random.normal(rng_key, (n,), z.dtype)
            return stratonovich_heun_step(sde, z, step_size, dW), jnp.array(True)

        return step

    def _baoab_step(self, step_size):
        """``B A O A B`` from the one-effect steps of :mod:`liesample.geometry.cotangent`; the
        carry is ``(point, converged)`` (``converged`` tracks the implicit midpoint of a
        ``G(q)``)."""
        system, scene, structure = self.system, self.scene, self.structure
        effects = {}
        if scene.hamiltonian:
            value_and_grad = jax.value_and_grad(lambda q: -system.potential(q, self.beta))
            effects["B"] = _carrying(kick(value_and_grad, step_size))
            effects["A"] = self._kinetic_flow(step_size)
        if scene.noise or scene.dissipation:
            effects["O"] = _carrying(self._ornstein_uhlenbeck(step_size))
        baoab = compose(BAOAB, effects)

        def step(rng_key, z):
            q, p = structure.split(z)
            point, converged = baoab((PhasePoint(q, p), jnp.array(True)), rng_key)
            return jnp.concatenate([point.position, point.momentum]), converged

        return step

    def _kinetic_flow(self, step_size):
        """``A``: the flow of ``q̇ = p/m``, ``ṗ = G(q) p/m`` (exact for a constant ``G``)."""
        structure, mass = self.structure, self.system.mass
        if not callable(structure.magnetic_term):
            field = structure.magnetic_term if structure.magnetic else None
            bundle = cotangent_bundle(Euclidean((self.system.dimension,)), 1.0 / mass, field)
            flows = {f: bundle.kinetic_flow(f * step_size) for f in fractions(BAOAB, "A")}
            return _carrying(drift(bundle, flows))

        def implicit_midpoint(carry, fraction, key):
            del key
            point, converged = carry
            q, p, dt = point.position, point.momentum, fraction * step_size
            scale = 1.0 + jnp.max(jnp.abs(jnp.concatenate([q, p])))

            def update(q_new, p_new):
                p_mid = 0.5 * (p + p_new)
                q_mid = 0.5 * (q + q_new)
                velocity = p_mid / mass
                return q + dt * velocity, p + dt * structure.magnetic_matrix(q_mid) @ velocity

            def body(carry):
                q_new, p_new, _, iteration = carry
                q_next, p_next = update(q_new, p_new)
                change = jnp.maximum(
                    jnp.max(jnp.abs(q_next - q_new)), jnp.max(jnp.abs(p_next - p_new))
                )
                return q_next, p_next, change, iteration + 1

            def keep_going(carry):
                _, _, change, iteration = carry
                return (change > _MIDPOINT_TOLERANCE * scale) & (
                    iteration < _MIDPOINT_MAX_ITERATIONS
                )

            start = (q + (dt / mass) * p, p, jnp.asarray(jnp.inf, p.dtype), 0)
            q_new, p_new, change, _ = jax.lax.while_loop(keep_going, body, start)
            ok = change <= _MIDPOINT_TOLERANCE * scale
            return PhasePoint(q_new, p_new), converged & ok

        return implicit_midpoint

    def _ornstein_uhlenbeck(self, step_size):
        """``O``: the exact flow of ``dp = −γ p dt + σ dW`` (derived dissipation + noise)."""
        scene, n = self.scene, self.system.dimension
        rate = self.friction_rate if scene.dissipation else 0.0
        diffusion = self.sde.sigma**2 if scene.noise else 0.0

        def effect(point, fraction, key):
            p = point.momentum
            noise = jax.random.normal(key, (n,), p.dtype) if scene.noise else None
            p = ornstein_uhlenbeck(p, noise, rate, diffusion, fraction * step_size)
            return point._replace(momentum=p)

        return effect


def _carrying(effect):
    """An effect on a :class:`~liesample.geometry.cotangent.PhasePoint` lifted to
    ``(point, converged)``."""

    def lifted(carry, fraction, key):
        point, converged = carry
        return effect(point, fraction, key), converged

    return lifted


def _derived_friction_rate(system: ChargedParticleSystem, sde: PoissonLangevinSDE) -> float:
    """Read ``γ`` off the generic derived dissipation and check it is ``(0, −γ p)``.

    The ``O`` step solves ``dp = D(z) dt + σ dW`` exactly, which needs ``D(z) = (0, −γ p)``
    with ``X_{ĥ_i} = (0, e_i)``: this evaluates the generic formula at probe states (concrete,
    at build time) instead of writing the friction by hand.
    """
    n = system.dimension
    rng = np.random.default_rng(0)
    probes = rng.normal(size=(2, 2 * n))
    unit = PoissonLangevinSDE(
        sde.structure, sde.hamiltonian, sde.noise_hamiltonians, 1.0, 0.0, sde.scene
    )
    dissipation, fields = evaluate(
        jit(jax.vmap(lambda z: (sde.dissipation(z), unit.noise_fields(z)))), probes
    )
    dissipation, fields = np.asarray(dissipation), np.asarray(fields[0])
    momenta = probes[:, n:]
    gamma = -float(np.sum(dissipation[:, n:] * momenta) / np.sum(momenta * momenta))
    expected_fields = np.concatenate([np.zeros((n, n)), np.eye(n)])
    if not (
        np.allclose(dissipation[:, :n], 0.0, atol=1e-12)
        and np.allclose(dissipation[:, n:], -gamma * momenta, rtol=1e-10, atol=1e-12)
        and np.allclose(fields, expected_fields, atol=1e-12)
    ):  # pragma: no cover - guards the system's declaration
        raise AssertionError("the derived dissipation of the charged particle is not (0, -γ p)")
    return gamma


def charged_particle_dynamics(
    system: ChargedParticleSystem,
    *,
    beta: float | None = None,
    sigma: float = 1.0,
    theta: float | None = None,
    hamiltonian: bool = True,
    magnetic: bool = True,
    integrator: str = "baoab",
) -> ChargedParticleDynamics:
    """Validate ``(β, σ, θ)``, build the scene and the generic SDE, and pick the integrator.

    With noise (``σ > 0``) ``θ = βσ²/2`` is derived (``β`` required, ``θ`` not allowed); without
    noise ``θ ≥ 0`` sets a pure friction flow and there is no ``β``. ``magnetic=False`` switches
    the field off (structurally). The scene holds only effects with a nonzero coefficient.
    """
    if not isinstance(system, ChargedParticleSystem):
        raise TypeError(f"system must come from charged_particle(...), got {type(system).__name__}")
    integrator = INTEGRATORS.lookup(integrator)
    if not isinstance(magnetic, bool):
        raise TypeError(f"magnetic must be a bool, got {magnetic!r}")
    sigma, theta, scene = make_dynamics(
        system, beta=beta, sigma=sigma, theta=theta, hamiltonian=hamiltonian
    )
    if beta is not None:
        beta = finite_float("beta", beta, positive=True)
    scene = MagneticScene(
        hamiltonian=scene.hamiltonian,
        dissipation=scene.dissipation,
        noise=scene.noise,
        magnetic=magnetic and system.structure.magnetic,
    )
    structure = system.structure if scene.magnetic else system.structure.without_magnetic_term()
    sde = PoissonLangevinSDE(
        structure,
        system.hamiltonian_fn(beta),
        system.noise_hamiltonians,
        sigma,
        theta,
        scene,
    )
    friction_rate = _derived_friction_rate(system, sde) if scene.dissipation else 0.0
    return ChargedParticleDynamics(system, sde, scene, beta, integrator, friction_rate)


def charged_particle_path(
    system: ChargedParticleSystem,
    rng_key: jax.Array,
    initial_state: ArrayLike,
    *,
    step_size: float,
    num_steps: int,
    thinning: int = 1,
    **dynamics_options: Any,
) -> ChargedParticlePath:
    """Simulate one path of the charged particle (validated, jit-compiled).

    ``dynamics_options`` are the keywords of :func:`charged_particle_dynamics` (``beta``,
    ``sigma``, ``theta``, ``hamiltonian``, ``magnetic``, ``integrator``); also
    ``initial_state`` ``z0 = (q, p)`` of shape ``(2n,)``, ``step_size > 0``, ``num_steps ≥ 1``
    and ``thinning`` (a divisor of ``num_steps``). Warns when the path became non-finite or an
    implicit solve did not converge (both are also flagged in the result).

    Examples
    --------
    >>> from liesample.systems import charged_particle, charged_particle_path
    >>> system = charged_particle(potential_fn=lambda q: 0.5 * q @ q,
    ...                           magnetic_field=jnp.array([0.0, 0.0, 1.0]))
    >>> path = charged_particle_path(system, jax.random.key(0), jnp.zeros(6), step_size=0.1,
    ...                              num_steps=10, beta=1.0, sigma=1.0)
    >>> path.states.shape, bool(path.nonfinite)  # the start and 10 states (q, p)
    ((11, 6), False)
    """
    dynamics = charged_particle_dynamics(system, **dynamics_options)
    system.check_state(initial_state)
    step_size = finite_float("step_size", step_size, positive=True)
    for name, value in (("num_steps", num_steps), ("thinning", thinning)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an int >= 1, got {value!r}")
    if num_steps % thinning:
        raise ValueError(f"num_steps ({num_steps}) must be a multiple of thinning ({thinning})")
    run = jit(dynamics.path, static_argnums=(3, 4))
    result = run(
        rng_key, jnp.asarray(initial_state, dtype=float), step_size, int(num_steps), int(thinning)
    )
    if bool(result.nonfinite):
        warnings.warn(
            "the charged-particle path became non-finite; reduce step_size",
            RuntimeWarning,
            stacklevel=2,
        )
    if not bool(result.converged):
        warnings.warn(
            "an implicit-midpoint solve hit its iteration cap; reduce step_size",
            RuntimeWarning,
            stacklevel=2,
        )
    return result
