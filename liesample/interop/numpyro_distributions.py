"""NumPyro distributions on spheres and SO(3): ``VonMisesFisher``, ``Bingham``, ``MatrixFisher``.

An optional integration module (NumPyro is not a dependency of the core: install it with
``pip install 'liesample[numpyro]'``). Use these distributions in a NumPyro model sampled by
:class:`liesample.interop.numpyro_kernel.GeometricHMC` (NumPyro's own samplers move in unconstrained
``Rᵈ`` and cannot stay on a sphere or a group), or their ``log_prob`` inside a ``logdensity_fn``
for :func:`liesample.geometric_hmc`, or their exact ``sample`` to simulate data. Their supports
are NumPyro's ``constraints.sphere`` (shared with ``ProjectedNormal``) and :data:`rotation`.

Every parameter may be traced: a latent concentration, a parameter computed inside the model,
a ``jit`` or ``vmap`` over the parameters. Normalisers are pure JAX (no host callback) and
differentiable in the parameters. Values are checked (with an error that names the parameter)
only when they are concrete; traced values are not checked, as with NumPyro's ``validate_args``.
With ``validate_args=True`` (or NumPyro's validation enabled), ``log_prob`` checks its value as
NumPyro's ``ProjectedNormal`` does: the wrong event shape raises ``ValueError``; a concrete value
off the support (not a unit vector, not a rotation) warns "Out-of-support values", and the
density is still the formula's (a sampler's state carries round-off off the manifold). A
likelihood's log-density is evaluated only traced, where nothing is checked: the kernel
:class:`liesample.interop.numpyro_kernel.GeometricHMC` checks every observed site's concrete
value against its distribution's support at ``init`` (:func:`check_observed_sites`) and raises
naming the site. ``infer_shapes`` gives ``(batch_shape, event_shape)`` from the parameters' shapes.

- ``VonMisesFisher(mean_direction, concentration)`` on ``S^{d−1}`` (``κ = 0``: uniform): density
  ``C_d(κ) exp(κ μ·x)`` with respect to the surface measure, ``C_d(κ) = κ^{d/2−1} /
  ((2π)^{d/2} I_{d/2−1}(κ))`` (as ``scipy.stats.vonmises_fisher``). On ``S²`` the closed form
  ``C_3(κ) = κ / (4π sinh κ)``, in logs ``log κ − log 2π − κ − log(1 − e^{−2κ})`` and a series in
  ``κ²`` near 0; on other spheres the Bessel function of :mod:`liesample.foundation.special`.
  Both are exact at ``κ = 0`` and differentiable in ``κ`` to any order (``jax.hessian``).
  ``sample``: exact; on ``S²`` the closed-form inverse of the cosine's distribution function
  (:func:`liesample.targets.spins.von_mises_fisher`), on other spheres Wood's (1994) rejection
  algorithm.
- ``Bingham(concentration, orientation=None)`` on ``S²``: density
  ``exp(−Σ_i λ_i (v_i·x)²) / Z(λ)`` with respect to the surface measure, ``v_i`` the columns of
  the rotation ``orientation`` (identity by default); ``Z(λ)`` is the exact 1-D quadrature of
  :func:`liesample.targets.orbits.bingham_log_normalizer`, differentiable in ``λ``.
  ``sample``: exact, by rejection from an angular central Gaussian envelope
  (:func:`liesample.targets.orbits.sample_bingham`).
- ``MatrixFisher(F)`` on SO(3): density ``exp(tr(FᵀR)) / c(F)`` with respect to the Haar
  probability measure. With the proper SVD ``F = U diag(s) Vᵀ`` (``U, V ∈ SO(3)``,
  ``s₁ ≥ s₂ ≥ |s₃|``, computed by ``jnp.linalg.svd``), ``c`` is the 1-D integral of
  :class:`liesample.targets.groups.MatrixFisherLaw`,
  ``c(s) = ½ ∫_{−1}^{1} I₀(½(s₁−s₂)(1−u)) I₀(½(s₁+s₂)(1+u)) e^{s₃u} du``, evaluated in logs by
  a fixed tanh-sinh rule (its nodes crowd double-exponentially onto the end points, where the
  integrand's boundary layers sit for large ``s``). ``∂ log c/∂F = E[R] = U diag(∂ log c/∂s) Vᵀ``
  is well defined also for repeated singular values (``F = κ I``), where the SVD's own
  derivative is not: the gradient in ``F`` is written this way. ``sample``: exact; the
  quaternion of ``R`` follows a Bingham law on ``S³``, drawn by the same angular-central-Gaussian
  rejection (acceptance ≳ 45 % for any ``F``).

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

import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import i0e, logsumexp

from liesample.foundation.compile import jit
from liesample.foundation.special import (
    bessel_iv_ratio,
    log_bessel_i0,
    log_bessel_iv,
    log_bessel_iv_reduced,
    log_bessel_ive,
)
from liesample.foundation.validation import concrete_array, single_key
from liesample.geometry.spaces import SO
from liesample.targets import groups, orbits
from liesample.targets.spins import von_mises_fisher

__all__ = [
    "Bingham",
    "MatrixFisher",
    "VonMisesFisher",
    "check_observed_sites",
    "log_bessel_iv",
    "rotation",
]


def _check_finite(name, value):
    """``ValueError`` when a concrete ``value`` has a non-finite entry (tracers pass)."""
    concrete = concrete_array(value)
    if concrete is not None and not np.all(np.isfinite(concrete)):
        raise ValueError(f"{name} must be finite, got {concrete}")
    return concrete


def _real_array(name: str, value, requirement: str):
    """``value`` as a real floating JAX array (integers are cast to float; a tracer keeps its
    floating dtype), or a ``TypeError`` naming ``name``: bool, complex, string and ragged inputs
    are refused (only the dtype is read, so a traced parameter is checked too)."""
    if not isinstance(value, jax.Array):
        try:
            value = np.asarray(value)
        except (TypeError, ValueError):  # a ragged list, an object numpy cannot hold
            raise TypeError(
                f"{name} must be {requirement} of real numbers, got {value!r}: pass a rectangular "
                "float array (np.asarray(..., dtype=float) must accept it)"
            ) from None
    dtype = value.dtype
    if not (jnp.issubdtype(dtype, jnp.floating) or jnp.issubdtype(dtype, jnp.integer)):
        fix = "its real part, np.real(...), when the imaginary part is 0" if jnp.issubdtype(
            dtype, jnp.complexfloating) else "floats, e.g. 1.0"  # fmt: skip
        raise TypeError(f"{name} must be {requirement} of real numbers (float or int), got "
                        f"dtype {dtype}: pass {fix}")  # fmt: skip
    return jnp.asarray(value, dtype=jnp.result_type(value, float))


def _broadcast_batch(**batch_shapes) -> tuple:
    """The common batch shape of the parameters, or a ``ValueError`` naming them all."""
    try:
        return jax.lax.broadcast_shapes(*batch_shapes.values())
    except ValueError:
        shapes = ", ".join(f"{name} {shape}" for name, shape in batch_shapes.items())
        raise ValueError(
            f"the parameters' batch shapes do not broadcast: {shapes}; give batch shapes that "
            "broadcast (equal, or 1 / absent along an axis), e.g. one shared scalar parameter"
        ) from None


def _one_key(key):
    """``key`` of a ``sample`` call as one typed JAX key, or an error that says what to pass."""
    return single_key(key, "key", batch_fix="draw several samples with sample_shape instead")


def _check_value(distribution, value):
    """Under ``validate_args``, NumPyro's checks of a ``log_prob`` value as ``ProjectedNormal``
    makes them: ``ValueError`` when ``value`` does not end in the event shape, a warning when a
    concrete value is off the support. The density itself is left as the formula: a sampler's
    state carries round-off off the sphere or the group, which must not turn into ``−inf``."""
    if distribution._validate_args:
        event_shape = tuple(jnp.shape(value)[jnp.ndim(value) - len(distribution.event_shape) :])
        if event_shape != distribution.event_shape:
            raise ValueError(
                f"value must have the event shape {distribution.event_shape} of "
                f"{type(distribution).__name__}, got shape {jnp.shape(value)}"
            )
        distribution._validate_sample(value)


def _validating(distribution) -> bool:
    """Whether ``distribution`` (or the distribution a NumPyro wrapper holds) validates."""
    while distribution is not None:
        if getattr(distribution, "_validate_args", False):
            return True
        distribution = getattr(distribution, "base_dist", None)
    return False


def check_observed_sites(trace) -> None:
    """``ValueError`` naming the first observed site of a model ``trace`` (NumPyro's
    ``handlers.trace``) whose distribution validates (``validate_args=True``, or NumPyro's
    validation enabled) and whose concrete value is off that distribution's support.

    NumPyro checks values only where ``log_prob`` sees them concrete; a sampler evaluates the
    likelihood traced, so an observation off the sphere (or a matrix that is not a rotation)
    would otherwise be sampled against without a word. Traced observations are not checked.

    Examples
    --------
    An observation off the sphere is refused, naming the site:

    >>> import numpyro
    >>> from numpyro import handlers
    >>> from liesample.numpyro import VonMisesFisher, check_observed_sites
    >>> def model():
    ...     law = VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 2.0, validate_args=True)
    ...     numpyro.sample("x", law, obs=jnp.array([1.0, 1.0, 0.0]))
    >>> check_observed_sites(handlers.trace(handlers.seed(model, 0)).get_trace())
    Traceback (most recent call last):
    ValueError: observed site 'x': its value is off the support of VonMisesFisher (Sphere) ...
    """
    for name, site in trace.items():
        if site["type"] != "sample" or not site["is_observed"] or not _validating(site["fn"]):
            continue
        value = concrete_array(site["value"])
        if value is None:
            continue
        inside = np.asarray(site["fn"].support(value))
        if np.all(inside):
            continue
        support = site["fn"].support
        bad = tuple(int(i) for i in np.unravel_index(int(np.argmax(~inside)), inside.shape))
        raise ValueError(
            f"observed site {name!r}: its value is off the support of "
            f"{type(site['fn']).__name__} ({type(support).__name__.strip('_')}) at "
            f"{int(np.sum(~inside))} of {inside.size} point(s), the first at batch index {bad}: "
            f"{value[bad]} (checked as the distribution validates: validate_args). Its "
            "log-density would be evaluated there as if it were inside; give data inside the "
            f"support: {_support_fix(support)}"
        )


def _support_fix(support) -> str:
    if support is constraints.sphere:
        return "unit vectors, e.g. x / np.linalg.norm(x, axis=-1, keepdims=True)"
    if support is rotation:
        return "rotation matrices (RᵀR = I, det R = 1), e.g. the polar factor U Vᵀ of R's SVD"
    return f"values where support(value) is True ({support})"


# --------------------------------------------------------------------------- vMF

# log(sinh κ / κ) = Σ_n 2^{2n} B_{2n} κ^{2n} / (2n (2n)!): the coefficients of κ², …, κ¹⁰.
_LOG_SINHC = (1.0 / 6.0, -1.0 / 180.0, 1.0 / 2835.0, -1.0 / 37800.0, 1.0 / 467775.0)
_SINHC_SWITCH = 0.1  # the first omitted term (κ¹²) is below 1e−18 there


def _log_vmf_normalizer_s2(kappa, reduced: bool):
    """``log(κ / (4π sinh κ))`` (``+ κ`` if ``reduced``), exact to round-off for every ``κ ≥ 0``
    (``−log 4π`` at 0)."""
    small = kappa < _SINHC_SWITCH
    k_small = jnp.where(small, kappa, 0.0)
    k_large = jnp.where(small, 1.0, kappa)
    k2 = k_small * k_small
    log_sinhc = jnp.zeros_like(k2)
    for c in reversed(_LOG_SINHC):
        log_sinhc = (log_sinhc + c) * k2
    series = -math.log(4.0 * math.pi) - log_sinhc + (k_small if reduced else 0.0)
    closed = jnp.log(k_large) - math.log(2.0 * math.pi) - jnp.log(-jnp.expm1(-2.0 * k_large))
    return jnp.where(small, series, closed if reduced else closed - k_large)


def _log_vmf_normalizer(kappa, d: int, reduced: bool = False):
    """``log C_d(κ)``, or with ``reduced`` ``log C_d(κ) + κ``: ``log_prob`` adds ``κ (μ·x − 1)``
    to the latter, so that ``log C_d(κ) ≈ −κ`` and ``κ μ·x ≈ κ`` never cancel (at ``κ = 1e200``
    they would leave nothing), and ``log_normalizer`` takes the former, so that its slope
    ``−A_d(κ)`` keeps its digits at small ``κ``. With ``ν = d/2 − 1``, ``log C_d(κ) = log Γ(d/2)
    + ν log 2 − (d/2) log 2π − log[Γ(ν+1)(κ/2)^{−ν} I_ν(κ)]``: below ``κ = 25`` the reduced
    Bessel function (no ``log κ`` term, so ``κ = 0`` is exact), above it
    ``log(I_ν(κ) e^{−κ})``, where nothing grows with ``κ``."""
    if d == 3:
        return _log_vmf_normalizer_s2(kappa, reduced)
    nu = d / 2.0 - 1.0
    constant = math.lgamma(d / 2.0) + nu * math.log(2.0) - (d / 2.0) * math.log(2.0 * math.pi)
    small = kappa <= 25.0
    k_small, k_large = jnp.where(small, kappa, 0.0), jnp.where(small, 50.0, kappa)
    series = constant - log_bessel_iv_reduced(nu, k_small) + (k_small if reduced else 0.0)
    large = (constant - math.lgamma(nu + 1.0) + nu * jnp.log(0.5 * k_large)
             - log_bessel_ive(nu, k_large))  # fmt: skip
    return jnp.where(small, series, large if reduced else large - k_large)


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
    """von Mises–Fisher law on the unit sphere ``S^{d−1}`` (module docstring).

    Examples
    --------
    >>> from liesample.numpyro import VonMisesFisher
    >>> law = VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 2.0)
    >>> x = law.sample(jax.random.key(0), (5,))
    >>> x.shape, bool(jnp.allclose(jnp.linalg.norm(x, axis=-1), 1.0))
    ((5, 3), True)
    """

    arg_constraints: ClassVar[dict] = {
        "mean_direction": constraints.sphere,
        "concentration": constraints.nonnegative,
    }
    support = constraints.sphere

    def __init__(self, mean_direction, concentration, *, validate_args=None):
        mean_direction = _real_array("mean_direction", mean_direction, "a unit vector")
        concentration = _real_array("concentration", concentration, "a scalar (or an array)")
        concentration = concentration.astype(mean_direction.dtype)
        if mean_direction.ndim < 1 or mean_direction.shape[-1] < 2:
            raise ValueError(
                f"mean_direction must be a unit vector of length d >= 2, got shape "
                f"{mean_direction.shape}"
            )
        direction = _check_finite("mean_direction", mean_direction)
        if direction is not None and np.any(np.abs(np.linalg.norm(direction, axis=-1) - 1) > 1e-6):
            raise ValueError(
                f"mean_direction must be a unit vector, got norm "
                f"{np.linalg.norm(direction, axis=-1)}"
            )
        kappa = _check_finite("concentration", concentration)
        if kappa is not None and np.any(kappa < 0):
            raise ValueError(f"concentration must be >= 0, got {kappa}")
        batch_shape = _broadcast_batch(
            mean_direction=mean_direction.shape[:-1], concentration=concentration.shape
        )
        event_shape = mean_direction.shape[-1:]
        self.mean_direction = jnp.broadcast_to(mean_direction, batch_shape + event_shape)
        self.concentration = jnp.broadcast_to(concentration, batch_shape)
        super().__init__(batch_shape, mean_direction.shape[-1:], validate_args=validate_args)

    @property
    def d(self) -> int:
        return self.event_shape[0]

    def log_normalizer(self):
        """``log C_d(κ)`` (surface measure); at ``κ = 0`` the uniform law's ``−log |S^{d−1}|``."""
        return _log_vmf_normalizer(self.concentration, self.d)

    @classmethod
    def infer_shapes(cls, mean_direction=(), concentration=()):
        batch_shape = jax.lax.broadcast_shapes(tuple(mean_direction)[:-1], tuple(concentration))
        return batch_shape, tuple(mean_direction)[-1:]

    def log_prob(self, value):
        _check_value(self, value)
        # log C + κ μ·x as (log C + κ) + κ (μ·x − 1): no cancellation of two terms ≈ κ.
        cosine_gap = jnp.sum(self.mean_direction * value, -1) - 1.0
        reduced = _log_vmf_normalizer(self.concentration, self.d, reduced=True)
        return reduced + self.concentration * cosine_gap

    @property
    def mean(self):
        """``A_d(κ) μ``, ``A_d = I_{d/2}/I_{d/2−1}``."""
        ratio = bessel_iv_ratio(self.d / 2.0 - 1.0, self.concentration)
        return ratio[..., None] * self.mean_direction

    def sample(self, key, sample_shape=()):
        key = _one_key(key)
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
    """The support of :class:`MatrixFisher` (``rotation``): ``3 × 3`` matrices with ``RᵀR = I``
    and ``det R = 1`` (to ``1e-6``).

    Examples
    --------
    >>> from liesample.numpyro import rotation
    >>> bool(rotation(jnp.eye(3))), bool(rotation(2.0 * jnp.eye(3)))
    (True, False)
    """

    event_dim = 2

    def __call__(self, x):
        concrete = concrete_array(x)  # a concrete value is checked in NumPy: nothing compiled
        xp, x = (jnp, x) if concrete is None else (np, concrete)
        gram = xp.swapaxes(x, -1, -2) @ x
        ok = xp.all(xp.abs(gram - xp.eye(3)) < 1e-6, axis=(-2, -1))
        return ok & (xp.abs(xp.linalg.det(x) - 1.0) < 1e-6)

    def feasible_like(self, prototype):
        return jnp.broadcast_to(jnp.eye(3), prototype.shape)


