"""Dynamics: what a system declares, and the Poisson–Langevin SDE built from it.

``PoissonLangevin`` (Lie–Poisson), ``PoissonLangevinSDE`` (any Poisson structure) and the
symplectic diffusions read a declaration; the dissipation is always derived from the noise.
"""

from liesample.dynamics.poisson_langevin import PoissonLangevin, Scene, make_dynamics
from liesample.dynamics.system import LiePoissonSystem

__all__ = ["LiePoissonSystem", "PoissonLangevin", "Scene", "make_dynamics"]
