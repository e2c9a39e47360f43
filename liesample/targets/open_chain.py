"""The exact law of an open chain whose ``length − 1`` bonds are i.i.d.: what the O(n) and
CP(N−1) chain references share, and (:class:`ChainLaw`) what they share with the periodic
rings' references: the checked parameters and the energy from the bond's mean.

On an open chain without field, ``h = −J Σ_x b(x, x+1)`` with a bond variable ``b`` whose law
under ``exp(−βh)`` is the same for every bond and independent of the others (fix the first
site, then each next one only through its bond). So ``E[h] = −J (length − 1) E[b]`` and
``Var(h) = J² (length − 1) Var(b)``: a reference gives the bond's two moments
(:meth:`OpenChainLaw.bond_mean`, :meth:`OpenChainLaw.bond_variance`) and checks its number of
components, and the rest follows here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from liesample.foundation.validation import finite_float, int_at_least

__all__ = ["ChainLaw", "OpenChainLaw"]


@dataclass(frozen=True)
class ChainLaw:
    """A chain of ``length`` sites with ``n`` components each at ``β`` and coupling ``J``, its
    parameters checked (each error names its parameter): the open chain
    (:class:`OpenChainLaw`) and the periodic rings (``targets.NVectorRingReference``,
    ``targets.CPRingReference``). Subclasses give :meth:`check_components`, :meth:`bond_mean`
    and :attr:`num_bonds`; the energy follows, ``E[h] = −J num_bonds E[b]``.
    """

    length: int
    n: int
    beta: float
    coupling: float = 1.0

    MIN_LENGTH: ClassVar[int] = 1
    """The fewest sites the law is defined for."""
    SITES: ClassVar[str] = "sites of the chain"
    """What ``length`` counts, for its error message."""

    def __post_init__(self):
        length = int_at_least("length", self.length, self.SITES, minimum=self.MIN_LENGTH)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "n", self.check_components(self.n))
        object.__setattr__(self, "beta", finite_float("beta", self.beta))
        object.__setattr__(self, "coupling", finite_float("coupling", self.coupling))

    @property
    def num_bonds(self) -> int:
        """Bonds of the chain: ``length − 1`` open."""
        return self.length - 1

    @staticmethod
    def check_components(n) -> int:
        """``n`` checked (an error naming it), as an int."""
        raise NotImplementedError

    def bond_mean(self) -> float:
        """``E[b]`` of one bond."""
        raise NotImplementedError

    def bond_energy_mean(self) -> float:
        """``E[−J b] = −J E[b]``: the energy per bond."""
        return -self.coupling * self.bond_mean()

    def energy_mean(self) -> float:
        """``E[h] = −J num_bonds E[b]``."""
        return self.num_bonds * self.bond_energy_mean()


@dataclass(frozen=True)
class OpenChainLaw(ChainLaw):
    """An open chain of ``length`` sites with ``n`` components each at ``β`` and coupling
    ``J``, its bonds i.i.d. (module docstring). Subclasses give :meth:`check_components`,
    :meth:`bond_mean` and :meth:`bond_variance`.

    Examples
    --------
    >>> from liesample.targets import NVectorChainReference
    >>> chain = NVectorChainReference(length=5, n=4, beta=1.0)
    >>> bool(abs(chain.energy_mean() - 4 * chain.bond_energy_mean()) < 1e-15)
    True
    """

    def bond_variance(self) -> float:
        """``Var(b)`` of one bond."""
        raise NotImplementedError

    def bond_energy_mean(self) -> float:
        """``E[−J b] = −J E[b]``: the energy per bond."""
        return -self.coupling * self.bond_mean()

    def energy_mean(self) -> float:
        """``E[h] = −J (length − 1) E[b]``."""
        return (self.length - 1) * self.bond_energy_mean()

    def energy_variance(self) -> float:
        """``Var(h) = J² (length − 1) Var(b)``."""
        return self.coupling**2 * (self.length - 1) * self.bond_variance()
