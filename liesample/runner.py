"""Run many chains of a BlackJAX-style sampler, vmapped, in chunks with a progress bar.

Draw ``d`` of chain ``c`` uses the key ``fold_in(key_c, step)``, so the draws do not depend on
the chunk size and a run can be split or resumed without changing them.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

# How per-step info is summarised over the steps a thinned draw spans.
_REDUCE_OVER_THINNING = {"nonfinite": jnp.any, "casimir_error": jnp.max}


class NonFiniteStateError(FloatingPointError):
    """A chain produced a non-finite state (the sampler kept the previous one and flagged it)."""


@dataclass(frozen=True)
class ChainsResult:
    """Draws of ``positions`` with shape ``(chains, draws, *event_shape)``, per-draw ``info``
    arrays with shape ``(chains, draws)``, and the sampling wall time in seconds (compilation
    excluded)."""

    positions: np.ndarray
    info: dict
    wall_time: float
    num_steps: int


def _check_run_arguments(
    initial_positions, num_draws, num_warmup, thinning, on_nonfinite, chunk_draws
):
    if np.ndim(initial_positions) < 1 or np.shape(initial_positions)[0] < 1:
        raise ValueError(
            "initial_positions must have a leading chain axis with at least one chain, "
            f"shape (chains, ...); got shape {np.shape(initial_positions)}"
        )
    for name, value, low in (
        ("num_draws", num_draws, 1),
        ("num_warmup", num_warmup, 0),
        ("thinning", thinning, 1),
    ):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if chunk_draws is not None and (
        not isinstance(chunk_draws, (int, np.integer))
        or isinstance(chunk_draws, bool)
        or chunk_draws < 1
    ):
        raise ValueError(f"chunk_draws must be None or an integer >= 1, got {chunk_draws!r}")
    if on_nonfinite not in ("warn", "raise"):
        raise ValueError(f"on_nonfinite must be 'warn' or 'raise', got {on_nonfinite!r}")


def sample_chains(
    algorithm,
    rng_key,
    initial_positions,
    num_draws: int,
    *,
    num_warmup: int = 0,
    thinning: int = 1,
    progress: bool = True,
    chunk_draws: int | None = None,
    on_nonfinite: str = "warn",
) -> ChainsResult:
    """Run ``len(initial_positions)`` chains of ``algorithm`` in parallel (``jax.vmap``).

    Parameters
    ----------
    algorithm : blackjax.base.SamplingAlgorithm
        ``init(position)`` and ``step(rng_key, state) -> (state, info)``; ``state.position``
        is recorded.
    rng_key : jax.Array
    initial_positions : array, shape ``(chains, *event_shape)``
    num_draws : int
        Draws kept per chain, each ``thinning`` steps apart, after ``num_warmup`` steps.
    progress : bool
        Show a progress bar (tqdm) over the draws.
    chunk_draws : int, optional
        Draws per compiled chunk (default: about 20 chunks).
    on_nonfinite : {"warn", "raise"}
        What to do if any step produced a non-finite state (``info.nonfinite``).
    """
    _check_run_arguments(
        initial_positions, num_draws, num_warmup, thinning, on_nonfinite, chunk_draws
    )
    initial_positions = jnp.asarray(initial_positions)
    num_chains = initial_positions.shape[0]
    if not np.all(np.isfinite(np.asarray(initial_positions))):
        raise ValueError("initial_positions must be finite")
    # Concrete checks (shape, orbit, constraints) of every distinct start; chains often share one.
    flat = np.asarray(initial_positions).reshape(num_chains, -1)
    _, first_chains = np.unique(flat, axis=0, return_index=True)
    for chain in np.sort(first_chains):
        try:
            algorithm.init(initial_positions[chain])
        except (ValueError, TypeError) as error:
            raise type(error)(f"initial_positions[{chain}]: {error}") from None
    states = jax.vmap(algorithm.init)(initial_positions)
    chain_keys = jax.random.split(rng_key, num_chains)

    def advance(state, key, first_step, num_steps):
        def one(state, step):
            return algorithm.step(jax.random.fold_in(key, step), state)

        return jax.lax.scan(one, state, first_step + jnp.arange(num_steps))

    @jax.jit
    def warmup(states, first_step):
        return jax.vmap(lambda s, k: advance(s, k, first_step, num_warmup)[0])(states, chain_keys)

    def draws(state, key, first_step, count):
        def one_draw(state, draw):
            state, infos = advance(state, key, first_step + draw * thinning, thinning)
            info = {
                name: _REDUCE_OVER_THINNING.get(name, lambda v: v[-1])(value)
                for name, value in infos._asdict().items()
            }
            return state, (state.position, info)

        return jax.lax.scan(one_draw, state, jnp.arange(count))

    chunk = chunk_draws if chunk_draws is not None else max(1, math.ceil(num_draws / 20))
    run_chunk = jax.jit(
        lambda states, first_step, count: jax.vmap(lambda s, k: draws(s, k, first_step, count))(
            states, chain_keys
        ),
        static_argnums=2,
    )
    # Compile outside the timed region (one chunk shape, plus the last partial one).
    if num_warmup:
        warmup = warmup.lower(states, 0).compile()
    compiled = {}
    for count in {min(chunk, num_draws), num_draws % chunk or chunk}:
        compiled[count] = run_chunk.lower(states, 0, count).compile()

    positions, infos = [], []
    start = time.perf_counter()
    if num_warmup:
        states = jax.block_until_ready(warmup(states, 0))
    bar = tqdm(total=num_draws, disable=not progress, unit="draw", desc=f"{num_chains} chains")
    done = 0
    while done < num_draws:
        count = min(chunk, num_draws - done)
        states, (chunk_positions, chunk_info) = compiled[count](
            states, num_warmup + done * thinning
        )
        positions.append(np.asarray(chunk_positions))
        infos.append(jax.tree.map(np.asarray, chunk_info))
        done += count
        bar.update(count)
    bar.close()
    wall_time = time.perf_counter() - start

    info = {name: np.concatenate([i[name] for i in infos], axis=1) for name in infos[0]}
    result = ChainsResult(
        np.concatenate(positions, axis=1), info, wall_time, num_warmup + num_draws * thinning
    )
    _report_nonfinite(result, on_nonfinite)
    return result


def _report_nonfinite(result: ChainsResult, on_nonfinite: str):
    flags = result.info.get("nonfinite")
    if flags is None or not np.any(flags):
        return
    chains = np.flatnonzero(np.any(flags, axis=1))
    message = (
        f"{int(np.sum(flags))} draws in {len(chains)} chain(s) (first: chain {chains[0]}) hit a "
        "non-finite state; those steps were rejected and flagged in info['nonfinite']. "
        "Reduce step_size or sigma."
    )
    if on_nonfinite == "raise":
        raise NonFiniteStateError(message)
    warnings.warn(message, RuntimeWarning, stacklevel=3)


def sample(
    algorithm,
    rng_key,
    initial_positions,
    num_draws: int,
    *,
    num_warmup: int = 0,
    thinning: int = 1,
    progress: bool = True,
    on_nonfinite: str = "warn",
    var_name: str = "mu",
    event_dims=("component",),
    coords=None,
    attrs=None,
):
    """Run chains with :func:`sample_chains` and return an ArviZ ``DataTree``.

    The tree has ``posterior/<var_name>`` with dims ``(chain, draw, *event_dims)`` and
    ``sample_stats`` (``energy``, ``diverging``, ``casimir_error``); its attributes record the
    wall time, the number of steps and ``attrs``.
    """
    from liesample.diagnostics import to_datatree

    result = sample_chains(
        algorithm,
        rng_key,
        initial_positions,
        num_draws,
        num_warmup=num_warmup,
        thinning=thinning,
        progress=progress,
        on_nonfinite=on_nonfinite,
    )
    return to_datatree(
        result.positions,
        result.info,
        var_name=var_name,
        event_dims=event_dims,
        coords=coords,
        thinning=thinning,
        attrs={
            "wall_time_seconds": result.wall_time,
            "num_steps": result.num_steps,
            "num_warmup": num_warmup,
            **(attrs or {}),
        },
    )
