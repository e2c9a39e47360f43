"""Symplectic diffusions on ``T*Rⁿ`` and a pathwise-symplectic integrator (paper,
``sec:stoch-ham``).

Bismut's symplectic diffusion (paper, ``eqn:ham_q``–``eqn:ham_p`` and
``eq:general-symplectic-diffusion``), the Hamiltonian side of the stochastic Hamilton–Pontryagin
principle, is

    dz = Σ_{i ≥ 0} X_{H_i}(z) ∘ dS^i,      X_H = (∂H/∂p, −∂H/∂q),      S^0 = t,

driven by the semimartingales ``S^i`` (e.g. ``S^i = W^i``; paper,
``def:driving_semimartingale``). Its stochastic flow is a symplectomorphism for every path.
No dissipation is added here: this is the conservative skeleton under the Poisson–Langevin SDE.

**Integrator: the stochastic implicit midpoint rule** (Milstein, Repin & Tretyakov 2002)

    z' = z + J ∇𝓗((z + z')/2),        𝓗 = Σ_i H_i ΔS^i,     J = [[0, I], [−I, 0]],

solved by fixed-point iteration to a tolerance near round-off. Why this one: for *fixed*
increments the step is the implicit midpoint rule for the autonomous Hamiltonian ``𝓗``, which is
a symplectic map for any ``𝓗`` — so the scheme is symplectic pathwise for non-separable and
multiplicative noise Hamiltonians alike (a stochastic Störmer–Verlet would need every ``H_i``
separable). Evaluating at the midpoint makes it consistent with the Stratonovich reading (no
Itô correction is added anywhere). Its strong (mean-square) order is 1 for commutative noise
and 1/2 in general (it does not sample Lévy areas); it is implicit, and for noise Hamiltonians
that are not linear the fixed point needs ``|ΔS|`` small enough: :func:`brownian_increments`
can truncate increments as MRT do (which keeps the mean-square order).

:func:`stochastic_heun_step` is the explicit Stratonovich Heun scheme: same order on this
problem, not symplectic (the baseline that the symplecticity test must reject).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.dynamics.sde import heun_step
from liesample.foundation.schemes import Schemes

_DEFAULT_TOLERANCE = 1e-14
_DEFAULT_MAX_ITERATIONS = 100


@dataclass(frozen=True, eq=False)
class SymplecticDiffusion:
    """``dz = Σ_{i=0}^{m} X_{H_i} ∘ dS^i`` on ``T*Rⁿ``; build with :func:`symplectic_diffusion`.

    Attributes
    ----------
    hamiltonians : callable
        ``z ↦ (H_0(z), …, H_m(z))``, shape ``(m + 1,)``; ``H_0`` is driven by ``S^0 = t``.
    dimension : int
        ``n``; states ``z = (q, p)`` have shape ``(2n,)``.
    num_drivers : int
        ``m + 1`` (time included).
    """

    hamiltonians: Callable
    dimension: int
    num_drivers: int

    def combined_hamiltonian(self, z, increments):
        """``𝓗(z) = Σ_i H_i(z) ΔS^i``: the step's autonomous Hamiltonian."""
        return jnp.dot(self.hamiltonians(z), increments)

    def vector_field(self, z, increments):
        """``J ∇𝓗(z) = Σ_i X_{H_i}(z) ΔS^i``."""
        gradient = jax.grad(self.combined_hamiltonian)(z, increments)
        n = self.dimension
        return jnp.concatenate([gradient[n:], -gradient[:n]])


def symplectic_diffusion(hamiltonians: Callable, dimension: int) -> SymplecticDiffusion:
    """Declare a symplectic diffusion from ``z ↦ (H_0, …, H_m)`` on ``T*R^dimension``."""
    if isinstance(dimension, bool) or not isinstance(dimension, (int, np.integer)) or dimension < 1:
        raise ValueError(f"dimension must be an int >= 1, got {dimension!r}")
    if not callable(hamiltonians):
        raise TypeError(
            f"hamiltonians must be a callable z -> (H_0, ..., H_m), got {hamiltonians!r}"
        )
    probe = jax.eval_shape(hamiltonians, jax.ShapeDtypeStruct((2 * int(dimension),), jnp.float64))
    shape = getattr(probe, "shape", None)
    if shape is None or len(shape) != 1 or shape[0] < 1:
        raise ValueError(
            f"hamiltonians must map a state of shape ({2 * dimension},) "
            "to a vector (H_0, ..., H_m) "
            f"of shape (m + 1,), got {shape}"
        )
    return SymplecticDiffusion(hamiltonians, int(dimension), int(shape[0]))


