"""Template for a new parameter space: copy to ``liesample/geometry/<your_space>.py``.

A space is one block of a position for the samplers on ``T*G``
(:mod:`liesample.samplers.cotangent`): ``shape`` independent copies of a manifold, with the
exact flow of the kinetic energy that the leapfrog's drift uses. Subclass
:class:`liesample.geometry.spaces.Space` and provide

- ``point_shape``, ``momentum_shape``, ``mass_shape`` (one copy each) and ``copy_dimension``;
- ``constraint_error(x)`` (NumPy, concrete): how far ``x`` is off the manifold; ``check`` turns
  it into a clear error, never a silent projection;
- ``uniform(key)`` (the Haar or uniform law; raise where there is none);
- ``perturb(x, ε)``: a curve through ``x`` with velocity ``ε``; the samplers differentiate
  ``ε ↦ log π(perturb(x, ε))`` at ``0`` to get the trivialised gradient;
- ``flow(x, p, inverse_mass, t)``: the *exact* flow of ``½ m⁻¹|p|²`` over time ``t``;
- ``log(x, y)`` where it is cheap (``exp`` comes from ``flow``).

The working example is the multiplicative group ``(R_{>0}, ×)``: points ``x > 0``, algebra
``R``, exponential ``x ↦ x e^ε``, Haar measure ``dx/x``. The kinetic flow is
``x ← x exp(t m⁻¹ p)`` with ``p`` constant (the group is abelian), so a log-density with
respect to ``dx/x`` is sampled on ``x > 0`` without a change of variables in user code.

A space is then used like the built-in ones, ``geometric_hmc(logdensity_fn,
PositiveReals((3,)), ...)``, in products (dicts and tuples of spaces) too. Imports may point
to ``foundation`` and this layer only.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.geometry.spaces import Space

__all__ = ["PositiveReals"]


@dataclasses.dataclass(frozen=True)
class PositiveReals(Space):
    """``(R_{>0})^shape`` as a multiplicative group, with Haar measure ``dx/x`` per copy."""

    shape: tuple[int, ...] = ()
    compact = False
    _off_manifold_hint = "Every entry must be > 0."

    def __post_init__(self):
        shape = (self.shape,) if isinstance(self.shape, int) else tuple(self.shape)
        if not all(isinstance(n, int) and n >= 0 for n in shape):
            raise ValueError(f"PositiveReals shape must be a tuple of ints >= 0, got {shape!r}")
        object.__setattr__(self, "shape", shape)

    def constraint_error(self, x: ArrayLike) -> float:
        return float("inf") if np.any(np.asarray(x) <= 0.0) else 0.0

    def uniform(self, rng_key: jax.Array, dtype: DTypeLike | None = None) -> jax.Array:
        raise ValueError("PositiveReals has no uniform probability law; give the start explicitly")

    def perturb(self, x: jax.Array, eps: jax.Array) -> jax.Array:
        return x * jnp.exp(eps)

    def flow(
        self, x: jax.Array, p: jax.Array, inverse_mass: jax.Array, t: ArrayLike
    ) -> tuple[jax.Array, jax.Array]:
        return x * jnp.exp(t * inverse_mass * p), p

    def log(self, x: jax.Array, y: jax.Array) -> jax.Array:
        return jnp.log(y / x)
