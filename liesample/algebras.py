"""Lie algebras and their coadjoint actions: the pure mathematics under every system.

Conventions (MATH.md §2): the (−) Lie–Poisson bracket ``{f, g}(μ) = −⟨μ, [∇f, ∇g]⟩`` and
``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩``, so that ``X_f(μ) = ad*_{∇f(μ)} μ`` and the Lie–Poisson
equation is ``μ̇ = ad*_{∇h} μ`` (paper, ``eq:lie-poisson``).

Every drift, dissipation and noise term on ``g*`` is a coadjoint action ``ad*_ζ μ`` for a
generator ``ζ ∈ g``; an integrator that moves by ``coadjoint_exp(ζ, μ) = Ad*_{exp ζ} μ`` stays
on the coadjoint orbit, so Casimirs are preserved to round-off by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp


@dataclass(frozen=True)
class LieAlgebra:
    """Interface of a Lie algebra ``g`` acting on its dual ``g*``.

    Elements of ``g`` and ``g*`` are arrays of the same shape, paired by the sum of the
    elementwise product. Subclasses provide ``bracket``, ``ad_star``, ``coadjoint_exp`` and
    ``casimirs``; all of them broadcast over leading axes where the algebra says so.
    """

    name: str = "g"

    def pairing(self, mu, xi):
        """``⟨μ, ξ⟩``: the duality pairing, summed over every axis of the element."""
        return jnp.sum(mu * xi)

    def bracket(self, xi, eta):  # pragma: no cover - interface
        raise NotImplementedError

    def ad_star(self, xi, mu):  # pragma: no cover - interface
        raise NotImplementedError

    def coadjoint_exp(self, zeta, mu):  # pragma: no cover - interface
        raise NotImplementedError

    def casimirs(self, mu):  # pragma: no cover - interface
        raise NotImplementedError


# Below this θ² the Taylor series (to θ⁴) is exact in float64 and smooth for autodiff.
_SMALL_ANGLE_SQ = 1e-6


def _rodrigues_coefficients(theta_sq):
    """``sin θ / θ`` and ``(1 − cos θ)/θ²`` as smooth functions of ``θ²`` (derivatives included).

    The double ``where`` keeps ``sqrt`` away from 0, so gradients at ``ζ = 0`` are finite.
    """
    small = theta_sq < _SMALL_ANGLE_SQ
    safe_sq = jnp.where(small, 1.0, theta_sq)
    theta = jnp.sqrt(safe_sq)
    sin_over_theta = jnp.where(
        small, 1.0 - theta_sq / 6.0 + theta_sq**2 / 120.0, jnp.sin(theta) / theta
    )
    one_minus_cos = jnp.where(
        small,
        0.5 - theta_sq / 24.0 + theta_sq**2 / 720.0,
        2.0 * jnp.sin(0.5 * theta) ** 2 / safe_sq,
    )
    return sin_over_theta, one_minus_cos


@dataclass(frozen=True)
class SO3(LieAlgebra):
    """so(3) ≅ (R³, ×), and its dual, in closed form.

    Arrays of shape ``(..., 3)`` are stacks of independent copies: a state of shape
    ``(N, 3)`` lives on the product ``(so(3)*)^N`` and the operations act copy by copy,
    vectorised. The Casimirs are the squared norms ``|μ_k|²`` of the copies.
    """

    name: str = "so(3)"

    def bracket(self, xi, eta):
        """``[ξ, η] = ξ × η``."""
        return jnp.cross(xi, eta)

    def ad_star(self, xi, mu):
        """``ad*_ξ μ = μ × ξ``, from ``⟨μ, ξ × η⟩ = ⟨μ × ξ, η⟩``."""
        return jnp.cross(mu, xi)

    def coadjoint_exp(self, zeta, mu):
        """``Ad*_{exp ζ} μ``: the time-one flow of ``μ̇ = μ × ζ``.

        That flow is the rotation by angle ``|ζ|`` about the axis ``−ζ/|ζ|`` (Rodrigues):
        ``μ + (sin θ/θ) μ×ζ + ((1 − cos θ)/θ²) ζ×(ζ×μ)`` with ``θ = |ζ|``; norm-preserving to
        round-off, and smooth (derivatives included) at ``ζ = 0``.
        """
        theta_sq = jnp.sum(zeta * zeta, axis=-1, keepdims=True)
        sin_over_theta, one_minus_cos_over_theta_sq = _rodrigues_coefficients(theta_sq)
        zeta_cross_mu = jnp.cross(zeta, mu)
        return (
            mu
            - sin_over_theta * zeta_cross_mu
            + one_minus_cos_over_theta_sq * jnp.cross(zeta, zeta_cross_mu)
        )

    def casimirs(self, mu):
        """``|μ_k|²`` for each copy (shape ``mu.shape[:-1]``)."""
        return jnp.sum(mu * mu, axis=-1)


so3 = SO3()
