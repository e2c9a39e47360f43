"""Run many chains of a BlackJAX-style sampler, vmapped, in chunks with a progress bar.

Draw ``d`` of chain ``c`` uses the key ``fold_in(key_c, step)`` (a sampler that draws its noise
in blocks, as the orbit samplers do, ``fold_in(key_c, block)``:
:mod:`liesample.integrators.chain_loop`),
so the draws do not depend on the chunk size and a run can be split or resumed without changing
them.

- **Devices.** ``devices=`` splits the chain axis over several devices with JAX's own sharding
  (:mod:`liesample.run.sharding`); the draws are those of the unsharded run.
- **Pytree positions.** ``initial_positions`` may be a pytree (a dict or tuple of arrays, e.g.
  ``{"mu": (chains, 3), "log_kappa": (chains,)}`` for the geometric samplers) whose leaves share
  the leading chain axis; the draws are then a pytree of arrays ``(chains, draws, *event)``.
  A list is read as one array, as before.
- **Long runs lose nothing.** ``output=`` writes every chunk of draws, and the chain states after
  it, to a NetCDF-4 file (h5netcdf, growing ``draw`` dimension) as soon as the chunk is done;
  ``resume=True`` continues a run from the last chunk saved there, after an interruption or to
  extend it to more draws, and returns the same draws as an uninterrupted run (bitwise).
- **Observables.** ``observables=`` evaluates functions of the position at every kept draw
  inside the compiled loop (magnetisation, correlation functions, spectra) and stores their
  values per draw; with ``keep_positions=False`` the full states are not stored (large lattices,
  Zeitlin's vorticity matrices). They are saved to ``output=``, restored on ``resume=`` and are
  posterior variables of :func:`sample`'s tree. The draws do not change.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import time
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from liesample.analysis.convergence import convergence_warnings
from liesample.foundation.compile import jit
from liesample.foundation.validation import (
    finite_float,
    is_single_array,
    prng_key,
    raise_or_warn,
)
from liesample.integrators.chain_loop import run_draws, run_steps
from liesample.run.sharding import chain_sharding, shard_chains, to_host
from liesample.samplers.contract import Sampler, as_sampler, reduce_over_thinning
from liesample.tuning.warmup import choose_from_starts, warm_up

DEFAULT_MIN_ACCEPTANCE_RATE = 0.05
"""A chain whose mean acceptance rate over the run is below this is reported as stuck."""
MAX_ENERGY_RHAT = 1.05
"""Chains whose energies have a split R-hat above this are reported as not converged."""

# Test hook: called as ``_after_chunk_hook(draws_done)`` once a chunk is saved to ``output``
# (tests/test_resume.py kills the process there to simulate an interruption).
_after_chunk_hook = None

_FORMAT = "liesample-chains-1"


class NonFiniteStateError(FloatingPointError):
    """A chain diverged: a step produced a non-finite state or energy (the sampler kept the
    previous state and flagged ``info.is_divergent``)."""


@dataclass(frozen=True)
class ChainsResult:
    """Draws of ``positions`` with shape ``(chains, draws, *event_shape)`` (a pytree of such
    arrays for pytree positions; ``None`` for a run with ``keep_positions=False``), per-draw
    ``info`` arrays with shape ``(chains, draws)``, the sampling wall time in seconds
    (compilation excluded; on a resumed run, the time of this session only), the sampler's
    ``settings`` after warm-up (step size and how it was chosen, stability mode, …), and the
    ``observables`` recorded at each draw (the pytree the ``observables`` option returns, each
    leaf ``(chains, draws, *shape)``; ``None`` without that option)."""

    positions: np.ndarray
    info: dict
    wall_time: float
    num_steps: int
    settings: dict = None
    observables: object = None


def _as_observables(observables, keep_positions):
    """``(function, cache key)``: ``observables`` (a callable, or a mapping name -> callable)
    as one function ``position -> pytree``, and a hashable key naming it for the compile cache;
    ``(None, None)`` without observables."""
    if not isinstance(keep_positions, bool):
        raise TypeError(f"keep_positions must be a bool, got {keep_positions!r}")
    if observables is None:
        if not keep_positions:
            raise ValueError(
                "keep_positions=False stores no draws at all without observables: pass "
                "observables= (a function of the position, or a dict name -> function)"
            )
        return None, None
    if callable(observables):
        return observables, observables
    if isinstance(observables, dict):
        if not observables:
            raise ValueError("observables is an empty dict: give at least one name -> function")
        for name, function in observables.items():
            if not isinstance(name, str) or not name:
                raise TypeError(f"observables' names must be non-empty strings, got {name!r}")
            if not callable(function):
                raise TypeError(
                    f"observables[{name!r}] must be a function of the position, got "
                    f"{type(function).__name__}"
                )
        functions = dict(observables)

        def observe(position):
            return {name: function(position) for name, function in functions.items()}

        return observe, tuple(functions.items())
    raise TypeError(
        "observables must be a function of the position (returning an array or a pytree of "
        f"arrays) or a dict name -> function, got {type(observables).__name__}"
    )


def _observable_shapes(observe, initial_positions):
    """The shapes and dtypes of ``observe`` vmapped over the starts' chains (checked: a
    non-empty pytree of numeric arrays)."""
    example = jax.eval_shape(jax.vmap(observe), initial_positions)
    leaves = jax.tree.leaves(example)
    if not leaves:
        raise ValueError("observables returned an empty pytree: it has no arrays")
    for leaf in leaves:
        if not hasattr(leaf, "dtype") or leaf.dtype.kind not in "biufc":
            raise TypeError(f"observables must return numeric arrays, got {leaf!r}")
    return example


def _as_positions(initial_positions):
    """``initial_positions`` as a JAX array, or a pytree of JAX arrays, with a leading chain axis
    shared by every leaf (checked); returns ``(positions, num_chains)``."""
    if is_single_array(initial_positions):
        positions = jnp.asarray(initial_positions)
        if positions.ndim < 1 or positions.shape[0] < 1:
            raise ValueError(
                "initial_positions must have a leading chain axis with at least one chain, "
                f"shape (chains, ...); got shape {positions.shape}"
            )
        return positions, positions.shape[0]
    paths, treedef = jax.tree_util.tree_flatten_with_path(initial_positions)
    if not paths:
        raise ValueError("initial_positions is an empty pytree: it has no arrays")
    leaves = [jnp.asarray(leaf) for _, leaf in paths]
    names = [f"initial_positions{jax.tree_util.keystr(path)}" for path, _ in paths]
    for name, leaf in zip(names, leaves, strict=True):
        if leaf.ndim < 1 or leaf.shape[0] < 1:
            raise ValueError(
                f"{name} must have a leading chain axis with at least one chain, shape "
                f"(chains, ...); got shape {leaf.shape}"
            )
        if leaf.shape[0] != leaves[0].shape[0]:
            raise ValueError(
                "every leaf of initial_positions must have the same leading chain axis: "
                f"{names[0]} has {leaves[0].shape[0]} chains (shape {leaves[0].shape}), {name} "
                f"has {leaf.shape[0]} (shape {leaf.shape})"
            )
    return jax.tree.unflatten(treedef, leaves), leaves[0].shape[0]


def _take_chain(positions, chain):
    return jax.tree.map(lambda leaf: leaf[chain], positions)


def _check_run_arguments(num_draws, num_warmup, thinning, on_nonfinite, chunk_draws, adapt):
    for name, value, low in (
        ("num_draws", num_draws, 1),
        ("num_warmup", num_warmup, 0),
        ("thinning", thinning, 1),
    ):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if chunk_draws is not None and (
        not isinstance(chunk_draws, (int, np.integer))
        or isinstance(chunk_draws, bool)
        or chunk_draws < 1
    ):
        raise ValueError(f"chunk_draws must be None or an integer >= 1, got {chunk_draws!r}")
    if on_nonfinite not in ("warn", "raise"):
        raise ValueError(f"on_nonfinite must be 'warn' or 'raise', got {on_nonfinite!r}")
    if adapt not in (None, True, False):
        raise TypeError(f"adapt must be None, True or False, got {adapt!r}")
    if adapt is True and num_warmup == 0:
        raise ValueError("adapt=True needs warm-up steps: pass num_warmup > 0")


def _wants_adaptation(sampler: Sampler, adapt, num_warmup, name: str) -> bool:
    """``adapt=None``: adapt what the user left unset (a sampler declaring a ``tuning`` whose
    step size was not given) when there is a warm-up; ``True``: adapt (the sampler must declare
    a ``tuning``); ``False``: never."""
    if adapt is True and sampler.tuning is None:
        raise ValueError(
            f"adapt=True: {name} has no warm-up adaptation; the orbit "
            "samplers (liesample.lie_poisson_langevin, liesample.adjusted_lie_poisson) have one, "
            "the magnetic samplers are tuned with blackjax.window_adaptation"
        )
    if adapt is None:
        return sampler.tuning is not None and num_warmup > 0 and not sampler.tuning.given
    return bool(adapt)


def _check_starts(sampler: Sampler, initial_positions, num_chains, step_size_checks=True):
    """Every start checked: in one vectorised call when the sampler declares
    ``check_positions``, else its ``init`` on each distinct start; errors name the first bad
    chain."""
    if sampler.check_positions is not None:
        sampler.check_positions(
            jax.tree.map(np.asarray, initial_positions), step_size_checks=step_size_checks
        )
        return
    flat = np.concatenate(
        [
            np.ascontiguousarray(np.asarray(leaf).reshape(num_chains, -1)).view(np.uint8)
            for leaf in jax.tree.leaves(initial_positions)
        ],
        axis=1,
    )  # bytes: one row per chain, whatever the leaves' dtypes
    _, first_chains = np.unique(flat, axis=0, return_index=True)
    for chain in np.sort(first_chains):
        try:
            sampler.init(_take_chain(initial_positions, chain))
        except (ValueError, TypeError) as error:
            raise type(error)(f"initial_positions[{chain}]: {error}") from None


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
    devices=None,
    output=None,
    resume: bool = False,
    adapt: bool | None = None,
    min_acceptance_rate: float = DEFAULT_MIN_ACCEPTANCE_RATE,
    observables=None,
    keep_positions: bool = True,
) -> ChainsResult:
    """Run ``len(initial_positions)`` chains of ``algorithm`` in parallel (``jax.vmap``).

    Parameters
    ----------
    algorithm : blackjax.base.SamplingAlgorithm
        ``init(position)`` and ``step(rng_key, state) -> (state, info)``; ``state.position``
        is recorded. liesample's samplers (:class:`liesample.samplers.contract.Sampler`) also
        declare a vectorised check of every start, their settings, how their step size is
        tuned (run by :mod:`liesample.tuning.warmup`) and their noise blocks; any other
        algorithm is read as a ``Sampler`` with the defaults
        (:func:`liesample.samplers.contract.as_sampler`).
    rng_key : jax.random.key or jax.random.PRNGKey
    initial_positions : array ``(chains, *event_shape)``, or a pytree of such arrays
        A pytree (dict, tuple, named tuple; e.g. the positions of ``liesample.geometric_hmc``
        on a product space) gives draws with the same structure; every leaf has the chain axis
        first, with the same number of chains. A (nested) list is read as one array.
    num_draws : int
        Draws kept per chain, each ``thinning`` steps apart, after ``num_warmup`` steps.
    num_warmup : int
        Steps run and discarded before the first draw; the adaptation happens there.
    adapt : None, True or False
        Warm-up adaptation of the step size, as the sampler declares it (``tuning``, run by
        :func:`liesample.tuning.warmup.warm_up`). ``None`` (default): adapt a sampler built
        without ``step_size`` when ``num_warmup > 0`` (the unadjusted sampler then chooses its
        step from the bias model on the run's starts, the adjusted one tunes it by dual
        averaging to its target acceptance); ``True``: adapt even a given step size; ``False``:
        never. A step size left unset and not adapted is the sampler's own choice for the
        run's starts (:func:`liesample.tuning.warmup.choose_from_starts`).
    progress : bool
        Show a progress bar (tqdm) over the draws (on a resumed run it starts at the draws
        already saved).
    chunk_draws : int, optional
        Draws per compiled chunk (default: about 20 chunks); also the unit of saving.
    on_nonfinite : {"warn", "raise"}
        What to do if any step diverged (``info.is_divergent``: a non-finite state or energy):
        a ``RuntimeWarning`` naming the chains, or :class:`NonFiniteStateError`.
    min_acceptance_rate : float
        Chains whose mean ``acceptance_rate`` over the draws is below this are reported as
        stuck (``RuntimeWarning`` naming them); 0 disables the check. Chains whose energies
        have a split R-hat above :data:`MAX_ENERGY_RHAT` are reported as not converged (a
        ``RuntimeWarning``: an unfinished warm-up, or a law that depends on the start).
    devices : None, "all", int, sequence of jax devices, or NamedSharding
        Split the chains over these devices (:func:`liesample.run.sharding.chain_sharding`); the
        number of chains must be a multiple of the number of devices. ``None``: one device.
    output : str or path, optional
        NetCDF file to which each chunk of draws and info, and the chain states after it, are
        written as soon as the chunk is done (:func:`load_chains` reads it back, so does
        ``xarray.open_dataset``). Refuses an existing file unless ``resume=True``. Pytree
        positions made of dicts (string keys), tuples and lists are saved leaf by leaf.
    resume : bool
        Continue the run saved in ``output``: same ``algorithm``, ``rng_key``,
        ``initial_positions``, ``num_warmup`` and ``thinning`` (checked, except the algorithm);
        ``num_draws`` may be larger than before to extend it. Starts afresh if the file does not
        exist yet. The returned draws include the saved ones and equal those of one
        uninterrupted run.
    observables : callable or dict of str to callable, optional
        Functions of one chain's position, evaluated at every kept draw inside the compiled
        loop (vmapped over chains; with ``thinning``, at the draw's own step only). A callable
        may return an array or a pytree of arrays; a dict ``{name: function}`` gives a dict of
        their values. ``ChainsResult.observables`` stacks them as ``(chains, draws, *shape)``.
        They are written to ``output`` with the draws, and a resumed run must pass the same
        observables (their names and shapes are checked). The draws do not depend on them.
    keep_positions : bool
        ``False`` stores only the observables (and info), not the positions (``positions`` is
        then ``None``): a run's memory is then that of the observables.

    Example: the magnetisation and energy of a spin lattice at every draw, no states kept::

        result = sample_chains(
            liesample.heisenberg_heat_bath(system, beta=1.0), key, starts, 1000,
            observables={"m": lambda s: s.reshape(-1, 3).mean(0), "h": system.hamiltonian},
            keep_positions=False,
        )
        result.observables["m"].shape  # (chains, 1000, 3)
    """
    initial_positions, num_chains = _as_positions(initial_positions)
    observe, observables_key = _as_observables(observables, keep_positions)
    observable_example = None if observe is None else _observable_shapes(observe, initial_positions)
    _check_run_arguments(num_draws, num_warmup, thinning, on_nonfinite, chunk_draws, adapt)
    rng_key = prng_key(rng_key)
    min_acceptance_rate = finite_float("min_acceptance_rate", min_acceptance_rate, nonnegative=True)
    if not isinstance(resume, bool):
        raise TypeError(f"resume must be a bool, got {resume!r}")
    if resume and output is None:
        raise ValueError("resume=True needs output= (the file the run was saved to)")
    finite = np.all(
        [
            np.isfinite(np.asarray(leaf)).reshape(num_chains, -1).all(axis=1)
            for leaf in jax.tree.leaves(initial_positions)
        ],
        axis=0,
    )
    if not finite.all():
        raise ValueError(f"initial_positions[{int(np.argmin(finite))}] must be finite")
    sharding = chain_sharding(devices, num_chains)
    sampler = as_sampler(algorithm)
    adapting = _wants_adaptation(sampler, adapt, num_warmup, type(algorithm).__name__)
    # The step size left unset and not adapted: the sampler's own choice for these starts.
    choosing = not adapting and sampler.tuning is not None and not sampler.tuning.given
    # Concrete checks (shape, orbit, constraints, energy, step size) of every start.
    _check_starts(
        sampler, initial_positions, num_chains, step_size_checks=not (adapting or choosing)
    )
    if choosing:
        sampler = choose_from_starts(sampler, initial_positions)
        _check_starts(sampler, initial_positions, num_chains)
    states = jax.vmap(sampler.init)(initial_positions)
    chain_keys = jax.random.split(rng_key, num_chains)

    states, chain_keys = shard_chains((states, chain_keys), sharding)
    run_warmup = num_warmup > 0
    if adapting:
        # From the initial states and deterministic given rng_key: a resumed run re-derives
        # the same parameters.
        sampler, adapted = warm_up(
            sampler, rng_key, chain_keys, states, initial_positions, num_warmup
        )
        _check_starts(sampler, initial_positions, num_chains)
        if adapted is not None:
            run_warmup = False
            states = adapted

    store = None
    done = 0
    previous = None
    if output is not None:
        store = _ChainStore(
            output,
            rng_key,
            initial_positions,
            num_warmup=num_warmup,
            thinning=thinning,
            observables=observable_example,
            keep_positions=keep_positions,
        )
        if store.exists():
            if not resume:
                raise FileExistsError(
                    f"output {os.fspath(output)!r} exists; pass resume=True to continue the run "
                    "saved there, or choose another path"
                )
            done, saved_states, previous = store.load(states, num_draws)
            if done:
                states = shard_chains(saved_states, sharding)
                run_warmup = False

    # One loop for every sampler (liesample.integrators.chain_loop): per-step keys, or noise blocks
    # for the samplers that declare them.
    @jit
    def warmup(states, keys, first_step):
        return jax.vmap(lambda s, k: run_steps(sampler, k, s, first_step, num_warmup)[0])(
            states, keys
        )

    if observe is None:
        record = None  # the positions themselves (the default loop, unchanged)
    elif keep_positions:
        record = lambda position: (position, observe(position))
    else:
        record = observe

    def draws(state, key, first_step, count):
        return run_draws(
            sampler, key, state, first_step, count, thinning, reduce_over_thinning, record
        )

    def split(recorded):
        """``(positions, observables)`` of one chunk's recorded values."""
        if observe is None:
            return recorded, None
        return recorded if keep_positions else (None, recorded)

    chunk = chunk_draws if chunk_draws is not None else max(1, math.ceil(num_draws / 20))
    run_chunk = jit(
        lambda states, keys, first_step, count: jax.vmap(
            lambda s, k: draws(s, k, first_step, count)
        )(states, keys),
        static_argnums=3,
    )
    remaining = num_draws - done
    # Compile outside the timed region (one chunk shape, plus the last partial one), once per
    # sampler and chain shapes: running the same sampler again (a resumed run, more draws)
    # reuses the executables.
    signature = _signature((states, chain_keys))
    if run_warmup:
        warmup = _compiled_once(
            ("warmup", sampler, num_warmup, signature),
            lambda: warmup.lower(states, chain_keys, 0).compile(),
        )
    compiled = {}
    if remaining:
        for count in {min(chunk, remaining), remaining % chunk or chunk}:
            recorded = () if observe is None else (observables_key, keep_positions)
            compiled[count] = _compiled_once(
                ("draws", sampler, thinning, count, signature, *recorded),
                lambda count=count: run_chunk.lower(states, chain_keys, 0, count).compile(),
            )

    positions, infos, observed = [], [], []
    if previous is not None:
        positions.append(previous[0])
        infos.append(previous[1])
        observed.append(previous[2])
    start = time.perf_counter()
    if run_warmup:
        states = jax.block_until_ready(warmup(states, chain_keys, 0))
    bar = tqdm(
        total=num_draws,
        initial=done,
        disable=not progress,
        unit="draw",
        desc=f"{num_chains} chains",
    )
    while done < num_draws:
        count = min(chunk, num_draws - done)
        states, (chunk_recorded, chunk_info) = compiled[count](
            states, chain_keys, num_warmup + done * thinning
        )
        chunk_recorded, chunk_info = to_host((chunk_recorded, chunk_info))
        chunk_positions, chunk_observed = split(chunk_recorded)
        positions.append(chunk_positions)
        infos.append(chunk_info)
        observed.append(chunk_observed)
        if store is not None:
            store.append(done, chunk_positions, chunk_info, to_host(states), chunk_observed)
        done += count
        bar.update(count)
        if store is not None and _after_chunk_hook is not None:
            _after_chunk_hook(done)
    bar.close()
    wall_time = time.perf_counter() - start

    info = {name: np.concatenate([i[name] for i in infos], axis=1) for name in infos[0]}

    def joined(chunks):
        if chunks[0] is None:
            return None
        return jax.tree.map(lambda *pieces: np.concatenate(pieces, axis=1), *chunks)

    result = ChainsResult(
        joined(positions),
        info,
        wall_time,
        num_warmup + num_draws * thinning,
        dict(sampler.settings, num_warmup=num_warmup, adapted=adapting),
        joined(observed),
    )
    _report_divergences(result, on_nonfinite)
    _report_stuck_chains(result, min_acceptance_rate)
    groups = None if sampler.law_groups is None else sampler.law_groups(initial_positions)
    _report_unconverged(result, groups)
    return result


_COMPILED_LIMIT = 16
_compiled: dict = {}  # key -> executable, least recently used first


def _compiled_once(key, compile_now):
    """The executable for ``key``, compiled by ``compile_now()`` the first time it is asked for
    (the ``_COMPILED_LIMIT`` most recently used are kept). ``key`` names the sampler (its
    ``init`` and ``step`` functions), every static argument and the chains' shapes."""
    if key in _compiled:
        _compiled[key] = _compiled.pop(key)
        return _compiled[key]
    executable = _compiled[key] = compile_now()
    while len(_compiled) > _COMPILED_LIMIT:
        del _compiled[next(iter(_compiled))]
    return executable


def _signature(tree):
    """What a compiled executable is specialised to: the tree's structure and each leaf's shape,
    dtype and sharding."""
    return jax.tree.structure(tree), tuple(
        (leaf.shape, leaf.dtype, getattr(leaf, "sharding", None)) for leaf in jax.tree.leaves(tree)
    )


def _chain_list(chains, limit=10) -> str:
    shown = ", ".join(str(int(c)) for c in chains[:limit])
    return shown + (f", … ({len(chains)} in all)" if len(chains) > limit else "")


def _report_divergences(result: ChainsResult, on_nonfinite: str):
    flags = result.info.get("is_divergent")
    if flags is None or not np.any(flags):
        return
    chains = np.flatnonzero(np.any(flags, axis=1))
    message = (
        f"{int(np.sum(flags))} draws in {len(chains)} chain(s) (chains {_chain_list(chains)}) "
        "contain a divergent step (a non-finite state or energy, or for the Metropolis-adjusted "
        "samplers an energy error above the divergence threshold); those steps were rejected "
        "and flagged in info['is_divergent'] (sample_stats 'diverging'). Reduce step_size or "
        "sigma, or let the warm-up adapt it."
    )
    raise_or_warn(message, on_nonfinite == "raise", NonFiniteStateError, RuntimeWarning, 3)


def _report_stuck_chains(result: ChainsResult, threshold: float):
    rates = result.info.get("acceptance_rate")
    if rates is None or threshold == 0.0:
        return
    per_chain = np.mean(rates, axis=1)
    chains = np.flatnonzero(per_chain < threshold)
    if chains.size == 0:
        return
    worst = ", ".join(f"chain {int(c)}: {per_chain[c]:.3f}" for c in chains[:5])
    warnings.warn(
        f"{len(chains)} chain(s) are stuck: their mean acceptance rate is below "
        f"{threshold:g} (chains {_chain_list(chains)}; {worst}). Use a smaller step_size, or "
        "let the warm-up adapt it (leave step_size unset and pass num_warmup > 0).",
        RuntimeWarning,
        stacklevel=3,
    )


def split_rhat(values) -> float:
    """Split R-hat (Gelman et al.) of ``values (chains, draws)``: NaN where it is undefined (one
    chain, few draws, or no spread within chains)."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[0] < 2 or values.shape[1] < 8:
        return math.nan
    half = values.shape[1] // 2
    halves = np.concatenate([values[:, :half], values[:, -half:]])
    within = np.mean(np.var(halves, axis=1, ddof=1))
    between = half * np.var(np.mean(halves, axis=1), ddof=1)
    if not (np.isfinite(within) and within > 0):
        return math.nan
    return float(np.sqrt(((half - 1) / half * within + between / half) / within))


def _varies(values) -> bool:
    """Whether ``values`` vary by more than ``1e-9`` of their size (more than round-off)."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    return finite.size > 0 and np.ptp(finite) > 1e-9 * max(np.max(np.abs(finite)), 1e-300)


def _report_unconverged(result: ChainsResult, groups):
    energy = result.info.get("energy")
    if energy is None or np.ndim(energy) != 2:
        return
    groups = np.zeros(len(energy), int) if groups is None else np.asarray(groups)
    # An energy constant to round-off (a Casimir, as for the isotropic rigid body) says nothing
    # about mixing: its R-hat would compare round-off.
    chains = [energy[groups == label] for label in np.unique(groups)]
    rhats = [split_rhat(group) for group in chains if _varies(group)]
    rhat = max((r for r in rhats if np.isfinite(r)), default=math.nan)
    if rhat > MAX_ENERGY_RHAT:
        warnings.warn(
            f"the chains disagree: the split R-hat of their energy is {rhat:.3g} > "
            f"{MAX_ENERGY_RHAT:g}, so they have not forgotten their starts or do not sample one "
            "law. Run longer (num_warmup, num_draws), start the chains from more spread-out "
            "points, or for an unadjusted sampler reduce step_size.",
            RuntimeWarning,
            stacklevel=3,
        )


def _report_convergence(posterior, groups):
    """One ``UserWarning`` with the messages of
    :func:`liesample.analysis.convergence.convergence_warnings` on every element of every
    variable of ``posterior`` (a tree's group: positions and observables), within each law
    group."""
    variables = {name: variable.values for name, variable in posterior.data_vars.items()}
    messages = convergence_warnings(variables, groups)
    if messages:
        warnings.warn("convergence checks: " + "; ".join(messages) + ".", UserWarning, stacklevel=3)


# --------------------------------------------------------------------------- saved runs


def _key_data(rng_key) -> np.ndarray:
    rng_key = jnp.asarray(rng_key) if not isinstance(rng_key, jax.Array) else rng_key
    if jnp.issubdtype(rng_key.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(rng_key))
    return np.asarray(rng_key)


def _fingerprint(positions, layout) -> str:
    digest = hashlib.sha256(b"" if layout == "null" else layout.encode())
    for leaf in jax.tree.leaves(positions):
        array = np.ascontiguousarray(np.asarray(leaf))
        digest.update(array.tobytes())
        digest.update(f"{array.dtype.str}{array.shape}".encode())
    return digest.hexdigest()


def _layout(positions):
    """The pytree structure of ``positions`` as JSON-able nested lists (``None`` for one array):
    ``["dict", [[key, sub], …]]``, ``["tuple", [sub, …]]``, ``["list", [sub, …]]`` or
    ``["leaf", i]``, leaves numbered in ``jax.tree.leaves`` order. Named tuples are recorded as
    dicts of their fields."""
    if is_single_array(positions):
        return None
    count = [0]

    def walk(node):
        if isinstance(node, dict):
            if not all(isinstance(key, str) for key in node):
                raise TypeError(
                    "output= saves dict positions with string keys only; got keys "
                    f"{sorted(map(repr, node))}"
                )
            return ["dict", [[key, walk(node[key])] for key in sorted(node)]]
        if isinstance(node, tuple) and hasattr(node, "_fields"):
            return ["dict", [[name, walk(getattr(node, name))] for name in node._fields]]
        if isinstance(node, (tuple, list)):
            return [type(node).__name__, [walk(item) for item in node]]
        count[0] += 1
        return ["leaf", count[0] - 1]

    layout = walk(positions)
    if count[0] != len(jax.tree.leaves(positions)):
        raise TypeError(
            "output= saves positions made of arrays in dicts, tuples and lists; this pytree has "
            f"other nodes ({jax.tree.structure(positions)})"
        )
    return layout


def _rebuild(layout, leaves):
    """The pytree that :func:`_layout` described, with ``leaves``."""
    kind, content = layout
    if kind == "leaf":
        return leaves[content]
    if kind == "dict":
        return {key: _rebuild(sub, leaves) for key, sub in content}
    items = [_rebuild(sub, leaves) for sub in content]
    return tuple(items) if kind == "tuple" else items


def _position_names(layout, num_leaves, prefix="position"):
    return [prefix] if layout is None else [f"{prefix}_{i}" for i in range(num_leaves)]


def _to_stored(leaf):
    """Complex draws are stored as a trailing (real, imag) axis (NetCDF has no complex type),
    booleans as ``uint8``."""
    leaf = np.asarray(leaf)
    if leaf.dtype == bool:
        return leaf.astype(np.uint8)
    return np.stack([leaf.real, leaf.imag], axis=-1) if np.iscomplexobj(leaf) else leaf


def _from_stored(variable, value):
    dtype = np.dtype(variable.attrs.get("dtype", value.dtype.str))
    if dtype.kind == "c":
        return (value[..., 0] + 1j * value[..., 1]).astype(dtype)
    return value.astype(dtype)


def _read_positions(f, layout, done, prefix="position"):
    names = sorted(
        (name for name in f.variables if name == prefix or name.startswith(f"{prefix}_")),
        key=lambda name: int(name[len(prefix) + 1 :] or 0),
    )
    leaves = [_from_stored(f.variables[n], np.asarray(f.variables[n][:, :done])) for n in names]
    return leaves[0] if layout is None else _rebuild(layout, leaves)


def _read_observables(f, done):
    """The observables saved in ``f`` (``None`` if the run recorded none)."""
    layout = json.loads(f.attrs.get("observables_layout", '"none"'))
    if layout == "none":
        return None
    return _read_positions(f, layout, done, prefix="observable")


def _write_variables(f, prefix, layout, tree, dims_prefix):
    """Create one variable per leaf of ``tree`` (``(chain, draw, *shape)``), named
    :func:`_position_names`, with dims ``<dims_prefix(name)>_<j>``."""
    leaves = jax.tree.leaves(tree)
    for name, leaf in zip(_position_names(layout, len(leaves), prefix), leaves, strict=True):
        stored = _to_stored(leaf)
        dims = tuple(f"{dims_prefix(name)}_{j}" for j in range(stored.ndim - 2))
        for dim, size in zip(dims, stored.shape[2:], strict=True):
            f.dimensions[dim] = size
        variable = f.create_variable(name, ("chain", "draw", *dims), stored.dtype)
        variable.attrs["dtype"] = np.asarray(leaf).dtype.str


def _append_variables(f, prefix, layout, tree, first_draw, end):
    leaves = jax.tree.leaves(tree)
    for name, leaf in zip(_position_names(layout, len(leaves), prefix), leaves, strict=True):
        f.variables[name][:, first_draw:end] = _to_stored(leaf)


class _ChainStore:
    """A run saved in one NetCDF-4 file (h5netcdf), grown chunk by chunk.

    Layout: dims ``chain``, ``draw`` (unlimited); the draws as ``position``
    ``(chain, draw, *event)`` (dims ``event_<j>``), or for pytree positions one variable
    ``position_<i>`` per leaf (dims ``position_<i>_dim_<j>``; complex leaves with a trailing
    ``(real, imag)`` axis) and the structure as the JSON attribute ``position_layout``;
    ``info_<name>`` ``(chain, draw)``, and the states after the last saved chunk, ``state_<i>``
    (leaf ``i`` of the state pytree, ``(chain, ...)``). Observables, if recorded, as
    ``observable`` or ``observable_<i>`` (dims ``observable[_<i>]_dim_<j>``) with their
    structure as the JSON attribute ``observables_layout`` (``"none"``: no observables); the
    positions are absent when ``keep_positions`` (attribute, 0 or 1) is 0. Attributes:
    ``draws_done`` (written last, so a chunk interrupted while being written is ignored),
    ``num_warmup``, ``thinning``, ``key_data`` and a fingerprint of the initial positions. Each
    chunk opens and closes the file, so a run killed between chunks leaves a valid file.
    """

    def __init__(
        self,
        path,
        rng_key,
        initial_positions,
        *,
        num_warmup,
        thinning,
        observables=None,
        keep_positions=True,
    ):
        self.path = os.fspath(path)
        self.key_data = _key_data(rng_key)
        self.layout = _layout(initial_positions)
        self.layout_json = json.dumps(self.layout)
        self.fingerprint = _fingerprint(initial_positions, self.layout_json)
        self.treedef = jax.tree.structure(initial_positions)
        self.num_chains = int(jax.tree.leaves(initial_positions)[0].shape[0])
        self.num_warmup = int(num_warmup)
        self.thinning = int(thinning)
        self.keep_positions = bool(keep_positions)
        # observables: shapes and dtypes of the recorded pytree (chain axis first), or None
        self.observables_layout = "none" if observables is None else _layout(observables)
        self.observables_signature = (
            "none"
            if observables is None
            else json.dumps(
                [[list(leaf.shape[1:]), leaf.dtype.str] for leaf in jax.tree.leaves(observables)]
            )
        )
        self.created = False

    def exists(self) -> bool:
        return os.path.exists(self.path)

    def _check_compatible(self, attrs):
        expected = {
            "format": _FORMAT,
            "initial_positions_sha256": self.fingerprint,
            "num_warmup": self.num_warmup,
            "thinning": self.thinning,
            "keep_positions": int(self.keep_positions),
            "observables_layout": json.dumps(self.observables_layout),
            "observables_signature": self.observables_signature,
        }
        # files written before observables existed: positions kept, no observables
        defaults = {
            "keep_positions": 1,
            "observables_layout": '"none"',
            "observables_signature": "none",
        }
        for name, value in expected.items():
            saved = attrs.get(name, defaults.get(name))
            saved = saved.item() if isinstance(saved, np.ndarray) and saved.ndim == 0 else saved
            if saved != value:
                raise ValueError(
                    f"cannot resume from {self.path!r}: it was saved with a different {name} "
                    f"({saved!r}, now {value!r})"
                )
        if not np.array_equal(np.asarray(attrs.get("key_data")), self.key_data.reshape(-1)):
            raise ValueError(
                f"cannot resume from {self.path!r}: it was saved with a different rng_key"
            )

    def load(self, states, num_draws):
        """``(draws_done, states, (positions, info, observables))`` of the saved run (``states``
        gives the pytree structure and dtypes)."""
        import h5netcdf

        with h5netcdf.File(self.path, "r") as f:
            self._check_compatible(dict(f.attrs))
            done = int(f.attrs["draws_done"])
            if done > num_draws:
                raise ValueError(
                    f"cannot resume from {self.path!r} with num_draws={num_draws}: it already "
                    f"holds {done} draws"
                )
            self.created = True
            if done == 0:
                return 0, None, None
            positions = None
            if self.keep_positions:
                positions = _read_positions(f, self.layout, done)
                if self.layout is not None:  # the caller's own node types (named tuples, …)
                    positions = jax.tree.unflatten(self.treedef, jax.tree.leaves(positions))
            observables = _read_observables(f, done)
            info = {}
            for name, variable in f.variables.items():
                if name.startswith("info_"):
                    value = np.asarray(variable[:, :done])
                    info[name[5:]] = value.astype(variable.attrs["dtype"])
            leaves, treedef = jax.tree.flatten(states)
            saved = []
            for i, leaf in enumerate(leaves):
                value = np.asarray(f.variables[f"state_{i}"][...])
                if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
                    saved.append(jax.random.wrap_key_data(value, impl=jax.random.key_impl(leaf)))
                else:
                    value = _from_stored(f.variables[f"state_{i}"], value)
                    saved.append(jnp.asarray(value.astype(leaf.dtype)))
                if saved[-1].shape != leaf.shape:
                    raise ValueError(
                        f"cannot resume from {self.path!r}: saved state leaf {i} has shape "
                        f"{saved[-1].shape}, the sampler's has {leaf.shape}"
                    )
        return done, jax.tree.unflatten(treedef, saved), (positions, info, observables)

    def _create(self, positions, info, states, observables):
        import h5netcdf

        with h5netcdf.File(self.path, "w") as f:
            f.dimensions = {"chain": self.num_chains, "draw": None}
            if positions is not None:
                _write_variables(
                    f,
                    "position",
                    self.layout,
                    positions,
                    lambda name: "event" if self.layout is None else f"{name}_dim",
                )
            if observables is not None:
                _write_variables(
                    f, "observable", self.observables_layout, observables, "{}_dim".format
                )
            for name, value in info.items():
                stored = np.uint8 if value.dtype == bool else value.dtype
                variable = f.create_variable(f"info_{name}", ("chain", "draw"), stored)
                variable.attrs["dtype"] = value.dtype.str
            for i, leaf in enumerate(jax.tree.leaves(states)):
                stored = _to_stored(leaf)
                dims = tuple(f"state_{i}_dim_{j}" for j in range(1, stored.ndim))
                for dim, size in zip(dims, stored.shape[1:], strict=True):
                    f.dimensions[dim] = size
                variable = f.create_variable(f"state_{i}", ("chain", *dims), stored.dtype)
                variable.attrs["dtype"] = leaf.dtype.str
            f.attrs["format"] = _FORMAT
            if self.layout is not None:
                f.attrs["position_layout"] = self.layout_json
            f.attrs["initial_positions_sha256"] = self.fingerprint
            f.attrs["num_warmup"] = self.num_warmup
            f.attrs["thinning"] = self.thinning
            f.attrs["keep_positions"] = int(self.keep_positions)
            f.attrs["observables_layout"] = json.dumps(self.observables_layout)
            f.attrs["observables_signature"] = self.observables_signature
            f.attrs["key_data"] = self.key_data.reshape(-1)
            f.attrs["draws_done"] = 0
        self.created = True

    def append(self, first_draw, positions, info, states, observables=None):
        """Write draws ``first_draw …`` (positions and/or observables, info) and the states
        after them; then mark them done."""
        import h5netcdf

        states = jax.tree.map(
            lambda leaf: (
                np.asarray(jax.random.key_data(leaf))
                if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key)
                else np.asarray(leaf)
            ),
            states,
        )
        if not self.created:
            self._create(positions, info, states, observables)
        end = first_draw + jax.tree.leaves((positions, observables))[0].shape[1]
        with h5netcdf.File(self.path, "a") as f:
            f.resize_dimension("draw", end)
            if positions is not None:
                _append_variables(f, "position", self.layout, positions, first_draw, end)
            if observables is not None:
                _append_variables(
                    f, "observable", self.observables_layout, observables, first_draw, end
                )
            for name, value in info.items():
                f.variables[f"info_{name}"][:, first_draw:end] = value
            for i, leaf in enumerate(jax.tree.leaves(states)):
                f.variables[f"state_{i}"][...] = _to_stored(leaf)
            f.attrs["draws_done"] = end


