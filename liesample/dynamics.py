"""The Poisson–Langevin SDE on a dual Lie algebra, assembled from declared effects.

MATH.md §1 (paper, ``eq:poisson-langevin-eq`` and ``eq:stoch-diss-lie-poisson``): with unit-strength
noise Hamiltonians ``ĥ_i``, noise strength ``σ`` and dissipation strength ``θ``,

    dμ = X_h dt  −  θ Σ_i {h, ĥ_i} X_{ĥ_i} dt  +  σ Σ_i X_{ĥ_i} ∘ dW_i          (Stratonovich)

and ``exp(−βh)`` is invariant on every coadjoint orbit when ``θ = βσ²/2``. The dissipation is
*derived* from the same ``ĥ_i`` and bracket as the noise; no system writes it by hand.

On ``g*`` each term is ``ad*_ζ μ`` (MATH.md §2), so the dynamics hands integrators a single
generator ``ζ ∈ g`` for a step ``(dt, dW)``:

    ζ = ∇h dt  −  θ Σ_i {h, ĥ_i} ∇ĥ_i dt  +  σ Σ_i ∇ĥ_i dW_i .

Which terms exist is a :class:`Scene`, fixed at build time: a disabled effect is never traced
and draws no random numbers (it is *not* a zero coefficient).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from liesample.systems.base import LiePoissonSystem


@dataclass(frozen=True)
class Scene:
    """Which effects of the Poisson–Langevin SDE a simulation computes.

    Parameters
    ----------
    hamiltonian : bool
        The Hamiltonian drift ``X_h``.
    dissipation : bool
        The derived dissipation ``−θ Σ {h, ĥ_i} X_{ĥ_i}``.
    noise : bool
        The Stratonovich noise ``σ Σ X_{ĥ_i} ∘ dW_i``.
    """

    hamiltonian: bool = True
    dissipation: bool = True
    noise: bool = True

    def __post_init__(self):
        for name in ("hamiltonian", "dissipation", "noise"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"Scene.{name} must be a bool, got {getattr(self, name)!r}")
        if not (self.hamiltonian or self.dissipation or self.noise):
            raise ValueError(
                "Scene has no effect enabled: enable hamiltonian, dissipation or noise"
            )

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the enabled effects, in a fixed order."""
        return tuple(n for n in ("hamiltonian", "dissipation", "noise") if getattr(self, n))


@dataclass(frozen=True)
class PoissonLangevin:
    """The Poisson–Langevin dynamics of a Lie–Poisson system, restricted to a scene.

    Parameters
    ----------
    system : LiePoissonSystem
        Declares the algebra, ``h`` and the unit-strength noise Hamiltonians ``ĥ_i``.
    sigma : float
        Noise strength ``σ`` (noise Hamiltonians are ``σ ĥ_i``).
    theta : float
        Dissipation strength ``θ``; Gibbs-exact for ``exp(−βh)`` when ``θ = βσ²/2``.
    scene : Scene
        The effects that exist.
    """

    system: LiePoissonSystem
    sigma: float
    theta: float
    scene: Scene

    @property
    def algebra(self):
        return self.system.algebra

    @property
    def num_noises(self) -> int:
        return self.system.num_noises

    def noise_gradients(self, mu):
        """``∇ĥ_i(μ)`` for every unit-strength noise Hamiltonian, shape ``(m, *μ.shape)``."""
        return jax.jacrev(self.system.noise_hamiltonians)(mu)

    def brackets_with_noise(self, mu, grad_h, noise_grads):
        """``{h, ĥ_i}(μ) = ⟨∇h, ad*_{∇ĥ_i} μ⟩`` for every ``i``, shape ``(m,)``."""
        ad_star = self.algebra.ad_star
        return jax.vmap(lambda g: self.algebra.pairing(grad_h, ad_star(g, mu)))(noise_grads)

    def generator(self, mu, dt, dW=None):
        """The generator ``ζ ∈ g`` of one step of length ``dt`` with Brownian increments ``dW``.

        Only the scene's effects are traced. ``dW`` (shape ``(m,)``) is required exactly when
        the scene has noise.
        """
        scene = self.scene
        if scene.noise != (dW is not None):
            raise ValueError("dW must be given exactly when the scene has noise")
        need_h = scene.hamiltonian or scene.dissipation
        grad_h = jax.grad(self.system.hamiltonian)(mu) if need_h else None
        noise_grads = self.noise_gradients(mu) if (scene.noise or scene.dissipation) else None
        zeta = jnp.zeros_like(mu)
        if scene.hamiltonian:
            zeta = zeta + grad_h * dt
        if scene.dissipation:
            rates = self.brackets_with_noise(mu, grad_h, noise_grads)
            zeta = zeta - (self.theta * dt) * jnp.tensordot(rates, noise_grads, axes=1)
        if scene.noise:
            zeta = zeta + self.sigma * jnp.tensordot(dW, noise_grads, axes=1)
        return zeta

    def direction_generator(self, mu, index, dt, dW_index=None):
        """The generator of noise direction ``index`` alone: ``(−θ {h, ĥ_i} dt + σ dW_i) ∇ĥ_i``.

        Along one direction the SDE is a one-dimensional Langevin equation with additive noise
        in the group coordinate ``φ`` of ``exp(φ ∇ĥ_i)`` (MATH.md §1: each direction leaves
        ``exp(−βh)`` invariant on its own), which is what the splitting integrator exploits.
        """
        scene = self.scene
        if scene.noise != (dW_index is not None):
            raise ValueError("dW_index must be given exactly when the scene has noise")
        grad_i = jax.grad(lambda m: self.system.noise_hamiltonians(m)[index])(mu)
        coefficient = jnp.zeros((), mu.dtype)
        if scene.dissipation:
            grad_h = jax.grad(self.system.hamiltonian)(mu)
            rate = self.algebra.pairing(grad_h, self.algebra.ad_star(grad_i, mu))
            coefficient = coefficient - self.theta * rate * dt
        if scene.noise:
            coefficient = coefficient + self.sigma * dW_index
        return coefficient * grad_i

    def vector_field(self, mu, dt, dW=None):
        """The ambient increment ``ad*_ζ μ`` (what a non-geometric integrator adds to ``μ``)."""
        return self.algebra.ad_star(self.generator(mu, dt, dW), mu)

    def brownian_increments(self, rng_key, dt, dtype):
        """``dW ~ N(0, dt I_m)`` when the scene has noise, else ``None`` (no draw at all)."""
        if not self.scene.noise:
            return None
        return jnp.sqrt(dt) * jax.random.normal(rng_key, (self.num_noises,), dtype=dtype)
