"""Template for a new orbit integrator: copy to ``liesample/integrators/<your_scheme>.py``.

An integrator is a one-step map ``(dynamics, μ, dt, dW) ↦ μ'`` wrapped in an
:class:`liesample.integrators.orbit.Integrator` that *declares* what it guarantees; samplers,
the stability check (:mod:`liesample.integrators.stability`) and the bias model
(:mod:`liesample.integrators.accuracy`) read those declarations, never the scheme's name.

- ``dynamics`` is a :class:`liesample.dynamics.PoissonLangevin`; ``dynamics.generator(μ, dt,
  dW)`` is the step's generator ``ζ ∈ g`` (Hamiltonian drift, derived dissipation and noise
  together) and ``dynamics.algebra.coadjoint_exp(ζ, μ)`` the orbit-preserving move
  ``Ad*_{exp ζ} μ``. A scheme that moves only by ``coadjoint_exp`` keeps Casimirs to round-off.
- ``dW`` holds the Brownian increments of the step (shape ``(m,)``), or ``None`` when the
  scene has no noise. Every stage must use the *same* ``dW``: that is what makes an explicit
  two-stage scheme consistent with the Stratonovich reading (paper, ``eq:poisson-langevin-eq``).

The working example is the explicit midpoint rule on the group,

    μ̃ = Ad*_{exp(ζ(μ)/2)} μ,        μ' = Ad*_{exp ζ(μ̃)} μ,

a Runge–Kutta–Munthe-Kaas scheme of weak order 1 under non-commuting noise; on ``y' = −λy`` its
amplification factor is ``1 − z + z²/2`` (``z = λ dt``), so its stability limit is ``κ ≤ 2``.

Use it by passing the object: ``liesample.lie_poisson_langevin(system, ...,
integrator=group_midpoint)``. To make it selectable by name, add it to
``liesample.integrators.orbit.INTEGRATORS``. Imports may point to ``foundation``,
``geometry``, ``dynamics`` and this layer only.
"""

from __future__ import annotations

from liesample.integrators.orbit import Integrator

__all__ = ["group_midpoint"]


def _group_midpoint_step(dynamics, mu, dt, dW):
    """``Ad*_{exp ζ(μ̃)} μ`` with the half-step predictor ``μ̃ = Ad*_{exp(ζ(μ)/2)} μ``."""
    move = dynamics.algebra.coadjoint_exp
    halfway = move(0.5 * dynamics.generator(mu, dt, dW), mu)
    return move(dynamics.generator(halfway, dt, dW), mu)


group_midpoint = Integrator(
    name="group_midpoint",
    weak_order=1,
    preserves_orbit=True,
    step=_group_midpoint_step,
    description="explicit midpoint on the group (RKMK2), same increments in both stages",
    stability_limit=2.0,
)
