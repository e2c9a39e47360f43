"""Thin systems: each declares its structure, Hamiltonian, noise and exact reference."""

from liesample.systems.base import LiePoissonSystem
from liesample.systems.heavy_top import heavy_top
from liesample.systems.rigid_body import rigid_body

__all__ = ["LiePoissonSystem", "heavy_top", "rigid_body"]
