"""Zeitlin's su(N) model of 2-D Euler on the sphere, with transport noise and derived dissipation.

The paper's dissipative SALT-Euler equation (``eq:salt-euler-with-dissipation``) is formal in
infinite dimensions; Zeitlin's quantisation is its structure-preserving finite model. The
vorticity is a skew-Hermitian trace-free matrix ``W ∈ su(N)``, stored as the real ``N × N``
coordinates of :class:`liesample.geometry.algebras.Unitary` (``x = Re W + Im W``; pairing
``⟨W, Ξ⟩ = −tr(WΞ)``, the Frobenius product). With the engine's conventions (paper,
``eq:lie-poisson``) ``Ẇ = ad*_{∇h} W = [W, ∇h]``; ``∇h = −P`` below, so this is Zeitlin's
``Ẇ = [P, W]``.

**Quantised harmonics** (Hoppe–Yau). ``S₁, S₂, S₃`` are the spin-``s = (N−1)/2`` matrices
(``S₃ = diag(s, s−1, …, −s)``, ``S₊ = S₁ + iS₂`` upper bidiagonal). The quantised Laplacian is
``Δ_N W = −Σ_k [S_k, [S_k, W]]``; it maps each diagonal of ``W`` to itself (``[S₃, ·]`` is ``m`` on
the ``m``-th superdiagonal), acting there as a real symmetric tridiagonal matrix whose
eigenvalues are ``ℓ(ℓ+1)``, ``ℓ = |m| … N−1``. Its eigenvectors ``T_ℓm`` (computed once per
``N`` in NumPy, ``scipy.linalg.eigh_tridiagonal``: O(N³) time, N³ floats of memory) have the
Condon–Shortley phases of spherical tensor operators: ``T_ℓ0`` has a positive leading
coefficient as a polynomial in ``S₃`` (so its value at the north pole ``μ = s`` is positive) and
``[S₊, T_ℓm] = √(ℓ(ℓ+1) − m(m+1)) T_ℓ,m+1``, which makes the coherent-state symbol of ``T_ℓm``
a positive multiple of ``Y_ℓm``. The real orthonormal basis
``E_ℓm`` of ``u(N)`` matches :mod:`liesample.geometry.spherical_harmonics` (no Condon–Shortley
phase)::

    E_ℓ0 = i T_ℓ0,   E_ℓm = (−1)^m i (T_ℓm + T_ℓmᵀ)/√2,   E_ℓ,−m = (−1)^m (T_ℓm − T_ℓmᵀ)/√2,

so the vorticity ``ω = Σ ω_ℓm Y_ℓm`` (``ℓ < N``, ``Y_ℓm`` orthonormal on the unit sphere) is
``W = Σ ω_ℓm E_ℓm`` and ``‖W‖² = ∫ω²`` (enstrophy ×2). ``ℓ = 0`` is the trace, absent in su(N).

**Hamiltonian.** ``P = Δ_N⁻¹ W`` (trace-free) and ``h(W) = ½ tr(PW) = −½⟨W, Δ_N⁻¹W⟩
= ½ Σ_ℓm ω_ℓm² / (ℓ(ℓ+1)) ≥ 0``, the kinetic energy ``½∫|∇ψ|²`` of the band-limited flow.
``Δ_N⁻¹`` is applied by one batched product with the pseudo-inverse of each diagonal's
tridiagonal operator (``V diag(1/(ℓ(ℓ+1))) Vᵀ``, N³ numbers like the eigenvectors; O(N³)
flops, no LAPACK call);
the coadjoint move costs O(N³): the exponential of a skew-Hermitian matrix by matrix products
alone (:class:`SkewHermitianUnitary`) and two products.

**Noise.** ``ĥ_ℓm(W) = ⟨W, ψ_ℓm⟩`` for ``1 ≤ ℓ ≤ L`` with ``ψ_ℓm = (ℓ(ℓ+1))^{−n/2} E_ℓm``,
orthonormal in the ``⟨α, (−Δ)ⁿβ⟩`` inner product (the paper's choice, with ``n`` =
``noise_smoothness``; default ``n = 1``: the noise velocity fields are L²-orthonormal). Linear,
so ``adjusted_lie_poisson`` applies; the dissipation is derived by the engine.

**N = 2**: ``su(2) ≅ so(3)`` by ``μ ↦ W = −i Σ_k μ_k σ_k`` (Pauli matrices), which maps the
rigid body's dual pairing and bracket onto these (``⟨W(μ), W(ν)⟩ = 2μ·ν`` and the generators
``−(i/2)σ_k`` obey ``[e_j, e_k] = ε_jkl e_l``): ``h = ½|μ|²`` (the rigid body with isotropic
inertia 1) and the ``ℓ = 1`` noise with ``n = 1`` is ``ĥ = Rμ`` for a rotation ``R``
(:func:`su2_from_so3`, :func:`so3_from_su2`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
from jax.typing import ArrayLike

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.precision import check_dtype, float64_hint, roundoff_tolerance
from liesample.foundation.validation import concrete_array, float_array
from liesample.geometry.algebras import Unitary
from liesample.geometry.spherical_harmonics import degrees_and_orders, real_spherical_harmonics
from liesample.integrators.orbit import Integrator
from liesample.targets.zeitlin import UnitaryOrbitLaw

__all__ = [
    "QuantisedHarmonics",
    "SkewHermitianUnitary",
    "isospectral_midpoint",
    "quantised_harmonics",
    "random_vorticity",
    "so3_from_su2",
    "su2_from_so3",
    "zeitlin_euler",
]


def _check_size(size):
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 2:
        raise ValueError(f"N must be an int >= 2 (su(N) with N = 1 is trivial), got {size!r}")
    return int(size)


class QuantisedHarmonics:
    """The quantised spherical harmonics of su(N) and the operators built on them.

    Every method takes real ``(..., N, N)`` coordinates
    (:class:`liesample.geometry.algebras.Unitary`) and broadcasts over leading axes. Build with
    :func:`quantised_harmonics` (cached per ``N``).
    """

    def __init__(self, size: int):
        n = self.size = _check_size(size)
        s = 0.5 * (n - 1)
        mu = s - np.arange(n)
        # (S₊)_{i,i+1} = √(s(s+1) − μ_{i+1}(μ_{i+1}+1))
        ladder = np.sqrt(s * (s + 1) - mu[1:] * (mu[1:] + 1))
        # On the m-th diagonal (entries x_k = W[k, k+m]), L = Σ_k [S_k,[S_k,·]] is tridiagonal:
        # (Lx)_k = (2s(s+1) − 2μ_k μ_{k+m}) x_k − a_k a_{k+m} x_{k+1} − a_{k−1} a_{k+m−1} x_{k−1}.
        diagonal = np.ones((n, n))
        off = np.zeros((n, n))
        vectors = np.zeros((n, n, n))
        for m in range(n):
            length = n - m
            diagonal[m, :length] = 2 * s * (s + 1) - 2 * mu[:length] * mu[m : m + length]
            off[m, : length - 1] = -ladder[: length - 1] * ladder[m : m + length - 1]
            values, v = scipy.linalg.eigh_tridiagonal(diagonal[m, :length], off[m, : length - 1])
            ell = np.arange(m, n)
            if not np.allclose(values, ell * (ell + 1), rtol=1e-9, atol=1e-9 * n * n):
                raise ArithmeticError(f"quantised Laplacian spectrum is off for N = {n}, m = {m}")
            vectors[m, :length, :length] = v
        # Phases (module docstring). m = 0: ⟨S₃ T_{ℓ−1,0}, T_ℓ0⟩ > 0, i.e. positive leading
        # coefficients, T_00 ∝ I positive; robust where the pole value itself is tiny.
        v0 = vectors[0]
        if v0[:, 0].sum() < 0:
            v0[:, 0] *= -1
        for ell in range(1, n):
            if np.sum(mu * v0[:, ell - 1] * v0[:, ell]) < 0:
                v0[:, ell] *= -1
        # m → m+1: ⟨[S₊, T_ℓm], T_ℓ,m+1⟩ > 0, with [S₊, T]_{p,p+m+1} = a_p x_{p+1} − x_p a_{p+m}.
        for m in range(n - 1):
            length = n - m
            x = vectors[m, :length, 1:length]  # ℓ = m+1 … N−1
            raised = ladder[: length - 1, None] * x[1:] - x[:-1] * ladder[m : m + length - 1, None]
            overlap = np.sum(raised * vectors[m + 1, : length - 1, : length - 1], axis=0)
            vectors[m + 1, :, : length - 1] *= np.where(overlap < 0, -1.0, 1.0)
        self.spin = s
        self.ladder = ladder
        self.eigenvectors = vectors  # [m, position along the diagonal, ℓ − m]
        index = np.arange(n)
        valid = index[None, :] < n - index[:, None]  # [m, k]: k < N − m
        self._valid = valid
        # The diagonals are read and written by pads and reshapes (:meth:`_pack`): no gather,
        # and their transposes (in every gradient) are slices, not scatters. Masks [half, m, k]:
        # the valid entries, and for writing back the main diagonal from the upper half only.
        self._pack_mask = np.stack([valid, valid]).astype(float)
        self._unpack_mask = self._pack_mask.copy()
        self._unpack_mask[1, 0, :] = 0.0
        # Scatter back as a gather from concat(upper, lower) (flattened; NumPy, in basis()).
        i, j = index[:, None], index[None, :]
        self._unpack_index = np.where(j >= i, (j - i) * n + i, n * n + (i - j) * n + j)
        # The tridiagonal bands of Δ_N⁻¹ (padded rows are identities; on m = 0, kernel I, the
        # last unknown pinned to 0), kept for peers that solve them (benchmarks/zeitlin.py).
        d, lo, up = diagonal.copy(), np.zeros((n, n)), np.zeros((n, n))
        up[:, :-1] = off[:, :-1]
        lo[:, 1:] = off[:, :-1]
        d[0, n - 1], lo[0, n - 1], up[0, n - 2] = 1.0, 0.0, 0.0
        self._solve_bands = (lo, d, up)
        # Δ_N⁻¹ on each diagonal as a dense matrix, V diag(1/(ℓ(ℓ+1))) Vᵀ with ℓ = 0 (the trace,
        # on m = 0) sent to 0: the pseudo-inverse, N³ floats like the eigenvectors. Applied
        # by one batched product (no LAPACK call, and its derivative is the same product).
        weights = np.zeros((n, n))
        for m in range(n):
            ell = np.arange(m, n)
            weights[m, : n - m] = np.where(ell > 0, 1.0 / np.maximum(ell * (ell + 1.0), 1.0), 0.0)
        inverse = np.einsum("mik,mk,mjk->mij", vectors, weights, vectors)
        centre = np.eye(n) - 1.0 / n  # m = 0: exactly trace-free in and out, to round-off
        inverse[0] = centre @ inverse[0] @ centre
        self._inverse = 0.5 * (inverse + np.swapaxes(inverse, -1, -2))
        ell = index[:, None] + index[None, :]  # [m, k] -> ℓ = m + k
        self._ell = np.where(valid, ell, 0)
        # Coefficient vector order: ℓ = 0 … N−1, m = −ℓ … ℓ
        # (liesample.geometry.spherical_harmonics).
        ell_c, m_c = degrees_and_orders(n - 1)
        am = np.abs(m_c)
        sign = (-1.0) ** am
        self._coef_rows = am * n + (ell_c - am)  # into the flattened [m, ℓ − m] arrays
        root = 1.0 / math.sqrt(2.0)
        self._coef_upper = np.where(m_c == 0, 1.0, sign * root)
        self._coef_lower = np.where(m_c == 0, 0.0, np.where(m_c > 0, 1.0, -1.0) * sign * root)
        self.degrees, self.orders = ell_c, m_c
        # from_coefficients' rows: [term (+m, −m), half, row] -> coefficient index and weight.
        rows = n * n
        index = np.zeros((2, 2, rows), int)
        weights = np.zeros((2, 2, rows))
        for term, chosen in enumerate((m_c >= 0, m_c < 0)):
            where = np.flatnonzero(chosen)
            for half, coefficient in enumerate((self._coef_upper, self._coef_lower)):
                index[term, half, self._coef_rows[where]] = where
                weights[term, half, self._coef_rows[where]] = coefficient[where]
        present = np.zeros((2, 2, rows), bool)
        present[0, :, self._coef_rows[m_c >= 0]] = True
        present[1, :, self._coef_rows[m_c < 0]] = True
        self._row_terms = (index, weights, present)

    # -- diagonals ------------------------------------------------------------------------

    def _pack(self, x):
        """``(..., 2, N, N)``: the upper and lower diagonals ``[m, k]`` (``x[k, k+m]`` and
        ``x[k+m, k]``), zero-padded."""
        x = jnp.asarray(x)
        both = jnp.stack([x, jnp.swapaxes(x, -1, -2)], axis=-3)
        return _skew(both, self.size) * jnp.asarray(self._pack_mask, dtype=both.dtype)

    def _unpack(self, packed):
        """The inverse of :meth:`_pack` (the main diagonal read from the upper half)."""
        packed = jnp.asarray(packed)
        halves = _unskew(packed * jnp.asarray(self._unpack_mask, dtype=packed.dtype), self.size)
        return halves[..., 0, :, :] + jnp.swapaxes(halves[..., 1, :, :], -1, -2)

    # -- operators ------------------------------------------------------------------------

    def laplacian(self, x: ArrayLike) -> jax.Array:
        """``Δ_N W = −Σ_k [S_k, [S_k, W]]`` (eigenvalues ``−ℓ(ℓ+1)``), in O(N²)."""
        p = self._pack(x)
        lo, d, up = (jnp.asarray(b) for b in self._operator_bands())
        shifted_up = jnp.concatenate([p[..., 1:], jnp.zeros_like(p[..., :1])], axis=-1)
        shifted_down = jnp.concatenate([jnp.zeros_like(p[..., :1]), p[..., :-1]], axis=-1)
        return -self._unpack(d * p + up * shifted_up + lo * shifted_down)

    def _operator_bands(self):
        n = self.size
        valid = self._valid
        s, mu = self.spin, self.spin - np.arange(n)
        d = np.zeros((n, n))
        up = np.zeros((n, n))
        for m in range(n):
            length = n - m
            d[m, :length] = 2 * s * (s + 1) - 2 * mu[:length] * mu[m : m + length]
            up[m, : length - 1] = -self.ladder[: length - 1] * self.ladder[m : m + length - 1]
        lo = np.zeros((n, n))
        lo[:, 1:] = up[:, :-1]
        return lo * valid, d * valid, up * valid

    def inverse_laplacian(self, x: ArrayLike) -> jax.Array:
        """``P = Δ_N⁻¹ W`` on trace-free ``W`` (the trace part is sent to 0): one batched
        product with the pseudo-inverse of each diagonal's tridiagonal operator, O(N³) flops on
        O(N²) numbers."""
        p = self._pack(x)
        inverse = jnp.asarray(self._inverse, dtype=p.dtype)
        return -self._unpack(jnp.einsum("mij,...hmj->...hmi", inverse, p))

    def energy(self, x: ArrayLike) -> jax.Array:
        """``h = −½⟨W, Δ_N⁻¹W⟩ = ½ Σ ω_ℓm²/(ℓ(ℓ+1))`` (shape ``x.shape[:-2]``).

        Its derivative is declared (``jax.custom_jvp``): ``Δ_N⁻¹`` is self-adjoint, so
        ``dh = −⟨Δ_N⁻¹W, dW⟩`` reuses the one product of the value, and a gradient transposes a
        product instead of the pseudo-inverse and the diagonal reads."""
        return _energy(self, jnp.asarray(x))

    # -- spherical-harmonic coefficients --------------------------------------------------

    def coefficients(self, x: ArrayLike) -> jax.Array:
        """``ω_ℓm`` with ``W = Σ ω_ℓm E_ℓm``, shape ``(..., N²)``, order ``(ℓ, m)`` as in
        :func:`liesample.geometry.spherical_harmonics.degrees_and_orders` (``ℓ ≤ N−1``). O(N³)."""
        v = jnp.asarray(self.eigenvectors, dtype=jnp.result_type(x, float))
        p = self._pack(x)
        c = jnp.einsum("mik,...mi->...mk", v, p)  # [..., 2, m, ℓ − m]
        flat = jnp.reshape(c, c.shape[:-2] + (self.size * self.size,))
        rows = flat[..., self._coef_rows]  # one gather for both halves
        return self._coef_upper * rows[..., 0, :] + self._coef_lower * rows[..., 1, :]

    def from_coefficients(self, coefficients: ArrayLike) -> jax.Array:
        """The inverse of :meth:`coefficients` (the transform is orthogonal)."""
        coefficients = jnp.asarray(coefficients)
        n = self.size
        if coefficients.shape[-1:] != (n * n,):
            raise ValueError(
                f"coefficients must have shape (..., {n * n}), got {coefficients.shape}"
            )
        batch = coefficients.shape[:-1]
        # Each row [|m|, ℓ − |m|] holds the terms of ±m: two gathers, not a scatter.
        index, weights, present = self._row_terms
        terms = coefficients[..., index] * jnp.asarray(weights, coefficients.dtype)
        terms = jnp.where(present, terms, 0.0)
        c = (terms[..., 0, :, :] + terms[..., 1, :, :]).reshape(batch + (2, n, n))
        v = jnp.asarray(self.eigenvectors, dtype=coefficients.dtype)
        p = jnp.einsum("mik,...mk->...mi", v, c)
        return self._unpack(p)

    def basis(self, max_degree: int, min_degree: int = 1) -> np.ndarray:
        """The matrices ``E_ℓm`` (real coordinates), ``min ≤ ℓ ≤ max``, shape ``(K, N, N)``."""
        if not 0 <= min_degree <= max_degree < self.size:
            raise ValueError(
                f"degrees must satisfy 0 <= min_degree <= max_degree <= N − 1 = {self.size - 1}, "
                f"got min_degree={min_degree}, max_degree={max_degree}"
            )
        # In NumPy (no program to compile): each matrix is :meth:`from_coefficients` of a unit
        # vector, whose one nonzero term per entry makes every sum exact, as in JAX.
        n = self.size
        first, last = min_degree**2, (max_degree + 1) ** 2
        rows, count = self._coef_rows[first:last], last - first
        packed = np.zeros((count, 2, n * n))
        packed[np.arange(count), 0, rows] = self._coef_upper[first:last]
        packed[np.arange(count), 1, rows] = self._coef_lower[first:last]
        p = np.matmul(self.eigenvectors, packed.reshape(count, 2, n, n, 1))[..., 0]
        return p.reshape(count, 2 * n * n)[:, self._unpack_index]

    def energy_spectrum(self, x: ArrayLike) -> jax.Array:
        """Energy per degree ``ε_ℓ = ½ Σ_m ω_ℓm²/(ℓ(ℓ+1))``, ``ℓ = 1 … N−1``; shape
        ``(..., N−1)``."""
        c = self.coefficients(x)
        ell = self.degrees
        weights = np.where(ell > 0, 0.5 / np.maximum(ell * (ell + 1), 1), 0.0)
        per_mode = c**2 * weights
        onehot = (ell[:, None] == np.arange(1, self.size)[None, :]).astype(float)
        return per_mode @ jnp.asarray(onehot, dtype=per_mode.dtype)

    def grid(
        self, x: ArrayLike, num_theta: int = 64, num_phi: int = 128
    ) -> tuple[np.ndarray, np.ndarray, jax.Array]:
        """The vorticity ``ω(θ, φ) = Σ ω_ℓm Y_ℓm`` on a ``(num_theta, num_phi)`` grid
        (cell-centred colatitudes, longitudes from 0): ``(theta, phi, values)``, values of shape
        ``x.shape[:-2] + (num_theta, num_phi)``. Evaluated row by row (bounded memory)."""
        theta = (np.arange(num_theta) + 0.5) * np.pi / num_theta
        phi = np.arange(num_phi) * 2 * np.pi / num_phi
        c = self.coefficients(jnp.asarray(x, dtype=float))
        values = _grid_values(c, jnp.asarray(theta), jnp.asarray(phi), self.size - 1)
        return theta, phi, values


def _skew(x, n):
    """``[..., m, k] = x[..., k, k+m]`` where ``k + m < n`` (other entries: other entries of
    ``x`` or 0; masked by the caller), by pads and reshapes: row ``k`` of ``x`` padded to
    ``n + 1`` columns and read with stride ``n + 2`` puts ``x[k, k+m]`` at ``(k, m)``."""
    lead = x.shape[:-2]
    none = [(0, 0, 0)] * len(lead)
    rows = jax.lax.pad(x, jnp.zeros((), x.dtype), none + [(0, 0, 0), (0, 1, 0)])
    flat = jax.lax.pad(
        jnp.reshape(rows, lead + (n * (n + 1),)), jnp.zeros((), x.dtype), none + [(0, n, 0)]
    )
    strided = jnp.reshape(flat, lead + (n, n + 2))[..., :n]
    return jnp.swapaxes(strided, -1, -2)


def _unskew(diagonals, n):
    """The transpose of :func:`_skew` on ``[..., m, k]`` arrays that are 0 where ``k + m ≥ n``:
    the upper triangle ``x[k, k+m] = diagonals[m, k]``, zeros below."""
    lead = diagonals.shape[:-2]
    none = [(0, 0, 0)] * len(lead)
    strided = jax.lax.pad(
        jnp.swapaxes(diagonals, -1, -2),
        jnp.zeros((), diagonals.dtype),
        none + [(0, 0, 0), (0, 2, 0)],
    )
    flat = jnp.reshape(strided, lead + (n * (n + 2),))[..., : n * (n + 1)]
    return jnp.reshape(flat, lead + (n, n + 1))[..., :n]


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _energy(harmonics, x):
    return -0.5 * jnp.sum(x * harmonics.inverse_laplacian(x), axis=(-2, -1))


@_energy.defjvp
def _energy_jvp(harmonics, primals, tangents):
    (x,), (dx,) = primals, tangents
    p = harmonics.inverse_laplacian(x)
    return -0.5 * jnp.sum(x * p, axis=(-2, -1)), -jnp.sum(p * dx, axis=(-2, -1))


@functools.partial(jax.jit, static_argnums=3)
def _grid_values(coefficients, theta, phi, max_degree):
    """``Σ_ℓm c_ℓm Y_ℓm(θ, φ)``, one colatitude row at a time (compiled once per shape)."""

    def row(t):
        points = jnp.stack(
            [jnp.sin(t) * jnp.cos(phi), jnp.sin(t) * jnp.sin(phi), jnp.cos(t) + 0.0 * phi], -1
        )
        y = real_spherical_harmonics(points, max_degree)  # (num_phi, (L+1)²)
        return jnp.einsum("pk,...k->...p", y, coefficients)

    values = jax.lax.map(row, theta)  # (num_theta, ..., num_phi)
    return jnp.moveaxis(values, 0, -2)


@functools.lru_cache(maxsize=8)
def quantised_harmonics(size: int) -> QuantisedHarmonics:
    """:class:`QuantisedHarmonics` of ``su(N)``, built once per ``N``."""
    return QuantisedHarmonics(size)


@functools.lru_cache(maxsize=8)
def _compiled_from_coefficients(harmonics):
    return jax.jit(harmonics.from_coefficients)


def random_vorticity(
    size: int, seed: int = 0, slope: float = 1.0, enstrophy: float = 0.5
) -> np.ndarray:
    """A trace-free vorticity with Gaussian coefficients ``ω_ℓm ∝ ℓ^{−slope/2}`` (all ``ℓ ≥ 1``),
    scaled to the enstrophy ``½∫ω² = ½‖W‖² = enstrophy``; real coordinates, shape ``(N, N)``.
    The default ``0.5`` is ``‖W‖² = 1``. (For a given energy spectrum:
    :func:`liesample.systems.zeitlin_states.spectral_vorticity`.)"""
    basis = quantised_harmonics(size)
    rng = np.random.default_rng(seed)
    ell = basis.degrees
    amplitude = np.where(ell > 0, np.maximum(ell, 1.0) ** (-slope / 2), 0.0)
    c = rng.standard_normal(ell.shape) * amplitude
    c *= math.sqrt(2.0 * enstrophy / np.sum(c**2))
    return np.asarray(_compiled_from_coefficients(basis)(jnp.asarray(c)))


def su2_from_so3(mu: ArrayLike) -> jax.Array:
    """``μ ∈ so(3)* ↦ W = −i Σ_k μ_k σ_k ∈ su(2)*`` in real coordinates, shape ``(..., 2, 2)``."""
    mu = jnp.asarray(mu)
    m1, m2, m3 = mu[..., 0], mu[..., 1], mu[..., 2]
    return jnp.stack([jnp.stack([-m3, -m1 - m2], -1), jnp.stack([m2 - m1, m3], -1)], -2)


def so3_from_su2(x: ArrayLike) -> jax.Array:
    """The inverse of :func:`su2_from_so3` (the trace part of ``x`` is dropped); its transpose is
    ``½ su2_from_so3``, so gradients map to the matching su(2) generators."""
    x = jnp.asarray(x)
    m1 = -0.5 * (x[..., 0, 1] + x[..., 1, 0])
    m2 = 0.5 * (x[..., 1, 0] - x[..., 0, 1])
    m3 = 0.5 * (x[..., 1, 1] - x[..., 0, 0])
    return jnp.stack([m1, m2, m3], -1)


# Noise streams kept as dense (m, N, N) arrays up to this many entries, and evaluated by one
# contraction while m ≤ this many times N (beyond, the O(N³) harmonic transform is cheaper).
_MAX_DENSE_STREAM_ENTRIES = 1 << 22
_DENSE_NOISE_DIRECTIONS_PER_N = 4

# Taylor degree of the exponential and the largest norm it takes without a squaring: the
# remainder θ^17/17! stays below the double-precision unit round-off 2^−53.
_TAYLOR_DEGREE = 16
_TAYLOR_RADIUS = 0.8
# Coefficients of (e^A − I)/A = Σ_k A^k/(k+1)!, k < _TAYLOR_DEGREE.
_EXPM1_COEFFICIENTS = tuple(1.0 / math.factorial(k + 1) for k in range(_TAYLOR_DEGREE))


def _skew_hermitian_exponential(a):
    """``e^{A}`` for skew-Hermitian ``A`` (complex ``(..., N, N)``) by matrix products alone.

    Scaling and squaring specialised to the unitary group, carried out on ``X = e^{A} − I``
    rather than on ``e^{A}``: ``A/2^s`` with ``s`` the fewest halvings that bring a norm bound
    (the smaller of the 1-norm and the Frobenius norm, both ``≥ ‖A‖₂``; chosen per matrix, not
    differentiated) within ``_TAYLOR_RADIUS``; ``X = A·Σ_k A^k/(k+1)!`` to degree 16, by
    Paterson–Stockmeyer in ``A⁴``; ``s`` squarings ``X ← 2X + X²``; one Newton–Schulz step
    towards the polar factor, ``U ← U(3 − U*U)/2`` with ``U*U − I = X + X* + X*X``; then
    ``U = I + X``.

    Why ``X``: next to ``I`` the entries of ``U*U − I`` are below the resolution of numbers
    near 1, so a Newton–Schulz step on ``U`` itself cannot see its own unitarity error. That
    error is systematic for a move repeated along one direction (a splitting moves along the
    same noise field every step), and the Casimirs then drift linearly in the number of
    steps; on ``X`` the step removes it, and what remains is random round-off.

    No LAPACK call (no linear solve, as a Padé approximant needs), so nothing waits on a
    threaded BLAS; batched over leading axes (a matrix that needs fewer squarings keeps its
    value while the others square). Unitary to round-off; the value is accurate to round-off
    times ``‖A‖₂``, as for any scaling and squaring.
    """
    norm = jax.lax.stop_gradient(
        jnp.minimum(
            jnp.max(jnp.sum(jnp.abs(a), axis=-2), axis=-1),
            jnp.sqrt(jnp.sum(jnp.abs(a) ** 2, axis=(-2, -1))),
        )
    )
    squarings = jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / _TAYLOR_RADIUS))
    squarings = jnp.maximum(squarings, 0.0).astype(jnp.int32)
    a = a * jnp.exp2(-squarings.astype(norm.dtype))[..., None, None].astype(a.dtype)
    eye = jnp.eye(a.shape[-1], dtype=a.dtype)
    a2 = a @ a
    a3 = a2 @ a
    a4 = a2 @ a2
    c = _EXPM1_COEFFICIENTS

    def block(j):  # Σ_{i<4} c_{4j+i} Aⁱ
        return c[4 * j] * eye + c[4 * j + 1] * a + c[4 * j + 2] * a2 + c[4 * j + 3] * a3

    series = block(_TAYLOR_DEGREE // 4 - 1)
    for j in range(_TAYLOR_DEGREE // 4 - 2, -1, -1):
        series = series @ a4 + block(j)
    x = a @ series  # e^{A} − I

    def square(i, x):  # (I + X)² = I + (2X + X²)
        return jnp.where((i < squarings)[..., None, None], 2.0 * x + x @ x, x)

    x = jax.lax.fori_loop(0, jnp.max(squarings), square, x)
    x_star = jnp.conj(jnp.swapaxes(x, -1, -2))
    unitarity_error = x + x_star + x_star @ x  # U*U − I, never formed from U
    x = x - 0.5 * unitarity_error - 0.5 * x @ unitarity_error
    return eye + x


@dataclass(frozen=True, init=False)
class SkewHermitianUnitary(Unitary):
    """:class:`liesample.geometry.algebras.Unitary` whose group element
    ``e^{−Z}`` is computed for what ``Z`` is: skew-Hermitian.

    The general ``expm`` (a Padé approximant, one LU solve, scaling and squaring) calls LAPACK
    for the solve; on a shared machine a threaded LAPACK's workers spin and that one call
    dominates the step. Here the exponential is matrix products only
    (:func:`_skew_hermitian_exponential`): same map to round-off, and differentiable in
    forward mode at ``Z = 0`` (the step-size rule differentiates moves along the noise), which
    an eigendecomposition with its degenerate eigenvalues is not.
    """

    def group_element(self, zeta: ArrayLike) -> jax.Array:
        """``U = e^{−Z}`` (unitary to round-off)."""
        return _skew_hermitian_exponential(-self.to_matrix(zeta))

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``e^{−Z} W e^{Z}`` (:meth:`Unitary.coadjoint_exp`), computed once where it is used:
        XLA would otherwise copy the projection onto the skew-Hermitian part into each of its
        uses (the energy, the brackets, the acceptance), each with transposes of its own."""
        return jax.lax.optimization_barrier(super().coadjoint_exp(zeta, mu))


