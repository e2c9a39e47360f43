"""Lie algebras and their coadjoint actions: the pure mathematics under every system.

Conventions (paper, ``sec:lie-poisson``): the (−) Lie–Poisson bracket ``{f, g}(μ) = −⟨μ, [∇f, ∇g]⟩``
and ``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩``, so that ``X_f(μ) = ad*_{∇f(μ)} μ`` and the Lie–Poisson
equation is ``μ̇ = ad*_{∇h} μ`` (paper, ``eq:lie-poisson``).

Every drift, dissipation and noise term on ``g*`` is a coadjoint action ``ad*_ζ μ`` for a
generator ``ζ ∈ g``; an integrator that moves by ``coadjoint_exp(ζ, μ) = Ad*_{exp ζ} μ`` stays
on the coadjoint orbit, so Casimirs are preserved to round-off by construction.

The algebras here:

- :class:`SO3` (``so3``): closed form (Rodrigues). It broadcasts over leading axes, so a state
  of shape ``(N, 3)`` *is* the product ``(so(3)*)^N`` (spins, point vortices): every operation
  acts copy by copy, vectorised, with no loop over the blocks.
- :class:`SE3` (``se3``): ``se(3)* = so(3)* ⋉ R³``, the heavy top, state ``(Π, Γ)`` of shape
  ``(..., 6)``; closed-form coadjoint action (paper, ``app:semidirect``).
- :class:`Unitary` (``unitary(N)``): ``u(N)`` on real ``N × N`` coordinates, ``Ad*`` by unitary
  conjugation (``expm``), O(N³); Casimirs the spectrum. Zeitlin's model of 2-D Euler on the
  sphere (:mod:`liesample.systems.zeitlin`) lives on it.
- :class:`StructureConstants`: any finite-dimensional algebra from its structure constants,
  validated (antisymmetry, Jacobi); ``coadjoint_exp`` by a matrix exponential. Instances:
  ``se3_structure_constants`` (cross-checks :class:`SE3`), and the non-compact ``sl2`` and
  ``se2``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import cast

import jax
import jax.numpy as jnp
import jax.scipy.linalg
import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.validation import float_array


@dataclass(frozen=True)
class LieAlgebra:
    """Interface of a Lie algebra ``g`` acting on its dual ``g*``.

    Elements of ``g`` and ``g*`` are arrays of the same shape, paired by the sum of the
    elementwise product. Subclasses provide ``bracket``, ``ad_star``, ``coadjoint_exp`` and
    ``casimirs``; all of them broadcast over leading axes where the algebra says so.

    Examples
    --------
    Every algebra moves a point of ``g*`` along its coadjoint orbit, keeping its Casimirs:

    >>> from liesample.algebras import so3
    >>> mu, zeta = jnp.array([1.0, 2.0, 2.0]), jnp.array([0.3, -0.1, 0.2])
    >>> bool(jnp.allclose(so3.casimirs(so3.coadjoint_exp(zeta, mu)), so3.casimirs(mu), atol=1e-12))
    True
    """

    name: str = "g"

    def pairing(self, mu: ArrayLike, xi: ArrayLike) -> jax.Array:
        """``⟨μ, ξ⟩``: the duality pairing, summed over every axis of the element."""
        return jnp.sum(mu * xi)

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def coadjoint_exp(
        self, zeta: ArrayLike, mu: ArrayLike
    ) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def casimirs(self, mu: ArrayLike) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError


def cross(a: ArrayLike, b: ArrayLike) -> jax.Array:
    """``a × b`` over the last axis (length 3), broadcasting.

    Examples
    --------
    >>> from liesample.algebras import cross
    >>> cross(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
    Array([0., 0., 1.], dtype=float64)
    """
    return jnp.cross(_last_axis_3("a", a), _last_axis_3("b", b))


def _last_axis_3(name: str, x: ArrayLike) -> ArrayLike:
    """``x``, refused unless its last axis has length 3 (a shape check: free under ``jit``)."""
    shape = jnp.shape(x)
    if shape[-1:] != (3,):
        raise ValueError(
            f"{name} must be an so(3) or so(3)* vector or a stack of them, shape (..., 3); got "
            f"shape {shape}"
        )
    return x


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

    Examples
    --------
    >>> from liesample.algebras import so3
    >>> mu = jnp.array([[1.0, 2.0, 2.0], [0.0, 0.0, 2.0]])  # two copies of so(3)*
    >>> so3.casimirs(mu)  # |μ_k|², one per copy
    Array([9., 4.], dtype=float64)
    >>> so3.coadjoint_exp(jnp.array([0.1, 0.2, 0.3]), mu).shape
    (2, 3)
    """

    name: str = "so(3)"

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        """``[ξ, η] = ξ × η``."""
        return cross(xi, eta)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``ad*_ξ μ = μ × ξ``, from ``⟨μ, ξ × η⟩ = ⟨μ × ξ, η⟩``."""
        return cross(mu, xi)

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``Ad*_{exp ζ} μ``: the time-one flow of ``μ̇ = μ × ζ``.

        That flow is the rotation by angle ``|ζ|`` about the axis ``−ζ/|ζ|`` (Rodrigues):
        ``μ + (sin θ/θ) μ×ζ + ((1 − cos θ)/θ²) ζ×(ζ×μ)`` with ``θ = |ζ|``; norm-preserving to
        round-off, and smooth (derivatives included) at ``ζ = 0``.
        """
        zeta = jnp.asarray(_last_axis_3("zeta", zeta))
        theta_sq = jnp.sum(zeta * zeta, axis=-1, keepdims=True)
        sin_over_theta, one_minus_cos_over_theta_sq = _rodrigues_coefficients(theta_sq)
        zeta_cross_mu = cross(zeta, mu)
        return (
            mu
            - sin_over_theta * zeta_cross_mu
            + one_minus_cos_over_theta_sq * cross(zeta, zeta_cross_mu)
        )

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """``|μ_k|²`` for each copy (shape ``mu.shape[:-1]``)."""
        mu = jnp.asarray(_last_axis_3("mu", mu))
        return jnp.sum(mu * mu, axis=-1)


so3 = SO3()


# ---------------------------------------------------------------------------------------------
# se(3)* = so(3)* ⋉ R³
# ---------------------------------------------------------------------------------------------

# Below this θ² the series of (θ − sin θ)/θ³ (to θ¹²) is exact in float64; above it the direct
# formula loses at most ~ulp(θ)/(θ − sin θ) ≲ 1e-15 relative (θ ≥ 0.5).
_SERIES_ANGLE_SQ = 0.25


def _theta_minus_sin_over_cube(theta_sq):
    """``(θ − sin θ)/θ³`` as a smooth function of ``θ²`` (derivatives included).

    The direct formula cancels catastrophically for small ``θ``, so below ``θ² = 0.25`` the
    alternating series ``Σ_k (−1)^k θ^{2k}/(2k+3)!`` (to ``k = 6``, truncation ``< 1e-18``) is
    used; the double ``where`` keeps the unused branch finite for autodiff.
    """
    small = theta_sq < _SERIES_ANGLE_SQ
    safe_sq = jnp.where(small, 1.0, theta_sq)
    theta = jnp.sqrt(safe_sq)
    series = 0.0
    for k in range(6, -1, -1):  # Horner in θ², from the highest term
        series = series * theta_sq + (-1.0) ** k / float(np.prod(np.arange(1, 2 * k + 4)))
    return jnp.where(small, series, (theta - jnp.sin(theta)) / (theta * safe_sq))


@dataclass(frozen=True)
class SE3(LieAlgebra):
    """se(3) = so(3) ⋉ R³ and its dual, in closed form; elements are arrays of shape ``(..., 6)``.

    An element of ``g`` is ``ζ = (ξ, v)`` (rotation, translation) and one of ``g*`` is
    ``μ = (Π, Γ)`` (the heavy top's body angular momentum and gravity direction), each stored
    as one array with the first three entries the so(3) part. Leading axes broadcast.

    - bracket ``[(ξ, v), (η, w)] = (ξ×η, ξ×w − η×v)``;
    - ``ad*_{(ξ,v)}(Π, Γ) = (Π×ξ + Γ×v, Γ×ξ)``, from ``⟨ad*_ζ μ, η⟩ = ⟨μ, [ζ, η]⟩``;
    - Casimirs ``(|Γ|², Π·Γ)`` (shape ``(..., 2)``); ``Π·Γ`` may be zero or negative.

    Examples
    --------
    >>> from liesample.algebras import se3
    >>> mu = jnp.array([0.0, 0.0, 1.0, 0.0, 0.0, 1.0])  # (Π, Γ)
    >>> se3.casimirs(mu)  # (|Γ|², Π·Γ)
    Array([1., 1.], dtype=float64)
    >>> moved = se3.coadjoint_exp(jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]), mu)
    >>> bool(jnp.allclose(se3.casimirs(moved), se3.casimirs(mu), atol=1e-12))
    True
    """

    name: str = "se(3)"

    @staticmethod
    def _split(x):
        return x[..., :3], x[..., 3:]

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        """``[(ξ, v), (η, w)] = (ξ×η, ξ×w − η×v)``."""
        (a, v), (b, w) = self._split(xi), self._split(eta)
        return jnp.concatenate([cross(a, b), cross(a, w) - cross(b, v)], axis=-1)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``ad*_{(ξ,v)}(Π, Γ) = (Π×ξ + Γ×v, Γ×ξ)``."""
        (a, v), (pi, gamma) = self._split(xi), self._split(mu)
        return jnp.concatenate([cross(pi, a) + cross(gamma, v), cross(gamma, a)], -1)

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``Ad*_{exp ζ} μ``: the time-one flow of ``μ̇ = ad*_ζ μ`` for constant ``ζ = (ξ, v)``.

        ``Γ̇ = Γ×ξ`` is the so(3) flow, ``Γ(t) = R(t)Γ₀`` with ``R(t) = exp(−t ξ̂)``. Then
        ``Π̇ = Π×ξ + Γ×v`` is linear with a forcing, and variation of constants gives
        ``Π(1) = R(1)Π₀ − ∫₀¹ R(1−s) v̂ R(s) Γ₀ ds``. With ``R(1−s) = R(1)R(s)ᵀ`` and
        ``R(s)ᵀ v̂ R(s) = (R(s)ᵀ v)^`` the integral is ``R(1)((J v)×Γ₀)``, ``J = ∫₀¹ exp(s ξ̂) ds``,
        so::

            Γ' = R Γ₀,    Π' = R Π₀ + Γ' × w,    w = R J v = ∫₀¹ exp(−u ξ̂) du · v
                                                    = v − ((1−cos θ)/θ²) ξ×v
                                                        + ((θ−sin θ)/θ³) ξ×(ξ×v)

        with ``θ = |ξ|``. Both Casimirs are kept to round-off (``R`` is a rotation and
        ``Γ'·(Γ'×w) = 0``); smooth, derivatives included, at ``ξ = 0`` (where ``Π' = Π₀ + Γ₀×v``).
        """
        (a, v), (pi, gamma) = self._split(zeta), self._split(mu)
        theta_sq = jnp.sum(a * a, axis=-1, keepdims=True)
        _, one_minus_cos = _rodrigues_coefficients(theta_sq)
        a_cross_v = cross(a, v)
        w = (
            v
            - one_minus_cos * a_cross_v
            + _theta_minus_sin_over_cube(theta_sq) * cross(a, a_cross_v)
        )
        gamma_new = so3.coadjoint_exp(a, gamma)
        pi_new = so3.coadjoint_exp(a, pi) + cross(gamma_new, w)
        return jnp.concatenate([pi_new, gamma_new], axis=-1)

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """``(|Γ|², Π·Γ)``, shape ``(..., 2)``."""
        pi, gamma = self._split(mu)
        return jnp.stack([jnp.sum(gamma * gamma, axis=-1), jnp.sum(pi * gamma, axis=-1)], -1)


se3 = SE3()


# ---------------------------------------------------------------------------------------------
# Any algebra from its structure constants
# ---------------------------------------------------------------------------------------------


def _no_casimirs(mu):
    return jnp.zeros(jnp.shape(mu)[:-1] + (0,), dtype=jnp.result_type(mu, float))


@dataclass(frozen=True, eq=False, init=False)
class StructureConstants(LieAlgebra):
    """A Lie algebra given by its structure constants ``[e_i, e_j] = Σ_k c_{ij}^k e_k``.

    Elements of ``g`` and ``g*`` are coordinate arrays of shape ``(..., n)`` (in the basis
    ``e_i`` and its dual basis); leading axes broadcast.

    - ``[ξ, η]_k = Σ_{ij} ξ_i η_j c_{ij}^k``;
    - ``ad*_ξ μ``: from ``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩ = Σ_{ijk} μ_k ξ_i η_j c_{ij}^k``,
      ``(ad*_ξ μ)_j = Σ_{ik} ξ_i μ_k c_{ij}^k``; i.e. ``ad*_ξ μ = M(ξ) μ`` with
      ``M(ξ)_{jk} = Σ_i ξ_i c_{ij}^k``;
    - ``coadjoint_exp(ζ, μ) = expm(M(ζ)) μ``, the time-one flow of ``μ̇ = ad*_ζ μ``;
    - Casimirs: whatever function the user declares (``casimirs=``), else none (shape
      ``(..., 0)``). They are not derived; tests should check they are preserved.

    Parameters
    ----------
    constants : array_like, shape (n, n, n)
        ``c[i, j, k] = c_{ij}^k``; must be finite, antisymmetric in ``(i, j)`` and satisfy the
        Jacobi identity (both to ``1e-10`` relative to the size of the constants).
    casimirs : callable, optional
        ``μ ↦ C(μ)`` with shape ``μ.shape[:-1] + (p,)``.
    name : str

    Examples
    --------
    so(3) from its structure constants ``c_{ij}^k = ε_{ijk}``, with the squared norm declared as
    its Casimir:

    >>> import numpy as np
    >>> from liesample.algebras import StructureConstants
    >>> eps = np.zeros((3, 3, 3))
    >>> for i, j, k in [(0, 1, 2), (1, 2, 0), (2, 0, 1)]:
    ...     eps[i, j, k], eps[j, i, k] = 1.0, -1.0
    >>> algebra = StructureConstants(eps, casimirs=lambda mu: (mu**2).sum(-1, keepdims=True))
    >>> algebra.bracket(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
    Array([0., 0., 1.], dtype=float64)
    """

    # The default only follows the base's defaulted fields: __init__ always sets the array.
    constants: np.ndarray = field(default=None, repr=False)  # type: ignore[arg-type]
    casimir_function: Callable[[jax.Array], jax.Array] | None = None

    def __init__(
        self,
        constants: ArrayLike,
        casimirs: Callable[[jax.Array], jax.Array] | None = None,
        name: str = "g",
    ):
        c = float_array(constants, "structure constants must be a real array of shape (n, n, n)")
        if c.ndim != 3 or not (c.shape[0] == c.shape[1] == c.shape[2]) or c.shape[0] == 0:
            raise ValueError(
                f"structure constants must have shape (n, n, n) with n >= 1, got shape {c.shape}"
            )
        if not np.all(np.isfinite(c)):
            raise ValueError("structure constants must be finite")
        size = max(1.0, float(np.max(np.abs(c))))
        asymmetry = float(np.max(np.abs(c + c.transpose(1, 0, 2))))
        if asymmetry > 1e-10 * size:
            raise ValueError(
                "structure constants must be antisymmetric, c[i, j, k] = -c[j, i, k]: "
                f"largest |c[i, j, k] + c[j, i, k]| = {asymmetry:.3g}"
            )
        # [e_i, [e_j, e_k]] = Σ_l c_jk^l c_il^m e_m, summed cyclically over (i, j, k).
        double = np.einsum("jkl,ilm->ijkm", c, c)
        jacobi = double + double.transpose(1, 2, 0, 3) + double.transpose(2, 0, 1, 3)
        violation = float(np.max(np.abs(jacobi)))
        if violation > 1e-10 * size**2:
            raise ValueError(
                "structure constants violate the Jacobi identity: largest "
                f"|[e_i,[e_j,e_k]] + cyclic| = {violation:.3g}"
            )
        if casimirs is not None and not callable(casimirs):
            raise TypeError(f"casimirs must be a callable μ ↦ C(μ), got {casimirs!r}")
        c.setflags(write=False)
        object.__setattr__(self, "name", str(name))
        object.__setattr__(self, "constants", c)
        object.__setattr__(self, "casimir_function", casimirs)

    @property
    def dimension(self) -> int:
        return self.constants.shape[0]

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        """``[ξ, η]_k = Σ_{ij} ξ_i η_j c_{ij}^k``."""
        return jnp.einsum("...i,...j,ijk->...k", xi, eta, self.constants)

    def coadjoint_matrix(self, zeta: ArrayLike) -> jax.Array:
        """``M(ζ)_{jk} = Σ_i ζ_i c_{ij}^k``, the matrix of ``μ ↦ ad*_ζ μ``; shape
        ``(..., n, n)``."""
        return jnp.einsum("...i,ijk->...jk", zeta, self.constants)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``(ad*_ξ μ)_j = Σ_{ik} ξ_i μ_k c_{ij}^k``."""
        return jnp.einsum("...i,...k,ijk->...j", xi, mu, self.constants)

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``expm(M(ζ)) μ``: the time-one flow of ``μ̇ = ad*_ζ μ``."""
        zeta, mu = jnp.broadcast_arrays(zeta, mu)
        flow = jax.scipy.linalg.expm(self.coadjoint_matrix(zeta))
        return jnp.einsum("...jk,...k->...j", flow, mu)

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """The declared Casimirs, or an empty array of shape ``μ.shape[:-1] + (0,)``."""
        if self.casimir_function is None:
            return _no_casimirs(mu)
        return self.casimir_function(cast(jax.Array, mu))  # μ as given: an array here


def _se3_constants():
    """``[e_i, e_j] = ε_ijk e_k``, ``[e_i, f_j] = ε_ijk f_k = [f_i, e_j]``, ``[f_i, f_j] = 0``
    (rotations ``e`` are coordinates 0–2, translations ``f`` 3–5): the bracket of :class:`SE3`."""
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    c = np.zeros((6, 6, 6))
    c[:3, :3, :3] = eps
    c[:3, 3:, 3:] = eps
    c[3:, :3, 3:] = eps
    return c


def _sl2_constants():
    """sl(2, R) in the basis ``(H, E, F)``: ``[H, E] = 2E``, ``[H, F] = −2F``, ``[E, F] = H``."""
    c = np.zeros((3, 3, 3))
    c[0, 1, 1], c[1, 0, 1] = 2.0, -2.0
    c[0, 2, 2], c[2, 0, 2] = -2.0, 2.0
    c[1, 2, 0], c[2, 1, 0] = 1.0, -1.0
    return c


def _sl2_casimir(mu):
    """``μ_H² + 4 μ_E μ_F``: the Killing form's dual quadratic form on ``sl(2)*``.

    The Killing form ``B(X, Y) = 4 tr(XY)`` has ``B(H, H) = 8``, ``B(E, F) = 4`` and zero
    otherwise; its inverse on the dual is ``μ_H²/8 + μ_E μ_F/2``, ``Ad*``-invariant because ``B``
    is ``Ad``-invariant; scaled here by 8. It is indefinite: with ``y = μ_E + μ_F`` and
    ``z = μ_E − μ_F`` it reads ``μ_H² + y² − z²``, so the orbits are one-sheeted hyperboloids
    (``C > 0``), sheets of two-sheeted ones (``C < 0``) or half-cones (``C = 0``): non-compact.
    """
    return (mu[..., 0] ** 2 + 4.0 * mu[..., 1] * mu[..., 2])[..., None]


def _se2_constants():
    """se(2) in the basis ``(J, P_x, P_y)``: ``[J, P_x] = P_y``, ``[J, P_y] = −P_x``,
    ``[P_x, P_y] = 0``."""
    c = np.zeros((3, 3, 3))
    c[0, 1, 2], c[1, 0, 2] = 1.0, -1.0
    c[0, 2, 1], c[2, 0, 1] = -1.0, 1.0
    return c


def _se2_casimir(mu):
    """``μ_x² + μ_y²`` (the squared translational momentum)."""
    return (mu[..., 1] ** 2 + mu[..., 2] ** 2)[..., None]


se3_structure_constants = StructureConstants(
    _se3_constants(), casimirs=se3.casimirs, name="se(3) (structure constants)"
)
sl2 = StructureConstants(_sl2_constants(), casimirs=_sl2_casimir, name="sl(2,R)")
se2 = StructureConstants(_se2_constants(), casimirs=_se2_casimir, name="se(2)")


# ---------------------------------------------------------------------------------------------
# u(N) on real N×N coordinates, coadjoint action by conjugation
# ---------------------------------------------------------------------------------------------


def _transpose(x):
    return jnp.swapaxes(x, -1, -2)


@dataclass(frozen=True, init=False)
class Unitary(LieAlgebra):
    """``u(N)`` and its dual on real ``(..., N, N)`` arrays; coadjoint action by conjugation.

    An element of ``u(N)`` is a skew-Hermitian matrix ``W = A + iS`` (``A`` real antisymmetric,
    ``S`` real symmetric). liesample stores it as the **real** matrix ``x = A + S`` (shape
    ``(..., N, N)``): ``A`` and ``S`` are the antisymmetric and symmetric parts of ``x``, so
    the map is a linear bijection ``R^{N×N} → u(N)`` and every engine piece (real Brownian
    increments, ``jax.grad``, ``jnp.where`` guards) works unchanged.

    **Pairing.** ``⟨W, Ξ⟩ = −tr(WΞ) = Re tr(W*Ξ)`` (the Frobenius inner product). In the real
    coordinates it is the plain sum ``Σ_ij x_ij y_ij`` (the cross terms ``A·T`` and ``S·B``
    vanish), so it is :meth:`LieAlgebra.pairing` and ``jax.grad`` of a real function of ``x`` *is*
    the Riesz representative of its differential: no conjugation convention enters. ``g*`` is
    identified with ``g`` by this pairing.

    **Bracket and coadjoint action** (the conventions above, ``⟨ad*_Ξ W, H⟩ = ⟨W, [Ξ, H]⟩``):

    - ``[Ξ, H] = ΞH − HΞ`` (matrix commutator);
    - ``ad*_Ξ W = [W, Ξ]`` (from ``−tr(W[Ξ, H]) = −tr([W, Ξ] H)``);
    - ``coadjoint_exp(Z, W) = e^{−Z} W e^{Z}``, the time-one flow of ``Ẇ = [W, Z]``: a unitary
      conjugation, so the spectrum of ``W`` is kept to round-off (``expm`` of a skew-Hermitian
      matrix by a diagonal Padé approximant and squaring is unitary to round-off). O(N³).

    Casimirs: the spectrum of the Hermitian matrix ``iW`` (ascending) and ``‖W‖² = −tr(W²)``, shape
    ``(..., N + 1)``; the orbits are the isospectral sets ``{U W₀ U*}``. Everything broadcasts over
    leading axes (a stack of chains). ``N = 2``: ``su(2) ≅ so(3)`` (``liesample.systems.zeitlin``).

    Parameters
    ----------
    size : int
        ``N ≥ 1``.

    Examples
    --------
    Conjugation keeps the spectrum, so a diagonal point stays on the orbit of its eigenvalues:

    >>> from liesample.algebras import unitary
    >>> u3 = unitary(3)
    >>> w0 = jnp.diag(jnp.array([1.0, 2.0, 3.0]))
    >>> w = u3.coadjoint_exp(jax.random.normal(jax.random.key(0), (3, 3)), w0)
    >>> w.shape, bool(jnp.allclose(u3.spectrum(w), u3.spectrum(w0), atol=1e-12))
    ((3, 3), True)
    """

    size: int = 2

    def __init__(self, size: int):
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"size N of u(N) must be an int >= 1, got {size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "name", f"u({size})")

    def _check(self, x):
        if jnp.shape(x)[-2:] != (self.size, self.size):
            raise ValueError(
                f"{self.name} elements are real arrays of shape (..., {self.size}, {self.size}), "
                f"got shape {jnp.shape(x)}"
            )

    def to_matrix(self, x: ArrayLike) -> jax.Array:
        """The skew-Hermitian matrix ``W`` (complex) of the real coordinates ``x``."""
        self._check(x)
        x = jnp.asarray(x)
        xt = _transpose(x)
        return 0.5 * (x - xt) + 0.5j * (x + xt)

    def from_matrix(self, w: ArrayLike) -> jax.Array:
        """The real coordinates of the skew-Hermitian part ``(W − W*)/2`` of a complex matrix.

        For a skew-Hermitian ``W`` this is ``Re W + Im W``, the inverse of :meth:`to_matrix`.
        """
        self._check(w)
        w = jnp.asarray(w)
        re, im = jnp.real(w), jnp.imag(w)
        return 0.5 * (re - _transpose(re)) + 0.5 * (im + _transpose(im))

    def bracket(self, xi: ArrayLike, eta: ArrayLike) -> jax.Array:
        """``[Ξ, H] = ΞH − HΞ``."""
        a, b = self.to_matrix(xi), self.to_matrix(eta)
        return self.from_matrix(a @ b - b @ a)

    def ad_star(self, xi: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``ad*_Ξ W = [W, Ξ] = WΞ − ΞW``."""
        a, w = self.to_matrix(xi), self.to_matrix(mu)
        return self.from_matrix(w @ a - a @ w)

    def group_element(self, zeta: ArrayLike) -> jax.Array:
        """``U = e^{−Z}`` (unitary), so that ``coadjoint_exp(ζ, W) = U W U*``."""
        return jax.scipy.linalg.expm(-self.to_matrix(zeta))

    def coadjoint_exp(self, zeta: ArrayLike, mu: ArrayLike) -> jax.Array:
        """``e^{−Z} W e^{Z}``: the time-one flow of ``Ẇ = [W, Z]`` (isospectral)."""
        zeta, mu = jnp.broadcast_arrays(jnp.asarray(zeta), jnp.asarray(mu))
        u = self.group_element(zeta)
        w = self.to_matrix(mu)
        return self.from_matrix(u @ w @ jnp.conj(_transpose(u)))

    def spectrum(self, mu: ArrayLike) -> jax.Array:
        """Eigenvalues of the Hermitian matrix ``iW``, ascending, shape ``(..., N)``."""
        return jnp.linalg.eigvalsh(1j * self.to_matrix(mu))

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        """``(spectrum of iW, ‖W‖²)``, shape ``(..., N + 1)``; ``‖W‖² = Σ_ij x_ij²``."""
        norm_sq = jnp.sum(jnp.asarray(mu) ** 2, axis=(-2, -1))
        return jnp.concatenate([self.spectrum(mu), norm_sq[..., None]], axis=-1)

    def casimir_scale(self, mu: ArrayLike) -> jax.Array:
        """Round-off scale of each Casimir: ``‖W‖`` for the eigenvalues, ``‖W‖²`` for the norm."""
        norm_sq = jnp.sum(jnp.asarray(mu) ** 2, axis=(-2, -1))[..., None]
        size = jnp.sqrt(norm_sq)
        return jnp.concatenate(
            [jnp.broadcast_to(size, norm_sq.shape[:-1] + (self.size,)), norm_sq], axis=-1
        )


def unitary(size: int) -> Unitary:
    """``u(N)`` (:class:`Unitary`).

    Examples
    --------
    >>> from liesample.algebras import unitary
    >>> unitary(4).casimirs(jnp.eye(4)).shape  # the spectrum of iW, then ‖W‖²
    (5,)
    """
    return Unitary(size)
