"""Heat bath plus over-relaxation for CP(N−1) lattices (:func:`liesample.systems.cp_model`).

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). Sites of one colour
class of the lattice's proper colouring (:func:`liesample.systems.heisenberg.colouring`, the
classes of :func:`liesample.samplers.spins._lattice.sublattices`) are never neighbours, so given
the other classes each ``z_x`` has the conditional law

    ``∝ exp(β z_x^† M_x z_x)``,   ``M_x = J Σ_{y~x} z_y z_y^†``   (Hermitian),

a complex Bingham law on ``CP^{N−1}``. One step is

1. ``heat_bath_sweeps`` sweeps, each redrawing every site from that law exactly, one colour
   class at a time (:func:`liesample.targets.cp_model.complex_bingham`: the eigenbasis of
   ``M_x``, an exact rejection draw of the squared moduli on the simplex, uniform phases);
2. ``overrelaxation`` sweeps of the reflection ``z ↦ (2 u u^† − 1) z`` about the eigenvector
   ``u`` of ``βM_x`` of the largest eigenvalue (the most likely ray, as ``F̂`` is for a spin).
   In the eigenbasis it changes the sign of every coordinate but ``u``'s, so it keeps every
   ``|w_k|²``, hence ``z^† M_x z``; it is unitary (keeps the Fubini–Study measure) and an
   involution, so it keeps the conditional law exactly. For ``N = 2`` the Hopf map carries it
   to the O(3) over-relaxation ``s ↦ 2(s·F̂)F̂ − s``.

A separate sampler rather than a case of :func:`liesample.heisenberg_heat_bath`: the state is
complex, the local law is Bingham, not von Mises–Fisher, and the precession angle of the O(n)
sampler has no counterpart here; the lattice code (colour classes, the compiled-once
:class:`~liesample.samplers.contract.Structure` of :func:`~liesample.samplers.spins._lattice.
spin_sampler`, the step's info) is shared.

**No cluster move.** For ``N ≥ 3`` liesample offers no Wolff or Swendsen–Wang embedding for
CP(N−1). Wolff's construction needs a reflection of the target space whose fixed set splits the
lattice into Ising-like clusters with an exact bond law; for CP(N−1), ``N ≥ 3``, the available
reflections have fixed sets of codimension greater than one, the embedded Ising models are
frustrated or trivial, and (from the literature as we recall it, not checked here: Caracciolo,
Edwards, Pelissetto and Sokal, Nucl. Phys. B 403 (1993) 475, "Wolff-type embedding algorithms
for general nonlinear σ-models") such embeddings cannot beat critical slowing down for these
models. For ``N = 2`` use ``n_vector(shape, 3, coupling=J/2)`` and its cluster moves.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp

from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import (
    SpinInfo,
    SpinState,
    Sublattice,
    check_beta,
    check_sweeps,
    checkerboard_step,
    spin_sampler,
    sublattices,
)
from liesample.systems.cp_model import CPModelSystem
from liesample.targets.cp_model import complex_bingham

__all__ = ["SpinInfo", "SpinState", "as_top_level_api", "build_kernel", "init"]


def check_cp_system(system) -> CPModelSystem:
    """``system`` if it is a :func:`~liesample.systems.cp_model` lattice, else a ``TypeError``."""
    if not isinstance(system, CPModelSystem):
        raise TypeError(
            "system must be a cp_model(...) CPModelSystem (liesample.systems.cp_model); for O(n) "
            f"spins use liesample.heisenberg_heat_bath; got {type(system).__name__}"
        )
    return system


def init(position, system: CPModelSystem, rng_key=None) -> SpinState:
    """Initial state: the unit vectors ``z`` (checked), as a complex array (``rng_key`` is
    ignored)."""
    del rng_key
    system.check_position(position)
    return SpinState(jnp.asarray(position, dtype=jnp.result_type(complex)))


def _init_on(system, position, rng_key=None):
    return init(position, system, rng_key)


def _start(system: CPModelSystem):
    """The sampler's ``init_fn(position, rng_key=None)`` (complex starts, unlike the O(n)
    samplers' real ones)."""
    return functools.partial(_init_on, system)


def local_matrices(system: CPModelSystem, flat, sublattice: Sublattice):
    """``M_x = J Σ_{y~x} z_y z_y^†`` at the sites of ``sublattice`` (``flat``: ``(V, N)``;
    a missing neighbour of an open boundary is the zero vector), shape ``(sites, N, N)``."""
    padded = jnp.concatenate([flat, jnp.zeros((1, flat.shape[-1]), flat.dtype)])
    neighbours = padded[sublattice.neighbours]  # (sites, 2d, N)
    outer = jnp.einsum("sya,syb->sab", neighbours, jnp.conj(neighbours))
    return system.params["coupling"] * outer


