"""NumPyro distributions on spheres and SO(3): ``VonMisesFisher``, ``Bingham``, ``MatrixFisher``.

An optional integration module (NumPyro is not a dependency of the core: install it with
``pip install 'liesample[numpyro]'``). Use these distributions in a NumPyro model sampled by
:class:`liesample.interop.numpyro_kernel.GeometricHMC` (NumPyro's own samplers move in unconstrained
``Rᵈ`` and cannot stay on a sphere or a group), or their ``log_prob`` inside a ``logdensity_fn``
for :func:`liesample.geometric_hmc`, or their exact ``sample`` to simulate data. Their supports
are NumPyro's ``constraints.sphere`` (shared with ``ProjectedNormal``) and :data:`rotation`.

- ``VonMisesFisher(mean_direction, concentration)`` on ``S^{d−1}`` (``κ = 0``: uniform): density
  ``C_d(κ) exp(κ μ·x)`` with respect to the surface measure, ``C_d(κ) = κ^{d/2−1} /
  ((2π)^{d/2} I_{d/2−1}(κ))`` (as ``scipy.stats.vonmises_fisher``); differentiable in ``μ``
  and ``κ`` (``log I_ν`` through SciPy's ``ive`` with its exact derivative). ``sample``: exact;
  on ``S²`` the closed-form inverse of the cosine's distribution function
  (:func:`liesample.targets.spins.von_mises_fisher`), on other spheres Wood's (1994) rejection
  algorithm.
- ``Bingham(concentration, orientation=None)`` on ``S²``: density
  ``exp(−Σ_i λ_i (v_i·x)²) / Z(λ)`` with respect to the surface measure, ``v_i`` the columns of
  the rotation ``orientation`` (identity by default); ``Z(λ)`` is the exact 1-D quadrature of
  :func:`liesample.targets.orbits.bingham_log_normalizer`, differentiable in ``λ`` (which may
  be a model parameter). ``sample``: exact, by rejection from an angular central Gaussian
  envelope (:func:`liesample.targets.orbits.sample_bingham`).
- ``MatrixFisher(F)`` on SO(3): density ``exp(tr(FᵀR)) / c(F)`` with respect to the Haar
  probability measure; ``c(F)`` by the 1-D Bessel integral of
  :class:`liesample.targets.groups.MatrixFisherLaw`, so ``F`` must be concrete (not a traced model
  parameter). ``sample``: exact; the quaternion of ``R`` follows a Bingham law on ``S³``, drawn
  by the same angular-central-Gaussian rejection (acceptance ≳ 45 % for any ``F``).

The rejection samplers are loops vmapped over draws, compiled with :func:`liesample.jit`
(XLA:CPU miscompiles small vmapped while loops otherwise; see ``liesample.foundation.compile``).
"""

from __future__ import annotations

try:
    import numpyro  # noqa: F401
    from numpyro.distributions import Distribution, constraints
except ImportError as error:  # an optional integration module
    raise ImportError(
        "liesample.interop.numpyro_distributions needs NumPyro: "
        "pip install 'liesample[numpyro]' (or pip install numpyro)"
    ) from error

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy import special

from liesample.foundation.compile import jit
from liesample.geometry.spaces import SO
from liesample.targets import groups, orbits
from liesample.targets.spins import von_mises_fisher

__all__ = ["Bingham", "MatrixFisher", "VonMisesFisher", "log_bessel_iv", "rotation"]


# --------------------------------------------------------------------------- log I_ν(κ)


def _log_ive_host(order, kappa):
    return np.log(special.ive(order, kappa)).astype(kappa.dtype)


def _ratio_host(order, kappa):
    return (special.ive(order + 1.0, kappa) / special.ive(order, kappa)).astype(kappa.dtype)


def _callback(fn, order, kappa):
    kappa = jnp.asarray(kappa)
    shape = jax.ShapeDtypeStruct(kappa.shape, kappa.dtype)
    return jax.pure_callback(
        lambda k: fn(order, np.asarray(k)), shape, kappa, vmap_method="broadcast_all"
    )


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _log_iv(order, kappa):
    return _callback(_log_ive_host, order, kappa) + kappa


@_log_iv.defjvp
def _log_iv_jvp(order, primals, tangents):
    (kappa,) = primals
    (dkappa,) = tangents
    # d/dκ log I_ν(κ) = I_{ν+1}(κ)/I_ν(κ) + ν/κ.
    slope = _callback(_ratio_host, order, kappa) + order / kappa
    return _log_iv(order, kappa), slope * dkappa


def log_bessel_iv(order: float, kappa):
    """``log I_ν(κ)`` for a fixed order ``ν ≥ 0`` and ``κ > 0``, differentiable in ``κ``."""
    return _log_iv(float(order), kappa)


# --------------------------------------------------------------------------- vMF


