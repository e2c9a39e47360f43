"""Point vortices on the sphere with spherical-harmonic transport noise.

Paper, ``sec:stoch-diss-point-vortices`` and ``app:point-vortex-derivation``.

**State.** The positions ``x_k`` of ``N`` vortices on the sphere of radius ``R``, shape
``(N, 3)``, with circulations ``Γ_k ≠ 0``.

**Structure.** Lie–Poisson on ``(so(3)*)^N`` through ``μ_k = −RΓ_k x_k`` (paper,
``eq:lie-poisson-so3-vortex``: ``X_f`` on ``x_k`` is ``(1/Γ_k) x_k × ∇_{x_k} f`` up to the global
sign). Rather than carry ``μ``,
the state *is* ``x`` and the algebra is so(3)^N with each copy's bracket scaled by
``w_k = −1/(RΓ_k)`` (:class:`ScaledSO3Product`): ``[ξ, η]_k = w_k ξ_k × η_k``,
``ad*_ξ x = x × (w ξ)``, ``Ad*_{exp ζ}`` = the so(3) rotation by ``w_k ζ_k``. This is the
pull-back of so(3)^N by the linear map ``x ↦ μ``, so everything the engine derives (drift,
dissipation, noise, the orbit-preserving moves) is that of ``(so(3)*)^N``, and ``|x_k|² = R²``
are the Casimirs. The sign ``−`` picks the classical orientation: the Hamiltonian velocity is

    ẋ_k = (1/4πR) Σ_{j≠k} Γ_j (x_j × x_k) / (R² − x_j·x_k)      (paper, eq:stoch-diss-point-vortex)

(either sign of the bracket is valid when it is used for all three terms, as here).

**Hamiltonian.** ``h = −Σ_{j<k} (Γ_jΓ_k/2π) log |x_j − x_k|`` (chordal distance), vectorised over
all pairs (``O(N²)`` memory and time, no Python loop over vortices).

**Noise.** ``ĥ_ℓm = Σ_k Γ_k ψ_ℓm(x_k/R)``, ``ψ_ℓm = Y_ℓ^m/√(ℓ(ℓ+1))`` (real orthonormal
harmonics, :mod:`liesample.geometry.spherical_harmonics`), ``1 ≤ ℓ ≤ L``: ``L(L+2)`` directions.
Each moves every vortex with the same divergence-free velocity ``−(1/R) u × ∇ψ_ℓm(u)``, ``u = x/R``
(transport noise; the ``Γ_k`` cancel). The **dissipation** is the engine's, derived from these
same truncated modes, so ``exp(−βh)`` is exactly invariant for every ``L`` (paper,
``eq:poisson-langevin-eq``). With
``L = 1`` the modes are rigid rotations, which commute with ``h``: no dissipation and no change
of the vortices' relative positions, so :func:`point_vortices` refuses it (``L ≥ 2``).

**The paper's closed form** (:func:`all_modes_dissipation`, the labelled variant
``point_vortex_integrator(..., dissipation="all_modes")``): the dissipation of
``eq:stoch-diss-point-vortex`` as printed, derived for *all* modes ``ℓ ≥ 1`` with the divergent
self-interaction (``k = i``) dropped. Paired with truncated noise it is not balanced, so its
stationary law differs from the Gibbs law.

**Gibbs law** and its exact references: :mod:`liesample.targets.vortices` (pair law for
``N = 2``; ``β`` bounds for normalisability, enforced by ``check_beta``).

**Collisions.** The Hamiltonian drift turns a pair at distance ``d`` at the rate
``(|Γ_j| + |Γ_k|)/(2πd²)``; :func:`point_vortex_integrator` wraps any integrator in adaptive
substeps driven by that rate (:mod:`liesample.integrators.substeps`). The derived (truncated)
dissipation and the noise stay bounded as ``d → 0``: they need no substeps, and the
Hamiltonian drift can be switched off for sampling (``hamiltonian=False``: same invariant law).

**Sampling.** The Hamiltonian rotation of a close pair is fast (rate ``∝ 1/d²``); a step that
does not resolve it flings the pair apart, so with the drift on and no substeps the unadjusted
chain has too few close pairs (most visible at ``β < 0``, where like-signed vortices cluster),
and that bias shrinks slowly with ``dt``. For the Gibbs law use
:func:`liesample.vortex_metropolis` (exact, no step), or ``lie_poisson_langevin(...,
hamiltonian=False)``, whose step bias vanishes as ``dt → 0`` without substeps.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.poisson_langevin import Scene
from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.precision import check_dtype, float64_hint, roundoff_tolerance
from liesample.foundation.validation import concrete_array, finite_float, nonzero_circulations
from liesample.geometry.algebras import LieAlgebra, cross, so3
from liesample.geometry.spherical_harmonics import num_harmonics, transport_mode, transport_modes
from liesample.integrators.orbit import Integrator, get_integrator
from liesample.integrators.substeps import adaptive_substepping
from liesample.targets.vortices import VortexPairLaw, check_vortex_beta

__all__ = [
    "PointVortexSystem",
    "ScaledSO3Product",
    "all_modes_dissipation",
    "angular_momentum",
    "collision_rate",
    "fibonacci_sphere",
    "minimum_distance",
    "point_vortex_integrator",
    "point_vortices",
    "substep_rate",
    "unresolved_fraction",
    "vortex_velocity",
]

ON_SPHERE_TOLERANCE = 1e-9
"""How far ``|x_k|/R`` may be from 1 in a float64 initial state (in float32, the round-off of
the start's dtype: :func:`liesample.foundation.precision.roundoff_tolerance`)."""

MIN_SEPARATION = 1e-9
"""Smallest chordal distance ``|x_j − x_k|/R`` accepted between two initial positions."""


@dataclass(frozen=True, eq=False)
class ScaledSO3Product(LieAlgebra):
    """so(3)^N with copy ``k``'s bracket scaled by ``w_k``: ``[ξ, η]_k = w_k ξ_k × η_k``.

    Isomorphic to so(3)^N (``ξ_k ↦ w_k ξ_k``); its dual carries the point-vortex bracket in
    position coordinates (module docstring). ``weights`` has shape ``(N,)``; elements have shape
    ``(N, 3)``.
    """

    weights: np.ndarray = field(default_factory=lambda: np.ones(1))
    name: str = "so(3)^N, scaled"

    def _w(self, like):
        return jnp.asarray(self.weights, dtype=like.dtype)[:, None]

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        return self._w(xi) * cross(xi, eta)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``ad*_ξ μ = μ × (w ξ)``, from ``⟨μ, [ξ, η]⟩ = Σ_k w_k μ_k·(ξ_k × η_k)``."""
        return cross(mu, self._w(mu) * xi)

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """The time-one flow of ``μ̇ = μ × (w ζ)``: so(3)'s Rodrigues rotation by ``w ζ``."""
        return so3.coadjoint_exp(self._w(mu) * zeta, mu)

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        return jnp.sum(mu * mu, axis=-1)


def _pair_geometry(x):
    """Squared chords ``d²_jk`` (diagonal set to 1) and the off-diagonal mask, from differences
    (not ``2R² − 2x·y``, which cancels catastrophically for close pairs)."""
    n = x.shape[0]
    diff = x[:, None, :] - x[None, :, :]
    off_diagonal = ~jnp.eye(n, dtype=bool)
    d2 = jnp.where(off_diagonal, jnp.sum(diff * diff, axis=-1), 1.0)
    return d2, off_diagonal


def vortex_velocity(x: ArrayLike, circulations: ArrayLike, radius: float = 1.0) -> jax.Array:
    """The classical velocity ``(1/4πR) Σ_{j≠k} Γ_j (x_j × x_k)/(R² − x_j·x_k)``, shape ``(N, 3)``.

    Written out directly (not via the engine), with ``R² − x_j·x_k = d²_jk/2``.
    """
    x = jnp.asarray(x)
    gamma = jnp.asarray(circulations, dtype=x.dtype)
    d2, off = _pair_geometry(x)
    weights = jnp.where(off, gamma[None, :] / (2.0 * math.pi * radius * d2), 0.0)
    return cross(weights @ x, x)


def angular_momentum(x: jax.Array, circulations: ArrayLike) -> jax.Array:
    """``Σ_k Γ_k x_k``, the momentum map of the diagonal rotations (shape ``(3,)``)."""
    return jnp.einsum("k,ki->i", jnp.asarray(circulations, dtype=x.dtype), x)


def minimum_distance(x: ArrayLike) -> jax.Array:
    """Smallest chordal distance between two vortices (``inf`` for one vortex)."""
    d2, off = _pair_geometry(jnp.asarray(x))
    return jnp.sqrt(jnp.min(jnp.where(off, d2, jnp.inf)))


def all_modes_dissipation(x: ArrayLike, circulations: ArrayLike, radius: float = 1.0) -> jax.Array:
    """The paper's closed-form dissipation velocity per unit ``θ`` (``eq:stoch-diss-point-vortex``).

    As printed, with ``u_k`` the classical velocity (:func:`vortex_velocity`):

        D_i = − Σ_{k≠i} Γ_k [ u_k × x_i / (4πR(R² − x_i·x_k))
                              + (x_i·u_k) (x_k × x_i) / (4πR(R² − x_i·x_k)²) ],

    so ``dx_i = θ D_i dt``. Derived for the infinite set of modes ``ℓ ≥ 1`` with the (divergent)
    self term ``k = i`` dropped; not the dissipation of any truncated noise.
    """
    x = jnp.asarray(x)
    gamma = jnp.asarray(circulations, dtype=x.dtype)
    u = vortex_velocity(x, circulations, radius)
    d2, off = _pair_geometry(x)
    half_d2 = 0.5 * d2  # R² − x_i·x_k
    a = jnp.where(off, gamma[None, :] / (4.0 * math.pi * radius * half_d2), 0.0)
    x_dot_u = x @ u.T  # [i, k] = x_i·u_k
    b = jnp.where(off, gamma[None, :] * x_dot_u / (4.0 * math.pi * radius * half_d2**2), 0.0)
    return -cross(a @ u + b @ x, x)


def collision_rate(x: ArrayLike, circulations: ArrayLike) -> jax.Array:
    """``max_{j<k} (|Γ_j| + |Γ_k|)/(2π d²_jk)``: how fast the Hamiltonian drift turns the closest
    pairs (a co-rotating pair at distance ``d`` turns at ``(Γ_j + Γ_k)/(2πd²)``), 1/time."""
    x = jnp.asarray(x)
    strength = jnp.abs(jnp.asarray(circulations, dtype=x.dtype))
    d2, off = _pair_geometry(x)
    rates = jnp.where(off, (strength[:, None] + strength[None, :]) / (2.0 * math.pi * d2), 0.0)
    return jnp.max(rates)


def unresolved_fraction(
    positions: ArrayLike,
    circulations: ArrayLike,
    step_size: float,
    *,
    safety: float | None = None,
    max_substeps: int | None = None,
) -> float:
    """Fraction of the states ``positions`` (``(..., N, 3)``, e.g. a run's draws) at which a step
    of the Hamiltonian drift does not resolve the closest pair's rotation: ``rate·dt > 1``
    radian without substeps, ``rate·dt > safety·max_substeps`` with them (the capped step's
    last substep), ``rate`` from :func:`collision_rate`. A run with the drift on whose fraction
    is not negligible has too few close pairs (module docstring, **Sampling**)."""
    positions = jnp.asarray(positions)
    flat = positions.reshape(-1, *positions.shape[-2:])
    rates = np.asarray(jax.vmap(lambda x: collision_rate(x, circulations))(flat))
    limit = 1.0 if max_substeps is None else float(cast(float, safety)) * int(max_substeps)
    return float(np.mean(rates * float(step_size) > limit))


def fibonacci_sphere(num_points: int, radius: float = 1.0) -> np.ndarray:
    """``num_points`` distinct, nearly uniform points on the sphere (golden-angle spiral)."""
    k = np.arange(num_points) + 0.5
    z = 1.0 - 2.0 * k / num_points
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    s = np.sqrt(1.0 - z * z)
    return radius * np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


@dataclass(frozen=True, eq=False)
class PointVortexSystem(LiePoissonSystem):
    """A :class:`LiePoissonSystem` of point vortices (module docstring); built by
    :func:`point_vortices`.

    ``check_position`` adds to the base checks: every ``|x_k|`` within ``1e-9`` (relative) of
    ``R`` (in float32, 1000 units of float32 round-off), and no two vortices closer than
    ``1e-9 R``.
    """

    circulations: np.ndarray = field(default_factory=lambda: np.ones(1))
    radius: float = 1.0
    max_degree: int = 1

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        super().check_position(position, name)
        value = concrete_array(position)
        if value is None:  # traced: value checks happen outside jit
            return
        dtype = check_dtype(value)
        tolerance = roundoff_tolerance(dtype, floor=ON_SPHERE_TOLERANCE)
        value = np.asarray(value, dtype=float)
        norms = np.linalg.norm(value, axis=-1) / self.radius
        bad = np.abs(norms - 1.0) > tolerance
        if np.any(bad):
            k = int(np.argmax(bad))
            raise ValueError(
                f"{name} must hold points on the sphere of radius {self.radius:g} "
                f"(|x_k| = R to {tolerance:.2g} relative); vortex {k} has |x| = "
                f"{norms[k] * self.radius:.12g} ({int(np.sum(bad))} off the sphere in all)."
                + float64_hint(dtype)
            )
        if value.shape[0] > 1:
            diff = value[:, None, :] - value[None, :, :]
            d = np.sqrt(np.sum(diff * diff, axis=-1)) / self.radius
            np.fill_diagonal(d, np.inf)
            j, k = np.unravel_index(int(np.argmin(d)), d.shape)
            if d[j, k] < MIN_SEPARATION:
                raise ValueError(
                    f"{name} has coincident vortices {min(j, k)} and {max(j, k)} (distance "
                    f"{d[j, k] * self.radius:.3g} < {MIN_SEPARATION:g} R): the vortex "
                    "Hamiltonian is singular there; start from distinct positions"
                )

    def velocity(self, x: ArrayLike) -> jax.Array:
        """Classical velocity of every vortex (:func:`vortex_velocity`)."""
        return vortex_velocity(x, self.circulations, self.radius)

    def angular_momentum(self, x: jax.Array) -> jax.Array:
        """``Σ_k Γ_k x_k``."""
        return angular_momentum(x, self.circulations)

    def collision_rate(self, x: ArrayLike) -> jax.Array:
        """:func:`collision_rate` for this system's circulations."""
        return collision_rate(x, self.circulations)


@by_value
def point_vortices(
    circulations: ArrayLike, max_degree: int = 2, radius: float = 1.0
) -> PointVortexSystem:
    """Point vortices on the sphere with transport noise of degrees ``1 … L`` (module docstring).

    Parameters
    ----------
    circulations : sequence of N nonzero floats
        ``Γ_k``; signs may differ.
    max_degree : int
        ``L ≥ 2``: the noise modes are ``ψ_ℓm``, ``1 ≤ ℓ ≤ L`` (``L(L+2)`` directions). ``L = 1``
        (rigid rotations only, which never change the vortices' relative positions) is refused.
    radius : float
        ``R > 0``. The Gibbs law in the unit vectors ``x/R`` does not depend on ``R``.

    Returns
    -------
    PointVortexSystem
        State shape ``(N, 3)``; default position: a Fibonacci spiral of radius ``R``;
        ``reference(beta)`` is the exact :class:`~liesample.targets.vortices.VortexPairLaw` of
        ``x₁·x₂/R²`` when ``N = 2``, else ``None``; ``check_beta`` refuses ``β`` where the Gibbs
        law is not normalisable (:func:`~liesample.targets.vortices.beta_bounds`).

    Examples
    --------
    A vortex pair, whose exact reference is the law of ``x₁·x₂``:

    >>> from liesample.systems import point_vortices
    >>> system = point_vortices([1.0, -1.0], max_degree=2)
    >>> system.event_shape, system.num_noises  # L(L + 2) noise modes
    ((2, 3), 8)
    >>> type(system.reference(1.0)).__name__
    'VortexPairLaw'
    """
    gamma = nonzero_circulations(circulations)
    if isinstance(max_degree, bool) or not isinstance(max_degree, (int, np.integer)):
        raise TypeError(f"max_degree must be an int >= 1, got {max_degree!r}")
    if max_degree < 1:
        raise ValueError(
            f"max_degree must be >= 1 (the transport modes are ℓ = 1 … L), got {max_degree}"
        )
    if max_degree == 1:
        raise ValueError(
            "max_degree=1 gives only the three rigid rotations as noise: they commute with h "
            "({h, ĥ_1m} = 0), so there is no dissipation, the vortices' relative positions never "
            "change and no sampler reaches the Gibbs law exp(-beta*h); use max_degree >= 2 "
            "(the default, 2), or liesample.vortex_metropolis, which needs no noise"
        )
    max_degree = int(max_degree)
    radius = finite_float("radius", radius, positive=True)
    num_vortices = gamma.size
    num_modes = num_harmonics(max_degree, 1)

    def hamiltonian(x):
        d2, off = _pair_geometry(x)
        g = jnp.asarray(gamma, dtype=x.dtype)
        products = g[:, None] * g[None, :]  # formed in the graph: an N×N constant is not captured
        # Σ_{j<k} log|x_j − x_k| Γ_jΓ_k/(2π) = Σ_{j≠k} log d²_jk Γ_jΓ_k/(8π)
        return -jnp.sum(jnp.where(off, products * jnp.log(d2), 0.0)) / (8.0 * math.pi)

    def noise_hamiltonians(x):
        return jnp.asarray(gamma, dtype=x.dtype) @ transport_modes(x, max_degree)

    def single_noise_hamiltonian(x, index):  # what one splitting piece needs
        return jnp.asarray(gamma, dtype=x.dtype) @ transport_mode(x, max_degree, index)

    def check_beta(beta):
        check_vortex_beta(gamma, beta)

    def reference(beta, position=None):
        del position  # the law of the unit vectors is the same on every orbit
        if num_vortices != 2:
            return None
        return VortexPairLaw.from_circulations(gamma, beta)

    return PointVortexSystem(
        name=f"{num_vortices} point vortices on the sphere (L = {max_degree})",
        algebra=ScaledSO3Product(weights=-1.0 / (radius * gamma)),
        hamiltonian=hamiltonian,
        noise_hamiltonians=noise_hamiltonians,
        num_noises=num_modes,
        single_noise_hamiltonian=single_noise_hamiltonian,
        event_shape=(num_vortices, 3),
        default_position=fibonacci_sphere(num_vortices, radius),
        reference=reference,
        component_names=("x", "y", "z"),
        params={
            "circulations": tuple(float(g) for g in gamma),
            "max_degree": max_degree,
            "radius": radius,
        },
        check_beta=check_beta,
        # ℓ ≤ L transport with L >= 2: brackets of the ℓ = 2 fields reach every degree, and the
        # Hamiltonian fields of all degrees move distinct vortices independently
        noise_reach="orbit",
        curvature_bound=False,  # h is singular at collisions: substepping handles stiffness
        circulations=gamma,
        radius=radius,
        max_degree=max_degree,
    )


# --------------------------------------------------------------------------- integrators


def _closed_form_generator(system: PointVortexSystem, x):
    """``ζ`` with ``ad*_ζ x = D(x)`` (:func:`all_modes_dissipation`): ``ζ_k = −Γ_k (D_k × x_k)/R``
    (for ``D_k ⊥ x_k``, ``x_k × (w_k ζ_k) = x_k × (D_k × x_k)/R² = D_k``)."""
    d = all_modes_dissipation(x, system.circulations, system.radius)
    gamma = jnp.asarray(system.circulations, dtype=x.dtype)[:, None]
    return -gamma * cross(d, x) / system.radius


def _with_all_modes_dissipation(system: PointVortexSystem, base):
    """Strang composition ``D(dt/2) ∘ base(Hamiltonian + noise)(dt) ∘ D(dt/2)`` where ``D`` is the
    closed-form dissipation, each half advanced by Heun on the group."""
    move = system.algebra.coadjoint_exp

    def dissipate(x, tau):
        def generator(m):
            return _closed_form_generator(system, m) * tau

        zeta = generator(x)
        return move(0.5 * (zeta + generator(move(zeta, x))), x)

    def step(dynamics, x, dt, dW=None):
        scene = dynamics.scene
        if not scene.dissipation:
            return base(dynamics, x, dt, dW)
        tau = 0.5 * dynamics.theta * dt
        x = dissipate(x, tau)
        if scene.hamiltonian or scene.noise:
            rest = Scene(hamiltonian=scene.hamiltonian, dissipation=False, noise=scene.noise)
            x = base(replace(dynamics, scene=rest), x, dt, dW)
        return dissipate(x, tau)

    return base.wrapping(
        step,
        f"{base.name}+all_modes",
        f"{base.name} with the paper's closed-form (all-modes) dissipation in place "
        "of the derived one (Strang): not Gibbs-exact",
        weak_order=1,
    )


def substep_rate(
    system: PointVortexSystem, dissipation: str = "truncated"
) -> Callable[[object, jax.Array], jax.Array]:
    """The rate ``(dynamics, x) ↦ λ`` (1/time) that drives the substeps of
    :func:`point_vortex_integrator`: ``ω = max_{j<k} (|Γ_j| + |Γ_k|)/(2π d_jk²)`` when the scene has
    the Hamiltonian drift, plus ``θ ω²`` when the closed-form dissipation is on (its terms grow
    like ``1/d³``). The derived (truncated) dissipation and the noise stay bounded near
    collisions and add nothing."""
    closed_form = dissipation == "all_modes"

    def rate_fn(dynamics, x):
        omega = collision_rate(x, system.circulations)
        rate = jnp.zeros_like(omega)
        if dynamics.scene.hamiltonian:
            rate = rate + omega
        if closed_form and dynamics.scene.dissipation:
            rate = rate + dynamics.theta * omega**2
        return rate

    return rate_fn


def point_vortex_integrator(
    system: PointVortexSystem,
    base: str | Integrator = "splitting",
    *,
    dissipation: str = "truncated",
    collision_safe: bool = True,
    safety: float = 0.05,
    max_substeps: int = 1000,
) -> Integrator:
    """The integrator to pass as ``integrator=`` to :func:`liesample.lie_poisson_langevin`.

    Parameters
    ----------
    system : PointVortexSystem
    base : str or Integrator
        Any engine integrator (``"splitting"``, ``"rkmk_heun"``, ``"lie_euler"``, …).
    dissipation : {"truncated", "all_modes"}
        ``"truncated"`` (default): the engine's dissipation derived from the system's modes,
        Gibbs-exact for every ``L``. ``"all_modes"``: the paper's closed form
        (:func:`all_modes_dissipation`) replaces it — a labelled variant, *not* Gibbs-exact.
    collision_safe : bool
        Run on adaptive substeps ``h = min(remaining, safety/rate)`` with
        ``rate = (|Γ_j| + |Γ_k|)/(2π d²)`` maximised over pairs when the scene has the
        Hamiltonian drift (plus ``θ·rate²`` for the closed-form dissipation, which is stiffer).
    safety : float
        Largest rotation of the closest pair per substep, in radians (roughly).
    max_substeps : int
        Cap per step: the last substep takes the rest of the step, unresolved (the clock is
        kept; :mod:`liesample.integrators.substeps`). Under ``vmap`` a batch of chains costs
        its slowest chain's substeps, at most this many per step.

    Examples
    --------
    >>> from liesample.systems import point_vortex_integrator, point_vortices
    >>> system = point_vortices([1.0, 1.0, -1.0])
    >>> integrator = point_vortex_integrator(system)  # adaptive substeps near collisions
    >>> sampler = liesample.lie_poisson_langevin(system, beta=1.0, step_size=0.01,
    ...                                          integrator=integrator)
    >>> integrator.name
    'splitting+substeps'
    """
    if not isinstance(system, PointVortexSystem):
        raise TypeError(f"system must be a PointVortexSystem, got {type(system).__name__}")
    if dissipation not in ("truncated", "all_modes"):
        raise ValueError(f"dissipation must be 'truncated' or 'all_modes', got {dissipation!r}")
    integrator = get_integrator(base)
    if dissipation == "all_modes":
        integrator = _with_all_modes_dissipation(system, integrator)
    if not collision_safe:
        return integrator
    rate_fn = substep_rate(system, dissipation)
    return adaptive_substepping(
        integrator,
        rate_fn,
        safety=safety,
        max_substeps=max_substeps,
        name=f"{integrator.name}+substeps",
    )