rotation = _RotationConstraint()


class Bingham(Distribution):
    """Bingham law on ``S²``, ``∝ exp(−Σ_i λ_i (v_i·x)²)`` w.r.t. area (module docstring).

    ``concentration`` (``..., 3``): ``λ``, any finite reals (only differences matter);
    ``orientation`` (``..., 3, 3``): a rotation whose columns are the axes ``v_i`` (identity by
    default). Antipodally symmetric: the mean is 0; :meth:`second_moment` is ``E[x xᵀ]``.

    Examples
    --------
    >>> from liesample.numpyro import Bingham
    >>> law = Bingham(jnp.array([0.0, 1.0, 4.0]))
    >>> x = law.sample(jax.random.key(0), (3,))
    >>> x.shape, bool(jnp.isclose(jnp.trace(law.second_moment()), 1.0))  # E|x|² = 1
    ((3, 3), True)
    """

    arg_constraints: ClassVar[dict] = {
        "concentration": constraints.real_vector,
        "orientation": rotation,
    }
    support = constraints.sphere

    def __init__(self, concentration, orientation=None, *, validate_args=None):
        concentration = _real_array("concentration", concentration, "a (..., 3) array")
        if concentration.ndim < 1 or concentration.shape[-1] != 3:
            raise ValueError(
                "concentration must have shape (..., 3) (the three λ_i of a Bingham law on "
                f"S²), got shape {concentration.shape}"
            )
        _check_finite("concentration", concentration)
        if orientation is None:
            orientation = jnp.eye(3, dtype=concentration.dtype)
        orientation = _real_array("orientation", orientation, "a (..., 3, 3) rotation matrix")
        orientation = orientation.astype(concentration.dtype)
        if orientation.ndim < 2 or orientation.shape[-2:] != (3, 3):
            raise ValueError(
                f"orientation must be a rotation matrix of shape (..., 3, 3), got shape "
                f"{orientation.shape}"
            )
        frame = _check_finite("orientation", orientation)
        if frame is not None and not np.all(rotation(frame)):
            raise ValueError(f"orientation must be a rotation matrix (RᵀR = I, det R = 1), "
                             f"got {frame}")  # fmt: skip
        batch_shape = _broadcast_batch(
            concentration=concentration.shape[:-1], orientation=orientation.shape[:-2]
        )
        self.concentration = jnp.broadcast_to(concentration, batch_shape + (3,))
        self.orientation = jnp.broadcast_to(orientation, batch_shape + (3, 3))
        super().__init__(batch_shape, (3,), validate_args=validate_args)

    def log_normalizer(self):
        """``log Z(λ)``, ``Z = ∫_{S²} exp(−Σ λ_i x_i²) dA`` (exact quadrature)."""
        return jnp.vectorize(orbits.bingham_log_normalizer, signature="(3)->()")(self.concentration)

    @classmethod
    def infer_shapes(cls, concentration=(3,), orientation=None):
        frame = () if orientation is None else tuple(orientation)[:-2]
        return jax.lax.broadcast_shapes(tuple(concentration)[:-1], frame), (3,)

    def log_prob(self, value):
        _check_value(self, value)
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
        key = _one_key(key)
        shape = tuple(sample_shape)
        n = max(int(np.prod(shape)), 1)
        lam = self.concentration.reshape(-1, 3)
        keys = jax.random.split(key, lam.shape[0])
        y = jax.vmap(lambda k, c: orbits.sample_bingham(k, c, n)[0])(keys, lam)  # (batch, n, 3)
        y = jnp.swapaxes(y, 0, 1)[: int(np.prod(shape))]
        y = y.reshape(shape + self.batch_shape + (3,))
        return jnp.einsum("...ij,...j->...i", self.orientation, y)


