"""Parameter spaces that are Lie groups or spheres: the position half of a chain on T*G.

The samplers in :mod:`liesample.samplers.cotangent.geometric_hmc` and
:mod:`liesample.samplers.cotangent.geometric_langevin` run the *unreduced* dissipative Hamiltonian
dynamics on ``T*G`` (paper, ``sec:dissipation``, before the reduction to ``g*``), with the
cotangent bundle left-trivialised, ``T*G ≅ G × g*``, and ``H(g, p) = U(g) + ½ pᵀM⁻¹p``. Its
Gibbs law ``exp(−H)`` has the ``G``-marginal ``exp(−U)`` with respect to Haar measure.

A *space* says how one block of the position moves. Every space has

- ``check(x)``: a clear error if ``x`` is not on the manifold (beyond round-off); a start is
  never silently projected;
- ``uniform(key)``: a draw from the uniform (Haar) law;
- ``flow(x, p, inverse_mass, t)``: the exact flow of the kinetic energy ``½ m⁻¹|p|²`` over a
  time ``t`` (the exp-map drift of the leapfrog; the group exponential is Rodrigues' formula
  on SO(3), closed form on SU(2), an eigendecomposition of the anti-Hermitian generator
  otherwise);
- ``perturb(x, ε)``: a curve through ``x`` with velocity ``ε`` (algebra coordinates); the
  trivialised gradient of ``log π`` is the autodiff gradient of ``ε ↦ log π(perturb(x, ε))``
  at ``ε = 0``, i.e. ``d/dε log π(g exp(εX))`` for a group (left trivialisation) and the
  Riemannian gradient for a sphere;
- ``exp(x, v)``, ``log(x, y)`` (where cheap), ``dimension``, ``momentum_shape``.

Spaces carry a ``shape``: the array of independent copies (``SU2(shape=(8, 8, 2))`` is the
link field of an 8×8 lattice). A product space is a pytree (dict, tuple, list) of spaces; a
position is a pytree of the same structure, one array per space.

Metric and mass. The momentum ``p`` lives in algebra coordinates (an orthonormal basis of
``g`` for the bi-invariant inner product ``⟨X, Y⟩ = ½ Re tr(X†Y)``). For a non-abelian group
the kinetic flow is the one-parameter subgroup ``g ↦ g exp(t m⁻¹ p)`` with ``p`` constant only
when the metric is bi-invariant, i.e. ``M ∝ I`` on each copy (otherwise ``p`` follows the
Euler–Arnold equation ``ṗ = ad*_{M⁻¹p} p`` of a free rigid body). Likewise the geodesic
formula of a sphere needs the round metric. So the inverse mass is one scalar per copy of a
group or sphere (shape ``shape + (1,)``) and one per coordinate of ``Euclidean`` and ``U1``
(shape ``shape``), where the flow is a translation for any diagonal mass; a ``Euclidean``
block of ``n`` coordinates may also take a dense ``(n, n)`` inverse mass. The momentum law,
the kinetic flow of a whole product (with an optional magnetic field on its ``Euclidean``
coordinates) and the one-effect steps built on them are in :mod:`liesample.geometry.cotangent`.

The sphere is a homogeneous space ``SO(n+1)/SO(n)``, not a group: its position is the unit
vector ``x ∈ Rⁿ⁺¹``, its momentum the tangent vector ``p ⟂ x`` in ambient coordinates, and its
drift the exact geodesic flow with parallel transport of the momentum,
``x ← x cos(|v|t) + v/|v| sin(|v|t)``, ``p ← p cos(|v|t) − x |p| sin(|v|t)``, ``v = m⁻¹p``
(the geodesic integrator of Byrne & Girolami 2013). It is the exact Hamiltonian flow of the
kinetic energy on ``T*Sⁿ``, so the leapfrog stays symplectic and reversible with respect to
the uniform measure × tangent Lebesgue measure.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.precision import roundoff_tolerance
from liesample.foundation.types import PRNGKey, PyTree, Tree, TreeDef
from liesample.foundation.validation import concrete_array, prng_key

__all__ = [
    "SO",
    "SU",
    "U1",
    "Euclidean",
    "Space",
    "SpaceTree",
    "Sphere",
    "check_inverse_mass",
    "check_inverse_mass_matrix",
    "check_position",
    "dimension",
    "is_space",
    "trivialised_value_and_grad",
    "uniform",
    "zero_momentum",
]


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
    drift is the exact geodesic flow with parallel transport (module docstring).

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


# ====================================================================== matrix groups


@functools.cache
def _so_basis(n: int) -> np.ndarray:
    """Orthonormal basis of so(n) for ``½ tr(XᵀY)``; for n = 3 the hat map ``ω ↦ ω×``."""
    if n == 3:
        basis = np.zeros((3, 3, 3))
        for k, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):  # hat(e_k)[i, j] = +1
            basis[k, i, j], basis[k, j, i] = 1.0, -1.0
        return basis
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    basis = np.zeros((len(pairs), n, n))
    for k, (i, j) in enumerate(pairs):
        basis[k, i, j], basis[k, j, i] = 1.0, -1.0
    return basis


@functools.cache
def _su_basis(n: int) -> np.ndarray:
    """``i λ_a`` with ``λ_a`` the generalised Gell-Mann matrices (``tr λ_aλ_b = 2δ_ab``):
    orthonormal for ``½ Re tr(X†Y)``; for n = 2, ``(iσ_x, iσ_y, iσ_z)``."""
    mats = []
    for j in range(n):
        for k in range(j + 1, n):
            m = np.zeros((n, n), complex)
            m[j, k] = m[k, j] = 1.0
            mats.append(m)
    for j in range(n):
        for k in range(j + 1, n):
            m = np.zeros((n, n), complex)
            m[j, k], m[k, j] = -1j, 1j
            mats.append(m)
    for ell in range(1, n):
        d = np.zeros(n)
        d[:ell] = 1.0
        d[ell] = -ell
        mats.append(np.diag(d * np.sqrt(2.0 / (ell * (ell + 1)))).astype(complex))
    return 1j * np.array(mats)


@dataclasses.dataclass(frozen=True)
class _MatrixGroup(Space):
    n: int
    shape: tuple[int, ...] = ()
    point_dims = ("row", "col")

    def __post_init__(self):
        group = type(self).__name__
        object.__setattr__(self, "n", _order(f"{group}(n): n", self.n, 2))
        object.__setattr__(self, "shape", _shape(f"{group} shape", self.shape))

    mass_shape = (1,)

    @property
    def point_shape(self) -> tuple[int, ...]:
        return (self.n, self.n)

    @property
    def momentum_shape(self) -> tuple[int, ...]:
        return (self.copy_dimension,)

    @property
    def basis(self) -> np.ndarray:
        raise NotImplementedError

    def hat(self, c):
        """Algebra coordinates ``(..., dim)`` → matrices ``(..., n, n)``."""
        basis = jnp.asarray(self.basis)
        return jnp.einsum("...k,kij->...ij", c.astype(basis.dtype), basis)

    def vee(self, X):
        """Matrices in the algebra → coordinates (``½ Re tr(B_k† X)``)."""
        basis = jnp.asarray(self.basis)
        return 0.5 * jnp.real(jnp.einsum("kij,...ij->...k", jnp.conj(basis), X))

    def perturb(self, x, eps):
        # g(I + X) has velocity gX at 0, like g exp(εX): the left-trivialised derivative.
        return x + x @ self.hat(eps).astype(x.dtype)

    def exponential(self, c):
        """``exp(ĉ)`` of algebra coordinates ``c``; closed forms in subclasses for n = 2, 3.

        ``ĉ`` is anti-Hermitian, so ``H = −iĉ`` is Hermitian: with ``H = V diag(λ) V†``
        (``eigh``), ``exp(ĉ) = V diag(e^{iλ}) V†``, unitary to round-off. One LAPACK call,
        where ``expm``'s Padé branches would all run under ``vmap``.
        """
        X = self.hat(c)
        lam, V = jnp.linalg.eigh(-1j * X.astype(jnp.result_type(X, jnp.complex64)))
        out = (V * jnp.exp(1j * lam)[..., None, :]) @ jnp.conj(jnp.swapaxes(V, -1, -2))
        return out if jnp.iscomplexobj(X) else jnp.real(out)

    def flow(self, x, p, inverse_mass, t):
        # Bi-invariant metric (M ∝ I per copy): ġ = g v̂, ṗ = ad*_v p = 0, so g ← g exp(t v̂).
        return x @ self.exponential(t * inverse_mass * p).astype(x.dtype), p

    def constraint_error(self, x):
        n = self.n
        gram = np.conj(np.swapaxes(x, -1, -2)) @ x
        unitary = np.max(np.abs(gram - np.eye(n)), initial=0.0)
        det = np.max(np.abs(np.linalg.det(x) - 1.0), initial=0.0) if x.size else 0.0
        return float(max(unitary, det))


@dataclasses.dataclass(frozen=True)
class SO(_MatrixGroup):
    """The rotation group ``SO(n)`` (real ``n × n`` matrices, ``RᵀR = I``, ``det R = 1``).

    Algebra coordinates: ``n(n−1)/2`` numbers in an orthonormal basis of antisymmetric
    matrices; for n = 3 they are the angular velocity (``hat(ω) v = ω × v``). ``exp`` is
    Rodrigues' formula for n = 3 and a Hermitian eigendecomposition otherwise.

    Examples
    --------
    >>> from liesample.spaces import SO
    >>> R = SO(3).uniform(jax.random.key(0))  # a Haar-uniform rotation
    >>> R.shape, bool(jnp.allclose(R.T @ R, jnp.eye(3), atol=1e-12))
    ((3, 3), True)
    >>> SO(3).exponential(jnp.array([0.0, 0.0, jnp.pi / 2])).round(12) @ jnp.array([1.0, 0, 0])
    Array([0., 1., 0.], dtype=float64)
    """

    draw_name = "R"

    @property
    def copy_dimension(self) -> int:
        return self.n * (self.n - 1) // 2

    @property
    def basis(self) -> np.ndarray:
        return _so_basis(self.n)

    _off_manifold_hint = "Rotations must satisfy RᵀR = I and det R = 1."

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        dtype = jnp.dtype(dtype or jnp.zeros(()).dtype)
        z = jax.random.normal(rng_key, self.position_array_shape, dtype)
        q, r = jnp.linalg.qr(z)
        q = q * jnp.sign(jnp.diagonal(r, axis1=-2, axis2=-1))[..., None, :]  # Haar on O(n)
        det = jnp.linalg.det(q)
        flip = jnp.ones(self.n, dtype).at[0].set(-1.0)
        return jnp.where((det < 0)[..., None, None], q * flip, q)  # Haar on SO(n)

    def exponential(self, c: jax.Array) -> jax.Array:
        if self.n != 3:
            return super().exponential(c)
        theta = _norm(c)[..., None, None]
        K = self.hat(c)
        return jnp.eye(3, dtype=c.dtype) + _sinc(theta) * K + _versine(theta) * (K @ K)

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        """Coordinates of ``log(xᵀy)`` for n = 3 (rotation angles below π)."""
        if self.n != 3:
            return super().log(x, y)
        r = jnp.swapaxes(x, -1, -2) @ y
        cos = jnp.clip(0.5 * (jnp.trace(r, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
        angle = jnp.arccos(cos)[..., None]
        return self.vee(0.5 * (r - jnp.swapaxes(r, -1, -2))) / _sinc(angle)


@dataclasses.dataclass(frozen=True)
class SU(_MatrixGroup):
    """The special unitary group ``SU(n)`` (complex matrices, ``U†U = I``, ``det U = 1``).

    Algebra coordinates: ``n² − 1`` numbers in the basis ``i λ_a`` (generalised Gell-Mann
    matrices; for n = 2, ``iσ_x, iσ_y, iσ_z``), orthonormal for ``½ Re tr(X†Y)``. ``exp`` is
    closed-form for n = 2 (``cos|c| I + i sin|c| ĉ·σ``) and a Hermitian eigendecomposition
    otherwise.

    Examples
    --------
    >>> from liesample.spaces import SU
    >>> U = SU(2, shape=(3,)).uniform(jax.random.key(0))  # three Haar-uniform SU(2) matrices
    >>> U.shape, U.dtype, bool(jnp.allclose(jnp.linalg.det(U), 1.0, atol=1e-12))
    ((3, 2, 2), dtype('complex128'), True)
    """

    draw_name = "U"

    @property
    def copy_dimension(self) -> int:
        return self.n**2 - 1

    @property
    def basis(self) -> np.ndarray:
        return _su_basis(self.n)

    _off_manifold_hint = "Elements of SU(n) must satisfy U†U = I and det U = 1."

    def position_dtype(self, dtype: DTypeLike) -> np.dtype:
        return jnp.result_type(jnp.dtype(dtype), jnp.complex64)

    def _check_dtype(self, dtype, name):
        if not jnp.issubdtype(dtype, jnp.complexfloating):
            raise TypeError(f"{name} must be a complex array for {self!r}, got {dtype}")

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        real = jnp.dtype(dtype or jnp.zeros(()).dtype)
        k1, k2 = jax.random.split(rng_key)
        shape = self.position_array_shape
        z = jax.random.normal(k1, shape, real) + 1j * jax.random.normal(k2, shape, real)
        q, r = jnp.linalg.qr(z)
        d = jnp.diagonal(r, axis1=-2, axis2=-1)
        q = q * (d / jnp.abs(d))[..., None, :]  # Haar on U(n)
        det = jnp.linalg.det(q)
        return q / (det ** (1.0 / self.n))[..., None, None]  # Haar on SU(n)

    def exponential(self, c: jax.Array) -> jax.Array:
        if self.n != 2:
            return super().exponential(c)
        angle = _norm(c)[..., None, None]
        return jnp.cos(angle) * jnp.eye(2) + _sinc(angle) * self.hat(c)

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        """Coordinates of ``log(x†y)`` for n = 2 (away from ``−I``)."""
        if self.n != 2:
            return super().log(x, y)
        u = jnp.conj(jnp.swapaxes(x, -1, -2)) @ y
        cos = jnp.clip(0.5 * jnp.real(jnp.trace(u, axis1=-2, axis2=-1)), -1.0, 1.0)
        angle = jnp.arccos(cos)[..., None]
        return self.vee(0.5 * (u - jnp.conj(jnp.swapaxes(u, -1, -2)))) / _sinc(angle)


# ====================================================================== pytrees of spaces


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


def dimension(space: SpaceTree) -> int:
    """Dimension of a space or product of spaces.

    Examples
    --------
    >>> from liesample.spaces import SO, Euclidean, dimension
    >>> dimension({"R": SO(3), "x": Euclidean((2,))})
    5
    """
    return sum(s.dimension for s in _spaces(space))


def check_position(space: SpaceTree, position: PyTree, name: str = "position") -> None:
    """Structure, shape, dtype and manifold constraint of a position (clear errors).

    Examples
    --------
    A point off the sphere is refused, with the fix:

    >>> from liesample.spaces import Sphere, check_position
    >>> check_position(Sphere(2), jnp.array([0.0, 0.0, 1.0]))  # a unit vector: accepted
    >>> check_position(Sphere(2), jnp.array([1.0, 1.0, 0.0]))
    Traceback (most recent call last):
    ValueError: position is off Sphere(n=2, shape=()) by 0.414 ... divide by the norm first.
    """
    _spaces(space)
    space_structure: TreeDef = jax.tree.structure(space, is_leaf=is_space)
    position_structure: TreeDef = jax.tree.structure(position)
    if space_structure != position_structure:
        raise ValueError(
            f"{name} must have the structure of the space {space_structure}, got "
            f"{position_structure}"
        )
    paths = jax.tree_util.tree_flatten_with_path(space, is_leaf=is_space)[0]
    for (path, s), x in zip(paths, jax.tree.leaves(position)):
        s.check(x, name + jax.tree_util.keystr(path))


def uniform(space: SpaceTree, rng_key: PRNGKey, dtype: DTypeLike | None = None) -> PyTree:
    """A draw from the uniform (Haar) law of every block (Euclidean blocks have none).

    Examples
    --------
    >>> from liesample.spaces import SO, U1, uniform
    >>> x = uniform({"R": SO(3), "theta": U1((2,))}, jax.random.key(0))
    >>> x["R"].shape, x["theta"].shape
    ((3, 3), (2,))
    """
    leaves = _spaces(space)
    keys = iter(jax.random.split(prng_key(rng_key), len(leaves)))
    return _map(lambda s: s.uniform(next(keys), dtype), space)


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


# ---------------------------------------------------------------------- gradients and momenta


def trivialised_value_and_grad[P: PyTree](
    logdensity_fn: Callable[[P], ArrayLike], space: SpaceTree
) -> Callable[[P], tuple[jax.Array, P]]:
    """``x ↦ (log π(x), ∇ log π(x))`` with the gradient in algebra coordinates: left-trivialised
    on groups (``d/dε log π(g exp(εX_k))``), Riemannian on spheres, ordinary on ``Rᵈ``.

    Examples
    --------
    The height on S²: its Riemannian gradient vanishes at the pole and is ``e_z`` on the equator:

    >>> from liesample.spaces import Sphere, trivialised_value_and_grad
    >>> value_and_grad = trivialised_value_and_grad(lambda x: x[2], Sphere(2))
    >>> value, grad = value_and_grad(jnp.array([1.0, 0.0, 0.0]))
    >>> float(value), grad.tolist()
    (0.0, [0.0, 0.0, 1.0])
    """

    def value_and_grad(position: P) -> tuple[jax.Array, P]:
        def along(eps: P) -> ArrayLike:
            return logdensity_fn(_map(lambda s, x, e: s.perturb(x, e), space, position, eps))

        zero = zero_momentum(space, position)
        return jax.value_and_grad(along)(zero)

    return value_and_grad


def zero_momentum(space: SpaceTree, position: PyTree) -> PyTree:
    """The zero momentum of every block (algebra coordinates, in the position's dtype).

    Examples
    --------
    >>> from liesample.spaces import SO, zero_momentum
    >>> zero_momentum(SO(3), jnp.eye(3)).shape  # one algebra coordinate per generator
    (3,)
    """
    return _map(
        lambda s, x: jnp.zeros(s.momentum_array_shape, s.momentum_dtype(x)), space, position
    )
