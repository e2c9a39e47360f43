"""Thin systems: each declares its structure, Hamiltonian, noise and exact reference."""

from liesample.dynamics.system import LiePoissonSystem
from liesample.systems.charged_particle import charged_particle, charged_particle_path
from liesample.systems.cp_model import CPModelSystem, cp_model
from liesample.systems.custom import lie_poisson_system
from liesample.systems.heavy_top import heavy_top
from liesample.systems.heisenberg import heisenberg
from liesample.systems.n_vector import NVectorSystem, n_vector
from liesample.systems.point_vortices import point_vortex_integrator, point_vortices
from liesample.systems.rigid_body import rigid_body
from liesample.systems.stochastic_pendulum import stochastic_pendulum
from liesample.systems.wilson_gauge import WilsonGauge, wilson_gauge
from liesample.systems.zeitlin import isospectral_midpoint, zeitlin_euler

__all__ = [
    "CPModelSystem",
    "LiePoissonSystem",
    "NVectorSystem",
    "WilsonGauge",
    "charged_particle",
    "charged_particle_path",
    "cp_model",
    "heavy_top",
    "heisenberg",
    "isospectral_midpoint",
    "lie_poisson_system",
    "n_vector",
    "point_vortex_integrator",
    "point_vortices",
    "rigid_body",
    "stochastic_pendulum",
    "wilson_gauge",
    "zeitlin_euler",
]
