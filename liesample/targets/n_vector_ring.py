"""The exact law of a periodic ring of O(n) spins without field, by its transfer matrix.

A ring of ``L`` unit vectors ``s_0, …, s_{L−1} ∈ S^{n−1}`` at ``K = βJ`` has the Gibbs weight
``Π_x T(s_x, s_{x+1})`` with the kernel ``T(s, s′) = exp(K s·s′)`` and ``s_L = s_0``. With the
uniform probability measure ``dσ`` on the sphere, ``T`` is an integral operator whose
expectations are traces: ``Z = Tr Tᴸ`` and ``E[s_0·s_r] = Σ_a Tr(S_a Tʳ S_a T^{L−r}) / Z``,
``S_a`` multiplication by the component ``s_a``.

**Spectrum.** ``T`` depends on ``s·s′`` only, so it commutes with rotations and acts as a
number ``λ_l`` on the space ``H_l`` of spherical harmonics of degree ``l`` (Funk–Hecke). The
expansion of a plane wave in Gegenbauer polynomials, ``e^{K t} = Γ(α)(K/2)^{−α} Σ_l (l + α)
I_{l+α}(K) C_l^α(t)`` with ``α = n/2 − 1``, gives

    ``λ_l = Γ(n/2) (2/K)^{n/2−1} I_{l+n/2−1}(K)``

(``I₀, I₁, …`` on the circle, where ``e^{K cos θ} = Σ_m I_{|m|}(K) e^{imθ}``). The dimension
of ``H_l`` is ``d_l = w_l + w_{l−1}`` with ``w_l = C(l + n − 2, n − 2)`` (harmonic
polynomials of degree ``l`` in ``n`` variables: all polynomials of degree ``l`` less ``|x|²``
times those of degree ``l − 2``); ``d_l = 1, 2, 2, …`` on ``S¹``, ``2l + 1`` on ``S²``,
``(l + 1)²`` on ``S³``. So ``Z = Σ_l d_l λ_lᴸ``.

**Correlation.** Multiplying a harmonic of degree ``l`` by a coordinate ``s_a`` gives a
polynomial of degree ``l + 1`` whose harmonic parts have degrees ``l + 1`` and ``l − 1``
only. Write ``W(l, l′) = Σ_a Σ_{m, m′} |⟨Y_{lm}, s_a Y_{l′m′}⟩|²`` over orthonormal bases of
``H_l`` and ``H_{l′}``; it vanishes unless ``|l − l′| = 1`` and is symmetric. Since
``Σ_a s_a² = 1``, summing over ``l′`` gives ``Σ_m ‖Y_{lm}‖² = d_l``: ``W(l, l + 1) +
W(l, l − 1) = d_l``, and from ``W(0, 1) = d_0 = 1`` by induction ``W(l, l + 1) = w_l``.
Expanding both traces in these bases,

    ``E[s_0·s_r] = Σ_l w_l (λ_lʳ λ_{l+1}^{L−r} + λ_{l+1}ʳ λ_l^{L−r}) / Σ_l d_l λ_lᴸ``.

When ``L → ∞`` only ``l = 0`` survives in the denominator and ``λ_0^{L−r}`` in the numerator:
``E[s_0·s_r] → (λ_1/λ_0)ʳ = uʳ`` with ``u = I_{n/2}(K)/I_{n/2−1}(K)``, the open chain of
:mod:`liesample.targets.n_vector`.

**Energy.** ``h = −J Σ_x s_x·s_{x+1}``, so ``E[Σ_x s_x·s_{x+1}] = ∂_K log Z`` and
``Var(Σ_x s_x·s_{x+1}) = ∂_K² log Z``. With ``a_l = ∂_K log λ_l = I_{l+α+1}(K)/I_{l+α}(K) +
l/K`` (from ``I_ν′ = I_{ν+1} + ν I_ν/K``), ``a_l′ = 1 − R² − (2l + n − 1) R/K − l/K²`` (``R``
that Bessel ratio; its Riccati equation) and the weights ``p_l = d_l λ_lᴸ / Z``:

    ``E[s_x·s_{x+1}] = Σ_l p_l a_l``,  ``Var(Σ_x s_x·s_{x+1}) = Σ_l p_l (L a_l′ + L² (a_l − ā)²)``

with ``ā = Σ_l p_l a_l``. The first equals the correlation formula at ``r = 1`` (both are
checked against each other and against direct integration over ``(S^{n−1})^L`` for
``L = 2, 3`` in the tests).

**Numerics.** Only the ratios ``ρ_l = λ_l/λ_0 = I_{l+α}(|K|)/I_α(|K|)`` enter, taken from
exponentially scaled Bessel functions (``scipy.special.ive``) and combined with ``log d_l``
in logarithms, so large ``K`` and large ``n`` stay finite. A negative ``K`` flips the sign of
the odd degrees, ``λ_l(−K) = (−1)ˡ λ_l(|K|)``. The sum runs over ``l ≤ 2|K| + 2n + 40``: past
``l + α + 1 > 2|K|`` each ratio ``ρ_{l+1}/ρ_l = I_{l+α+1}/I_{l+α}`` is below
``|K|/(2(l + α + 1)) < 1/4`` and, for ``l ≥ 2n``, ``d_{l+1}/d_l < 2``, so each neglected term is
below half the one before and their sum below the last kept term, which must be below
:data:`RING_TOLERANCE` (else the reference is refused). ``K = 0`` (independent spins) is taken
in closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from liesample.targets.n_vector import (
    check_spin_components,
    n_vector_bond_mean,
    n_vector_bond_variance,
)
from liesample.targets.open_chain import ChainLaw

__all__ = ["RING_TOLERANCE", "NVectorRingReference"]

RING_TOLERANCE = 1e-15
"""Largest relative size allowed for the last degree kept in the sums (module docstring)."""

_CANCELLATION = 1e8
"""``Σ_l |d_l ρ_lᴸ|`` over ``Z/λ_0ᴸ`` above which a frustrated ring (``K < 0``, odd ``L``)
would lose more than half the digits of ``Z`` to cancellation: refused."""


def _degree_logs(n: int, degrees: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(log w_l, log d_l)`` at ``degrees`` (module docstring: ``w_l = C(l + n − 2, n − 2)``,
    ``d_l = w_l + w_{l−1}``)."""
    from scipy.special import gammaln

    log_w = gammaln(degrees + n - 1.0) - gammaln(degrees + 1.0) - gammaln(n - 1.0)
    log_w_below = np.concatenate([[-np.inf], log_w[:-1]])
    return log_w, np.logaddexp(log_w, log_w_below)