def _tanh_sinh_rule(step: float, half_width: float):
    """Nodes of the tanh-sinh rule on ``[−1, 1]`` as ``(1 − u, 1 + u, log w)``, each computed
    without cancellation (``1 − u`` reaches ``1e−60``: the end points' layers are resolved)."""
    t = np.arange(-half_width, half_width + 0.5 * step, step)
    y = 0.5 * np.pi * np.sinh(t)
    one_minus = 2.0 / (np.exp(2.0 * y) + 1.0)
    one_plus = 2.0 / (1.0 + np.exp(-2.0 * y))
    log_cosh = np.abs(y) + np.log1p(np.exp(-2.0 * np.abs(y))) - np.log(2.0)
    log_weight = np.log(step * 0.5 * np.pi * np.cosh(t)) - 2.0 * log_cosh
    return one_minus, one_plus, log_weight


# Step 1/32 on |t| ≤ 4.5 (289 nodes), on each of two pieces of ``[−1, 1]`` (see _log_c_reduced):
# the nodes, dense in log(1 ∓ u), come within 1e−60 of the ends, so the end points' integrable
# layers (width ~1/(s₁ ± s₂)) stay resolved.
_ONE_MINUS_U, _ONE_PLUS_U, _LOG_WEIGHT = _tanh_sinh_rule(1.0 / 32.0, 4.5)
_LAYER = 45.0  # e^{−45} < 3e−20: past w = 45/(s₂ + s₃) the integrand is below round-off


