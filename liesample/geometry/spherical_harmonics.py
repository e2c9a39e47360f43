"""Real orthonormal spherical harmonics in JAX, as polynomials in Cartesian coordinates.

The transport noise of point vortices (paper, ``sec:stoch-diss-point-vortices`` and
``eq:stoch-diss-point-vortex``) needs ``Y_ℓ^m`` and its gradient at every vortex. Here

    Y_ℓ^0 = q_ℓ0(z),   Y_ℓ^m = √2 q_ℓm(z) Re (x + iy)^m,   Y_ℓ^{−m} = √2 q_ℓm(z) Im (x + iy)^m

for ``1 ≤ m ≤ ℓ``, evaluated at the unit vector ``u = x/|x|``. ``q_ℓm`` is the fully normalised
associated Legendre function divided by ``sin^m θ`` (a polynomial in ``z = cos θ``), computed by
the standard stable three-term recurrences; ``(x + iy)^m = sin^m θ e^{imφ}`` is a polynomial
too. So there is no ``1/sin θ`` anywhere: values and autodiff gradients are smooth at the
poles. No Condon–Shortley phase: ``Y_ℓ^m = √2 (−1)^m Re Y_ℓ^{m, complex}`` in the physics
convention (``scipy.special.sph_harm_y``), ``Y_ℓ^{−m} = √2 (−1)^m Im Y_ℓ^{m, complex}``.

Evaluating at ``x/|x|`` extends each function to ``R³ \\ {0}`` as a 0-homogeneous function, so
its gradient is tangent to the sphere: a generator built from it rotates a point along the
sphere only (no spin about the point itself).

Ordering: degree ``ℓ = ℓ_min … L``, then ``m = −ℓ … ℓ``; the index of ``(ℓ, m)`` is
``ℓ² + ℓ + m − ℓ_min²``. :func:`degrees_and_orders` lists them.

Gridded fields: :func:`harmonic_analysis` (samples on a latitude–longitude grid → coefficients,
by quadrature on a :func:`gauss_legendre_grid` or by least squares on any colatitudes) and
:func:`harmonic_synthesis` (back), in NumPy float64 with O(L³) work: a discrete Fourier
transform in longitude, then one Legendre sum or small least-squares problem per order.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

__all__ = [
    "degrees_and_orders",
    "gauss_legendre_grid",
    "harmonic_analysis",
    "harmonic_synthesis",
    "num_harmonics",
    "real_spherical_harmonics",
    "transport_mode",
    "transport_modes",
]


def _check_degrees(max_degree, min_degree):
    for name, value in (("max_degree", max_degree), ("min_degree", min_degree)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int, got {value!r}")
    if min_degree < 0:
        raise ValueError(f"min_degree must be >= 0, got {min_degree}")
    if max_degree < min_degree:
        raise ValueError(f"max_degree must be >= min_degree = {min_degree}, got {max_degree}")
    return int(max_degree), int(min_degree)


def num_harmonics(max_degree: int, min_degree: int = 0) -> int:
    """``Σ_{ℓ=min}^{max} (2ℓ+1) = (L+1)² − ℓ_min²``."""
    max_degree, min_degree = _check_degrees(max_degree, min_degree)
    return (max_degree + 1) ** 2 - min_degree**2


def degrees_and_orders(max_degree: int, min_degree: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(ℓ, m)`` of every output column, in order (two int arrays)."""
    max_degree, min_degree = _check_degrees(max_degree, min_degree)
    pairs = [(ell, m) for ell in range(min_degree, max_degree + 1) for m in range(-ell, ell + 1)]
    ell, m = np.array(pairs, dtype=np.int64).T
    return ell, m


