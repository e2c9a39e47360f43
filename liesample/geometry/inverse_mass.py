"""The inverse mass of a position: its checks, and the dense form a ``Euclidean`` block allows.

The inverse mass is one scalar per copy of a group or sphere (shape ``shape + (1,)``: the
kinetic flow needs the bi-invariant or round metric, :mod:`liesample.geometry.spaces`) and one
per coordinate of ``Euclidean`` and ``U1`` (shape ``shape``); a ``Euclidean`` block of ``n``
coordinates may instead take a dense symmetric positive definite ``(n, n)`` matrix.
:func:`check_inverse_mass` turns what a user gives (``None``, a scalar, a pytree like the
space) into arrays of those shapes; :func:`check_inverse_mass_matrix` checks a flat ``M⁻¹``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.types import PyTree, TreeDef
from liesample.foundation.validation import concrete_array
from liesample.geometry.flat_and_round import Euclidean
from liesample.geometry.space_base import Space, SpaceTree, _map, _spaces, is_space

__all__ = ["check_inverse_mass", "check_inverse_mass_matrix"]


def real_finite_array(name: str, value: ArrayLike, ndims: Sequence[int]) -> np.ndarray | None:
    """Rank check always; dtype and finiteness only when ``value`` is concrete (not a tracer).
    Returns the concrete numpy array, or ``None`` for a traced value."""
    shape = np.shape(value)
    if len(shape) not in ndims:
        want = " or ".join(f"{n}-D" for n in ndims)
        raise ValueError(f"{name} must be a {want} array, got shape {shape}")
    array = concrete_array(value)
    if array is not None:
        if array.dtype.kind not in "iuf":
            raise TypeError(f"{name} must be a real array, got dtype {array.dtype}")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} must be finite, got non-finite entries")
    return array


def check_inverse_mass_matrix(
    inverse_mass_matrix: ArrayLike, dimension: int | None = None, name: str = "inverse_mass_matrix"
) -> None:
    """A flat ``M⁻¹``: diagonal (``(d,)``, entries > 0) or dense (``(d, d)``, symmetric positive
    definite); value checks only when concrete.

    Examples
    --------
    >>> from liesample.spaces import check_inverse_mass_matrix
    >>> check_inverse_mass_matrix(jnp.array([1.0, 2.0]))  # a diagonal M⁻¹: accepted
    >>> check_inverse_mass_matrix(jnp.array([1.0, -1.0]))
    Traceback (most recent call last):
    ValueError: inverse_mass_matrix (diagonal) must have all entries > 0
    """
    imm = real_finite_array(name, inverse_mass_matrix, (1, 2))
    shape = np.shape(inverse_mass_matrix)
    if len(shape) == 2 and shape[0] != shape[1]:
        raise ValueError(f"{name} must be (d,) or square (d, d), got shape {shape}")
    if dimension is not None and shape[0] != dimension:
        raise ValueError(
            f"{name} must have leading size {dimension} to match the {dimension} position "
            f"coordinates, got shape {shape}"
        )
    if imm is None:
        return
    if imm.ndim == 1 and not np.all(imm > 0):
        raise ValueError(f"{name} (diagonal) must have all entries > 0")
    if imm.ndim == 2:
        if not np.allclose(imm, imm.T, rtol=1e-10, atol=0.0):
            raise ValueError(f"{name} (dense) must be symmetric")
        if imm.size and not np.all(np.linalg.eigvalsh(imm) > 0):
            raise ValueError(f"{name} (dense) must be positive definite")


def is_dense_inverse_mass(space: Space, inverse_mass: ArrayLike) -> bool:
    """Whether ``inverse_mass`` is a dense ``(n, n)`` matrix for a ``Euclidean`` block of ``n``
    coordinates (raveled order), rather than a diagonal broadcast to its shape."""
    n = math.prod(space.shape)
    shape = np.shape(inverse_mass)
    return isinstance(space, Euclidean) and shape == (n, n) and shape != space.shape


def check_inverse_mass(
    space: SpaceTree, inverse_mass: PyTree, dtype: DTypeLike | None = None
) -> PyTree:
    """``None`` (unit mass), a positive scalar, or a pytree like ``space`` of arrays that
    broadcast to each block's ``mass_array_shape`` → a pytree of arrays of those shapes.

    A ``Euclidean`` block of ``n`` coordinates may instead take a dense symmetric positive
    definite ``(n, n)`` matrix (its coordinates in raveled order), kept as it is.

    Examples
    --------
    >>> from liesample.spaces import Euclidean, check_inverse_mass
    >>> check_inverse_mass(Euclidean((3,)), 2.0)  # a scalar, broadcast to the block
    Array([2., 2., 2.], dtype=float64)
    >>> check_inverse_mass({"x": Euclidean((2,))}, None)  # unit mass
    {'x': Array([1., 1.], dtype=float64)}
    """
    leaves = _spaces(space)
    dtype = dtype or jnp.zeros(()).dtype
    if inverse_mass is None:
        return _map(lambda s: jnp.ones(s.mass_array_shape, dtype), space)
    if np.ndim(cast(ArrayLike, inverse_mass)) == 0 and not isinstance(
        inverse_mass, (dict, list, tuple)
    ):
        given = _map(lambda s: inverse_mass, space)
    else:
        given = inverse_mass
        structure: TreeDef = jax.tree.structure(space, is_leaf=is_space)
        given_structure: TreeDef = jax.tree.structure(given)
        if given_structure != structure and len(leaves) > 1:
            raise ValueError(
                f"inverse_mass_matrix must be a scalar or a pytree like the space {structure}, "
                f"got {given_structure}"
            )
        if len(leaves) == 1 and given_structure.num_leaves == 1:
            given = _map(lambda s: jax.tree.leaves(inverse_mass)[0], space)

    def one(s, m):
        dtype = np.dtype(m.dtype if hasattr(m, "dtype") else np.asarray(m).dtype)
        if dtype.kind not in "iuf":
            raise TypeError(f"inverse mass for {s!r} must be real (floats > 0), got dtype "
                            f"{dtype}; pass an array of positive floats")  # fmt: skip
        if is_dense_inverse_mass(s, m):
            check_inverse_mass_matrix(m, name=f"inverse mass for {s!r}")
            return jnp.asarray(m, dtype)
        try:
            out = jnp.broadcast_to(jnp.asarray(m, dtype), s.mass_array_shape)
        except ValueError:
            dense = " or a dense (n, n) matrix" if isinstance(s, Euclidean) else ""
            raise ValueError(
                f"inverse mass for {s!r} must broadcast to shape {s.mass_array_shape} (one "
                f"value per copy{'' if s.mass_shape == () else ' of the group or sphere'})"
                f"{dense}, got shape {np.shape(m)}"
            ) from None
        value = concrete_array(out)
        if value is not None and not (np.all(np.isfinite(value)) and np.all(value > 0)):
            raise ValueError(f"inverse mass for {s!r} must be finite and > 0")
        return out

    return _map(one, space, given)
