"""Ergodic averages of independent chains, kept as running sums (nothing per step is stored).

- :func:`coupled_ergodic_averages` runs independent chains, each at several step sizes
  ``h, h/2, h/4, …`` driven by *the same* Brownian path (the coarse increments are sums of the
  fine ones), so that the differences ``A(h) − A(h/2)`` have a small variance; per-chain means
  make every standard error honest (the chains are independent);
- :func:`ergodic_averages` runs any BlackJAX-style sampler (unadjusted or
  :func:`liesample.adjusted_lie_poisson`) as vmapped chains.

Both return per-chain time averages (:class:`CoupledAverages`, :class:`ChainAverages`) whose
mean, MCSE and ESS come from the spread of the independent chains. Without Lévy areas the
schemes are strong order 1/2 under non-commuting noise, so coupled levels drift apart by
``O(√h)``: the coupling shrinks the variance of the differences but does not remove it, and
the SE from the chains' spread includes it. The step-size choice that reads these averages is
:mod:`liesample.integrators.accuracy`.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.poisson_langevin import PoissonLangevin, make_dynamics
from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.compile import jit
from liesample.foundation.types import PRNGKey, PyTree
from liesample.foundation.validation import finite_float, prng_key
from liesample.integrators.chain_loop import run_steps
from liesample.integrators.orbit import DEFAULT_INTEGRATOR, Integrator, get_integrator

if TYPE_CHECKING:
    from blackjax.base import SamplingAlgorithm

__all__ = ["ChainAverages", "CoupledAverages", "coupled_ergodic_averages", "ergodic_averages"]


def _real_starts(initial_positions) -> jax.Array:
    """``initial_positions`` as a float array; bool, complex and string starts are refused
    before the cast would hide them."""
    given = getattr(initial_positions, "dtype", None)
    given = np.asarray(initial_positions).dtype if given is None else given
    if not (jnp.issubdtype(given, jnp.floating) or jnp.issubdtype(given, jnp.integer)):
        raise TypeError(
            f"initial_positions must be real floating point, got dtype {given}: pass real "
            "positions, e.g. np.real(initial_positions) when the imaginary part is 0"
        )
    return jnp.asarray(initial_positions, dtype=jnp.result_type(float))


def _positive_int(name, value, low=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


class _IndependentChains:
    """Estimates from per-chain time averages ``chain_means`` / ``chain_square_means`` (leading
    axis: independent chains): mean, MCSE from the chains' spread, and ESS (batch means, one
    batch per chain)."""

    chain_means: np.ndarray
    chain_square_means: np.ndarray

    @property
    def num_chains(self) -> int:
        return self.chain_means.shape[0]

    @property
    def estimate(self) -> np.ndarray:
        """Mean over chains, shape (levels, k)."""
        return self.chain_means.mean(0)

    @property
    def mcse(self) -> np.ndarray:
        """Standard error of :attr:`estimate` from the spread of independent chains."""
        return self.chain_means.std(0, ddof=1) / math.sqrt(self.num_chains)

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per level and observable: stationary variance / MCSE²."""
        variance = self.chain_square_means.mean(0) - self.estimate**2
        with np.errstate(divide="ignore", invalid="ignore"):
            return variance / self.mcse**2


@dataclass(frozen=True)
class CoupledAverages(_IndependentChains):
    """Per-chain time averages at step sizes ``step_sizes`` driven by one Brownian path per chain.

    Attributes
    ----------
    step_sizes : tuple of float
        ``h, h/2, …`` (largest first).
    chain_means : array (chains, levels, k)
        Time average of each observable, per chain and step size (burn-in excluded).
    chain_square_means : array (chains, levels, k)
        Time average of the squared observables (for the stationary variance).
    nonfinite_steps : array (chains, levels)
        Steps rejected because they produced NaN/inf (the chain kept its state).
    wall_time : float
        Seconds for the whole run (compilation excluded).
    kept_time : float
        Physical time averaged over per chain.

    Examples
    --------
    Two levels, ``h = 0.1`` and ``h/2``, driven by one Brownian path per chain:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> averages = liesample.accuracy.coupled_ergodic_averages(
    ...     system, 3.0, lambda mu: mu**2, step_size=0.1, levels=2, rng_key=jax.random.key(0),
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]), total_time=2.0)
    >>> averages.step_sizes, averages.chain_means.shape  # (chains, levels, observables)
    ((0.1, 0.05), (2, 2, 3))
    """

    step_sizes: tuple[float, ...]
    chain_means: np.ndarray
    chain_square_means: np.ndarray
    nonfinite_steps: np.ndarray
    wall_time: float
    kept_time: float

    @property
    def tau_int(self) -> np.ndarray:
        """Integrated autocorrelation time in time units: chains × kept time / ESS."""
        with np.errstate(divide="ignore"):
            return self.num_chains * self.kept_time / self.ess


