"""Exact laws of two-dimensional lattice gauge theory with the Wilson action.

In two dimensions the plaquettes of an open lattice are independent, each with the
single-plaquette law ``∝ exp((β/N) Re tr U) dHaar(U)``; on the torus the product of all
plaquettes is constrained and the character expansion gives, for ``V`` plaquettes,

- U(1): ``Z = Σ_k I_k(β)^V`` (times ``e^{−βV}``), the geometric charge ``Q = Σ_P arg U_P / 2π``
  an integer with ``P(Q = q) ∝ ∫ dν cos(2πνq) f(ν)^V``, ``f(ν) = ∫_{−π}^{π} e^{β cos φ}
  cos(νφ) dφ`` (the density of the sum of ``V`` independent plaquette angles at ``2πq``);
- SU(2): ``Z = Σ_{n≥1} ((2/β) I_n(β))^V`` (the spin ``j = (n−1)/2`` term);
- SU(N): ``Z = Σ_λ (c_λ(β)/d_λ)^V`` over the irreducible representations ``λ``, with the
  character coefficients ``c_λ = ∫ χ_λ(U)^* e^{(β/N) Re tr U} dU = Σ_{k∈ℤ}
  det[I_{λ_j+k+i−j}(β/N)]_{i,j=1…N}`` (the Bessel determinant of the unitary group, summed over
  the windings ``k`` that restrict ``U(N)`` to ``SU(N)``) and ``d_λ`` the dimensions.

The plaquette means are ``(1/V) ∂_β log Z`` of these sums. The single-plaquette laws of SU(N)
are integrals over the eigenphases (Weyl's integration formula).
"""

from __future__ import annotations

from typing import cast

import numpy as np
from scipy import special

from liesample.foundation.validation import finite_float

__all__ = [
    "single_plaquette_mean",
    "su2_torus_plaquette_mean",
    "su3_torus_plaquette_mean",
    "sun_character_coefficients",
    "sun_torus_plaquette_mean",
    "u1_torus_charge_law",
    "u1_torus_plaquette_mean",
]

TERMS = 60  # representations kept in the character sums (their weights fall like (β/2n)^{nV})


def _weighted_mean(log_weights, values) -> float:
    w = np.exp(log_weights - np.max(log_weights))
    return float(np.sum(w * values) / np.sum(w))


def _plaquettes(num_plaquettes) -> int:
    bad = isinstance(num_plaquettes, bool) or int(num_plaquettes) != num_plaquettes
    if bad or num_plaquettes < 1:
        raise ValueError(f"num_plaquettes must be an integer >= 1, got {num_plaquettes!r}")
    return int(num_plaquettes)


def u1_torus_plaquette_mean(beta: float, num_plaquettes: int) -> float:
    """``E[cos θ_P]`` of 2-D U(1) on a torus of ``V`` plaquettes: ``(1/V) ∂_β log Σ_k I_k^V``.

    Any finite ``β`` (the law is normalisable on the compact links): at ``β < 0``,
    ``I_k(β) = (−1)^k I_k(|β|)``, so the terms carry the signs ``(−1)^{kV}`` and each
    ``∂_β log I_k`` changes sign (for even ``V`` the mean is minus that at ``|β|``).

    Examples
    --------
    >>> from liesample.targets import u1_plaquette_mean, u1_torus_plaquette_mean
    >>> bool(0 < u1_torus_plaquette_mean(1.0, num_plaquettes=4) < 1)
    True
    """
    beta = finite_float("beta", beta)
    if beta == 0.0:
        return 0.0
    v = _plaquettes(num_plaquettes)
    k = np.arange(-TERMS, TERMS + 1)
    x = abs(beta)
    k = k[special.ive(k, x) > 0]  # at small |β| the high orders underflow: they weigh nothing
    i_k = special.ive(k, x)
    derivative = 0.5 * (special.ive(k - 1, x) + special.ive(k + 1, x)) / i_k
    if beta > 0:
        return _weighted_mean(v * np.log(i_k), derivative)
    log_w = v * np.log(i_k)
    w = np.exp(log_w - np.max(log_w)) * np.where((k * v) % 2, -1.0, 1.0)
    return float(-np.sum(w * derivative) / np.sum(w))


