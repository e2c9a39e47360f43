"""Exact references for tests, reports and benchmarks: the layer beside the geometry.

One module per family of laws; everything public is re-exported here.
"""

from liesample.targets.cp_model import (
    CPChainReference,
    complex_bingham,
    cp_bond_moments,
    tilted_simplex,
)
from liesample.targets.cp_ring import CPRingReference
from liesample.targets.gauge import (
    single_plaquette_mean,
    su2_torus_plaquette_mean,
    su3_torus_plaquette_mean,
    sun_character_coefficients,
    sun_torus_plaquette_mean,
    u1_torus_charge_law,
    u1_torus_plaquette_mean,
)
from liesample.targets.gaussian import (
    Gaussian,
    correlated_gaussian,
    linear_step_moments,
    ou_cross_covariance,
    ou_drift,
    ou_stationary_covariance,
)
from liesample.targets.groups import (
    MatrixFisherLaw,
    VonMisesFisherLaw,
    VonMisesFisherPosterior,
    quaternion_to_rotation,
    su2_plaquette_mean,
    u1_plaquette_mean,
    vmf_mean_resultant_length,
)
from liesample.targets.n_vector import (
    NVectorChainReference,
    n_vector_bond_mean,
    n_vector_bond_variance,
    von_mises_fisher_sphere,
)
from liesample.targets.n_vector_ring import NVectorRingReference
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
from liesample.targets.zeitlin import (
    UnitaryOrbitLaw,
    dipole_gibbs_moments,
    haar_unitaries,
    uniform_orbit_energy_spectrum,
)

__all__ = [
    "CPChainReference",
    "CPRingReference",
    "Gaussian",
    "HeavyTopGibbs",
    "HeisenbergChainReference",
    "MatrixFisherLaw",
    "NVectorChainReference",
    "NVectorRingReference",
    "RestrictedGaussian",
    "UnitaryOrbitLaw",
    "VonMisesFisherLaw",
    "VonMisesFisherPosterior",
    "VortexPairLaw",
    "beta_bounds",
    "bingham_log_normalizer",
    "bingham_marginal_density",
    "bingham_second_moments",
    "check_vortex_beta",
    "complex_bingham",
    "correlated_gaussian",
    "cp_bond_moments",
    "dipole_gibbs_moments",
    "gibbs_expectation",
    "haar_unitaries",
    "heisenberg_chain_correlation",
    "isotropic_autocorrelation",
    "langevin_function",
    "linear_step_moments",
    "n_vector_bond_mean",
    "n_vector_bond_variance",
    "ou_cross_covariance",
    "ou_drift",
    "ou_stationary_covariance",
    "quaternion_to_rotation",
    "sample_bingham",
    "single_plaquette_mean",
    "su2_plaquette_mean",
    "su2_torus_plaquette_mean",
    "su3_torus_plaquette_mean",
    "sun_character_coefficients",
    "sun_torus_plaquette_mean",
    "tilted_simplex",
    "u1_plaquette_mean",
    "u1_torus_charge_law",
    "u1_torus_plaquette_mean",
    "uniform_orbit_energy_spectrum",
    "vmf_mean_resultant_length",
    "von_mises_fisher_sphere",
]