def load_chains(path) -> ChainsResult:
    """The draws saved by ``sample_chains(..., output=path)`` (complete or interrupted).

    ``wall_time`` is ``nan`` (not recorded) and ``num_steps`` counts warm-up and saved draws.
    Pytree positions and observables come back as dicts, tuples and lists (named tuples as
    dicts of their fields); ``positions`` is ``None`` for a run with ``keep_positions=False``.
    """
    import h5netcdf

    with h5netcdf.File(os.fspath(path), "r") as f:
        if f.attrs.get("format") != _FORMAT:
            raise ValueError(f"{os.fspath(path)!r} is not a file written by sample_chains")
        done = int(f.attrs["draws_done"])
        layout = f.attrs.get("position_layout")
        positions = None
        if int(f.attrs.get("keep_positions", 1)):
            positions = _read_positions(f, None if layout is None else json.loads(layout), done)
        observables = _read_observables(f, done)
        info = {
            name[5:]: np.asarray(v[:, :done]).astype(v.attrs["dtype"])
            for name, v in f.variables.items()
            if name.startswith("info_")
        }
        num_steps = int(f.attrs["num_warmup"]) + done * int(f.attrs["thinning"])
    return ChainsResult(positions, info, math.nan, num_steps, observables=observables)


def _saved_num_warmup(run_options) -> int | None:
    """The ``num_warmup`` of the run that ``resume=True`` continues, if its file exists."""
    output = run_options.get("output")
    if not run_options.get("resume") or output is None or not os.path.exists(output):
        return None
    import h5netcdf

    with h5netcdf.File(output, "r") as f:
        return int(f.attrs["num_warmup"])


