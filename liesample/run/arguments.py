"""The checks of a run's arguments, made before any compilation: the algorithm, the starts (an
array or a pytree with a leading chain axis), the observables, the counts and options, whether
the warm-up adapts, and whether the run's steps and kept draws fit.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.validation import finite_float, is_single_array
from liesample.samplers.contract import Sampler


def as_observables(observables, keep_positions):
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


def observable_shapes(observe, initial_positions):
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


ONE_START = (
    "One start without a chain axis (such as the state window_adaptation(...).run returns for "
    "a single start) is one chain as jax.tree.map(lambda x: x[None], position)."
)


def as_positions(initial_positions):
    """``initial_positions`` as a JAX array, or a pytree of JAX arrays, with a leading chain axis
    shared by every leaf (checked); returns ``(positions, num_chains)``."""
    if is_single_array(initial_positions):
        positions = jnp.asarray(initial_positions)
        if positions.ndim < 1 or positions.shape[0] < 1:
            raise ValueError(
                "initial_positions must have a leading chain axis with at least one chain, "
                f"shape (chains, ...); got shape {positions.shape}. {ONE_START}"
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
                f"(chains, ...); got shape {leaf.shape}. {ONE_START}"
            )
        if leaf.shape[0] != leaves[0].shape[0]:
            raise ValueError(
                "every leaf of initial_positions must have the same leading chain axis: "
                f"{names[0]} has {leaves[0].shape[0]} chains (shape {leaves[0].shape}), {name} "
                f"has {leaf.shape[0]} (shape {leaf.shape})"
            )
    return jax.tree.unflatten(treedef, leaves), leaves[0].shape[0]


def check_chain_axis(sampler: Sampler, positions, error: Exception | None = None) -> None:
    """A single-array ``positions`` that is one start, not starts with a leading chain axis
    (its first chain is no start for ``sampler`` but the whole array is), refused with the fix
    (raised from ``error``, the failed check of the starts that calls this probe). Shapes only
    (``jax.eval_shape`` of ``init``): nothing is compiled."""
    if not is_single_array(positions):
        return  # a pytree's leaves were checked for a shared chain axis (as_positions)
    try:
        jax.eval_shape(sampler.init, take_chain(positions, 0))
        return
    except Exception:  # a probe: the checks of the starts report what is wrong
        pass
    try:
        jax.eval_shape(sampler.init, positions)
    except Exception:  # not one start either: the checks of the starts report it
        return
    ones = ", 1" * positions.ndim
    raise ValueError(
        f"initial_positions needs a leading chain axis: its shape {positions.shape} is that of "
        f"one start (read as {positions.shape[0]} chains of shape {positions.shape[1:]}); pass "
        f"x[None] for one chain, or jnp.tile(x, (num_chains{ones})) for num_chains chains from "
        "it"
    ) from error


def take_chain(positions, chain):
    return jax.tree.map(lambda leaf: leaf[chain], positions)


def _integer(name, value, low):
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")


def check_run_arguments(num_draws, num_warmup, thinning, on_nonfinite, chunk_draws, adapt):
    """The counts (``num_draws >= 1``, ``num_warmup >= 0``, ``thinning >= 1``, ``chunk_draws``
    None or ``>= 1``), ``on_nonfinite`` and ``adapt``, each refused by name."""
    _integer("num_draws", num_draws, 1)
    _integer("num_warmup", num_warmup, 0)
    _integer("thinning", thinning, 1)
    if chunk_draws is not None and (
        not isinstance(chunk_draws, (int, np.integer))
        or isinstance(chunk_draws, bool)
        or chunk_draws < 1
    ):
        raise ValueError(f"chunk_draws must be None or an integer >= 1, got {chunk_draws!r}")
    if not isinstance(on_nonfinite, str) or on_nonfinite not in ("warn", "raise"):
        raise ValueError(f"on_nonfinite must be 'warn' or 'raise', got {on_nonfinite!r}")
    if adapt is not None and not isinstance(adapt, bool):
        raise TypeError(f"adapt must be None, True or False, got {adapt!r}")
    if adapt is True and num_warmup == 0:
        raise ValueError("adapt=True needs warm-up steps: pass num_warmup > 0")


def _flag(name, value, meaning):
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, True or False ({meaning}), got {value!r}")


def check_options(num_draws, options) -> None:
    """Every keyword of :func:`liesample.sample_chains` that is a plain value, refused by name
    with what is allowed, before anything is traced or compiled (``options``: its
    :class:`liesample.run.loop.RunOptions`; the observables, ``log_likelihood`` and ``devices``
    are checked where they are read)."""
    o = options
    check_run_arguments(num_draws, o.num_warmup, o.thinning, o.on_nonfinite, o.chunk_draws, o.adapt)
    _flag("progress_bar", o.progress_bar, "show a progress bar")
    _flag("keep_positions", o.keep_positions, "store the positions of every draw")
    rate = finite_float("min_acceptance_rate", o.min_acceptance_rate, nonnegative=True)
    if not rate < 1.0:
        raise ValueError(
            f"min_acceptance_rate must be in [0, 1), got {rate}: chains whose mean acceptance "
            "rate is below it are reported as stuck (0 disables the check)"
        )
    check_output(o.output, o.resume)
    if o.callback is not None and not callable(o.callback):
        raise TypeError(f"callback must be a function of draws_done, got {o.callback!r}")


def check_output(output, resume) -> None:
    """``output`` a path or None, ``resume`` a bool that needs ``output``."""
    _flag("resume", resume, "continue the run saved in output=")
    if output is not None and not isinstance(output, (str, os.PathLike)):
        raise TypeError(
            "output must be None or the path of the run file (a str or os.PathLike, e.g. "
            f"'run.nc'), got {type(output).__name__}"
        )
    if resume and output is None:
        raise ValueError("resume=True needs output= (the file the run was saved to)")


def _dim_names(name, dims) -> None:
    if isinstance(dims, str) or not isinstance(dims, (list, tuple)):
        raise TypeError(
            f"{name} must be a list or tuple of dim names, one per event axis (e.g. "
            f"('row', 'col')), got {dims!r}"
        )
    for dim in dims:
        if not isinstance(dim, str) or not dim:
            raise TypeError(f"{name} must hold non-empty strings (dim names), got {dim!r}")


def check_tree_names(var_name, event_dims, coords, attrs) -> None:
    """The names of :func:`liesample.sample`'s tree by type (``var_name`` a non-empty string,
    ``event_dims`` dim names or a mapping leaf name -> dim names, ``coords`` a mapping dim ->
    values, ``attrs`` a mapping); whether they fit the starts is checked on the starts."""
    if var_name is not None and not isinstance(var_name, str):
        raise TypeError(f"var_name must be None or a non-empty string, got {var_name!r}")
    if var_name == "":
        raise ValueError("var_name must be None or a non-empty string, got ''")
    if isinstance(event_dims, Mapping):
        for leaf, dims in event_dims.items():
            _dim_names(f"event_dims[{leaf!r}]", dims)
    elif event_dims is not None:
        _dim_names("event_dims", event_dims)
    if coords is not None:
        if not isinstance(coords, Mapping):
            raise TypeError(
                "coords must be None or a mapping {dim name: coordinate values}, e.g. "
                f"{{'component': ['x', 'y', 'z']}}; got {type(coords).__name__}"
            )
        for dim, values in coords.items():
            if not isinstance(dim, str) or isinstance(values, str) or np.ndim(values) != 1:
                raise TypeError(
                    f"coords[{dim!r}] must be the 1-D coordinate values of a dim named by a "
                    f"string, got {values!r}"
                )
    if attrs is not None and (
        not isinstance(attrs, Mapping) or not all(isinstance(k, str) for k in attrs)
    ):
        raise TypeError(f"attrs must be None or a mapping of str names to values, got {attrs!r}")


def check_algorithm(algorithm) -> None:
    """``algorithm`` is a sampler: an object with ``init(position)`` and ``step(rng_key,
    state)`` (a liesample sampler, a BlackJAX ``SamplingAlgorithm``); anything else is a
    ``TypeError`` that says what is expected and how to build one."""
    if callable(getattr(algorithm, "init", None)) and callable(getattr(algorithm, "step", None)):
        return
    expected = (
        "algorithm must be a sampler: a liesample sampler such as "
        "liesample.lie_poisson_langevin(system, beta=1.0), or a BlackJAX SamplingAlgorithm "
        "with init(position) and step(rng_key, state) such as blackjax.nuts(logdensity_fn, "
        "step_size, inverse_mass_matrix)"
    )
    if callable(getattr(algorithm, "build_kernel", None)):  # the API object, not called
        name = type(algorithm).__name__
        raise TypeError(
            f"{expected}; got the sampler family {name} itself: call it with its arguments "
            f"first, {name}(...) (its help() lists them)"
        )
    if callable(algorithm):
        raise TypeError(
            f"{expected}; got the function {getattr(algorithm, '__name__', algorithm)!r}: a "
            "step function alone is not a sampler, wrap it with its init as "
            "blackjax.base.SamplingAlgorithm(init, step)"
        )
    raise TypeError(f"{expected}; got {type(algorithm).__name__}")


def wants_adaptation(sampler: Sampler, adapt, num_warmup, name: str) -> bool:
    """``adapt=None``: adapt what the user left unset (a sampler declaring an ``adaptation`` whose
    step size was not given) when there is a warm-up; ``True``: adapt (the sampler must declare
    an ``adaptation``); ``False``: never."""
    if adapt is True and sampler.adaptation is None:
        raise ValueError(
            f"adapt=True: {name} has no warm-up adaptation; the orbit "
            "samplers (liesample.lie_poisson_langevin, liesample.adjusted_lie_poisson) and "
            "liesample.geometric_hmc / geometric_langevin have one, the magnetic samplers are "
            "tuned with liesample.window_adaptation"
        )
    if adapt is None:
        return sampler.adaptation is not None and num_warmup > 0 and not sampler.adaptation.given
    return bool(adapt)


def check_starts(sampler: Sampler, initial_positions, num_chains, step_size_checks=True):
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
    # each distinct row's first chain (np.unique over rows of many bytes is slow: it compares
    # them as structured records)
    first_chains: dict[bytes, int] = {}
    for chain, row in enumerate(flat):
        first_chains.setdefault(row.tobytes(), chain)
    for chain in sorted(first_chains.values()):
        try:
            sampler.init(take_chain(initial_positions, chain))
        except (ValueError, TypeError) as error:
            raise type(error)(f"initial_positions[{chain}]: {error}") from None


def check_finite_starts(initial_positions, num_chains):
    """Every leaf of every chain's start finite (the error names the first bad chain)."""
    finite = np.all(
        [
            np.isfinite(np.asarray(leaf)).reshape(num_chains, -1).all(axis=1)
            for leaf in jax.tree.leaves(initial_positions)
        ],
        axis=0,
    )
    if not finite.all():
        raise ValueError(f"initial_positions[{int(np.argmin(finite))}] must be finite")


