"""Trajectory length of HMC: a jittered integration time, its length learnt by a ChEES-type rule.

Every HMC-type warm-up of liesample runs this one rule, in BlackJAX's shape
(:func:`trajectory_adaptation` returns ``(init, update, final)``), as the trajectory piece of
the window adaptation (:func:`liesample.tuning.windows.windows_adaptation`), which
:func:`liesample.window_adaptation`, :func:`liesample.tuning.adaptation.magnetic_window_adaptation`
and the NumPyro kernel :class:`liesample.interop.numpyro_kernel.GeometricHMC` run.

**Jitter.** Transition ``n`` integrates for ``t = u_n T`` (``L = ceil(u_n T / ε)`` steps, at least
one), ``u_n`` the base-2 Halton sequence (:func:`halton`, the same for every chain). A fixed
``T`` resonates with any direction whose half period divides it: for a Gaussian direction of
frequency ``ω`` with ``ωT ≈ π`` each draw is nearly minus the previous one and the chain's
amplitude freezes where the warm-up left it. Under the jitter ``ω u T`` sweeps ``(0, ωT)`` and
no direction can sit at a resonance.

**Length (ChEES).** ``log T`` is moved by ``learning_rate`` times the estimated gradient
(clipped to ``[−2, 2]``) of the log of the squared distance's ESS per gradient,
``(1 − ρ)/((1 + ρ) T)``, with ``1 − ρ`` read off ChEES normalised by its value for independent
draws (:func:`_log_efficiency_gradient`, from running means of the estimates of
:func:`_chees_terms`). ChEES needs the target's centre: the mean over chains when several
chains move together, else a running mean of the one chain's positions. The derivative is
taken at the time integrated, ``L ε``, not at ``u T``; at ``T <= ε`` ``T`` is not lowered (a
transition is one step whatever ``T`` is). When the mass changes, ``T`` is rescaled to the new
whitened units (:func:`_rescale`). After each update ``T`` is pulled down towards
``min(L_max ε, π √(tr Σ̃))`` when above it (:func:`_bound_log_time`). The tuned ``T`` is
``exp`` of the mean of ``log T`` over the transitions updated with ``average=True`` (the last
slow window and the final fast window of Stan's schedule,
:func:`liesample.tuning.protocol.schedule`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.types import TreeDef
from liesample.geometry import spaces

__all__ = [
    "CHEES_LEARNING_RATE",
    "DEFAULT_INTEGRATION_TIME",
    "MAX_NUM_INTEGRATION_STEPS",
    "TrajectoryAdaptation",
    "TrajectoryState",
    "chain_move",
    "euclidean_size",
    "halton",
    "jittered_steps",
    "trajectory_adaptation",
]

DEFAULT_INTEGRATION_TIME = 0.5 * math.pi
"""The starting ``T`` (a quarter period of a whitened Gaussian) and the fixed one's default."""
MAX_NUM_INTEGRATION_STEPS = 1024
CHEES_LEARNING_RATE = 0.01
CHEES_AVERAGING = 0.95  # running means of the ChEES estimates (and a single chain's centre)
CHEES_MAX_TIME_PER_SD = math.pi
"""Upper bound of the learnt ``T`` in units of ``√(tr Σ̃)``, ``Σ̃`` the target's covariance
whitened by the current mass (estimated from the chains' spread): half a period of a Gaussian's
slowest direction is at most ``π √(tr Σ̃)``, beyond which it turns back."""
CHEES_MAX_PULL = 0.1
"""The most (in ``log T``) the bound of :func:`_bound_log_time` lowers ``T`` per transition:
a bound that dips for a few transitions (dual averaging trying a tiny ``ε``, chains that
started together) cannot drag ``T`` far down, from where the gradient raises it by
``2 · learning_rate`` at most."""
HALTON_BITS = 31


def _van_der_corput(num: int) -> np.ndarray:
    """The base-2 Halton sequence ``1/2, 1/4, 3/4, 1/8, …`` (``num`` points in ``(0, 1)``)."""
    return np.asarray(halton(np.arange(num)))


def halton(index):
    """``u`` of transition ``index`` (0-based, traceable): the base-2 Halton point of
    ``index + 1``, in ``(0, 1)``."""
    n = jnp.asarray(index, jnp.int32) + 1
    u = jnp.zeros(jnp.shape(n), jnp.zeros(()).dtype)
    for bit in range(HALTON_BITS):
        u = u + ((n >> bit) & 1) * 0.5 ** (bit + 1)
    return u


def jittered_steps(u, trajectory_length, step_size, max_steps: int = MAX_NUM_INTEGRATION_STEPS):
    """``L = ceil(u T / ε)`` clipped to ``[1, max_steps]`` (traceable)."""
    steps = jnp.ceil(u * trajectory_length / step_size)
    return jnp.clip(steps, 1, max_steps).astype(int)


