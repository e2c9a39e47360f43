"""The Gibbs law of a unitary coadjoint orbit, by importance sampling over Haar unitaries.

On ``u(N)*`` the coadjoint orbit of ``W₀`` is ``{U W₀ U* : U ∈ U(N)}`` and its Liouville measure,
normalised, is the push-forward of the Haar measure of ``U(N)`` (the unique invariant probability
on the orbit). So ``E_π[f] = E_Haar[f(UW₀U*) e^{−βh(UW₀U*)}] / E_Haar[e^{−βh(UW₀U*)}]``, estimated
by self-normalised importance sampling with i.i.d. Haar unitaries (QR of a complex Ginibre
matrix with the phases of ``R``'s diagonal divided out, Mezzadri's recipe). The estimate comes
with its delta-method standard error, so a test compares a chain against it with the two
errors combined. Exact up to that Monte-Carlo error, for any ``h``; meant for small ``N`` (the
weights degenerate as the orbit's dimension ``N² − N`` grows).

Two laws are exact in closed form at any ``N``: the mean energy spectrum of the uniform law
(``β = 0``, :func:`uniform_orbit_energy_spectrum`), and the Gibbs law of a Hamiltonian linear in
the ``ℓ = 1`` modes, ``h = κ ω_10``, by the Harish-Chandra–Itzykson–Zuber integral
(:func:`dipole_gibbs_moments`).

States are the real coordinates of :class:`liesample.geometry.algebras.Unitary`
(``x = Re W + Im W``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from liesample.foundation.validation import finite_float

__all__ = [
    "UnitaryOrbitLaw",
    "dipole_gibbs_moments",
    "haar_unitaries",
    "uniform_orbit_energy_spectrum",
]


def haar_unitaries(rng: np.random.Generator, num: int, size: int) -> np.ndarray:
    """``num`` i.i.d. Haar-distributed ``size × size`` unitaries, shape ``(num, size, size)``.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import haar_unitaries
    >>> U = haar_unitaries(np.random.default_rng(0), num=2, size=3)
    >>> U.shape, bool(np.allclose(U @ U.conj().transpose(0, 2, 1), np.eye(3)))
    ((2, 3, 3), True)
    """
    z = rng.standard_normal((num, size, size)) + 1j * rng.standard_normal((num, size, size))
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

    Examples
    --------
    Monte Carlo over the orbit, with each estimate's standard error:

    >>> import numpy as np
    >>> from liesample.systems import zeitlin_euler
    >>> from liesample.targets import UnitaryOrbitLaw
    >>> system = zeitlin_euler(3)
    >>> law = UnitaryOrbitLaw(system.hamiltonian, system.default_position, beta=1.0)
    >>> mean, error, ess = law.expectations(lambda x: x[:, None, 0, 0], num_samples=1000)
    >>> mean.shape, error.shape
    ((1,), (1,))
    """

    hamiltonian: Callable[[np.ndarray], npt.ArrayLike]
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

    def expectations(
        self,
        functions: Callable[[np.ndarray], npt.ArrayLike],
        num_samples: int = 200_000,
        seed: int = 0,
        batch: int = 20_000,
    ) -> tuple[np.ndarray, np.ndarray, float]:
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


# ---------------------------------------------------------------------------------------------
# Exact laws at any N
# ---------------------------------------------------------------------------------------------


def _spin_norm(size: int) -> float:
    """``‖S₃‖_F = √(N(N² − 1)/12)``: ``E_10 = i S₃ / ‖S₃‖_F`` is the unit ``ℓ = 1, m = 0`` mode."""
    return math.sqrt(size * (size * size - 1) / 12.0)