def as_log_likelihood(log_likelihood):
    """``log_likelihood`` (a dict ``{observed variable: function of the position}`` giving each
    observation's log-likelihood) as a hashable tuple of ``(name, function)`` pairs, or
    ``None``."""
    if log_likelihood is None:
        return None
    if not isinstance(log_likelihood, dict) or not log_likelihood:
        raise TypeError(
            "log_likelihood must be a non-empty dict {observed variable name: function of the "
            "position returning the pointwise log-likelihoods}, got "
            f"{type(log_likelihood).__name__}"
        )
    for name, function in log_likelihood.items():
        if not isinstance(name, str) or not name or not callable(function):
            raise TypeError(
                f"log_likelihood[{name!r}] must be a function of the position under a "
                f"non-empty string name, got {type(function).__name__}"
            )
    return tuple(log_likelihood.items())


# --------------------------------------------------------------------------- sizes

KEY_DATA_BITS = 32
"""A step's key is ``fold_in(key_c, step)``, which folds in the step index as 32 bits."""


def chunk_length(num_draws: int, chunk_draws) -> int:
    """Draws per compiled chunk: ``chunk_draws``, else about 20 chunks, of equal length where a
    divisor of ``num_draws`` gives 10 to 40 of them: every chunk is then one compiled program
    (a last, shorter chunk would be a second program, compiling the step's body again).

    Examples
    --------
    >>> from liesample.run.arguments import chunk_length
    >>> chunk_length(50, None), chunk_length(1000, None), chunk_length(997, None)
    (2, 50, 50)
    """
    if chunk_draws:
        return int(chunk_draws)
    even = [num_draws // k for k in range(10, 41) if num_draws % k == 0]  # k chunks of n / k
    if even:
        return min(even, key=lambda d: abs(num_draws / d - 20))
    return max(1, math.ceil(num_draws / 20))


def max_steps(sampler: Sampler) -> int:
    """The most steps a chain can run: its step index is a JAX integer of the default dtype
    (``int32`` unless ``jax_enable_x64``), the end of its last noise block must fit it too, and
    ``fold_in`` reads the index as 32 bits (:mod:`liesample.integrators.chain_loop`)."""
    counter = np.iinfo(jax.dtypes.canonicalize_dtype(np.int64)).max
    blocks = sampler.noise_blocks
    return min(counter - (0 if blocks is None else blocks.size - 1), 2**KEY_DATA_BITS)


def check_steps(sampler: Sampler, num_draws: int, options) -> None:
    """``num_warmup + num_draws * thinning`` steps fit the step counter (:func:`max_steps`)."""
    o = options
    steps, limit = o.num_warmup + num_draws * o.thinning, max_steps(sampler)
    if steps <= limit:
        return
    dtype = jax.dtypes.canonicalize_dtype(np.int64).name
    x64 = "" if dtype == "int64" else "; jax_enable_x64 makes it int64, up to 2**32 steps"
    raise ValueError(
        f"num_draws={num_draws}, thinning={o.thinning} and num_warmup={o.num_warmup} make "
        f"num_warmup + num_draws * thinning = {steps} steps per chain, more than the {limit} a "
        f"chain's step counter ({dtype}, folded into each step's key as {KEY_DATA_BITS} bits"
        f"{x64}) can count: lower num_draws, thinning or num_warmup (liesample.sample's default "
        "num_warmup is num_draws * thinning); for more draws, run more chains"
    )


def _bytes(count: int) -> str:
    return f"{count} bytes ({count / 2**30:.3g} GiB)"


def host_memory() -> int | None:
    """The host's physical memory in bytes (``None`` where the system does not say)."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def device_memory(devices) -> tuple[int | None, str]:
    """The free memory in bytes of the fullest of ``devices`` (``memory_stats``) and its name;
    the host's memory where a device does not report it (the CPU)."""
    free = []
    for device in devices:
        try:
            stats = device.memory_stats()
        except (NotImplementedError, RuntimeError):
            stats = None
        if not stats or "bytes_limit" not in stats:
            return host_memory(), "host memory"
        free.append(int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0)))
    return min(free), f"{devices[0].platform} device memory"