def _chees_terms(before, after, momentum, accepted, acceptance, inverse_mass, time, centre=None):
    """Estimates of ``ChEES`` and of ``∂ ChEES / ∂ log T`` from a batch of chains.

    ``ChEES = ¼ E[(‖x' − E x‖² − ‖x − E x‖²)²]`` (Hoffman, Radul & Sountsov 2021) in the
    coordinates whitened by the mass (``x = M^{1/2} q``), the centre estimated by the mean
    over chains (or ``centre``, the same for both ends, for a single chain). Its derivative
    along a trajectory of length ``t = u T`` is ``Δ · (x' − x̄')·ẋ' · t`` with ``Δ`` the change
    of squared distance, and ``(x' − x̄')·ẋ' = (q' − q̄')·p'`` (the mass cancels, and a
    magnetic field does not enter: ``q̇ = M⁻¹p`` with or without it). The paper weights each
    chain's proposal by its acceptance probability; here the chain's accepted move stands in
    for it (a rejected move contributes 0, the same in expectation), normalised by the summed
    probabilities. Returns ``(chees, gradient, spread)``, ``spread`` the chains' mean of
    ``‖x' − x̄'‖²`` and of its square.
    """
    if centre is None:
        centred_before = before - jnp.mean(before, 0)
        centred_after = after - jnp.mean(after, 0)
    else:
        centred_before, centred_after = before - centre, after - centre
    change = jnp.sum(centred_after**2 / inverse_mass, -1) - jnp.sum(
        centred_before**2 / inverse_mass, -1
    )
    rate = jnp.sum(centred_after * momentum, -1)
    total = jnp.sum(acceptance)
    norm = jnp.where(total > 0, 1.0 / jnp.maximum(total, 1e-30), 0.0)
    chees = norm * jnp.sum(jnp.where(accepted, 0.25 * change**2, 0.0))
    gradient = norm * jnp.sum(jnp.where(accepted, time * change * rate, 0.0))
    distance = jnp.sum(centred_after**2 / inverse_mass, -1)
    spread = jnp.stack([jnp.mean(distance), jnp.mean(distance**2)])
    return chees, gradient, spread


def _chees_gradient(*args):
    """``∂ ChEES / ∂ log T`` of :func:`_chees_terms`."""
    return _chees_terms(*args)[1]


def _log_efficiency_gradient(means, cost_slope):
    """``∂/∂ log T`` of ``log[(1 − ρ)/((1 + ρ) E L)]`` from running means ``(Ĉ, ĝ, E s, E s²)``.

    ``ρ`` is the one-transition autocorrelation of the squared distance ``s = ‖x − x̄‖²``, so
    ``(1 − ρ)/(1 + ρ)`` is its effective sample size per transition and dividing by the mean
    number of steps, ``E L ≈ T/(2ε) + ½``, makes it per gradient evaluation
    (``cost_slope = ∂ log E L / ∂ log T = T/(T + ε)``; every step of a scheme costs the same
    number of gradients, so the rule is the same for every scheme). ChEES is ``(1 − ρ)``
    times its value for independent draws, ``½ Var s``, so with ``r = Ĉ / (½ Var s)``,
    ``1 − ρ = r/2`` and the gradient is ``(ĝ/Ĉ) · 4/(4 − r) − cost_slope``.
    For one Gaussian direction of frequency ``ω`` its maximum is at ``T ≈ 1.8/ω`` (ChEES
    alone first peaks at ``2.25/ω``, ChEES per unit length at ``π/(2ω)``).
    """
    chees, gradient, mean, square = means[0], means[1], means[2], means[3]
    independent = 0.5 * (square - mean**2)
    r = jnp.clip(chees / jnp.maximum(independent, 1e-300), 0.0, 3.0)
    ratio = gradient / jnp.maximum(chees, 1e-300)
    return jnp.where((chees > 0) & (independent > 0), ratio * 4.0 / (4.0 - r) - cost_slope, 0.0)


def _rescale(state: TrajectoryState, inverse_mass) -> TrajectoryState:
    """``T`` carried across a change of the mass: a Gaussian direction's frequency goes as
    ``√(M⁻¹)``, so ``T`` (and the averaged ``log T``) is divided by the geometric mean of
    ``√(M⁻¹_new / M⁻¹_old)``, and the running means, in the old whitened units, restart."""
    previous = state.inverse_mass
    ratio = jnp.where(previous > 0, inverse_mass / jnp.where(previous > 0, previous, 1.0), 1.0)
    changed = jnp.any(ratio != 1.0)
    shift = jnp.where(changed, -0.5 * jnp.mean(jnp.log(ratio)), 0.0)
    return state._replace(
        log_time=state.log_time + shift,
        log_sum=state.log_sum + shift * state.num_averaged,
        means=jnp.where(changed, 0.0, state.means),
        since=jnp.where(changed, 0, state.since),
    )


