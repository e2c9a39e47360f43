"""Stochastic Lie–Poisson systems driven by semimartingales, and their simulation.

The paper's Poisson diffusion (``eq:poisson-diffusion``) is ``dF = Σ_i {F, H_i} ∘ dS^i`` with a
driving semimartingale ``S = (t, S¹, S², …)`` (``def:driving_semimartingale``: each ``S^i``
continuous, with a nonzero martingale part, and ``[S^i, S^j] = 0`` for ``i ≠ j``). Here
``H_0 = h`` and ``H_i = σ ĥ_i``, so on ``g*``

    dμ = X_h dt + σ Σ_i X_{ĥ_i} ∘ dS^i .

Every term is a Hamiltonian vector field, so Casimirs are kept pathwise by any orbit-preserving
integrator, whatever the driver (paper, ``eq:stochastic-poisson-system``), and a momentum map is
kept when every ``H_i`` is invariant (stochastic Noether, ``prop:stoch-noether``). The integrators
of :mod:`liesample.integrators` take the increments ``dS`` of a step, so a driver only has to
supply them. The derived dissipation balances Brownian noise (``d[S^i] = dt``) only, so
:func:`simulate` adds it only with a standard Brownian driver.

Drivers (one independent copy per noise direction):

- :class:`BrownianMotion` ``S = c W``;
- :class:`DriftedBrownianMotion` ``S = a t + c W``;
- :class:`TimeChangedBrownianMotion` ``S = W_{τ(t)}`` for an increasing clock ``τ``, ``τ(0) = 0``:
  a continuous Gaussian martingale with ``[S]_t = τ(t)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.dynamics.poisson_langevin import PoissonLangevin, Scene
from liesample.dynamics.system import LiePoissonSystem, checked_beta
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.types import PRNGKey
from liesample.foundation.validation import finite_float
from liesample.integrators.orbit import DEFAULT_INTEGRATOR, Integrator, get_integrator

__all__ = [
    "BrownianMotion",
    "DriftedBrownianMotion",
    "Path",
    "TimeChangedBrownianMotion",
    "simulate",
]


class _Driver:
    """Increments ``dS^i`` over ``[t, t + dt]`` for ``m`` independent directions."""

    def increments(
        self,
        rng_key: PRNGKey,
        t: jax.Array | float,
        dt: jax.Array | float,
        num_noises: int,
        dtype: DTypeLike,
    ) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def quadratic_variation(
        self, t: jax.Array | float, dt: jax.Array | float
    ) -> jax.Array | float:  # pragma: no cover - interface
        """``d[S^i]`` over ``[t, t + dt]`` (deterministic for these drivers)."""
        raise NotImplementedError

    def check_times(self, times: ArrayLike) -> None:
        """Reject a time grid on which the driver is not a valid semimartingale."""


@dataclass(frozen=True)
class DriftedBrownianMotion(_Driver):
    """``S^i_t = a_i t + c W^i_t``: Brownian motion with drift (``def:driving_semimartingale``).

    Parameters
    ----------
    drift : float or sequence of floats
        ``a`` (one value, or one per noise direction); finite.
    scale : float
        ``c > 0``: the martingale part must not vanish.

    Examples
    --------
    >>> from liesample.drivers import DriftedBrownianMotion
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> path = liesample.simulate(system, jax.random.key(0), jnp.array([1.5, 0.0, 0.0]),
    ...                           step_size=0.01, num_steps=10,
    ...                           driver=DriftedBrownianMotion(drift=(0.1, 0.0, 0.0)))
    >>> bool(jnp.allclose(jnp.linalg.norm(path.positions, axis=-1), 1.5))  # still on the orbit
    True
    """

    drift: float | tuple = 0.0
    scale: float = 1.0

    def __post_init__(self):
        drift = np.asarray(self.drift, dtype=float)
        if drift.ndim > 1 or not np.all(np.isfinite(drift)):
            raise ValueError(
                "drift must be a finite scalar or a 1-D sequence (one per noise), "
                f"got {self.drift!r}"
            )
        object.__setattr__(self, "drift", float(drift) if drift.ndim == 0 else tuple(drift))
        object.__setattr__(self, "scale", finite_float("scale", self.scale, positive=True))

    def _drift(self, num_noises: int):
        drift = np.asarray(self.drift)
        if drift.ndim == 1 and drift.shape != (num_noises,):
            raise ValueError(
                f"drift has {drift.shape[0]} entries but the system has {num_noises} noise "
                "directions; give one value or one per direction"
            )
        return drift

    def increments(
        self,
        rng_key: PRNGKey,
        t: jax.Array | float,
        dt: jax.Array | float,
        num_noises: int,
        dtype: DTypeLike,
    ) -> jax.Array:
        del t
        normal = jax.random.normal(rng_key, (num_noises,), dtype=dtype)
        return self._drift(num_noises) * dt + self.scale * jnp.sqrt(dt) * normal

    def quadratic_variation(self, t: jax.Array | float, dt: jax.Array | float) -> jax.Array | float:
        del t
        return self.scale**2 * dt


@dataclass(frozen=True, init=False)
class BrownianMotion(DriftedBrownianMotion):
    """``S^i = c W^i`` (``c = 1``: the standard driver, the only one the dissipation balances).

    Examples
    --------
    >>> from liesample.drivers import BrownianMotion
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> path = liesample.simulate(system, jax.random.key(0), jnp.array([1.5, 0.0, 0.0]),
    ...                           step_size=0.01, num_steps=10, driver=BrownianMotion(scale=0.5))
    >>> path.positions.shape
    (11, 3)
    """

    def __init__(self, scale: float = 1.0):
        super().__init__(drift=0.0, scale=scale)

    @property
    def is_standard(self) -> bool:
        return self.scale == 1.0


@dataclass(frozen=True)
class TimeChangedBrownianMotion(_Driver):
    """``S^i_t = W^i_{τ(t)}``: Brownian motion run on the clock ``τ``.

    Parameters
    ----------
    clock : callable
        ``t ↦ τ(t)``, traceable by JAX, strictly increasing with ``τ(0) = 0`` (checked on the
        simulation's time grid). E.g. ``lambda t: t**2`` or ``lambda t: t + 0.5*jnp.sin(t)``.
        The increments are ``N(0, τ(t+dt) − τ(t))`` and ``d[S] = τ(t+dt) − τ(t)``.

    Examples
    --------
    >>> from liesample.drivers import TimeChangedBrownianMotion
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> path = liesample.simulate(system, jax.random.key(0), jnp.array([1.5, 0.0, 0.0]),
    ...                           step_size=0.01, num_steps=10,
    ...                           driver=TimeChangedBrownianMotion(lambda t: t**2))
    >>> path.positions.shape
    (11, 3)
    """

    clock: Callable[[jax.Array | float], jax.Array | float]

    def __post_init__(self):
        if not callable(self.clock):
            raise TypeError(f"clock must be a callable t ↦ τ(t), got {self.clock!r}")

    def quadratic_variation(self, t: jax.Array | float, dt: jax.Array | float) -> jax.Array | float:
        return self.clock(t + dt) - self.clock(t)

    def increments(
        self,
        rng_key: PRNGKey,
        t: jax.Array | float,
        dt: jax.Array | float,
        num_noises: int,
        dtype: DTypeLike,
    ) -> jax.Array:
        normal = jax.random.normal(rng_key, (num_noises,), dtype=dtype)
        return jnp.sqrt(self.quadratic_variation(t, dt)) * normal

    def check_times(self, times: ArrayLike) -> None:
        tau = np.asarray(evaluate(jax.vmap(self.clock), np.asarray(times)), dtype=float)
        if not np.all(np.isfinite(tau)):
            raise ValueError("clock returned a non-finite value on the time grid")
        if abs(tau[0]) > 1e-12 * max(1.0, float(np.max(np.abs(tau)))):
            raise ValueError(f"clock must start at τ(0) = 0, got τ(0) = {tau[0]:.3g}")
        if np.any(np.diff(tau) <= 0):
            raise ValueError("clock must be strictly increasing on the time grid")


class Path(NamedTuple):
    """A simulated path: ``positions[k]`` at ``times[k]`` (the start included), and whether a
    step produced a non-finite state (the path then keeps its last finite state).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> path = liesample.simulate(system, jax.random.key(0), jnp.array([1.5, 0.0, 0.0]),
    ...                           step_size=0.01, num_steps=10, save_every=5)
    >>> path.times.shape, path.positions.shape, bool(path.nonfinite)  # t = 0, 0.05, 0.1
    ((3,), (3, 3), False)
    """

    times: jax.Array
    positions: jax.Array
    nonfinite: jax.Array


def ito_euler_maruyama(dynamics: PoissonLangevin, mu, dt, dS, quadratic_variation):
    """One Euler–Maruyama step of the Itô form (ambient, leaves the orbit at ``O(dt)``)::

        μ' = μ + ad*_{ζ(μ; dt, dS)} μ + ½ σ² Σ_i d[S^i] (DX_{ĥ_i} · X_{ĥ_i})(μ).

    A cross-check of the Stratonovich integrators: both converge to the same law.
    """
    increment = dynamics.vector_field(mu, dt, dS)
    if dynamics.scene.noise:
        increment = increment + dynamics.ito_correction(mu, quadratic_variation)
    return mu + increment


def simulate(
    system: LiePoissonSystem,
    rng_key: PRNGKey,
    position: ArrayLike | None = None,
    *,
    step_size: float,
    num_steps: int,
    sigma: float = 1.0,
    driver: _Driver | None = None,
    beta: float | None = None,
    hamiltonian: bool = True,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    form: str = "stratonovich",
    save_every: int = 1,
) -> Path:
    """Simulate ``dμ = X_h dt + σ Σ_i X_{ĥ_i} ∘ dS^i`` (``− θ Σ{h,ĥ_i}X_{ĥ_i} dt`` with ``beta``).

    Parameters
    ----------
    system : LiePoissonSystem
    rng_key : jax.Array
        Step ``k`` draws its increments with ``fold_in(rng_key, k)``; ``jax.vmap`` over keys
        gives an ensemble of paths.
    position : array, optional
        Start (default ``system.default_position``).
    step_size, num_steps : float > 0, int ≥ 1
    sigma : float ≥ 0
        Noise strength; ``0`` gives the deterministic flow (no driver is used).
    driver : BrownianMotion, DriftedBrownianMotion or TimeChangedBrownianMotion
        Default: standard Brownian motion.
    beta : float, optional
        Add the derived dissipation ``θ = βσ²/2`` (paper, ``eq:poisson-langevin-eq``), which makes
        ``exp(−βh)`` invariant; only with a standard Brownian driver, the case the balance holds
        for.
    hamiltonian : bool
        Whether the Hamiltonian drift ``X_h`` is in the scene.
    integrator : str or Integrator
        A Stratonovich integrator (``form="stratonovich"``).
    form : {"stratonovich", "ito"}
        ``"ito"`` steps the Itô form by :func:`ito_euler_maruyama` instead (a cross-check).
    save_every : int ≥ 1
        Keep every ``save_every``-th state; ``num_steps`` must be a multiple of it.

    Examples
    --------
    Ten steps of the rigid body's noisy flow (no dissipation: ``beta`` not given), every state
    kept, on the orbit ``|μ| = 1.5``:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> path = liesample.simulate(system, jax.random.key(0), jnp.array([1.5, 0.0, 0.0]),
    ...                           step_size=0.01, num_steps=10)
    >>> path.positions.shape, bool(jnp.allclose(jnp.linalg.norm(path.positions, axis=-1), 1.5))
    ((11, 3), True)
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    position = system.default_position if position is None else position
    system.check_position(position)
    step_size = finite_float("step_size", step_size, positive=True)
    sigma = finite_float("sigma", sigma, nonnegative=True)
    for name, value in (("num_steps", num_steps), ("save_every", save_every)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if num_steps % save_every:
        raise ValueError(f"num_steps ({num_steps}) must be a multiple of save_every ({save_every})")
    if form not in ("stratonovich", "ito"):
        raise ValueError(f"form must be 'stratonovich' or 'ito', got {form!r}")
    driver = BrownianMotion() if driver is None else driver
    if not isinstance(driver, _Driver):
        raise TypeError(
            "driver must be BrownianMotion, DriftedBrownianMotion or TimeChangedBrownianMotion, "
            f"got {driver!r}"
        )
    theta = 0.0
    if beta is not None:
        beta = checked_beta(system, beta)
        if sigma == 0:
            raise ValueError(
                "beta needs noise (sigma > 0); for a noise-free dissipative flow "
                "use liesample.lie_poisson_langevin with sigma=0, theta=..."
            )
        if not (isinstance(driver, BrownianMotion) and driver.is_standard):
            raise ValueError(
                "the derived dissipation balances standard Brownian noise only (d[S] = dt); "
                f"got driver {driver!r} with beta — drop beta or the driver"
            )
        theta = 0.5 * beta * sigma**2
    scene = Scene(hamiltonian=hamiltonian, dissipation=theta != 0.0, noise=sigma > 0)
    integrator = get_integrator(integrator)
    times = step_size * np.arange(num_steps + 1)
    if scene.noise:
        driver.check_times(times)
    dynamics = PoissonLangevin(system, sigma=sigma, theta=theta, scene=scene)
    num_noises = system.num_noises

    def step(carry, k):
        mu, nonfinite = carry
        t = k * step_size
        dS = None
        if scene.noise:
            key = jax.random.fold_in(rng_key, k)
            dS = driver.increments(key, t, step_size, num_noises, mu.dtype)
        if form == "ito":
            qv = driver.quadratic_variation(t, step_size) if scene.noise else 0.0
            proposal = ito_euler_maruyama(dynamics, mu, step_size, dS, qv)
        else:
            proposal = integrator(dynamics, mu, step_size, dS)
        bad = ~jnp.all(jnp.isfinite(proposal))
        return (jnp.where(bad, mu, proposal), nonfinite | bad), None

    def block(carry, first):
        carry, _ = jax.lax.scan(step, carry, first + jnp.arange(save_every))
        return carry, carry[0]

    start = jnp.asarray(position, dtype=jnp.result_type(float))
    # Compiled by liesample.jit even when called eagerly or under an eager vmap
    # (liesample.foundation.compile).
    (_, nonfinite), saved = jit(
        lambda start: jax.lax.scan(
            block, (start, jnp.asarray(False)), save_every * jnp.arange(num_steps // save_every)
        )
    )(start)
    positions = jnp.concatenate([start[None], saved], axis=0)
    return Path(jnp.asarray(times[::save_every]), positions, nonfinite)
