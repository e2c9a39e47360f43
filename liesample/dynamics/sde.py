"""The Poisson–Langevin SDE written for any Poisson structure (paper, ``eq:poisson-langevin-eq``).

``PoissonLangevinSDE`` assembles the step ``J(z) ζ`` from a structure of
:mod:`liesample.geometry.poisson`; :class:`liesample.dynamics.PoissonLangevin` is its
Lie–Poisson face.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import jax
import jax.numpy as jnp

from liesample.geometry.poisson import PoissonStructure


class Effects(Protocol):
    """What :class:`PoissonLangevinSDE` reads of its ``scene``: which effects exist."""

    @property
    def hamiltonian(self) -> bool: ...
    @property
    def dissipation(self) -> bool: ...
    @property
    def noise(self) -> bool: ...


@dataclass(frozen=True, eq=False)
class PoissonLangevinSDE:
    """The Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``) on a
    :class:`PoissonStructure`.

    Parameters
    ----------
    structure : PoissonStructure
        Provides ``apply(z, ζ) = J(z) ζ``.
    hamiltonian : callable
        ``z ↦ h(z)``.
    noise_hamiltonians : callable
        ``z ↦ (ĥ_1(z), …, ĥ_m(z))``, unit strength; the dissipation is derived from them.
    sigma, theta : float
        Noise and dissipation strengths (``θ = βσ²/2`` leaves ``exp(−βh)`` invariant).
    scene : liesample.dynamics.Scene
        Which effects exist (any object with boolean ``hamiltonian``, ``dissipation`` and
        ``noise``); a disabled one is never traced.

    Notes
    -----
    The Lie–Poisson case ``structure = LiePoissonStructure(algebra)`` reproduces
    :class:`liesample.dynamics.PoissonLangevin`: :meth:`covector` is its ``generator``.
    """

    structure: PoissonStructure
    hamiltonian: Callable[[jax.Array], jax.Array]
    noise_hamiltonians: Callable[[jax.Array], jax.Array]
    sigma: float
    theta: float
    scene: Effects

    def brackets_with_noise(self, z, hamiltonian_field=None):
        """``{h, ĥ_i}(z) = −dĥ_i(X_h)`` for every ``i`` (one JVP; ``J`` is antisymmetric)."""
        if hamiltonian_field is None:
            hamiltonian_field = self.structure.hamiltonian_vector_field(self.hamiltonian, z)
        return -jax.jvp(self.noise_hamiltonians, (z,), (hamiltonian_field,))[1]

    def noise_coefficients(self, z, dt, dW=None, grad_h=None):
        """``c_i = −θ {h, ĥ_i} dt + σ dW_i`` (only the scene's terms); ``grad_h`` may be reused."""
        scene = self.scene
        if scene.noise != (dW is not None):
            raise ValueError("dW must be given exactly when the scene has noise")
        coefficients = 0.0
        if scene.dissipation:
            if grad_h is None:
                grad_h = jax.grad(self.hamiltonian)(z)
            brackets = self.brackets_with_noise(z, self.structure.apply(z, grad_h))
            coefficients = -(self.theta * dt) * brackets
        if scene.noise:
            coefficients = coefficients + self.sigma * dW
        return coefficients

    def covector(self, z, dt, dW=None):
        """``ζ = ∇h dt + Σ_i c_i ∇ĥ_i`` (scene's terms only); the increment is ``J(z) ζ``."""
        scene = self.scene
        need_h = scene.hamiltonian or scene.dissipation
        grad_h = jax.grad(self.hamiltonian)(z) if need_h else None  # computed once, used twice
        zeta = grad_h * dt if scene.hamiltonian else jnp.zeros_like(z)
        if scene.noise or scene.dissipation:
            coefficients = self.noise_coefficients(z, dt, dW, grad_h)
            _, pullback = jax.vjp(self.noise_hamiltonians, z)
            zeta = zeta + pullback(coefficients)[0]
        elif dW is not None:
            raise ValueError("dW must be given exactly when the scene has noise")
        return zeta

    def increment(self, z, dt, dW=None):
        """The Stratonovich increment ``J(z) ζ`` of one step ``(dt, dW)``."""
        return self.structure.apply(z, self.covector(z, dt, dW))

    def drift(self, z):
        """The drift ``X_h − θ Σ {h, ĥ_i} X_{ĥ_i}`` (scene's terms; Stratonovich, no Itô term)."""
        scene = self.scene
        if not (scene.hamiltonian or scene.dissipation):
            return jnp.zeros_like(z)
        deterministic = PoissonLangevinSDE(
            self.structure,
            self.hamiltonian,
            self.noise_hamiltonians,
            self.sigma,
            self.theta,
            _deterministic_scene(scene),
        )
        return deterministic.increment(z, 1.0)

    def dissipation(self, z):
        """The derived dissipation ``−θ Σ_i {h, ĥ_i}(z) X_{ĥ_i}(z)`` alone."""
        coefficients = -self.theta * self.brackets_with_noise(z)
        _, pullback = jax.vjp(self.noise_hamiltonians, z)
        return self.structure.apply(z, pullback(coefficients)[0])

    def noise_fields(self, z):
        """The Stratonovich diffusion matrix ``σ [X_{ĥ_1}, …, X_{ĥ_m}]``, shape ``z.shape + (m,)``
        (``(d, m)`` for vector states; matrix states keep their axes in order)."""
        gradients = jax.jacrev(self.noise_hamiltonians)(z)  # (m, *z.shape)
        fields = jax.vmap(lambda g: self.structure.apply(z, g))(gradients)
        return self.sigma * jnp.moveaxis(fields, 0, -1)


def _deterministic_scene(scene):
    return replace(scene, noise=False)


def heun_step(increment: Callable, z):
    """The explicit Stratonovich Heun step ``z + ½(F(z) + F(z + F(z)))`` for a fixed increment
    map ``F`` (one step's ``dt`` and ``dW`` already in it): weak order 1, strong order 1 for
    additive noise, consistent with the Stratonovich reading (the same ``dW`` feeds both
    stages). A baseline: it preserves neither Casimirs nor the symplectic form."""
    start = increment(z)
    return z + 0.5 * (start + increment(z + start))


def stratonovich_heun_step(sde: PoissonLangevinSDE, z, dt, dW=None):
    """One stochastic Heun step (:func:`heun_step`) of the structure-agnostic increment
    ``J(z)ζ(z)``."""
    return heun_step(lambda x: sde.increment(x, dt, dW), z)
