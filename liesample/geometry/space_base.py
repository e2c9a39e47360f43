"""What a space is: the interface of one block of a position, and products as pytrees.

A space (:class:`Space`) is ``shape`` independent copies of one manifold; it says how a block
of the position is checked (``check``), drawn from its uniform law (``uniform``), moved by the
exact flow of the kinetic energy (``flow``) and perturbed along an algebra direction
(``perturb``, from which the trivialised gradient follows). A product space is a pytree (dict,
tuple, list) of spaces (:data:`SpaceTree`); :func:`is_space` tells a block from a product. The
built-in spaces subclass :class:`Space` in :mod:`liesample.geometry.flat_and_round` (``Rⁿ``,
the circle, the spheres) and :mod:`liesample.geometry.matrix_groups` (``SO(n)``, ``SU(n)``);
the metric, the mass and the flows they implement are described in
:mod:`liesample.geometry.spaces`, which gathers every space's public name.

Below the interface are the helpers the built-in spaces share: the checks of their
constructors' arguments and the closed forms of their flows that stay smooth at 0.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.precision import roundoff_tolerance
from liesample.foundation.types import Tree
from liesample.foundation.validation import concrete_array

__all__ = ["Space", "SpaceTree", "is_space"]


def _shape(name, shape) -> tuple[int, ...]:
    if isinstance(shape, (int, np.integer)) and not isinstance(shape, bool):
        shape = (int(shape),)
    try:
        if isinstance(shape, str) or any(isinstance(s, (bool, np.bool_)) for s in shape):
            raise TypeError
        shape = tuple(operator.index(s) for s in shape)  # 2.5 is refused, not truncated
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a tuple of non-negative ints, got {shape!r}") from None
    if any(s < 0 for s in shape):
        raise ValueError(f"{name} must be a tuple of non-negative ints, got {shape!r}")
    return shape


def _order(name, n, minimum) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {n!r}")
    return int(n)


def _sinc(x):
    """``sin(x)/x``, smooth at 0 (no NaN in values or gradients)."""
    small = jnp.abs(x) < 1e-4
    safe = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 - x**2 / 6.0 + x**4 / 120.0, jnp.sin(safe) / safe)


def _versine(x):
    """``(1 − cos x)/x²``, smooth at 0."""
    small = jnp.abs(x) < 1e-4
    safe = jnp.where(small, 1.0, x)
    return jnp.where(small, 0.5 - x**2 / 24.0 + x**4 / 720.0, (1.0 - jnp.cos(safe)) / safe**2)


def _norm(x, keepdims=False):
    """Euclidean norm over the last axis, with a zero (not NaN) gradient at 0."""
    sq = jnp.sum(x * x, -1, keepdims=keepdims)
    positive = sq > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


def _wrap(theta):
    """Angle in ``[−π, π)``."""
    return jnp.mod(theta + jnp.pi, 2.0 * jnp.pi) - jnp.pi


class Space:
    """One block of the position: ``shape`` independent copies of a manifold.

    Subclasses set ``point_shape`` (one copy), ``momentum_shape`` (algebra coordinates of one
    copy), ``mass_shape`` (the inverse mass of one copy) and ``copy_dimension``.

    Examples
    --------
    Every space has a dimension, the array shape of its points and a uniform law where it has
    one; a product of spaces is a pytree of them:

    >>> from liesample.spaces import SO, Sphere
    >>> Sphere(2, shape=(4,)).position_array_shape, Sphere(2, shape=(4,)).dimension
    ((4, 3), 8)
    >>> SO(3).uniform(jax.random.key(0)).shape
    (3, 3)
    """

    shape: tuple[int, ...]
    if TYPE_CHECKING:  # read-only: a subclass sets each as a class attribute or a property

        @property
        def point_shape(self) -> tuple[int, ...]: ...
        @property
        def momentum_shape(self) -> tuple[int, ...]: ...
        @property
        def copy_dimension(self) -> int: ...

    else:
        point_shape = ()
        momentum_shape = ()
        copy_dimension = 1
    mass_shape: tuple[int, ...] = ()
    compact: bool = True
    # How draws of a single block are named in a DataTree: the variable, the dim of its copy
    # axes and the dims of one copy's point.
    draw_name = "mu"
    copy_dim = "copy"
    point_dims: tuple[str, ...] = ()

    def draw_dims(self) -> tuple[str, ...]:
        """Dims of the position's axes: ``copy_dim`` (numbered if several) then ``point_dims``."""
        if len(self.shape) == 1:
            return (self.copy_dim, *self.point_dims)
        return (*(f"{self.copy_dim}_{k}" for k in range(len(self.shape))), *self.point_dims)

    # ---------------------------------------------------------------- shapes
    @property
    def position_array_shape(self) -> tuple[int, ...]:
        return self.shape + self.point_shape

    @property
    def momentum_array_shape(self) -> tuple[int, ...]:
        return self.shape + self.momentum_shape

    @property
    def mass_array_shape(self) -> tuple[int, ...]:
        return self.shape + self.mass_shape

    @property
    def dimension(self) -> int:
        """Dimension of the manifold (all copies)."""
        return self.copy_dimension * math.prod(self.shape)

    def position_dtype(self, dtype: DTypeLike) -> np.dtype:
        return jnp.dtype(dtype)

    # ---------------------------------------------------------------- checks
    def check(self, x: ArrayLike, name: str = "position") -> None:
        """Raise a ``ValueError``/``TypeError`` unless ``x`` is a point of this space.

        Shape and dtype are always checked; the manifold constraint only when ``x`` is concrete
        (under ``jit`` there is nothing to inspect). Tolerance: 1000 ulps of ``x``'s dtype.
        """
        if not hasattr(x, "dtype"):  # a number or a nested list
            x = np.asarray(x)
        if np.shape(x) != self.position_array_shape:
            raise ValueError(
                f"{name} must have shape {self.position_array_shape} for {self!r}, got "
                f"{np.shape(x)}"
            )
        dtype = jnp.result_type(x)
        self._check_dtype(dtype, name)
        value = concrete_array(x)
        if value is None:
            return
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite for {self!r}, got non-finite entries")
        error = self.constraint_error(value)
        tolerance = roundoff_tolerance(np.finfo(dtype).dtype)
        if error > tolerance:
            raise ValueError(
                f"{name} is off {self!r} by {error:.3g} (allowed: round-off, {tolerance:.1g}). "
                f"{self._off_manifold_hint}"
            )

    def _check_dtype(self, dtype, name):
        if not jnp.issubdtype(dtype, jnp.floating):
            raise TypeError(f"{name} must be a real floating array for {self!r}, got {dtype}")

    _off_manifold_hint = ""

    def constraint_error(self, x: ArrayLike) -> float:  # numpy, concrete
        return 0.0

    # ---------------------------------------------------------------- geometry
    def momentum_dtype(self, x: jax.Array) -> np.dtype:
        return jnp.real(x).dtype

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        raise NotImplementedError

    def perturb(self, x: jax.Array, eps: jax.Array) -> jax.Array:
        """A curve through ``x`` with velocity ``eps`` at 0 (first order suffices)."""
        raise NotImplementedError

    def flow(
        self, x: jax.Array, p: jax.Array, inverse_mass: jax.Array, t: ArrayLike
    ) -> tuple[jax.Array, jax.Array]:
        """Exact flow of ``½ m⁻¹|p|²`` over time ``t``."""
        raise NotImplementedError

    def project(self, x: jax.Array, p: jax.Array) -> jax.Array:
        """The tangent part of an ambient momentum (identity except on spheres)."""
        return p

    def exp(self, x: jax.Array, v: jax.Array) -> jax.Array:
        """The exponential map: the point reached from ``x`` with velocity ``v`` at time 1."""
        return self.flow(x, v, jnp.ones(self.mass_array_shape, v.dtype), 1.0)[0]

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        raise NotImplementedError(f"log is not implemented for {self!r}")


type SpaceTree = Tree[Space]
"""A space, or a pytree of spaces (a dict, tuple or list of them, nested): a product space."""


def is_space(value: object) -> bool:
    """Whether ``value`` is one block (a :class:`Space`), not a pytree of them.

    Examples
    --------
    >>> from liesample.spaces import Sphere, is_space
    >>> is_space(Sphere(2)), is_space({"x": Sphere(2)}), is_space(3.0)
    (True, False, False)
    """
    return isinstance(value, Space)


def _spaces(space) -> list[Space]:
    leaves = jax.tree.leaves(space, is_leaf=is_space)
    if not leaves or not all(is_space(s) for s in leaves):
        bad = [s for s in leaves if not is_space(s)]
        raise TypeError(
            "space must be a Space (Euclidean, Sphere, SO, SU, U1) or a pytree (dict, tuple, "
            f"list) of them, got {bad[0] if bad else space!r}"
        )
    return leaves


def _map(fn: Callable, space, *trees):
    return jax.tree.map(fn, space, *trees, is_leaf=is_space)