def _householder_to(mean_direction, x):
    """Apply the reflection that maps the last basis vector to ``mean_direction``."""
    d = mean_direction.shape[-1]
    e = jnp.zeros(d).at[-1].set(1.0)
    u = e - mean_direction
    norm2 = jnp.sum(u * u, -1, keepdims=True)
    safe = jnp.where(norm2 > 1e-30, norm2, 1.0)
    reflected = x - 2.0 * u * jnp.sum(u * x, -1, keepdims=True) / safe
    return jnp.where(norm2 > 1e-30, reflected, x)


def _wood_cosine(key, kappa, d):
    """One draw of ``w = μ·x`` (Wood 1994): Beta proposal, exact rejection."""
    m = d - 1.0
    b = m / (2.0 * kappa + jnp.sqrt(4.0 * kappa**2 + m**2))  # stable form of Wood's b
    x0 = (1.0 - b) / (1.0 + b)
    c = kappa * x0 + m * jnp.log(1.0 - x0**2)

    def body(state):
        key, _, _ = state
        key, k1, k2 = jax.random.split(key, 3)
        z = jax.random.beta(k1, m / 2.0, m / 2.0, dtype=kappa.dtype)
        w = (1.0 - (1.0 + b) * z) / (1.0 - (1.0 - b) * z)
        u = jax.random.uniform(k2, (), kappa.dtype)
        accept = kappa * w + m * jnp.log(1.0 - x0 * w) - c >= jnp.log(u)
        return key, w, accept

    _, w, _ = jax.lax.while_loop(lambda s: ~s[2], body, (key, jnp.zeros_like(kappa), False))
    return w


class VonMisesFisher(Distribution):
    """von Mises–Fisher law on the unit sphere ``S^{d−1}`` (module docstring)."""

    arg_constraints = {
        "mean_direction": constraints.sphere,
        "concentration": constraints.nonnegative,
    }
    support = constraints.sphere

    def __init__(self, mean_direction, concentration, *, validate_args=None):
        mean_direction = jnp.asarray(mean_direction)
        concentration = jnp.asarray(concentration, dtype=jnp.result_type(mean_direction, float))
        if mean_direction.ndim < 1 or mean_direction.shape[-1] < 2:
            raise ValueError(
                f"mean_direction must be a unit vector of length d >= 2, got shape "
                f"{mean_direction.shape}"
            )
        batch_shape = jax.lax.broadcast_shapes(mean_direction.shape[:-1], concentration.shape)
        event_shape = mean_direction.shape[-1:]
        self.mean_direction = jnp.broadcast_to(mean_direction, batch_shape + event_shape)
        self.concentration = jnp.broadcast_to(concentration, batch_shape)
        super().__init__(batch_shape, mean_direction.shape[-1:], validate_args=validate_args)

    @property
    def d(self) -> int:
        return self.event_shape[0]

    def log_normalizer(self):
        """``log C_d(κ)`` (surface measure); at ``κ = 0`` the uniform law's ``−log |S^{d−1}|``."""
        nu = self.d / 2.0 - 1.0
        kappa = self.concentration
        # Below 1e-8 the series C_d(κ) = C_d(0) (1 − A κ² + …) is C_d(0) to round-off.
        small = kappa < 1e-8
        safe = jnp.where(small, 1.0, kappa)
        log_2pi = jnp.log(2 * jnp.pi)
        general = nu * jnp.log(safe) - (self.d / 2.0) * log_2pi - log_bessel_iv(nu, safe)
        uniform = special.gammaln(self.d / 2.0) - np.log(2.0) - (self.d / 2.0) * np.log(np.pi)
        return jnp.where(small, uniform, general)

    def log_prob(self, value):
        return self.log_normalizer() + self.concentration * jnp.sum(
            self.mean_direction * value, -1
        )

    @property
    def mean(self):
        nu = self.d / 2.0 - 1.0
        ratio = jnp.exp(log_bessel_iv(nu + 1.0, self.concentration)
                        - log_bessel_iv(nu, self.concentration))
        return ratio[..., None] * self.mean_direction

    def sample(self, key, sample_shape=()):
        shape = tuple(sample_shape) + self.batch_shape
        kappa = jnp.broadcast_to(self.concentration, shape)
        mean = jnp.broadcast_to(self.mean_direction, shape + (self.d,))
        if self.d == 3:  # closed form on S²
            return von_mises_fisher(key, mean, kappa)
        k_w, k_v = jax.random.split(key)
        keys = jax.random.split(k_w, max(int(np.prod(shape)), 1))[: int(np.prod(shape))]
        w = jit(jax.vmap(lambda k, c: _wood_cosine(k, c, float(self.d))))(
            keys, kappa.reshape(-1)
        ).reshape(shape)
        v = jax.random.normal(k_v, shape + (self.d - 1,), kappa.dtype)
        v = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
        x = jnp.concatenate([jnp.sqrt(jnp.clip(1.0 - w**2, 0.0))[..., None] * v, w[..., None]], -1)
        return _householder_to(mean, x)


# --------------------------------------------------------------------------- matrix Fisher


