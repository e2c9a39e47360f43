"""Exact Gaussian references for the magnetic samplers (paper, ``sec:brownian-particle``).

- :class:`Gaussian`: a target ``N(mean, covariance)`` with its ``logdensity_fn`` and exact
  moments; :func:`correlated_gaussian` builds test/benchmark instances.
- :func:`ou_drift` / :func:`ou_stationary_covariance` / :func:`ou_cross_covariance`: with
  ``V = ½(q−m)ᵀK(q−m)`` and constant ``G`` the magnetic Langevin SDE is Ornstein–Uhlenbeck,
  ``dz = A z dt + Σ dW`` with ``A = [[0, M⁻¹], [−K, (G − θ)M⁻¹]]``; ``C₀`` solves
  ``A C₀ + C₀Aᵀ + ΣΣᵀ = 0`` (``scipy.linalg.solve_continuous_lyapunov``) and
  ``Cov(z_t, z_0) = e^{At} C₀``.
- :func:`linear_step_moments`: for a step that is affine in the state and the noise (any
  splitting scheme on a Gaussian target), the exact stationary covariance of the *discrete*
  chain, ``C = T C Tᵀ + N Nᵀ``, and its lag-k cross-covariances ``T^k C``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
import scipy.linalg
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float

__all__ = [
    "Gaussian",
    "correlated_gaussian",
    "linear_step_moments",
    "ou_cross_covariance",
    "ou_drift",
    "ou_stationary_covariance",
]


@dataclass(frozen=True)
class Gaussian:
    """``N(mean, covariance)`` on Rᵈ with its log-density (up to a constant).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import Gaussian
    >>> target = Gaussian(np.zeros(2), np.array([[2.0, 1.0], [1.0, 2.0]]))
    >>> target.dimension, float(target.logdensity_fn(jnp.zeros(2)))
    (2, 0.0)
    """

    mean: np.ndarray
    covariance: np.ndarray

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=float)
        cov = np.asarray(self.covariance, dtype=float)
        d = mean.shape[0]
        if mean.ndim != 1 or cov.shape != (d, d):
            raise ValueError(
                f"mean must be (d,) and covariance (d, d), got {mean.shape}, {cov.shape}"
            )
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise ValueError(f"mean and covariance must be finite, got mean {mean}")
        if not np.allclose(cov, cov.T) or np.linalg.eigvalsh(cov).min() <= 0:
            raise ValueError("covariance must be symmetric positive definite")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)

    @property
    def dimension(self) -> int:
        return self.mean.shape[0]

    @property
    def precision(self) -> np.ndarray:
        return np.linalg.inv(self.covariance)

    def logdensity_fn(self, x: ArrayLike) -> jax.Array:
        """``−½(x − m)ᵀ K (x − m)`` (JAX-traceable)."""
        r = jnp.asarray(x) - jnp.asarray(self.mean)
        return -0.5 * r @ (jnp.asarray(self.precision) @ r)

    def second_moments(self) -> np.ndarray:
        """``E[x xᵀ] = Σ + m mᵀ``."""
        return self.covariance + np.outer(self.mean, self.mean)


def correlated_gaussian(
    dimension: int,
    condition_number: float,
    *,
    seed: int = 0,
    rotate: bool = True,
    mean: npt.ArrayLike | None = None,
) -> Gaussian:
    """``N(mean, R diag(λ) Rᵀ)``, ``λ`` log-spaced in ``[1/√κ, √κ]``, ``R`` a random rotation.

    For ``dimension = 2`` the eigenvalues are ``1 ± ρ`` with ``ρ = (κ − 1)/(κ + 1)`` on the
    diagonals at 45°, i.e. unit variances and correlation ``ρ``.

    Examples
    --------
    In two dimensions: unit variances and correlation ``ρ = (κ − 1)/(κ + 1)``:

    >>> import numpy as np
    >>> from liesample.targets import correlated_gaussian
    >>> target = correlated_gaussian(2, condition_number=9.0)
    >>> bool(np.allclose(target.second_moments(), [[1.0, 0.8], [0.8, 1.0]], atol=1e-12))
    True
    """
    if not isinstance(dimension, (int, np.integer)) or isinstance(dimension, bool) or dimension < 1:
        raise ValueError(f"dimension must be an integer >= 1, got {dimension!r}")
    condition_number = finite_float("condition_number", condition_number)
    if condition_number < 1:
        raise ValueError(f"condition_number must be >= 1, got {condition_number}")
    if dimension == 2 and rotate:
        rho = (condition_number - 1.0) / (condition_number + 1.0)
        cov = np.array([[1.0, rho], [rho, 1.0]])
    else:
        lam = np.logspace(-0.5, 0.5, dimension) ** np.log10(condition_number)
        if rotate:
            rng = np.random.default_rng(seed)
            q, r = np.linalg.qr(rng.normal(size=(dimension, dimension)))
            q = q * np.sign(np.diag(r))
            cov = (q * lam) @ q.T
            cov = 0.5 * (cov + cov.T)
        else:
            cov = np.diag(lam)
    mean = np.zeros(dimension) if mean is None else np.asarray(mean, dtype=float)
    return Gaussian(mean, cov)


def ou_drift(
    precision: npt.ArrayLike,
    inverse_mass_matrix: npt.ArrayLike,
    magnetic_field: npt.ArrayLike,
    friction: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(A, ΣΣᵀ)`` of the magnetic Langevin SDE on a Gaussian target (``β = 1``, ``σ² = 2θ``).

    Examples
    --------
    The magnetic Langevin SDE on ``N(0, I₂)``: its stationary covariance is the target's, for
    any field:

    >>> import numpy as np
    >>> from liesample.targets import ou_drift, ou_stationary_covariance
    >>> drift, diffusion = ou_drift(np.eye(2), np.ones(2), np.array([[0.0, 1.0], [-1.0, 0.0]]), 1.0)
    >>> drift.shape, bool(np.allclose(ou_stationary_covariance(drift, diffusion), np.eye(4)))
    ((4, 4), True)
    """
    k = np.atleast_2d(np.asarray(precision, dtype=float))
    d = k.shape[0]
    imm = np.asarray(inverse_mass_matrix, dtype=float)
    minv = np.diag(imm) if imm.ndim == 1 else imm
    g = np.asarray(magnetic_field, dtype=float)
    a = np.block([[np.zeros((d, d)), minv], [-k, (g - friction * np.eye(d)) @ minv]])
    diffusion = np.zeros((2 * d, 2 * d))
    diffusion[d:, d:] = 2.0 * friction * np.eye(d)
    return a, diffusion


