"""Run many chains of a BlackJAX-style sampler, vmapped, in chunks with a progress bar.

Draw ``d`` of chain ``c`` uses the key ``fold_in(key_c, step)``, so the draws do not depend on
the chunk size and a run can be split or resumed without changing them.

- **Devices.** ``devices=`` splits the chain axis over several devices with JAX's own sharding
  (:mod:`liesample.sharding`); the draws are those of the unsharded run.
- **Long runs lose nothing.** ``output=`` writes every chunk of draws, and the chain states after
  it, to a NetCDF-4 file (h5netcdf, growing ``draw`` dimension) as soon as the chunk is done;
  ``resume=True`` continues a run from the last chunk saved there, after an interruption or to
  extend it to more draws, and returns the same draws as an uninterrupted run (bitwise).
"""

from __future__ import annotations

import hashlib
import math
import os
import time
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from liesample.compile import jit
from liesample.sharding import chain_sharding, shard_chains, to_host

# How per-step info is summarised over the steps a thinned draw spans.
_REDUCE_OVER_THINNING = {"nonfinite": jnp.any, "casimir_error": jnp.max}

# Test hook: called as ``_after_chunk_hook(draws_done)`` once a chunk is saved to ``output``
# (tests/test_resume.py kills the process there to simulate an interruption).
_after_chunk_hook = None

_FORMAT = "liesample-chains-1"


class NonFiniteStateError(FloatingPointError):
    """A chain produced a non-finite state (the sampler kept the previous one and flagged it)."""


