"""Exact references for laws on spheres and Lie groups (tests of the geometric samplers).

- von Mises–Fisher on ``Sⁿ``: ``p(x) ∝ exp(κ μ·x)`` (uniform base measure); its mean is
  ``A_d(κ) μ`` with ``A_d(κ) = I_{d/2}(κ)/I_{d/2−1}(κ)``, ``d = n + 1``.
- matrix Fisher on ``SO(3)``: ``p(R) ∝ exp(tr(FᵀR))`` (Haar base measure). With the proper
  SVD ``F = U diag(s) Vᵀ`` (``det U = det V = 1``, ``s₃`` signed) the normaliser is the 1-D
  integral ``c(s) = ∫_{−1}^{1} ½ I₀(½(s_i − s_j)(1 − u)) I₀(½(s_i + s_j)(1 + u)) e^{s_k u} du``
  for any permutation ``(i, j, k)`` (the law is a Bingham law on ``S³`` in quaternions), and
  ``E[R] = U diag(∂ log c/∂s) Vᵀ`` with ``∂c/∂s_k = ∫ u K_k(u) du`` (only ``e^{s_k u}`` depends
  on ``s_k`` in the ``k``-th form).
- lattice gauge theories in 2-D with open boundaries: after a maximal-tree gauge fixing the
  plaquette variables are independent, so ``E[cos θ_P] = I₁(β)/I₀(β)`` for U(1) with
  ``S = −β Σ cos θ_P`` and ``E[½ tr U_P] = I₂(β)/I₁(β)`` for SU(2) with
  ``S = −(β/2) Σ tr U_P`` (Haar law of ``½ tr U`` is ``(2/π) sin²α dα``, ``cos α = ½ tr U``).
- the posterior of the mean direction and the log-concentration of von Mises–Fisher data on
  ``S²``, exact by 1-D quadrature over ``η = log κ`` (the direction integrates out in closed
  form: ``∫ e^{κ μ·S} dσ(μ) = sinh(κR)/(κR)``, ``R = |S|``).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping
from types import ModuleType
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike
from scipy import integrate, special

from liesample.foundation.validation import finite_float
from liesample.targets import orbits

__all__ = [
    "MatrixFisherLaw",
    "VonMisesFisherLaw",
    "VonMisesFisherPosterior",
    "quaternion_to_rotation",
    "su2_plaquette_mean",
    "u1_plaquette_mean",
    "vmf_mean_resultant_length",
]


def vmf_mean_resultant_length(kappa: float, d: int) -> float:
    """``A_d(κ) = I_{d/2}(κ)/I_{d/2−1}(κ)``: ``E[μ·x]`` for the vMF law on ``S^{d−1}``.

    Examples
    --------
    >>> from liesample.targets import vmf_mean_resultant_length
    >>> vmf_mean_resultant_length(0.0, 3)  # κ = 0: uniform, E[μ·x] = 0
    0.0
    """
    kappa = finite_float("kappa", kappa, nonnegative=True)
    if kappa == 0.0:
        return 0.0
    return float(special.ive(d / 2.0, kappa) / special.ive(d / 2.0 - 1.0, kappa))


def u1_plaquette_mean(beta: float) -> float:
    """``E[cos θ_P] = I₁(β)/I₀(β)`` (2-D U(1) gauge theory, open boundaries).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import u1_plaquette_mean
    >>> u1_plaquette_mean(0.0), bool(0 < u1_plaquette_mean(1.0) < 1)
    (0.0, True)
    """
    beta = finite_float("beta", beta)
    return float(special.ive(1, beta) / special.ive(0, beta))


def su2_plaquette_mean(beta: float) -> float:
    """``E[½ tr U_P] = I₂(β)/I₁(β)`` (2-D SU(2) gauge theory, open boundaries, β > 0).

    Examples
    --------
    >>> from liesample.targets import su2_plaquette_mean
    >>> bool(0 < su2_plaquette_mean(1.0) < su2_plaquette_mean(4.0) < 1)
    True
    """
    beta = finite_float("beta", beta, positive=True)
    return float(special.ive(2, beta) / special.ive(1, beta))


def _unit_vector(name, value) -> np.ndarray:
    v = np.array(value, dtype=float)
    if v.ndim != 1 or v.size < 2 or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite vector of length >= 2, got {value!r}")
    norm = np.linalg.norm(v)
    if abs(norm - 1.0) > 1e-10:
        raise ValueError(f"{name} must be a unit vector, got norm {norm}")
    return v


@dataclasses.dataclass(frozen=True)
class VonMisesFisherLaw:
    """The exact von Mises–Fisher law ``p(x) ∝ exp(κ μ·x)`` on ``S^{d−1}`` (uniform base law).

    A reference for tests, with closed-form moments; the NumPyro distribution of the same law
    is :class:`liesample.interop.numpyro_distributions.VonMisesFisher`.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import VonMisesFisherLaw
    >>> law = VonMisesFisherLaw(np.array([0.0, 0.0, 1.0]), kappa=2.0)
    >>> bool(np.allclose(law.mean(), [0.0, 0.0, law.mean_resultant_length]))
    True
    """

    mean_direction: np.ndarray
    kappa: float

    def __post_init__(self):
        object.__setattr__(
            self, "mean_direction", _unit_vector("mean_direction", self.mean_direction)
        )
        object.__setattr__(self, "kappa", finite_float("kappa", self.kappa, nonnegative=True))

    @property
    def d(self) -> int:
        return self.mean_direction.size

    def logdensity(self, x: ArrayLike) -> jax.Array:
        """Unnormalised ``κ μ·x`` (jax-traceable)."""
        return self.kappa * jnp.sum(jnp.asarray(self.mean_direction) * x, -1)

    @property
    def mean_resultant_length(self) -> float:
        return vmf_mean_resultant_length(self.kappa, self.d)

    def mean(self) -> np.ndarray:
        return self.mean_resultant_length * self.mean_direction


def _matrix_fisher_kernel(s, k):
    """The integrand ``K_k`` of ``c(s)`` in its ``k``-th form as ``(log_peak, scaled)``:
    ``K_k = e^{log_peak} · scaled(1 − u, 1 + u)``, ``log_peak`` the largest exponent of
    ``I₀ I₀ e^{s_k u}`` (the exponent ``a + b + s_k u`` is linear in ``u``, largest at an end
    point), so ``scaled ≤ 1``. ``scaled`` takes ``1 ∓ u`` themselves, never their difference
    from ``±1``: the integrand's boundary layers, of width down to ``1/max|s|``, sit there."""
    i, j = [m for m in range(3) if m != k]
    half_difference, half_sum = 0.5 * abs(s[i] - s[j]), 0.5 * abs(s[i] + s[j])
    slope = half_sum - half_difference + s[k]  # d(a + b + s_k u)/du
    log_peak = max(2.0 * half_sum + s[k], 2.0 * half_difference - s[k])  # at u = 1, u = −1

    def scaled(one_minus_u, one_plus_u):
        decay = slope * one_minus_u if slope >= 0.0 else -slope * one_plus_u
        bessels = special.ive(0, half_difference * one_minus_u)
        return 0.5 * bessels * special.ive(0, half_sum * one_plus_u) * np.exp(-decay)

    return log_peak, scaled


