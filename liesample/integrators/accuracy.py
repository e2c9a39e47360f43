"""Accuracy as a knob: ask for a bias tolerance, not a step size.

The unadjusted samplers' ergodic averages carry a discretisation bias ``A(h) − A(0) ≈ C h^q``
(``q`` → the integrator's weak order, ``liesample.integrators.INTEGRATORS[name].weak_order``,
as ``h → 0``). This module measures it instead of guessing:

- :func:`coupled_ergodic_averages` runs independent chains, each at several step sizes
  ``h, h/2, h/4, …`` driven by *the same* Brownian path (the coarse increments are sums of the
  fine ones), so that the differences ``A(h) − A(h/2)`` have a small variance; per-chain means
  make every standard error honest (the chains are independent);
- :func:`choose_step_size` turns short coupled pilots into a step size (and a noise strength
  ``σ``, which at fixed ``β`` trades mixing against stiffness) whose predicted bias is below a
  tolerance, allowing for pre-asymptotic slopes;
- :func:`richardson_romberg` combines averages at ``h`` and ``h/2``,
  ``(2^p A(h/2) − A(h)) / (2^p − 1)``, with its MCSE; :func:`richardson_romberg_run` does both
  runs, coupled;
- :func:`ergodic_averages` runs any BlackJAX-style sampler (unadjusted or
  :func:`liesample.adjusted_lie_poisson`) as vmapped chains keeping only running sums.

Without Lévy areas the schemes are strong order 1/2 under non-commuting noise, so coupled levels
drift apart by ``O(√h)``: the coupling shrinks the variance of the differences but
does not remove it; every SE here comes from the spread of
independent chains, coupling included.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, cast

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
from liesample.integrators.stability import stiffness

if TYPE_CHECKING:
    from blackjax.base import SamplingAlgorithm

__all__ = [
    "DEFAULT_RELATIVE_TOLERANCE",
    "ChainAverages",
    "CoupledAverages",
    "RichardsonRomberg",
    "StepSizeChoice",
    "choose_step_size",
    "coupled_ergodic_averages",
    "default_step_size",
    "ergodic_averages",
    "largest_accurate_stability_number",
    "linear_sd_bias",
    "richardson_romberg",
    "richardson_romberg_run",
    "warn_given_step",
]

# A difference counts as measured when it is at least this many standard errors from zero.
_RESOLVED_Z = 2.0
# The slope used to extrapolate the bias down is never taken below this (a flatter observed
# slope is noise or a regime far from asymptotic; the user should lower the pilot step sizes).
_MIN_SLOPE = 0.5

DEFAULT_RELATIVE_TOLERANCE = 0.05
"""Default bias tolerance of :func:`default_step_size`: ``|bias| ≤ 0.05 × posterior sd`` of each
observable (about 1/20 of the spread: well below the MCSE of runs with fewer than ~400 effective
draws)."""


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


# --------------------------------------------------------------------------- Richardson–Romberg


@dataclass(frozen=True)
class RichardsonRomberg:
    """``(2^p A(h/2) − A(h)) / (2^p − 1)`` per observable, with its MCSE and the inputs.

    Examples
    --------
    A bias ``C h²``: averages 1 at ``h`` and 0.75 at ``h/2`` extrapolate to ``2/3`` at ``h = 0``:

    >>> import numpy as np
    >>> from liesample.accuracy import richardson_romberg
    >>> result = richardson_romberg(np.array([[1.0], [1.0]]), np.array([[0.75], [0.75]]), order=2)
    >>> bool(np.allclose(result.estimate, 2 / 3)), result.order
    (True, 2.0)
    """

    estimate: np.ndarray
    mcse: np.ndarray
    order: float
    coarse: np.ndarray
    fine: np.ndarray
    coarse_mcse: np.ndarray
    fine_mcse: np.ndarray
    paired: bool
    wall_time: float = math.nan


def richardson_romberg(
    coarse: ArrayLike, fine: ArrayLike, order: float, *, paired: bool = False
) -> RichardsonRomberg:
    """Richardson–Romberg extrapolation of ergodic averages across step sizes ``h`` and ``h/2``.

    Parameters
    ----------
    coarse, fine : array (chains, k) or (chains,)
        Per-chain time averages at ``h`` and at ``h/2`` from independent chains.
    order : float
        The order ``p`` of the leading bias term (the integrator's ``weak_order``, or a
        measured slope); the combination cancels ``C h^p``.
    paired : bool
        ``True`` when chain ``c`` of both inputs was driven by the same Brownian path
        (:func:`coupled_ergodic_averages`): the MCSE then comes from the spread of the per-chain
        combinations (which includes the coupling's correlation). ``False``: the two runs are
        independent and their variances add.

    Examples
    --------
    A bias ``C h²``: averages 1 at ``h`` and 0.75 at ``h/2`` extrapolate to ``(4·0.75 − 1)/3``:

    >>> import numpy as np
    >>> from liesample.accuracy import richardson_romberg
    >>> result = richardson_romberg(np.array([[1.0], [1.0]]), np.array([[0.75], [0.75]]), order=2)
    >>> bool(np.allclose(result.estimate, 2 / 3))
    True
    """
    order = finite_float("order", order, positive=True)
    coarse = np.asarray(coarse, dtype=float)
    fine = np.asarray(fine, dtype=float)
    if coarse.ndim == 1:
        coarse, fine = coarse[:, None], fine[:, None] if fine.ndim == 1 else fine
    if coarse.ndim != 2 or fine.ndim != 2 or coarse.shape[1] != fine.shape[1]:
        raise ValueError(
            f"coarse and fine must be per-chain averages of shape (chains, k) with the same k, "
            f"got {coarse.shape} and {fine.shape}"
        )
    if min(coarse.shape[0], fine.shape[0]) < 2:
        raise ValueError("coarse and fine need at least 2 chains each (for the MCSE)")
    if paired and coarse.shape != fine.shape:
        raise ValueError(f"paired runs need the same shape, got {coarse.shape} and {fine.shape}")
    weight = 2.0**order
    se_coarse = coarse.std(0, ddof=1) / math.sqrt(coarse.shape[0])
    se_fine = fine.std(0, ddof=1) / math.sqrt(fine.shape[0])
    if paired:
        combined = (weight * fine - coarse) / (weight - 1.0)
        estimate = combined.mean(0)
        mcse = combined.std(0, ddof=1) / math.sqrt(combined.shape[0])
    else:
        estimate = (weight * fine.mean(0) - coarse.mean(0)) / (weight - 1.0)
        mcse = np.hypot(weight * se_fine, se_coarse) / (weight - 1.0)
    return RichardsonRomberg(
        estimate, mcse, order, coarse.mean(0), fine.mean(0), se_coarse, se_fine, paired
    )


def richardson_romberg_run(
    system: LiePoissonSystem,
    beta: float,
    observables: Callable[[jax.Array], jax.Array],
    *,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    order: float | None = None,
    **run_options: Any,
) -> RichardsonRomberg:
    """Run coupled chains at ``step_size`` and ``step_size/2`` and extrapolate.

    ``order`` defaults to the integrator's declared weak order. ``run_options`` (``step_size``,
    ``initial_positions``, ``rng_key``, ``total_time``, and optionally ``burn_in``, ``sigma``)
    are those of :func:`coupled_ergodic_averages`.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> result = liesample.accuracy.richardson_romberg_run(
    ...     system, 3.0, lambda mu: mu**2, step_size=0.1, rng_key=jax.random.key(0),
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]), total_time=2.0)
    >>> result.estimate.shape, result.order  # the splitting scheme's weak order
    ((3,), 2.0)
    """
    integrator = get_integrator(integrator)
    averages = coupled_ergodic_averages(
        system, beta, observables, levels=2, integrator=integrator, **run_options
    )
    result = richardson_romberg(
        averages.chain_means[:, 0],
        averages.chain_means[:, 1],
        integrator.weak_order if order is None else order,
        paired=True,
    )
    return RichardsonRomberg(**{**result.__dict__, "wall_time": averages.wall_time})


# --------------------------------------------------------------------------- step-size choice


@dataclass(frozen=True)
class StepSizeChoice:
    """The step size (and σ) :func:`choose_step_size` picked, and the evidence for it.

    Attributes
    ----------
    step_size, sigma, integrator : what to pass to :func:`liesample.lie_poisson_langevin`.
    tolerance : the requested absolute bound on ``|bias|`` of every observable (or ``None``).
    relative_tolerance : the requested bound in posterior sd (or ``None``).
    tolerances : array (k,), the absolute bound applied per observable (``inf``: not bounded).
    predicted_bias_bound : array (k,)
        Upper bound (2 SE) on ``|bias|`` at ``step_size`` from the model ``C h^q``.
    slope : array (k,)
        The exponent ``q`` used per observable: ``min(observed, weak order)`` when the pilot
        resolved the slope, else the weak order.
    steps_per_effective_sample : float
        Predicted cost: ``max_k τ_int,k / step_size`` (τ from the finest pilot).
    candidates : list of dict
        Per σ tried: its step size, bounds, slopes, τ and cost.
    pilot_wall_time : float
        Seconds spent in pilots (compilation excluded).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.default_step_size(system, 3.0)  # pilots, then the bias model
    >>> choice.integrator, choice.relative_tolerance, bool(choice.step_size > 0)
    ('splitting', 0.05, True)
    """

    step_size: float
    sigma: float
    integrator: str
    tolerance: float | None
    predicted_bias_bound: np.ndarray
    slope: np.ndarray
    steps_per_effective_sample: float
    candidates: list[dict[str, Any]] = field(default_factory=list)
    pilot_wall_time: float = 0.0
    relative_tolerance: float | None = None
    tolerances: np.ndarray | None = None

    def sampler_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for :func:`liesample.lie_poisson_langevin` (with ``beta``)."""
        return {"step_size": self.step_size, "sigma": self.sigma, "integrator": self.integrator}


