"""liesample: Gibbs-exact samplers from stochastic-dissipative geometric mechanics.

The one equation is the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``); systems
declare a Poisson structure, a Hamiltonian and noise, and the dissipation is derived.
"""

from liesample.compile import jit, safe_compiler_options
from liesample import accuracy, algebras, drivers, integrators, structures, symplectic, systems
from liesample.drivers import simulate
from liesample.dynamics import PoissonLangevin, Scene
from liesample.runner import load_chains, sample, sample_chains
from liesample.samplers.adjusted_lie_poisson import adjusted_lie_poisson
from liesample.samplers.lie_poisson_langevin import lie_poisson_langevin
from liesample.samplers.magnetic_hmc import magnetic_hmc
from liesample.samplers.magnetic_langevin import magnetic_langevin
from liesample.samplers.spins_heat_bath import heisenberg_heat_bath
from liesample.samplers.spins_metropolis import heisenberg_metropolis
from liesample.samplers.spins_wolff import heisenberg_wolff

__all__ = [
    "PoissonLangevin",
    "Scene",
    "accuracy",
    "adjusted_lie_poisson",
    "algebras",
    "drivers",
    "heisenberg_heat_bath",
    "heisenberg_metropolis",
    "heisenberg_wolff",
    "integrators",
    "jit",
    "lie_poisson_langevin",
    "load_chains",
    "magnetic_hmc",
    "magnetic_langevin",
    "sample",
    "sample_chains",
    "safe_compiler_options",
    "simulate",
    "structures",
    "symplectic",
    "systems",
]

# Lie groups and spheres as parameter spaces (geometric HMC and Langevin on T*G).
from liesample import spaces  # noqa: E402
from liesample.samplers.geometric_hmc import geometric_hmc  # noqa: E402
from liesample.samplers.geometric_langevin import geometric_langevin  # noqa: E402

__all__ += ["geometric_hmc", "geometric_langevin", "spaces"]
from liesample.adaptation import (  # noqa: E402
    jittered_magnetic_hmc,
    magnetic_window_adaptation,
    window_adaptation,
)

__all__ += ["jittered_magnetic_hmc", "magnetic_window_adaptation", "window_adaptation"]
