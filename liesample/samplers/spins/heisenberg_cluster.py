"""Cluster moves for the classical Heisenberg (O(3)) ferromagnet: Swendsen–Wang and Wolff, with
Wolff's embedding, vectorised in any dimension.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). One step (Wolff
1989, embedded Ising spins ``σ_k = sign(r·s_k)``):

1. draw a uniform reflection direction ``r ∈ S²`` (``S^{n−1}`` for an O(n) lattice of
   :func:`liesample.systems.n_vector`: the embedding and everything below hold for every ``n``);
2. open every nearest-neighbour bond ``⟨ij⟩`` independently with probability

   ``p_ij = 1 − exp(min(0, −2βJ (r·s_i)(r·s_j)))``

   (the Fortuin–Kasteleyn bonds of the embedded Ising model, coupling ``βJ|r·s_i||r·s_j|``);
3. find the connected components of the open bonds (:func:`connected_components`);
4. reflect clusters, ``s ↦ s − 2(r·s)r``: with ``clusters="all"`` (Swendsen–Wang) each cluster
   independently with probability 1/2, with ``clusters="seed"`` (Wolff's single cluster) the one
   holding a uniform seed site.

A reflection keeps every bond inside and outside a cluster, and the bond probabilities make both
moves satisfy detailed balance for ``exp(−βh)`` with no rejection. That holds for the isotropic
nearest-neighbour model with ``J > 0``, no field, no anisotropy and ``β ≥ 0``; other systems are
refused. A Swendsen–Wang step gives every site a new bond configuration and a chance to flip: it
is one sweep of the lattice, so a warm-up of ``n`` steps is ``n`` sweeps. A Wolff step moves one
cluster only (at high temperature one site), however large the lattice.

The bonds live on the grid (``bond_open[a][x]`` joins ``x`` and ``x + e_a``), so neighbours are
``jnp.roll`` shifts, not gathers; the uniform of each bond is drawn in the order of
:func:`bond_table` whichever end sees it. The connected components come from label propagation
with pointer jumping (no site-by-site loop): every site points to a site of smaller index in its
cluster; each round hooks the root of every site onto the smallest label across its open bonds
(a scatter-min) and halves the pointer paths twice; the round repeats until nothing changes, a
number of rounds that grows like the logarithm of the cluster diameter rather than the diameter
itself. The root of a cluster is its smallest site index, whatever the search, so the coin of
each cluster (drawn per root) does not depend on how the components are found.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import (
    SpinState,
    SpinSystem,
    check_beta,
    check_spin_system,
    finish_step,
    init,
    spin_sampler,
)
from liesample.systems.heisenberg import neighbour_table
from liesample.targets.spins import von_mises_fisher

__all__ = [
    "CLUSTER_RULES",
    "ClusterInfo",
    "SpinState",
    "as_top_level_api",
    "bond_table",
    "build_kernel",
    "check_cluster_system",
    "connected_components",
    "init",
]

CLUSTER_RULES = ("all", "seed")
"""``"all"``: Swendsen–Wang (every cluster flips with probability 1/2); ``"seed"``: Wolff's single
cluster (the cluster of a uniform seed site flips)."""


class ClusterInfo(NamedTuple):
    """What one cluster move did: the shared spin-info fields plus ``cluster_size`` (the number
    of sites reflected). ``acceptance_rate`` is always 1 (the move is rejection-free)."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    cluster_size: jax.Array


def check_cluster_system(system: SpinSystem, sampler: str) -> None:
    """Refuse what reflections do not sample: ``J ≤ 0``, a field, an anisotropy."""
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
            f"{sampler} is exact only for the isotropic ferromagnet without field "
            "(reflections must keep h); this system has " + "; ".join(problems) + ". Use "
            "heisenberg_heat_bath (any coupling sign and field) or heisenberg_metropolis "
            "(anisotropy too) instead"
        )


def check_cluster_beta(beta, sampler: str) -> float:
    beta = check_beta(beta)
    if beta < 0.0:
        raise ValueError(
            f"beta must be >= 0 for {sampler} (a negative temperature turns the ferromagnet "
            f"into an antiferromagnet, which reflections do not sample); got {beta!r}. Use "
            "heisenberg_heat_bath for beta < 0"
        )
    return beta


