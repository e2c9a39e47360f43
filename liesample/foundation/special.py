"""Special functions in JAX: the modified Bessel function ``I_ν(κ)`` in logs.

``log I_ν(κ)`` for a fixed order ``ν ≥ 0`` (a Python number) and ``κ ≥ 0`` (any array, traced or
not), built from elementary JAX operations only, so ``jit``, ``vmap``, ``jax.grad`` and
``jax.hessian`` apply to any order with no callback into the host. Two branches:

- ``κ ≤ 25``: the power series ``I_ν(κ) = (κ/2)^ν / Γ(ν+1) · Σ_k (κ²/4)^k / (k! (ν+1)_k)``, whose
  terms are all positive (no cancellation), 48 terms, summed as powers of ``κ²/25² ≤ 1``;
- ``κ > 25``: Debye's uniform expansion (DLMF 10.41.3) written in ``r = √(ν² + κ²)`` and
  ``p = ν/r``: ``I_ν(κ) ≈ e^{r} (κ/(ν+r))^ν / √(2π r) · Σ_k U_k(p)/ν^k`` with
  ``U_k(p)/ν^k = r^{−k} Σ_j u_{kj} p^{2j}`` (so ``ν = 0`` is Hankel's large-argument series), 20
  terms. The polynomials ``U_k`` come from their recurrence (DLMF 10.41.9) in exact rational
  arithmetic. With ``r > 25`` the first omitted term is below ``1e−17`` relative for every
  ``ν``.

Both branches are evaluated at inputs clipped to their own range and joined by ``jnp.where``,
so neither produces a NaN in the other's range (nor in its derivatives). The order enters the
compiled code as a value, not a constant: one compile serves every order. ``log_bessel_i0`` is a
cheaper ``log I₀`` (from ``jax.scipy.special.i0e``) for quadrature rules with many nodes.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaln, i0e, i1e
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float

__all__ = [
    "bessel_iv_ratio",
    "log_bessel_i0",
    "log_bessel_iv",
    "log_bessel_iv_reduced",
    "log_bessel_ive",
]

_SWITCH = 25.0  # the series below, Debye's expansion above
_SERIES_TERMS = 48  # at κ = 25 the 48th term (κ²/4)^k / (k!)² is e^{−61} of the sum
_DEBYE_TERMS = 20  # max_p |U_21(p)/p^21| / 25^21 < 1e−17


def _order(order) -> float:
    return finite_float("order", order, nonnegative=True)


@functools.lru_cache(maxsize=1)
def _debye_polynomials() -> tuple[tuple[Fraction, ...], ...]:
    """Coefficients (in powers of ``p``) of ``U_0, …, U_K``:
    ``U_{k+1}(p) = ½ p²(1 − p²) U_k'(p) + ⅛ ∫_0^p (1 − 5t²) U_k(t) dt``, ``U_0 = 1``."""
    polynomials: list[tuple[Fraction, ...]] = [(Fraction(1),)]
    for _ in range(_DEBYE_TERMS):
        u = polynomials[-1]
        new = [Fraction(0)] * (len(u) + 3)
        for i in range(1, len(u)):  # ½ p²(1 − p²) · i u_i p^{i−1}
            new[i + 1] += Fraction(i, 2) * u[i]
            new[i + 3] -= Fraction(i, 2) * u[i]
        for i, c in enumerate(u):  # ⅛ ∫ (1 − 5t²) u_i t^i
            new[i + 1] += c / (8 * (i + 1))
            new[i + 3] -= 5 * c / (8 * (i + 3))
        polynomials.append(tuple(new))
    return tuple(polynomials)


@functools.lru_cache(maxsize=1)
def _debye_matrix() -> np.ndarray:
    """``C`` (K, K+1): ``U_k(p) = p^k Σ_j C[k−1, j] p^{2j}`` for ``k = 1…K``."""
    matrix = np.zeros((_DEBYE_TERMS, _DEBYE_TERMS + 1))
    for k, u in enumerate(_debye_polynomials()[1:], start=1):
        coefficients = [float(c) for c in u[k::2]]
        matrix[k - 1, : len(coefficients)] = coefficients
    return matrix


