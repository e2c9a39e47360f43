"""liesample.foundation.special (log I_ν in JAX) and the von Mises–Fisher normaliser built on it:
against SciPy to round-off on a log grid κ ∈ [1e-8, 1e5], first and second derivatives against
the Bessel identities evaluated with SciPy, ``jax.hessian`` of a vMF log_prob, no host callback.
The order is an argument of the compiled functions, not a constant: all orders share compiles."""

import inspect

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from liesample.foundation.special import (
    bessel_iv_ratio,
    log_bessel_i0,
    log_bessel_iv,
    log_bessel_iv_reduced,
    log_bessel_ive,
)

# κ = 0, a log grid, and the switch between the series and Debye's expansion at κ = 25.
KAPPA = np.concatenate([[0.0], np.geomspace(1e-8, 1e5, 400), np.linspace(24.0, 26.0, 21)])
ORDERS = [0.0, 0.5, 1.0, 1.5, 4.0, 2.3, 49.0]  # d = 2, 3, 4, 5, 10; a fractional and a large ν


def _everything(order, k):
    first = jax.vmap(jax.grad(lambda x: log_bessel_iv(order, x)))(k)
    second = jax.vmap(jax.hessian(lambda x: log_bessel_iv(order, x)))(k)
    return (log_bessel_iv(order, k), log_bessel_ive(order, k), log_bessel_iv_reduced(order, k),
            bessel_iv_ratio(order, k), first, second)  # fmt: skip


@pytest.mark.parametrize("order", ORDERS)
def test_log_bessel_and_its_derivatives_match_scipy_to_round_off(order):
    """Values to ~1e−13 relative. Derivatives: ``(log I_ν)' = R + ν/κ`` and
    ``(log I_ν)'' = 1 − (2ν+1)R/κ − R² − ν/κ²``, ``R = I_{ν+1}/I_ν`` (from
    ``I_ν' = I_{ν+1} + (ν/κ) I_ν``, ``I_{ν+1}' = I_ν − ((ν+1)/κ) I_{ν+1}``)."""
    ok = special.ive(order + 1.0, KAPPA) > 1e-280  # κ > 0 where SciPy does not underflow
    k = KAPPA[ok]
    log_ive = np.log(special.ive(order, k))
    log_iv = log_ive + k
    ratio = special.ive(order + 1.0, k) / special.ive(order, k)
    out = [np.asarray(a)[ok] for a in _everything(order, KAPPA)]
    assert np.all(np.abs(out[0] - log_iv) <= 1e-13 * np.maximum(1.0, np.abs(log_iv)))
    assert np.allclose(out[1], log_ive, rtol=1e-13, atol=1e-13)
    power = order * np.log(k / 2.0) - special.gammaln(order + 1.0)
    scale = 1.0 + np.abs(log_iv) + np.abs(power)  # the reference's own cancellation
    assert np.all(np.abs(out[2] - (log_iv - power)) <= 1e-13 * scale)
    assert np.allclose(out[3], ratio, rtol=1e-12, atol=0.0)
    assert np.allclose(out[4], ratio + order / k, rtol=1e-12, atol=0.0)
    terms = (1.0, (2 * order + 1) * ratio / k, ratio**2, order / k**2)
    # The identity cancels to O(1/κ²) for large κ: SciPy's own error is ~1e−16 × the terms.
    exact = terms[0] - terms[1] - terms[2] - terms[3]
    assert np.all(np.abs(out[5] - exact) <= 1e-12 * sum(np.abs(t) for t in terms))


def test_closed_forms_and_the_limit_at_zero():
    """Through the functions compiled above (same grid): ``I_{1/2}(κ) = √(2/(πκ)) sinh κ``;
    at ``κ = 0`` the reduced function and the ratio vanish, ``log I₀`` has slope 0 and
    curvature 1/2, ``log I₁ = −inf``."""
    k = (KAPPA > 1e-3) & (KAPPA < 700.0)
    half = np.asarray(_everything(0.5, KAPPA)[0])[k]
    exact = 0.5 * np.log(2 / (np.pi * KAPPA[k])) + np.log(np.sinh(KAPPA[k]))
    assert np.allclose(half, exact, rtol=1e-14)
    for order in (0.0, 1.0, 4.0):
        log_iv, _, reduced, ratio, first, second = (float(a[0]) for a in _everything(order, KAPPA))
        assert reduced == 0.0 and ratio == 0.0
        assert log_iv == (0.0 if order == 0.0 else -np.inf)
        if order == 0.0:
            assert first == 0.0 and second == 0.5
    # The fast log I₀ (quadrature rules): values, I₁/I₀ and its derivative 1 − R/κ − R².
    k = KAPPA[1:]
    ratio = special.ive(1.0, k) / special.ive(0.0, k)
    assert np.allclose(log_bessel_i0(k), np.log(special.ive(0.0, k)) + k, rtol=1e-13, atol=1e-15)
    slope = np.asarray(jax.vmap(jax.grad(log_bessel_i0))(KAPPA))
    curvature = np.asarray(jax.vmap(jax.hessian(log_bessel_i0))(KAPPA))
    assert slope[0] == 0.0 and curvature[0] == 0.5
    assert np.allclose(slope[1:], ratio, rtol=1e-13, atol=0.0)
    assert np.allclose(curvature[1:], 1.0 - ratio / k - ratio**2, rtol=1e-9, atol=1e-15)
    with pytest.raises(ValueError, match="order must be >= 0"):
        log_bessel_iv(-1.0, 2.0)


