"""The cotangent bundle ``T*G ≅ G × g*`` of a parameter space, and the one-effect steps on it.

A position lives on a space of :mod:`liesample.geometry.spaces` (a Lie group, a sphere, ``Rⁿ``, or a
pytree of them); its momentum ``p`` lives in algebra coordinates (left trivialisation). The
Hamiltonian is ``H(g, p) = −log π(g) + ½ pᵀM⁻¹p``. An optional constant antisymmetric
*magnetic field* ``G`` acts on the ``Euclidean`` coordinates (all ``Euclidean`` blocks raveled
and concatenated in pytree order): it adds ``ṗ = G M⁻¹p`` there, the magnetic 2-form of the
charged particle (paper, ``sec:brownian-particle``). ``G`` does no work, so the Gibbs law
``exp(−H)`` is the same for every ``G``.

Every sampler and simulation that moves on ``T*G`` is a composition of four one-effect steps,
each solved exactly:

- ``B`` (:func:`kick`): the potential flow ``ṗ = ∇log π(g)`` (trivialised gradient);
- ``A`` (:func:`drift`): the kinetic flow, the exp-map drift ``g ← g exp(t M⁻¹p)`` of each
  space (geodesics on spheres, translations on ``Rⁿ``), and on the ``Euclidean`` coordinates
  with a field the exact kinetic–magnetic flow ``p ← e^{tGM⁻¹}p``,
  ``q ← q + M⁻¹ t φ₁(tGM⁻¹) p`` (:func:`liesample.geometry.poisson.kinetic_magnetic_exponential`);
- ``O`` (:func:`refresh`): the exact Ornstein–Uhlenbeck flow of the friction and noise,
  ``dp = −γM⁻¹p dt + √(2γ) dW`` (the derived dissipation of ``sec:dissipation``);
- the Metropolis test, in :mod:`liesample.samplers.cotangent._core`.

:func:`compose` chains them by a *scheme*, a list of ``(effect, fraction of the step)``
pairs, as BlackJAX composes its palindromic integrators from coefficient lists. The named
schemes (:data:`SCHEMES`, what the samplers' ``integrator=`` accepts by name): :data:`LEAPFROG`
(``B A B``, velocity Verlet), :data:`MINIMAL_NORM` (McLachlan's two-stage ``B A B A B``),
:data:`BAOAB`, :data:`OBABO` and :data:`OBAB`. ``B`` and ``A`` are exact Hamiltonian flows on
``T*G`` (volume preserving: ``tr(GM⁻¹) = 0``), so every palindromic composition of them is
reversible under ``(p, G) ↦ (−p, −G)``. :func:`check_scheme` validates a scheme and
:func:`gradient_evaluations` counts what one step of it costs.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple, cast

import jax
import jax.numpy as jnp
import jax.scipy.linalg
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.schemes import Schemes
from liesample.foundation.types import PRNGKey, PyTree, TreeDef
from liesample.foundation.validation import concrete_array
from liesample.geometry import spaces
from liesample.geometry.poisson import kinetic_magnetic_exponential

__all__ = [
    "BAOAB",
    "LEAPFROG",
    "MINIMAL_NORM",
    "OBAB",
    "OBABO",
    "SCHEMES",
    "CotangentBundle",
    "Drift",
    "KineticMagneticFlow",
    "Metric",
    "PhasePoint",
    "check_magnetic_field",
    "check_scheme",
    "compose",
    "cotangent_bundle",
    "drift",
    "evaluated",
    "gradient_evaluations",
    "kick",
    "kinetic_magnetic_flow",
    "make_metric",
    "ornstein_uhlenbeck",
    "refresh",
]

LEAPFROG = (("B", 0.5), ("A", 1.0), ("B", 0.5))
"""Velocity Verlet (Strang splitting of ``H = U + K``): one gradient per step."""
BAOAB = (("B", 0.5), ("A", 0.5), ("O", 1.0), ("A", 0.5), ("B", 0.5))
"""Leimkuhler–Matthews' kinetic Langevin splitting (weak order 2); one gradient per step."""
OBAB = (("O", 1.0), *LEAPFROG)
"""OU refresh, then a leapfrog step: the unadjusted form of Horowitz's generalised HMC."""
OBABO = (("O", 0.5), *LEAPFROG, ("O", 0.5))
"""Half OU refresh, a leapfrog step, half OU refresh (Bussi & Parrinello's splitting)."""
MINIMAL_NORM_B = 0.1931833275037836
"""``b`` of the two-stage minimal-norm scheme: it minimises the norm of the leading error
terms of ``e^{bεB} e^{εA/2} e^{(1−2b)εB} e^{εA/2} e^{bεB}`` (McLachlan 1995; Blanes, Casas &
Sanz-Serna 2014)."""
MINIMAL_NORM = (
    ("B", MINIMAL_NORM_B),
    ("A", 0.5),
    ("B", 1.0 - 2.0 * MINIMAL_NORM_B),
    ("A", 0.5),
    ("B", MINIMAL_NORM_B),
)
"""McLachlan's two-stage minimal-norm palindrome ``B A B A B``: two gradients per step, a
smaller energy error than two leapfrog steps of half the size on most targets."""
SCHEMES = Schemes(
    "T*G",
    {
        "leapfrog": LEAPFROG,
        "minimal_norm": MINIMAL_NORM,
        "baoab": BAOAB,
        "obabo": OBABO,
        "obab": OBAB,
    },
    {
        "leapfrog": "velocity Verlet: one gradient per step",
        "minimal_norm": "McLachlan's two-stage minimal-norm palindrome: two gradients per step",
        "baoab": "Leimkuhler–Matthews' kinetic Langevin splitting",
        "obabo": "half OU refresh, a leapfrog step, half OU refresh",
        "obab": "OU refresh, then a leapfrog step",
    },
)
"""The named schemes: name -> coefficient list ``((effect, fraction), …)``
(:class:`liesample.foundation.schemes.Schemes`)."""

