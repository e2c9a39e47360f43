"""Which sampler to use for a system: the one that gives the exact law fastest.

:func:`recommended_sampler` is the default path for a physicist who does not want to choose:

- spin lattices (Heisenberg): :func:`liesample.heisenberg_heat_bath` with over-relaxation;
  exact local moves, no step size;
- lattice gauge fields (:func:`liesample.systems.wilson_gauge`):
  :func:`liesample.wilson_heat_bath` with one over-relaxation sweep; exact, no step size;
- point vortices: :func:`liesample.vortex_metropolis`; exact, no step bias near collisions;
- other Lie–Poisson systems with linear noise (rigid body, heavy top, Zeitlin):
  :func:`liesample.adjusted_lie_poisson`; exact (Metropolis-adjusted), its step tuned in the
  warm-up;
- non-linear noise: :func:`liesample.lie_poisson_langevin`, its step chosen by the bias model.

The Gibbs law ``exp(−βh)`` on the orbit does not depend on the choice; the choice sets the cost
of an effective sample and whether a step-size bias exists at all.
"""

from __future__ import annotations

from liesample.dynamics.system import LiePoissonSystem
from liesample.samplers.contract import Sampler
from liesample.samplers.gauge.heat_bath import wilson_heat_bath
from liesample.samplers.orbit.adjusted_lie_poisson import adjusted_lie_poisson, check_linear_noise
from liesample.samplers.orbit.lie_poisson_langevin import lie_poisson_langevin
from liesample.samplers.orbit.vortex_metropolis import vortex_metropolis
from liesample.samplers.spins.heisenberg_heat_bath import heisenberg_heat_bath
from liesample.systems.heisenberg import SpinLatticeSystem
from liesample.systems.point_vortices import PointVortexSystem
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["recommended_sampler"]


def recommended_sampler(system: LiePoissonSystem, *, beta, **options) -> Sampler:
    """The recommended sampler of ``exp(−βh)`` for ``system`` (module table), built with
    ``beta`` and the sampler's own keyword ``options``; ``settings["sampler"]`` names it."""
    if isinstance(system, WilsonGauge):
        options.setdefault("overrelaxation", 1)
        return wilson_heat_bath(system, beta=beta, **options)
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(
            "system must be a LiePoissonSystem or a WilsonGauge (liesample.systems), got "
            f"{type(system).__name__}"
        )
    if isinstance(system, SpinLatticeSystem):
        options.setdefault("overrelaxation", 1)
        return heisenberg_heat_bath(system, beta=beta, **options)
    if isinstance(system, PointVortexSystem):
        return vortex_metropolis(system, beta=beta, **options)
    try:
        check_linear_noise(system)
    except ValueError:
        return lie_poisson_langevin(system, beta=beta, **options)
    return adjusted_lie_poisson(system, beta=beta, **options)
