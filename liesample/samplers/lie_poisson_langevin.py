"""The Lie–Poisson–Langevin sampler: Gibbs-exact sampling on a coadjoint orbit.

A BlackJAX-shaped module (``State``/``Info``, ``init``, ``build_kernel``, ``as_top_level_api``).
The chain is the Poisson–Langevin SDE of MATH.md §1 with ``θ = βσ²/2`` (paper,
``eq:lie-poisson-langevin``), whose invariant law on the orbit of the initial state is
``∝ exp(−βh)``; the discretisation bias is that of the chosen integrator.
"""

from __future__ import annotations

from typing import NamedTuple

import blackjax
import jax
import jax.numpy as jnp

from liesample._validation import concrete_array, finite_float
from liesample.dynamics import PoissonLangevin, Scene, make_dynamics
from liesample.integrators import DEFAULT_INTEGRATOR, get_integrator
from liesample.stability import STABILITY_MODES, check_step_size
from liesample.systems.base import LiePoissonSystem

__all__ = [
    "LiePoissonInfo",
    "LiePoissonState",
    "as_top_level_api",
    "build_kernel",
    "init",
    "make_dynamics",
]


class LiePoissonState(NamedTuple):
    """State of a chain.

    position : the point ``μ`` on the orbit.
    reference_casimirs : the Casimirs of the initial point, against which drift is measured.
    """

    position: jax.Array
    reference_casimirs: jax.Array


class LiePoissonInfo(NamedTuple):
    """What one step did.

    energy : ``h`` at the new state.
    casimir_error : largest relative drift ``|C − C₀|/|C₀|`` of the Casimirs; for systems that
        declare a ``casimir_scale`` (a Casimir may be zero, e.g. the heavy top's ``Π·Γ``) the
        denominator is ``max(|C₀|, scale(μ))`` (``LiePoissonSystem.casimir_error``).
    nonfinite : the step produced NaN/inf; the chain then kept its previous state.
    """

    energy: jax.Array
    casimir_error: jax.Array
    nonfinite: jax.Array


def init(position, system: LiePoissonSystem, rng_key=None) -> LiePoissonState:
    """Initial state on the orbit through ``position`` (no key needed; ``rng_key`` is ignored)."""
    del rng_key
    system.check_position(position)
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    return LiePoissonState(position, system.casimirs(position))


def _info(system, position, reference_casimirs, nonfinite):
    drift = system.casimir_error(position, reference_casimirs)
    return LiePoissonInfo(system.hamiltonian(position), drift, nonfinite)


def build_kernel(
    system: LiePoissonSystem, integrator=DEFAULT_INTEGRATOR, scene: Scene | None = None
):
    """Build ``kernel(rng_key, state, step_size, sigma, theta) -> (state, info)``.

    The scene and integrator are structural (they decide what is traced); ``step_size``,
    ``sigma`` and ``theta`` may be traced values.
    """
    integrator = get_integrator(integrator)
    scene = Scene() if scene is None else scene

    def kernel(rng_key, state: LiePoissonState, step_size, sigma, theta):
        dynamics = PoissonLangevin(system, sigma=sigma, theta=theta, scene=scene)
        dW = dynamics.brownian_increments(rng_key, step_size, state.position.dtype)
        proposal = integrator(dynamics, state.position, step_size, dW)
        nonfinite = ~jnp.all(jnp.isfinite(proposal))
        position = jnp.where(nonfinite, state.position, proposal)
        new_state = LiePoissonState(position, state.reference_casimirs)
        return new_state, _info(system, position, state.reference_casimirs, nonfinite)

    return kernel


def as_top_level_api(
    system: LiePoissonSystem,
    *,
    beta=None,
    sigma=1.0,
    step_size,
    integrator=DEFAULT_INTEGRATOR,
    theta=None,
    hamiltonian: bool = True,
    stability: str = "warn",
) -> blackjax.base.SamplingAlgorithm:
    """Lie–Poisson–Langevin sampler of ``exp(−βh)`` on the orbit of the initial state.

    Parameters
    ----------
    system : LiePoissonSystem
        E.g. :func:`liesample.systems.rigid_body`.
    beta : float
        Inverse temperature; any finite value (``β < 0`` samples a negative temperature where
        the orbit is compact). Required when ``sigma > 0``.
    sigma : float
        Noise strength ``σ ≥ 0``: trades mixing against stiffness at fixed ``β``.
    step_size : float
        Time step ``dt > 0``.
    integrator : str or Integrator
        One of ``liesample.integrators.INTEGRATORS``; default ``"rkmk_heun"``.
    theta : float, optional
        Dissipation strength for a noise-free flow (``sigma = 0``) only.
    hamiltonian : bool
        Whether the scene has the Hamiltonian drift (it does not change the invariant law).
    stability : {"warn", "raise", "off"}
        What ``init`` does when ``step_size`` is beyond the integrator's stable bound on the
        orbit of the initial position, ``κ = step_size·θ·max_i |h''_i| > 2``
        (:mod:`liesample.stability`; rigid body: ``θ·step_size·r²(1/I_min − 1/I_max) ≤ 2``): a
        ``UserWarning`` naming the bound, a ``ValueError``, or nothing.

    Returns
    -------
    blackjax.base.SamplingAlgorithm
        ``init(position)`` and ``step(rng_key, state) -> (state, info)``.
    """
    if not isinstance(system, LiePoissonSystem):
        raise TypeError(f"system must be a LiePoissonSystem, got {type(system).__name__}")
    step_size = finite_float("step_size", step_size, positive=True)
    sigma, theta, scene = make_dynamics(
        system, beta=beta, sigma=sigma, theta=theta, hamiltonian=hamiltonian
    )
    if stability not in STABILITY_MODES:
        raise ValueError(f"stability must be one of {STABILITY_MODES}, got {stability!r}")
    integrator_name = get_integrator(integrator).name
    kernel = build_kernel(system, integrator, scene)

    def init_fn(position, rng_key=None):
        state = init(position, system, rng_key)
        if stability != "off" and concrete_array(position) is not None:
            check_step_size(system, integrator_name, step_size, theta, position, stability)
        return state

    def step_fn(rng_key, state):
        return kernel(rng_key, state, step_size, sigma, theta)

    return blackjax.base.SamplingAlgorithm(init_fn, step_fn)


lie_poisson_langevin = blackjax.GenerateSamplingAPI(as_top_level_api, init, build_kernel)
