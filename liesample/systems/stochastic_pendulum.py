"""The stochastic pendulum on ``T*R``: a symplectic diffusion with two non-commuting noises."""

from __future__ import annotations

import jax.numpy as jnp

from liesample.dynamics.symplectic import SymplecticDiffusion, symplectic_diffusion
from liesample.foundation.validation import finite_float

__all__ = ["stochastic_pendulum"]


def stochastic_pendulum(
    noise_position: float = 0.5, noise_momentum: float = 0.3, quadratic_momentum_noise: bool = False
) -> SymplecticDiffusion:
    """The stochastic pendulum: ``H_0 = p²/2 − cos q``, ``H_1 = σ₁ cos q``, ``H_2 = σ₂ p``.

    ``H_1`` kicks the momentum (``dp ∋ σ₁ sin q ∘ dW¹``, multiplicative); ``H_2`` moves the
    position (``dq ∋ σ₂ ∘ dW²``), or, with ``quadratic_momentum_noise``, ``H_2 = σ₂ p²/2``
    (``dq ∋ σ₂ p ∘ dW²``, a random time change of the free motion). The two noises do not
    commute (``{H_1, H_2} ≠ 0``), so the midpoint rule has strong order 1/2 here.

    Examples
    --------
    One path along given Brownian increments (``liesample.symplectic``):

    >>> from liesample import symplectic
    >>> from liesample.systems import stochastic_pendulum
    >>> pendulum = stochastic_pendulum()
    >>> increments = symplectic.brownian_increments(jax.random.key(0), 0.01, 10, 2)
    >>> symplectic.symplectic_path(pendulum, jnp.array([0.0, 1.0]), increments).states.shape
    (11, 2)
    """
    sigma_1 = finite_float("noise_position", noise_position)
    sigma_2 = finite_float("noise_momentum", noise_momentum)
    if not isinstance(quadratic_momentum_noise, bool):
        raise TypeError(
            f"quadratic_momentum_noise must be a bool, got {quadratic_momentum_noise!r}"
        )

    def hamiltonians(z):
        q, p = z[0], z[1]
        momentum_noise = 0.5 * p * p if quadratic_momentum_noise else p
        return jnp.stack([0.5 * p * p - jnp.cos(q), sigma_1 * jnp.cos(q), sigma_2 * momentum_noise])

    return symplectic_diffusion(hamiltonians, 1)
