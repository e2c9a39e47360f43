"""Template for a new sampler: copy to ``liesample/samplers/<phase space>/<your_sampler>.py``.

A sampler is a BlackJAX-shaped module: ``init``, ``build_kernel`` (the pure kernel, with every
tunable parameter an argument) and ``as_top_level_api`` (parameters fixed, returns a
:class:`liesample.samplers.contract.Sampler`), plus the module-level object built by
:func:`liesample.samplers.contract.sampling_api`, whose ``help()`` is ``as_top_level_api``'s
docstring. Its ``info`` keeps the contract of :mod:`liesample.samplers.contract`:
``is_divergent``, ``acceptance_rate`` and ``energy`` first, own fields after them;
``check_info`` verifies it, and then the runner (:func:`liesample.sample`), the diagnostics
and ArviZ output work unchanged.

The working example is random-walk Metropolis on a coadjoint orbit of so(3)*: the proposal is
``μ' = Ad*_{exp(ε ξ)} μ`` with ``ξ ~ N(0, I)`` in ``g``. A random rotation whose law is the same
as its inverse's maps the uniform law of the orbit to itself, so the proposal is symmetric and
the acceptance probability is ``min(1, exp(−β(h(μ') − h(μ))))``. (For non-compact orbits or
other algebras the proposal must be checked to be symmetric.) A divergent (non-finite)
proposal is rejected and flagged, as the contract requires.

Steps for your own sampler: put it in the folder of its phase space (``orbit/``,
``cotangent/``, ``spins/``), validate every argument in ``as_top_level_api`` (a bad input fails
at construction, naming the parameter), record the settings, and export it from
``liesample/__init__.py`` if it is public. Imports may point to the layers below
(``foundation`` … ``systems``) and this layer only.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.validation import finite_float
from liesample.samplers.contract import Sampler, sampling_api, step_key

__all__ = [
    "OrbitMetropolisInfo",
    "OrbitMetropolisState",
    "as_top_level_api",
    "build_kernel",
    "init",
]


class OrbitMetropolisState(NamedTuple):
    """The point ``position`` on the orbit and its energy ``h``."""

    position: jax.Array
    energy: jax.Array


class OrbitMetropolisInfo(NamedTuple):
    """The contract's three fields, then the sampler's own."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    is_accepted: jax.Array


def init(position, system: LiePoissonSystem, rng_key=None) -> OrbitMetropolisState:
    """The state at ``position`` (checked to lie on a valid orbit of ``system``)."""
    del rng_key  # the state draws nothing
    position = jnp.asarray(position)
    system.check_position(position)
    return OrbitMetropolisState(position, system.hamiltonian(position))


def build_kernel(system: LiePoissonSystem):
    """``kernel(rng_key, state, beta, scale) -> (state, info)``; ``beta`` and ``scale`` may be
    traced."""
    algebra = system.algebra

    def kernel(rng_key, state: OrbitMetropolisState, beta, scale):
        key_propose, key_accept = jax.random.split(rng_key)
        xi = jax.random.normal(key_propose, state.position.shape, state.position.dtype)
        proposal = algebra.coadjoint_exp(scale * xi, state.position)
        energy = system.hamiltonian(proposal)
        finite = jnp.all(jnp.isfinite(proposal)) & jnp.isfinite(energy)
        log_ratio = jnp.where(finite, -beta * (energy - state.energy), -jnp.inf)
        acceptance = jnp.minimum(1.0, jnp.exp(log_ratio))
        accept = jax.random.uniform(key_accept, (), state.position.dtype) < acceptance
        new = jax.tree.map(
            lambda a, b: jnp.where(accept, a, b), OrbitMetropolisState(proposal, energy), state
        )
        return new, OrbitMetropolisInfo(~finite, acceptance, new.energy, accept)

    return kernel


def as_top_level_api(system: LiePoissonSystem, *, beta, scale=0.5) -> Sampler:
    """Random-walk Metropolis on a coadjoint orbit of so(3)*, exact for ``∝ exp(−βh)``.

    Parameters
    ----------
    system : LiePoissonSystem
        A system on ``so3`` (e.g. :func:`liesample.systems.rigid_body`).
    beta : float
        Inverse temperature (finite).
    scale : float
        ``ε > 0``, the size of the random rotation.

    Returns
    -------
    Sampler
        ``init(position)`` and ``step(rng_key, state) -> (state, OrbitMetropolisInfo)``.
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {system!r}")
    beta = finite_float("beta", beta)
    scale = finite_float("scale", scale, positive=True)
    kernel = build_kernel(system)

    def init_fn(position, rng_key=None):
        return init(position, system, rng_key)

    def step_fn(rng_key, state):
        return kernel(step_key(rng_key), state, beta, scale)

    settings = {"sampler": "orbit_metropolis", "system": system.name, "beta": beta, "scale": scale}
    return Sampler(init_fn, step_fn, settings=settings)


orbit_metropolis = sampling_api(as_top_level_api, init, build_kernel, "orbit_metropolis", __name__)