@jax.custom_jvp
def _log_i0e(y):
    """``log(I₀(y) e^{−y})`` for ``y ≥ 0`` without the cancellation of ``log I₀(y) − y``; its
    derivative ``I₁/I₀ − 1`` (``−1`` at ``y = 0``), and the higher ones, from ``log_bessel_i0``."""
    return jnp.log(i0e(y))


@_log_i0e.defjvp
def _log_i0e_jvp(primals, tangents):
    (y,), (dy,) = primals, tangents
    _, ratio = jax.jvp(log_bessel_i0, (y,), (jnp.ones_like(y),))
    return _log_i0e(y), (ratio - 1.0) * dy


def _proper_svd(F):
    """``(U, s, V)`` with ``F = U diag(s) Vᵀ``, ``U, V ∈ SO(3)``, ``s₁ ≥ s₂ ≥ |s₃|`` (JAX)."""
    u, s, vt = jnp.linalg.svd(F)
    v = vt.T
    sign_u, sign_v = jnp.sign(jnp.linalg.det(u)), jnp.sign(jnp.linalg.det(v))
    last = jnp.array([0.0, 0.0, 1.0], F.dtype)
    flip_u, flip_v = 1.0 + (sign_u - 1.0) * last, 1.0 + (sign_v - 1.0) * last
    return u * flip_u, s * flip_u * flip_v, v * flip_v