def _bound_log_time(log_time, step_size, max_steps, means, index, correction):
    """``log T`` pulled down towards ``log min(L_max ε, π √(tr Σ̃))`` when above it, by
    :data:`CHEES_MAX_PULL` at most per transition.

    ``tr Σ̃`` is the running mean of the chains' squared distance to their centre (``means[2]``
    of :func:`_log_efficiency_gradient`), corrected for the running mean's start at 0 and by
    ``correction`` for the centre's estimate (``C/(C − 1)`` for the mean of ``C`` chains):
    above ``π √(tr Σ̃)`` the slowest direction of a Gaussian turns back
    (:data:`CHEES_MAX_TIME_PER_SD`).
    """
    weight = 1.0 - CHEES_AVERAGING ** (index + 1.0)
    trace = means[2] / weight * correction
    upper = jnp.log(max_steps * step_size)
    spread = jnp.log(CHEES_MAX_TIME_PER_SD * jnp.sqrt(trace))
    upper = jnp.where(jnp.isfinite(spread) & (trace > 0), jnp.minimum(upper, spread), upper)
    return log_time - jnp.clip(log_time - upper, 0.0, CHEES_MAX_PULL)


class TrajectoryState(NamedTuple):
    """The rule's carry: ``log T``; running means of the ChEES estimates and the updates since
    they restarted; a single chain's running centre (unused with several chains) and the
    updates made; the sum and count of ``log T`` over the averaged transitions; the diagonal
    inverse mass of the last update (0 before the first)."""

    log_time: jax.Array
    means: jax.Array
    since: jax.Array
    centre: jax.Array
    count: jax.Array  # type: ignore[assignment]  # the field shadows tuple.count
    log_sum: jax.Array
    num_averaged: jax.Array
    inverse_mass: jax.Array


class TrajectoryAdaptation(NamedTuple):
    """``init(dimension, dtype)``, ``update(state, move, step_size, steps, average)``,
    ``final(state) -> T`` (:func:`trajectory_adaptation`); ``learn``: whether ``T`` moves."""

    init: Callable
    update: Callable
    final: Callable
    learn: bool


class ChainMove(NamedTuple):
    """What one transition of a batch of chains did, in whitened coordinates for the ChEES
    estimates: positions ``before`` and ``after`` (``(C, d)``), the momentum after
    (``x·p`` as ``q·p``), the chains' acceptance and acceptance probabilities, and the inverse
    mass that whitens (ones when the coordinates are already whitened)."""

    before: jax.Array
    after: jax.Array
    momentum: jax.Array
    accepted: jax.Array
    acceptance: jax.Array
    inverse_mass: jax.Array


def euclidean_size(space) -> int:
    """The coordinates the rule reads on ``space``: those of its ``Euclidean`` blocks (spheres
    and groups are compact, and a circle's angle has no centre)."""
    return sum(math.prod(s.shape) for s in spaces._spaces(space) if _is_euclidean(s))


def _is_euclidean(s) -> bool:
    return isinstance(s, spaces.Euclidean)


def chain_move(space, before, after, info, inverse_mass, batched: bool) -> ChainMove:
    """One transition of geometric HMC on ``space`` as the rule reads it: the ``Euclidean``
    blocks' positions (states ``before`` and ``after``, a leading chain axis when ``batched``,
    else a batch of one), in the norm of the diagonal ``D`` of ``M⁻¹``, with ``D⁻¹ M⁻¹ p`` as the
    momentum (so ``(q − c)·D⁻¹q̇`` is the rate of the squared distance; ``p`` itself for a
    diagonal mass)."""
    flat = lambda x: x.reshape((x.shape[0], -1)) if batched else x.reshape((1, -1))
    parts: dict[str, list[jax.Array]] = {"before": [], "after": [], "momentum": [], "scale": []}
    blocks = zip(
        spaces._spaces(space),
        jax.tree.leaves(before.position),
        jax.tree.leaves(after.position),
        jax.tree.leaves(after.momentum),
        _mass_leaves(space, inverse_mass),
        strict=True,
    )
    for s, q0, q1, p, m in blocks:
        if not _is_euclidean(s):
            continue
        p = flat(p)
        if jnp.ndim(m) == 2:
            diagonal = jnp.diagonal(m)
            p = (p @ m.T) / diagonal
        else:
            diagonal = jnp.broadcast_to(jnp.ravel(m), p.shape[-1:])
        parts["before"].append(flat(q0))
        parts["after"].append(flat(q1))
        parts["momentum"].append(p)
        parts["scale"].append(diagonal)
    size = euclidean_size(space)
    width = jax.tree.leaves(before.position)[0].shape[0] if batched else 1
    empty = {"scale": jnp.zeros(0)}
    out = {
        n: jnp.concatenate(v, -1) if v else empty.get(n, jnp.zeros((width, size)))
        for n, v in parts.items()
    }
    accepted, rate = info.is_accepted, info.acceptance_rate
    if not batched:
        accepted, rate = jnp.asarray(accepted)[None], jnp.asarray(rate)[None]
    return ChainMove(out["before"], out["after"], out["momentum"], accepted, rate, out["scale"])


