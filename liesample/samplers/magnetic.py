"""Shared pieces of the magnetic samplers on T*Rⁿ (MATH.md §3).

The chain state is ``z = (q, p)`` with the Poisson tensor ``J = [[0, I], [−I, G]]``, ``G`` a
constant antisymmetric matrix (the *magnetic field*), and ``h = −log π(q) + ½ pᵀM⁻¹p``. This
module holds what :mod:`liesample.samplers.magnetic_hmc` and
:mod:`liesample.samplers.magnetic_langevin` share:

- :func:`magnetic_flow`: the exact flow of the kinetic + magnetic part
  ``q̇ = M⁻¹p, ṗ = G M⁻¹ p`` over a time ``ε``, from ONE ``expm`` of an augmented block matrix
  (valid for singular ``G``; no eigendecomposition of a skew matrix);
- :class:`Metric`: the Gaussian momentum law ``N(0, M)`` for a diagonal or dense ``M⁻¹``, and the
  exact Ornstein–Uhlenbeck step of the friction + noise part;
- parameter validation and :func:`default_magnetic_field`, the default field and its tuning
  rule.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from liesample._validation import concrete_array
from liesample.compile import jit
from liesample.samplers.contract import first_bad_chain
from liesample.structures import kinetic_magnetic_exponential

__all__ = [
    "MagneticFlow",
    "Metric",
    "check_magnetic_field",
    "default_magnetic_field",
    "check_starts",
    "initial_values",
    "magnetic_flow",
    "make_metric",
    "ravel_logdensity",
]

ANTISYMMETRY_TOLERANCE = 1e-10  # relative to max|G|: round-off of a user-built field


# --------------------------------------------------------------------------- validation


def _check_real_finite(name, value, ndims):
    """Shape/rank check always; value checks only when ``value`` is concrete (not a tracer)."""
    shape = np.shape(value)
    if len(shape) not in ndims:
        want = " or ".join(f"{n}-D" for n in ndims)
        raise ValueError(f"{name} must be a {want} array, got shape {shape}")
    array = concrete_array(value)
    if array is not None:
        if array.dtype.kind not in "biuf":
            raise TypeError(f"{name} must be a real array, got dtype {array.dtype}")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} must be finite, got non-finite entries")
    return array


def check_magnetic_field(magnetic_field, dimension: int | None = None):
    """Validate an antisymmetric ``(d, d)`` field; raise a ``ValueError`` that says what is wrong.

    ``dimension`` is the number of position coordinates (after raveling a pytree), if known.
    Value checks (finite, ``G + Gᵀ = 0`` to ``1e-10·max|G|``) are skipped for traced values.
    """
    field = _check_real_finite("magnetic_field", magnetic_field, (2,))
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


def check_inverse_mass_matrix(inverse_mass_matrix, dimension: int | None = None):
    """Diagonal (``(d,)``, entries > 0) or dense (``(d, d)``, symmetric positive definite)."""
    imm = _check_real_finite("inverse_mass_matrix", inverse_mass_matrix, (1, 2))
    shape = np.shape(inverse_mass_matrix)
    if len(shape) == 2 and shape[0] != shape[1]:
        raise ValueError(f"inverse_mass_matrix must be (d,) or square (d, d), got shape {shape}")
    if dimension is not None and shape[0] != dimension:
        raise ValueError(
            f"inverse_mass_matrix must have leading size {dimension} to match the "
            f"{dimension} position coordinates, got shape {shape}"
        )
    if imm is None:
        return
    if imm.ndim == 1 and not np.all(imm > 0):
        raise ValueError("inverse_mass_matrix (diagonal) must have all entries > 0")
    if imm.ndim == 2:
        if not np.allclose(imm, imm.T, rtol=1e-10, atol=0.0):
            raise ValueError("inverse_mass_matrix (dense) must be symmetric")
        if imm.size and not np.all(np.linalg.eigvalsh(imm) > 0):
            raise ValueError("inverse_mass_matrix (dense) must be positive definite")


def check_step_size(step_size):
    """``step_size`` must be a scalar, finite and > 0 (checked when concrete)."""
    if np.ndim(step_size) != 0:
        raise ValueError(f"step_size must be a scalar, got shape {np.shape(step_size)}")
    value = concrete_array(step_size)
    if value is not None and not (np.isfinite(value) and value > 0):
        raise ValueError(f"step_size must be finite and > 0, got {float(value)}")


# --------------------------------------------------------------------------- pytrees


def ravel_logdensity(position, logdensity_fn):
    """``(flat_position, flat_logdensity_fn, unravel)`` for a pytree ``position``."""
    flat, unravel = ravel_pytree(position)

    def flat_logdensity_fn(x):
        return logdensity_fn(unravel(x))

    return flat, flat_logdensity_fn, unravel


def ravel(tree):
    return ravel_pytree(tree)[0]


def initial_values(position, logdensity_fn):
    """``(log π, ∇log π, zero flat momentum)`` at ``position``, shared by both samplers' ``init``.

    Raises a ``ValueError`` when ``log π`` or its gradient is not finite (checked when concrete:
    under ``jit``/``vmap`` the kernels' non-finite guard takes over).
    """
    logdensity, grad = jax.value_and_grad(logdensity_fn)(position)
    flat_grad = ravel(grad)
    values = concrete_array(jnp.append(flat_grad, logdensity))
    if values is not None and not np.all(np.isfinite(values)):
        raise ValueError(
            "logdensity_fn or its gradient is not finite at the initial position; start the "
            "chain where log π is finite"
        )
    return logdensity, grad, jnp.zeros_like(ravel(position), dtype=flat_grad.dtype)


def check_starts(positions, logdensity_fn, dimension=None):
    """Check every start (a pytree whose leaves have a leading chain axis) in one vectorised
    call: ``log π`` and its gradient finite, ``dimension`` coordinates; the error names the
    first bad chain."""

    def finite(position):
        logdensity, grad = jax.value_and_grad(logdensity_fn)(position)
        return jnp.isfinite(logdensity) & jnp.all(jnp.isfinite(ravel(grad)))

    first = jax.tree.map(lambda leaf: leaf[0], positions)
    size = ravel(first).shape[0]
    if dimension is not None and size != dimension:
        raise ValueError(
            f"initial_positions[0] has {size} coordinates but inverse_mass_matrix and "
            f"magnetic_field are for {dimension}"
        )
    with jax.ensure_compile_time_eval():
        ok = np.asarray(jit(jax.vmap(finite))(positions))
    chain = first_bad_chain(ok)
    if chain is not None:
        raise ValueError(
            f"initial_positions[{chain}]: logdensity_fn or its gradient is not finite there; "
            "start the chain where log π is finite"
        )


# --------------------------------------------------------------------------- momentum law


class Metric(NamedTuple):
    """The momentum law ``N(0, M)`` and the OU step, for a diagonal or dense ``M⁻¹``.

    Dense matrices are handled through the symmetric eigendecomposition of ``M⁻¹`` (symmetric
    positive definite, so ``eigh`` is the right tool; only the skew ``G`` must never go
    through it).
    """

    inverse_mass_matrix: jax.Array  # (d,) or (d, d)
    eigenvalues: jax.Array  # of M⁻¹, (d,)
    eigenvectors: jax.Array | None  # None when diagonal

    def velocity(self, momentum):
        """``M⁻¹ p``."""
        if self.eigenvectors is None:
            return self.inverse_mass_matrix * momentum
        return self.inverse_mass_matrix @ momentum

    def kinetic_energy(self, momentum):
        """``½ pᵀ M⁻¹ p``."""
        return 0.5 * jnp.dot(momentum, self.velocity(momentum))

    def _from_eigenbasis(self, x):
        return x if self.eigenvectors is None else self.eigenvectors @ x

    def _to_eigenbasis(self, x):
        return x if self.eigenvectors is None else self.eigenvectors.T @ x

    def sample_momentum(self, rng_key, dtype):
        """A draw of ``N(0, M)``: ``U (ξ / √λ)`` with ``M⁻¹ = U diag(λ) Uᵀ``."""
        z = jax.random.normal(rng_key, self.eigenvalues.shape, dtype)
        return self._from_eigenbasis(z / jnp.sqrt(self.eigenvalues))

    def ornstein_uhlenbeck(self, rng_key, momentum, friction, time):
        """Exact solution of ``dp = −θ M⁻¹ p dt + √(2θ) dW`` over ``time`` (law ``N(0, M)`` kept).

        In the eigenbasis of ``M⁻¹`` each coordinate is a scalar OU process with rate ``θλ``:
        ``p ← e^{−θλt} p + √((1 − e^{−2θλt})/λ) ξ``.
        """
        decay = jnp.exp(-friction * time * self.eigenvalues)
        scale = jnp.sqrt(-jnp.expm1(-2.0 * friction * time * self.eigenvalues) / self.eigenvalues)
        z = jax.random.normal(rng_key, self.eigenvalues.shape, momentum.dtype)
        return self._from_eigenbasis(decay * self._to_eigenbasis(momentum) + scale * z)


def make_metric(inverse_mass_matrix, dtype=None) -> Metric:
    """:class:`Metric` from a diagonal ``(d,)`` or dense ``(d, d)`` inverse mass matrix."""
    imm = jnp.asarray(inverse_mass_matrix, dtype=dtype)
    if imm.ndim == 1:
        return Metric(imm, imm, None)
    eigenvalues, eigenvectors = jnp.linalg.eigh(0.5 * (imm + imm.T))
    return Metric(imm, eigenvalues, eigenvectors)


# --------------------------------------------------------------------------- exact flow


class MagneticFlow(NamedTuple):
    """The exact flow of ``q̇ = M⁻¹p, ṗ = G M⁻¹ p`` over one time step ``ε``.

    ``p ← E p`` and ``q ← q + M⁻¹ (Φ p)`` with ``E = e^{εGM⁻¹}``, ``Φ = ε φ₁(εGM⁻¹)``,
    ``φ₁(X) = Σ_k X^k/(k+1)!``. For ``M = I``: ``p ← e^{εG}p``, ``q ← q + (∫₀^ε e^{sG} ds) p``.
    """

    propagator: jax.Array  # E = e^{εGM⁻¹}, (d, d)
    displacement: jax.Array  # Φ = ε φ₁(εGM⁻¹), (d, d)

    def __call__(self, metric: Metric, position, momentum):
        new_position = position + metric.velocity(self.displacement @ momentum)
        return new_position, self.propagator @ momentum


def magnetic_flow(magnetic_field, metric: Metric, time) -> MagneticFlow:
    """Exact kinetic + magnetic flow over ``time`` from one ``expm`` of a ``2d × 2d`` matrix.

    With ``B = GM⁻¹``: ``expm([[tB, tI], [0, 0]]) = [[e^{tB}, t φ₁(tB)], [0, I]]``. Derivation
    (MATH.md §3 with a mass matrix): ``ṗ = GM⁻¹p`` gives ``p(t) = e^{tB} p``, and
    ``q̇ = M⁻¹p(t)`` integrates to ``q(t) = q + M⁻¹ ∫₀^t e^{sB} ds p = q + M⁻¹ t φ₁(tB) p``.
    The kinetic energy is conserved: ``d/dt ½pᵀM⁻¹p = pᵀM⁻¹GM⁻¹p = 0`` (``G`` antisymmetric),
    and ``E`` is orthogonal when ``M = I``. Valid for singular ``G`` (``G = 0`` gives
    ``E = I``, ``Φ = tI``, the drift of velocity Verlet).
    """
    field = jnp.asarray(magnetic_field)
    if metric.eigenvectors is None:
        b = field * metric.inverse_mass_matrix[None, :]  # G diag(m⁻¹)
    else:
        b = field @ metric.inverse_mass_matrix
    return MagneticFlow(*kinetic_magnetic_exponential(b, time))


# --------------------------------------------------------------------------- default field


def default_magnetic_field(inverse_mass_matrix, strength, covariance=None):
    """The default field ``G = strength · M^{1/2} J̃ M^{1/2}`` and its tuning rule.

    **Orientation.** In the coordinates whitened by the mass matrix (``x = M^{1/2} q``, where the
    adapted ``M⁻¹`` approximates the target's covariance, so the target is near ``N(0, I)``) the
    field is ``strength · J̃`` with ``J̃ = Σ_k (u_k v_kᵀ − v_k u_kᵀ)``, a sum of unit rotations in
    planes spanned by orthonormal pairs ``(u_k, v_k)``. The canonical change of variables
    ``q = M^{-1/2}x, p = M^{1/2}y`` turns ``ṗ = GM⁻¹p`` into ``ẏ = M^{-1/2}GM^{-1/2} y``, hence
    ``G = M^{1/2} (strength·J̃) M^{1/2}``.

    - Without ``covariance``: the pairs are the whitened coordinate axes ``(1, 2), (3, 4), …``.
    - With a ``covariance`` estimate (e.g. of warm-up draws): the principal directions of the
      whitened covariance ``M^{1/2} Σ M^{1/2}``, sorted by variance, paired largest with
      smallest, second largest with second smallest, … — each plane couples a slow direction
      (what the mass matrix missed) with a fast one. With odd ``d`` the median direction is
      left out.

    **Strength (the tuning rule).** ``strength`` is the rotation rate of the whitened velocity
    (rad per unit time); ``strength = 0`` gives plain HMC / underdamped Langevin. What matters
    for a leapfrog trajectory is the angle turned per step, ``strength · step_size``: after
    window adaptation the step size is set by the fastest direction, so a field with a fixed
    angle per step scales with the target's stiffest frequency. Rule: take
    ``strength = angle / step_size`` with ``angle = 0.25`` rad as the default, then compare
    ESS per gradient over a few angles ``{0, 0.25, 0.5, 1}`` on a short run and keep the best
    (``benchmarks/euclidean.py`` does exactly this; ``benchmarks/results/euclidean.json``). Measured
    there (L = 10, diagonal mass from window adaptation, 4 × 2000 draws): on a strongly
    correlated 2-d Gaussian (ρ = 0.99) the best angle, 1, gave 1.5x the ESS per gradient of
    the same kernel without field and 1.8x BlackJAX HMC's; on the rotated 100-d Gaussian
    (κ = 100) and the logistic regression the best angle, 0.25, is within ±20 % of HMC; on the
    banana two runs at 0.25 on different keys gave 1.24x and 0.20x HMC (divergent transitions
    in the stiff tails; the step size is adapted without the field); on Neal's funnel no angle
    helped. Angles ≥ 0.5 cost a factor
    2–100 on the 100-d Gaussian and the logistic regression: a strong field slows the slowest
    modes (the product of the two frequencies of a coupled pair is fixed, their spread grows).
    ``angle = 0`` (plain HMC) is always a safe fallback.

    Parameters
    ----------
    inverse_mass_matrix : array, (d,) or (d, d)
        E.g. the one returned by ``blackjax.window_adaptation``.
    strength : float
        Field strength in the whitened frame (≥ 0).
    covariance : array (d, d), optional
        A covariance estimate of the target; orients the field along its principal directions.

    Returns
    -------
    numpy.ndarray, (d, d)
        An antisymmetric field (exactly: it is built as ``A − Aᵀ``).
    """
    imm = np.asarray(inverse_mass_matrix, dtype=float)
    check_inverse_mass_matrix(imm)
    if isinstance(strength, bool) or np.ndim(strength) != 0 or not np.isfinite(strength):
        raise ValueError(f"strength must be a finite real scalar, got {strength!r}")
    if strength < 0:
        raise ValueError(f"strength must be >= 0, got {strength}")
    d = imm.shape[0]
    if imm.ndim == 1:
        mass_sqrt = np.diag(1.0 / np.sqrt(imm))
    else:
        lam, u = np.linalg.eigh(imm)
        mass_sqrt = (u / np.sqrt(lam)) @ u.T
    if covariance is None:
        basis = np.eye(d)
    else:
        covariance = np.asarray(covariance, dtype=float)
        if covariance.shape != (d, d) or not np.all(np.isfinite(covariance)):
            raise ValueError(
                f"covariance must be a finite ({d}, {d}) matrix, got shape {covariance.shape}"
            )
        whitened = mass_sqrt @ covariance @ mass_sqrt
        lam, u = np.linalg.eigh(0.5 * (whitened + whitened.T))
        order = np.argsort(lam)[::-1]  # largest variance first
        u = u[:, order]
        # interleave: largest, smallest, 2nd largest, 2nd smallest, ...
        idx = []
        lo, hi = 0, d - 1
        while hi - lo >= 1:
            idx += [lo, hi]
            lo, hi = lo + 1, hi - 1
        basis = u[:, idx]
    rotation = np.zeros((d, d))
    for k in range(0, basis.shape[1] - 1, 2):
        a, b = basis[:, k], basis[:, k + 1]
        rotation += np.outer(a, b)
    rotation = rotation - rotation.T
    field = float(strength) * mass_sqrt @ rotation @ mass_sqrt
    return 0.5 * (field - field.T)