def ou_stationary_covariance(drift: npt.ArrayLike, diffusion: npt.ArrayLike) -> np.ndarray:
    """``C₀`` with ``A C₀ + C₀ Aᵀ + ΣΣᵀ = 0``.

    Examples
    --------
    The Ornstein–Uhlenbeck process ``dz = −z dt + √2 dW`` is stationary at ``N(0, 1)``:

    >>> import numpy as np
    >>> from liesample.targets import ou_stationary_covariance
    >>> ou_stationary_covariance(-np.eye(1), 2.0 * np.eye(1))
    array([[1.]])
    """
    c0 = scipy.linalg.solve_continuous_lyapunov(np.asarray(drift), -np.asarray(diffusion))
    return 0.5 * (c0 + c0.T)


def ou_cross_covariance(
    drift: npt.ArrayLike, stationary_covariance: npt.ArrayLike, time: float
) -> np.ndarray:
    """``Cov(z_t, z_0) = e^{At} C₀`` (entry ``[i, j] = Cov(z_i(t), z_j(0))``).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import ou_cross_covariance
    >>> bool(np.allclose(ou_cross_covariance(-np.eye(1), np.eye(1), 1.0), np.exp(-1.0)))
    True
    """
    return scipy.linalg.expm(np.asarray(drift) * time) @ np.asarray(stationary_covariance)


def linear_step_moments(
    transition: npt.ArrayLike, noise: npt.ArrayLike, lags: Sequence[int] = (0, 1)
) -> dict[int, np.ndarray]:
    """Exact stationary moments of the affine chain ``z' = T z + N ξ``, ``ξ ~ N(0, I)``.

    Parameters
    ----------
    transition : (n, n) array ``T`` (spectral radius < 1).
    noise : (n, m) array ``N``.
    lags : lags ``k`` at which to return ``Cov(z_{t+k}, z_t) = T^k C``.

    Returns
    -------
    dict lag -> (n, n) array; lag 0 is the stationary covariance ``C = T C Tᵀ + N Nᵀ``.

    Examples
    --------
    The AR(1) chain ``z' = z/2 + ξ``: variance ``1/(1 − 1/4) = 4/3``, lag-one covariance ``2/3``:

    >>> import numpy as np
    >>> from liesample.targets import linear_step_moments
    >>> moments = linear_step_moments(np.array([[0.5]]), np.array([[1.0]]), lags=(0, 1))
    >>> bool(np.allclose(moments[0], 4 / 3)), bool(np.allclose(moments[1], 2 / 3))
    (True, True)
    """
    t = np.asarray(transition, dtype=float)
    n = np.asarray(noise, dtype=float)
    if np.max(np.abs(np.linalg.eigvals(t))) >= 1.0:
        raise ValueError("transition has spectral radius >= 1: the chain has no stationary law")
    c = scipy.linalg.solve_discrete_lyapunov(t, n @ n.T)
    c = 0.5 * (c + c.T)
    return {k: np.linalg.matrix_power(t, k) @ c for k in lags}