class _RotationConstraint(constraints.Constraint):
    event_dim = 2

    def __call__(self, x):
        gram = jnp.swapaxes(x, -1, -2) @ x
        ok = jnp.all(jnp.abs(gram - jnp.eye(3)) < 1e-6, axis=(-2, -1))
        return ok & (jnp.abs(jnp.linalg.det(x) - 1.0) < 1e-6)

    def feasible_like(self, prototype):
        return jnp.broadcast_to(jnp.eye(3), prototype.shape)


rotation = _RotationConstraint()


class Bingham(Distribution):
    """Bingham law on ``S²``, ``∝ exp(−Σ_i λ_i (v_i·x)²)`` w.r.t. area (module docstring).

    ``concentration`` (``..., 3``): ``λ``, any finite reals (only differences matter);
    ``orientation`` (``..., 3, 3``): a rotation whose columns are the axes ``v_i`` (identity by
    default). Antipodally symmetric: the mean is 0; :meth:`second_moment` is ``E[x xᵀ]``.
    """

    arg_constraints = {"concentration": constraints.real_vector, "orientation": rotation}
    support = constraints.sphere

    def __init__(self, concentration, orientation=None, *, validate_args=None):
        concentration = jnp.asarray(concentration, dtype=jnp.result_type(concentration, float))
        if concentration.ndim < 1 or concentration.shape[-1] != 3:
            raise ValueError(
                "concentration must have shape (..., 3) (the three λ_i of a Bingham law on "
                f"S²), got shape {concentration.shape}"
            )
        if orientation is None:
            orientation = jnp.eye(3, dtype=concentration.dtype)
        orientation = jnp.asarray(orientation, dtype=concentration.dtype)
        if orientation.ndim < 2 or orientation.shape[-2:] != (3, 3):
            raise ValueError(
                f"orientation must be a rotation matrix of shape (..., 3, 3), got shape "
                f"{orientation.shape}"
            )
        batch_shape = jax.lax.broadcast_shapes(concentration.shape[:-1], orientation.shape[:-2])
        self.concentration = jnp.broadcast_to(concentration, batch_shape + (3,))
        self.orientation = jnp.broadcast_to(orientation, batch_shape + (3, 3))
        super().__init__(batch_shape, (3,), validate_args=validate_args)

    def log_normalizer(self):
        """``log Z(λ)``, ``Z = ∫_{S²} exp(−Σ λ_i x_i²) dA`` (exact quadrature)."""
        return jnp.vectorize(orbits.bingham_log_normalizer, signature="(3)->()")(
            self.concentration
        )

    def log_prob(self, value):
        y = jnp.einsum("...j,...ji->...i", value, self.orientation)  # y_i = v_i·x
        return -jnp.sum(self.concentration * y * y, -1) - self.log_normalizer()

    @property
    def mean(self):
        return jnp.zeros(self.batch_shape + (3,), self.concentration.dtype)

    def second_moment(self):
        """``E[x xᵀ] = V diag(E[y_i²]) Vᵀ`` with ``E[y_i²] = −∂ log Z/∂λ_i`` (exact)."""
        moments = jnp.vectorize(orbits.bingham_second_moments, signature="(3)->(3)")(
            self.concentration
        )
        return jnp.einsum("...ik,...k,...jk->...ij", self.orientation, moments, self.orientation)

    def sample(self, key, sample_shape=()):
        shape = tuple(sample_shape)
        n = max(int(np.prod(shape)), 1)
        lam = self.concentration.reshape(-1, 3)
        keys = jax.random.split(key, lam.shape[0])
        y = jax.vmap(lambda k, c: orbits.sample_bingham(k, c, n)[0])(keys, lam)  # (batch, n, 3)
        y = jnp.swapaxes(y, 0, 1)[: int(np.prod(shape))]
        y = y.reshape(shape + self.batch_shape + (3,))
        return jnp.einsum("...ij,...j->...i", self.orientation, y)


class MatrixFisher(Distribution):
    """Matrix Fisher law on SO(3), ``∝ exp(tr(FᵀR))`` w.r.t. Haar (module docstring)."""

    arg_constraints = {}
    support = rotation

    def __init__(self, F, *, validate_args=None):
        F = np.asarray(F, dtype=float)
        self._reference = groups.MatrixFisherLaw(F)  # validates: a finite 3x3 matrix
        self.F = jnp.asarray(F)
        self._log_c = self._reference.log_normalizer()
        super().__init__((), (3, 3), validate_args=validate_args)

    def log_prob(self, value):
        return jnp.sum(self.F * value, axis=(-2, -1)) - self._log_c

    @property
    def mean(self):
        return jnp.asarray(self._reference.mean())

    def sample(self, key, sample_shape=()):
        """Exact draws: the quaternion's Bingham law on S³ (``targets.groups.MatrixFisherLaw``)."""
        shape = tuple(sample_shape)
        n = max(int(np.prod(shape)), 1)
        draws = self._reference.sample(key, n)
        return draws[: int(np.prod(shape))].reshape(shape + (3, 3))


SO3 = SO(3)  # the space MatrixFisher lives on, for liesample.geometric_hmc