def _tolerances(averages: CoupledAverages, tolerance, relative_tolerance):
    """Per-observable absolute tolerances, and the averages the bias model is applied to.

    Absolute: ``tolerance`` on each observable's mean. Relative: ``relative_tolerance × sd`` on
    each mean and ``2 × relative_tolerance × variance`` on each variance (so the sd is within
    ``relative_tolerance`` of itself), the variance taken per chain (``E[f²] − E[f]²`` of its
    time averages: coupled levels share its finite-time bias, which cancels in the
    differences) and the stationary sd from the finest level. Observables constant to
    round-off are not bounded (``inf``). Returns ``(tolerances, averages)``.
    """
    if relative_tolerance is None:
        return np.full(averages.chain_means.shape[-1], tolerance), averages
    means = averages.chain_means
    variances = np.maximum(averages.chain_square_means - means**2, 0.0)
    finest = means[:, -1].mean(0)
    variance = np.maximum(averages.chain_square_means[:, -1].mean(0) - finest**2, 0.0)
    sd = np.sqrt(variance)
    constant = sd <= 1e-7 * (np.abs(finest) + np.max(sd, initial=0.0) + 1e-300)
    tolerances = np.concatenate(
        [
            np.where(constant, np.inf, relative_tolerance * sd),
            np.where(constant, np.inf, 2.0 * relative_tolerance * variance),
        ]
    )
    augmented = replace(averages, chain_means=np.concatenate([means, variances], axis=-1))
    return tolerances, augmented


