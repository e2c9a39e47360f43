"""Window adaptation for the geometric samplers: step size, mass and trajectory length.

``liesample.window_adaptation(algorithm, logdensity_fn, space, **parameters)`` mirrors
``blackjax.window_adaptation``: ``.run(rng_key, initial_position, num_steps)`` returns
``((state, parameters), info)`` and ``algorithm(logdensity_fn, space, **parameters)`` is the
tuned sampler. Stan's schedule (``blackjax.adaptation.window_adaptation.build_schedule``): a
fast window (step size only), doubling slow windows (step size and mass; the step size is
restarted at the end of each), a final fast window. The step size is tuned by dual averaging
(``blackjax.adaptation.step_size.dual_averaging_adaptation``) towards a target Metropolis rate
(``info.metropolis_rate``: for unadjusted Langevin the rate the step *would* have).

**Mass, in algebra coordinates.** ``Euclidean`` blocks: ``M⁻¹`` is the Welford variance of the
position (as BlackJAX, with Stan's shrinkage towards ``1e-3``). Group, sphere and ``U1`` blocks
have no global coordinates whose variance means anything (an angle's variance depends on where
it is cut), so there the mass is the mean squared trivialised gradient,
``M = E[(X_k log π)²] + 1`` (one value per copy of a group or sphere, the mean over its
algebra coordinates; one per angle for ``U1``). Integration by parts against Haar measure
(left-invariant fields are divergence-free) gives ``E[(X_k log π)²] = −E[X_k² log π]``, the
mean curvature of ``−log π`` along ``X_k``: for a Gaussian ``N(0, Σ)`` it is ``Σ⁻¹``, i.e. the
ideal mass. The ``+ 1`` is the unit sphere's own curvature scale: it keeps the mass finite for
a nearly uniform law, where any mass would do.

**Trajectory length (HMC).** Default: a fixed integration time ``T = π/2`` in the units set by
the mass (a quarter period of a whitened Gaussian, whose position after ``T`` is independent
of its start), with ``num_integration_steps = ceil(T / step_size)`` re-derived at every step
of the warm-up and for the tuned sampler. Pass ``integration_time`` to change ``T`` or
``num_integration_steps`` to fix ``L`` instead (then the integration time follows the step
size, as in ``blackjax.window_adaptation``). Measured in ``docs/groups.md``.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from blackjax.adaptation.step_size import dual_averaging_adaptation
from blackjax.adaptation.window_adaptation import build_schedule

from liesample import spaces
from liesample._validation import finite_float
from liesample.compile import jit

__all__ = ["DEFAULT_INTEGRATION_TIME", "window_adaptation"]

DEFAULT_INTEGRATION_TIME = 0.5 * math.pi
MAX_NUM_INTEGRATION_STEPS = 1024


class GeometricAdaptation(NamedTuple):
    """What ``window_adaptation`` returns: ``run(rng_key, initial_position, num_steps)``."""

    run: Callable


class AdaptationInfo(NamedTuple):
    """Per warm-up step: the sampler's state and info, the step size and trajectory length."""

    state: object
    info: object
    step_size: jax.Array
    num_integration_steps: jax.Array


def _statistic(space, state):
    """Flat vector whose Welford moments give the mass: positions of Euclidean blocks, the
    trivialised gradient of the others."""
    leaves = spaces._map(
        lambda s, x, g: jnp.ravel(x if not s.compact else g),
        space,
        state.position,
        state.logdensity_grad,
    )
    return jnp.concatenate(jax.tree.leaves(leaves))


