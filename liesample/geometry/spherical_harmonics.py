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
"""

from __future__ import annotations

import functools
import math

import jax.numpy as jnp
import numpy as np

__all__ = [
    "degrees_and_orders",
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


def real_spherical_harmonics(x, max_degree: int, min_degree: int = 0):
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


def transport_modes(x, max_degree: int):
    """``ψ_ℓm = Y_ℓ^m / √(ℓ(ℓ+1))`` for ``1 ≤ ℓ ≤ L``, shape ``(..., L(L+2))``.

    The noise potentials of the paper's ``eq:stoch-diss-point-vortex``: their velocity fields
    ``x × ∇ψ_ℓm`` are orthonormal in ``L²(S²)`` (``∫|∇ψ_ℓm|² = 1``).
    """
    max_degree = _check_transport_degree(max_degree)
    q, angular = _legendre_and_angular(x, max_degree)
    ell, m = degrees_and_orders(max_degree, 1)
    scale = jnp.asarray(_transport_scale(max_degree), dtype=q.dtype)
    return scale * q[..., ell, np.abs(m)] * angular[..., max_degree + m]


@functools.lru_cache(maxsize=None)
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


@functools.lru_cache(maxsize=None)
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


def transport_mode(x, max_degree: int, index):
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
