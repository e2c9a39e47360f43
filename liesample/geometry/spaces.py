"""Parameter spaces that are Lie groups or spheres: the position half of a chain on T*G.

The samplers in :mod:`liesample.samplers.cotangent.geometric_hmc` and
:mod:`liesample.samplers.cotangent.geometric_langevin` run the *unreduced* dissipative Hamiltonian
dynamics on ``T*G`` (paper, ``sec:dissipation``, before the reduction to ``g*``), with the
cotangent bundle left-trivialised, ``T*G ≅ G × g*``, and ``H(g, p) = U(g) + ½ pᵀM⁻¹p``. Its
Gibbs law ``exp(−H)`` has the ``G``-marginal ``exp(−U)`` with respect to Haar measure.

A *space* says how one block of the position moves. Every space has

- ``check(x)``: a clear error if ``x`` is not on the manifold (beyond round-off); a start is
  never silently projected;
- ``uniform(key)``: a draw from the uniform (Haar) law;
- ``flow(x, p, inverse_mass, t)``: the exact flow of the kinetic energy ``½ m⁻¹|p|²`` over a
  time ``t`` (the exp-map drift of the leapfrog; the group exponential is Rodrigues' formula
  on SO(3), closed form on SU(2), an eigendecomposition of the anti-Hermitian generator
  otherwise);
- ``perturb(x, ε)``: a curve through ``x`` with velocity ``ε`` (algebra coordinates); the
  trivialised gradient of ``log π`` is the autodiff gradient of ``ε ↦ log π(perturb(x, ε))``
  at ``ε = 0``, i.e. ``d/dε log π(g exp(εX))`` for a group (left trivialisation) and the
  Riemannian gradient for a sphere;
- ``exp(x, v)``, ``log(x, y)`` (where cheap), ``dimension``, ``momentum_shape``.

Spaces carry a ``shape``: the array of independent copies (``SU2(shape=(8, 8, 2))`` is the
link field of an 8×8 lattice). A product space is a pytree (dict, tuple, list) of spaces; a
position is a pytree of the same structure, one array per space.

Metric and mass. The momentum ``p`` lives in algebra coordinates (an orthonormal basis of
``g`` for the bi-invariant inner product ``⟨X, Y⟩ = ½ Re tr(X†Y)``). For a non-abelian group
the kinetic flow is the one-parameter subgroup ``g ↦ g exp(t m⁻¹ p)`` with ``p`` constant only
when the metric is bi-invariant, i.e. ``M ∝ I`` on each copy (otherwise ``p`` follows the
Euler–Arnold equation ``ṗ = ad*_{M⁻¹p} p`` of a free rigid body). Likewise the geodesic
formula of a sphere needs the round metric. So the inverse mass is one scalar per copy of a
group or sphere (shape ``shape + (1,)``) and one per coordinate of ``Euclidean`` and ``U1``
(shape ``shape``), where the flow is a translation for any diagonal mass; a ``Euclidean``
block of ``n`` coordinates may also take a dense ``(n, n)`` inverse mass. The momentum law,
the kinetic flow of a whole product (with an optional magnetic field on its ``Euclidean``
coordinates) and the one-effect steps built on them are in :mod:`liesample.geometry.cotangent`.

The sphere is a homogeneous space ``SO(n+1)/SO(n)``, not a group: its position is the unit
vector ``x ∈ Rⁿ⁺¹``, its momentum the tangent vector ``p ⟂ x`` in ambient coordinates, and its
drift the exact geodesic flow with parallel transport of the momentum,
``x ← x cos(|v|t) + v/|v| sin(|v|t)``, ``p ← p cos(|v|t) − x |p| sin(|v|t)``, ``v = m⁻¹p``
(the geodesic integrator of Byrne & Girolami 2013). It is the exact Hamiltonian flow of the
kinetic energy on ``T*Sⁿ``, so the leapfrog stays symplectic and reversible with respect to
the uniform measure × tangent Lebesgue measure.

This module is the spaces' public face: every name of a space is importable from here (as
``liesample.spaces``), and it holds what acts on a whole position, one array per block of a
product space: :func:`dimension`, :func:`check_position`, :func:`uniform`, the trivialised
gradient (:func:`trivialised_value_and_grad`) and :func:`zero_momentum`. The spaces themselves
live by kind: the interface :class:`Space` and products as pytrees in
:mod:`liesample.geometry.space_base`, ``Euclidean``, ``U1`` and ``Sphere`` in
:mod:`liesample.geometry.flat_and_round`, ``SO`` and ``SU`` in
:mod:`liesample.geometry.matrix_groups`, the checks of the inverse mass in
:mod:`liesample.geometry.inverse_mass`.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.types import PRNGKey, PyTree, TreeDef
from liesample.foundation.validation import prng_key
from liesample.geometry.flat_and_round import U1, Euclidean, Sphere
from liesample.geometry.inverse_mass import check_inverse_mass, check_inverse_mass_matrix
from liesample.geometry.inverse_mass import is_dense_inverse_mass as is_dense_inverse_mass
from liesample.geometry.inverse_mass import real_finite_array as real_finite_array
from liesample.geometry.matrix_groups import SO, SU
from liesample.geometry.space_base import Space, SpaceTree, is_space
from liesample.geometry.space_base import _map as _map
from liesample.geometry.space_base import _spaces as _spaces
from liesample.geometry.space_base import _wrap as _wrap

__all__ = [
    "SO",
    "SU",
    "U1",
    "Euclidean",
    "Space",
    "SpaceTree",
    "Sphere",
    "check_inverse_mass",
    "check_inverse_mass_matrix",
    "check_position",
    "dimension",
    "is_space",
    "trivialised_value_and_grad",
    "uniform",
    "zero_momentum",
]


def dimension(space: SpaceTree) -> int:
    """Dimension of a space or product of spaces.

    Examples
    --------
    >>> from liesample.spaces import SO, Euclidean, dimension
    >>> dimension({"R": SO(3), "x": Euclidean((2,))})
    5
    """
    return sum(s.dimension for s in _spaces(space))


def check_position(space: SpaceTree, position: PyTree, name: str = "position") -> None:
    """Structure, shape, dtype and manifold constraint of a position (clear errors).

    Examples
    --------
    A point off the sphere is refused, with the fix:

    >>> from liesample.spaces import Sphere, check_position
    >>> check_position(Sphere(2), jnp.array([0.0, 0.0, 1.0]))  # a unit vector: accepted
    >>> check_position(Sphere(2), jnp.array([1.0, 1.0, 0.0]))
    Traceback (most recent call last):
    ValueError: position is off Sphere(n=2, shape=()) by 0.414 ... divide by the norm first.
    """
    _spaces(space)
    space_structure: TreeDef = jax.tree.structure(space, is_leaf=is_space)
    position_structure: TreeDef = jax.tree.structure(position)
    if space_structure != position_structure:
        raise ValueError(
            f"{name} must have the structure of the space {space_structure}, got "
            f"{position_structure}"
        )
    paths = jax.tree_util.tree_flatten_with_path(space, is_leaf=is_space)[0]
    for (path, s), x in zip(paths, jax.tree.leaves(position)):
        s.check(x, name + jax.tree_util.keystr(path))


def uniform(space: SpaceTree, rng_key: PRNGKey, dtype: DTypeLike | None = None) -> PyTree:
    """A draw from the uniform (Haar) law of every block (Euclidean blocks have none).

    Examples
    --------
    >>> from liesample.spaces import SO, U1, uniform
    >>> x = uniform({"R": SO(3), "theta": U1((2,))}, jax.random.key(0))
    >>> x["R"].shape, x["theta"].shape
    ((3, 3), (2,))
    """
    leaves = _spaces(space)
    keys = iter(jax.random.split(prng_key(rng_key), len(leaves)))
    return _map(lambda s: s.uniform(next(keys), dtype), space)


# ---------------------------------------------------------------------- gradients and momenta


def trivialised_value_and_grad[P: PyTree](
    logdensity_fn: Callable[[P], ArrayLike], space: SpaceTree
) -> Callable[[P], tuple[jax.Array, P]]:
    """``x ↦ (log π(x), ∇ log π(x))`` with the gradient in algebra coordinates: left-trivialised
    on groups (``d/dε log π(g exp(εX_k))``), Riemannian on spheres, ordinary on ``Rᵈ``.

    Examples
    --------
    The height on S²: its Riemannian gradient vanishes at the pole and is ``e_z`` on the equator:

    >>> from liesample.spaces import Sphere, trivialised_value_and_grad
    >>> value_and_grad = trivialised_value_and_grad(lambda x: x[2], Sphere(2))
    >>> value, grad = value_and_grad(jnp.array([1.0, 0.0, 0.0]))
    >>> float(value), grad.tolist()
    (0.0, [0.0, 0.0, 1.0])
    """

    def value_and_grad(position: P) -> tuple[jax.Array, P]:
        def along(eps: P) -> ArrayLike:
            return logdensity_fn(_map(lambda s, x, e: s.perturb(x, e), space, position, eps))

        zero = zero_momentum(space, position)
        return jax.value_and_grad(along)(zero)

    return value_and_grad


def zero_momentum(space: SpaceTree, position: PyTree) -> PyTree:
    """The zero momentum of every block (algebra coordinates, in the position's dtype).

    Examples
    --------
    >>> from liesample.spaces import SO, zero_momentum
    >>> zero_momentum(SO(3), jnp.eye(3)).shape  # one algebra coordinate per generator
    (3,)
    """
    return _map(
        lambda s, x: jnp.zeros(s.momentum_array_shape, s.momentum_dtype(x)), space, position
    )
