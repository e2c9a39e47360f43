"""Special functions in JAX: the modified Bessel function ``I_ν(κ)`` in logs.

``log I_ν(κ)`` for a fixed order ``ν ≥ 0`` (a Python number) and ``κ ≥ 0`` (any array, traced or
not), built from elementary JAX operations only, so ``jit``, ``vmap``, ``jax.grad`` and
``jax.hessian`` apply to any order with no callback into the host. Two branches:

- ``κ ≤ 25``: the power series ``I_ν(κ) = (κ/2)^ν / Γ(ν+1) · Σ_k (κ²/4)^k / (k! (ν+1)_k)``, whose
  terms are all positive (no cancellation), 48 terms in nested (Horner) form;
- ``κ > 25``: Debye's uniform expansion (DLMF 10.41.3) written in ``r = √(ν² + κ²)`` and
  ``p = ν/r``: ``I_ν(κ) ≈ e^{r} (κ/(ν+r))^ν / √(2π r) · Σ_k U_k(p)/ν^k`` with
  ``U_k(p)/ν^k = r^{−k} Σ_j u_{kj} p^{2j}`` (so ``ν = 0`` is Hankel's large-argument series), 20
  terms. The polynomials ``U_k`` come from their recurrence (DLMF 10.41.9) in exact rational
  arithmetic. With ``r > 25`` the first omitted term is below ``1e−17`` relative for every
  ``ν``.

Both branches are evaluated at inputs clipped to their own range and joined by ``jnp.where``,
so neither produces a NaN in the other's range (nor in its derivatives).
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import jax.numpy as jnp

from liesample.foundation.validation import finite_float

__all__ = [
    "bessel_iv_ratio",
    "log_bessel_iv",
    "log_bessel_iv_reduced",
    "log_bessel_ive",
]

_SWITCH = 25.0  # the series below, Debye's expansion above
_SERIES_TERMS = 48  # (κ²/4)^k / (k!)² at κ = 25, k = 48 is e^{−42} of the sum's size
_DEBYE_TERMS = 20  # max_p |U_21(p)/p^21| / 25^21 < 1e−17


def _order(order) -> float:
    return finite_float("order", order, nonnegative=True)


@functools.lru_cache(maxsize=1)
def _debye_polynomials() -> tuple[tuple[Fraction, ...], ...]:
    """Coefficients (in powers of ``p``) of ``U_0, …, U_K``:
    ``U_{k+1}(p) = ½ p²(1 − p²) U_k'(p) + ⅛ ∫_0^p (1 − 5t²) U_k(t) dt``, ``U_0 = 1``."""
    polynomials = [(Fraction(1),)]
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
def _debye_coefficients() -> tuple[tuple[float, ...], ...]:
    """For ``k = 1…K``: ``(u_{k0}, u_{k1}, …)`` with ``U_k(p) = p^k Σ_j u_{kj} p^{2j}``."""
    return tuple(tuple(float(c) for c in u[k::2]) for k, u in enumerate(_debye_polynomials())
                 if k > 0)  # fmt: skip


def _log_series(order: float, kappa):
    """``log Σ_k (κ²/4)^k / (k! (ν+1)_k)``: the reduced function on the series branch."""
    q = 0.25 * kappa * kappa
    nested = jnp.ones_like(kappa)
    for k in range(_SERIES_TERMS, 1, -1):
        nested = 1.0 + q * nested / (k * (k + order))
    return jnp.log1p(q * nested / (1.0 + order))


def _log_ive_debye(order: float, kappa):
    """``log(I_ν(κ) e^{−κ})`` by Debye's expansion (valid for ``√(ν²+κ²) > 25``)."""
    r = jnp.sqrt(order * order + kappa * kappa)
    p2 = (order / r) ** 2
    inverse_r = 1.0 / r
    total = jnp.zeros_like(kappa)
    for coefficients in reversed(_debye_coefficients()):  # Horner in 1/r over k ≥ 1
        inner = jnp.zeros_like(kappa)
        for c in reversed(coefficients):  # Horner in p² over j
            inner = inner * p2 + c
        total = (total + inner) * inverse_r
    log_ive = order * order / (r + kappa) - 0.5 * jnp.log(2.0 * math.pi * r) + jnp.log1p(total)
    if order > 0.0:
        log_ive = log_ive + order * jnp.log(kappa / (order + r))
    return log_ive


def _branches(order: float, kappa):
    kappa = jnp.asarray(kappa, dtype=jnp.result_type(kappa, float))
    small = kappa <= _SWITCH
    return kappa, small, jnp.where(small, kappa, _SWITCH), jnp.where(small, 2.0 * _SWITCH, kappa)


def _log_half_power(order: float, kappa):
    """``ν log(κ/2) − log Γ(ν+1)`` (``−log Γ(1) = 0`` for ``ν = 0``, also at ``κ = 0``)."""
    if order == 0.0:
        return jnp.zeros_like(kappa)
    return order * jnp.log(0.5 * kappa) - math.lgamma(order + 1.0)


def log_bessel_iv_reduced(order, kappa):
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
    order = _order(order)
    kappa, small, k_small, k_large = _branches(order, kappa)
    large = _log_ive_debye(order, k_large) + k_large - _log_half_power(order, k_large)
    return jnp.where(small, _log_series(order, k_small), large)


def log_bessel_ive(order, kappa):
    """``log(I_ν(κ) e^{−κ})`` (as ``log scipy.special.ive``) for ``ν ≥ 0``, ``κ ≥ 0``.

    ``−inf`` at ``κ = 0`` for ``ν > 0``. Differentiable in ``κ`` to any order for ``κ > 0``.
    """
    order = _order(order)
    kappa, small, k_small, k_large = _branches(order, kappa)
    series = _log_half_power(order, k_small) + _log_series(order, k_small) - k_small
    return jnp.where(small, series, _log_ive_debye(order, k_large))


def log_bessel_iv(order, kappa):
    """``log I_ν(κ)`` for a fixed order ``ν ≥ 0`` and ``κ ≥ 0`` (module docstring).

    Parameters
    ----------
    order : float
        ``ν ≥ 0`` (a Python number, not traced).
    kappa : array_like
        ``κ ≥ 0``, any shape; may be traced.

    Returns
    -------
    jax array, shape of ``kappa``
        ``log I_ν(κ)`` (``−inf`` at ``κ = 0`` for ``ν > 0``); ``d/dκ log I_ν(κ) =
        I_{ν+1}(κ)/I_ν(κ) + ν/κ`` and higher derivatives by ``jax.grad``/``jax.hessian``.
    """
    order = _order(order)
    kappa, small, k_small, k_large = _branches(order, kappa)
    series = _log_half_power(order, k_small) + _log_series(order, k_small)
    return jnp.where(small, series, _log_ive_debye(order, k_large) + k_large)


def bessel_iv_ratio(order, kappa):
    """``I_{ν+1}(κ) / I_ν(κ)`` (``0`` at ``κ = 0``), differentiable in ``κ`` to any order."""
    order = _order(order)
    kappa, small, k_small, k_large = _branches(order, kappa)
    series = (0.5 * k_small / (order + 1.0)) * jnp.exp(
        _log_series(order + 1.0, k_small) - _log_series(order, k_small)
    )
    debye = jnp.exp(_log_ive_debye(order + 1.0, k_large) - _log_ive_debye(order, k_large))
    return jnp.where(small, series, debye)
