"""The checks of a run's arguments, made before any compilation: the starts (an array or a
pytree with a leading chain axis), the observables, the counts, and whether the warm-up adapts.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.validation import is_single_array
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


def take_chain(positions, chain):
    return jax.tree.map(lambda leaf: leaf[chain], positions)


def check_run_arguments(num_draws, num_warmup, thinning, on_nonfinite, chunk_draws, adapt):
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
    _, first_chains = np.unique(flat, axis=0, return_index=True)
    for chain in np.sort(first_chains):
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
