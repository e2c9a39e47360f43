"""The Gibbs law of a unitary coadjoint orbit, by importance sampling over Haar unitaries.

On ``u(N)*`` the coadjoint orbit of ``W₀`` is ``{U W₀ U* : U ∈ U(N)}`` and its Liouville measure,
normalised, is the push-forward of the Haar measure of ``U(N)`` (the unique invariant probability
on the orbit). So ``E_π[f] = E_Haar[f(UW₀U*) e^{−βh(UW₀U*)}] / E_Haar[e^{−βh(UW₀U*)}]``, estimated
by self-normalised importance sampling with i.i.d. Haar unitaries (QR of a complex Ginibre
matrix with the phases of ``R``'s diagonal divided out, Mezzadri's recipe). The estimate comes
with its delta-method standard error, so a test compares a chain against it with the two
errors combined. Exact up to that Monte-Carlo error, for any ``h``; meant for small ``N``.

States are the real coordinates of :class:`liesample.geometry.algebras.Unitary`
(``x = Re W + Im W``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from liesample.foundation.validation import finite_float

__all__ = ["UnitaryOrbitLaw", "haar_unitaries"]


def haar_unitaries(rng: np.random.Generator, num: int, size: int) -> np.ndarray:
    """``num`` i.i.d. Haar-distributed ``size × size`` unitaries, shape ``(num, size, size)``."""
    z = (rng.standard_normal((num, size, size)) + 1j * rng.standard_normal((num, size, size)))
    q, r = np.linalg.qr(z / np.sqrt(2.0))
    phases = np.diagonal(r, axis1=-2, axis2=-1)
    return q * (phases / np.abs(phases))[:, None, :]


def _to_matrix(x):
    xt = np.swapaxes(x, -1, -2)
    return 0.5 * (x - xt) + 0.5j * (x + xt)


def _from_matrix(w):
    return np.real(w) + np.imag(w)


@dataclass(frozen=True)
class UnitaryOrbitLaw:
    """``∝ exp(−β h)`` on the orbit ``{U W₀ U*}`` of ``position`` (real coordinates).

    Parameters
    ----------
    hamiltonian : callable
        ``x ↦ h(x)`` on a stack ``(K, N, N)`` of states, returning shape ``(K,)``.
    position : array, shape (N, N)
        A point of the orbit.
    beta : float
    """

    hamiltonian: Callable
    position: np.ndarray
    beta: float

    def __post_init__(self):
        position = np.asarray(self.position, dtype=float)
        if position.ndim != 2 or position.shape[0] != position.shape[1]:
            raise ValueError(f"position must be a square (N, N) array, got {position.shape}")
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "beta", finite_float("beta", self.beta))

    def orbit_samples(self, rng: np.random.Generator, num: int) -> np.ndarray:
        """``num`` states ``U W₀ U*`` uniform (Liouville) on the orbit, shape ``(num, N, N)``."""
        u = haar_unitaries(rng, num, self.position.shape[0])
        w = u @ _to_matrix(self.position) @ np.conj(np.swapaxes(u, -1, -2))
        return _from_matrix(w)

    def expectations(self, functions: Callable, num_samples: int = 200_000, seed: int = 0,
                     batch: int = 20_000):
        """``(E_π[f], standard error)`` for ``f = functions(x)`` of shape ``(K, p)`` on a stack.

        Self-normalised importance sampling; the standard error is the delta-method one,
        ``√(Σ w_k² (f_k − f̂)²) / Σ w_k``. Also returns the effective sample size
        ``(Σw)²/Σw²`` as the third item.
        """
        rng = np.random.default_rng(seed)
        log_w, values = [], []
        for start in range(0, num_samples, batch):
            x = self.orbit_samples(rng, min(batch, num_samples - start))
            log_w.append(-self.beta * np.asarray(self.hamiltonian(x), dtype=float))
            values.append(np.asarray(functions(x), dtype=float).reshape(len(x), -1))
        log_w = np.concatenate(log_w)
        values = np.concatenate(values)
        w = np.exp(log_w - log_w.max())
        total = w.sum()
        mean = (w[:, None] * values).sum(0) / total
        error = np.sqrt((w[:, None] ** 2 * (values - mean) ** 2).sum(0)) / total
        return mean, error, float(total**2 / np.sum(w**2))