def _log_c_reduced(s):
    """``log c(s) − (s₁ + s₂ + s₃)`` for proper singular values ``s₁ ≥ s₂ ≥ |s₃|`` (module
    docstring), with no cancellation however large ``s`` is.

    In ``w = 1 − u`` the reduced integrand is ``I₀e(½(s₁−s₂)w) I₀e(½(s₁+s₂)(2−w)) e^{−(s₂+s₃)w}``
    (``I₀e(y) = e^{−y} I₀(y)``; every factor ≤ 1). The exponential's layer at ``w = 0``, of width
    ``1/(s₂+s₃)``, is too thin for the nodes once ``s₂ + s₃`` is large, so the rule is applied on
    ``[0, h]`` and on ``[h, 2]``, ``h = min(1, 45/(s₂+s₃))``: the layer then spans the first
    piece and the second holds round-off."""
    dtype = s.dtype
    one_minus, one_plus = jnp.asarray(_ONE_MINUS_U, dtype), jnp.asarray(_ONE_PLUS_U, dtype)
    decay = s[1] + s[2]
    h = jax.lax.stop_gradient(_LAYER / jnp.maximum(decay, _LAYER))  # the integral's own split
    # [0, h]: w = h(1−u)/2; [h, 2]: w = h + (2−h)(1−u)/2 and 2 − w = (2−h)(1+u)/2, no cancellation
    w = jnp.concatenate([0.5 * h * one_minus, h + (1.0 - 0.5 * h) * one_minus])
    rest = jnp.concatenate([2.0 - 0.5 * h * one_minus, (1.0 - 0.5 * h) * one_plus])
    log_weight = jnp.asarray(_LOG_WEIGHT, dtype)
    log_weight = jnp.concatenate([log_weight + jnp.log(0.5 * h), log_weight + jnp.log1p(-0.5 * h)])
    log_integrand = (_log_i0e(0.5 * (s[0] - s[1]) * w) + _log_i0e(0.5 * (s[0] + s[1]) * rest)
                     - decay * w)  # fmt: skip
    return logsumexp(log_weight + log_integrand) - math.log(2.0)


