"""Single-spin Metropolis for the classical Heisenberg model: the physicists' baseline.

A *sweep* proposes a new direction for every spin once, one colour class of a proper colouring
of the lattice at a time: no two sites of a class are neighbours, so the spins of a class are
conditionally independent given the others and their Metropolis updates run simultaneously
(vectorised), each exactly reversible for ``∝ exp(−βh)``. Open boundaries and periodic even
extents use the two-colour checkerboard (even/odd sublattices for a chain); a periodic odd extent
(an odd cycle) needs three colours, built as ``Σ_a c_a(i_a) mod 3``.

Proposals (both symmetric, so the acceptance probability is ``min(1, exp(−βΔh))``):

- ``"uniform"``: a fresh direction uniform on the sphere;
- ``"rotation"``: ``s' = (s + ε g)/|s + ε g|`` with ``g ~ N(0, I₃)``, whose law depends only on
  ``s·s'`` (isotropy), with tunable size ``ε = proposal_scale``.

``Δh`` at site ``k`` uses the local field ``F_k = J Σ_{j~k} s_j + B``:
``Δh = −(s'_k − s_k)·F_k − D((s'_k·e_z)² − (s_k·e_z)²)``.
"""

from __future__ import annotations

from typing import NamedTuple

import blackjax
import jax
import jax.numpy as jnp

from liesample._validation import finite_float
from liesample.systems.heisenberg import SpinLatticeSystem, colouring, neighbour_sum

__all__ = [
    "MetropolisInfo",
    "MetropolisState",
    "heisenberg_metropolis",
    "local_energy_change",
]

PROPOSALS = ("uniform", "rotation")


class MetropolisState(NamedTuple):
    """The spins (``position``, shape ``(*shape, 3)``)."""

    position: jax.Array


class MetropolisInfo(NamedTuple):
    """What one sweep did: ``h`` after it and the fraction of accepted single-spin proposals."""

    energy: jax.Array
    acceptance_rate: jax.Array


def local_energy_change(system: SpinLatticeSystem, s, new):
    """``Δh_k = h(s with s_k → new_k) − h(s)`` for every site ``k`` at once (shape ``shape``).

    ``−(new_k − s_k)·(J Σ_{j~k} s_j + B) − D((new_k·e_z)² − (s_k·e_z)²)``: exact, because ``h``
    has no self-interaction (every bond joins two distinct sites).
    """
    params = system.params
    local_field = params["coupling"] * neighbour_sum(s, params["periodic"]) + jnp.asarray(
        params["field"], dtype=s.dtype
    )
    delta = -jnp.sum((new - s) * local_field, axis=-1)
    if params["anisotropy"] != 0.0:
        delta = delta - params["anisotropy"] * (new[..., 2] ** 2 - s[..., 2] ** 2)
    return delta


def _random_directions(key, shape, dtype):
    g = jax.random.normal(key, (*shape, 3), dtype=dtype)
    return g / jnp.linalg.norm(g, axis=-1, keepdims=True)


def heisenberg_metropolis(
    system: SpinLatticeSystem,
    *,
    beta,
    proposal: str = "uniform",
    proposal_scale=0.5,
) -> blackjax.base.SamplingAlgorithm:
    """Checkerboard single-spin Metropolis sampler of ``exp(−βh)`` for a :func:`heisenberg` system.

    Parameters
    ----------
    system : SpinLatticeSystem
        From :func:`liesample.systems.heisenberg.heisenberg` (its ``params`` define the model).
    beta : float
        Inverse temperature (finite).
    proposal : {"uniform", "rotation"}
        Independent uniform direction, or a small random rotation of size ``proposal_scale``.
    proposal_scale : float
        ``ε > 0`` of the rotation proposal (ignored for ``"uniform"``).

    Returns
    -------
    blackjax.base.SamplingAlgorithm
        ``init(position) -> MetropolisState`` and ``step(rng_key, state) -> (state, info)``,
        one step being one full sweep; jit- and vmap-able, usable with ``liesample.runner``.
    """
    if not isinstance(system, SpinLatticeSystem):
        raise TypeError(
            f"system must be a heisenberg(...) SpinLatticeSystem, got {type(system).__name__}"
        )
    beta = finite_float("beta", beta)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    proposal_scale = finite_float("proposal_scale", proposal_scale, positive=True)
    params = system.params
    shape, periodic = params["shape"], params["periodic"]
    colours, num_colours = colouring(shape, periodic)
    masks = [jnp.asarray(colours == c) for c in range(num_colours)]

    def propose(key, s):
        if proposal == "uniform":
            return _random_directions(key, shape, s.dtype)
        moved = s + proposal_scale * jax.random.normal(key, s.shape, dtype=s.dtype)
        return moved / jnp.linalg.norm(moved, axis=-1, keepdims=True)

    def update_colour(s, key, mask):
        key_propose, key_accept = jax.random.split(key)
        new = propose(key_propose, s)
        delta = local_energy_change(system, s, new)
        log_u = jnp.log(jax.random.uniform(key_accept, shape, dtype=s.dtype))
        accept = mask & (log_u < -beta * delta)
        return jnp.where(accept[..., None], new, s), jnp.sum(accept)

    def init_fn(position, rng_key=None):
        del rng_key
        system.check_position(position)
        return MetropolisState(jnp.asarray(position, dtype=jnp.result_type(float)))

    def step_fn(rng_key, state: MetropolisState):
        s = state.position
        keys = jax.random.split(rng_key, num_colours)
        accepted = jnp.zeros((), jnp.int32)
        for c in range(num_colours):  # a handful of colour classes, unrolled
            s, count = update_colour(s, keys[c], masks[c])
            accepted = accepted + count
        rate = accepted / colours.size
        return MetropolisState(s), MetropolisInfo(system.hamiltonian(s), rate)

    return blackjax.base.SamplingAlgorithm(init_fn, step_fn)
