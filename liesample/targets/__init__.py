"""Exact references for tests, reports and benchmarks (ARCHITECTURE: *targets*).

One module per family of laws; everything public is re-exported here.
"""

from liesample.targets.orbits import (
    HeavyTopGibbs,
    RestrictedGaussian,
    bingham_log_normalizer,
    bingham_marginal_density,
    bingham_second_moments,
    isotropic_autocorrelation,
    sample_bingham,
)

__all__ = [
    "HeavyTopGibbs",
    "RestrictedGaussian",
    "bingham_log_normalizer",
    "bingham_marginal_density",
    "bingham_second_moments",
    "isotropic_autocorrelation",
    "sample_bingham",
]
