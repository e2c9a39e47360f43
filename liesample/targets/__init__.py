"""Exact references for tests, reports and benchmarks: the layer beside the geometry.

One module per family of laws; everything public is re-exported here.
"""

from liesample.targets.gaussian import (
    Gaussian,
    correlated_gaussian,
    linear_step_moments,
    ou_cross_covariance,
    ou_drift,
    ou_stationary_covariance,
)
from liesample.targets.orbits import (
    HeavyTopGibbs,
    RestrictedGaussian,
    bingham_log_normalizer,
    bingham_marginal_density,
    bingham_second_moments,
    isotropic_autocorrelation,
    sample_bingham,
)
from liesample.targets.spins import (
    HeisenbergChainReference,
    heisenberg_chain_correlation,
    langevin_function,
)
from liesample.targets.vortices import (
    VortexPairLaw,
    beta_bounds,
    check_vortex_beta,
    gibbs_expectation,
)

__all__ = [
    "Gaussian",
    "HeavyTopGibbs",
    "HeisenbergChainReference",
    "RestrictedGaussian",
    "VortexPairLaw",
    "beta_bounds",
    "bingham_log_normalizer",
    "bingham_marginal_density",
    "bingham_second_moments",
    "check_vortex_beta",
    "correlated_gaussian",
    "gibbs_expectation",
    "heisenberg_chain_correlation",
    "isotropic_autocorrelation",
    "langevin_function",
    "linear_step_moments",
    "ou_cross_covariance",
    "ou_drift",
    "ou_stationary_covariance",
    "sample_bingham",
]
