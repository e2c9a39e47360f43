"""The flat and round spaces: ``Rⁿ`` (:class:`Euclidean`), the circle (:class:`U1`, as
angles) and the spheres ``Sⁿ`` (:class:`Sphere`), whose kinetic flows are translations and
great circles.

The flow of ``Euclidean`` and ``U1`` is a translation ``x + t M⁻¹p`` for any diagonal mass (the
angle wrapped to ``[−π, π)``); a ``Euclidean`` block may also take a dense inverse mass
(:mod:`liesample.geometry.inverse_mass`). The sphere is a homogeneous space
``SO(n+1)/SO(n)``, not a group: its position is the unit vector ``x ∈ Rⁿ⁺¹``, its momentum the
tangent vector ``p ⟂ x`` in ambient coordinates, and its drift the exact geodesic flow with
parallel transport of the momentum (the formulas are in :mod:`liesample.geometry.spaces`),
which needs the round metric: one inverse mass per copy.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.geometry.space_base import Space, _norm, _order, _shape, _sinc, _wrap

__all__ = ["U1", "Euclidean", "Sphere"]


# ====================================================================== Euclidean


@dataclasses.dataclass(frozen=True)
class Euclidean(Space):
    """``R^shape`` with Lebesgue measure; the flow is a translation ``x + t M⁻¹p``.

    Examples
    --------
    >>> from liesample.spaces import Euclidean
    >>> space = Euclidean((3,))
    >>> space.dimension, space.position_array_shape
    (3, (3,))
    """

    shape: tuple[int, ...] = ()
    compact = False

    def __post_init__(self):
        object.__setattr__(self, "shape", _shape("Euclidean shape", self.shape))

    copy_dim = "component"

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        raise ValueError(
            "Euclidean space has no uniform probability law; give the starting position explicitly"
        )

    def perturb(self, x: jax.Array, eps: jax.Array) -> jax.Array:
        return x + eps

    def flow(
        self, x: jax.Array, p: jax.Array, inverse_mass: jax.Array, t: ArrayLike
    ) -> tuple[jax.Array, jax.Array]:
        return x + t * inverse_mass * p, p

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        return y - x


# ====================================================================== U(1)


@dataclasses.dataclass(frozen=True)
class U1(Space):
    """The circle group ``U(1)`` as angles ``θ`` (any real: ``θ`` and ``θ + 2π`` are one point).

    Haar measure is ``dθ/2π``; the flow ``θ ← wrap(θ + t m⁻¹p)`` returns angles in ``[−π, π)``.

    Examples
    --------
    >>> from liesample.spaces import U1
    >>> theta = U1((4,)).uniform(jax.random.key(0))
    >>> theta.shape, bool(jnp.all((theta >= -jnp.pi) & (theta < jnp.pi)))
    ((4,), True)
    """

    shape: tuple[int, ...] = ()
    draw_name = "theta"

    def __post_init__(self):
        object.__setattr__(self, "shape", _shape("U1 shape", self.shape))

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        dtype = jnp.dtype(dtype or jnp.zeros(()).dtype)
        return jax.random.uniform(rng_key, self.shape, dtype, -jnp.pi, jnp.pi)

    def perturb(self, x: jax.Array, eps: jax.Array) -> jax.Array:
        return x + eps

    def flow(
        self, x: jax.Array, p: jax.Array, inverse_mass: jax.Array, t: ArrayLike
    ) -> tuple[jax.Array, jax.Array]:
        return _wrap(x + t * inverse_mass * p), p

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        return _wrap(y - x)


# ====================================================================== spheres


@dataclasses.dataclass(frozen=True)
class Sphere(Space):
    """The unit sphere ``Sⁿ ⊂ Rⁿ⁺¹`` (points are unit vectors), with its uniform law.

    Momenta are tangent vectors in ambient coordinates (``n + 1`` numbers, ``p·x = 0``); the
    drift is the exact geodesic flow with parallel transport (:mod:`liesample.geometry.spaces`).

    Examples
    --------
    >>> from liesample.spaces import Sphere
    >>> x = Sphere(2, shape=(5,)).uniform(jax.random.key(0))  # five points of S²
    >>> x.shape, bool(jnp.allclose(jnp.linalg.norm(x, axis=-1), 1.0, atol=1e-12))
    ((5, 3), True)
    """

    n: int
    shape: tuple[int, ...] = ()
    point_dims = ("component",)

    def __post_init__(self):
        object.__setattr__(self, "n", _order("Sphere dimension n", self.n, 1))
        object.__setattr__(self, "shape", _shape("Sphere shape", self.shape))

    @property
    def point_shape(self) -> tuple[int, ...]:
        return (self.n + 1,)

    @property
    def momentum_shape(self) -> tuple[int, ...]:
        return (self.n + 1,)

    mass_shape = (1,)

    @property
    def copy_dimension(self) -> int:
        return self.n

    _off_manifold_hint = "Points of a sphere are unit vectors: divide by the norm first."

    def constraint_error(self, x: ArrayLike) -> float:
        return float(np.max(np.abs(np.linalg.norm(x, axis=-1) - 1.0), initial=0.0))

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        dtype = jnp.dtype(dtype or jnp.zeros(()).dtype)
        z = jax.random.normal(rng_key, self.position_array_shape, dtype)
        return z / jnp.linalg.norm(z, axis=-1, keepdims=True)

    def project(self, x: jax.Array, p: jax.Array) -> jax.Array:
        return p - jnp.sum(p * x, -1, keepdims=True) * x

    def perturb(self, x: jax.Array, eps: jax.Array) -> jax.Array:
        # The tangent part of eps: the gradient is then the Riemannian one, (I − xxᵀ)∇.
        return x + self.project(x, eps)

    def flow(
        self, x: jax.Array, p: jax.Array, inverse_mass: jax.Array, t: ArrayLike
    ) -> tuple[jax.Array, jax.Array]:
        speed = _norm(p, keepdims=True)  # |p|; |v| = m⁻¹|p|
        angle = t * inverse_mass * speed
        cos, sin = jnp.cos(angle), jnp.sin(angle)
        new_x = cos * x + (t * inverse_mass * _sinc(angle)) * p
        new_p = cos * p - sin * speed * x
        # Round-off control only: the exact flow keeps |x| = 1, float arithmetic to ~1 ulp.
        new_x = new_x / jnp.linalg.norm(new_x, axis=-1, keepdims=True)
        return new_x, new_p

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        """Tangent vector at ``x`` pointing to ``y`` with length the geodesic distance."""
        c = jnp.clip(jnp.sum(x * y, -1, keepdims=True), -1.0, 1.0)
        w = y - c * x
        angle = jnp.arctan2(_norm(w, keepdims=True), c)
        return w / _sinc(angle)