TRACE_TOLERANCE = 1e-10
"""The float64 floor of the trace a start may have, relative to its norm (in float32 the
round-off of the start's dtype sets it: :meth:`ZeitlinSystem.check_position`)."""


class ZeitlinSystem(LiePoissonSystem):
    """A :class:`LiePoissonSystem` whose states must also be trace-free (su(N), not u(N))."""

    def step_casimir_error(self, mu: ArrayLike, reference_casimirs: jax.Array) -> jax.Array:
        """Relative drift of the Casimir ``‖W‖² = −tr(W²)`` alone: O(N²), what the adjusted
        sampler reports per step (``casimir_error`` of its Info).

        Every move is a conjugation ``U W U*``, which changes the spectrum only through the
        round-off of ``U``'s unitarity, and that shows in ``‖W‖²``; :meth:`casimir_error`
        compares the whole spectrum (one Hermitian eigenvalue problem, O(N³)).
        """
        norm_sq = jnp.sum(jnp.asarray(mu) ** 2, axis=(-2, -1))
        reference = reference_casimirs[..., -1]
        return jnp.abs(norm_sq - reference) / jnp.maximum(jnp.abs(reference), norm_sq)

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        """The base checks, and a trace-free state: ``|tr W| ≤ tol · ‖W‖`` with ``tol`` the
        larger of ``1e-10`` and ``N`` sums' round-off in the start's dtype
        (:func:`liesample.foundation.precision.roundoff_tolerance`)."""
        super().check_position(position, name)
        value = concrete_array(position)
        if value is not None:
            dtype = check_dtype(value)
            trace, size = float(np.trace(value)), float(np.linalg.norm(value))
            tolerance = roundoff_tolerance(dtype, floor=TRACE_TOLERANCE, terms=len(value))
            if abs(trace) > tolerance * max(size, 1e-300):
                raise ValueError(
                    f"{name} must be trace-free (a vorticity in su(N)); its trace is {trace:.3g} "
                    f"(allowed: {tolerance:.2g} of its norm {size:.3g}). Subtract trace/N from "
                    "the diagonal." + float64_hint(dtype)
                )