ANTISYMMETRY_TOLERANCE = 1e-10  # relative to max|G|: round-off of a user-built field


# --------------------------------------------------------------------------- the OU step


def ornstein_uhlenbeck(
    momentum: jax.Array,
    noise: jax.Array | None,
    rate: jax.Array | float,
    diffusion: jax.Array | float,
    time: jax.Array | float,
) -> jax.Array:
    """Exact solution of ``dp = −r p dt + √D dW`` over ``time``, coordinate by coordinate.

    ``p ← e^{−rt} p + s ξ`` with ``s² = D (1 − e^{−2rt})/(2r)`` (``D t`` at ``r = 0``: pure
    noise); ``noise`` is the standard normal ``ξ``, or ``None`` for the friction alone.
    """
    decay = jnp.exp(-rate * time)
    if noise is None:
        return decay * momentum
    x = 2.0 * rate * time
    small = x < 1e-8
    ratio = jnp.where(small, 1.0 - 0.5 * x, -jnp.expm1(-x) / jnp.where(small, 1.0, x))
    return decay * momentum + jnp.sqrt(diffusion * time * ratio) * noise


# --------------------------------------------------------------------------- flat momentum law


class Metric(NamedTuple):
    """The momentum law ``N(0, M)`` on ``Rᵈ`` and its OU step, for a diagonal or dense ``M⁻¹``.

    Dense matrices go through the symmetric eigendecomposition ``M⁻¹ = U diag(λ) Uᵀ`` (``eigh``
    is right for the symmetric positive definite ``M⁻¹``; the skew ``G`` never goes through it).
    """

    inverse_mass_matrix: jax.Array  # (d,) or (d, d)
    eigenvalues: jax.Array  # of M⁻¹, (d,)
    eigenvectors: jax.Array | None  # None when diagonal

    def velocity(self, momentum: jax.Array) -> jax.Array:
        """``M⁻¹ p``."""
        if self.eigenvectors is None:
            return self.inverse_mass_matrix * momentum
        return self.inverse_mass_matrix @ momentum

    def kinetic_energy(self, momentum: jax.Array) -> jax.Array:
        """``½ pᵀ M⁻¹ p``."""
        return 0.5 * jnp.dot(momentum, self.velocity(momentum))

    def _from_eigenbasis(self, x):
        return x if self.eigenvectors is None else self.eigenvectors @ x

    def _to_eigenbasis(self, x):
        return x if self.eigenvectors is None else self.eigenvectors.T @ x

    def sample_momentum(self, rng_key: PRNGKey, dtype: DTypeLike) -> jax.Array:
        """A draw of ``N(0, M)``: ``U (ξ / √λ)``."""
        z = jax.random.normal(rng_key, self.eigenvalues.shape, dtype)
        return self._from_eigenbasis(z / jnp.sqrt(self.eigenvalues))

    def ornstein_uhlenbeck(
        self,
        rng_key: PRNGKey,
        momentum: jax.Array,
        friction: jax.Array | float,
        time: jax.Array | float,
    ) -> jax.Array:
        """Exact ``dp = −γ M⁻¹ p dt + √(2γ) dW`` over ``time`` (law ``N(0, M)`` kept): in the
        eigenbasis of ``M⁻¹`` a scalar OU process of rate ``γλ`` per coordinate."""
        z = jax.random.normal(rng_key, self.eigenvalues.shape, momentum.dtype)
        rate = friction * self.eigenvalues
        moved = ornstein_uhlenbeck(self._to_eigenbasis(momentum), z, rate, 2.0 * friction, time)
        return self._from_eigenbasis(moved)


