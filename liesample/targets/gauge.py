"""Exact laws of two-dimensional lattice gauge theory with the Wilson action.

In two dimensions the plaquettes of an open lattice are independent, each with the
single-plaquette law ``∝ exp((β/N) Re tr U) dHaar(U)``; on the torus the product of all
plaquettes is constrained and the character expansion gives, for ``V`` plaquettes,

- U(1): ``Z = Σ_k I_k(β)^V`` (times ``e^{−βV}``), the geometric charge ``Q = Σ_P arg U_P / 2π``
  an integer with ``P(Q = q) ∝ ∫ dν cos(2πνq) f(ν)^V``, ``f(ν) = ∫_{−π}^{π} e^{β cos φ}
  cos(νφ) dφ`` (the density of the sum of ``V`` independent plaquette angles at ``2πq``);
- SU(2): ``Z = Σ_{n≥1} ((2/β) I_n(β))^V`` (the spin ``j = (n−1)/2`` term).

The plaquette means are ``(1/V) ∂_β log Z`` of these sums. The single-plaquette laws of SU(N)
are integrals over the eigenphases (Weyl's integration formula).
"""

from __future__ import annotations

import numpy as np
from scipy import special

from liesample.foundation.validation import finite_float

__all__ = [
    "single_plaquette_mean",
    "su2_torus_plaquette_mean",
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


def u1_torus_plaquette_mean(beta, num_plaquettes) -> float:
    """``E[cos θ_P]`` of 2-D U(1) on a torus of ``V`` plaquettes: ``(1/V) ∂_β log Σ_k I_k^V``."""
    beta = finite_float("beta", beta, positive=True)
    v = _plaquettes(num_plaquettes)
    k = np.arange(-TERMS, TERMS + 1)
    i_k = special.ive(k, beta)
    derivative = 0.5 * (special.ive(k - 1, beta) + special.ive(k + 1, beta)) / i_k
    return _weighted_mean(v * np.log(i_k), derivative)


def su2_torus_plaquette_mean(beta, num_plaquettes) -> float:
    """``E[½ tr U_P]`` of 2-D SU(2) on a torus of ``V`` plaquettes:
    ``(1/V) ∂_β log Σ_{n≥1} ((2/β) I_n(β))^V``."""
    beta = finite_float("beta", beta, positive=True)
    v = _plaquettes(num_plaquettes)
    n = np.arange(1, TERMS + 1)
    i_n = special.ive(n, beta)
    derivative = 0.5 * (special.ive(n - 1, beta) + special.ive(n + 1, beta)) / i_n - 1.0 / beta
    return _weighted_mean(v * np.log(2.0 * i_n / beta), derivative)


def u1_torus_charge_law(beta, num_plaquettes, max_charge: int = 10) -> np.ndarray:
    """``P(Q = q)`` for ``q = −max_charge … max_charge`` (2-D U(1) torus, geometric charge)."""
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


def single_plaquette_mean(beta, n: int) -> float:
    """``E[Re tr U / N]`` under ``exp((β/N) Re tr U) dHaar`` on U(1) (``n = 1``), SU(2), SU(3)
    (Weyl's integration formula over the eigenphases)."""
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
