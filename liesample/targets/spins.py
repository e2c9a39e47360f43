"""Exact references for classical Heisenberg spins: the open chain without field (Fisher 1964)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from liesample._validation import finite_float

__all__ = ["HeisenbergChainReference", "heisenberg_chain_correlation", "langevin_function"]


def langevin_function(x):
    """``L(x) = coth x − 1/x`` (``x/3`` near 0, odd), stable for every finite ``x``."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    series = x / 3.0 - x**3 / 45.0 + 2.0 * x**5 / 945.0
    return np.where(small, series, 1.0 / np.tanh(safe) - 1.0 / safe)


def heisenberg_chain_correlation(n, beta, coupling=1.0):
    """Exact ``E[s_k·s_{k+n}] = u^n``, ``u = coth(βJ) − 1/(βJ)`` (Fisher 1964).

    For the open classical Heisenberg chain without field or anisotropy, at any length and for
    any ``k``: the bond angles are independent under the Gibbs law. ``n ≥ 0`` (array or int).
    """
    n = np.asarray(n)
    if not np.issubdtype(n.dtype, np.integer) or np.any(n < 0):
        raise ValueError(f"n must be a non-negative integer (or array of them), got {n!r}")
    beta = finite_float("beta", beta)
    coupling = finite_float("coupling", coupling)
    return langevin_function(beta * coupling) ** n


@dataclass(frozen=True)
class HeisenbergChainReference:
    """Exact Gibbs law of an open chain of ``length`` spins, ``B = 0``, ``D = 0`` (Fisher 1964).

    With ``K = βJ``, the ``length − 1`` bond cosines ``c_k = s_k·s_{k+1}`` are i.i.d. with
    density ``∝ exp(K c)`` on ``[−1, 1]``: mean ``L(K)`` (Langevin function) and variance
    ``L′(K) = 1/K² − 1/sinh²K``.
    """

    length: int
    beta: float
    coupling: float

    @property
    def u(self) -> float:
        return float(langevin_function(self.beta * self.coupling))

    def correlation(self, n):
        """``E[s_k·s_{k+n}] = u^n``."""
        return heisenberg_chain_correlation(n, self.beta, self.coupling)

    def bond_variance(self) -> float:
        """``Var(s_k·s_{k+1}) = 1/K² − 1/sinh²K``."""
        k = self.beta * self.coupling
        if abs(k) < 1e-3:
            return 1.0 / 3.0 - 2.0 * k**2 / 15.0
        return 1.0 / k**2 - 1.0 / math.sinh(k) ** 2

    def energy_mean(self) -> float:
        """``E[h] = −J (length − 1) u``."""
        return -self.coupling * (self.length - 1) * self.u

    def energy_variance(self) -> float:
        """``Var(h) = J² (length − 1) Var(c)``."""
        return self.coupling**2 * (self.length - 1) * self.bond_variance()