# ---------------------------------------------------------------------- the vMF distribution

pytest.importorskip("numpyro")
from liesample.interop import numpyro_distributions
from liesample.interop.numpyro_distributions import VonMisesFisher


def _vmf(d, k):
    mu = jnp.zeros(d).at[0].set(1.0)
    log_c = lambda x: VonMisesFisher(mu, x).log_normalizer()
    mean = jax.vmap(lambda x: VonMisesFisher(mu, x).mean[0])(k)
    return jax.vmap(log_c)(k), jax.vmap(jax.grad(log_c))(k), mean


@pytest.mark.parametrize("d", [2, 3, pytest.param(4, marks=pytest.mark.slow), 5, 10])
def test_vmf_normaliser_matches_scipy_and_its_derivatives(d):
    k = np.concatenate([[0.0], np.geomspace(1e-8, 1e5, 200)])
    log_c, slope, mean = (np.asarray(a) for a in _vmf(d, k))
    nu, kp = d / 2.0 - 1.0, k[1:]
    expected = nu * np.log(kp) - (d / 2.0) * np.log(2 * np.pi) - np.log(special.ive(nu, kp)) - kp
    assert np.all(np.abs(log_c[1:] - expected) <= 1e-13 * np.maximum(1.0, np.abs(expected)))
    # d/dκ log C_d = ν/κ − (log I_ν)' = −R, R = I_{d/2}/I_{d/2−1} = E[μ·x].
    ratio = special.ive(d / 2.0, kp) / special.ive(nu, kp)
    assert np.allclose(slope[1:], -ratio, rtol=1e-12, atol=0.0)
    assert np.allclose(mean[1:], ratio, rtol=1e-12, atol=0.0)
    # κ = 0: the uniform law, −log|S^{d−1}| = log Γ(d/2) − log 2 − (d/2) log π; slope 0.
    uniform = special.gammaln(d / 2.0) - np.log(2.0) - (d / 2.0) * np.log(np.pi)
    assert log_c[0] == pytest.approx(uniform, rel=1e-15, abs=1e-15)
    assert slope[0] == 0.0 and mean[0] == 0.0


def test_vmf_log_prob_has_a_hessian_in_kappa_and_no_callback():
    mu = jnp.array([0.0, 0.6, 0.8])
    x = jnp.array([0.0, 1.0, 0.0])
    kappa = jnp.array([1e-6, 0.05, 3.0, 80.0])
    hess = jax.jit(jax.vmap(jax.hessian(lambda k: VonMisesFisher(mu, k).log_prob(x))))(kappa)
    # d²/dκ² log C_3(κ) = 1/sinh²κ − 1/κ² (closed form on S²; −1/3 + κ²/15 near 0).
    k = np.asarray(kappa)
    exact = np.where(k > 1e-3, 1.0 / np.sinh(k) ** 2 - 1.0 / k**2, -1.0 / 3.0 + k**2 / 15.0)
    assert np.allclose(hess, exact, rtol=1e-8, atol=1e-12)
    d5 = jnp.array([0.0, 0.0, 0.6, 0.0, 0.8])
    hess = jax.jit(jax.hessian(lambda k: VonMisesFisher(d5, k).log_prob(d5)))(2.5)
    ratio = special.ive(2.5, 2.5) / special.ive(1.5, 2.5)
    exact = -(1.0 - 4.0 * ratio / 2.5 - ratio**2)  # −R' with ν = 3/2
    assert float(hess) == pytest.approx(exact, rel=1e-12)
    jaxpr = str(jax.make_jaxpr(lambda k: VonMisesFisher(d5, k).log_prob(d5))(2.5))
    assert "callback" not in jaxpr
    assert "pure_callback" not in inspect.getsource(numpyro_distributions)


@pytest.mark.parametrize("order", [0.5, 49.0])
def test_huge_concentrations_stay_finite_and_right(order):
    """Beyond κ ≈ 1e154, κ² overflows float64: the ratio is 1 and log(I_ν(κ)e^{−κ}) is
    −½ log(2πκ) to round-off (the leading term of the asymptotic series; the next is ~1/κ)."""
    kappa = jnp.array([1e160, 1e200, 1e300])
    assert np.all(np.asarray(bessel_iv_ratio(order, kappa)) == 1.0)
    np.testing.assert_allclose(
        log_bessel_ive(order, kappa), -0.5 * np.log(2.0 * np.pi * np.asarray(kappa)), rtol=1e-15
    )
    grad = jax.vmap(jax.grad(lambda x: log_bessel_ive(order, x)))(kappa)
    assert np.all(np.isfinite(np.asarray(grad)))
