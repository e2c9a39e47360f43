"""liesample: Gibbs-exact samplers from stochastic-dissipative geometric mechanics.

The one equation is the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``); systems
declare a Poisson structure, a Hamiltonian and noise, and the dissipation is derived.

The layers, bottom up, are the sub-packages ``foundation``, ``geometry`` and ``targets``,
``dynamics``, ``integrators``, ``systems``, ``samplers``, ``tuning``, then ``run``,
``analysis`` and ``interop``; this module is the curated public face.
"""

import sys

from liesample import analysis, dynamics, geometry, integrators, systems, targets
from liesample.analysis import diagnostics
from liesample.dynamics import PoissonLangevin, Scene, symplectic
from liesample.foundation.compile import jit, safe_compiler_options
from liesample.geometry import algebras, spaces
from liesample.integrators import accuracy, drivers, stability
from liesample.integrators.drivers import simulate
from liesample.run import sharding
from liesample.run.runner import load_chains, sample, sample_chains
from liesample.samplers.cotangent._euclidean import default_magnetic_field
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.samplers.cotangent.geometric_langevin import geometric_langevin
from liesample.samplers.cotangent.magnetic_hmc import jittered_magnetic_hmc, magnetic_hmc
from liesample.samplers.cotangent.magnetic_langevin import magnetic_langevin
from liesample.samplers.orbit.adjusted_lie_poisson import adjusted_lie_poisson
from liesample.samplers.orbit.lie_poisson_langevin import lie_poisson_langevin
from liesample.samplers.orbit.vortex_metropolis import vortex_metropolis
from liesample.samplers.recommended import recommended_sampler
from liesample.samplers.spins.heisenberg_cluster import heisenberg_cluster
from liesample.samplers.spins.heisenberg_heat_bath import heisenberg_heat_bath
from liesample.samplers.spins.heisenberg_metropolis import heisenberg_metropolis
from liesample.samplers.spins.heisenberg_wolff import heisenberg_wolff
from liesample.tuning.adaptation import magnetic_window_adaptation, window_adaptation

# The public sub-modules also import by their short names (``from liesample.spaces import
# Sphere``), as the README writes them.
for _name, _module in {
    "accuracy": accuracy,
    "algebras": algebras,
    "diagnostics": diagnostics,
    "drivers": drivers,
    "sharding": sharding,
    "spaces": spaces,
    "stability": stability,
    "symplectic": symplectic,
}.items():
    sys.modules[f"{__name__}.{_name}"] = _module
del _name, _module

__all__ = [
    "PoissonLangevin",
    "Scene",
    "accuracy",
    "adjusted_lie_poisson",
    "algebras",
    "analysis",
    "default_magnetic_field",
    "diagnostics",
    "drivers",
    "dynamics",
    "geometric_hmc",
    "geometric_langevin",
    "geometry",
    "heisenberg_cluster",
    "heisenberg_heat_bath",
    "heisenberg_metropolis",
    "heisenberg_wolff",
    "integrators",
    "jit",
    "jittered_magnetic_hmc",
    "lie_poisson_langevin",
    "load_chains",
    "magnetic_hmc",
    "magnetic_langevin",
    "magnetic_window_adaptation",
    "recommended_sampler",
    "safe_compiler_options",
    "sample",
    "sample_chains",
    "sharding",
    "simulate",
    "spaces",
    "stability",
    "symplectic",
    "systems",
    "targets",
    "vortex_metropolis",
    "window_adaptation",
]
