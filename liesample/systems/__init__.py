"""Thin systems: each declares its structure, Hamiltonian, noise and exact reference."""

from liesample.systems.base import LiePoissonSystem, lie_poisson_system
from liesample.systems.heavy_top import heavy_top
from liesample.systems.heisenberg import heisenberg
from liesample.systems.heisenberg_metropolis import heisenberg_metropolis
from liesample.systems.rigid_body import rigid_body

__all__ = [
    "LiePoissonSystem",
    "heavy_top",
    "heisenberg",
    "heisenberg_metropolis",
    "lie_poisson_system",
    "rigid_body",
]