def _recurrence_coefficients(max_degree):
    """Coefficient vectors (over ``m = 0 … L``) of the degree recurrence, one row per ``ℓ``.

    ``q_ℓ = A_ℓ z q_{ℓ−1} − B_ℓ q_{ℓ−2} + C_ℓ (q_{ℓ−1} shifted by one order)``, which packs
    ``q_ℓm = a_ℓm (z q_{ℓ−1,m} − b_ℓm q_{ℓ−2,m})`` (``m ≤ ℓ−2``),
    ``q_{ℓ,ℓ−1} = √(2ℓ+1) z q_{ℓ−1,ℓ−1}`` and ``q_ℓℓ = √((2ℓ+1)/(2ℓ)) q_{ℓ−1,ℓ−1}``.
    """
    size = max_degree + 1
    a = np.zeros((size, size))
    b = np.zeros((size, size))
    c = np.zeros((size, size))
    for ell in range(1, size):
        for m in range(ell - 1):
            a[ell, m] = math.sqrt((4 * ell * ell - 1) / (ell * ell - m * m))
            b[ell, m] = a[ell, m] * math.sqrt(((ell - 1) ** 2 - m * m) / (4 * (ell - 1) ** 2 - 1))
        a[ell, ell - 1] = math.sqrt(2 * ell + 1)
        c[ell, ell] = math.sqrt((2 * ell + 1) / (2 * ell))
    return a, b, c


def _legendre_over_sin_power(z, max_degree):
    """``q[..., ℓ, m]`` for ``0 ≤ m ≤ ℓ ≤ L`` (zero for ``m > ℓ``): ``P̄_ℓ^m(z) / sin^m θ``, with
    ``∫|P̄_ℓ^m e^{imφ}|² dΩ = 1``.

    The standard recurrences of the fully normalised functions (``q_00 = 1/√(4π)``, then
    :func:`_recurrence_coefficients`), vectorised over ``m``: values stay O(1) (no factorials)
    for every degree, and the graph has a few operations per degree.
    """
    a, b, c = (jnp.asarray(v, dtype=z.dtype) for v in _recurrence_coefficients(max_degree))
    size = max_degree + 1
    first = jnp.zeros((*z.shape, size), z.dtype).at[..., 0].set(1.0 / math.sqrt(4.0 * math.pi))
    rows = [first]
    previous = jnp.zeros_like(first)
    for ell in range(1, size):
        current = rows[-1]
        shifted = jnp.concatenate([jnp.zeros_like(current[..., :1]), current[..., :-1]], axis=-1)
        rows.append(a[ell] * z[..., None] * current - b[ell] * previous + c[ell] * shifted)
        previous = current
    return jnp.stack(rows, axis=-2)


def _legendre_and_angular(x, max_degree):
    """``q[..., ℓ, m]`` (:func:`_legendre_over_sin_power`) and ``angular[..., L + m]`` (``s_{|m|}``
    for ``m < 0``, 1 for ``m = 0``, ``c_m`` for ``m > 0``) at ``u = x/|x|``."""
    x = jnp.asarray(x)
    if x.shape[-1:] != (3,):
        raise ValueError(f"x must have shape (..., 3), got {x.shape}")
    u = x / jnp.linalg.norm(x, axis=-1, keepdims=True)
    ux, uy, uz = u[..., 0], u[..., 1], u[..., 2]
    q = _legendre_over_sin_power(uz, max_degree)
    # (x + iy)^m = c_m + i s_m by the recurrence (c, s) <- (c x - s y, c y + s x).
    cos_part, sin_part = [jnp.ones_like(ux)], [jnp.zeros_like(ux)]
    for _ in range(max_degree):
        c, s = cos_part[-1], sin_part[-1]
        cos_part.append(c * ux - s * uy)
        sin_part.append(c * uy + s * ux)
    return q, jnp.stack(sin_part[:0:-1] + cos_part, axis=-1)


