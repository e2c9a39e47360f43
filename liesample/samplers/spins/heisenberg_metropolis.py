"""Single-spin Metropolis for the classical Heisenberg model: the physicists' baseline.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). A step is one
*sweep*: every spin gets one proposal, one colour class of the lattice's proper colouring at a
time (:func:`liesample.systems.heisenberg.colouring`). No two sites of a class are neighbours,
so the spins of a class are conditionally independent given the others and their Metropolis
updates run simultaneously (vectorised), each exactly reversible for ``∝ exp(−βh)``.

Proposals (both symmetric, so the acceptance probability is ``min(1, exp(−βΔh))``):

- ``"uniform"``: a fresh direction uniform on the sphere;
- ``"rotation"``: ``s' = (s + ε g)/|s + ε g|`` with ``g ~ N(0, I₃)``, whose law depends only on
  ``s·s'`` (isotropy), with tunable size ``ε = proposal_scale``.

``Δh`` at site ``k`` is :func:`liesample.samplers.spins._lattice.energy_change` in the local field
``F_k = J Σ_{j~k} s_j + B`` (any coupling, field and anisotropy). Both proposals, written here
for ``S²``, are the same on every sphere, so the sampler takes the O(n) lattices of
:func:`liesample.systems.n_vector` as well (``g ~ N(0, Iₙ)``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from liesample.foundation.validation import finite_float
from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import (
    SpinInfo,
    SpinState,
    SpinSystem,
    check_beta,
    check_spin_system,
    energy_change,
    finish_step,
    init,
    spin_sampler,
    sublattice_field,
    sublattices,
)

__all__ = ["PROPOSALS", "SpinInfo", "SpinState", "as_top_level_api", "build_kernel", "init"]

PROPOSALS = ("uniform", "rotation")


def _random_directions(key, shape, n, dtype):
    g = jax.random.normal(key, (*shape, n), dtype=dtype)
    return g / jnp.linalg.norm(g, axis=-1, keepdims=True)


def build_kernel(system: SpinSystem, proposal: str = "uniform"):
    """``kernel(rng_key, state, beta, proposal_scale) -> (state, SpinInfo)``, one sweep.

    ``proposal`` is structural; ``beta`` and ``proposal_scale`` may be traced.
    """
    check_spin_system(system)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    classes = sublattices(system)

    def propose(key, s, scale):
        if proposal == "uniform":
            return _random_directions(key, s.shape[:-1], s.shape[-1], s.dtype)
        moved = s + scale * jax.random.normal(key, s.shape, dtype=s.dtype)
        return moved / jnp.linalg.norm(moved, axis=-1, keepdims=True)

    def kernel(rng_key, state: SpinState, beta, proposal_scale):
        flat = state.position.reshape(-1, state.position.shape[-1])
        keys = jax.random.split(rng_key, len(classes))
        accepted = jnp.zeros((), jnp.int32)
        for key, sublattice in zip(keys, classes):  # a handful of colour classes, unrolled
            key_propose, key_accept = jax.random.split(key)
            s = flat[sublattice.sites]
            new = propose(key_propose, s, proposal_scale)
            delta = energy_change(system, s, new, sublattice_field(system, flat, sublattice))
            log_u = jnp.log(jax.random.uniform(key_accept, s.shape[:-1], dtype=s.dtype))
            accept = log_u < -beta * delta
            flat = flat.at[sublattice.sites].set(jnp.where(accept[:, None], new, s))
            accepted = accepted + jnp.sum(accept)
        position = flat.reshape(state.position.shape)
        return finish_step(system, state.position, position, accepted / flat.shape[0])

    return kernel


def as_top_level_api(
    system: SpinSystem,
    *,
    beta: float,
    proposal: str = "uniform",
    proposal_scale: float = 0.5,
) -> Sampler:
    """Checkerboard single-spin Metropolis sampler of ``exp(−βh)`` for a :func:`heisenberg` system.

    Parameters
    ----------
    system : SpinLatticeSystem or NVectorSystem
        From :func:`liesample.systems.heisenberg` (any coupling, field, anisotropy, boundary) or
        :func:`liesample.systems.n_vector` (any ``n ≥ 2``).
    beta : float
        Inverse temperature (finite).
    proposal : {"uniform", "rotation"}
        Independent uniform direction, or a small random rotation of size ``proposal_scale``.
    proposal_scale : float
        ``ε > 0`` of the rotation proposal (ignored for ``"uniform"``).

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` and ``step(rng_key, state) -> (state, SpinInfo)``, one
        step being one full sweep; jit- and vmap-able, usable with :mod:`liesample.run.runner`.

    Examples
    --------
    >>> system = liesample.systems.heisenberg((4,))
    >>> sampler = liesample.heisenberg_metropolis(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> bool(jnp.allclose(jnp.linalg.norm(state.position, axis=-1), 1.0))  # unit spins
    True
    """
    check_spin_system(system)
    beta = check_beta(beta)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    proposal_scale = finite_float("proposal_scale", proposal_scale, positive=True)
    return spin_sampler(
        "heisenberg_metropolis",
        build_kernel,
        (proposal,),
        system,
        beta,
        proposal_scale,
        proposal=proposal,
        proposal_scale=proposal_scale,
    )


heisenberg_metropolis = sampling_api(
    as_top_level_api, init, build_kernel, "heisenberg_metropolis", __name__
)
