"""Which sampler to use for a system: the one that gives the exact law fastest.

:func:`recommended_sampler` is the default path for a physicist who does not want to choose:

- spin lattices (Heisenberg): :func:`liesample.heisenberg_heat_bath` with over-relaxation
  (exact local moves, no step size), except near the 3-D critical point on large lattices,
  where :func:`liesample.heisenberg_cluster` (Swendsen–Wang) is faster per effective sample
  (:func:`spin_sampler_name`, chosen by measurement); O(n) lattices with ``n ≠ 3``
  (:func:`liesample.systems.n_vector`): for the XY (``n = 2``) and O(4) models on periodic 2-D
  and 3-D lattices, Swendsen–Wang inside the measured windows of
  :data:`N_VECTOR_CLUSTER_WINDOWS` (the ``cluster_choice`` benchmark suite), the heat bath with
  over-relaxation outside them and for every other ``n`` and dimension, where nothing was
  measured;
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
from typing import Any, NamedTuple

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

__all__ = ["ClusterWindow", "recommended_sampler", "spin_sampler_name"]

CLUSTER_MIN_SITES = 32**3
"""Smallest 3-D lattice on which the cluster moves beat heat bath + over-relaxation at β_c."""

CLUSTER_BETA_WINDOW = (0.65, 0.75)
"""``βJ`` around the 3-D critical point (``β_c J ≈ 0.693``) where they do."""


class ClusterWindow(NamedTuple):
    """Where Swendsen–Wang beat heat bath + over-relaxation for the O(n) model on periodic
    lattices of one dimension: at least ``min_sites`` sites and ``βJ`` in
    ``[beta_low, beta_high]``."""

    n: int
    dimension: int
    min_sites: int
    beta_low: float
    beta_high: float


N_VECTOR_CLUSTER_WINDOWS: tuple[ClusterWindow, ...] = (
    ClusterWindow(n=2, dimension=3, min_sites=8**3, beta_low=0.40, beta_high=0.51),
    ClusterWindow(n=4, dimension=3, min_sites=8**3, beta_low=0.85, beta_high=1.02),
    ClusterWindow(n=2, dimension=2, min_sites=16**2, beta_low=0.7, beta_high=1.5),
    ClusterWindow(n=4, dimension=2, min_sites=16**2, beta_low=1.2, beta_high=2.4),
)
"""For O(n), ``n ≠ 3`` (:func:`liesample.systems.n_vector`), per ``(n, dimension)``: the
smallest lattice and the ``βJ`` range where the cluster moves were faster per effective sample
of ``|m|`` and the energy, as measured by the repository's ``cluster_choice`` benchmark suite
(the 3-D XY and O(4) models around their critical points and on either side, the 2-D XY model on
both sides of its BKT point, the 2-D O(4) model). Each window is the measured range itself:
outside it (other ``n``, other dimensions, smaller lattices, other ``β``) nothing was measured
and the heat bath with over-relaxation is kept."""


def _is_cluster_system(params: dict) -> bool:
    """The isotropic periodic ferromagnet without field: what the reflections sample and the
    measurements covered."""
    return (
        params["coupling"] > 0.0
        and not any(params["field"])
        and params["anisotropy"] == 0.0
        and bool(params["periodic"])
    )


def _n_vector_cluster_wins(params: dict, beta_j: float) -> bool:
    """Whether ``(n, dimension, sites, βJ)`` lies in one of :data:`N_VECTOR_CLUSTER_WINDOWS`."""
    sites = math.prod(params["shape"])
    return any(
        w.n == params["n"]
        and w.dimension == len(params["shape"])
        and sites >= w.min_sites
        and w.beta_low <= beta_j <= w.beta_high
        for w in N_VECTOR_CLUSTER_WINDOWS
    )


def spin_sampler_name(system: SpinLatticeSystem | NVectorSystem, beta) -> str:
    """``"heisenberg_cluster"`` or ``"heisenberg_heat_bath"``: the faster exact sampler, by
    measurement of the effective samples per second of ``|m|`` and the energy.

    Only the isotropic ferromagnet without field on a periodic lattice (the systems the
    reflections sample and the measurements covered) may get the cluster moves; every other
    system gets the heat bath with over-relaxation, exact for every coupling sign and field.

    For O(3) (:func:`liesample.systems.heisenberg`), measured by the ``spins`` benchmark suite:
    Swendsen–Wang wins only where critical slowing down is strong enough to pay for the cluster
    search: a cubic lattice of at least :data:`CLUSTER_MIN_SITES` sites with ``βJ`` in
    :data:`CLUSTER_BETA_WINDOW`. Everywhere else measured (smaller lattices, other
    temperatures) the heat bath with over-relaxation, whose over-relaxation already cuts the
    local moves' autocorrelation time, was faster; in other dimensions it is the default as
    well.

    For O(n) with ``n ≠ 3`` (:func:`liesample.systems.n_vector`), measured by the
    ``cluster_choice`` benchmark suite: the cluster moves inside the windows of
    :data:`N_VECTOR_CLUSTER_WINDOWS` (per ``n`` and dimension, a smallest lattice and a ``βJ``
    range), the heat bath with over-relaxation outside them, where nothing was measured
    (including every ``n`` other than 2 and 4, chains, and lattices of four or more
    dimensions).

    Examples
    --------
    >>> from liesample.samplers.recommended import spin_sampler_name
    >>> spin_sampler_name(liesample.systems.n_vector((16, 16, 16), 2, periodic=True), 0.4542)
    'heisenberg_cluster'
    >>> spin_sampler_name(liesample.systems.n_vector((16, 16, 16), 2), 0.4542)  # open
    'heisenberg_heat_bath'
    """
    params = system.params
    beta_j = float(beta) * params["coupling"]
    if not _is_cluster_system(params):
        return "heisenberg_heat_bath"
    if isinstance(system, NVectorSystem):
        wins = _n_vector_cluster_wins(params, beta_j)
    else:
        wins = (
            len(params["shape"]) == 3
            and math.prod(params["shape"]) >= CLUSTER_MIN_SITES
            and CLUSTER_BETA_WINDOW[0] <= beta_j <= CLUSTER_BETA_WINDOW[1]
        )
    return "heisenberg_cluster" if wins else "heisenberg_heat_bath"


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