@dataclass(frozen=True)
class NVectorRingReference(ChainLaw):
    """Exact Gibbs law of a periodic ring of ``length`` O(n) spins without field at ``β`` and
    coupling ``J`` (``K = βJ``), from the spectrum of its transfer matrix (module docstring).

    The reference of ``systems.n_vector((length,), n, coupling, periodic=True)``: its
    ``length`` bonds ``s_x·s_{x+1}`` (with ``s_length = s_0``) are not independent, unlike
    those of the open chain (:class:`~liesample.targets.n_vector.NVectorChainReference`).
    ``length = 2`` is the ring of two sites joined twice (one bond at ``2K``).

    Examples
    --------
    The XY ring of 8 sites at ``β = 1``; a long ring is the open chain's law:

    >>> from liesample.targets import NVectorChainReference, NVectorRingReference
    >>> ring = NVectorRingReference(length=8, n=2, beta=1.0)
    >>> bool(ring.correlation(4) > NVectorChainReference(8, 2, 1.0).correlation(4))
    True
    >>> long = NVectorRingReference(length=400, n=2, beta=1.0)
    >>> bool(abs(long.bond_mean() - NVectorChainReference(400, 2, 1.0).u) < 1e-12)
    True
    """

    MIN_LENGTH = 2
    SITES = "sites of the ring"

    @staticmethod
    def check_components(n) -> int:
        """``n`` checked by :func:`check_spin_components`."""
        return check_spin_components(n)

    @property
    def num_bonds(self) -> int:
        """Bonds of the ring: ``length`` (``s_length = s_0``)."""
        return self.length

    def __post_init__(self):
        super().__post_init__()
        if self._k != 0.0:
            self._spectrum()  # a ring that cannot be summed is refused at once

    @property
    def _k(self) -> float:
        return self.beta * self.coupling

    def _spectrum(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(degrees, log w_l, log d_l, log |ρ_l|, sign of ρ_l)`` for ``l = 0 … l_max``."""
        from scipy.special import ive

        k, n = self._k, self.n
        degrees = np.arange(int(2 * abs(k)) + 2 * n + 41, dtype=float)
        with np.errstate(divide="ignore"):
            log_rho = np.log(ive(degrees + n / 2 - 1, abs(k))) - math.log(ive(n / 2 - 1, abs(k)))
        signs = np.where((degrees % 2 == 1) & (k < 0), -1.0, 1.0)
        log_w, log_d = _degree_logs(n, degrees)
        last = log_d[-1] + self.length * log_rho[-1]
        if not last < math.log(RING_TOLERANCE):
            raise ValueError(
                f"the transfer-matrix sum of the ring (n={n}, K={k}) does not converge within "
                f"{degrees.size} degrees; use a smaller n or |beta * coupling|"
            )
        terms = np.exp(log_d + self.length * log_rho) * signs**self.length
        if np.sum(np.abs(terms)) > _CANCELLATION * np.sum(terms):
            raise ValueError(
                f"a frustrated ring (odd length={self.length}, beta * coupling={k} < 0) loses "
                "its partition function to cancellation at this |K|; use an even length or a "
                "smaller |beta * coupling|"
            )
        return degrees, log_w, log_d, log_rho, signs

    def _weights(self) -> np.ndarray:
        """``p_l = d_l λ_lᴸ / Z`` (summing to one)."""
        _, _, log_d, log_rho, signs = self._spectrum()
        terms = np.exp(log_d + self.length * log_rho) * signs**self.length
        return terms / np.sum(terms)

    def correlation(self, r: npt.ArrayLike) -> np.ndarray:
        """``E[s_x·s_{x+r}]`` for integer ``0 ≤ r ≤ length`` (any ``x``; ``r`` and
        ``length − r`` are the same pair)."""
        r = np.asarray(r)
        if not np.issubdtype(r.dtype, np.integer) or np.any(r < 0) or np.any(r > self.length):
            raise ValueError(
                f"r must be integers in [0, {self.length}] (distances around the ring of "
                f"{self.length} sites), got {r!r}"
            )
        if self._k == 0.0:
            return np.where((r == 0) | (r == self.length), 1.0, 0.0)
        _, log_w, log_d, log_rho, signs = self._spectrum()
        big = self.length
        z = np.sum(np.exp(log_d + big * log_rho) * signs**big)
        rr = r.astype(float)[..., None]
        lo, hi = log_rho[:-1], log_rho[1:]
        s_lo, s_hi = signs[:-1], signs[1:]
        with np.errstate(invalid="ignore"):  # 0 · (−inf) where a ratio underflows: no term
            first = np.exp(log_w[:-1] + rr * lo + (big - rr) * hi) * s_lo**rr * s_hi ** (big - rr)
            second = np.exp(log_w[:-1] + rr * hi + (big - rr) * lo) * s_hi**rr * s_lo ** (big - rr)
        numerator = np.sum(np.nan_to_num(first) + np.nan_to_num(second), axis=-1)
        return numerator / z

    def _bond_derivatives(self) -> tuple[np.ndarray, np.ndarray]:
        """``(a_l, a_l′)``: first and second derivatives of ``log |λ_l|`` in ``K``, zero where
        ``λ_l`` underflows (its weight is zero there)."""
        from scipy.special import ive

        degrees, _, _, log_rho, _ = self._spectrum()
        k, n = self._k, self.n
        nu = degrees + n / 2 - 1
        live = np.isfinite(log_rho)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(live, ive(nu + 1, abs(k)) / ive(nu, abs(k)), 0.0)
            a = np.where(live, ratio + degrees / abs(k), 0.0)
            da = np.where(live, 1 - ratio**2 - (2 * nu + 1) * ratio / abs(k) - degrees / k**2, 0.0)
        a[0] = n_vector_bond_mean(n, abs(k))  # l = 0: the open chain's bond (Taylor at small K)
        da[0] = n_vector_bond_variance(n, abs(k))
        return math.copysign(1.0, k) * a, da

    def bond_mean(self) -> float:
        """``E[s_x·s_{x+1}] = ∂_K log Z / length``."""
        if self._k == 0.0:
            return 0.0
        return float(np.sum(self._weights() * self._bond_derivatives()[0]))

    def energy_variance(self) -> float:
        """``Var(h) = J² ∂_K² log Z`` (``J² length / n`` at ``K = 0``)."""
        if self._k == 0.0:
            return self.coupling**2 * self.length / self.n
        p = self._weights()
        a, da = self._bond_derivatives()
        mean = np.sum(p * a)
        big = self.length
        return float(self.coupling**2 * np.sum(p * (big * da + big**2 * (a - mean) ** 2)))