@by_value
def zeitlin_euler(
    size: int,
    noise_degree: int | None = None,
    noise_smoothness: int = 1,
    position: ArrayLike | None = None,
) -> ZeitlinSystem:
    """Zeitlin's su(N) Euler equations on the sphere with transport noise (module docstring).

    **Choosing the noise.** The Gibbs law ``exp(−βh)`` on the orbit does not depend on the
    noise: ``noise_degree`` and ``noise_smoothness`` set only how fast a sampler mixes, and any
    ``L ≥ 2`` is exact with ``adjusted_lie_poisson``. The defaults force every resolved degree
    (``L = N − 1``) with L²-orthonormal velocity fields (``n = 1``), as measured (the project's
    Zeitlin benchmark): at ``β > 0`` every choice mixes every degree's energy within a
    few steps; at ``β < 0`` energy must flow into ``ℓ = 1`` (condensation), and noise on the
    large scales alone (small ``L``) reaches stationarity from points spread over the orbit in
    many times more steps, and gives a lower ESS per step of the slowest degree, than noise on
    every degree; smoother noise (``n = 2``) is slower there than ``n ≤ 1``. With the adjusted
    sampler the noise costs one O(N³) harmonic transform per step whatever ``L``. The
    unadjusted sampler's ``splitting`` integrator moves one noise direction at a time, so its
    step costs ``L(L + 2)`` moves: pass a small ``noise_degree`` there.

    Parameters
    ----------
    size : int
        ``N ≥ 2``; the vorticity is resolved up to degree ``ℓ = N − 1``.
    noise_degree : int or None
        ``L``: noise Hamiltonians from the ``L(L+2)`` modes ``1 ≤ ℓ ≤ L`` (``L ≤ N − 1``);
        ``None`` (default): ``N − 1``, every resolved degree.
        ``L = 1`` is refused for ``N ≥ 3``: rigid rotations alone keep ``h`` fixed (for
        ``N = 2`` they are the whole algebra and ``h`` is a Casimir).
    noise_smoothness : int
        ``n ≥ 0``: ``ψ_ℓm = (ℓ(ℓ+1))^{−n/2} E_ℓm`` is orthonormal in ``⟨α, (−Δ)ⁿβ⟩``
        (default 1).
    position : array (N, N), optional
        Default start; :func:`random_vorticity` (seed 0, ``‖W‖² = 1``) when omitted.

    Returns
    -------
    LiePoissonSystem
        Algebra ``u(N)`` (:class:`liesample.geometry.algebras.Unitary`); Casimirs the spectrum of
        ``iW`` and ``‖W‖²``. ``system.params["harmonics"]`` is the :class:`QuantisedHarmonics`;
        ``system.params["noise_streams"]`` the ``ψ_i`` as an ``(m, N, N)`` array, or ``None``
        where that would be large (many directions at large ``N``).
        ``system.reference(beta, position)`` is the exact orbit law by Haar importance sampling
        (:class:`liesample.targets.zeitlin.UnitaryOrbitLaw`), for small ``N``.

    Examples
    --------
    >>> from liesample.systems import zeitlin_euler
    >>> system = zeitlin_euler(3)  # su(3): degrees ℓ = 1, 2
    >>> system.event_shape, system.num_noises  # L(L + 2) noise modes, L = N − 1
    ((3, 3), 8)
    >>> type(system.reference(1.0, system.default_position)).__name__
    'UnitaryOrbitLaw'
    """
    size = _check_size(size)
    if noise_degree is None:
        noise_degree = size - 1
    for name, value, low, high in (
        ("noise_degree", noise_degree, 1, size - 1),
        ("noise_smoothness", noise_smoothness, 0, None),
    ):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int, got {value!r}")
        if value < low or (high is not None and value > high):
            allowed = f"{low} … {high}" if high is not None else f">= {low}"
            raise ValueError(f"{name} must be in {allowed} for N = {size}, got {value}")
    if noise_degree == 1 and size > 2:
        raise ValueError(
            f"noise_degree=1 cannot mix for N = {size}: the ℓ = 1 noise fields are rigid "
            "rotations of the sphere, which commute with the Laplacian, so {h, ĥ_i} = 0, the "
            "energy h never changes and no sampler reaches the Gibbs law. Use noise_degree >= 2"
        )
    harmonics = quantised_harmonics(size)
    algebra = SkewHermitianUnitary(size)
    num_noises = (noise_degree + 1) ** 2 - 1
    ell = harmonics.degrees[1 : num_noises + 1]
    weights = (ell * (ell + 1.0)) ** (-0.5 * noise_smoothness)
    # The streams ψ_i as dense matrices (m N² floats) where that is small; the noise is then one
    # contraction, O(m N²). With many directions the harmonic transform, O(N³), is cheaper.
    streams = None
    if num_noises * size * size <= _MAX_DENSE_STREAM_ENTRIES:
        streams = harmonics.basis(noise_degree, 1) * weights[:, None, None]
        streams.setflags(write=False)

    def hamiltonian(x):
        return harmonics.energy(x)

    if streams is not None and num_noises <= _DENSE_NOISE_DIRECTIONS_PER_N * size:

        def noise_hamiltonians(x):
            return jnp.einsum("knm,...nm->...k", jnp.asarray(streams, dtype=x.dtype), x)

    else:

        def noise_hamiltonians(x):
            coefficients = harmonics.coefficients(x)[..., 1 : num_noises + 1]
            return coefficients * jnp.asarray(weights, dtype=coefficients.dtype)

    def reference(beta, position):
        return UnitaryOrbitLaw(
            lambda xs: np.asarray(jax.jit(hamiltonian)(jnp.asarray(xs))), position, beta
        )

    if position is None:
        position = random_vorticity(size)
    position = float_array(position, f"position must be a real ({size}, {size}) array", TypeError)
    system = ZeitlinSystem(
        name=f"Zeitlin su({size}) Euler",
        algebra=algebra,
        hamiltonian=hamiltonian,
        noise_hamiltonians=noise_hamiltonians,
        num_noises=num_noises,
        event_shape=(size, size),
        default_position=position,
        reference=reference,
        # the ℓ ≤ L modes with L >= 2 generate su(N) under brackets (checked by the rank test of
        # liesample.dynamics.noise_span in tests/test_noise_span.py)
        noise_reach="orbit",
        params={
            "N": size,
            "noise_degree": noise_degree,
            "noise_smoothness": noise_smoothness,
            "harmonics": harmonics,
            "noise_streams": streams,
        },
        positive_casimirs=(size,),
        casimir_scale=algebra.casimir_scale,
    )
    system.check_position(position)
    return system


