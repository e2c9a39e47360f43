"""The energy of a periodic ring of CP(N−1) sites without field, by its transfer matrix.

A ring of ``L`` sites ``z_0, …, z_{L−1} ∈ CP^{N−1}`` (unit vectors of ``Cᴺ`` modulo a phase)
at ``K = βJ`` has the Gibbs weight ``Π_x T(z_x, z_{x+1})``, ``z_L = z_0``, with the kernel
``T(z, z′) = exp(K t)``, ``t = |z^† z′|² ∈ [0, 1]``. With the Haar (Fubini–Study) probability
measure, ``Z = Tr Tᴸ``.

**Spectrum.** ``T`` depends on ``t`` only, so it commutes with ``SU(N)`` and acts as a number
``λ_l`` on each irreducible space of functions on ``CP^{N−1} = SU(N)/U(N − 1)``: the harmonic
polynomials of bidegree ``(l, l)`` in ``(z, z̄)``, of dimension

    ``d_l = (2l + N − 1)/(N − 1) · C(l + N − 2, l)²``

(``1, N² − 1, …``; ``2l + 1`` for ``N = 2``). Their zonal functions are the Jacobi polynomials
``φ_l(t) = P_l^{(N−2, 0)}(2t − 1) / C(l + N − 2, l)`` (``φ_l(1) = 1``), and the Funk–Hecke
formula of this rank-one symmetric space gives, with ``t`` under the Haar law of one bond
(density ``(N − 1)(1 − t)^{N−2}``, the open chain of :mod:`liesample.targets.cp_model`),

    ``λ_l = E[e^{Kt} φ_l(t)]``,  ``Z = Σ_l d_l λ_lᴸ``.

For ``N = 2`` the Hopf map (``2t − 1 = s·s′``) turns ``φ_l`` into the Legendre polynomials
and this into the O(3) ring of :mod:`liesample.targets.n_vector_ring` at ``K/2``.

**Energy.** ``h = −J Σ_x t_x``, so ``E[Σ_x t_x] = ∂_K log Z`` and ``Var(Σ_x t_x) = ∂_K² log Z``:
with ``a_l = λ_l′/λ_l`` (``λ_l′ = E[t e^{Kt} φ_l]``), ``a_l′ = λ_l″/λ_l − a_l²`` and the
weights ``p_l = d_l λ_lᴸ / Z``,

    ``E[t_x] = Σ_l p_l a_l``,  ``Var(Σ_x t_x) = Σ_l p_l (L a_l′ + L² (a_l − ā)²)``.

(The correlations ``E[|z_0^† z_r|²]`` at ``r ≥ 2`` need the matrix elements of ``z z^†``
between the degrees ``l`` and ``l, l ± 1``; they are not given here.)

**Numerics.** The three expectations are Gauss–Jacobi sums (``scipy.special.roots_jacobi``,
weight ``(1 − t)^{N−2}``) of ``e^{K(t − 1)}`` (shifted so it never overflows; the shift
cancels in every ratio) times ``φ_l``, with :data:`NODES_PER_K` nodes per unit of ``|K|``
beyond the degree; only ``λ_l/λ_0`` enters. The degrees run up to ``30 + 3√|K| + N``, and the
last one kept is checked to add less than :data:`~liesample.targets.n_vector_ring.
RING_TOLERANCE` to ``Z`` relative to ``λ_0ᴸ``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from liesample.targets.cp_model import check_cp_components
from liesample.targets.n_vector_ring import RING_TOLERANCE
from liesample.targets.open_chain import ChainLaw

__all__ = ["CPRingReference"]

NODES_PER_K = 1.0
"""Gauss–Jacobi nodes per unit of ``|K|``, beyond the degree ``l_max`` and a margin of 40: the
sums integrate ``e^{Kt}`` times polynomials of degree ``≤ l_max + 2`` to round-off."""

_CANCELLATION = 1e8
"""``Σ_l |d_l λ_lᴸ|`` over ``|Z|`` (both over ``λ_0ᴸ``) above which the sum has lost more than
half its digits: refused."""


@dataclass(frozen=True)
class CPRingReference(ChainLaw):
    """Exact energy of a periodic ring of ``length`` CP(N−1) sites without field at ``β`` and
    coupling ``J`` (``K = βJ``), from the spectrum of its transfer matrix (module docstring):
    the reference of ``systems.cp_model((length,), N, coupling, periodic=True)`` for its
    energy; ``n`` is ``N``.

    Examples
    --------
    The CP(2) ring of 8 sites at ``β = 2``; a long ring is the open chain's law:

    >>> from liesample.targets import CPChainReference, CPRingReference
    >>> ring = CPRingReference(length=8, n=3, beta=2.0)
    >>> bool(ring.bond_mean() > CPChainReference(8, 3, 2.0).bond_mean())  # more ordered
    True
    >>> long = CPRingReference(length=400, n=3, beta=2.0)
    >>> bool(abs(long.bond_mean() - CPChainReference(400, 3, 2.0).bond_mean()) < 1e-10)
    True
    """

    MIN_LENGTH = 2
    SITES = "sites of the ring"

    @staticmethod
    def check_components(n) -> int:
        """``n`` checked by :func:`check_cp_components`."""
        return check_cp_components(n)

    @property
    def num_bonds(self) -> int:
        """Bonds of the ring: ``length`` (``s_length = s_0``)."""
        return self.length

    def __post_init__(self):
        super().__post_init__()
        self._spectrum()  # a ring that cannot be summed is refused at once

    def _spectrum(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(p_l, a_l, a_l′)`` for ``l = 0 … l_max`` (module docstring)."""
        from scipy.special import eval_jacobi, gammaln, roots_jacobi

        k, n, big = self.beta * self.coupling, self.n, self.length
        degrees = np.arange(int(30 + 3 * math.sqrt(abs(k)) + n))
        x, w = roots_jacobi(int(degrees[-1] + 40 + NODES_PER_K * abs(k)), n - 2.0, 0.0)
        t = (1.0 + x) / 2.0
        base = w * np.exp(k * t - max(k, 0.0))  # e^{K t} up to a constant factor
        log_norm = gammaln(degrees + n - 1.0) - gammaln(degrees + 1.0) - gammaln(n - 1.0)
        phi = eval_jacobi(degrees[:, None], n - 2.0, 0.0, x[None, :]) / np.exp(log_norm)[:, None]
        lam, lam1, lam2 = (phi @ (base * t**p) for p in (0, 1, 2))
        ratio = lam / lam[0]
        log_d = np.log((2 * degrees + n - 1.0) / (n - 1.0)) + 2 * log_norm
        terms = np.exp(log_d + big * np.log(np.abs(ratio))) * np.sign(ratio) ** big
        if not abs(terms[-1]) < RING_TOLERANCE:
            raise ValueError(
                f"the transfer-matrix sum of the CP({n - 1}) ring (K={k}) does not converge "
                f"within {degrees.size} degrees; use a smaller |beta * coupling|"
            )
        if np.sum(np.abs(terms)) > _CANCELLATION * abs(np.sum(terms)):
            raise ValueError(
                f"the CP({n - 1}) ring of length={big} at beta * coupling={k} loses its "
                "partition function to cancellation; use a smaller |beta * coupling|"
            )
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(terms != 0.0, lam1 / lam, 0.0)
            da = np.where(terms != 0.0, lam2 / lam - a**2, 0.0)
        return terms / np.sum(terms), a, da

    def bond_mean(self) -> float:
        """``E[|z_x^† z_{x+1}|²] = ∂_K log Z / length``."""
        p, a, _ = self._spectrum()
        return float(np.sum(p * a))

    def energy_variance(self) -> float:
        """``Var(h) = J² ∂_K² log Z``."""
        p, a, da = self._spectrum()
        big = self.length
        mean = np.sum(p * a)
        return float(self.coupling**2 * np.sum(p * (big * da + big**2 * (a - mean) ** 2)))