def info_bytes(positions, contract: bool) -> int:
    """Bytes of one step's info, at least: the Info contract's fields (``is_divergent``, a
    bool; ``acceptance_rate`` and ``energy`` in the positions' real dtype) for a liesample
    sampler (``contract``), nothing known for another algorithm."""
    if not contract:
        return 0
    dtype = jnp.result_type(*jax.tree.leaves(positions))
    real = dtype if jnp.issubdtype(dtype, jnp.inexact) else jnp.result_type(float)
    return 1 + 2 * jnp.finfo(real).dtype.itemsize


def draw_bytes(positions, keep_positions: bool, recorded, info: int) -> int:
    """Bytes of one chain's kept draw: its position (if kept), the shapes ``recorded`` (the
    observables' and log-likelihoods', chains first) and ``info``."""
    trees = [*recorded, positions] if keep_positions else list(recorded)
    leaves = [leaf for tree in trees if tree is not None for leaf in jax.tree.leaves(tree)]
    return info + sum(math.prod(leaf.shape[1:]) * np.dtype(leaf.dtype).itemsize for leaf in leaves)


def check_memory(sizes, num_draws: int, options, devices, lattice_parts: int = 1) -> None:
    """The kept draws fit: the whole run in host memory (the draws are returned there), one
    chunk and its thinning window on each device. ``sizes``: ``(chains, bytes of one chain's
    draw, bytes of one step's info)``; ``lattice_parts``: the devices one chain's lattice is
    split over (``lattice_sharding=``), each holding that fraction of its draws. Lower bounds:
    only what surely cannot fit is refused."""
    o, (chains, per_draw, info) = options, sizes
    total, host = chains * num_draws * per_draw, host_memory()
    fewer = (
        "keep_positions=False with observables= (only the functions of the position you need)"
        if o.keep_positions
        else "fewer or smaller observables"
    )
    if host is not None and total > host:
        raise ValueError(
            f"num_draws={num_draws}: the kept draws need at least {_bytes(total)} of host "
            f"memory ({chains} chains × {num_draws} draws × {per_draw} bytes), more than the "
            f"{_bytes(host)} this machine has: keep fewer draws (a smaller num_draws, or a "
            f"larger thinning: one draw every thinning steps), or {fewer}"
        )
    chunk = min(chunk_length(num_draws, o.chunk_draws), num_draws)
    per_device = math.ceil(chains / (len(devices) // lattice_parts))
    need = per_device * (math.ceil(chunk * per_draw / lattice_parts) + o.thinning * info)
    free, where = device_memory(devices)
    if free is not None and need > free:
        raise ValueError(
            f"chunk_draws={o.chunk_draws} (chunks of {chunk} draws) and thinning={o.thinning}: "
            f"one compiled chunk needs at least {_bytes(need)} of {where} ({per_device} chains "
            f"× ({chunk} draws × {per_draw} bytes + a window of {o.thinning} steps × {info} "
            f"bytes of info)), more than the {_bytes(free)} available: a smaller chunk_draws, "
            f"a smaller thinning, devices= to spread the chains, or {fewer}"
        )