def _bias_model(averages: CoupledAverages, weak_order: float, tolerance: float):
    """Step size meeting ``tolerance`` from three coupled levels ``h, h/2, h/4``.

    ``D₁ = A(h) − A(h/2)``, ``D₂ = A(h/2) − A(h/4)`` (per-chain, so their SEs include the
    coupling). Under ``b(h) = C h^q``: ``D₁/D₂ = 2^q`` and ``b(h/4) = D₂/(2^q − 1)``. The slope
    is ``min(observed, weak order)`` when both differences are resolved with the same sign (a
    pre-asymptotic slope below the order steepens as ``h`` falls, one above it flattens, so the
    smaller is the cautious one), else the weak order. The bias bound at ``h/4`` uses
    ``|D₂| + 2 SE(D₂)``, and then ``h* = (h/4) (tolerance / bound)^{1/q}``, capped at ``h``.
    """
    means = averages.chain_means
    d1 = means[:, 0] - means[:, 1]
    d2 = means[:, 1] - means[:, 2]
    n = means.shape[0]
    m1, s1 = d1.mean(0), d1.std(0, ddof=1) / math.sqrt(n)
    m2, s2 = d2.mean(0), d2.std(0, ddof=1) / math.sqrt(n)
    resolved = (np.abs(m1) > _RESOLVED_Z * s1) & (np.abs(m2) > _RESOLVED_Z * s2) & (m1 * m2 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        observed = np.where(resolved, np.log2(np.abs(m1 / m2)), np.nan)
    slope = np.where(resolved, np.clip(observed, _MIN_SLOPE, weak_order), weak_order)
    finest = averages.step_sizes[2]
    bound = (np.abs(m2) + _RESOLVED_Z * s2) / (2.0**slope - 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.nan_to_num(finest * (tolerance / bound) ** (1.0 / slope), nan=np.inf)
    step = float(min(np.min(steps), averages.step_sizes[0]))
    predicted = bound * (step / finest) ** slope
    return step, predicted, slope, observed, (m1, s1, m2, s2)


def choose_step_size(
    system: LiePoissonSystem,
    beta: float,
    tolerance: float | None = None,
    *,
    relative_tolerance: float | None = None,
    observables: Callable[[jax.Array], jax.Array],
    initial_positions: ArrayLike,
    rng_key: PRNGKey,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    sigmas: Sequence[float] = (1.0,),
    pilot_step_size: float = 0.4,
    pilot_time: float = 50.0,
    burn_in: float = 5.0,
    max_refinements: int = 2,
) -> StepSizeChoice:
    """Pick the step size (and σ) whose bias on every observable is at most ``tolerance``
    (absolute) or ``relative_tolerance`` × its posterior sd.

    For each σ in ``sigmas``, one coupled pilot (:func:`coupled_ergodic_averages`, levels
    ``h, h/2, h/4`` with ``h = pilot_step_size / σ²``: noise and dissipation scale with
    ``σ² dt``) measures the differences between levels; the
    bias model ``C h^q`` (see :func:`_bias_model`: ``q`` the integrator's weak order, or the
    observed slope where it is smaller) gives the largest step with predicted
    ``|bias| ≤ tolerance`` (never larger than the pilot's). Among the σ, the one with the fewest
    steps per effective sample (``max_k τ_int,k / h*``, τ from the finest level) wins.

    Parameters
    ----------
    tolerance : float, optional
        Bound on the absolute bias of each observable (> 0). The statistical error of the
        production run comes on top; size the run for it.
    relative_tolerance : float, optional
        Bound on the bias of each observable relative to its stationary standard deviation
        (measured on the pilot's finest level); observables constant to round-off are not
        bounded; the variance of each observable is bounded too (by ``2 × relative_tolerance ×
        variance``, i.e. its sd is within ``relative_tolerance`` of itself), so the arrays of
        the result list the means' entries, then the variances'. Give this or ``tolerance``;
        with neither,
        :data:`DEFAULT_RELATIVE_TOLERANCE` (0.05 sd) applies.
    rng_key : jax.random.key or jax.random.PRNGKey
    observables : callable
        ``μ ↦`` array (k,): the expectations that must be accurate.
    initial_positions : array (chains, *event_shape)
        Starts of the pilot chains (≥ 2; a few hundred give a usable bias constant).
    sigmas : sequence of float
        Noise strengths to try (each > 0).
    pilot_step_size, pilot_time, burn_in : float
        The coarsest pilot step at ``σ = 1`` (divided by ``σ²`` for other σ), and the pilot's
        physical time and discarded start per chain.
    max_refinements : int
        When the chosen step is below half the pilot's finest step, the pilot is repeated
        closer to it (coarse step ``max(4 h*, h/8)``), at most this many times: a slope
        measured at larger steps is not trusted over a range it was not seen on.

    Returns
    -------
    StepSizeChoice

    Examples
    --------
    A short pilot (a real one runs longer: ``pilot_time=50``) for a bias of at most 0.1
    posterior sd in each coordinate of ``μ``:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.choose_step_size(
    ...     system, 3.0, relative_tolerance=0.1, observables=lambda mu: mu,
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]),
    ...     rng_key=jax.random.key(0), pilot_time=2.0, burn_in=0.5)
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=choice.step_size,
    ...                                          sigma=choice.sigma, integrator=choice.integrator)
    """
    if tolerance is not None and relative_tolerance is not None:
        raise ValueError("give tolerance (absolute) or relative_tolerance, not both")
    if tolerance is None and relative_tolerance is None:
        relative_tolerance = DEFAULT_RELATIVE_TOLERANCE
    if tolerance is not None:
        tolerance = finite_float("tolerance", tolerance, positive=True)
    else:
        relative_tolerance = finite_float("relative_tolerance", relative_tolerance, positive=True)
    rng_key = prng_key(rng_key)
    integrator = get_integrator(integrator)
    if np.ndim(sigmas) != 1 or len(sigmas) < 1:
        raise ValueError(f"sigmas must be a non-empty sequence of floats > 0, got {sigmas!r}")
    sigmas = [finite_float(f"sigmas[{i}]", s, positive=True) for i, s in enumerate(sigmas)]
    pilot_step_size = finite_float("pilot_step_size", pilot_step_size, positive=True)
    pilot_time = finite_float("pilot_time", pilot_time, positive=True)
    burn_in = finite_float("burn_in", burn_in, nonnegative=True)
    max_refinements = _positive_int("max_refinements", max_refinements, low=0)
    run = _CoupledRun(system, beta, observables, integrator, 3, initial_positions)
    candidates, wall = [], 0.0
    for i, sigma in enumerate(sigmas):
        # Noise and dissipation scale with σ²·dt: the same stiffness at every σ.
        coarse = pilot_step_size / sigma**2
        pilots = []
        for attempt in range(max_refinements + 1):
            pilot = run(
                step_size=coarse,
                sigma=sigma,
                rng_key=jax.random.fold_in(jax.random.fold_in(rng_key, i), attempt),
                total_time=pilot_time,
                burn_in=burn_in,
            )
            wall += pilot.wall_time
            tolerances, modelled = _tolerances(pilot, tolerance, relative_tolerance)
            step, predicted, slope, observed, (m1, s1, m2, s2) = _bias_model(
                modelled, integrator.weak_order, tolerances
            )
            pilots.append(
                {
                    "pilot_step_size": coarse,
                    "step_size": step,
                    "observed_slope": observed,
                    "difference_coarse": m1,
                    "difference_coarse_se": s1,
                    "difference_fine": m2,
                    "difference_fine_se": s2,
                    "wall_time": pilot.wall_time,
                }
            )
            # Far below the pilot's finest step, the extrapolation spans a range whose slope
            # was not seen: measure again closer to the candidate (at most 8× lower per round).
            if step >= 0.5 * pilot.step_sizes[2] or attempt == max_refinements:
                break
            coarse = max(4.0 * step, coarse / 8.0)
        tau = pilot.tau_int[2]
        candidates.append(
            {
                "sigma": sigma,
                "step_size": step,
                "predicted_bias_bound": predicted,
                "slope": slope,
                "observed_slope": observed,
                "tau_int": tau,
                "steps_per_effective_sample": float(np.max(tau) / step),
                "nonfinite_steps": int(pilot.nonfinite_steps.sum()),
                "tolerances": tolerances,
                "pilots": pilots,
            }
        )
    best = min(candidates, key=lambda c: c["steps_per_effective_sample"])
    return StepSizeChoice(
        step_size=best["step_size"],
        sigma=best["sigma"],
        integrator=integrator.name,
        tolerance=tolerance,
        relative_tolerance=relative_tolerance,
        tolerances=best["tolerances"],
        predicted_bias_bound=best["predicted_bias_bound"],
        slope=best["slope"],
        steps_per_effective_sample=best["steps_per_effective_sample"],
        candidates=candidates,
        pilot_wall_time=wall,
    )


# --------------------------------------------------------------------------- default step size

_PILOT_CHAINS = 16
_PILOT_COARSE_STEPS = 2000
_MAX_PILOT_TIME = 50.0


def _coordinates(mu):
    return jnp.ravel(mu)


def default_step_size(
    system: LiePoissonSystem,
    beta: float,
    *,
    sigma: float = 1.0,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    initial_positions: ArrayLike | None = None,
    rng_key: PRNGKey | None = None,
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
) -> StepSizeChoice:
    """The step size :func:`liesample.lie_poisson_langevin` uses when none is given.

    :func:`choose_step_size` on the coordinates of ``μ`` with ``relative_tolerance`` (bias at
    most 0.05 posterior sd by default), with pilots scaled to the problem: the coarsest pilot
    step is ``min(0.4/σ², 1/s)`` with ``s = θ·max_i|h''_i|`` the stiffness on the orbit
    (:mod:`liesample.integrators.stability`), i.e. half the stability bound ``κ ≤ 2``, so every
    level of the pilot and the chosen step are stable; the pilot runs ``min(50, 2000 h)`` time units
    (10 % burn-in) on 16 chains started from ``initial_positions`` (cycled; default: the
    system's default position), ``rng_key`` default ``jax.random.key(0)``.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.default_step_size(system, 3.0)
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=choice.step_size)
    >>> choice.relative_tolerance  # the bias bound, in posterior sd
    0.05
    """
    integrator = get_integrator(integrator)
    sigma, theta, _ = make_dynamics(system, beta=beta, sigma=sigma)
    if initial_positions is None:
        initial_positions = np.asarray(system.default_position)[None]
    starts = np.asarray(initial_positions, dtype=float)
    if starts.ndim != len(system.event_shape) + 1 or starts.shape[0] < 1:
        raise ValueError(
            f"initial_positions must have shape (chains, *{tuple(system.event_shape)}), got "
            f"{starts.shape}"
        )
    starts = starts[np.arange(_PILOT_CHAINS) % starts.shape[0]]
    stiff = max(
        stiffness(system, theta, start) if system.curvature_bound else 0.0
        for start in _distinct(starts)
    )
    coarse = 0.4 / sigma**2 if stiff == 0.0 else min(0.4 / sigma**2, 1.0 / stiff)
    pilot_time = min(_MAX_PILOT_TIME, _PILOT_COARSE_STEPS * coarse)
    return choose_step_size(
        system,
        beta,
        relative_tolerance=relative_tolerance,
        observables=_coordinates,
        initial_positions=starts,
        rng_key=jax.random.key(0) if rng_key is None else rng_key,
        integrator=integrator,
        sigmas=(sigma,),
        pilot_step_size=coarse * sigma**2,
        pilot_time=pilot_time,
        burn_in=0.1 * pilot_time,
    )


def _distinct(starts):
    _, first = np.unique(starts.reshape(len(starts), -1), axis=0, return_index=True)
    return starts[np.sort(first)]


# --------------------------------------------------------------------------- a given step's bias

# The step of each built-in scheme on the scalar Ornstein-Uhlenbeck equation
# dφ = −λφ dt + σ dW, with z = λ dt: φ' = R(z) φ + b(z) σ ΔW (Heun feeds one increment to both
# stages; every piece of ``splitting`` is Heun along one noise direction).
_LINEAR_STEPS = {
    "lie_euler": lambda z: (1.0 - z, 1.0),
    "rkmk_heun": lambda z: (1.0 - z + 0.5 * z * z, 1.0 - 0.5 * z),
    "splitting": lambda z: (1.0 - z + 0.5 * z * z, 1.0 - 0.5 * z),
}


def linear_sd_bias(integrator: str | Integrator, stability_number: float) -> float | None:
    """The relative error of the stationary sd along the stiffest noise direction, from the
    linearised dynamics at the stability number ``κ = step_size·θ·max|h''|``
    (:mod:`liesample.integrators.stability`): no pilot run, one formula.

    Along one noise direction the SDE linearises to ``dφ = −λφ dt + σ dW`` with ``λ = θ h''``
    (the stability module's derivation), whose law is ``N(0, σ²/2λ)``. A scheme's step there is
    ``φ' = R(κ) φ + b(κ) σ ΔW``, whose stationary variance is ``b² σ² dt / (1 − R²)``; the ratio
    to the exact one is ``2κ b² / (1 − R²)`` (Heun, ``splitting``'s pieces:
    ``(2 − κ)/(2 − κ + κ²/2)``, sd too small; Lie–Euler: ``2/(2 − κ)``, too large). At the
    stiffest direction this is the largest error a near-Gaussian law sees; it leaves out what
    the linear model cannot see (the Hamiltonian drift, non-commuting noise directions, a
    far-from-Gaussian law), so it indicates a given step's accuracy, it does not certify it.

    Returns ``sqrt(ratio) − 1`` (e.g. ``-0.1``: 10 % too small), ``None`` for an integrator
    without a declared linear step (``euler_heun``, user schemes) or ``κ`` outside
    ``[0, stability limit)``; ``0`` for ``κ < 1e-6`` (a flat direction: the isotropic body).

    Examples
    --------
    Lie–Euler at ``κ = 1``: the sd ratio is ``√(2/(2 − κ)) = √2``, 41 % too large:

    >>> import numpy as np
    >>> from liesample.accuracy import linear_sd_bias
    >>> bool(np.isclose(linear_sd_bias("lie_euler", 1.0), np.sqrt(2) - 1))
    True
    >>> linear_sd_bias("splitting", 0.0), linear_sd_bias("euler_heun", 1.0)  # flat; no model
    (0.0, None)
    """
    integrator = get_integrator(integrator)
    linear = _LINEAR_STEPS.get(integrator.name)
    limit = integrator.stability_limit
    kappa = float(stability_number)
    if linear is None or limit is None or not 0.0 <= kappa < limit:
        return None
    if kappa < 1e-6:  # |error| < κ/4 is below any tolerance, and 1 − R² would round to 0
        return 0.0
    r, b = linear(kappa)
    return math.sqrt(2.0 * kappa * b * b / (1.0 - r * r)) - 1.0


def largest_accurate_stability_number(
    integrator: str | Integrator, tolerance: float
) -> float | None:
    """The largest ``κ`` at which :func:`linear_sd_bias` is within ``tolerance`` (bisection; the
    error grows with ``κ``), ``None`` where the integrator has no linear model.

    Examples
    --------
    >>> from liesample.accuracy import largest_accurate_stability_number, linear_sd_bias
    >>> kappa = largest_accurate_stability_number("splitting", 0.05)
    >>> bool(0 < kappa < 2), bool(abs(linear_sd_bias("splitting", kappa)) <= 0.05 + 1e-9)
    (True, True)
    """
    integrator = get_integrator(integrator)
    if integrator.name not in _LINEAR_STEPS or integrator.stability_limit is None:
        return None
    low, high = 0.0, integrator.stability_limit
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (
            (middle, high)
            if abs(cast(float, linear_sd_bias(integrator, middle))) <= tolerance  # has a model
            else (
                low,
                middle,
            )
        )
    return low


def warn_given_step(
    integrator: str | Integrator, step_size: float, stability_number: float, tolerance: float
) -> float | None:
    """:func:`linear_sd_bias` of a given step, with a ``UserWarning`` naming a step within
    ``tolerance`` (and the other ways out) when its magnitude exceeds ``tolerance``.

    Examples
    --------
    >>> import warnings
    >>> from liesample.accuracy import warn_given_step
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     bias = warn_given_step("lie_euler", 0.1, stability_number=1.0, tolerance=0.05)
    >>> "41% too large" in str(caught[0].message)
    True
    """
    bias = linear_sd_bias(integrator, stability_number)
    if bias is None or abs(bias) <= tolerance:
        return bias
    accurate = cast(float, largest_accurate_stability_number(integrator, tolerance))  # has a model
    warnings.warn(
        f"step_size={step_size:.4g} (given) has the stability number κ = "
        f"{stability_number:.3g}: linearised along the stiffest noise direction, the "
        f"{get_integrator(integrator).name} scheme's stationary sd is "
        f"{abs(bias):.0%} too {'small' if bias < 0 else 'large'}, beyond bias_tolerance="
        f"{tolerance:g} (liesample.integrators.accuracy.linear_sd_bias; the law's own error "
        f"is often smaller, but not within the tolerance by any guarantee). Use step_size <= "
        f"{step_size * accurate / stability_number:.3g} (κ <= {accurate:.3g}), leave step_size "
        "unset for the bias model's choice, or use liesample.adjusted_lie_poisson (exact at "
        "any step)",
        UserWarning,
        stacklevel=4,
    )
    return bias