def heat_bath(system: CPModelSystem, rng_key, flat, sublattice: Sublattice, beta):
    """The sites of ``sublattice`` redrawn from their exact conditional laws
    ``∝ exp(β z^† M_x z)`` (:func:`liesample.targets.cp_model.complex_bingham`)."""
    draw = complex_bingham(rng_key, local_matrices(system, flat, sublattice), beta)
    return flat.at[sublattice.sites].set(draw.astype(flat.dtype))


def reflect(system: CPModelSystem, flat, sublattice: Sublattice, beta):
    """Over-relaxation of the sites of ``sublattice``: ``z ↦ (2 u u^† − 1) z`` with ``u`` the
    eigenvector of ``βM_x`` of the largest eigenvalue (module docstring)."""
    values, vectors = jnp.linalg.eigh(local_matrices(system, flat, sublattice))
    top = jnp.argmax(beta * values, axis=-1)
    u = jnp.take_along_axis(vectors, top[:, None, None], axis=-1)[..., 0]  # (sites, N)
    z = flat[sublattice.sites]
    overlap = jnp.sum(jnp.conj(u) * z, axis=-1, keepdims=True)
    return flat.at[sublattice.sites].set(2.0 * overlap * u - z)


def build_kernel(system: CPModelSystem, heat_bath_sweeps: int = 1, overrelaxation: int = 1):
    """``kernel(rng_key, state, beta) -> (state, SpinInfo)``; the sweep counts are structural
    (unrolled), ``beta`` may be traced."""
    check_cp_system(system)
    heat_bath_sweeps = check_sweeps("heat_bath_sweeps", heat_bath_sweeps)
    overrelaxation = check_sweeps("overrelaxation", overrelaxation)
    classes = sublattices(system)

    def kernel(rng_key, state: SpinState, beta):
        return checkerboard_step(
            system, rng_key, state, classes, heat_bath_sweeps, overrelaxation,
            lambda key, flat, sublattice: heat_bath(system, key, flat, sublattice, beta),
            lambda flat, sublattice: reflect(system, flat, sublattice, beta),
        )  # fmt: skip

    return kernel


def as_top_level_api(
    system: CPModelSystem, *, beta: float, overrelaxation: int = 1, heat_bath_sweeps: int = 1
) -> Sampler:
    """Heat-bath + over-relaxation sampler of ``exp(−βh)`` for a CP(N−1) lattice.

    Parameters
    ----------
    system : CPModelSystem
        From :func:`liesample.systems.cp_model` (any ``N ≥ 2``, shape, coupling, boundary).
    beta : float
        Inverse temperature (finite, any sign).
    overrelaxation : int
        Over-relaxation sweeps per step (the reflection of the module docstring), ``≥ 0``.
    heat_bath_sweeps : int
        Exact heat-bath sweeps per step, ``≥ 0``; with 0 the chain keeps ``h`` (it samples
        ``exp(−βh)`` only from exact starting draws).

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` (complex ``z`` of shape ``(*shape, N)``) and
        ``step(rng_key, state) -> (state, SpinInfo)``; jit- and vmap-able. ``β`` is traced in
        its declared structure, so a sweep over ``β`` compiles one step.

    Examples
    --------
    >>> system = liesample.systems.cp_model((4, 4), N=3, periodic=True)
    >>> sampler = liesample.cp_heat_bath(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((4, 4, 3), False)
    """
    beta = check_beta(beta)
    check_cp_system(system)
    heat_bath_sweeps = check_sweeps("heat_bath_sweeps", heat_bath_sweeps)
    overrelaxation = check_sweeps("overrelaxation", overrelaxation)
    if heat_bath_sweeps + overrelaxation == 0:
        raise ValueError("heat_bath_sweeps + overrelaxation must be >= 1 (a step must move)")
    return spin_sampler(
        "cp_heat_bath",
        build_kernel,
        (heat_bath_sweeps, overrelaxation),
        system,
        beta,
        start=_start,
        heat_bath_sweeps=heat_bath_sweeps,
        overrelaxation=overrelaxation,
    )


cp_heat_bath = sampling_api(as_top_level_api, init, build_kernel, "cp_heat_bath", __name__)