def _powers(z, n: int):
    """``(z⁰, z¹, …, zⁿ)`` along a new last axis, by repeated doubling: products only, so every
    derivative is exact also at ``z = 0`` (``z ** k`` is not)."""
    powers = jnp.stack([jnp.ones_like(z), z], axis=-1)
    while powers.shape[-1] < n + 1:
        top = powers[..., -1:] * z[..., None]  # z^m, m = current length
        powers = jnp.concatenate([powers, powers * top], axis=-1)
    return powers[..., : n + 1]


def _log_series(order, kappa):
    """``log Σ_k (κ²/4)^k / (k! (ν+1)_k)``: the reduced function on the series branch, summed in
    powers of ``z = κ²/25² ≤ 1`` with coefficients ``Q^k / (k! (ν+1)_k)``, ``Q = 25²/4`` (no power
    overflows, in any precision; the coefficients are products, not logs, of their ratios)."""
    k = jnp.arange(1, _SERIES_TERMS + 1, dtype=kappa.dtype)
    coefficients = jnp.cumprod(0.25 * _SWITCH * _SWITCH / (k * (k + order)))
    z = kappa * kappa / (_SWITCH * _SWITCH)
    return jnp.log1p(jnp.sum(_powers(z, _SERIES_TERMS)[..., 1:] * coefficients, axis=-1))


_HUGE_KAPPA = 1e150
"""Above this ``κ``, Debye's ``√(ν²+κ²)`` is computed as ``κ√(1+(ν/κ)²)`` (``κ²`` would overflow
float64 near ``1e154``)."""


def _log_ive_debye(order, kappa):
    """``log(I_ν(κ) e^{−κ})`` by Debye's expansion (valid for ``√(ν²+κ²) > 25``)."""
    # √(ν²+κ²) without overflow in κ² (κ above ~1e154 in float64): scaled by κ there only, so
    # smaller κ keep their rounding; the safe κ keeps the unused branch's gradient finite
    huge = kappa > _HUGE_KAPPA
    tame = jnp.where(huge, 1.0, kappa)
    r = jnp.where(
        huge, kappa * jnp.sqrt(1.0 + (order / kappa) ** 2), jnp.sqrt(order * order + tame * tame)
    )
    p2 = (order / r) ** 2
    matrix = jnp.asarray(_debye_matrix(), kappa.dtype)
    inner = _powers(p2, _DEBYE_TERMS) @ matrix.T  # U_k(p)/p^k, k = 1…K
    total = jnp.sum(inner * _powers(1.0 / r, _DEBYE_TERMS)[..., 1:], axis=-1)
    return (order * order / (r + kappa) + order * jnp.log(kappa / (order + r))
            - 0.5 * jnp.log(2.0 * math.pi * r) + jnp.log1p(total))  # fmt: skip


def _branches(order, kappa):
    """``(ν, κ, κ ≤ 25, κ for the series, κ for Debye)``, each input safe for its branch."""
    kappa = jnp.asarray(kappa, dtype=jnp.result_type(kappa, float))
    order = jax.lax.stop_gradient(jnp.asarray(order, kappa.dtype))
    small = kappa <= _SWITCH
    k_small, k_large = jnp.where(small, kappa, _SWITCH), jnp.where(small, 2.0 * _SWITCH, kappa)
    return order, kappa, small, k_small, k_large


def _log_half_power(order, kappa):
    """``ν log(κ/2) − log Γ(ν+1)``; ``0`` for ``ν = 0`` (also at ``κ = 0``)."""
    zero = order == 0.0
    safe = jnp.where(zero, 1.0, kappa)
    return jnp.where(zero, 0.0, order * jnp.log(0.5 * safe) - gammaln(order + 1.0))


