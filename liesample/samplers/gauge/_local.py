"""Exact draws from the conditional law of one link in its frozen staple, vectorised over links.

- U(1): ``θ ∝ exp(κ cos(θ − θ₀))``, a von Mises draw (Best & Fisher 1979, rejection from a
  wrapped Cauchy law).
- SU(2): ``W ∝ exp(α ½ tr W)`` under Haar measure: ``a₀ = ½ tr W`` has density
  ``∝ √(1 − a₀²) e^{α a₀}`` on ``[−1, 1]`` (Creutz 1980 for ``α < 2``, Kennedy & Pendleton 1985
  above, both exact rejection samplers), the rest of the quaternion uniform on the sphere of
  radius ``√(1 − a₀²)``.

Every sampler here loops until every site has accepted (``lax.while_loop``), each site drawing
its own proposals, so the draws are exact whatever the acceptance rate. The sites are drawn as
one flat axis: XLA compiles random draws of a many-axis shape inside such a loop into machine
code whose size grows with the lattice (seconds to minutes of compilation); the flat draws are
the same numbers in the same order (JAX's partitionable Threefry counts in row-major order).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["quaternion_part", "su2_from_a0", "su2_heat_bath_a0", "von_mises"]

CREUTZ_BELOW = 2.0  # α below which Creutz's sampler is used (KP's acceptance falls at small α)


def _flat(draw):
    """``draw(rng_key, parameter)`` on the parameter's sites as one flat axis, reshaped back."""

    def flat_draw(rng_key, parameter):
        return draw(rng_key, parameter.reshape(-1)).reshape(parameter.shape)

    return flat_draw


def _until_accepted(rng_key, shape, dtype, propose):
    """Draw ``propose(key) -> (candidate, accepted)`` until every site has accepted once."""

    def body(carry):
        key, done, out = carry
        key, sub = jax.random.split(key)
        candidate, accepted = propose(sub)
        take = accepted & ~done
        return key, done | accepted, jnp.where(take, candidate, out)

    def cond(carry):
        return ~jnp.all(carry[1])

    start = (rng_key, jnp.zeros(shape, bool), jnp.zeros(shape, dtype))
    return jax.lax.while_loop(cond, body, start)[2]


def _unit(key, shape, dtype):
    """Uniform on ``(0, 1]`` (safe under ``log``)."""
    return 1.0 - jax.random.uniform(key, shape, dtype)


def _units(key, count, shape, dtype):
    """``_unit`` of each of ``split(key, count)``, drawn by one ``vmap`` over the keys: the
    same numbers as ``count`` separate draws, with one random-bits computation to compile."""
    keys = jax.random.split(key, count)
    return jax.vmap(lambda sub: _unit(sub, shape, dtype))(keys)


@_flat
def von_mises(rng_key, kappa):
    """Angles ``φ ∈ (−π, π]`` with density ``∝ exp(κ cos φ)`` (``κ ≥ 0``; ``κ = 0``: uniform)."""
    dtype = kappa.dtype
    k = jnp.maximum(kappa, 1e-30)
    root = jnp.sqrt(1.0 + 4.0 * k**2)
    tau = 1.0 + root
    rho = 2.0 * k * tau / ((root + 1.0) * (tau + jnp.sqrt(2.0 * tau)))  # (τ − √2τ)/2κ, stably
    r = (1.0 + rho**2) / (2.0 * rho)

    def propose(key):
        u1, u2, u3 = _units(key, 3, kappa.shape, dtype)
        z = jnp.cos(jnp.pi * u1)
        f = (1.0 + r * z) / (r + z)
        c = k * (r - f)
        accepted = (c * (2.0 - c) - u2 > 0) | (jnp.log(c / u2) + 1.0 - c >= 0)
        angle = jnp.sign(u3 - 0.5) * jnp.arccos(jnp.clip(f, -1.0, 1.0))
        return angle, accepted

    return _until_accepted(rng_key, kappa.shape, dtype, propose)


@_flat
def su2_heat_bath_a0(rng_key, alpha):
    """``a₀ ∈ [−1, 1]`` with density ``∝ √(1 − a₀²) e^{α a₀}`` (``α ≥ 0``)."""
    dtype = alpha.dtype
    a = jnp.maximum(alpha, 1e-12)

    def propose(key):
        x1, x2, x3, x4 = _units(key, 4, alpha.shape, dtype)
        # Kennedy–Pendleton: X = 1 − a₀ from a Gamma(3/2)-like draw, accepted with √(1 − X/2)
        big_x = -(jnp.log(x1) + jnp.cos(2.0 * jnp.pi * x2) ** 2 * jnp.log(x3)) / a
        kp = (x4**2 <= 1.0 - 0.5 * big_x, 1.0 - big_x)
        # Creutz: a₀ from e^{α a₀} on [−1, 1], accepted with √(1 − a₀²)
        a0 = 1.0 + jnp.log1p(-(1.0 - x1) * -jnp.expm1(-2.0 * a)) / a
        creutz = (x4**2 <= 1.0 - a0**2, a0)
        use_kp = a >= CREUTZ_BELOW
        return jnp.where(use_kp, kp[1], creutz[1]), jnp.where(use_kp, kp[0], creutz[0])

    return _until_accepted(rng_key, alpha.shape, dtype, propose)


def su2_from_a0(rng_key, a0, complex_dtype):
    """The SU(2) matrix ``a₀ I + i a⃗·σ⃗`` with ``|a⃗| = √(1 − a₀²)`` in a uniform direction."""
    n = jax.random.normal(rng_key, (a0.size, 3), a0.dtype).reshape(*a0.shape, 3)  # flat: _flat
    n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
    a = jnp.sqrt(jnp.clip(1.0 - a0**2, 0.0, None))[..., None] * n
    return quaternion(a0, a[..., 0], a[..., 1], a[..., 2]).astype(complex_dtype)


def quaternion(a0, a1, a2, a3):
    """``a₀ I + i(a₁σ₁ + a₂σ₂ + a₃σ₃)`` as 2×2 complex matrices."""
    row0 = jnp.stack([a0 + 1j * a3, a2 + 1j * a1], -1)
    row1 = jnp.stack([-a2 + 1j * a1, a0 - 1j * a3], -1)
    return jnp.stack([row0, row1], -2)


def quaternion_part(r):
    """``(k, V)``: the part ``k V`` (``k ≥ 0``, ``V ∈ SU(2)``) of a complex 2×2 ``r`` that
    ``Re tr(s r)`` sees for ``s ∈ SU(2)`` (``V = I`` where ``k = 0``)."""
    a = 0.5 * (r[..., 0, 0] + jnp.conj(r[..., 1, 1]))
    b = 0.5 * (r[..., 0, 1] - jnp.conj(r[..., 1, 0]))
    k = jnp.sqrt(jnp.abs(a) ** 2 + jnp.abs(b) ** 2)
    safe = jnp.where(k > 0, k, 1.0)
    a, b = jnp.where(k > 0, a / safe, 1.0), jnp.where(k > 0, b / safe, 0.0)
    v = jnp.stack([jnp.stack([a, b], -1), jnp.stack([-jnp.conj(b), jnp.conj(a)], -1)], -2)
    return k, v