def stochastic_midpoint_step(
    system: SymplecticDiffusion,
    z,
    increments,
    *,
    tolerance: float = _DEFAULT_TOLERANCE,
    max_iterations: int = _DEFAULT_MAX_ITERATIONS,
):
    """One implicit-midpoint step ``z' = z + J∇𝓗((z + z')/2)``; returns ``(z', converged)``.

    Fixed-point iteration from the explicit Euler predictor, until the update is at most
    ``tolerance · (1 + max|z|)``. Forward-mode derivatives (``jax.jacfwd``) go through the
    iteration; its tangents contract at the same rate, so ``Dφ`` is accurate to about the same
    tolerance. ``converged`` is ``False`` when ``max_iterations`` was reached (reduce the step
    or truncate the increments).
    """
    scale = 1.0 + jnp.max(jnp.abs(z))

    def update(z_new):
        return z + system.vector_field(0.5 * (z + z_new), increments)

    def body(carry):
        z_new, _, iteration = carry
        z_next = update(z_new)
        return z_next, jnp.max(jnp.abs(z_next - z_new)), iteration + 1

    def keep_going(carry):
        _, change, iteration = carry
        return (change > tolerance * scale) & (iteration < max_iterations)

    start = (z + system.vector_field(z, increments), jnp.asarray(jnp.inf, z.dtype), 0)
    z_new, change, _ = jax.lax.while_loop(keep_going, body, start)
    return z_new, change <= tolerance * scale


def stochastic_heun_step(system: SymplecticDiffusion, z, increments):
    """Explicit Stratonovich Heun ``z + ½(F(z) + F(z + F(z)))``, ``F = J∇𝓗``
    (:func:`liesample.dynamics.sde.heun_step`): not symplectic."""
    return heun_step(lambda x: system.vector_field(x, increments), z)


SCHEMES = Schemes(
    "a symplectic diffusion's phase space",
    {"midpoint": "midpoint", "heun": "heun"},
    {
        "midpoint": "implicit stochastic midpoint: symplectic, solved by fixed-point iteration",
        "heun": "explicit Stratonovich Heun: not symplectic",
    },
    parameter="scheme",
)
"""The schemes of :func:`symplectic_path` (:class:`liesample.foundation.schemes.Schemes`)."""


class SymplecticPath(NamedTuple):
    """``states`` of shape ``(num_steps + 1, 2n)`` (start first); ``converged``: every implicit
    solve met its tolerance (always ``True`` for Heun)."""

    states: jax.Array
    converged: jax.Array


def symplectic_path(system: SymplecticDiffusion, initial_state, increments, *, scheme="midpoint"):
    """Integrate along given increments ``ΔS`` of shape ``(num_steps, m + 1)`` (column 0 is ``Δt``).

    Pure and jittable; the increments are explicit so that one Brownian path can be replayed at
    several resolutions (:func:`coarsen_increments`).
    """
    scheme = SCHEMES.lookup(scheme)
    if jnp.shape(initial_state) != (2 * system.dimension,):
        raise ValueError(
            f"initial_state must have shape ({2 * system.dimension},), "
            f"got {jnp.shape(initial_state)}"
        )
    if jnp.ndim(increments) != 2 or jnp.shape(increments)[1] != system.num_drivers:
        raise ValueError(
            f"increments must have shape (num_steps, {system.num_drivers}) (dt first), "
            f"got {jnp.shape(increments)}"
        )

    def one(carry, increment):
        z, converged = carry
        if scheme == "midpoint":
            z, ok = stochastic_midpoint_step(system, z, increment)
            converged = converged & ok
        else:
            z = stochastic_heun_step(system, z, increment)
        return (z, converged), z

    z0 = jnp.asarray(initial_state)
    (_, converged), states = jax.lax.scan(one, (z0, jnp.array(True)), increments)
    return SymplecticPath(jnp.concatenate([z0[None], states]), converged)


def brownian_increments(
    rng_key, step_size, num_steps: int, num_noises: int, *, truncate: bool = False
):
    """``ΔS`` of shape ``(num_steps, 1 + num_noises)``: ``Δt`` then ``ΔW^i ~ N(0, Δt)``.

    With ``truncate``, ``ΔW`` is clipped to ``±√(4 Δt |ln Δt|)`` (MRT 2002, ``k = 2``), which
    bounds the implicit solve for nonlinear noise and keeps the mean-square order.
    """
    noise = jnp.sqrt(step_size) * jax.random.normal(rng_key, (num_steps, num_noises))
    if truncate:
        bound = jnp.sqrt(4.0 * step_size * jnp.abs(jnp.log(step_size)))
        noise = jnp.clip(noise, -bound, bound)
    time = jnp.full((num_steps, 1), step_size, dtype=noise.dtype)
    return jnp.concatenate([time, noise], axis=1)


def coarsen_increments(increments, factor: int):
    """Sum consecutive blocks of ``factor`` increments: the same path at step ``factor · Δt``."""
    num_steps, width = jnp.shape(increments)
    if num_steps % factor:
        raise ValueError(
            f"the number of increments ({num_steps}) must be a multiple of factor ({factor})"
        )
    return jnp.sum(jnp.reshape(increments, (num_steps // factor, factor, width)), axis=1)


def symplectic_form(dimension: int) -> np.ndarray:
    """``Ω = [[0, I], [−I, 0]]`` on ``T*R^dimension``."""
    identity = np.eye(dimension)
    zero = np.zeros((dimension, dimension))
    return np.block([[zero, identity], [-identity, zero]])


def symplecticity_defect(step_map: Callable, z, dimension: int):
    """``max |Dφᵀ Ω Dφ − Ω|`` for a one-step map ``z ↦ φ(z)`` (``jax.jacfwd``); 0 iff symplectic."""
    jacobian = jax.jacfwd(step_map)(z)
    omega = jnp.asarray(symplectic_form(dimension), dtype=jacobian.dtype)
    return jnp.max(jnp.abs(jacobian.T @ omega @ jacobian - omega))