def _mass_leaves(space, inverse_mass):
    """``inverse_mass``'s block per space leaf (a dense block is one leaf, an array)."""
    structure: TreeDef = jax.tree.structure(space, is_leaf=spaces.is_space)
    return structure.flatten_up_to(inverse_mass)


def trajectory_adaptation(
    initial_time: float = DEFAULT_INTEGRATION_TIME,
    learning_rate: float = CHEES_LEARNING_RATE,
    max_steps: int = MAX_NUM_INTEGRATION_STEPS,
    learn: bool = True,
) -> TrajectoryAdaptation:
    """The ChEES-type rule of the module docstring (``learn=False``: ``T`` stays at
    ``initial_time``, still jittered by the caller)."""

    def init(dimension: int, dtype) -> TrajectoryState:
        zero = jnp.zeros((), dtype)
        return TrajectoryState(
            jnp.log(jnp.asarray(initial_time, dtype)),
            jnp.zeros(4, dtype),
            jnp.asarray(0),
            jnp.zeros(dimension, dtype),
            jnp.asarray(0),
            zero,
            zero,
            jnp.zeros(dimension, dtype),
        )

    def update(state: TrajectoryState, move: ChainMove, step_size, steps, average):
        if learn and move.before.shape[-1] > 0:
            state = _learn(_rescale(state, move.inverse_mass), move, step_size, steps)
        return state._replace(
            count=state.count + 1,
            log_sum=state.log_sum + jnp.where(average, state.log_time, 0.0),
            num_averaged=state.num_averaged + jnp.where(average, 1.0, 0.0),
        )

    def _learn(state, move, step_size, steps):
        log_time, means, index = state.log_time, state.means, state.since
        num_chains = move.before.shape[0]
        single = num_chains == 1
        weight = 1.0 - CHEES_AVERAGING ** (state.count + 1.0)
        centre = CHEES_AVERAGING * state.centre + (1.0 - CHEES_AVERAGING) * move.before[0]
        trajectory = jnp.exp(log_time)
        chees, gradient, spread = _chees_terms(
            move.before,
            move.after,
            move.momentum,
            move.accepted,
            move.acceptance,
            move.inverse_mass,
            steps * step_size,  # the time integrated (not u T: L >= 1 and ceil)
            centre / weight if single else None,
        )
        # Running means of the estimates, then their ratios (not the mean of ratios: one
        # batch's ChEES can be near 0).
        terms = jnp.concatenate([jnp.stack([chees, gradient]), spread])
        ok = jnp.all(jnp.isfinite(terms))
        means = jnp.where(ok, CHEES_AVERAGING * means + (1.0 - CHEES_AVERAGING) * terms, means)
        gradient = _log_efficiency_gradient(means, trajectory / (trajectory + step_size))
        # The gradient is dimensionless (≈ +1 for too short, ≥ −1 for too long a trajectory),
        # so plain stochastic ascent on log T with a fixed step.
        change = learning_rate * jnp.clip(gradient, -2.0, 2.0)
        # At T <= ε a transition is one step whatever T is: no lower T to move to.
        change = jnp.where(trajectory <= step_size, jnp.maximum(change, 0.0), change)
        log_time = jnp.where(jnp.isfinite(change), log_time + change, log_time)
        correction = 1.0 if single else num_chains / (num_chains - 1.0)
        log_time = _bound_log_time(log_time, step_size, max_steps, means, index, correction)
        return state._replace(
            log_time=log_time,
            means=means,
            since=index + 1,
            centre=centre if single else state.centre,
            inverse_mass=move.inverse_mass,
        )

    def final(state: TrajectoryState):
        averaged = state.log_sum / jnp.maximum(state.num_averaged, 1.0)
        return jnp.exp(jnp.where(state.num_averaged > 0, averaged, state.log_time))

    return TrajectoryAdaptation(init, update, final, learn)