def su2_torus_plaquette_mean(beta: float, num_plaquettes: int) -> float:
    """``E[½ tr U_P]`` of 2-D SU(2) on a torus of ``V`` plaquettes:
    ``(1/V) ∂_β log Σ_{n≥1} ((2/β) I_n(β))^V``.

    Examples
    --------
    >>> from liesample.targets import su2_torus_plaquette_mean
    >>> bool(0 < su2_torus_plaquette_mean(1.0, num_plaquettes=4) < 1)
    True
    """
    beta = finite_float("beta", beta, positive=True)
    v = _plaquettes(num_plaquettes)
    n = np.arange(1, TERMS + 1)
    i_n = special.ive(n, beta)
    derivative = 0.5 * (special.ive(n - 1, beta) + special.ive(n + 1, beta)) / i_n - 1.0 / beta
    return _weighted_mean(v * np.log(2.0 * i_n / beta), derivative)


def _highest_weights(n: int, max_row: int) -> np.ndarray:
    """Every ``λ_1 ≥ … ≥ λ_{N−1} ≥ λ_N = 0`` with ``λ_1 ≤ max_row`` (the SU(N) irreps), rows."""
    rows: list[tuple[int, ...]] = [(0,)]
    for _ in range(n - 1):
        rows = [(v, *r) for r in rows for v in range(r[0], max_row + 1)]
    return np.array(sorted(rows), dtype=int)