@jax.custom_jvp
def _matrix_fisher_log_normalizer_parts(F):
    """``(s₁ + s₂ + s₃, log c(F) − (s₁ + s₂ + s₃))``: ``log_prob`` subtracts the first from
    ``tr(FᵀR)`` before the second, so that two terms ≈ ``|F|`` never cancel (at ``F = 1e100 I``
    they would leave nothing)."""
    s = _proper_svd(F)[1]
    return jnp.sum(s), _log_c_reduced(s)


@_matrix_fisher_log_normalizer_parts.defjvp
def _matrix_fisher_log_normalizer_parts_jvp(primals, tangents):
    # ds_k = (Uᵀ dF V)_kk and d log c = tr(E[R]ᵀ dF) = Σ_k ∂_k log c(s) ds_k: defined for
    # repeated singular values too (differentiating the SVD itself is not).
    (F,), (dF,) = primals, tangents
    u, s, v = _proper_svd(F)
    value, slope = jax.value_and_grad(_log_c_reduced)(s)
    ds = jnp.diagonal(u.T @ dF @ v)
    return (jnp.sum(s), value), (jnp.sum(ds), jnp.sum(slope * ds))


def _matrix_fisher_log_normalizer(F):
    total, reduced = _matrix_fisher_log_normalizer_parts(F)
    return total + reduced


