"""Which sampler to use for a system: the one that gives the exact law fastest.

:func:`recommended_sampler` is the default path for a physicist who does not want to choose:

- spin lattices (Heisenberg): :func:`liesample.heisenberg_heat_bath` with over-relaxation
  (exact local moves, no step size), except near the 3-D critical point on large lattices,
  where :func:`liesample.heisenberg_cluster` (Swendsen–Wang) is faster per effective sample
  (:func:`spin_sampler_name`, chosen by measurement); O(n) lattices with ``n ≠ 3``
  (:func:`liesample.systems.n_vector`): the heat bath with over-relaxation (a default, not a
  measurement: :func:`spin_sampler_name`);
- CP(N−1) lattices (:func:`liesample.systems.cp_model`): :func:`liesample.cp_heat_bath` with
  one over-relaxation sweep (exact local moves; no cluster embedding exists for ``N ≥ 3``);
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

import math
from typing import Any

from liesample.dynamics.system import LiePoissonSystem
from liesample.samplers.contract import Sampler
from liesample.samplers.gauge.heat_bath import wilson_heat_bath
from liesample.samplers.orbit.adjusted_lie_poisson import adjusted_lie_poisson, check_linear_noise
from liesample.samplers.orbit.lie_poisson_langevin import lie_poisson_langevin
from liesample.samplers.orbit.vortex_metropolis import vortex_metropolis
from liesample.samplers.spins.cp_heat_bath import cp_heat_bath
from liesample.samplers.spins.heisenberg_cluster import heisenberg_cluster
from liesample.samplers.spins.heisenberg_heat_bath import heisenberg_heat_bath
from liesample.systems.cp_model import CPModelSystem
from liesample.systems.heisenberg import SpinLatticeSystem
from liesample.systems.n_vector import NVectorSystem
from liesample.systems.point_vortices import PointVortexSystem
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["recommended_sampler", "spin_sampler_name"]

CLUSTER_MIN_SITES = 32**3
"""Smallest 3-D lattice on which the cluster moves beat heat bath + over-relaxation at β_c."""

CLUSTER_BETA_WINDOW = (0.65, 0.75)
"""``βJ`` around the 3-D critical point (``β_c J ≈ 0.693``) where they do."""


def spin_sampler_name(system: SpinLatticeSystem | NVectorSystem, beta) -> str:
    """``"heisenberg_cluster"`` or ``"heisenberg_heat_bath"``: the faster exact sampler, by
    measurement of the effective samples per second of ``|m|`` and the energy.

    Swendsen–Wang wins only where critical slowing down is strong enough to pay for the
    cluster search: a cubic lattice of at least :data:`CLUSTER_MIN_SITES` sites with ``βJ`` in
    :data:`CLUSTER_BETA_WINDOW`, for the isotropic ferromagnet without field (the only systems
    the reflections sample). Everywhere else measured (smaller lattices, other temperatures)
    the heat bath with over-relaxation, whose over-relaxation already cuts the local moves'
    autocorrelation time, was faster; in other dimensions it is the default as well.

    For O(n) lattices with ``n ≠ 3`` (:func:`liesample.systems.n_vector`) the choice is the heat
    bath with over-relaxation everywhere, unmeasured: it is exact for every coupling sign and
    field (the cluster moves need the ferromagnet without field), and the O(3) measurement
    found it the faster sampler away from one window around one critical point. Where the
    cluster moves should win for ``n ≠ 3`` (near the 3-D XY and O(4) critical points, the 2-D
    XY model below its BKT temperature) is not measured here; pass
    :func:`liesample.heisenberg_cluster` explicitly there.
    """
    params = system.params
    if isinstance(system, NVectorSystem):
        return "heisenberg_heat_bath"
    beta_j = float(beta) * params["coupling"]
    cluster_system = (
        params["coupling"] > 0.0
        and not any(params["field"])
        and params["anisotropy"] == 0.0
        and len(params["shape"]) == 3
        and params["periodic"]
    )
    large = math.prod(params["shape"]) >= CLUSTER_MIN_SITES
    near_critical = CLUSTER_BETA_WINDOW[0] <= beta_j <= CLUSTER_BETA_WINDOW[1]
    if cluster_system and large and near_critical:
        return "heisenberg_cluster"
    return "heisenberg_heat_bath"


def recommended_sampler(system: LiePoissonSystem, *, beta: float, **options: Any) -> Sampler:
    """The recommended sampler of ``exp(−βh)`` for ``system`` (module table), built with
    ``beta`` and the sampler's own keyword ``options``; ``settings["sampler"]`` names it.

    Examples
    --------
    >>> system = liesample.systems.heisenberg((4,))
    >>> sampler = liesample.recommended_sampler(system, beta=1.0)  # heat bath + over-relaxation
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape
    (4, 3)
    """
    if isinstance(system, WilsonGauge):
        options.setdefault("overrelaxation", 1)
        return wilson_heat_bath(system, beta=beta, **options)
    if isinstance(system, CPModelSystem):
        options.setdefault("overrelaxation", 1)
        return cp_heat_bath(system, beta=beta, **options)
    if not isinstance(system, (LiePoissonSystem, NVectorSystem)):
        raise TypeError(
            "system must be a LiePoissonSystem, an NVectorSystem, a CPModelSystem or a WilsonGauge "
            f"(liesample.systems), got {type(system).__name__}"
        )
    if isinstance(system, (SpinLatticeSystem, NVectorSystem)):
        if spin_sampler_name(system, beta) == "heisenberg_cluster":
            return heisenberg_cluster(system, beta=beta, **options)
        options.setdefault("overrelaxation", 1)
        return heisenberg_heat_bath(system, beta=beta, **options)
    if isinstance(system, PointVortexSystem):
        return vortex_metropolis(system, beta=beta, **options)
    try:
        check_linear_noise(system)
    except ValueError:
        return lie_poisson_langevin(system, beta=beta, **options)
    return adjusted_lie_poisson(system, beta=beta, **options)
