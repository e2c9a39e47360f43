"""Parameter checks shared by constructors: each error names the parameter and what is allowed."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import SupportsFloat, cast

import jax
import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.types import PyTree, TreeDef


def float_array(value: object, requirement: str, error: type[Exception] = ValueError) -> np.ndarray:
    """``np.array(value, dtype=float)``, or ``error("<requirement>, got <value>")`` when ``value``
    is not an array of real numbers (bool, complex and string arrays included: none is cast)."""
    try:
        if np.asarray(value).dtype.kind in "bcSU":  # bool, complex, bytes, str
            raise TypeError
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise error(f"{requirement}, got {value!r}") from None


def finite_float(
    name: str,
    value: object,
    *,
    positive: bool = False,
    nonnegative: bool = False,
    rate: bool = False,
) -> float:
    """``value`` as a Python float, or a ``ValueError``/``TypeError`` that says what is allowed
    (``rate``: strictly between 0 and 1, as a target acceptance rate)."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or np.ndim(cast(ArrayLike, value)) != 0:
        raise TypeError(f"{name} must be a real scalar, got {value!r}")
    try:
        x = float(cast(SupportsFloat, value))
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real scalar, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x}")
    if positive and not x > 0:
        raise ValueError(f"{name} must be > 0, got {x}")
    if nonnegative and not x >= 0:
        raise ValueError(f"{name} must be >= 0, got {x}")
    if rate and not 0.0 < x < 1.0:
        raise ValueError(f"{name} must be in (0, 1), got {x}")
    return x


def int_at_least(name: str, value, what: str, minimum: int = 1) -> int:
    """``value`` as an int ``>= minimum`` (``what`` says what it counts), else a ``TypeError``
    (not an int, or a bool) or a ``ValueError`` (below ``minimum``), each naming ``name``.

    Examples
    --------
    >>> from liesample.foundation.validation import int_at_least
    >>> int_at_least("length", np.int64(12), "sites of the chain")
    12
    """
    message = f"{name} must be an int >= {minimum} ({what}), got {value!r}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(message)
    if value < minimum:
        raise ValueError(message)
    return int(value)


def principal_moments(inertia: Sequence[float]) -> tuple[float, float, float]:
    """Three finite, positive principal moments of inertia, or a ``ValueError`` naming the bad
    one."""
    if np.ndim(inertia) != 1 or len(inertia) != 3:
        raise ValueError(
            f"inertia must be a sequence of 3 principal moments (each finite and > 0), "
            f"got {inertia!r}"
        )
    a, b, c = (finite_float(f"inertia[{i}]", v, positive=True) for i, v in enumerate(inertia))
    return a, b, c


def nonzero_vector3(name: str, value: ArrayLike | Sequence[float]) -> np.ndarray:
    """A finite, nonzero, read-only float array of shape (3,), or a ``ValueError`` naming it."""
    vector = float_array(value, f"{name} must be a 3-vector of finite reals")
    if vector.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, got shape {vector.shape}")
    if not np.all(np.isfinite(vector)):
        raise ValueError(f"{name} must be finite, got {vector}")
    if not np.any(vector != 0.0):
        raise ValueError(f"{name} must be nonzero, got {vector}")
    vector.setflags(write=False)
    return vector


def concrete_array(value: ArrayLike) -> np.ndarray | None:
    """``np.asarray(value)``, or ``None`` when ``value`` is a tracer (checks then happen outside
    jit)."""
    try:
        return np.asarray(value)
    except jax.errors.TracerArrayConversionError:  # value checks are skipped under tracing
        return None