def _matrix_fisher_mean(F):
    """``E[R] = U diag(∂ log c/∂s) Vᵀ``, ``∂ log c/∂s = 1 + ∂(log c − Σ s)/∂s``."""
    u, s, v = _proper_svd(F)
    return (u * (1.0 + jax.grad(_log_c_reduced)(s))) @ v.T


def _quaternion_basis() -> np.ndarray:
    """``M`` (3, 3, 4, 4) with ``R(q)_ab = qᵀ M_ab q``: ``R(q)`` is a homogeneous quadratic in the
    quaternion, read off by polarisation."""
    basis = np.eye(4)
    M = np.zeros((3, 3, 4, 4))
    for i in range(4):
        M[:, :, i, i] = groups.quaternion_to_rotation(basis[i], xp=np)
    for i in range(4):
        for j in range(i + 1, 4):
            polar = groups.quaternion_to_rotation(basis[i] + basis[j], xp=np)
            M[:, :, i, j] = M[:, :, j, i] = 0.5 * (polar - M[:, :, i, i] - M[:, :, j, j])
    return M


_QUATERNION_BASIS = _quaternion_basis()


def _sample_matrix_fisher(key, F, num_samples: int):
    """Exact draws ``(num_samples, 3, 3)`` for a (possibly traced) ``F``: ``tr(FᵀR(q)) = qᵀBq``,
    so ``±q`` is Bingham on ``S³`` (as :meth:`liesample.targets.groups.MatrixFisherLaw.sample`)."""
    B = jnp.einsum("ab,abij->ij", F, jnp.asarray(_QUATERNION_BASIS, F.dtype))
    eigenvalues, eigenvectors = jnp.linalg.eigh(B)
    x, _ = orbits.sample_bingham(key, -eigenvalues, num_samples)
    return groups.quaternion_to_rotation(x @ eigenvectors.T)


