"""Wolff single-cluster moves for the classical Heisenberg (O(3)) ferromagnet, and for every
O(n) ferromagnet of :func:`liesample.systems.n_vector` (the embedding holds for every ``n``).

``heisenberg_wolff(system, beta=β)`` is :func:`liesample.heisenberg_cluster` with
``clusters="seed"`` (one implementation: :mod:`liesample.samplers.spins.heisenberg_cluster`),
kept under its own name: draw a uniform reflection direction, open the embedded Ising bonds,
reflect the cluster of a uniform seed site. One step moves one cluster (at high temperature a
single site), so a warm-up of ``n`` steps is far less than ``n`` sweeps;
``heisenberg_cluster`` (Swendsen–Wang, the default ``clusters="all"``) reflects every cluster
with probability 1/2 and makes one step one sweep.
"""

from __future__ import annotations

from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import SpinState, SpinSystem, init, spin_sampler
from liesample.samplers.spins.heisenberg_cluster import (
    ClusterInfo,
    bond_table,
    check_cluster_beta,
    check_cluster_system,
)
from liesample.samplers.spins.heisenberg_cluster import build_kernel as _cluster_kernel

__all__ = ["SpinState", "WolffInfo", "as_top_level_api", "bond_table", "build_kernel", "init"]

WolffInfo = ClusterInfo
"""What one Wolff move did (:class:`~liesample.samplers.spins.heisenberg_cluster.ClusterInfo`)."""


def build_kernel(system: SpinSystem):
    """``kernel(rng_key, state, beta) -> (state, WolffInfo)``: one cluster reflection."""
    check_cluster_system(system, "heisenberg_wolff")
    return _cluster_kernel(system, "seed")


def as_top_level_api(system: SpinSystem, *, beta: float) -> Sampler:
    """Wolff single-cluster sampler of ``exp(−βh)`` for the isotropic ferromagnet, no field.

    Parameters
    ----------
    system : SpinLatticeSystem or NVectorSystem
        From :func:`liesample.systems.heisenberg` or :func:`liesample.systems.n_vector` (any
        dimension, any ``n``) with ``coupling > 0``, zero ``field`` and ``anisotropy = 0``, open
        or periodic (a ``ValueError`` names what is not
        allowed).
    beta : float
        Inverse temperature, finite and ``≥ 0``.

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` and ``step(rng_key, state) -> (state, WolffInfo)``, one
        step being one cluster reflection (``info.cluster_size`` sites); jit- and vmap-able.
        For a step that is one sweep, use :func:`liesample.heisenberg_cluster`.

    Examples
    --------
    >>> system = liesample.systems.heisenberg((4,))
    >>> sampler = liesample.heisenberg_wolff(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> 1 <= int(info.cluster_size) <= 4  # one cluster flipped
    True
    """
    check_cluster_system(system, "heisenberg_wolff")
    beta = check_cluster_beta(beta, "heisenberg_wolff")
    return spin_sampler("heisenberg_wolff", build_kernel, (), system, beta)


heisenberg_wolff = sampling_api(as_top_level_api, init, build_kernel, "heisenberg_wolff", __name__)