def nonzero_circulations(circulations: ArrayLike) -> np.ndarray:
    """Point-vortex circulations ``(Γ_1, …, Γ_N)``: a read-only 1-D array, finite and nonzero."""
    gamma = float_array(
        circulations, "circulations must be a 1-D sequence of nonzero finite reals", TypeError
    )
    if gamma.ndim != 1 or gamma.size < 1:
        raise ValueError(
            f"circulations must be a 1-D sequence (Γ_1, …, Γ_N) with N >= 1, got shape "
            f"{gamma.shape}"
        )
    if not np.all(np.isfinite(gamma)):
        raise ValueError(f"circulations must be finite, got {gamma}")
    if np.any(gamma == 0.0):
        raise ValueError(
            f"circulations must be nonzero: vortex {int(np.argmax(gamma == 0.0))} has Γ = 0 (a "
            "vortex without circulation does not move the fluid nor lie on the coadjoint orbit)"
        )
    gamma.setflags(write=False)
    return gamma


KEY_FORMS = "jax.random.key(seed), or the older jax.random.PRNGKey(seed)"
"""The key styles every key argument accepts (:func:`prng_key`)."""


def prng_key(rng_key: ArrayLike, name: str = "rng_key") -> jax.Array:
    """A typed JAX key from either key style: ``jax.random.key(seed)`` (returned as is) or the
    raw ``uint32`` key data of ``jax.random.PRNGKey(seed)`` (wrapped, same random stream); a
    leading batch axis is kept. Anything else (an integer seed among them) is a ``TypeError``
    that says what is allowed. Only the shape and dtype are read: a traced key is accepted."""
    import jax.numpy as jnp

    if isinstance(rng_key, jax.Array) and jnp.issubdtype(rng_key.dtype, jax.dtypes.prng_key):
        return rng_key
    array = concrete_array(rng_key) if not isinstance(rng_key, jax.Array) else rng_key
    key_shape = jax.eval_shape(lambda: jax.random.key_data(jax.random.key(0))).shape
    if array is not None and getattr(array, "dtype", None) == np.uint32:
        if tuple(array.shape[-len(key_shape) :]) == key_shape:
            return jax.random.wrap_key_data(jnp.asarray(array, dtype=jnp.uint32))
    if isinstance(rng_key, (int, np.integer)) and not isinstance(rng_key, bool):
        raise TypeError(
            f"{name} must be a JAX random key, {KEY_FORMS}; got the integer {int(rng_key)}, "
            f"a seed, not a key: pass jax.random.key({int(rng_key)})"
        )
    if isinstance(rng_key, (np.ndarray, jax.Array)):
        got = f"an array of dtype {rng_key.dtype} and shape {rng_key.shape}"
    else:
        got = repr(rng_key)
    raise TypeError(
        f"{name} must be a JAX random key, {KEY_FORMS} (uint32 data of shape {key_shape}); got "
        f"{got}: pass jax.random.key(seed)"
    )


def single_key(rng_key: ArrayLike, name: str = "rng_key", *, batch_fix: str = "") -> jax.Array:
    """One typed JAX key (:func:`prng_key`), or a ``ValueError`` for a batch of keys that says
    what to do instead (``batch_fix``). Reads only the shape and dtype, so that it serves inside
    ``jax.jit`` and ``jax.vmap`` (where a vmapped key has the shape of one)."""
    key = prng_key(rng_key, name)
    if key.shape != ():
        raise ValueError(
            f"{name} must be one key, got a batch of keys of shape {key.shape}"
            + (f": {batch_fix}" if batch_fix else "")
        )
    return key


def is_single_array(positions: PyTree) -> bool:
    """Whether ``positions`` is one array (an array, a number or a nested list), not a pytree
    of several leaves (dict, tuple, named tuple, …)."""
    structure: TreeDef = jax.tree.structure(positions)
    return isinstance(positions, list) or structure.num_nodes == structure.num_leaves == 1


def raise_or_warn(
    message: str,
    raise_error: bool,
    error: type[Exception] = ValueError,
    warning: type[Warning] = UserWarning,
    stacklevel: int = 2,
) -> None:
    """Raise ``error(message)`` if ``raise_error``, else warn ``warning(message)`` at the caller
    of the function that calls this one (``stacklevel`` counted from that function)."""
    if raise_error:
        raise error(message)
    warnings.warn(message, warning, stacklevel=stacklevel + 1)