def bond_table(shape, periodic: bool):
    """``(neighbours (N, 2·dim), bond ids (N, 2·dim), bond ends (B, 2))`` of the lattice.

    ``neighbours`` is :func:`~liesample.systems.heisenberg.neighbour_table` (``N`` where an open
    edge has none); ``bond ids[i, d]`` numbers the undirected bond from ``i`` to its ``d``-th
    neighbour (``B`` where there is none), in the order the rows first meet them; ``ends[b]``
    holds its two sites, smaller first.
    """
    table = neighbour_table(shape, periodic)
    num_sites, degree = table.shape
    i = np.repeat(np.arange(num_sites), degree)
    j = table.reshape(-1)
    valid = j != num_sites
    key = np.minimum(i, j)[valid] * num_sites + np.maximum(i, j)[valid]
    unique, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first)  # number the bonds in the order the rows first meet them
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    bonds = np.full(num_sites * degree, unique.size, dtype=np.int64)
    bonds[valid] = rank[inverse.reshape(-1)]
    ends = np.stack([unique // num_sites, unique % num_sites], axis=1)[order]
    return table, bonds.reshape(table.shape), ends.astype(np.int64).reshape(-1, 2)


def connected_components(bond_open):
    """``root`` (flat, ``N = prod(shape)``), the smallest flat site index in each site's
    component, for ``bond_open`` (bool, ``(dim, *shape)``): ``bond_open[a][x]`` joins site ``x``
    to ``x + e_a`` (periodically wrapped; an open lattice passes ``False`` on its last layer).

    Label propagation with pointer jumping: ``parent[k] ≤ k`` always; a round takes at every
    ``k`` the smallest parent across its open bonds (``jnp.roll`` on the grid), hooks the parent
    of ``k`` onto it (scatter-min) and jumps pointers twice. A round that changes nothing leaves
    every tree a star whose linked sites share the root, so the loop stops exactly at the
    components. Under ``jax.vmap`` the lattices of the batch are labelled as one disjoint union
    (labels offset by ``N`` per lattice), so the hooks and jumps stay one-dimensional gathers and
    scatters, cheaper than batched ones; the price is that chains sharded over several devices
    gather their bonds onto each device for this search.
    """
    return _components(bond_open[None])[0]


@jax.custom_batching.custom_vmap
def _components(bond_open):
    """:func:`connected_components` of ``bond_open`` (``(lattices, dim, *shape)``) as one graph,
    roots ``(lattices, N)`` counted within each lattice."""
    lattices, dim, *shape = bond_open.shape
    num_sites = math.prod(shape)
    total = lattices * num_sites
    if total > np.iinfo(np.int32).max and not jax.config.jax_enable_x64:
        raise ValueError(
            f"connected_components: {lattices} lattices of {num_sites} sites need 64-bit labels; "
            "enable them with jax.config.update('jax_enable_x64', True) or run fewer chains "
            "per call"
        )
    dtype = jnp.int32 if total <= np.iinfo(np.int32).max else jnp.int64
    grid_shape = (lattices, *shape)
    # Bond ``a`` of site ``x`` seen from both ends: to ``x + e_a`` and from ``x − e_a``.
    up = [bond_open[:, a] for a in range(dim)]
    down = [jnp.roll(bond_open[:, a], 1, axis=1 + a) for a in range(dim)]

    def smallest_linked(parent):
        grid = parent.reshape(grid_shape)
        smallest = grid
        for a in range(dim):
            smallest = jnp.minimum(smallest, jnp.where(up[a], jnp.roll(grid, -1, 1 + a), grid))
            smallest = jnp.minimum(smallest, jnp.where(down[a], jnp.roll(grid, 1, 1 + a), grid))
        return smallest.reshape(-1)

    def round_(carry):
        parent, _ = carry
        hooked = parent.at[parent].min(smallest_linked(parent))
        jumped = hooked[hooked]
        jumped = jumped[jumped]
        return jumped, jnp.any(jumped != parent)

    parent, _ = jax.lax.while_loop(
        lambda carry: carry[1], round_, (jnp.arange(total, dtype=dtype), True)
    )
    offset = jnp.arange(lattices, dtype=dtype)[:, None] * num_sites
    return (parent.reshape(lattices, num_sites) - offset).astype(jnp.int32)


@_components.def_vmap
def _components_batched(axis_size, in_batched, bond_open):
    """A batch of unions is one larger union (so nested ``vmap`` stays flat too)."""
    del in_batched  # the rule runs only when its one argument is batched
    roots = _components(bond_open.reshape(axis_size * bond_open.shape[1], *bond_open.shape[2:]))
    return roots.reshape(axis_size, -1, roots.shape[-1]), True


def _uniform_direction(rng_key, n: int, dtype):
    """A uniform ``r ∈ S^{n−1}``: on ``S²`` the von Mises–Fisher draw at ``κ = 0`` (as the O(3)
    draws were always made), else a normalised Gaussian vector."""
    if n == 3:
        return von_mises_fisher(rng_key, jnp.array([0.0, 0.0, 1.0], dtype), 0.0)
    g = jax.random.normal(rng_key, (n,), dtype=dtype)
    return g / jnp.linalg.norm(g)


def build_kernel(system: SpinSystem, clusters: str = "all"):
    """``kernel(rng_key, state, beta) -> (state, ClusterInfo)``: one cluster step.

    ``clusters`` (structural) is ``"all"`` (Swendsen–Wang) or ``"seed"`` (Wolff); ``beta`` may
    be traced.
    """
    if clusters not in CLUSTER_RULES:
        raise ValueError(
            f"clusters must be one of {CLUSTER_RULES} ('all': Swendsen-Wang, 'seed': Wolff), "
            f"got {clusters!r}"
        )
    check_cluster_system(system, "heisenberg_cluster")
    params = system.params
    coupling = params["coupling"]
    shape = params["shape"]
    _, bonds, ends = bond_table(shape, params["periodic"])
    num_sites, num_bonds = bonds.shape[0], ends.shape[0]
    # ``up[a][x]``: the id of the bond from x to x + e_a (column 2a + 1 of the neighbour table;
    # ``num_bonds`` past an open edge), so that bond ``b`` gets the ``b``-th uniform.
    up = bonds[:, 1::2].T.reshape(len(shape), *shape)
    bond_ids, exists = jnp.asarray(up, jnp.int32), jnp.asarray(up < num_bonds)

    def kernel(rng_key, state: SpinState, beta):
        s = state.position.reshape(num_sites, state.position.shape[-1])
        key_r, key_seed, key_bonds = jax.random.split(rng_key, 3)
        r = _uniform_direction(key_r, s.shape[-1], s.dtype)
        projection = s @ r
        grid = projection.reshape(shape)
        product = jnp.stack([grid * jnp.roll(grid, -1, a) for a in range(len(shape))])
        p_bond = -jnp.expm1(jnp.minimum(0.0, -2.0 * beta * coupling * product))
        uniform = jax.random.uniform(key_bonds, (num_bonds,), dtype=s.dtype)
        bond_open = exists & (jnp.append(uniform, 1.0)[bond_ids] < p_bond)
        root = connected_components(bond_open)
        if clusters == "all":
            coin = jax.random.bernoulli(key_seed, 0.5, (num_sites,))
            flip = coin[root]
        else:
            seed = jax.random.randint(key_seed, (), 0, num_sites, dtype=jnp.int32)
            flip = root == root[seed]
        new = jnp.where(flip[:, None], s - 2.0 * projection[:, None] * r, s)
        new = jax.lax.optimization_barrier(new)  # computed once, not once per use below
        return finish_step(
            system,
            state.position,
            new.reshape(state.position.shape),
            1.0,
            info_class=ClusterInfo,
            cluster_size=jnp.sum(flip, dtype=jnp.int32),
        )

    return kernel


def as_top_level_api(system: SpinSystem, *, beta: float, clusters: str = "all") -> Sampler:
    """Cluster sampler of ``exp(−βh)`` for the isotropic ferromagnet without field.

    Parameters
    ----------
    system : SpinLatticeSystem or NVectorSystem
        From :func:`liesample.systems.heisenberg` or :func:`liesample.systems.n_vector` (any
        ``n``), any dimension, open or periodic, with
        ``coupling > 0``, zero ``field`` and ``anisotropy = 0`` (a ``ValueError`` names what is
        not allowed and the sampler to use instead).
    beta : float
        Inverse temperature, finite and ``≥ 0``.
    clusters : {"all", "seed"}
        ``"all"``: Swendsen–Wang, every cluster of the bond configuration reflected with
        probability 1/2 (one step is one sweep of the lattice); ``"seed"``: Wolff's single
        cluster, the one holding a uniform seed site (one step moves one cluster).

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` and ``step(rng_key, state) -> (state, ClusterInfo)``
        (``info.cluster_size``: sites reflected); jit- and vmap-able.

    Examples
    --------
    >>> system = liesample.systems.heisenberg((4,))
    >>> sampler = liesample.heisenberg_cluster(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((4, 3), False)
    """
    if clusters not in CLUSTER_RULES:
        raise ValueError(
            f"clusters must be one of {CLUSTER_RULES} ('all': Swendsen-Wang, 'seed': Wolff), "
            f"got {clusters!r}"
        )
    check_cluster_system(system, "heisenberg_cluster")
    beta = check_cluster_beta(beta, "heisenberg_cluster")
    return spin_sampler(
        "heisenberg_cluster", build_kernel, (clusters,), system, beta, clusters=clusters
    )


heisenberg_cluster = sampling_api(
    as_top_level_api, init, build_kernel, "heisenberg_cluster", __name__
)
