"""Poisson structures: what the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``) needs.

A Poisson structure is known through one linear map, the Poisson tensor applied to a covector,
``apply(z, ζ) = J(z) ζ``. Everything else follows from it:

- ``X_f(z) = J(z) ∇f(z)`` (:meth:`PoissonStructure.hamiltonian_vector_field`);
- ``{f, g}(z) = ∇f(z)ᵀ J(z) ∇g(z)`` (:meth:`PoissonStructure.bracket`);
- the Poisson–Langevin SDE (:class:`liesample.dynamics.sde.PoissonLangevinSDE`), with unit-strength
  noise Hamiltonians ``ĥ_i``, noise strength ``σ`` and dissipation strength ``θ`` (``θ = βσ²/2`` for
  ``exp(−βh)``):

      dz = X_h dt − θ Σ_i {h, ĥ_i} X_{ĥ_i} dt + σ Σ_i X_{ĥ_i} ∘ dW_i        (Stratonovich)

  assembled as ``J(z) ζ`` with the covector ``ζ = ∇h dt + Σ_i c_i ∇ĥ_i``,
  ``c_i = −θ {h, ĥ_i} dt + σ dW_i``. Since ``J`` is antisymmetric,
  ``{h, ĥ_i} = −dĥ_i(X_h)``: one application of ``J`` and one JVP of the noise Hamiltonians,
  and no Jacobian is formed.

The structures here:

- :class:`CanonicalStructure`: ``T*Rⁿ`` with ``J(q) = [[0, I], [−I, G(q)]]`` and an
  antisymmetric magnetic term ``G`` (paper, ``sec:brownian-particle``), constant or from a vector
  potential;
- :class:`LiePoissonStructure`: ``g*`` with ``J(μ) ζ = ad*_ζ μ`` (paper, ``eq:lie-poisson``), the
  structure that :class:`liesample.dynamics.PoissonLangevin` specialises (its generator *is* ``ζ``).

Magnetic conventions (physics, checked against the Lorentz force): the reduced symplectic form
``Σ dq^i ∧ dp_i − e dA`` with ``i_X ω = dh`` gives ``G_kj = e (∂_k A_j − ∂_j A_k)`` and, in
R³, ``G w = e w × B`` with ``B = curl A``, so ``ṗ = −∇V + e (p/m) × B``. (The paper's index
formula for ``B`` below ``sec:brownian-particle`` is ``−curl A``; only the sign of ``G`` changes,
and the invariant law does not depend on ``G``.)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import jax
import jax.numpy as jnp
import jax.scipy.linalg
import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float, float_array
from liesample.geometry.algebras import LieAlgebra

# A constant magnetic term must be antisymmetric to this relative accuracy (round-off of a
# matrix typed in or computed in float64, far below any real asymmetry).
_ANTISYMMETRY_RTOL = 1e-10


class PoissonStructure:
    """Interface: a Poisson tensor ``J(z)``, known through ``apply(z, ζ) = J(z) ζ``."""

    def apply(self, z: jax.Array, covector: jax.Array) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def hamiltonian_vector_field(
        self, f: Callable[[jax.Array], jax.Array], z: jax.Array
    ) -> jax.Array:
        """``X_f(z) = J(z) ∇f(z)``."""
        return self.apply(z, jax.grad(f)(z))

    def bracket(
        self, f: Callable[[jax.Array], jax.Array], g: Callable[[jax.Array], jax.Array], z: jax.Array
    ) -> jax.Array:
        """``{f, g}(z) = ∇f(z)ᵀ J(z) ∇g(z) = df(X_g)``."""
        return jnp.vdot(jax.grad(f)(z), self.hamiltonian_vector_field(g, z))

    def poisson_tensor(self, z: jax.Array) -> jax.Array:
        """The matrix ``J(z)`` (dense; for tests and small systems)."""
        flat = jnp.ravel(z)
        basis = jnp.eye(flat.size, dtype=flat.dtype).reshape((flat.size, *jnp.shape(z)))
        columns = jax.vmap(lambda e: jnp.ravel(self.apply(z, e)))(basis)
        return columns.T


@dataclass(frozen=True, eq=False)
class LiePoissonStructure(PoissonStructure):
    """``g*`` with the (−) Lie–Poisson bracket: ``J(μ) ζ = ad*_ζ μ`` (paper, ``eq:lie-poisson``)."""

    algebra: LieAlgebra

    def apply(self, z: jax.Array, covector: jax.Array) -> jax.Array:
        return self.algebra.ad_star(covector, z)


def cross_product_matrix(field: np.ndarray | Sequence[float]) -> np.ndarray:
    """The antisymmetric ``F`` with ``F w = w × B`` for a 3-vector ``B`` (``F_kj = ε_kjl B_l``)."""
    b1, b2, b3 = field
    return np.array([[0.0, b3, -b2], [-b3, 0.0, b1], [b2, -b1, 0.0]])


def field_from_vector_potential(
    vector_potential: Callable[[jax.Array], jax.Array],
) -> Callable[[jax.Array], jax.Array]:
    """``q ↦ B(q) = curl A(q)`` in R³, by forward-mode autodiff of ``A`` (divergence-free)."""

    def field(q: jax.Array) -> jax.Array:
        jacobian = jax.jacfwd(vector_potential)(q)  # jacobian[j, k] = ∂_k A_j
        return jnp.stack(
            [
                jacobian[2, 1] - jacobian[1, 2],
                jacobian[0, 2] - jacobian[2, 0],
                jacobian[1, 0] - jacobian[0, 1],
            ]
        )

    return field


def field_strength_from_vector_potential(
    vector_potential: Callable[[jax.Array], jax.Array],
) -> Callable[[jax.Array], jax.Array]:
    """``q ↦ F(q)``, ``F_kj = ∂_k A_j − ∂_j A_k`` in any ``Rⁿ`` (``F w = w × curl A`` in R³)."""

    def field_strength(q: jax.Array) -> jax.Array:
        jacobian = jax.jacfwd(vector_potential)(q)  # jacobian[j, k] = ∂_k A_j
        return jacobian.T - jacobian

    return field_strength


def antisymmetric_matrix(name: str, value: ArrayLike, dimension: int | None = None) -> np.ndarray:
    """A finite, antisymmetric, read-only ``(n, n)`` float array, or a ``ValueError`` naming it."""
    matrix = float_array(value, f"{name} must be an array of finite reals")
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1] or matrix.shape[0] == 0:
        raise ValueError(f"{name} must be a square (n, n) matrix, got shape {matrix.shape}")
    if dimension is not None and matrix.shape[0] != dimension:
        raise ValueError(
            f"{name} must have shape ({dimension}, {dimension}) to match dimension={dimension}, "
            f"got {matrix.shape}"
        )
    if not np.all(np.isfinite(matrix)):
        raise ValueError(f"{name} must be finite, got {matrix}")
    asymmetry = np.max(np.abs(matrix + matrix.T))
    if asymmetry > _ANTISYMMETRY_RTOL * max(1.0, np.max(np.abs(matrix))):
        raise ValueError(
            f"{name} must be antisymmetric (G = -G^T, so that J is a Poisson tensor and the "
            f"magnetic flow conserves kinetic energy); max |G + G^T| = {asymmetry:.3g}"
        )
    matrix = 0.5 * (matrix - matrix.T)
    matrix.setflags(write=False)
    return matrix


@dataclass(frozen=True, eq=False)
class CanonicalStructure(PoissonStructure):
    """``T*Rⁿ``, ``z = (q, p)``, with ``J(q) = [[0, I], [−I, G(q)]]`` (paper,
    ``sec:brownian-particle``).

    Parameters
    ----------
    dimension : int
        ``n``; states have shape ``(2n,)``.
    magnetic_term : array, callable or None
        ``G``: a constant antisymmetric ``(n, n)`` array, a callable ``q ↦ G(q)`` (antisymmetric
        for every ``q``, closed as a 2-form: use :func:`magnetic_structure`), or ``None`` for
        the canonical structure.

    Notes
    -----
    ``X_f = (∇_p f, −∇_q f + G(q) ∇_p f)``; for ``h = |p|²/2m + V(q)`` this is
    ``q̇ = p/m``, ``ṗ = −∇V + G p/m``.
    """

    dimension: int
    magnetic_term: np.ndarray | Callable[[jax.Array], jax.Array] | None = None

    @property
    def magnetic(self) -> bool:
        return self.magnetic_term is not None

    @property
    def constant_magnetic_term(self) -> bool:
        """``True`` when ``G`` is a constant array (its flow is then solved exactly)."""
        return self.magnetic and not callable(self.magnetic_term)

    def split(self, z: jax.Array) -> tuple[jax.Array, jax.Array]:
        return z[: self.dimension], z[self.dimension :]

    def magnetic_matrix(self, q: jax.Array) -> jax.Array | None:
        """``G(q)``, or ``None`` for the canonical structure."""
        if self.magnetic_term is None:
            return None
        if callable(self.magnetic_term):
            return self.magnetic_term(q)
        return jnp.asarray(self.magnetic_term, dtype=jnp.result_type(q))

    def apply(self, z: jax.Array, covector: jax.Array) -> jax.Array:
        q, _ = self.split(z)
        covector_q, covector_p = self.split(covector)
        force = -covector_q
        if self.magnetic:
            force = force + cast(jax.Array, self.magnetic_matrix(q)) @ covector_p
        return jnp.concatenate([covector_p, force])

    def without_magnetic_term(self) -> CanonicalStructure:
        """The canonical structure on the same ``T*Rⁿ`` (a scene with the field switched off)."""
        return CanonicalStructure(self.dimension)


def canonical_structure(dimension: int) -> CanonicalStructure:
    """``T*Rⁿ`` with its canonical Poisson tensor ``[[0, I], [−I, 0]]``."""
    return CanonicalStructure(_dimension(dimension))


def _dimension(dimension) -> int:
    if isinstance(dimension, bool) or not isinstance(dimension, (int, np.integer)):
        raise TypeError(f"dimension must be a positive int, got {dimension!r}")
    if dimension < 1:
        raise ValueError(f"dimension must be >= 1, got {dimension}")
    return int(dimension)


def magnetic_structure(
    *,
    magnetic_field: ArrayLike | None = None,
    vector_potential: Callable[[jax.Array], jax.Array] | None = None,
    charge: float = 1.0,
    dimension: int | None = None,
) -> CanonicalStructure:
    """``T*Rⁿ`` with the magnetic term ``G = e F`` of a field (paper, ``sec:brownian-particle``).

    Exactly one of:

    magnetic_field : array
        A constant field: a 3-vector ``B`` (``n = 3``, ``F w = w × B``) or an antisymmetric
        ``(n, n)`` field-strength matrix ``F`` (any ``n``; a 2-form, so the Jacobi identity
        holds).
    vector_potential : callable
        ``q ↦ A(q) ∈ Rⁿ``; ``F_kj = ∂_k A_j − ∂_j A_k`` by autodiff. ``F = dA`` is closed,
        so ``J`` is a Poisson tensor for every smooth ``A`` and, in R³, ``B = curl A`` is
        divergence-free (:func:`field_from_vector_potential`). ``dimension`` is required.

    charge : float
        ``e`` (finite; 0 gives the canonical structure's flow with a magnetic term of zero).
    dimension : int, optional
        ``n``; inferred from a constant field, required with a vector potential.
    """
    charge = finite_float("charge", charge)
    if dimension is not None:
        dimension = _dimension(dimension)
    if (magnetic_field is None) == (vector_potential is None):
        raise ValueError("give exactly one of magnetic_field (constant) or vector_potential")
    if vector_potential is not None:
        if not callable(vector_potential):
            raise TypeError(
                f"vector_potential must be a callable q -> A(q), got {vector_potential!r}"
            )
        if dimension is None:
            raise ValueError("dimension is required with a vector_potential (A maps R^n to R^n)")
        probe = jax.eval_shape(vector_potential, jax.ShapeDtypeStruct((dimension,), jnp.float64))
        if getattr(probe, "shape", None) != (dimension,):
            raise ValueError(
                f"vector_potential must map a position of shape ({dimension},) to a vector of "
                f"shape ({dimension},), got {getattr(probe, 'shape', probe)}"
            )
        field_strength = field_strength_from_vector_potential(vector_potential)
        return CanonicalStructure(dimension, lambda q: charge * field_strength(q))
    assert magnetic_field is not None  # exactly one of the two was given (checked above)
    if callable(magnetic_field):
        raise TypeError(
            "magnetic_field must be a constant array (a 3-vector B or an antisymmetric (n, n) "
            "matrix); for a position-dependent field pass vector_potential=q -> A(q)"
        )
    if np.ndim(magnetic_field) == 1:
        field = np.array(magnetic_field, dtype=float)
        if field.shape != (3,) or not np.all(np.isfinite(field)):
            raise ValueError(
                "magnetic_field as a vector must be a finite 3-vector B (R^3); "
                f"got {magnetic_field!r}"
                "; in other dimensions pass an antisymmetric (n, n) matrix"
            )
        if dimension is not None and dimension != 3:
            raise ValueError(f"a 3-vector magnetic_field needs dimension=3, got {dimension}")
        matrix = cross_product_matrix(field)
    else:
        matrix = antisymmetric_matrix("magnetic_field", magnetic_field, dimension)
    magnetic_term = charge * matrix
    magnetic_term.setflags(write=False)
    return CanonicalStructure(matrix.shape[0], magnetic_term)


def kinetic_magnetic_exponential(
    generator: ArrayLike, time: ArrayLike
) -> tuple[jax.Array, jax.Array]:
    """``(e^{tB}, t φ₁(tB))`` for ``B = G M⁻¹`` from one ``expm([[tB, tI], [0, 0]])``.

    ``φ₁(X) = Σ_k X^k/(k+1)!``, so ``t φ₁(tB) = ∫₀^t e^{sB} ds``: the exact flow of
    ``q̇ = M⁻¹p, ṗ = G M⁻¹ p`` is ``p ← e^{tB} p``, ``q ← q + M⁻¹ t φ₁(tB) p``. Valid for
    singular ``G`` (``G = 0`` gives ``(I, tI)``); never from a symmetric eigensolver.
    """
    generator, time = jnp.asarray(generator), jnp.asarray(time)
    n = generator.shape[0]
    eye = jnp.eye(n, dtype=generator.dtype)
    zeros = jnp.zeros_like(generator)
    exponential = jax.scipy.linalg.expm(jnp.block([[time * generator, time * eye], [zeros, zeros]]))
    return exponential[:n, :n], exponential[:n, n:]