def make_metric(inverse_mass_matrix: ArrayLike, dtype: DTypeLike | None = None) -> Metric:
    """:class:`Metric` from a diagonal ``(d,)`` or dense ``(d, d)`` inverse mass matrix."""
    imm = jnp.asarray(inverse_mass_matrix, dtype=dtype)
    if imm.ndim == 1:
        return Metric(imm, imm, None)
    eigenvalues, eigenvectors = jnp.linalg.eigh(0.5 * (imm + imm.T))
    return Metric(imm, eigenvalues, eigenvectors)


# --------------------------------------------------------------------------- kinetic–magnetic flow


class KineticMagneticFlow(NamedTuple):
    """The exact flow of ``q̇ = M⁻¹p, ṗ = G M⁻¹ p`` on ``Rᵈ`` over one time ``t``.

    ``p ← E p`` and ``q ← q + M⁻¹ (Φ p)`` with ``E = e^{tGM⁻¹}``, ``Φ = t φ₁(tGM⁻¹)``,
    ``φ₁(X) = Σ_k X^k/(k+1)!``. Without a field ``propagator`` is ``None`` and
    ``displacement`` is ``t`` (the translation ``q + t M⁻¹p``).
    """

    propagator: jax.Array | None  # E, (d, d)
    displacement: jax.Array  # Φ, (d, d), or the time t

    def __call__(
        self, metric: Metric, position: jax.Array, momentum: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        if self.propagator is None:
            return position + metric.velocity(self.displacement * momentum), momentum
        return position + metric.velocity(self.displacement @ momentum), self.propagator @ momentum


def kinetic_magnetic_flow(
    magnetic_field: ArrayLike | None, metric: Metric, time: ArrayLike
) -> KineticMagneticFlow:
    """:class:`KineticMagneticFlow` of a constant field over ``time`` (``None``: no field).

    ``B = GM⁻¹``; one ``expm`` of a ``2d × 2d`` matrix (paper, ``sec:brownian-particle``). The
    kinetic energy is conserved (``pᵀM⁻¹GM⁻¹p = 0``), and ``E`` is orthogonal when ``M = I``.
    Valid for singular
    ``G`` (``G = 0`` gives ``E = I``, ``Φ = tI``).
    """
    if magnetic_field is None:
        return KineticMagneticFlow(None, jnp.asarray(time, metric.eigenvalues.dtype))
    field = jnp.asarray(magnetic_field, metric.eigenvalues.dtype)
    if metric.eigenvectors is None:
        generator = field * metric.inverse_mass_matrix[None, :]  # G diag(m⁻¹)
    else:
        generator = field @ metric.inverse_mass_matrix
    return KineticMagneticFlow(*kinetic_magnetic_exponential(generator, time))


def check_magnetic_field(magnetic_field: ArrayLike, dimension: int | None = None) -> None:
    """Validate an antisymmetric ``(d, d)`` field; raise a ``ValueError`` that says what is wrong.

    ``dimension`` is the number of (Euclidean, raveled) position coordinates, if known. Value
    checks (finite, ``G + Gᵀ = 0`` to ``1e-10·max|G|``) are skipped for traced values.
    """
    field = spaces.real_finite_array("magnetic_field", magnetic_field, (2,))
    shape = np.shape(magnetic_field)
    if shape[0] != shape[1]:
        raise ValueError(f"magnetic_field must be a square (d, d) matrix, got shape {shape}")
    if dimension is not None and shape[0] != dimension:
        raise ValueError(
            f"magnetic_field must have shape ({dimension}, {dimension}) to match the "
            f"{dimension} position coordinates, got shape {shape}"
        )
    if field is not None:
        scale = max(float(np.max(np.abs(field))), np.finfo(float).tiny) if field.size else 1.0
        asym = float(np.max(np.abs(field + field.T))) if field.size else 0.0
        if asym > ANTISYMMETRY_TOLERANCE * scale:
            raise ValueError(
                "magnetic_field must be antisymmetric (G = -G^T); "
                f"max|G + G^T| = {asym:.3g} relative to max|G| = {scale:.3g}. "
                "Use G - G.T (or default_magnetic_field) to build one."
            )


# --------------------------------------------------------------------------- the bundle


class Drift(NamedTuple):
    """The kinetic flow over one time: ``time`` for the exp-map drift of the curved blocks,
    ``euclidean`` for the (kinetic–magnetic) flow of the ``Euclidean`` coordinates."""

    time: jax.Array
    euclidean: KineticMagneticFlow


@dataclasses.dataclass(frozen=True, eq=False)
class CotangentBundle:
    """``T*G`` of a space with a mass (and a field): the momentum law, ``K`` and its flow.

    Build with :func:`cotangent_bundle`. Blocks other than ``Euclidean`` carry a per-copy
    (groups, spheres) or per-coordinate (``U1``) inverse mass; the ``Euclidean`` blocks are
    handled together as one ``Rᴰ`` (raveled, concatenated in pytree order) with a
    :class:`Metric` (diagonal, or block-diagonal dense) and the optional field ``G`` (D × D).
    """

    space: spaces.SpaceTree
    inverse_mass: PyTree  # pytree like space
    magnetic_field: jax.Array | None
    metric: Metric | None  # of the Euclidean coordinates (None when there are none)

    @property
    def structure(self) -> TreeDef:
        return jax.tree.structure(self.space, is_leaf=spaces.is_space)

    @property
    def blocks(self) -> list[spaces.Space]:
        return jax.tree.leaves(self.space, is_leaf=spaces.is_space)

    @property
    def euclidean(self) -> list[bool]:
        return [isinstance(s, spaces.Euclidean) for s in self.blocks]

    @property
    def euclidean_dimension(self) -> int:
        return sum(math.prod(s.shape) for s, e in zip(self.blocks, self.euclidean) if e)

    def _leaves(self, tree):
        return self.structure.flatten_up_to(tree)

    def _flat(self, leaves):
        """The ``Euclidean`` coordinates of a list of leaves, raveled and concatenated."""
        parts = [jnp.ravel(x) for x, e in zip(leaves, self.euclidean) if e]
        return parts[0] if len(parts) == 1 else jnp.concatenate(parts)

    def _unflat(self, leaves, flat):
        """``leaves`` with their ``Euclidean`` entries replaced by the pieces of ``flat``."""
        out, offset = [], 0
        for x, s, e in zip(leaves, self.blocks, self.euclidean):
            if e:
                size = math.prod(s.shape)
                x = flat[offset : offset + size].reshape(s.shape)
                offset += size
            out.append(x)
        return out

    def _keys(self, rng_key):
        """One key per curved block and one for the Euclidean coordinates (no split if one)."""
        count = sum(not e for e in self.euclidean) + (self.metric is not None)
        return iter([rng_key] if count == 1 else list(jax.random.split(rng_key, count)))

    def zero_momentum(self, position: PyTree) -> PyTree:
        return spaces.zero_momentum(self.space, position)

    def kinetic_energy(self, momentum: PyTree) -> jax.Array:
        """``½ pᵀM⁻¹p`` summed over every block."""
        leaves = self._leaves(momentum)
        masses = self._leaves(self.inverse_mass)
        terms = [
            0.5 * jnp.sum(m * p**2) for p, m, e in zip(leaves, masses, self.euclidean) if not e
        ]
        if self.metric is not None:
            terms.append(self.metric.kinetic_energy(self._flat(leaves)))
        return cast(jax.Array, sum(terms))  # one term or more: every space has a block

    def _momentum_noise(self, rng_key, position, momentum, euclidean, curved):
        """Leaf by leaf: ``curved(s, x, p, m, ξ)`` with ``ξ`` a standard normal (tangent on
        spheres) for the curved blocks, ``euclidean(key, flat p)`` for the Euclidean ones."""
        keys = self._keys(rng_key)
        xs, ps = self._leaves(position), self._leaves(momentum)
        masses, out = self._leaves(self.inverse_mass), []
        for s, x, p, m, e in zip(self.blocks, xs, ps, masses, self.euclidean):
            if e:
                out.append(p)
                continue
            z = jax.random.normal(next(keys), s.momentum_array_shape, s.momentum_dtype(x))
            out.append(curved(p, m, s.project(x, z)))
        if self.metric is not None:
            out = self._unflat(out, euclidean(next(keys), self._flat(ps)))
        return self.structure.unflatten(out)

    def sample_momentum(self, rng_key: PRNGKey, position: PyTree) -> PyTree:
        """A draw of ``N(0, M)`` in each tangent space."""
        zero = self.zero_momentum(position)
        return self._momentum_noise(
            rng_key,
            position,
            zero,
            lambda key, p: cast(Metric, self.metric).sample_momentum(key, p.dtype),
            lambda p, m, z: z / jnp.sqrt(m),
        )

    def ornstein_uhlenbeck(
        self,
        rng_key: PRNGKey,
        position: PyTree,
        momentum: PyTree,
        friction: jax.Array | float,
        time: jax.Array | float,
    ) -> PyTree:
        """Exact OU step ``dp = −γ M⁻¹p dt + √(2γ) dW`` over ``time`` (``N(0, M)`` kept)."""
        return self._momentum_noise(
            rng_key,
            position,
            momentum,
            lambda key, p: cast(Metric, self.metric).ornstein_uhlenbeck(key, p, friction, time),
            lambda p, m, z: ornstein_uhlenbeck(p, z, friction * m, 2.0 * friction, time),
        )

    def kinetic_flow(self, time: ArrayLike, sign: float = 1.0) -> Drift:
        """The flow of ``K`` (and of the field times ``sign``) over ``time``; its matrices are
        computed here, once, for :meth:`drift`."""
        metric = self.metric
        if metric is None:
            return Drift(jnp.asarray(time), KineticMagneticFlow(None, jnp.asarray(time)))
        field = None if self.magnetic_field is None else sign * self.magnetic_field
        return Drift(jnp.asarray(time), kinetic_magnetic_flow(field, metric, time))

    def drift(self, flow: Drift, position: PyTree, momentum: PyTree) -> tuple[PyTree, PyTree]:
        """Apply a :meth:`kinetic_flow`: ``(g, p) ↦ (g', p')``."""
        xs, ps = self._leaves(position), self._leaves(momentum)
        masses = self._leaves(self.inverse_mass)
        new_x, new_p = [], []
        for s, x, p, m, e in zip(self.blocks, xs, ps, masses, self.euclidean):
            if not e:
                x, p = s.flow(x, p, m, flow.time)
            new_x.append(x)
            new_p.append(p)
        if self.metric is not None:
            q, p = flow.euclidean(self.metric, self._flat(xs), self._flat(ps))
            new_x, new_p = self._unflat(new_x, q), self._unflat(new_p, p)
        return self.structure.unflatten(new_x), self.structure.unflatten(new_p)


def cotangent_bundle(
    space: spaces.SpaceTree,
    inverse_mass_matrix: PyTree = None,
    magnetic_field: ArrayLike | None = None,
    dtype: DTypeLike | None = None,
    metric: Metric | None = None,
) -> CotangentBundle:
    """:class:`CotangentBundle` of ``space`` with ``M⁻¹`` (see
    :func:`liesample.geometry.spaces.check_inverse_mass`: dense ``(n, n)`` allowed on ``Euclidean``
    blocks) and an optional constant antisymmetric field on the ``Euclidean`` coordinates.

    ``metric``: the ``metric`` of a bundle built before from the same ``space``,
    ``inverse_mass_matrix`` and ``dtype``, used as it is, so that a dense ``M⁻¹`` that many
    transitions share is decomposed (``eigh``) once rather than in each; ``None`` (default)
    computes it."""
    inverse_mass = spaces.check_inverse_mass(space, inverse_mass_matrix, dtype)
    blocks = jax.tree.leaves(space, is_leaf=spaces.is_space)
    structure: TreeDef = jax.tree.structure(space, is_leaf=spaces.is_space)
    masses = structure.flatten_up_to(inverse_mass)
    euclidean = [(s, m) for s, m in zip(blocks, masses) if isinstance(s, spaces.Euclidean)]
    dimension = sum(math.prod(s.shape) for s, _ in euclidean)
    if magnetic_field is not None:
        if dimension == 0:
            raise ValueError(
                "magnetic_field acts on the Euclidean coordinates, and this space has none"
            )
        check_magnetic_field(magnetic_field, dimension)
        concrete = concrete_array(magnetic_field)
        if concrete is not None and not np.any(concrete):
            magnetic_field = None  # a zero field: the free drift, no matrix exponential
    if not euclidean:
        metric = None
    elif metric is None:
        if all(not spaces.is_dense_inverse_mass(s, m) for s, m in euclidean):
            imm = jnp.concatenate([jnp.ravel(m) for _, m in euclidean])
        else:  # block-diagonal over the Euclidean blocks
            imm = jax.scipy.linalg.block_diag(
                *[
                    m if spaces.is_dense_inverse_mass(s, m) else jnp.diag(jnp.ravel(m))
                    for s, m in euclidean
                ]
            )
        metric = make_metric(imm)
    if magnetic_field is not None:
        magnetic_field = jnp.asarray(magnetic_field, cast(Metric, metric).eigenvalues.dtype)
    return CotangentBundle(space, inverse_mass, magnetic_field, metric)


# --------------------------------------------------------------------------- one-effect steps


class PhasePoint(NamedTuple):
    """A point of ``T*G`` during a step: position and momentum (pytrees like the space), and
    ``log π`` with its trivialised gradient at the position (``None`` once a drift has moved it,
    until the next kick needs them). ``heat`` accumulates the kinetic energy the ``O`` steps
    put in (``None``: not tracked); ``ΔH − heat`` is the error of the Hamiltonian pieces."""

    position: object
    momentum: object
    logdensity: jax.Array | None = None
    logdensity_grad: object = None
    heat: jax.Array | None = None


def evaluated(point: PhasePoint, value_and_grad: Callable) -> PhasePoint:
    """``point`` with ``log π`` and its gradient at its position (computed only if missing)."""
    if point.logdensity_grad is not None:
        return point
    logdensity, grad = value_and_grad(point.position)
    return point._replace(logdensity=logdensity, logdensity_grad=grad)


def kick(value_and_grad: Callable, step_size: jax.Array | float) -> Callable:
    """``B``: ``p ← p + t ∇log π(g)`` (``ġ = 0``; the Lie–Poisson term vanishes as ``U`` does not
    depend on ``p``). Evaluates the gradient only where a drift has moved the position."""

    def effect(point, fraction, key):
        del key
        point = evaluated(point, value_and_grad)
        time = fraction * step_size
        momentum = jax.tree.map(lambda p, g: p + time * g, point.momentum, point.logdensity_grad)
        return point._replace(momentum=momentum)

    return effect


def drift(bundle: CotangentBundle, flows: dict) -> Callable:
    """``A``: the exact kinetic (and magnetic) flow, ``flows[fraction]`` from
    :meth:`CotangentBundle.kinetic_flow` (computed once per step size)."""

    def effect(point, fraction, key):
        del key
        position, momentum = bundle.drift(flows[fraction], point.position, point.momentum)
        return PhasePoint(position, momentum, heat=point.heat)

    return effect


def refresh(
    bundle: CotangentBundle, step_size: jax.Array | float, friction: jax.Array | float
) -> Callable:
    """``O``: the exact OU flow of the friction ``γ`` and noise ``√(2γ)`` over the fraction."""

    def effect(point, fraction, key):
        momentum = bundle.ornstein_uhlenbeck(
            key, point.position, point.momentum, friction, fraction * step_size
        )
        heat = point.heat
        if heat is not None:
            heat = heat + bundle.kinetic_energy(momentum) - bundle.kinetic_energy(point.momentum)
        return point._replace(momentum=momentum, heat=heat)

    return effect


def fractions(scheme: Sequence[tuple[str, float]], effect: str) -> tuple:
    """The distinct fractions of the step at which ``scheme`` applies ``effect``."""
    return tuple(sorted({fraction for name, fraction in scheme if name == effect}))


def check_scheme(
    scheme: str | Sequence[tuple[str, float]], effects: str = "ABO", name: str = "integrator"
) -> tuple:
    """A scheme as a tuple of ``(effect, fraction)`` pairs; a name of :data:`SCHEMES` is looked
    up. Raises a ``ValueError`` that says what is wrong unless every effect is one of
    ``effects``, every fraction is finite and > 0, and the fractions of each effect present
    sum to 1 (one step of size ``ε`` of each flow)."""
    allowed = f"a name of {sorted(SCHEMES)} or a tuple of (effect, fraction) pairs"
    if isinstance(scheme, str):
        if scheme not in SCHEMES:
            raise ValueError(f"{name} must be {allowed}; got the unknown name {scheme!r}")
        scheme = SCHEMES[scheme]
    try:
        pairs = tuple((str(effect), float(fraction)) for effect, fraction in scheme)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {allowed}, got {scheme!r}") from None
    if not pairs:
        raise ValueError(f"{name} must have at least one (effect, fraction) pair")
    unknown = sorted({effect for effect, _ in pairs} - set(effects))
    if unknown:
        raise ValueError(
            f"{name} may only use the effects {list(effects)} here, got {unknown} in {pairs}"
        )
    bad = [f for _, f in pairs if not (math.isfinite(f) and f > 0)]
    if bad:
        raise ValueError(f"{name}: every fraction must be finite and > 0, got {bad}")
    for effect in sorted({effect for effect, _ in pairs}):
        total = math.fsum(f for e, f in pairs if e == effect)
        if abs(total - 1.0) > 1e-12:
            raise ValueError(
                f"{name}: the fractions of {effect!r} must sum to 1 (one step of each flow), "
                f"got {total!r} in {pairs}"
            )
    return pairs


def gradient_evaluations(scheme: Sequence[tuple[str, float]]) -> int:
    """Gradients of ``log π`` one step of ``scheme`` evaluates, the step starting and ending at
    an evaluated point: one per ``B`` that follows an ``A`` (:func:`kick` reuses the gradient
    where the position has not moved), and one at the end if the step ends after an ``A``."""
    count, fresh = 0, True
    for effect, _ in scheme:
        if effect == "A":
            fresh = False
        elif effect == "B" and not fresh:
            count, fresh = count + 1, True
    return count + (not fresh)


def compose(scheme: Sequence[tuple[str, float]], effects: dict) -> Callable:
    """``step(point, rng_key=None)``: the effects applied in the order of ``scheme``.

    ``effects`` maps ``"B"``, ``"A"``, ``"O"`` to ``effect(point, fraction, key)`` (from
    :func:`kick`, :func:`drift`, :func:`refresh`, or the caller's own); a missing or ``None``
    effect is skipped (never traced). Each ``O`` gets its own key; the point may be any
    carry the effects agree on.
    """
    unknown = {name for name, _ in scheme} - {"A", "B", "O"}
    if unknown:
        raise ValueError(f"scheme effects must be 'A', 'B' or 'O', got {sorted(unknown)}")
    active = [(name, fraction) for name, fraction in scheme if effects.get(name) is not None]
    random = sum(name == "O" for name, _ in active)

    def step(point, rng_key=None):
        keys = iter([rng_key] if random <= 1 else list(jax.random.split(rng_key, random)))
        for name, fraction in active:
            point = effects[name](point, fraction, next(keys) if name == "O" else None)
        return point

    return step