def _guarded(integrator, dynamics, mu, dt, dW):
    proposal = integrator(dynamics, mu, dt, dW)
    bad = ~jnp.all(jnp.isfinite(proposal))
    return jnp.where(bad, mu, proposal), bad


def _coupled_runner(system, integrator, levels, observables, scene, example):
    """Compiled ``(keys, starts, step_size, sigma, theta, num_total, num_burn) -> (means, squares,
    nonfinite)``; the scalars are traced, so one executable serves every step size and σ."""
    fine = 2 ** (levels - 1)
    m = system.num_noises
    num_obs = int(np.size(jax.eval_shape(observables, example)))

    def chain(key, start, step_size, sigma, theta, num_total, num_burn):
        dynamics = PoissonLangevin(system, sigma=sigma, theta=theta, scene=scene)
        fine_dt = step_size / fine

        def coarse_step(i, carry):
            mus, sums, squares, bad = carry
            dW = jnp.sqrt(fine_dt) * jax.random.normal(
                jax.random.fold_in(key, i), (fine, m), start.dtype
            )
            kept = i >= num_burn
            new_mus, new_sums, new_squares, new_bad = [], [], [], []
            for level in range(levels):
                blocks = dW.reshape(2**level, fine // 2**level, m).sum(1)
                dt = step_size / 2**level

                def sub(c, increment, dt=dt):
                    mu, total, square, count = c
                    mu, flag = _guarded(integrator, dynamics, mu, dt, increment)
                    value = jnp.ravel(observables(mu))
                    return (mu, total + value, square + value * value, count + flag), None

                zero = jnp.zeros(num_obs, start.dtype)
                (mu, total, square, count), _ = jax.lax.scan(
                    sub, (mus[level], zero, zero, jnp.int32(0)), blocks
                )
                new_mus.append(mu)
                new_sums.append(sums[level] + jnp.where(kept, total / 2**level, 0.0))
                new_squares.append(squares[level] + jnp.where(kept, square / 2**level, 0.0))
                new_bad.append(bad[level] + count)
            return (
                jnp.stack(new_mus),
                jnp.stack(new_sums),
                jnp.stack(new_squares),
                jnp.stack(new_bad),
            )

        zeros = jnp.zeros((levels, num_obs), start.dtype)
        carry = (jnp.stack([start] * levels), zeros, zeros, jnp.zeros(levels, jnp.int32))
        _, sums, squares, bad = jax.lax.fori_loop(0, num_total, coarse_step, carry)
        kept = num_total - num_burn
        return sums / kept, squares / kept, bad

    batched = jax.vmap(chain, in_axes=(0, 0, None, None, None, None, None))
    return jit(batched)


@functools.lru_cache(maxsize=16)
def _compiled_runner(system, integrator, levels, observables, scene, shape, dtype):
    """The compiled coupled runner, cached: repeated runs (pilots, refinements, a production
    run at the same level count) pay compilation once."""
    starts = jax.ShapeDtypeStruct(shape, jnp.dtype(dtype))
    runner = _coupled_runner(
        system, integrator, levels, observables, scene, jnp.zeros(shape[1:], dtype)
    )
    keys = jax.random.split(jax.random.key(0), shape[0])
    scalar = jax.ShapeDtypeStruct((), jnp.dtype(dtype))
    count = jax.ShapeDtypeStruct((), jnp.int32)
    return runner.lower(keys, starts, scalar, scalar, scalar, count, count).compile()


class _CoupledRun:
    """One compiled coupled runner for a system, integrator, level count and observables."""

    def __init__(self, system, beta, observables, integrator, levels, initial_positions):
        if not isinstance(system, LiePoissonSystem):
            raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
        if not callable(observables):
            raise TypeError(f"observables must be a callable μ ↦ array, got {observables!r}")
        self.system = system
        self.beta = beta
        self.integrator = get_integrator(integrator)
        self.levels = _positive_int("levels", levels)
        _, _, self.scene = make_dynamics(system, beta=beta, sigma=1.0)
        starts = _real_starts(initial_positions)
        if starts.ndim != len(system.event_shape) + 1 or starts.shape[0] < 2:
            raise ValueError(
                f"initial_positions must have shape (chains, *{system.event_shape}) with chains "
                f">= 2 (the standard errors come from independent chains), got "
                f"{tuple(starts.shape)}"
            )
        system.check_position(starts[0], "initial_positions[0]")
        self.starts = starts
        self.compiled = _compiled_runner(
            system,
            self.integrator,
            self.levels,
            observables,
            self.scene,
            tuple(starts.shape),
            str(starts.dtype),
        )

    def __call__(self, *, step_size, sigma, rng_key, total_time, burn_in) -> CoupledAverages:
        step_size = finite_float("step_size", step_size, positive=True)
        total_time = finite_float("total_time", total_time, positive=True)
        burn_in = finite_float("burn_in", burn_in, nonnegative=True)
        sigma, theta, scene = make_dynamics(self.system, beta=self.beta, sigma=sigma)
        if scene != self.scene:
            raise ValueError(f"sigma must be > 0 to sample exp(-beta*h), got {sigma}")
        num_total = max(1, round(total_time / step_size))
        num_burn = round(burn_in / step_size)
        if num_burn >= num_total:
            raise ValueError(f"burn_in ({burn_in}) must be shorter than total_time ({total_time})")
        keys = jax.random.split(prng_key(rng_key), self.starts.shape[0])
        dtype = self.starts.dtype
        args = (
            keys,
            self.starts,
            jnp.asarray(step_size, dtype),
            jnp.asarray(sigma, dtype),
            jnp.asarray(theta, dtype),
            jnp.asarray(num_total, jnp.int32),
            jnp.asarray(num_burn, jnp.int32),
        )
        begin = time.perf_counter()
        means, squares, bad = jax.block_until_ready(self.compiled(*args))
        wall = time.perf_counter() - begin
        return CoupledAverages(
            step_sizes=tuple(step_size / 2**level for level in range(self.levels)),
            chain_means=np.asarray(means),
            chain_square_means=np.asarray(squares),
            nonfinite_steps=np.asarray(bad),
            wall_time=wall,
            kept_time=(num_total - num_burn) * step_size,
        )


def coupled_ergodic_averages(
    system: LiePoissonSystem,
    beta: float,
    observables: Callable[[jax.Array], jax.Array],
    *,
    step_size: float,
    levels: int = 2,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    sigma: float = 1.0,
    initial_positions: ArrayLike,
    rng_key: PRNGKey,
    total_time: float,
    burn_in: float = 0.0,
) -> CoupledAverages:
    """Time averages of ``observables`` at ``step_size / 2^l``, ``l < levels``, on coupled paths.

    Each chain draws, per coarse step, ``2^(levels−1)`` Brownian increments of the finest step;
    level ``l`` advances with their sums over blocks of ``2^(levels−1−l)``, i.e. all levels see
    the same Brownian path. All effects are on (``θ = βσ²/2``), as in
    :func:`liesample.lie_poisson_langevin`. A step that produces NaN/inf is rejected and counted.
    With ``levels=1`` this is a plain run of independent chains.

    Parameters
    ----------
    observables : callable
        ``μ ↦`` array of shape ``(k,)``.
    initial_positions : array (chains, *event_shape)
        One start per chain (all on the orbit to be sampled), at least 2 chains.
    total_time, burn_in : float
        Physical time per chain, and the part of it (at the start) not averaged.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> averages = liesample.accuracy.coupled_ergodic_averages(
    ...     system, 3.0, lambda mu: mu**2, step_size=0.1, levels=2, rng_key=jax.random.key(0),
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]), total_time=2.0)
    >>> extrapolated = liesample.accuracy.richardson_romberg(
    ...     averages.chain_means[:, 0], averages.chain_means[:, 1], order=2, paired=True)
    >>> extrapolated.estimate.shape, int(averages.nonfinite_steps.sum())
    ((3,), 0)
    """
    rng_key = prng_key(rng_key)
    run = _CoupledRun(system, beta, observables, integrator, levels, initial_positions)
    return run(
        step_size=step_size, sigma=sigma, rng_key=rng_key, total_time=total_time, burn_in=burn_in
    )


@dataclass(frozen=True)
class ChainAverages(_IndependentChains):
    """Per-chain time averages of observables from any BlackJAX-style sampler.

    ``chain_means``/``chain_square_means`` have shape ``(chains, k)``; ``info_means`` holds the
    per-chain mean of each numeric ``info`` field (e.g. ``acceptance_rate``), shape
    ``(chains,)``; ``wall_time`` excludes compilation; ``num_steps`` are the averaged steps.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=0.05)
    >>> starts = jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]])
    >>> averages = liesample.accuracy.ergodic_averages(sampler, jax.random.key(0), starts,
    ...                                                lambda mu: mu**2, num_steps=100)
    >>> averages.chain_means.shape, averages.num_steps  # (chains, observables)
    ((2, 3), 100)
    """

    chain_means: np.ndarray
    chain_square_means: np.ndarray
    info_means: dict[str, np.ndarray]
    wall_time: float
    num_steps: int


def ergodic_averages(
    algorithm: SamplingAlgorithm,
    rng_key: PRNGKey,
    initial_positions: PyTree,
    observables: Callable[[Any], jax.Array],
    *,
    num_steps: int,
    num_warmup: int = 0,
    info_fields: Sequence[str] | None = None,
) -> ChainAverages:
    """Run independent vmapped chains of ``algorithm`` and keep only running sums.

    ``algorithm`` has ``init(position)`` and ``step(rng_key, state) -> (state, info)``
    (:func:`liesample.lie_poisson_langevin`, :func:`liesample.adjusted_lie_poisson`); step ``i``
    of chain ``c`` uses ``fold_in(key_c, i)``, or the sampler's noise blocks
    (:mod:`liesample.integrators.chain_loop`). Nothing per step is stored, so long runs of many
    chains fit in memory. The scalar ``info`` fields named in ``info_fields`` (default: all) are
    averaged over the kept steps; fields not asked for are not computed (XLA drops them).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> sampler = liesample.adjusted_lie_poisson(system, beta=3.0, step_size=0.2)
    >>> starts = jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]])
    >>> averages = liesample.accuracy.ergodic_averages(sampler, jax.random.key(0), starts,
    ...                                                lambda mu: mu**2, num_steps=100)
    >>> bool(jnp.allclose(averages.chain_means.sum(axis=1), 1.5**2))  # |μ|² stays on the orbit
    True
    """
    num_steps = _positive_int("num_steps", num_steps)
    num_warmup = _positive_int("num_warmup", num_warmup, low=0)
    starts = _real_starts(initial_positions)
    if starts.ndim < 1 or starts.shape[0] < 2:
        raise ValueError(
            f"initial_positions must have a leading chain axis with >= 2 chains, got "
            f"{tuple(starts.shape)}"
        )
    example_state = algorithm.init(starts[0])
    num_obs = int(np.size(jax.eval_shape(observables, starts[0])))
    _, example_info = jax.eval_shape(algorithm.step, jax.random.key(0), example_state)
    scalars = [name for name, value in example_info._asdict().items() if value.shape == ()]
    info_names = scalars if info_fields is None else list(info_fields)
    unknown = sorted(set(info_names) - set(scalars))
    if unknown:
        raise ValueError(f"info_fields {unknown} are not scalar info fields; have {scalars}")

    def chain(key, start):
        def update(i, state, info, carry):
            total, square, infos = carry
            value = jnp.ravel(observables(state.position))
            kept = i >= num_warmup
            info_values = jnp.asarray(
                [getattr(info, n).astype(total.dtype) for n in info_names], total.dtype
            )
            return (
                jnp.where(kept, total + value, total),
                jnp.where(kept, square + value * value, square),
                jnp.where(kept, infos + info_values, infos),
            )

        zero = jnp.zeros(num_obs, starts.dtype)
        carry = (zero, zero, jnp.zeros(len(info_names), starts.dtype))
        _, (total, square, infos) = run_steps(
            algorithm, key, algorithm.init(start), 0, num_warmup + num_steps, update, carry
        )
        return total / num_steps, square / num_steps, infos / num_steps

    keys = jax.random.split(prng_key(rng_key), starts.shape[0])
    run = jit(jax.vmap(chain)).lower(keys, starts).compile()
    begin = time.perf_counter()
    means, squares, infos = jax.block_until_ready(run(keys, starts))
    wall = time.perf_counter() - begin
    infos = np.asarray(infos)
    return ChainAverages(
        np.asarray(means),
        np.asarray(squares),
        {name: infos[:, i] for i, name in enumerate(info_names)},
        wall,
        num_steps,
    )
