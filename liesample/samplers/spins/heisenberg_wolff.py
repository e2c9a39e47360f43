"""Wolff single-cluster moves for the classical Heisenberg (O(3)) model.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). One step (Wolff
1989, embedded Ising spins): draw a uniform reflection direction ``r ∈ S²`` and a uniform seed
site; grow a cluster from the seed, each bond ``⟨ij⟩`` from a cluster site ``i`` to a site ``j``
outside it joining ``j`` with probability

    ``p_ij = 1 − exp(min(0, −2βJ (r·s_i)(r·s_j)))``

(projections before the flip; each bond is tested at most once), then reflect the cluster,
``s ↦ s − 2(r·s)r``. The reflection keeps every bond inside and outside the cluster, and the
bond probabilities make the move satisfy detailed balance for ``exp(−βh)`` with no rejection.
That holds for the isotropic nearest-neighbour model with ``J > 0``, no field, no anisotropy
and ``β ≥ 0``; other systems are refused.

The coins of all bonds are drawn at once, vectorised (the growth looks at each bond at most
once, so this is Wolff's law exactly); the growth is then a ``lax.while_loop`` over a
breadth-first queue of fixed size ``N``, one site popped per iteration and its ≤ 4 neighbours
joined at once.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import (
    SpinState,
    check_beta,
    check_spin_system,
    finish_step,
    init,
    spin_sampler,
)
from liesample.systems.heisenberg import SpinLatticeSystem, neighbour_table
from liesample.targets.spins import von_mises_fisher

__all__ = [
    "SpinState",
    "WolffInfo",
    "as_top_level_api",
    "bond_table",
    "build_kernel",
    "init",
]


class WolffInfo(NamedTuple):
    """What one cluster move did: the shared spin-info fields plus ``cluster_size`` (sites
    reflected). ``acceptance_rate`` is always 1 (the move is rejection-free)."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    cluster_size: jax.Array


def check_wolff_system(system: SpinLatticeSystem) -> None:
    params = check_spin_system(system)
    problems = []
    if params["coupling"] <= 0.0:
        problems.append(f"coupling J = {params['coupling']:g} (must be > 0, ferromagnetic)")
    if any(b != 0.0 for b in params["field"]):
        problems.append(f"field = {params['field']} (must be zero)")
    if params["anisotropy"] != 0.0:
        problems.append(f"anisotropy = {params['anisotropy']:g} (must be 0)")
    if problems:
        raise ValueError(
            "heisenberg_wolff is exact only for the isotropic ferromagnet without field "
            "(reflections must keep h); this system has " + "; ".join(problems) + ". Use "
            "heisenberg_heat_bath or heisenberg_metropolis instead"
        )


def bond_table(shape, periodic: bool):
    """``(neighbours (N, 2·dim), bond ids (N, 2·dim), bond ends (B, 2))`` of the lattice.

    ``neighbours`` is :func:`~liesample.systems.heisenberg.neighbour_table` (``N`` where an open
    edge has none); ``bond ids[i, d]`` numbers the undirected bond from ``i`` to its ``d``-th
    neighbour (``B`` where there is none), ``ends[b]`` its two sites.
    """
    table = neighbour_table(shape, periodic)
    num_sites = table.shape[0]
    ids, ends = {}, []
    bonds = np.empty_like(table)
    for i, row in enumerate(table):
        for d, j in enumerate(row):
            if j == num_sites:
                bonds[i, d] = -1
                continue
            key = (min(i, j), max(i, j))
            if key not in ids:
                ids[key] = len(ends)
                ends.append(key)
            bonds[i, d] = ids[key]
    bonds[bonds < 0] = len(ends)
    return table, bonds, np.array(ends, dtype=np.int64).reshape(-1, 2)


def build_kernel(system: SpinLatticeSystem):
    """``kernel(rng_key, state, beta) -> (state, WolffInfo)``: one cluster reflection."""
    check_wolff_system(system)
    params = system.params
    shape, coupling = params["shape"], params["coupling"]
    table, bonds, ends = bond_table(shape, params["periodic"])
    table, bonds, ends = (jnp.asarray(a, jnp.int32) for a in (table, bonds, ends))
    num_sites = table.shape[0]

    def kernel(rng_key, state: SpinState, beta):
        s = state.position.reshape(num_sites, 3)
        key_r, key_seed, key_bonds = jax.random.split(rng_key, 3)
        r = von_mises_fisher(key_r, jnp.array([0.0, 0.0, 1.0], s.dtype), 0.0)  # uniform on S²
        projection = s @ r
        # One coin per bond, drawn at once: the growth below looks at a bond at most once (from
        # the first of its ends to be popped, if the other is outside), so the cluster has
        # exactly Wolff's law. The last entry is the missing bond of an open edge: never open.
        product = projection[ends[:, 0]] * projection[ends[:, 1]]
        p_bond = -jnp.expm1(jnp.minimum(0.0, -2.0 * beta * coupling * product))
        bond_open = jax.random.uniform(key_bonds, p_bond.shape, dtype=s.dtype) < p_bond
        bond_open = jnp.append(bond_open, False)
        seed = jax.random.randint(key_seed, (), 0, num_sites, dtype=jnp.int32)
        in_cluster = jnp.zeros(num_sites + 1, bool).at[seed].set(True).at[num_sites].set(True)
        queue = jnp.zeros(num_sites, jnp.int32).at[0].set(seed)

        def grow(carry):
            in_cluster, queue, head, tail = carry
            i = queue[head]
            j = table[i]  # (degree,) distinct sites or the sentinel, which is always "in"
            join = bond_open[bonds[i]] & ~in_cluster[j]
            in_cluster = in_cluster.at[j].max(join)
            slot = tail + jnp.cumsum(join) - 1
            queue = queue.at[jnp.where(join, slot, num_sites)].set(j, mode="drop")
            return in_cluster, queue, head + 1, tail + jnp.sum(join, dtype=jnp.int32)

        in_cluster, _, _, size = jax.lax.while_loop(
            lambda carry: carry[2] < carry[3],
            grow,
            (in_cluster, queue, jnp.int32(0), jnp.int32(1)),
        )
        flip = in_cluster[:num_sites, None]
        new = jnp.where(flip, s - 2.0 * projection[:, None] * r, s)
        return finish_step(
            system,
            state.position,
            new.reshape(state.position.shape),
            1.0,
            info_class=WolffInfo,
            cluster_size=size,
        )

    return kernel


def as_top_level_api(system: SpinLatticeSystem, *, beta) -> Sampler:
    """Wolff single-cluster sampler of ``exp(−βh)`` for the isotropic ferromagnet, no field.

    Parameters
    ----------
    system : SpinLatticeSystem
        From :func:`liesample.systems.heisenberg` with ``coupling > 0``, zero ``field`` and
        ``anisotropy = 0``, open or periodic (a ``ValueError`` names what is not allowed).
    beta : float
        Inverse temperature, finite and ``≥ 0``.

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` and ``step(rng_key, state) -> (state, WolffInfo)``, one
        step being one cluster reflection (``info.cluster_size`` sites); jit- and vmap-able.
    """
    check_wolff_system(system)
    beta = check_beta(beta)
    if beta < 0.0:
        raise ValueError(
            f"beta must be >= 0 for heisenberg_wolff (a negative temperature turns the "
            f"ferromagnet into an antiferromagnet, which reflections do not sample); got {beta!r}"
        )
    kernel = build_kernel(system)

    return spin_sampler("heisenberg_wolff", kernel, system, beta)


heisenberg_wolff = sampling_api(as_top_level_api, init, build_kernel, "heisenberg_wolff", __name__)