def real_spherical_harmonics(x: ArrayLike, max_degree: int, min_degree: int = 0) -> jax.Array:
    """Real orthonormal ``Y_ℓ^m(x/|x|)`` for ``ℓ_min ≤ ℓ ≤ L``, shape ``(..., (L+1)² − ℓ_min²)``.

    ``x`` has shape ``(..., 3)`` and must be nonzero. Orthonormal on the unit sphere:
    ``∫ Y_ℓ^m Y_ℓ'^m' dΩ = δ δ``.
    """
    max_degree, min_degree = _check_degrees(max_degree, min_degree)
    q, angular = _legendre_and_angular(x, max_degree)
    ell, m = degrees_and_orders(max_degree, min_degree)
    factor = np.where(m == 0, 1.0, math.sqrt(2.0))
    legendre = q[..., ell, np.abs(m)]
    return jnp.asarray(factor, dtype=q.dtype) * legendre * angular[..., max_degree + m]


def _check_transport_degree(max_degree):
    if isinstance(max_degree, bool) or not isinstance(max_degree, (int, np.integer)):
        raise TypeError(f"max_degree must be an int >= 1, got {max_degree!r}")
    if max_degree < 1:
        raise ValueError(
            f"max_degree must be >= 1 (transport modes start at ℓ = 1), got {max_degree}"
        )
    return int(max_degree)


def _transport_scale(max_degree):
    """``√2^{[m≠0]} / √(ℓ(ℓ+1))`` of each transport mode, in order."""
    ell, m = degrees_and_orders(max_degree, 1)
    return np.where(m == 0, 1.0, math.sqrt(2.0)) / np.sqrt(ell * (ell + 1.0))


def transport_modes(x: ArrayLike, max_degree: int) -> jax.Array:
    """``ψ_ℓm = Y_ℓ^m / √(ℓ(ℓ+1))`` for ``1 ≤ ℓ ≤ L``, shape ``(..., L(L+2))``.

    The noise potentials of the paper's ``eq:stoch-diss-point-vortex``: their velocity fields
    ``x × ∇ψ_ℓm`` are orthonormal in ``L²(S²)`` (``∫|∇ψ_ℓm|² = 1``).
    """
    max_degree = _check_transport_degree(max_degree)
    q, angular = _legendre_and_angular(x, max_degree)
    ell, m = degrees_and_orders(max_degree, 1)
    scale = jnp.asarray(_transport_scale(max_degree), dtype=q.dtype)
    return scale * q[..., ell, np.abs(m)] * angular[..., max_degree + m]


@functools.cache
def _legendre_polynomials(max_degree):
    """Monomial coefficients ``A[ℓ, m, k]`` of ``q_ℓm(z) = Σ_k A[ℓ, m, k] z^k`` (float64), by the
    recurrences of :func:`_legendre_over_sin_power` run on coefficient arrays, and the condition
    number ``max_{ℓ,m} max_{|z|≤1} Σ_k |A z^k| / |q|`` of evaluating them from monomials."""
    a, b, c = _recurrence_coefficients(max_degree)
    size = max_degree + 1
    current = np.zeros((size, size + 1))
    current[0, 0] = 1.0 / math.sqrt(4.0 * math.pi)
    previous = np.zeros_like(current)
    rows = [current]
    for ell in range(1, size):
        times_z = np.concatenate([np.zeros((size, 1)), current[:, :-1]], axis=1)
        shifted = np.concatenate([np.zeros((1, size + 1)), current[:-1]], axis=0)
        new = a[ell][:, None] * times_z - b[ell][:, None] * previous + c[ell][:, None] * shifted
        previous, current = current, new
        rows.append(current)
    coefficients = np.stack(rows)[..., :size]
    z = np.linspace(-1.0, 1.0, 1001)
    powers = z[:, None] ** np.arange(size)
    values = np.abs(np.einsum("zk,lmk->zlm", powers, coefficients))
    bounds = np.einsum("zk,lmk->zlm", np.abs(powers), np.abs(coefficients))
    valid = np.tril(np.ones((size, size), bool))
    condition = float(np.max(bounds.max(0)[valid] / values.max(0)[valid]))
    return coefficients, condition