def log_bessel_iv_reduced(order: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """``log[Γ(ν+1) (κ/2)^{−ν} I_ν(κ)]``: smooth and even in ``κ``, ``0`` at ``κ = 0``.

    Parameters
    ----------
    order : float
        ``ν ≥ 0`` (a Python number, not traced).
    kappa : array_like
        ``κ ≥ 0``, any shape; may be traced.

    Returns
    -------
    jax array, shape of ``kappa``
        Differentiable in ``κ`` to any order, also at ``κ = 0``.
    """
    return _reduced(_order(order), kappa)


@jax.jit
def _reduced(order, kappa):
    order, kappa, small, k_small, k_large = _branches(order, kappa)
    large = _log_ive_debye(order, k_large) + k_large - _log_half_power(order, k_large)
    return jnp.where(small, _log_series(order, k_small), large)


def log_bessel_ive(order: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """``log(I_ν(κ) e^{−κ})`` (as ``log scipy.special.ive``) for ``ν ≥ 0``, ``κ ≥ 0``.

    ``−inf`` at ``κ = 0`` for ``ν > 0``. Differentiable in ``κ`` to any order for ``κ > 0``.
    """
    return _log_ive(_order(order), kappa)


@jax.jit
def _log_ive(order, kappa):
    order, kappa, small, k_small, k_large = _branches(order, kappa)
    series = _log_half_power(order, k_small) + _log_series(order, k_small) - k_small
    return jnp.where(small, series, _log_ive_debye(order, k_large))


def log_bessel_iv(order: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """``log I_ν(κ)`` for a fixed order ``ν ≥ 0`` and ``κ ≥ 0`` (module docstring), shaped like
    ``kappa``; the arguments are those of :func:`log_bessel_iv_reduced`. ``−inf`` at ``κ = 0``
    for ``ν > 0``; ``d/dκ log I_ν(κ) = I_{ν+1}(κ)/I_ν(κ) + ν/κ``, and higher derivatives, by
    ``jax.grad``/``jax.hessian``.

    Examples
    --------
    ``I_{1/2}(κ) = √(2/(πκ)) sinh κ``:

    >>> import numpy as np
    >>> from liesample.numpyro import log_bessel_iv
    >>> value = log_bessel_iv(0.5, jnp.array([1.0]))
    >>> bool(np.allclose(value, np.log(np.sqrt(2 / np.pi) * np.sinh(1.0))))
    True
    """
    return _log_iv(_order(order), kappa)


@jax.jit
def _log_iv(order, kappa):
    order, kappa, small, k_small, k_large = _branches(order, kappa)
    series = _log_half_power(order, k_small) + _log_series(order, k_small)
    return jnp.where(small, series, _log_ive_debye(order, k_large) + k_large)


def bessel_iv_ratio(order: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """``I_{ν+1}(κ) / I_ν(κ)`` (``0`` at ``κ = 0``), differentiable in ``κ`` to any order."""
    return _ratio(_order(order), kappa)


@jax.jit
def _ratio(order, kappa):
    order, kappa, small, k_small, k_large = _branches(order, kappa)
    series = (0.5 * k_small / (order + 1.0)) * jnp.exp(
        _log_series(order + 1.0, k_small) - _log_series(order, k_small)
    )
    debye = jnp.exp(_log_ive_debye(order + 1.0, k_large) - _log_ive_debye(order, k_large))
    return jnp.where(small, series, debye)


# --------------------------------------------------------------------------- order 0, fast


@jax.custom_jvp
def log_bessel_i0(y: ArrayLike) -> jax.Array:
    """``log I₀(y)`` for ``y ≥ 0`` from ``jax.scipy.special.i0e`` (Chebyshev expansions, cheaper
    than :func:`log_bessel_iv` for quadrature rules with many nodes).

    Its derivative is ``I₁/I₀``, exactly ``0`` at ``y = 0`` (differentiating ``y + log i0e(y)``
    directly gives the one-sided ``1`` there), and so on to any order.
    """
    y = jnp.asarray(y, dtype=jnp.result_type(y, float))
    return y + jnp.log(i0e(y))


@log_bessel_i0.defjvp
def _log_bessel_i0_jvp(primals, tangents):
    (y,), (dy,) = primals, tangents
    return log_bessel_i0(y), _i0_ratio(y) * dy


@jax.custom_jvp
def _i0_ratio(y):
    """``R(y) = I₁(y)/I₀(y)``."""
    return i1e(y) / i0e(y)


@_i0_ratio.defjvp
def _i0_ratio_jvp(primals, tangents):
    # R' = 1 − R/y − R² (from I₀' = I₁, I₁' = I₀ − I₁/y); near 0 its series 1/2 − 3y²/16.
    (y,), (dy,) = primals, tangents
    ratio = _i0_ratio(y)
    small = jnp.abs(y) < 1e-4
    safe = jnp.where(small, 1.0, y)
    slope = jnp.where(small, 0.5 - 3.0 * y * y / 16.0, 1.0 - ratio / safe - ratio * ratio)
    return ratio, slope * dy