def _langevin(x):
    """``L(x) = coth x − 1/x`` and ``L'(x) = 1/x² − 1/sinh² x``, by series for ``|x| < 1e-3``."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    value = np.where(small, x / 3.0 - x**3 / 45.0, 1.0 / np.tanh(safe) - 1.0 / safe)
    slope = np.where(small, 1.0 / 3.0 - x**2 / 15.0, 1.0 / safe**2 - 1.0 / np.sinh(safe) ** 2)
    return value, slope


def _pair_half_gaps(spectrum, coupling):
    """``κ (b_j − b_k) / (2‖S₃‖_F)`` over the pairs ``j < k`` of the spectrum ``b`` of ``iW``."""
    b = np.asarray(spectrum, dtype=float)
    if b.ndim != 1 or b.size < 2 or not np.all(np.isfinite(b)):
        raise ValueError(f"spectrum must be a finite 1-D array of >= 2 eigenvalues, got {b!r}")
    j, k = np.triu_indices(b.size, 1)
    return finite_float("coupling", coupling) * (b[j] - b[k]) / (2.0 * _spin_norm(b.size))


def dipole_gibbs_moments(
    spectrum: npt.ArrayLike, beta: float, coupling: float = 1.0
) -> tuple[float, float]:
    """Exact ``(E[h], Var[h])`` of ``h = κ ω_10`` under ``∝ exp(−βh)`` on a unitary orbit.

    ``ω_10 = ⟨W, E_10⟩`` is the ``ℓ = 1, m = 0`` coefficient of the vorticity (its dipole
    moment along the axis; by the orbit's invariance any unit direction of the ``ℓ = 1`` modes
    gives the same law). ``spectrum`` is the eigenvalues ``b`` of the Hermitian ``iW`` (the
    orbit; any ``N ≥ 2``, repeated values allowed). With ``c_jk = κ (b_j − b_k) / (2‖S₃‖_F)``
    the Harish-Chandra–Itzykson–Zuber integral factorises,
    ``E_Haar[exp(−βh)] = Π_{j<k} sinh(βc_jk) / (βc_jk)``, so ``h`` is a sum of independent
    ``c_jk V_jk`` with ``V_jk`` exponentially tilted uniform on ``[−1, 1]``:

        E[h] = −Σ_{j<k} c_jk L(βc_jk),      Var[h] = Σ_{j<k} c_jk² L'(βc_jk),

    with the Langevin function ``L(x) = coth x − 1/x``. Stable for every ``β`` (either sign)
    and ``N``; O(N²). Why it factorises: ``E_10 ∝ iS₃`` has equally spaced eigenvalues, so the
    HCIZ determinant is a Vandermonde determinant in ``e^{βκ b_j/‖S₃‖_F}`` (the
    Duistermaat–Heckman formula of the rotations about the axis).

    Examples
    --------
    At ``β = 0`` the dipole moment has mean 0:

    >>> from liesample.targets import dipole_gibbs_moments
    >>> mean, variance = dipole_gibbs_moments([-1.0, 1.0], beta=0.0)
    >>> abs(mean), bool(variance > 0)
    (0.0, True)
    """
    c = _pair_half_gaps(spectrum, coupling)
    value, slope = _langevin(finite_float("beta", beta) * c)
    return float(-np.sum(c * value)), float(np.sum(c * c * slope))


def uniform_orbit_energy_spectrum(size: int, squared_norm: float) -> np.ndarray:
    """Exact mean energy per degree, ``E[ε_ℓ]`` for ``ℓ = 1 … N−1``, under the uniform
    (``β = 0``) law on the orbit of any trace-free ``W`` with ``‖W‖² = squared_norm``.

    ``su(N)`` is an irreducible real representation of ``U(N)``, so by Schur's lemma the Haar
    average of ``W ⊗ W`` is ``‖W‖²/(N² − 1)`` times the identity: every coefficient ``ω_ℓm``
    (``ℓ ≥ 1``) has ``E[ω_ℓm²] = ‖W‖²/(N² − 1)``, and
    ``E[ε_ℓ] = (2ℓ + 1) ‖W‖² / (2ℓ(ℓ + 1)(N² − 1))``. The mean energy ``E[h]`` is their sum.

    Examples
    --------
    ``N = 3``: two degrees, whose energies sum to the mean energy:

    >>> from liesample.targets import uniform_orbit_energy_spectrum
    >>> uniform_orbit_energy_spectrum(3, squared_norm=8.0).shape
    (2,)
    """
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 2:
        raise ValueError(f"size must be an int >= 2, got {size!r}")
    squared_norm = finite_float("squared_norm", squared_norm)
    if squared_norm < 0:
        raise ValueError(f"squared_norm must be >= 0, got {squared_norm}")
    ell = np.arange(1, size, dtype=float)
    return (2 * ell + 1) * squared_norm / (2 * ell * (ell + 1) * (size * size - 1.0))
