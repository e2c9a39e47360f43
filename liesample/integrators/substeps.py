"""Adaptive substepping: an :class:`~liesample.integrators.Integrator` built from another one.

A step of length ``dt`` is cut into substeps whose length follows the state: each substep is

    h = min(remaining, safety / rate(dynamics, μ)),

where ``rate`` (1/time) is a system-supplied bound on how fast the drift turns the state near
``μ`` (for point vortices, the fastest pair rotation ``(|Γ_j| + |Γ_k|)/(2π d_jk²)``; see
:func:`liesample.systems.point_vortices.collision_rate`). The base integrator advances each
substep with the Brownian increments scaled in proportion, ``dW · h/dt``: this integrates the
step's piecewise-linear (Wong–Zakai) noise path more finely, which converges to the
Stratonovich SDE (paper, ``eq:poisson-langevin-eq``) as ``dt → 0`` like the base scheme, while the
stiff drift is resolved at the scale ``safety/rate``. Every substep is a coadjoint move of the base
integrator, so an orbit-preserving base stays on the orbit to round-off.

A state far from stiffness costs one substep (one ``rate`` evaluation extra). A step that would
need more than ``max_substeps`` takes the rest of its time in its last substep: the clock is
never slowed (a step always advances by ``dt``, drift and noise alike), and only that last
substep is longer than the rule allows; :func:`substep` reports it (``resolved = False``).
Dropping the rest of the time instead would slow the clock where the rate is large, and a
process slowed by a factor ``s(μ)`` samples ``∝ exp(−βh)/s(μ)``: for point vortices at ``β < 0``,
a law that piles up at collisions. The unresolved part is confined to states whose rate exceeds
``max_substeps·safety/dt``, a region that shrinks as ``dt → 0``.

**Batched chains.** Under ``jax.vmap`` the substep loop runs until the slowest chain is done (every
chain is computed at every substep and masked), so a batch of chains costs the largest number
of substeps among them: at most ``max_substeps`` base steps per chain and step, the bound the
cap gives.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from liesample.foundation.validation import finite_float
from liesample.integrators.orbit import Integrator, get_integrator

__all__ = ["adaptive_substepping", "substep"]


def substep(base, rate_fn: Callable, dynamics, mu, dt, dW=None, *, safety=0.1, max_substeps=256):
    """One adaptive step; returns ``(μ', number_of_substeps, resolved)``.

    ``resolved`` is ``False`` when the step reached ``max_substeps`` and its last substep took
    the rest of the step, longer than ``safety/rate`` (module docstring).

    Parameters
    ----------
    base : Integrator
        Advances each substep.
    rate_fn : callable
        ``(dynamics, μ) ↦`` a non-negative scalar rate (1/time); 0 means no constraint.
    safety : float
        Substep length in units of ``1/rate``.
    max_substeps : int
        Upper bound on substeps per step; the last one takes the rest of the step.
    """
    dt = jnp.asarray(dt, dtype=mu.dtype)

    def cond(carry):
        remaining, count, _, _ = carry
        return (remaining > 0) & (count < max_substeps)

    def body(carry):
        remaining, count, position, resolved = carry
        rate = rate_fn(dynamics, position)
        limit = jnp.where(rate > 0, safety / jnp.where(rate > 0, rate, 1.0), remaining)
        last = count >= max_substeps - 1
        h = jnp.where(last, remaining, jnp.minimum(remaining, limit))
        resolved = resolved & (h <= limit)
        increments = None if dW is None else dW * (h / dt)
        position = base(dynamics, position, h, increments)
        remaining = jnp.where(h >= remaining, jnp.zeros_like(remaining), remaining - h)
        return remaining, count + 1, position, resolved

    start = (dt, jnp.int32(0), mu, jnp.ones((), bool))
    _, count, mu, resolved = jax.lax.while_loop(cond, body, start)
    return mu, count, resolved


def adaptive_substepping(
    base, rate_fn: Callable, *, safety: float = 0.1, max_substeps: int = 256, name=None
) -> Integrator:
    """An :class:`Integrator` that runs ``base`` on adaptive substeps (module docstring).

    Pass it as ``integrator=`` to :func:`liesample.lie_poisson_langevin`. Its weak order and
    orbit preservation (every declaration) are those of ``base``.
    """
    base = get_integrator(base)
    safety = finite_float("safety", safety, positive=True)
    if isinstance(max_substeps, bool) or not isinstance(max_substeps, int) or max_substeps < 1:
        raise ValueError(f"max_substeps must be an int >= 1, got {max_substeps!r}")
    if not callable(rate_fn):
        raise TypeError(f"rate_fn must be a callable (dynamics, mu) -> rate, got {rate_fn!r}")

    def step(dynamics, mu, dt, dW=None):
        return substep(
            base, rate_fn, dynamics, mu, dt, dW, safety=safety, max_substeps=max_substeps
        )[0]

    return base.wrapping(
        step,
        name or f"{base.name}+substeps",
        f"{base.name} on adaptive substeps h = min(remaining, {safety:g}/rate(μ)), "
        f"at most {max_substeps} per step",
    )