def _end_layer_edges(s) -> np.ndarray:
    """Break points ``t`` of ``[0, 1]``, ``t`` the distance ``1 ∓ u`` from an end point of
    ``[−1, 1]``: for large singular values ``K_k`` varies on scales down to ``1/max|s|`` next to
    ``u = ±1`` (the decay of its exponential away from the peak, ``I₀``'s ``O(1)`` argument
    range), far below what one adaptive rule on the whole interval resolves (a layer of width
    ``1e−4`` falls between its nodes and its mass is lost). The pieces shrink geometrically,
    by 4, down to below ``1e−3/max|s|``."""
    scale = 1.0 + 2.0 * float(np.max(np.abs(s)))
    depth = max(int(np.ceil(np.log(1e3 * scale) / np.log(4.0))), 1)
    return np.concatenate([[0.0], 4.0 ** -np.arange(depth, -1, -1)])  # 0, 4^−depth, …, 1


@dataclasses.dataclass(frozen=True)
class MatrixFisherLaw:
    """The exact matrix Fisher law ``p(R) ∝ exp(tr(FᵀR))`` on ``SO(3)`` (Haar base measure).

    A reference for tests; the NumPyro distribution of the same law is
    :class:`liesample.interop.numpyro_distributions.MatrixFisher`.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import MatrixFisherLaw
    >>> law = MatrixFisherLaw(np.eye(3))
    >>> R = law.sample(jax.random.key(0), 3)  # exact i.i.d. rotations
    >>> R.shape, bool(jnp.allclose(jnp.linalg.det(R), 1.0))
    ((3, 3, 3), True)
    """

    F: np.ndarray

    def __post_init__(self):
        F = np.array(self.F, dtype=float)
        if F.shape != (3, 3) or not np.all(np.isfinite(F)):
            raise ValueError(f"F must be a finite 3x3 matrix, got {self.F!r}")
        object.__setattr__(self, "F", F)

    def proper_svd(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(U, s, V)`` with ``F = U diag(s) Vᵀ``, ``U, V ∈ SO(3)``."""
        u, s, vt = np.linalg.svd(self.F)
        v = vt.T
        det_u, det_v = np.sign(np.linalg.det(u)), np.sign(np.linalg.det(v))
        s = s * np.array([1.0, 1.0, det_u * det_v])
        return u * np.array([1.0, 1.0, det_u]), s, v * np.array([1.0, 1.0, det_v])

    def _integrals(self, s, k):
        """``(z, dz, log_peak)``: ``c = z e^{log_peak}``, ``∂c/∂s_k = dz e^{log_peak}`` (the
        ``k``-th form, :func:`_matrix_fisher_kernel`), by adaptive quadrature on each half of
        ``[−1, 1]`` in the distance ``t`` from its end point, piece by piece
        (:func:`_end_layer_edges`)."""
        log_peak, scaled = _matrix_fisher_kernel(s, k)

        def right(t, power):  # u = 1 − t
            return (1.0 - t) ** power * scaled(t, 2.0 - t)

        def left(t, power):  # u = t − 1
            return (t - 1.0) ** power * scaled(2.0 - t, t)

        edges = _end_layer_edges(s)
        opts = {"epsabs": 1e-300, "epsrel": 1e-13, "limit": 100}  # scaled integrand <= 1
        z = dz = 0.0
        for half in (right, left):
            for lo, hi in itertools.pairwise(edges):
                z += integrate.quad(half, lo, hi, args=(0,), **opts)[0]
                dz += integrate.quad(half, lo, hi, args=(1,), **opts)[0]
        return z, dz, log_peak

    def log_normalizer(self) -> float:
        """``log ∫_{SO(3)} exp(tr(FᵀR)) dR`` (Haar probability measure; 0 for ``F = 0``)."""
        _, s, _ = self.proper_svd()
        z, _, shift = self._integrals(s, 2)
        return float(np.log(z) + shift)

    def mean(self) -> np.ndarray:
        """``E[R] = U diag(∂ log c/∂s) Vᵀ``."""
        u, s, v = self.proper_svd()
        diag = []
        for k in range(3):
            z, dz, _ = self._integrals(s, k)
            diag.append(dz / z)
        return u @ np.diag(diag) @ v.T

    def logdensity(self, R: ArrayLike) -> jax.Array:
        return jnp.sum(jnp.asarray(self.F) * R, axis=(-2, -1))

    def quaternion_form(self) -> np.ndarray:
        """``B`` (4 × 4, symmetric) with ``tr(FᵀR(q)) = qᵀBq`` for unit quaternions ``q``: the
        law of ``±q`` is the Bingham law ``∝ exp(qᵀBq)`` on ``S³`` (Haar on SO(3) is uniform on
        ``S³`` modulo ``±``). ``R(q)`` is a homogeneous quadratic, so ``B`` is read off by
        polarisation."""
        basis = np.eye(4)

        def form(q):
            return float(np.sum(self.F * quaternion_to_rotation(q, xp=np)))

        diagonal = np.array([form(e) for e in basis])
        B = np.diag(diagonal)
        for i in range(4):
            for j in range(i + 1, 4):
                B[i, j] = B[j, i] = 0.5 * (form(basis[i] + basis[j]) - diagonal[i] - diagonal[j])
        return B

    def sample(self, rng_key: jax.Array, num_samples: int) -> jax.Array:
        """Exact i.i.d. rotations ``(num_samples, 3, 3)``: Bingham draws of the quaternion
        (:meth:`quaternion_form`, angular-central-Gaussian rejection, acceptance ≳ 45 %)."""
        eigenvalues, eigenvectors = np.linalg.eigh(self.quaternion_form())
        x, _ = orbits.sample_bingham(rng_key, -eigenvalues, num_samples)
        return cast(jax.Array, quaternion_to_rotation(x @ jnp.asarray(eigenvectors).T))


def quaternion_to_rotation(
    q: jax.Array | np.ndarray, xp: ModuleType = jnp
) -> jax.Array | np.ndarray:
    """The rotation of a unit quaternion ``(w, x, y, z)`` (``±q`` give the same one); the
    entries are homogeneous quadratics in ``q``. Leading axes broadcast; ``xp=numpy`` computes
    it eagerly (also inside a trace).

    Examples
    --------
    >>> from liesample.targets import quaternion_to_rotation
    >>> quaternion_to_rotation(jnp.array([1.0, 0.0, 0.0, 0.0]))  # the identity
    Array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]], dtype=float64)
    """
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ]
    return xp.stack([xp.stack(row, -1) for row in rows], -2)


def _log_vmf_normalizer_s2(kappa):
    """``log(κ/sinh κ)``: minus the log normaliser of vMF on S² (uniform base law)."""
    kappa = np.asarray(kappa, dtype=float)
    return np.log(2.0 * kappa) - kappa - np.log1p(-np.exp(-2.0 * kappa))


@dataclasses.dataclass(frozen=True)
class VonMisesFisherPosterior:
    """Posterior of ``(μ, η = log κ)`` for iid vMF data ``x_1…x_N`` on ``S²``.

    Prior: ``μ`` uniform on ``S²``, ``η ~ N(prior_mean, prior_sd²)``. The log-density with
    respect to uniform × Lebesgue is ``N log(κ/sinh κ) + κ μ·S + log N(η)``, ``S = Σ x_i``.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import VonMisesFisherPosterior
    >>> posterior = VonMisesFisherPosterior(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
    >>> position = {"direction": jnp.array([0.0, 0.0, 1.0]), "log_kappa": jnp.array(0.0)}
    >>> posterior.logdensity(position).shape
    ()
    """

    data: np.ndarray
    prior_mean: float = 0.0
    prior_sd: float = 1.0

    def __post_init__(self):
        x = np.array(self.data, dtype=float)
        if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] < 1:
            raise ValueError(f"data must be an (N, 3) array of unit vectors, got {x.shape}")
        if not np.allclose(np.linalg.norm(x, axis=1), 1.0, atol=1e-10, rtol=0.0):
            raise ValueError("data must be unit vectors")
        object.__setattr__(self, "data", x)
        finite_float("prior_mean", self.prior_mean)
        finite_float("prior_sd", self.prior_sd, positive=True)

    @property
    def resultant(self) -> np.ndarray:
        return self.data.sum(0)

    def logdensity(self, position: Mapping[str, jax.Array]) -> jax.Array:
        """``position = {"direction": unit 3-vector, "log_kappa": scalar}`` (jax-traceable)."""
        mu, eta = position["direction"], position["log_kappa"]
        kappa = jnp.exp(eta)
        n = self.data.shape[0]
        log_c = jnp.log(2.0 * kappa) - kappa - jnp.log1p(-jnp.exp(-2.0 * kappa))
        prior = -0.5 * ((eta - self.prior_mean) / self.prior_sd) ** 2
        return n * log_c + kappa * jnp.dot(mu, jnp.asarray(self.resultant)) + prior

    def _log_marginal(self, eta):
        """Unnormalised log-density of ``η`` (``μ`` integrated out)."""
        kappa = np.exp(eta)
        r = np.linalg.norm(self.resultant)
        kr = kappa * r
        log_sinhc = kr + np.log1p(-np.exp(-2.0 * kr)) - np.log(2.0 * kr)  # log(sinh(κR)/(κR))
        prior = -0.5 * ((eta - self.prior_mean) / self.prior_sd) ** 2
        return self.data.shape[0] * _log_vmf_normalizer_s2(kappa) + log_sinhc + prior

    def expectations(self) -> dict[str, float | np.ndarray]:
        """``E[η]``, ``Var[η]``, ``E[μ]`` (vector) by adaptive quadrature over ``η``."""
        # Locate the bulk of the η-marginal (much narrower than the prior) on a fine grid.
        half_width = 12.0 * self.prior_sd
        grid = np.linspace(self.prior_mean - half_width, self.prior_mean + half_width, 20001)
        logp = self._log_marginal(grid)
        shift = logp.max()
        bulk = grid[logp > shift - 40.0]
        lo, hi = bulk.min(), bulk.max()

        def integral(f):
            return integrate.quad(
                lambda e: f(e) * np.exp(self._log_marginal(e) - shift),
                lo,
                hi,
                epsabs=0.0,
                epsrel=1e-12,
                limit=400,
            )[0]

        z = integral(lambda e: 1.0)
        mean_eta = integral(lambda e: e) / z
        var_eta = integral(lambda e: (e - mean_eta) ** 2) / z
        r = np.linalg.norm(self.resultant)
        # Given κ, μ is vMF(S/R, κR): E[μ | κ] = A_3(κR) S/R.
        a = integral(lambda e: vmf_mean_resultant_length(np.exp(e) * r, 3)) / z
        return {
            "log_kappa": mean_eta,
            "log_kappa_var": var_eta,
            "direction": a * self.resultant / r,
        }