@functools.cache
def _angular_binomials(max_degree):
    """``B[L + m, a]``: ``angular_m(x, y) = Σ_a B[L + m, a] x^a y^{|m|−a}``, where ``angular_m`` is
    ``Re (x + iy)^m`` for ``m ≥ 0`` and ``Im (x + iy)^{|m|}`` for ``m < 0``."""
    table = np.zeros((2 * max_degree + 1, max_degree + 1))
    for order in range(max_degree + 1):
        for j in range(order + 1):  # the term C(order, j) x^{order−j} (iy)^j
            term = math.comb(order, j) * (-1) ** (j // 2)
            if j % 2 == 0:
                table[max_degree + order, order - j] = term
            elif order > 0:
                table[max_degree - order, order - j] = term
    return table


# Monomial evaluation of one mode is used while it loses at most this relative accuracy.
_MONOMIAL_ACCURACY = 1e-10


def transport_mode(x: ArrayLike, max_degree: int, index: ArrayLike) -> jax.Array:
    """The single column ``index`` of :func:`transport_modes` (``index`` may be traced), shape
    ``x.shape[:-1]``: one mode without evaluating all ``L(L+2)`` of them.

    Where it is accurate (``L ≤ 16`` in float64, ``L ≤ 4`` in float32) the mode is evaluated
    from monomials, ``q_ℓm(z) = Σ_k A_k z^k`` times ``Re``/``Im (x + iy)^{|m|}`` expanded in
    ``x^a y^b``: a fixed handful of operations whatever ``L`` (the splitting integrator
    evaluates one mode per piece, ``L(L+2)`` pieces per step). Otherwise: the stable
    recurrences, then the one column.
    """
    max_degree = _check_transport_degree(max_degree)
    x = jnp.asarray(x)
    if x.shape[-1:] != (3,):
        raise ValueError(f"x must have shape (..., 3), got {x.shape}")
    ell, m = (jnp.asarray(v)[index] for v in degrees_and_orders(max_degree, 1))
    scale = jnp.asarray(_transport_scale(max_degree), dtype=x.dtype)[index]
    coefficients, condition = _legendre_polynomials(max_degree)
    if condition * float(jnp.finfo(x.dtype).eps) > _MONOMIAL_ACCURACY:
        q, angular = _legendre_and_angular(x, max_degree)
        legendre = jnp.take(jnp.take(q, ell, axis=-2), jnp.abs(m), axis=-1)
        return scale * legendre * jnp.take(angular, max_degree + m, axis=-1)
    u = x / jnp.linalg.norm(x, axis=-1, keepdims=True)
    degrees = jnp.arange(max_degree + 1)
    columns = [jnp.ones_like(u)]
    for _ in range(max_degree):  # elementwise: XLA fuses the chain into one kernel
        columns.append(columns[-1] * u)
    powers = jnp.stack(columns, axis=-1)  # (..., 3, L+1)
    legendre = powers[..., 2, :] @ jnp.asarray(coefficients, dtype=x.dtype)[ell, jnp.abs(m)]
    # Re / Im (x + iy)^{|m|} = Σ_a B_a x^a y^{|m|−a}
    # (binomial expansion, :func:`_angular_binomials`)
    binomials = jnp.asarray(_angular_binomials(max_degree), dtype=x.dtype)[max_degree + m]
    # y^{|m|−a} for each a, by a 0/1 matrix rather than a gather (batched gathers and their
    # scatter-add transposes are slow on CPU)
    select = (jnp.abs(m) - degrees)[:, None] == degrees[None, :]
    y_powers = powers[..., 1, :] @ select.T.astype(x.dtype)
    angular = jnp.sum(binomials * powers[..., 0, :] * y_powers, axis=-1)
    return scale * legendre * angular


# ---------------------------------------------------------------------------------------------
# Transforms between a latitude–longitude grid and coefficients (NumPy, float64)
# ---------------------------------------------------------------------------------------------


def gauss_legendre_grid(
    max_degree: int, num_theta: int | None = None, num_phi: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grid on which :func:`harmonic_analysis` is exact for degree ``≤ L``.

    Returns ``(theta, phi, weights)``: ``num_theta ≥ L + 1`` Gauss–Legendre colatitudes
    (ascending), ``num_phi ≥ 2L + 1`` equispaced longitudes from 0, and the latitude weights
    (``Σ weights = 2``, the quadrature of ``∫ dz``). The product of two functions of degree ``≤ L``
    is integrated exactly. Defaults: the smallest sizes.
    """
    max_degree, _ = _check_degrees(max_degree, 0)
    num_theta = max_degree + 1 if num_theta is None else int(num_theta)
    num_phi = 2 * max_degree + 1 if num_phi is None else int(num_phi)
    if num_theta < max_degree + 1 or num_phi < 2 * max_degree + 1:
        raise ValueError(
            f"an exact grid for degree {max_degree} needs num_theta >= {max_degree + 1} and "
            f"num_phi >= {2 * max_degree + 1}, got {num_theta} and {num_phi}"
        )
    z, weights = np.polynomial.legendre.leggauss(num_theta)
    theta = np.arccos(z[::-1])
    return theta, 2.0 * np.pi * np.arange(num_phi) / num_phi, weights[::-1].copy()


def _legendre_table(theta, max_degree):
    """``G[t, ℓ, m] = f_m q_ℓm(cos θ_t) sin^m θ_t`` (``f_0 = 1``, else ``√2``) in float64, zero
    for ``m > ℓ``: the latitude factor of ``Y_ℓ^{±m}`` (:func:`real_spherical_harmonics`)."""
    theta = np.asarray(theta, dtype=float)
    if theta.ndim != 1 or np.any((theta < 0) | (theta > np.pi)):
        raise ValueError("theta must be a 1-D array of colatitudes in [0, π]")
    a, b, c = _recurrence_coefficients(max_degree)
    z = np.cos(theta)
    current = np.zeros((theta.size, max_degree + 1))
    current[:, 0] = 1.0 / math.sqrt(4.0 * math.pi)
    previous = np.zeros_like(current)
    rows = [current]
    for ell in range(1, max_degree + 1):
        shifted = np.concatenate([np.zeros_like(current[:, :1]), current[:, :-1]], axis=1)
        previous, current = (
            current,
            a[ell] * z[:, None] * current - b[ell] * previous + (c[ell] * shifted),
        )
        rows.append(current)
    q = np.stack(rows, axis=1)  # [t, ℓ, m]
    orders = np.arange(max_degree + 1)
    factor = np.where(orders == 0, 1.0, math.sqrt(2.0))
    return q * factor * np.sin(theta)[:, None, None] ** orders


def _check_grid(values, theta, max_degree):
    values = np.asarray(values, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if values.ndim < 2 or values.shape[-2] != theta.size:
        raise ValueError(
            f"values must have shape (..., num_theta, num_phi) with num_theta = {theta.size}, "
            f"got {values.shape}"
        )
    if values.shape[-1] < 2 * max_degree + 1:
        raise ValueError(
            f"degree {max_degree} needs num_phi >= {2 * max_degree + 1} equispaced longitudes, "
            f"got {values.shape[-1]}"
        )
    return values, theta


def harmonic_analysis(
    values: npt.ArrayLike,
    theta: npt.ArrayLike,
    max_degree: int,
    weights: npt.ArrayLike | None = None,
) -> np.ndarray:
    """Coefficients ``c_ℓm`` (order of :func:`degrees_and_orders`) of ``f ≈ Σ c_ℓm Y_ℓ^m`` from
    samples ``values[..., t, p] = f(θ_t, φ_p)``, ``φ_p = 2πp/num_phi`` (``num_phi ≥ 2L + 1``).

    The longitudes are resolved exactly by a discrete Fourier transform; then, order by order:

    - ``weights`` given (latitude weights for ``∫ dz``, e.g. :func:`gauss_legendre_grid`):
      quadrature, ``c_ℓm = Σ w_t (2π/num_phi) Σ_p f Y_ℓ^m`` — the ``L²`` projection, exact for
      band-limited ``f`` on a Gauss–Legendre grid;
    - ``weights=None``: least squares over the colatitudes ``theta`` (any ``≥ L + 1`` distinct
      values, e.g. an equiangular grid), exact for band-limited ``f``.
    """
    max_degree, _ = _check_degrees(max_degree, 0)
    values, theta = _check_grid(values, theta, max_degree)
    num_phi = values.shape[-1]
    spectrum = np.fft.rfft(values, axis=-1)[..., : max_degree + 1]  # Σ_p f e^{−imφ_p}
    table = _legendre_table(theta, max_degree)
    ell, m = degrees_and_orders(max_degree)
    out = np.zeros(values.shape[:-2] + (ell.size,))
    if weights is not None:
        weights = np.asarray(weights, dtype=float)
        if weights.shape != theta.shape:
            raise ValueError(f"weights must have shape {theta.shape}, got {weights.shape}")
        scale = (2.0 * np.pi / num_phi) * weights[:, None]
        cosine = np.einsum("...tm,tlm->...lm", spectrum.real * scale, table)
        sine = np.einsum("...tm,tlm->...lm", -spectrum.imag * scale, table)
        return np.where(m >= 0, cosine[..., ell, np.abs(m)], sine[..., ell, np.abs(m)])
    if np.unique(theta).size < max_degree + 1:
        raise ValueError(
            f"least squares for degree {max_degree} needs >= {max_degree + 1} distinct "
            f"colatitudes, got {np.unique(theta).size}"
        )
    # f = Σ_m A_m(θ) cos mφ + B_m(θ) sin mφ: A_0 = F_0/n, A_m = 2 Re F_m/n, B_m = −2 Im F_m/n.
    norm = np.where(np.arange(max_degree + 1) == 0, 1.0, 2.0) / num_phi
    cosine, sine = spectrum.real * norm, -spectrum.imag * norm
    for order in range(max_degree + 1):
        rows = table[:, order:, order]  # [t, ℓ − m]
        columns = np.flatnonzero(m == order)
        for part, index in ((cosine, columns), (sine, np.flatnonzero(m == -order))):
            if order == 0 and part is sine:
                continue
            flat = part[..., order].reshape(-1, theta.size).T
            solution = np.linalg.lstsq(rows, flat, rcond=None)[0]
            out[..., index] = solution.T.reshape(values.shape[:-2] + (index.size,))
    return out


def harmonic_synthesis(
    coefficients: npt.ArrayLike, theta: npt.ArrayLike, num_phi: int
) -> np.ndarray:
    """``f(θ_t, φ_p) = Σ c_ℓm Y_ℓ^m`` on colatitudes ``theta`` and ``num_phi`` equispaced
    longitudes from 0: shape ``(..., num_theta, num_phi)``; the inverse of
    :func:`harmonic_analysis` for band-limited fields. ``coefficients`` has ``(L + 1)²`` entries
    in the order of :func:`degrees_and_orders`. O(L³)."""
    coefficients = np.asarray(coefficients, dtype=float)
    max_degree = math.isqrt(coefficients.shape[-1]) - 1
    if coefficients.ndim < 1 or (max_degree + 1) ** 2 != coefficients.shape[-1]:
        raise ValueError(
            f"coefficients must have (L + 1)² entries on the last axis, got {coefficients.shape}"
        )
    table = _legendre_table(theta, max_degree)
    ell, m = degrees_and_orders(max_degree)
    orders = np.arange(max_degree + 1)
    cosine = np.zeros(coefficients.shape[:-1] + (max_degree + 1, max_degree + 1))
    sine = np.zeros_like(cosine)
    cosine[..., ell[m >= 0], m[m >= 0]] = coefficients[..., m >= 0]
    sine[..., ell[m < 0], -m[m < 0]] = coefficients[..., m < 0]
    phi = 2.0 * np.pi * np.arange(int(num_phi)) / int(num_phi)
    angle = orders[:, None] * phi[None, :]
    a = np.einsum("...lm,tlm->...tm", cosine, table)
    b = np.einsum("...lm,tlm->...tm", sine, table)
    return a @ np.cos(angle) + b @ np.sin(angle)
