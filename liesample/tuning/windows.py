"""Stan's window adaptation as an instance of the adaptation protocol: step size, mass,
trajectory length and field, tuned together on one batch of chains.

:func:`windows_adaptation` composes the pieces into one
:class:`liesample.tuning.protocol.Adaptation` from what a sampler is read by
(:class:`Windows`):

- the step size: dual averaging of the chains' pooled rate
  (:func:`liesample.tuning.protocol.step_size_adaptation`), restarted from its average at the
  end of each slow window when the mass is adapted; pooled as ``Windows.pooling`` says
  (:func:`liesample.tuning.protocol.pooled_rate`): the harmonic rule, which lowers the step
  until a stuck chain moves (:func:`liesample.window_adaptation` and
  :func:`liesample.magnetic_window_adaptation`), or (``"harmonic_then_median"``, the NumPyro
  kernel's) that rule in the initial fast window only and the median of the chains' running
  rates after it, so that a minority of chains that fall into a region no step of the
  others' size moves in (a degenerate mode of a mixture, the neck of a funnel) cannot lower
  the step of the rest: those chains are named after the warm-up
  (:func:`liesample.tuning.protocol.odd_chains`);
- the mass: Welford moments of a statistic of the chains' states (pooled over the chains) in
  the slow windows, turned into the inverse mass at each window's end (``mass_from``);
  optionally dense blocks (:class:`DenseBlocks`: the pooled Welford covariance of some
  ``Euclidean`` blocks, shrunk as Stan does);
- the trajectory length of HMC (:mod:`liesample.tuning.trajectory`): each transition integrates
  ``L = ceil(u T / ε)`` steps, ``u`` the base-2 Halton point of its index, and ``T`` is learnt by
  the ChEES-type rule (or fixed); or a fixed ``L``;
- a magnetic field derived from the current mass and step (``extra``).

:func:`liesample.window_adaptation`, :func:`liesample.magnetic_window_adaptation` (both through
:func:`liesample.tuning.protocol.run_adaptation`) and the NumPyro kernel
(:class:`liesample.interop.numpyro_kernel.GeometricHMC`, one ``update`` per NumPyro iteration)
all tune with it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.types import TreeDef
from liesample.geometry import spaces
from liesample.tuning.protocol import (
    Adaptation,
    StepSizeState,
    restart_step_size,
    step_size_adaptation,
)
from liesample.tuning.trajectory import (
    MAX_NUM_INTEGRATION_STEPS,
    TrajectoryAdaptation,
    halton,
    jittered_steps,
)

__all__ = [
    "FAR_APART",
    "DenseBlocks",
    "WindowState",
    "Windows",
    "far_adapted",
    "inverse_mass",
    "regularised_variance",
    "statistic",
    "welford_batch",
    "windows_adaptation",
]


def statistic(space, state):
    """Flat vector whose Welford moments give the mass: positions of Euclidean blocks, the
    trivialised gradient of the others (one chain's state)."""
    leaves = spaces._map(
        lambda s, x, g: jnp.ravel(x if not s.compact else g),
        space,
        state.position,
        state.logdensity_grad,
    )
    return jnp.concatenate(jax.tree.leaves(leaves))


def regularised_variance(variance, count):
    """Stan's diagonal inverse mass from ``count`` draws: shrunk towards ``1e-3``."""
    return (count / (count + 5.0)) * variance + 1e-3 * (5.0 / (count + 5.0))


def inverse_mass(space, mean, m2, count):
    """Inverse mass (pytree like ``space``) from Welford moments of :func:`statistic`:
    Euclidean blocks the regularised variance of the position, compact ones
    ``1 / (E[(X_k log π)²] + 1)`` (:mod:`liesample.tuning.adaptation`)."""
    variance = m2 / jnp.maximum(count - 1, 1)
    n = count.astype(mean.dtype)
    out, offset = [], 0
    for s in spaces._spaces(space):
        size = math.prod(s.momentum_array_shape)
        var = variance[offset : offset + size].reshape(s.momentum_array_shape)
        mu = mean[offset : offset + size].reshape(s.momentum_array_shape)
        offset += size
        if not s.compact:
            out.append(regularised_variance(var, n))
            continue
        squared = var + mu**2
        if s.mass_shape == (1,):
            squared = jnp.sum(squared, -1, keepdims=True) / s.copy_dimension
        out.append(1.0 / (squared + 1.0))
    structure: TreeDef = jax.tree.structure(space, is_leaf=spaces.is_space)
    return structure.unflatten(out)


def welford_batch(welford, x):
    """Chan et al.'s update of ``(mean, m2, count)`` with a batch ``x`` of shape ``(n, d)``;
    ``m2`` a vector (diagonal) or a matrix (dense: the batch's outer products)."""
    mean, m2, count = welford
    n = x.shape[0]
    batch_mean = jnp.mean(x, 0)
    centred = x - batch_mean
    total = count + n
    delta = batch_mean - mean
    new_mean = mean + delta * (n / total)
    if jnp.ndim(m2) == 2:
        batch_m2 = centred.T @ centred
        spread = jnp.outer(delta, delta)
    else:
        batch_m2 = jnp.sum(centred**2, 0)
        spread = delta**2
    return new_mean, m2 + batch_m2 + spread * (count * n / total), total


class DenseBlocks(NamedTuple):
    """Dense inverse masses: ``keys`` of the blocks of the sampler's (dict) position whose
    ``M⁻¹`` is a matrix (``Euclidean`` vectors), adapted to their pooled Welford covariance."""

    keys: tuple


class Windows(NamedTuple):
    """What :func:`windows_adaptation` reads from its sampler.

    target, rate_field : dual averaging's target and the info field it reads
        (``metropolis_rate`` for the T*G samplers, ``acceptance_rate`` for magnetic HMC).
    statistic : ``states (chains first) -> (chains, k)``, whose moments give the mass.
    mass_from : ``(mean, m2, count) -> inverse mass`` (the diagonal part).
    adapt_mass : whether the mass is adapted.
    lengths : a :class:`liesample.tuning.trajectory.TrajectoryAdaptation` (HMC with ``L``
        jittered), or ``None`` (a fixed ``L``, or not HMC).
    move : ``(before, after, infos, inverse_mass) -> ChainMove`` for ``lengths``.
    dimension : the coordinates ``lengths`` reads.
    fixed_steps : ``L`` when fixed (HMC), else ``None``.
    max_steps : the cap on ``L``.
    extra : ``(row, step_size, inverse_mass) -> dict`` of further parameters (the field), or
        ``None``.
    dense : :class:`DenseBlocks` or ``None``.
    jitter : ``L = ceil(u T / ε)`` with ``u`` the Halton point (default), else ``u = 1``.
    step_size : a step size kept fixed (not adapted), or ``None``.
    pooling : how the chains' rates are pooled
        (:func:`liesample.tuning.protocol.step_size_adaptation`): ``"harmonic"`` (default: a
        stuck chain lowers the step until it moves), ``"harmonic_then_median"`` (stuck starts
        freed, then a minority cannot move the step) or ``"median"``.
    """

    target: float
    rate_field: str
    statistic: Callable
    mass_from: Callable
    adapt_mass: bool = True
    lengths: TrajectoryAdaptation | None = None
    move: Callable | None = None
    dimension: int = 0
    fixed_steps: int | None = None
    max_steps: int = MAX_NUM_INTEGRATION_STEPS
    extra: Callable | None = None
    dense: DenseBlocks | None = None
    jitter: bool = True
    step_size: float | None = None
    pooling: str = "harmonic"


class WindowState(NamedTuple):
    """The adaptation state: the step's, the current inverse mass, the window's Welford moments
    ``(mean, m2, count)`` (and each dense block's), the trajectory rule's state (or ``None``)."""

    step: StepSizeState
    inverse_mass: object
    welford: tuple
    dense: dict
    length: object


def _zeroed(welford):
    mean, m2, count = welford
    return jnp.zeros_like(mean), jnp.zeros_like(m2), 0 * count


def _shrunk(mean, m2, count):
    """The dense inverse mass: the Welford covariance ``Σ`` shrunk as Stan does, by the weight
    ``5/(n + 5)`` towards ``1e-3`` times a diagonal, but the diagonal of ``Σ`` itself (``1``
    where a coordinate did not move), not ``I``: the shrinkage then does not depend on the
    coordinates' units. Towards ``1e-3 I`` it would swamp the narrow direction of two
    correlated coordinates of small scale (a slope whose sd is ``1e-2`` or less, correlated
    with its intercept near ``−1``), and the mass would whiten nothing there."""
    n = count.astype(mean.dtype)
    covariance = m2 / jnp.maximum(n - 1.0, 1.0)
    covariance = 0.5 * (covariance + covariance.T)
    variance = jnp.diagonal(covariance)
    target = jnp.diag(jnp.where(variance > 0, variance, 1.0))
    return (n / (n + 5.0)) * covariance + 1e-3 * (5.0 / (n + 5.0)) * target


def windows_adaptation(w: Windows) -> Adaptation:
    """The window adaptation of ``w`` (module docstring) in the protocol's shape. ``init``
    reads ``parameters["step_size"]`` and ``parameters["inverse_mass_matrix"]`` (dense blocks:
    matrices); ``current`` gives ``step_size``, ``inverse_mass_matrix``,
    ``num_integration_steps`` (HMC), ``integration_time`` (the ``T`` jittered, with
    ``lengths``) and ``extra``'s; ``final`` gives ``step_size``,
    ``inverse_mass_matrix`` and ``integration_time`` (with ``lengths``)."""
    step = step_size_adaptation(w.target, w.rate_field, pooling=w.pooling)
    dense_keys = () if w.dense is None else w.dense.keys

    def init(states, parameters):
        x = w.statistic(states)
        zero = jnp.zeros(x.shape[-1], x.dtype)
        dense = {}
        for key in dense_keys:
            y = states.position[key]
            dense[key] = (y[0] * 0, jnp.zeros((y.shape[-1],) * 2, y.dtype), jnp.asarray(0))
        length = None if w.lengths is None else w.lengths.init(w.dimension, x.dtype)
        mass = parameters["inverse_mass_matrix"]
        welford = (zero, zero, jnp.asarray(0))
        return WindowState(step.init(states, parameters), mass, welford, dense, length)

    def step_size_of(parameters):
        if w.step_size is not None:
            return jnp.asarray(w.step_size, parameters["step_size"].dtype)
        return parameters["step_size"]

    def current(state, row):
        step_size = step_size_of(step.current(state.step))
        out = {"step_size": step_size, "inverse_mass_matrix": state.inverse_mass}
        if w.fixed_steps is not None:
            out["num_integration_steps"] = jnp.asarray(w.fixed_steps)
        elif w.lengths is not None:
            time = jnp.exp(state.length.log_time)
            out["integration_time"] = time
            u = halton(row.index) if w.jitter else 1.0
            out["num_integration_steps"] = jittered_steps(u, time, step_size, w.max_steps)
        if w.extra is not None:
            out.update(w.extra(row, step_size, state.inverse_mass))
        return out

    def update(state, row, parameters, before, after, infos):
        new_step = cast(Callable, step.update)(state.step, row, parameters, before, after, infos)
        length = state.length
        if w.lengths is not None:
            move = cast(Callable, w.move)(before, after, infos, parameters["inverse_mass_matrix"])
            length = w.lengths.update(
                length, move, parameters["step_size"], parameters["num_integration_steps"],
                row.average,
            )  # fmt: skip
        slow = (row.stage == 1) & w.adapt_mass
        keep = lambda new, old: jax.tree.map(lambda a, b: jnp.where(slow, a, b), new, old)
        welford = keep(welford_batch(state.welford, w.statistic(after)), state.welford)
        dense = {
            key: keep(welford_batch(moments, after.position[key]), moments)
            for key, moments in state.dense.items()
        }
        state = WindowState(new_step, state.inverse_mass, welford, dense, length)
        if not w.adapt_mass:
            return state
        return jax.lax.cond(row.window_end, close, lambda state: state, state)

    def close(state):
        mass = dict(w.mass_from(*state.welford)) if dense_keys else w.mass_from(*state.welford)
        for key, moments in state.dense.items():
            mass[key] = _shrunk(*moments)
        dense = {key: _zeroed(moments) for key, moments in state.dense.items()}
        restarted = restart_step_size(state.step, w.target)
        return WindowState(restarted, mass, _zeroed(state.welford), dense, state.length)

    def final(state):
        out = {"step_size": step_size_of(step.final(state.step)),
               "inverse_mass_matrix": state.inverse_mass}  # fmt: skip
        if w.lengths is not None:
            out["integration_time"] = w.lengths.final(state.length)
        return out

    return Adaptation(init, current, update, final)


FAR_APART = 10.0
"""How far (a factor) a chain adapted alone may end from the others before it is reported."""


def far_adapted(step_sizes, inverse_masses, factor: float = FAR_APART) -> list[tuple[int, str]]:
    """Chains adapted alone whose step size, or an inverse mass coordinate, ended more than
    ``factor`` times (either way) from the median of the other chains' (their finite values):
    ``(chain, message)`` for each, the message naming the value and that median. A non-finite
    value counts as far.

    ``step_sizes`` ``(chains,)``; ``inverse_masses`` ``(chains, k)``, each chain's diagonal
    inverse mass flattened. Chains adapted together share their parameters and are never far;
    this is for those a warm-up tunes one at a time (NumPyro's ``chain_method="sequential"``).
    With two chains neither can be told apart from the other: the second is reported.
    """
    steps = np.asarray(step_sizes, dtype=float)
    masses = np.asarray(inverse_masses, dtype=float).reshape(len(steps), -1)
    bound = math.log(factor)
    out = []
    for chain in range(1 if len(steps) == 2 else 0, len(steps)):
        others = np.delete(np.arange(len(steps)), chain)
        if not others.size:
            continue
        step_median = _finite_median(steps[others, None])[0]
        mass_median = _finite_median(masses[others])
        parts = []
        with np.errstate(divide="ignore", invalid="ignore"):
            step_off = np.abs(np.log(steps[chain] / step_median))
            mass_off = np.abs(np.log(masses[chain] / mass_median))
        if not step_off <= bound:
            parts.append(
                f"step_size {steps[chain]:.3g} against the others' median {step_median:.3g}"
            )
        bad = np.flatnonzero(~(mass_off <= bound))
        if bad.size:
            k = int(bad[np.argmax(np.nan_to_num(mass_off[bad], nan=np.inf))])
            parts.append(
                f"inverse mass {masses[chain, k]:.3g} at coordinate {k} against the others' "
                f"median {mass_median[k]:.3g}"
            )
        if parts:
            out.append((chain, f"chain {chain}: " + " and ".join(parts)))
    return out


def _finite_median(values):
    """The median of each column over its finite entries (``nan`` where there is none)."""
    finite = np.where(np.isfinite(values), values, np.nan)
    with np.errstate(invalid="ignore"):
        out = np.full(values.shape[1], np.nan)
        some = np.any(np.isfinite(values), axis=0)
        out[some] = np.nanmedian(finite[:, some], axis=0)
    return out