def _inverse_mass(space, mean, m2, count, dtype):
    """Inverse mass (pytree like ``space``) from Welford moments of :func:`_statistic`."""
    variance = m2 / jnp.maximum(count - 1, 1)
    n = count.astype(dtype)
    out, offset = [], 0
    for s in spaces._spaces(space):
        size = math.prod(s.momentum_array_shape)
        var = variance[offset : offset + size].reshape(s.momentum_array_shape)
        mu = mean[offset : offset + size].reshape(s.momentum_array_shape)
        offset += size
        if not s.compact:  # Stan's regularised variance
            out.append((n / (n + 5.0)) * var + 1e-3 * (5.0 / (n + 5.0)))
            continue
        squared = var + mu**2
        if s.mass_shape == (1,):
            squared = jnp.sum(squared, -1, keepdims=True) / s.copy_dimension
        out.append(1.0 / (squared + 1.0))
    structure = jax.tree.structure(space, is_leaf=spaces.is_space)
    return structure.unflatten(out)


def window_adaptation(
    algorithm,
    logdensity_fn: Callable,
    space,
    *,
    initial_step_size: float = 0.1,
    target_acceptance_rate: float | None = None,
    integration_time: float | None = None,
    adapt_mass: bool = True,
    progress_bar: bool = False,
    **parameters,
) -> GeometricAdaptation:
    """Tune ``algorithm`` (``liesample.geometric_hmc`` or ``liesample.geometric_langevin``).

    Parameters
    ----------
    algorithm
        The sampler's API object; its ``build_kernel`` takes the options in ``parameters`` that
        are not kernel arguments (e.g. ``adjusted=True`` for Langevin).
    logdensity_fn, space
        As for the sampler.
    initial_step_size : float
        Starting point of dual averaging.
    target_acceptance_rate : float, optional
        Target Metropolis rate: 0.8 for HMC, 0.9 for Langevin (one step per transition;
        unadjusted chains are biased by the step size) by default.
    integration_time : float, optional
        HMC only: ``T`` of the trajectory (default ``π/2``) unless ``num_integration_steps`` is
        given.
    adapt_mass : bool
        Adapt the inverse mass (else keep ``inverse_mass_matrix`` or unit mass).
    parameters
        The sampler's other arguments: ``num_integration_steps`` (HMC, fixes ``L``),
        ``friction`` (Langevin, default 1), ``inverse_mass_matrix`` (the starting mass),
        and ``build_kernel`` options (``adjusted``, ``divergence_threshold``).
    """
    del progress_bar  # accepted for BlackJAX compatibility; the warm-up runs in one compiled loop
    spaces._spaces(space)
    finite_float("initial_step_size", initial_step_size, positive=True)
    build_options = {
        k: parameters.pop(k) for k in ("adjusted", "divergence_threshold") if k in parameters
    }
    kernel = algorithm.build_kernel(**build_options)
    arguments = inspect.signature(kernel).parameters
    is_hmc = "num_integration_steps" in arguments
    fixed_steps = parameters.pop("num_integration_steps", None)
    if is_hmc:
        if fixed_steps is not None and integration_time is not None:
            raise ValueError("give integration_time or num_integration_steps, not both")
        if fixed_steps is None:
            time = DEFAULT_INTEGRATION_TIME if integration_time is None else integration_time
            integration_time = finite_float("integration_time", time, positive=True)
        elif isinstance(fixed_steps, bool) or int(fixed_steps) != fixed_steps or fixed_steps < 1:
            raise ValueError(f"num_integration_steps must be an integer >= 1, got {fixed_steps!r}")
    elif fixed_steps is not None or integration_time is not None:
        raise ValueError("num_integration_steps and integration_time are HMC parameters")
    else:
        parameters.setdefault("friction", 1.0)
    if target_acceptance_rate is None:
        target_acceptance_rate = 0.8 if is_hmc else 0.9
    target = finite_float("target_acceptance_rate", target_acceptance_rate)
    if not 0.0 < target < 1.0:
        raise ValueError(f"target_acceptance_rate must be in (0, 1), got {target}")
    if "step_size" in parameters:
        raise TypeError("step_size is what window_adaptation tunes: give initial_step_size")
    unknown = set(parameters) - (set(arguments) - {"rng_key", "state", "logdensity_fn", "space"})
    if unknown:
        raise TypeError(f"unknown parameters for {algorithm}: {sorted(unknown)}")
    initial_mass = parameters.pop("inverse_mass_matrix", None)
    da_init, da_update, da_final = dual_averaging_adaptation(target)

    def num_steps_for(step_size):
        if not is_hmc:
            return jnp.asarray(1)
        if fixed_steps is not None:
            return jnp.asarray(int(fixed_steps))
        steps = jnp.ceil(integration_time / step_size)
        return jnp.clip(steps, 1, MAX_NUM_INTEGRATION_STEPS).astype(int)

    def one_step(carry, xs):
        state, da_state, step_size, inverse_mass, welford = carry
        key, (stage, window_end) = xs
        steps = num_steps_for(step_size)
        extra = {"num_integration_steps": steps} if is_hmc else {}
        state, info = kernel(
            key,
            state,
            logdensity_fn,
            space,
            step_size=step_size,
            inverse_mass_matrix=inverse_mass,
            **extra,
            **parameters,
        )
        rate = jnp.where(jnp.isfinite(info.metropolis_rate), info.metropolis_rate, 0.0)
        da_state = da_update(da_state, rate)
        mean, m2, count = welford
        slow = (stage == 1) & adapt_mass
        x = _statistic(space, state)
        new_count = count + 1
        delta = x - mean
        new_mean = mean + delta / new_count
        new_m2 = m2 + delta * (x - new_mean)
        welford = jax.tree.map(
            lambda a, b: jnp.where(slow, a, b), (new_mean, new_m2, new_count), welford
        )

        def end_window(operands):
            da_state, inverse_mass, welford = operands
            mean, m2, count = welford
            dtype = mean.dtype
            inverse_mass = _inverse_mass(space, mean, m2, count, dtype)
            da_state = da_init(da_final(da_state))
            return da_state, inverse_mass, (jnp.zeros_like(mean), jnp.zeros_like(m2), 0 * count)

        da_state, inverse_mass, welford = jax.lax.cond(
            window_end & adapt_mass,
            end_window,
            lambda operands: operands,
            (da_state, inverse_mass, welford),
        )
        step_size = jnp.exp(da_state.log_step_size)
        record = AdaptationInfo(state, info, step_size, steps)
        return (state, da_state, step_size, inverse_mass, welford), record

    def run(rng_key, initial_position, num_steps: int = 1000):
        """Warm up for ``num_steps`` transitions; ``((state, parameters), info)``."""
        if isinstance(num_steps, bool) or int(num_steps) != num_steps or num_steps < 20:
            raise ValueError(f"num_steps must be an integer >= 20, got {num_steps!r}")
        state = algorithm.init(initial_position, logdensity_fn, space)
        dtype = jnp.asarray(state.logdensity).dtype
        inverse_mass = spaces.check_inverse_mass(space, initial_mass, dtype)
        schedule = np.asarray(build_schedule(int(num_steps)))
        stages = jnp.asarray(schedule[:, 0])
        ends = jnp.asarray(schedule[:, 1].astype(bool))
        size = _statistic(space, state).shape[0]
        welford = (jnp.zeros(size, dtype), jnp.zeros(size, dtype), jnp.asarray(0))
        da_state = da_init(jnp.asarray(initial_step_size, dtype))
        carry = (state, da_state, jnp.asarray(initial_step_size, dtype), inverse_mass, welford)
        keys = jax.random.split(rng_key, int(num_steps))

        @jit
        def warmup(carry, keys, stages, ends):
            return jax.lax.scan(one_step, carry, (keys, (stages, ends)))

        (state, da_state, _, inverse_mass, _), info = warmup(carry, keys, stages, ends)
        step_size = float(da_final(da_state))
        tuned = dict(parameters)
        tuned["step_size"] = step_size
        tuned["inverse_mass_matrix"] = inverse_mass
        if is_hmc:
            tuned["num_integration_steps"] = int(num_steps_for(step_size))
        tuned.update(build_options)
        return (state, tuned), info

    return GeometricAdaptation(run)