# ---------------------------------------------------------------------------------------------
# Isospectral midpoint (Modin–Viviani)
# ---------------------------------------------------------------------------------------------

_MIDPOINT_TOLERANCE = 1e-14
_MIDPOINT_MAX_ITERATIONS = 100


def _isospectral_midpoint(dynamics, mu, dt, dW):
    """One step of the isospectral midpoint rule for ``Ẇ = [B(W), W]``, ``B = −ζ`` (the engine's
    generator, so ``ad*_ζ W = [W, ζ] = [B, W]``), with the step's ``dt``/``dW`` frozen.

    With ``A = ½ B(W̃)``: ``W_n = (I − A) W̃ (I + A)`` defines ``W̃`` (fixed-point iteration
    ``W̃ ← W_n + [A, W̃] + A W̃ A`` to relative ``1e-14``, at most 100 sweeps), and
    ``W_{n+1} = (I + A) W̃ (I − A)`` is computed as ``C W_n C*`` with the Cayley transform
    ``C = (I + A)(I − A)⁻¹`` (unitary: ``A`` is skew-Hermitian), which is the same matrix when
    ``W̃`` solves its equation and isospectral to round-off whatever the iteration's residual.
    """
    algebra = dynamics.algebra
    if not isinstance(algebra, Unitary):
        raise TypeError(
            f"isospectral_midpoint needs a system on u(N) (liesample.geometry.algebras.Unitary), "
            f"got the algebra {algebra.name}"
        )
    w0 = algebra.to_matrix(mu)

    def half_b(x):
        return -0.5 * algebra.to_matrix(dynamics.generator(x, dt, dW))

    def update(x):
        a, w = half_b(x), algebra.to_matrix(x)
        return algebra.from_matrix(w0 + a @ w - w @ a + a @ w @ a)

    scale = jnp.sqrt(jnp.sum(mu * mu))

    def not_done(carry):
        x, previous, count = carry
        change = jnp.sqrt(jnp.sum((x - previous) ** 2))
        return (change > _MIDPOINT_TOLERANCE * scale) & (count < _MIDPOINT_MAX_ITERATIONS)

    def iterate(carry):
        x, _, count = carry
        return update(x), x, count + 1

    x_mid, _, _ = jax.lax.while_loop(not_done, iterate, (update(mu), mu, 1))
    a = half_b(x_mid)
    eye = jnp.eye(algebra.size, dtype=a.dtype)
    cayley = jnp.linalg.solve(eye - a, eye + a)  # (I + A)(I − A)⁻¹ (the factors commute)
    return algebra.from_matrix(cayley @ w0 @ jnp.conj(jnp.swapaxes(cayley, -1, -2)))


isospectral_midpoint = Integrator(
    "isospectral_midpoint",
    weak_order=1,
    preserves_orbit=True,
    step=_isospectral_midpoint,
    description="Modin–Viviani isospectral midpoint on u(N): implicit, second order without "
    "noise, a Cayley conjugation (isospectral to round-off)",
    stability_limit=None,  # implicit; its fixed-point iteration needs dt·‖∇h‖ small, no κ bound
)
