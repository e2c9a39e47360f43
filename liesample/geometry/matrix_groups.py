"""The matrix groups ``SO(n)`` (:class:`SO`) and ``SU(n)`` (:class:`SU`): their algebra
bases, the hat and vee maps, and the group exponential that is their kinetic flow.

The momentum is in algebra coordinates, an orthonormal basis of ``g`` for the bi-invariant
inner product ``⟨X, Y⟩ = ½ Re tr(X†Y)``. With the bi-invariant metric (one inverse mass per
copy) the kinetic flow is the one-parameter subgroup ``g ↦ g exp(t m⁻¹ p)`` with ``p``
constant (:mod:`liesample.geometry.spaces` says why a general mass would not be); the
exponential is Rodrigues' formula on ``SO(3)``, closed form on ``SU(2)``, an
eigendecomposition of the anti-Hermitian generator otherwise.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import DTypeLike

from liesample.geometry.space_base import Space, _norm, _order, _shape, _sinc, _versine

__all__ = ["SO", "SU"]


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