@dataclass(frozen=True)
class ChainsResult:
    """Draws of ``positions`` with shape ``(chains, draws, *event_shape)``, per-draw ``info``
    arrays with shape ``(chains, draws)``, and the sampling wall time in seconds (compilation
    excluded; on a resumed run, the time of this session only)."""

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
        Show a progress bar (tqdm) over the draws (on a resumed run it starts at the draws
        already saved).
    chunk_draws : int, optional
        Draws per compiled chunk (default: about 20 chunks); also the unit of saving.
    on_nonfinite : {"warn", "raise"}
        What to do if any step produced a non-finite state (``info.nonfinite``).
    devices : None, "all", int, sequence of jax devices, or NamedSharding
        Split the chains over these devices (:func:`liesample.sharding.chain_sharding`); the
        number of chains must be a multiple of the number of devices. ``None``: one device.
    output : str or path, optional
        NetCDF file to which each chunk of draws and info, and the chain states after it, are
        written as soon as the chunk is done (:func:`load_chains` reads it back, so does
        ``xarray.open_dataset``). Refuses an existing file unless ``resume=True``.
    resume : bool
        Continue the run saved in ``output``: same ``algorithm``, ``rng_key``,
        ``initial_positions``, ``num_warmup`` and ``thinning`` (checked, except the algorithm);
        ``num_draws`` may be larger than before to extend it. Starts afresh if the file does not
        exist yet. The returned draws include the saved ones and equal those of one
        uninterrupted run.
    """
    _check_run_arguments(
        initial_positions, num_draws, num_warmup, thinning, on_nonfinite, chunk_draws
    )
    if not isinstance(resume, bool):
        raise TypeError(f"resume must be a bool, got {resume!r}")
    if resume and output is None:
        raise ValueError("resume=True needs output= (the file the run was saved to)")
    initial_positions = jnp.asarray(initial_positions)
    num_chains = initial_positions.shape[0]
    if not np.all(np.isfinite(np.asarray(initial_positions))):
        raise ValueError("initial_positions must be finite")
    sharding = chain_sharding(devices, num_chains)
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

    store = None
    done = 0
    previous = None
    if output is not None:
        store = _ChainStore(
            output, rng_key, initial_positions, num_warmup=num_warmup, thinning=thinning
        )
        if store.exists():
            if not resume:
                raise FileExistsError(
                    f"output {os.fspath(output)!r} exists; pass resume=True to continue the run "
                    "saved there, or choose another path"
                )
            done, saved_states, previous = store.load(states, num_draws)
            if done:
                states = saved_states

    states, chain_keys = shard_chains((states, chain_keys), sharding)

    def advance(state, key, first_step, num_steps):
        def one(state, step):
            return algorithm.step(jax.random.fold_in(key, step), state)

        return jax.lax.scan(one, state, first_step + jnp.arange(num_steps))

    @jit
    def warmup(states, keys, first_step):
        return jax.vmap(lambda s, k: advance(s, k, first_step, num_warmup)[0])(states, keys)

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
    run_chunk = jit(
        lambda states, keys, first_step, count: jax.vmap(
            lambda s, k: draws(s, k, first_step, count)
        )(states, keys),
        static_argnums=3,
    )
    remaining = num_draws - done
    run_warmup = num_warmup > 0 and done == 0
    # Compile outside the timed region (one chunk shape, plus the last partial one).
    if run_warmup:
        warmup = warmup.lower(states, chain_keys, 0).compile()
    compiled = {}
    if remaining:
        for count in {min(chunk, remaining), remaining % chunk or chunk}:
            compiled[count] = run_chunk.lower(states, chain_keys, 0, count).compile()

    positions, infos = [], []
    if previous is not None:
        positions.append(previous[0])
        infos.append(previous[1])
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
        states, (chunk_positions, chunk_info) = compiled[count](
            states, chain_keys, num_warmup + done * thinning
        )
        chunk_positions, chunk_info = to_host((chunk_positions, chunk_info))
        positions.append(chunk_positions)
        infos.append(chunk_info)
        if store is not None:
            store.append(done, chunk_positions, chunk_info, to_host(states))
        done += count
        bar.update(count)
        if store is not None and _after_chunk_hook is not None:
            _after_chunk_hook(done)
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


# --------------------------------------------------------------------------- saved runs


def _key_data(rng_key) -> np.ndarray:
    rng_key = jnp.asarray(rng_key) if not isinstance(rng_key, jax.Array) else rng_key
    if jnp.issubdtype(rng_key.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(rng_key))
    return np.asarray(rng_key)


def _fingerprint(array) -> str:
    array = np.ascontiguousarray(np.asarray(array))
    digest = hashlib.sha256(array.tobytes())
    digest.update(f"{array.dtype.str}{array.shape}".encode())
    return digest.hexdigest()


class _ChainStore:
    """A run saved in one NetCDF-4 file (h5netcdf), grown chunk by chunk.

    Layout: dims ``chain``, ``draw`` (unlimited), ``event_<j>``; variables ``position``
    ``(chain, draw, *event)``, ``info_<name>`` ``(chain, draw)``, and the states after the last
    saved chunk, ``state_<i>`` (leaf ``i`` of the state pytree, ``(chain, ...)``). Attributes:
    ``draws_done`` (written last, so a chunk interrupted while being written is ignored),
    ``num_warmup``, ``thinning``, ``key_data`` and a fingerprint of the initial positions.
    Each chunk opens and closes the file, so a run killed between chunks leaves a valid file.
    """

    def __init__(self, path, rng_key, initial_positions, *, num_warmup, thinning):
        self.path = os.fspath(path)
        self.key_data = _key_data(rng_key)
        self.fingerprint = _fingerprint(initial_positions)
        self.num_chains = int(initial_positions.shape[0])
        self.event_shape = tuple(initial_positions.shape[1:])
        self.num_warmup = int(num_warmup)
        self.thinning = int(thinning)
        self.created = False

    def exists(self) -> bool:
        return os.path.exists(self.path)

    def _check_compatible(self, attrs):
        expected = {
            "format": _FORMAT,
            "initial_positions_sha256": self.fingerprint,
            "num_warmup": self.num_warmup,
            "thinning": self.thinning,
        }
        for name, value in expected.items():
            saved = attrs.get(name)
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
        """``(draws_done, states, (positions, info))`` of the saved run (``states`` gives the
        pytree structure and dtypes)."""
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
            positions = np.asarray(f.variables["position"][:, :done])
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
                    saved.append(jnp.asarray(value.astype(leaf.dtype)))
                if saved[-1].shape != leaf.shape:
                    raise ValueError(
                        f"cannot resume from {self.path!r}: saved state leaf {i} has shape "
                        f"{saved[-1].shape}, the sampler's has {leaf.shape}"
                    )
        return done, jax.tree.unflatten(treedef, saved), (positions, info)

    def _create(self, positions, info, states):
        import h5netcdf

        with h5netcdf.File(self.path, "w") as f:
            event_dims = tuple(f"event_{j}" for j in range(len(self.event_shape)))
            dimensions = {"chain": self.num_chains, "draw": None}
            dimensions.update(zip(event_dims, self.event_shape, strict=True))
            f.dimensions = dimensions
            f.create_variable("position", ("chain", "draw", *event_dims), positions.dtype)
            for name, value in info.items():
                stored = np.uint8 if value.dtype == bool else value.dtype
                variable = f.create_variable(f"info_{name}", ("chain", "draw"), stored)
                variable.attrs["dtype"] = value.dtype.str
            for i, leaf in enumerate(jax.tree.leaves(states)):
                dims = tuple(f"state_{i}_dim_{j}" for j in range(1, leaf.ndim))
                for dim, size in zip(dims, leaf.shape[1:], strict=True):
                    f.dimensions[dim] = size
                f.create_variable(f"state_{i}", ("chain", *dims), leaf.dtype)
            f.attrs["format"] = _FORMAT
            f.attrs["initial_positions_sha256"] = self.fingerprint
            f.attrs["num_warmup"] = self.num_warmup
            f.attrs["thinning"] = self.thinning
            f.attrs["key_data"] = self.key_data.reshape(-1)
            f.attrs["draws_done"] = 0
        self.created = True

    def append(self, first_draw, positions, info, states):
        """Write draws ``first_draw …`` and the states after them; then mark them done."""
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
            self._create(positions, info, states)
        end = first_draw + positions.shape[1]
        with h5netcdf.File(self.path, "a") as f:
            f.resize_dimension("draw", end)
            f.variables["position"][:, first_draw:end] = positions
            for name, value in info.items():
                f.variables[f"info_{name}"][:, first_draw:end] = value
            for i, leaf in enumerate(jax.tree.leaves(states)):
                f.variables[f"state_{i}"][...] = leaf
            f.attrs["draws_done"] = end


def load_chains(path) -> ChainsResult:
    """The draws saved by ``sample_chains(..., output=path)`` (complete or interrupted).

    ``wall_time`` is ``nan`` (not recorded) and ``num_steps`` counts warm-up and saved draws.
    """
    import h5netcdf

    with h5netcdf.File(os.fspath(path), "r") as f:
        if f.attrs.get("format") != _FORMAT:
            raise ValueError(f"{os.fspath(path)!r} is not a file written by sample_chains")
        done = int(f.attrs["draws_done"])
        positions = np.asarray(f.variables["position"][:, :done])
        info = {
            name[5:]: np.asarray(v[:, :done]).astype(v.attrs["dtype"])
            for name, v in f.variables.items()
            if name.startswith("info_")
        }
        num_steps = int(f.attrs["num_warmup"]) + done * int(f.attrs["thinning"])
    return ChainsResult(positions, info, math.nan, num_steps)


def sample(
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
    var_name: str = "mu",
    event_dims=("component",),
    coords=None,
    attrs=None,
):
    """Run chains with :func:`sample_chains` and return an ArviZ ``DataTree``.

    The tree has ``posterior/<var_name>`` with dims ``(chain, draw, *event_dims)`` and
    ``sample_stats`` (``energy``, ``diverging``, ``casimir_error``); its attributes record the
    wall time, the number of steps and ``attrs``. ``chunk_draws``, ``devices``, ``output`` and
    ``resume`` are passed to :func:`sample_chains` (sharded chains, incremental saving, resume).
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
        chunk_draws=chunk_draws,
        on_nonfinite=on_nonfinite,
        devices=devices,
        output=output,
        resume=resume,
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
