"""The Poisson–Langevin SDE on a dual Lie algebra, assembled from declared effects.

Paper, ``eq:poisson-langevin-eq`` and ``eq:stoch-diss-lie-poisson``: with unit-strength noise
Hamiltonians ``ĥ_i``, noise strength ``σ`` and dissipation strength ``θ``,

    dμ = X_h dt  −  θ Σ_i {h, ĥ_i} X_{ĥ_i} dt  +  σ Σ_i X_{ĥ_i} ∘ dW_i          (Stratonovich)

and ``exp(−βh)`` is invariant on every coadjoint orbit when ``θ = βσ²/2``. The dissipation is
*derived* from the same ``ĥ_i`` and bracket as the noise; no system writes it by hand.

On ``g*`` each term is ``ad*_ζ μ`` (paper, ``eq:lie-poisson``), so the dynamics hands
integrators a single generator ``ζ ∈ g`` for a step ``(dt, dW)``:

    ζ = ∇h dt  −  θ Σ_i {h, ĥ_i} ∇ĥ_i dt  +  σ Σ_i ∇ĥ_i dW_i .

Which terms exist is a :class:`Scene`, fixed at build time: a disabled effect is never traced
and draws no random numbers (it is *not* a zero coefficient).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol, cast

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike, DTypeLike

from liesample.dynamics.sde import PoissonLangevinSDE
from liesample.dynamics.system import DeclaresBeta, LiePoissonSystem, checked_beta
from liesample.foundation.types import PRNGKey
from liesample.foundation.validation import finite_float
from liesample.geometry.algebras import LieAlgebra
from liesample.geometry.poisson import LiePoissonStructure


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

    Examples
    --------
    >>> liesample.Scene(noise=False).effects  # energy descent with the Hamiltonian drift
    ('hamiltonian', 'dissipation')
    """

    hamiltonian: bool = True
    dissipation: bool = True
    noise: bool = True

    def __post_init__(self):
        kind = type(self).__name__  # subclasses add flags (every field is one)
        for item in fields(self):
            value = getattr(self, item.name)
            if not isinstance(value, bool):
                raise TypeError(f"{kind}.{item.name} must be a bool, got {value!r}")
        if not (self.hamiltonian or self.dissipation or self.noise):
            raise ValueError(
                f"{kind} has no effect enabled: enable hamiltonian, dissipation or noise"
            )

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the enabled effects, in a fixed order (the order of the fields)."""
        return tuple(item.name for item in fields(self) if getattr(self, item.name))


class _Declarations(DeclaresBeta, Protocol):
    """What :func:`make_dynamics` reads of a system: ``check_beta`` and ``check_noise``."""

    @property
    def check_noise(self) -> Callable[[], object] | None: ...


def make_dynamics(
    system: _Declarations,
    *,
    beta: float | None = None,
    sigma: float = 1.0,
    theta: float | None = None,
    hamiltonian: bool = True,
) -> tuple[float, float, Scene]:
    """Validate ``(β, σ, θ)`` and return ``(sigma, theta, scene)``.

    With noise (``σ > 0``) the dissipation is derived, ``θ = βσ²/2``, so ``β`` is required and
    ``θ`` may not be given. Without noise (``σ = 0``) there is no temperature; ``θ ≥ 0`` sets a
    pure energy-descent flow. Effects whose coefficient vanishes are left out of the scene.
    ``system`` is anything with ``check_beta`` (``None`` or ``β ↦ None``, raising where
    ``exp(−βh)`` is not normalisable) and ``check_noise`` (``None`` or ``() ↦ None``, raising
    where the noise cannot reach the orbit) attributes.
    """
    sigma = finite_float("sigma", sigma, nonnegative=True)
    if sigma > 0:
        if beta is None:
            raise ValueError(
                "beta is required when sigma > 0 (the noise samples exp(-beta*h)): pass beta=, "
                "e.g. beta=1.0, or sigma=0 (with theta >= 0) for a noise-free flow"
            )
        beta = checked_beta(system, beta)
        if system.check_noise is not None:
            system.check_noise()
        if theta is not None:
            raise ValueError(
                "theta is derived from beta and sigma (theta = beta*sigma**2/2); "
                "pass beta, not theta"
            )
        theta = finite_float("theta = beta*sigma**2/2 (reduce sigma)", 0.5 * beta * sigma * sigma)
    else:
        if beta is not None:
            raise ValueError(
                "beta needs noise: with sigma = 0 nothing is sampled; pass theta >= 0 for a "
                "noise-free dissipative flow, or sigma > 0 to sample exp(-beta*h)"
            )
        theta = finite_float("theta", 0.0 if theta is None else theta, nonnegative=True)
    if not isinstance(hamiltonian, bool):
        raise TypeError(f"hamiltonian must be a bool, got {hamiltonian!r}")
    scene = Scene(hamiltonian=hamiltonian, dissipation=theta != 0.0, noise=sigma > 0)
    return sigma, theta, scene


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

    Examples
    --------
    The generator ``ζ`` of one step of the rigid body at ``β = 3`` (``θ = βσ²/2``); moving by
    ``Ad*_{exp ζ}`` keeps the orbit:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> dynamics = liesample.PoissonLangevin(system, sigma=1.0, theta=1.5, scene=liesample.Scene())
    >>> mu = jnp.array([1.5, 0.0, 0.0])
    >>> zeta = dynamics.generator(mu, 0.01, jnp.array([0.1, 0.0, 0.2]))  # dt, dW
    >>> bool(jnp.isclose(jnp.linalg.norm(system.algebra.coadjoint_exp(zeta, mu)), 1.5))
    True
    """

    system: LiePoissonSystem
    sigma: float
    theta: float
    scene: Scene

    @property
    def algebra(self) -> LieAlgebra:
        return self.system.algebra

    @property
    def num_noises(self) -> int:
        return self.system.num_noises

    @property
    def sde(self) -> PoissonLangevinSDE:
        """The structure-agnostic SDE (:mod:`liesample.dynamics.sde`) on ``g*``,
        ``J(μ)ζ = ad*_ζ μ``."""
        system = self.system
        return PoissonLangevinSDE(
            LiePoissonStructure(system.algebra),
            system.hamiltonian,
            system.noise_hamiltonians,
            self.sigma,
            self.theta,
            self.scene,
        )

    def brackets_with_noise(self, mu: jax.Array, grad_h: jax.Array) -> jax.Array:
        """``{h, ĥ_i}(μ) = −dĥ_i(ad*_{∇h} μ)`` for every ``i``, shape ``(m,)`` (one JVP)."""
        return self.sde.brackets_with_noise(mu, self.algebra.ad_star(grad_h, mu))

    def noise_coefficients(
        self,
        mu: jax.Array,
        dt: jax.Array | float,
        dW: jax.Array | None = None,
        grad_h: jax.Array | None = None,
    ) -> jax.Array:
        """``c_i = −θ {h, ĥ_i} dt + σ dW_i`` (only the scene's terms), shape ``(m,)``.

        ``{h, ĥ_i} = −dĥ_i(X_h)``: one JVP of the noise Hamiltonians, no Jacobian formed.
        """
        coefficients = self.sde.noise_coefficients(mu, dt, dW, grad_h)
        return jnp.broadcast_to(coefficients, (self.num_noises,))

    def noise_generator(self, mu: jax.Array, coefficients: jax.Array) -> jax.Array:
        """``Σ_i c_i ∇ĥ_i(μ)``: one VJP of the noise Hamiltonians (no Jacobian is formed)."""
        _, pullback = jax.vjp(self.system.noise_hamiltonians, mu)
        return pullback(coefficients)[0]

    def generator(
        self, mu: jax.Array, dt: jax.Array | float, dW: jax.Array | None = None
    ) -> jax.Array:
        """The generator ``ζ ∈ g`` of one step of length ``dt`` with Brownian increments ``dW``:
        ``∇h dt + Σ_i c_i ∇ĥ_i`` (the SDE's covector; the increment is ``ad*_ζ μ``).

        Only the scene's effects are traced. ``dW`` (shape ``(m,)``) is required exactly when
        the scene has noise.
        """
        return self.sde.covector(mu, dt, dW)

    def group_generator(
        self,
        mu: jax.Array,
        group: int | jax.Array,
        dt: jax.Array | float,
        dW: jax.Array | None = None,
    ) -> jax.Array:
        """The generator of one group of noise directions alone: ``Σ_{i∈group} c_i ∇ĥ_i``.

        Along one direction the SDE is a one-dimensional Langevin equation with additive noise
        in the group coordinate ``φ`` of ``exp(φ ∇ĥ_i)`` (each direction leaves ``exp(−βh)``
        invariant on its own: the paper's ``eq:poisson-langevin-eq`` with one noise
        Hamiltonian), which is what the splitting integrator exploits.
        A system may group directions that commute and do not affect each other's
        coefficients (``LiePoissonSystem.noise_groups``); a group then moves as one piece.
        A system that declares ``LiePoissonSystem.single_noise_hamiltonian`` has each direction
        evaluated alone (:meth:`_one_direction_generator`).
        """
        if self.system.single_noise_hamiltonian is not None:
            return self._one_direction_generator(mu, group, dt, dW)
        coefficients = self.noise_coefficients(mu, dt, dW)
        in_group = self.system.noise_group_labels == group
        return self.noise_generator(mu, jnp.where(in_group, coefficients, 0.0))

    def _one_direction_generator(self, mu, i, dt, dW):
        """:meth:`group_generator` for the direction ``i`` alone, from
        ``single_noise_hamiltonian``: one gradient ``∇ĥ_i``, and ``{h, ĥ_i} = ⟨∇h, ad*_{∇ĥ_i} μ⟩``
        from it, so no JVP of the noise is needed."""
        scene = self.scene
        if scene.noise != (dW is not None):
            raise ValueError("dW must be given exactly when the scene has noise")
        noise = cast(
            Callable[[jax.Array, ArrayLike], jax.Array], self.system.single_noise_hamiltonian
        )
        gradient = jax.grad(lambda m: noise(m, i))(mu)
        coefficient = jnp.zeros((), mu.dtype)
        if scene.dissipation:
            grad_h = jax.grad(self.system.hamiltonian)(mu)
            bracket = self.algebra.pairing(self.algebra.ad_star(gradient, mu), grad_h)
            coefficient = coefficient - (self.theta * dt) * bracket
        if scene.noise:
            coefficient = coefficient + self.sigma * dW[i]
        return coefficient * gradient

    def vector_field(
        self, mu: jax.Array, dt: jax.Array | float, dW: jax.Array | None = None
    ) -> jax.Array:
        """The ambient increment ``ad*_ζ μ`` (what a non-geometric integrator adds to ``μ``)."""
        return self.algebra.ad_star(self.generator(mu, dt, dW), mu)

    def ito_correction(self, mu: jax.Array, quadratic_variation: jax.Array | float) -> jax.Array:
        """``½ σ² Σ_i d[S^i] (DX_i · X_i)(μ)``, ``X_i = X_{ĥ_i}``: the drift that turns the
        Stratonovich noise into Itô form (paper, the Itô-form proposition of ``sec:stoch-ham``).
        ``quadratic_variation`` holds ``d[S^i]`` over the step, shape ``(m,)`` or a
        scalar. Only Itô-reading integrators add it; none does silently.
        """

        def field(coefficients, m):
            return self.algebra.ad_star(self.noise_generator(m, coefficients), m)

        def along_itself(coefficients):
            return jax.jvp(lambda m: field(coefficients, m), (mu,), (field(coefficients, mu),))[1]

        directions = jnp.eye(self.num_noises, dtype=mu.dtype)
        weights = jnp.broadcast_to(quadratic_variation, (self.num_noises,))
        second_order = jax.vmap(along_itself)(directions)
        return 0.5 * self.sigma**2 * jnp.tensordot(weights, second_order, axes=1)

    def brownian_increments(
        self, rng_key: PRNGKey, dt: jax.Array | float, dtype: DTypeLike
    ) -> jax.Array | None:
        """``dW ~ N(0, dt I_m)`` when the scene has noise, else ``None`` (no draw at all)."""
        if not self.scene.noise:
            return None
        return jnp.sqrt(dt) * jax.random.normal(rng_key, (self.num_noises,), dtype=dtype)
