"""Analysis: comparison with exact references (MCSE z-scores, ESS, R-hat), plots, and the
topological charge of 2-D O(3) configurations (:mod:`liesample.analysis.topology`)."""

from liesample.analysis.topology import (
    topological_charge,
    topological_charge_density,
    topological_susceptibility,
)

__all__ = ["topological_charge", "topological_charge_density", "topological_susceptibility"]
