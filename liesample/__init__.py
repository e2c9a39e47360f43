"""liesample: Gibbs-exact samplers from stochastic-dissipative geometric mechanics.

The one equation is the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``); systems
declare a Poisson structure, a Hamiltonian and noise, and the dissipation is derived.

The layers, bottom up, are the sub-packages ``foundation``, ``geometry`` and ``targets``,
``dynamics``, ``integrators``, ``systems``, ``samplers``, ``tuning``, then ``run``,
``analysis`` and ``interop``; this module is the curated public face.

Its names load on first use (PEP 562), so ``import liesample`` costs about what importing jax
and blackjax does; ``liesample.sample``, ``from liesample import spaces`` and
``from liesample.spaces import Sphere`` work as if everything were imported at once.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _distribution_version
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # what the lazy names below resolve to, for type checkers and readers
    from liesample import analysis, dynamics, geometry, integrators, systems, targets
    from liesample.analysis import diagnostics
    from liesample.dynamics import PoissonLangevin, Scene, symplectic
    from liesample.foundation.compile import jit, safe_compiler_options
    from liesample.geometry import algebras, spaces
    from liesample.integrators import accuracy, drivers, stability
    from liesample.integrators.drivers import simulate
    from liesample.run import sharding
    from liesample.run.ildg import load_ildg, save_ildg
    from liesample.run.runner import load_chains, sample, sample_chains
    from liesample.samplers.cotangent._euclidean import default_magnetic_field
    from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
    from liesample.samplers.cotangent.geometric_langevin import geometric_langevin
    from liesample.samplers.cotangent.magnetic_hmc import jittered_magnetic_hmc, magnetic_hmc
    from liesample.samplers.cotangent.magnetic_langevin import magnetic_langevin
    from liesample.samplers.gauge.heat_bath import wilson_heat_bath
    from liesample.samplers.orbit.adjusted_lie_poisson import adjusted_lie_poisson
    from liesample.samplers.orbit.lie_poisson_langevin import lie_poisson_langevin
    from liesample.samplers.orbit.vortex_metropolis import vortex_metropolis
    from liesample.samplers.recommended import recommended_sampler
    from liesample.samplers.spins.cp_heat_bath import cp_heat_bath
    from liesample.samplers.spins.heisenberg_cluster import heisenberg_cluster
    from liesample.samplers.spins.heisenberg_heat_bath import heisenberg_heat_bath
    from liesample.samplers.spins.heisenberg_metropolis import heisenberg_metropolis
    from liesample.samplers.spins.heisenberg_wolff import heisenberg_wolff
    from liesample.tuning.adaptation import magnetic_window_adaptation, window_adaptation

# Public modules deeper in the layers, by short name: ``liesample.spaces`` and
# ``from liesample.spaces import Sphere`` work, as the README writes them. The sub-packages
# (``liesample.systems``, ``liesample.targets``, ...) load on first use as well.
_SHORT_NAMES = {
    "accuracy": "liesample.integrators.accuracy",
    "algebras": "liesample.geometry.algebras",
    "diagnostics": "liesample.analysis.diagnostics",
    "drivers": "liesample.integrators.drivers",
    "sharding": "liesample.run.sharding",
    "spaces": "liesample.geometry.spaces",
    "stability": "liesample.integrators.stability",
    "symplectic": "liesample.dynamics.symplectic",
}
# Public functions and classes: name -> the module that defines it under that name.
_ATTRIBUTES = {
    "PoissonLangevin": "liesample.dynamics",
    "Scene": "liesample.dynamics",
    "adjusted_lie_poisson": "liesample.samplers.orbit.adjusted_lie_poisson",
    "cp_heat_bath": "liesample.samplers.spins.cp_heat_bath",
    "default_magnetic_field": "liesample.samplers.cotangent._euclidean",
    "geometric_hmc": "liesample.samplers.cotangent.geometric_hmc",
    "geometric_langevin": "liesample.samplers.cotangent.geometric_langevin",
    "heisenberg_cluster": "liesample.samplers.spins.heisenberg_cluster",
    "heisenberg_heat_bath": "liesample.samplers.spins.heisenberg_heat_bath",
    "heisenberg_metropolis": "liesample.samplers.spins.heisenberg_metropolis",
    "heisenberg_wolff": "liesample.samplers.spins.heisenberg_wolff",
    "jit": "liesample.foundation.compile",
    "jittered_magnetic_hmc": "liesample.samplers.cotangent.magnetic_hmc",
    "lie_poisson_langevin": "liesample.samplers.orbit.lie_poisson_langevin",
    "load_chains": "liesample.run.runner",
    "load_ildg": "liesample.run.ildg",
    "magnetic_hmc": "liesample.samplers.cotangent.magnetic_hmc",
    "magnetic_langevin": "liesample.samplers.cotangent.magnetic_langevin",
    "magnetic_window_adaptation": "liesample.tuning.adaptation",
    "recommended_sampler": "liesample.samplers.recommended",
    "safe_compiler_options": "liesample.foundation.compile",
    "sample": "liesample.run.runner",
    "sample_chains": "liesample.run.runner",
    "save_ildg": "liesample.run.ildg",
    "simulate": "liesample.integrators.drivers",
    "vortex_metropolis": "liesample.samplers.orbit.vortex_metropolis",
    "wilson_heat_bath": "liesample.samplers.gauge.heat_bath",
    "window_adaptation": "liesample.tuning.adaptation",
}

__all__ = [
    "PoissonLangevin",
    "Scene",
    "__version__",
    "accuracy",
    "adjusted_lie_poisson",
    "algebras",
    "analysis",
    "cp_heat_bath",
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
    "load_ildg",
    "magnetic_hmc",
    "magnetic_langevin",
    "magnetic_window_adaptation",
    "recommended_sampler",
    "safe_compiler_options",
    "sample",
    "sample_chains",
    "save_ildg",
    "sharding",
    "simulate",
    "spaces",
    "stability",
    "symplectic",
    "systems",
    "targets",
    "vortex_metropolis",
    "wilson_heat_bath",
    "window_adaptation",
]


def __getattr__(name: str):
    """Load a public name on first use and keep it in the module (PEP 562)."""
    if name in _SHORT_NAMES:  # through the finder below: liesample.<name> is in sys.modules too
        value = importlib.import_module(f"{__name__}.{name}")
    elif name in _ATTRIBUTES:
        value = getattr(importlib.import_module(_ATTRIBUTES[name]), name)
    elif name == "__version__":
        try:
            value = _distribution_version(__name__)
        except PackageNotFoundError:  # imported from a source tree that was never installed
            value = "0+unknown"
    elif not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}"):
        value = importlib.import_module(f"{__name__}.{name}")  # any sub-package: liesample.run
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


class _ShortNameFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``liesample.<short name>`` as the module it names (the same module object)."""

    def find_spec(self, fullname, path=None, target=None):
        package, _, name = fullname.rpartition(".")
        if package == __name__ and name in _SHORT_NAMES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        return None  # a placeholder, replaced below

    def exec_module(self, module):
        """Put the real module in the placeholder's place, with its own ``__spec__``."""
        real = importlib.import_module(_SHORT_NAMES[module.__name__.rpartition(".")[2]])
        sys.modules[module.__name__] = real


if not any(type(finder).__name__ == "_ShortNameFinder" for finder in sys.meta_path):
    sys.meta_path.append(_ShortNameFinder())