def sample(
    algorithm,
    rng_key,
    initial_positions,
    num_draws: int,
    *,
    num_warmup: int | None = None,
    var_name: str | None = None,
    event_dims=None,
    coords=None,
    attrs=None,
    **run_options,
):
    """Run chains with :func:`sample_chains` and return an ArviZ ``DataTree``.

    The tree has ``posterior/<var_name>`` with dims ``(chain, draw, *event_dims)`` and
    ``sample_stats`` under ArviZ's names (``diverging``, ``acceptance_rate``, ``energy``, and
    the sampler's own fields such as ``casimir_error``); its attributes record the wall time,
    the number of steps, the sampler's settings (``sampler``, ``step_size`` and
    ``step_size_source``, ``stability`` mode and ``stability_number``, …), whether the warm-up
    adapted, and ``attrs``.

    Parameters
    ----------
    algorithm, rng_key, initial_positions, num_draws
        As for :func:`sample_chains`.
    num_warmup : int, optional
        Steps run and discarded before the first draw (the sampler adapts there). Default:
        as many steps as the draws span (``num_draws * thinning``): chains started from
        arbitrary points forget their starts before anything is kept, and a sampler built
        without a step size tunes it there. ``0`` keeps every step from the starts and warns,
        unless ``exact_starts=True`` says the starts are already draws from the target.
    var_name, event_dims
        Name and event dims of single-array positions. Default: the sampler's declaration
        (``R`` with dims ``(row, col)`` for ``SO(n)``, ``U`` for ``SU(n)``), else ``mu`` with
        dims named from the event's rank (``component``; ``row, col``). Pytree positions give
        one variable per leaf, named from its key path (``mu``, ``log_kappa``; tuple entries
        ``x0``, ``x1``…; nested keys joined with ``.``), with dims ``<name>_dim_k``
        (``event_dims`` may map a leaf's name to other dims); a complex leaf ``U`` is split into
        ``U.real`` and ``U.imag`` (:func:`liesample.analysis.diagnostics.to_datatree`). Names,
        dims and ``coords`` are checked against the starts before any sampling.
    coords, attrs
        Coordinates by dim name, and extra attributes for the tree.
    run_options
        The other keywords of :func:`sample_chains`: ``thinning``, ``progress``,
        ``chunk_draws``, ``on_nonfinite``, ``devices``, ``output``, ``resume``, ``adapt``,
        ``min_acceptance_rate``, ``observables``, ``keep_positions``; and ``exact_starts``
        (bool, default False).

    ``observables=`` (a function of one chain's position, or a dict ``{name: function}``)
    records those values at every draw and adds them to ``posterior`` (a dict's keys name
    them, a single array is ``observable``; dims ``<name>_dim_k``, or as ``event_dims`` maps
    them for pytree positions), so that ``az.summary``, ESS and R-hat act on them; with
    ``keep_positions=False`` the posterior holds only the observables. For example
    ``sample(liesample.heisenberg_heat_bath(system, beta=1.0), key, starts, 1000,
    observables={"h": system.hamiltonian}, keep_positions=False)`` gives ``posterior/h``.

    ArviZ's ESS and R-hat of these variables are those of the ambient coordinates (vector
    components, matrix entries), not of intrinsic coordinates on the group or sphere.

    Every element of every posterior variable is then checked
    (:func:`liesample.analysis.convergence.convergence_warnings`, within the sampler's law
    groups): one ``UserWarning`` names those whose rank-normalised split R-hat is above 1.01
    or whose bulk or tail ESS is below 100 per chain, and says when one chain or too few draws
    make the checks impossible.

    Example: ``sample(liesample.adjusted_lie_poisson(system, beta=1.0), key, starts, 1000)``
    tunes the step size by dual averaging in a warm-up of 1000 steps, then samples.
    """
    from liesample.analysis.diagnostics import to_datatree

    exact_starts = run_options.pop("exact_starts", False)
    if not isinstance(exact_starts, bool):
        raise TypeError(f"exact_starts must be a bool, got {exact_starts!r}")
    thinning = run_options.get("thinning", 1)
    if num_warmup is None:
        num_warmup = _saved_num_warmup(run_options)
    if num_warmup is None:
        _check_run_arguments(num_draws, 0, thinning, "warn", None, None)
        num_warmup = int(num_draws) * int(thinning)
    elif num_warmup == 0 and not exact_starts:
        warnings.warn(
            "num_warmup=0: every step from initial_positions is kept; unless the starts are "
            "draws from the target (then pass exact_starts=True), the draws are biased towards "
            "them. Leave num_warmup unset for a warm-up as long as the run.",
            UserWarning,
            stacklevel=2,
        )
    positions, _ = _as_positions(initial_positions)
    keep_positions = run_options.get("keep_positions", True)
    observe, _ = _as_observables(run_options.get("observables"), keep_positions)
    names = as_sampler(algorithm).draw_names
    if (
        keep_positions
        and var_name is None
        and event_dims is None
        and names is not None
        and is_single_array(positions)
        and np.ndim(positions) - 1 == len(names.event_dims)
    ):
        var_name, event_dims = names
    # the names, dims and coords of the draws, checked on the starts before any work
    datatree = functools.partial(
        to_datatree, var_name=var_name, event_dims=event_dims, coords=coords
    )
    example_observables = None
    if observe is not None:
        example_observables = jax.tree.map(
            lambda leaf: np.zeros((leaf.shape[0], 1, *leaf.shape[1:]), leaf.dtype),
            _observable_shapes(observe, positions),
        )
    example_positions = None
    if keep_positions:
        example_positions = jax.tree.map(lambda leaf: np.asarray(leaf)[:, None], positions)
    with warnings.catch_warnings():  # ArviZ remarks on a tree of one draw
        warnings.simplefilter("ignore", UserWarning)
        datatree(example_positions, observables=example_observables)

    result = sample_chains(
        algorithm, rng_key, initial_positions, num_draws, num_warmup=num_warmup, **run_options
    )
    settings = {
        k: v for k, v in (result.settings or {}).items() if k not in ("num_warmup", "step_size")
    }
    tree = datatree(
        result.positions,
        result.info,
        observables=result.observables,
        thinning=thinning,
        step_size=(result.settings or {}).get("step_size"),
        attrs={
            "wall_time_seconds": result.wall_time,
            "num_steps": result.num_steps,
            "num_warmup": num_warmup,
            "on_nonfinite": run_options.get("on_nonfinite", "warn"),
            **settings,
            **(attrs or {}),
        },
    )
    law_groups = as_sampler(algorithm).law_groups
    _report_convergence(tree.posterior, None if law_groups is None else law_groups(positions))
    return tree