def sun_character_coefficients(
    beta: float, n: int, max_row: int = 40, windings: int = 40
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The character expansion ``e^{(β/N) Re tr U} = Σ_λ c_λ(β) χ_λ(U)`` on SU(N).

    Returns ``(λ, c, dc, d)``: the highest weights ``λ`` (rows ``λ_1 ≥ … ≥ λ_N = 0``, ``λ_1 ≤
    max_row``), ``c_λ e^{−β}``, ``∂_β c_λ e^{−β}`` and the dimensions ``d_λ``, from
    ``c_λ = Σ_{|k| ≤ windings} det[I_{λ_j+k+i−j}(β/N)]`` (the common factor ``e^{−β}`` keeps
    large ``β`` finite).

    Examples
    --------
    >>> from liesample.targets import sun_character_coefficients
    >>> weights, c, dc, dims = sun_character_coefficients(1.0, n=2, max_row=5)
    >>> weights[:3, 0].tolist(), dims[:3].tolist()  # SU(2): the spins 0, ½, 1
    ([0, 1, 2], [1.0, 2.0, 3.0])
    """
    beta = finite_float("beta", beta)
    if isinstance(n, bool) or int(n) != n or n < 2:
        raise ValueError(f"n must be an integer >= 2 (SU(n)), got {n!r}")
    n, x = int(n), beta / n
    lam = _highest_weights(n, max_row)
    i, k = np.arange(n), np.arange(-windings, windings + 1)
    order = lam[:, None, None, :] + k[:, None, None] + i[:, None] - i  # (λ, k, i, j)
    low = order.min() - 1
    table = special.ive(np.arange(low, order.max() + 2), x)  # I_m e^{−x}, m = low, low + 1, …
    entries = table[order - low]
    slopes = 0.5 * (table[order - 1 - low] + table[order + 1 - low]) / n  # e^{−x} ∂_β I_m(β/N)
    terms = np.linalg.det(entries)
    if np.max(np.abs(terms[:, [0, -1]])) > 1e-15 * np.max(np.abs(terms)):
        raise ValueError(
            f"beta = {beta:g} needs more than windings = {windings} terms of the sum over k; "
            "raise windings"
        )
    c = terms.sum(1)
    dc = 0.0
    for j in range(n):  # d det = Σ_j det(column j differentiated)
        dc = dc + np.linalg.det(np.concatenate(
            [entries[..., :j], slopes[..., j : j + 1], entries[..., j + 1 :]], axis=-1
        )).sum(1)  # fmt: skip
    shifted = lam + (n - 1 - i)
    d = np.ones(len(lam))
    for p in range(n):
        for q in range(p + 1, n):
            d = d * (shifted[:, p] - shifted[:, q]) / (q - p)
    return lam, c, cast(np.ndarray, dc), d  # an array: SU(N) has N >= 2 columns


def sun_torus_plaquette_mean(beta: float, num_plaquettes: int, n: int) -> float:
    """``E[Re tr U_P / N]`` of 2-D SU(N) on a torus of ``V`` plaquettes:
    ``(1/V) ∂_β log Σ_λ (c_λ/d_λ)^V`` (:func:`sun_character_coefficients`).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import su2_torus_plaquette_mean, sun_torus_plaquette_mean
    >>> bool(np.isclose(sun_torus_plaquette_mean(1.0, 4, n=2), su2_torus_plaquette_mean(1.0, 4)))
    True
    """
    beta = finite_float("beta", beta, positive=True)
    v = _plaquettes(num_plaquettes)
    max_row = 30 + int(10.0 * np.sqrt(beta / n))  # I_m(β/N) is negligible beyond (and k too)
    with np.errstate(divide="ignore", under="ignore"):  # negligible terms underflow to 0
        lam, c, dc, d = sun_character_coefficients(beta, n, max_row, max_row)
        keep = c > 0.0  # the coefficients are positive; rounding can flip the negligible ones
        log_w = v * np.log(c[keep] / d[keep])
    tail = np.max(log_w[lam[keep, 0] == max_row], initial=-np.inf) - np.max(log_w)
    if tail > np.log(1e-15):
        raise ValueError(
            f"beta = {beta:g} is too large for num_plaquettes = {v} in the character sum "
            f"(representations with lambda_1 > {max_row} matter); use a smaller beta or more "
            "plaquettes (the law then tends to single_plaquette_mean)"
        )
    return _weighted_mean(log_w, dc[keep] / c[keep])


def su3_torus_plaquette_mean(beta: float, num_plaquettes: int) -> float:
    """``E[Re tr U_P / 3]`` of 2-D SU(3) on a torus of ``V`` plaquettes
    (:func:`sun_torus_plaquette_mean` with ``n = 3``).

    Examples
    --------
    >>> from liesample.targets import su3_torus_plaquette_mean
    >>> bool(0 < su3_torus_plaquette_mean(1.0, num_plaquettes=4) < 1)
    True
    """
    return sun_torus_plaquette_mean(beta, num_plaquettes, 3)


def u1_torus_charge_law(beta: float, num_plaquettes: int, max_charge: int = 10) -> np.ndarray:
    """``P(Q = q)`` for ``q = −max_charge … max_charge`` (2-D U(1) torus, geometric charge).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import u1_torus_charge_law
    >>> law = u1_torus_charge_law(1.0, num_plaquettes=4, max_charge=3)  # P(Q = −3), …, P(Q = 3)
    >>> law.shape, bool(np.isclose(law.sum(), 1.0)), bool(np.allclose(law, law[::-1]))
    ((7,), True, True)
    """
    beta = finite_float("beta", beta)
    v = _plaquettes(num_plaquettes)
    phi, w_phi = np.polynomial.legendre.leggauss(400)
    phi, w_phi = np.pi * phi, np.pi * w_phi
    density = np.exp(beta * (np.cos(phi) - 1.0)) * w_phi
    nu = np.linspace(0.0, 60.0, 24001)
    f = np.cos(np.outer(nu, phi)) @ density
    f = f / f[0]
    q = np.arange(-max_charge, max_charge + 1)
    integrand = np.cos(2.0 * np.pi * np.outer(q, nu)) * f**v
    law = np.trapezoid(integrand, nu, axis=1)
    law = np.clip(law, 0.0, None)
    return law / np.sum(law)


def single_plaquette_mean(beta: float, n: int) -> float:
    """``E[Re tr U / N]`` under ``exp((β/N) Re tr U) dHaar`` on U(1) (``n = 1``), SU(2), SU(3)
    (Weyl's integration formula over the eigenphases).

    Examples
    --------
    >>> from liesample.targets import single_plaquette_mean, u1_plaquette_mean
    >>> import numpy as np
    >>> bool(np.isclose(single_plaquette_mean(1.0, n=1), u1_plaquette_mean(1.0)))
    True
    """
    beta = finite_float("beta", beta)
    if n == 1:
        return float(special.ive(1, beta) / special.ive(0, beta))
    grid = np.linspace(-np.pi, np.pi, 721)[:-1]
    if n == 2:
        # eigenphases ±a: Haar density ∝ sin² a, Re tr U / 2 = cos a
        retrace, haar = np.cos(grid), np.sin(grid) ** 2
    elif n == 3:
        a, b = np.meshgrid(grid, grid, indexing="ij")
        phases = np.stack([a, b, -a - b])
        haar = np.ones_like(a)
        for i, j in ((0, 1), (0, 2), (1, 2)):
            haar = haar * np.abs(np.exp(1j * phases[i]) - np.exp(1j * phases[j])) ** 2
        retrace = np.cos(phases).sum(0) / 3.0
    else:
        raise ValueError(f"single_plaquette_mean takes n = 1, 2 or 3, got {n!r}")
    weight = haar * np.exp(beta * (retrace - 1.0))
    return float(np.sum(weight * retrace) / np.sum(weight))