class MatrixFisher(Distribution):
    """Matrix Fisher law on SO(3), ``∝ exp(tr(FᵀR))`` w.r.t. Haar (module docstring).

    ``F`` (``..., 3, 3``): any finite real matrices, possibly traced; leading axes are the
    batch.

    Examples
    --------
    >>> from liesample.numpyro import MatrixFisher
    >>> R = MatrixFisher(jnp.eye(3)).sample(jax.random.key(0), (2,))  # two rotations
    >>> R.shape, bool(jnp.allclose(jnp.linalg.det(R), 1.0))
    ((2, 3, 3), True)
    """

    arg_constraints: ClassVar[dict] = {"F": constraints.independent(constraints.real, 2)}
    support = rotation

    def __init__(self, F, *, validate_args=None):
        F = _real_array("F", F, "a 3x3 matrix (or a batch (..., 3, 3))")
        if F.ndim < 2 or F.shape[-2:] != (3, 3):
            raise ValueError(f"F must be a finite 3x3 matrix (or a batch (..., 3, 3)), got "
                             f"shape {F.shape}")  # fmt: skip
        _check_finite("F", F)
        self.F = F
        super().__init__(F.shape[:-2], (3, 3), validate_args=validate_args)

    def log_normalizer(self):
        """``log c(F) = log ∫_{SO(3)} exp(tr(FᵀR)) dR`` (Haar probability; 0 at ``F = 0``)."""
        return jnp.vectorize(_matrix_fisher_log_normalizer, signature="(3,3)->()")(self.F)

    @classmethod
    def infer_shapes(cls, F=(3, 3)):
        return tuple(F)[:-2], (3, 3)

    def log_prob(self, value):
        _check_value(self, value)
        total, reduced = jnp.vectorize(
            _matrix_fisher_log_normalizer_parts, signature="(3,3)->(),()"
        )(self.F)
        return (jnp.sum(self.F * value, axis=(-2, -1)) - total) - reduced

    @property
    def mean(self):
        """``E[R] = U diag(∂ log c/∂s) Vᵀ`` (exact)."""
        return jnp.vectorize(_matrix_fisher_mean, signature="(3,3)->(3,3)")(self.F)

    def sample(self, key, sample_shape=()):
        """Exact draws: the quaternion's Bingham law on S³ (``targets.groups.MatrixFisherLaw``)."""
        key = _one_key(key)
        shape = tuple(sample_shape)
        count = int(np.prod(shape))
        n = max(count, 1)
        concrete = concrete_array(self.F)
        if concrete is not None and not self.batch_shape:  # the reference's own draws
            draws = groups.MatrixFisherLaw(concrete).sample(key, n)
            return draws[:count].reshape(shape + (3, 3))
        flat = self.F.reshape(-1, 3, 3)
        keys = jax.random.split(key, flat.shape[0])
        draws = jax.vmap(lambda k, f: _sample_matrix_fisher(k, f, n))(keys, flat)
        draws = jnp.swapaxes(draws, 0, 1)[:count]  # (count, batch, 3, 3)
        return draws.reshape(shape + self.batch_shape + (3, 3))


SO3 = SO(3)  # the space MatrixFisher lives on, for liesample.geometric_hmc
