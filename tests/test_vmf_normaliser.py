"""liesample.foundation.special (log I_ν in JAX) and the von Mises–Fisher normaliser built on it:
against SciPy to round-off on a log grid κ ∈ [1e-8, 1e5], first and second derivatives against
the Bessel identities evaluated with SciPy, ``jax.hessian`` of a vMF log_prob, no host callback."""

import inspect

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from liesample.foundation.special import (
    bessel_iv_ratio,
    log_bessel_iv,
    log_bessel_iv_reduced,
    log_bessel_ive,
)

KAPPA = np.concatenate([np.geomspace(1e-8, 1e5, 600), np.linspace(24.0, 26.0, 41)])  # + switch
ORDERS = [0.0, 0.5, 1.0, 1.5, 4.0, 2.3, 12.5, 49.0]  # d = 2, 3, 4, 5, 10; fractional; large


def _scipy(order, kappa):
    """SciPy's ``log(I_ν e^{−κ})``, ``R = I_{ν+1}/I_ν``, kept where ``ive`` does not underflow."""
    ok = special.ive(order + 1.0, kappa) > 1e-280
    k = kappa[ok]
    log_ive = np.log(special.ive(order, k))
    return k, log_ive, special.ive(order + 1.0, k) / special.ive(order, k)


@pytest.mark.parametrize("order", ORDERS)
def test_log_bessel_matches_scipy_to_round_off(order):
    k, log_ive, ratio = _scipy(order, KAPPA)
    log_iv = log_ive + k
    out = np.asarray(log_bessel_iv(order, k))
    assert np.all(np.abs(out - log_iv) <= 1e-13 * np.maximum(1.0, np.abs(log_iv)))
    assert np.allclose(log_bessel_ive(order, k), log_ive, rtol=1e-13, atol=1e-13)
    power = order * np.log(k / 2.0) - special.gammaln(order + 1.0)
    scale = 1.0 + np.abs(log_iv) + np.abs(power)  # the reference's own cancellation
    assert np.all(np.abs(log_bessel_iv_reduced(order, k) - (log_iv - power)) <= 1e-13 * scale)
    assert np.allclose(bessel_iv_ratio(order, k), ratio, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("order", ORDERS)
def test_first_and_second_derivatives_are_the_bessel_identities(order):
    """``(log I_ν)' = R + ν/κ`` and ``(log I_ν)'' = 1 − (2ν+1)R/κ − R² − ν/κ²``, ``R = I_{ν+1}/I_ν``
    (from ``I_ν' = I_{ν+1} + (ν/κ) I_ν``, ``I_{ν+1}' = I_ν − ((ν+1)/κ) I_{ν+1}``)."""
    k, _, ratio = _scipy(order, KAPPA)
    first = jax.vmap(jax.grad(lambda x: log_bessel_iv(order, x)))(k)
    assert np.allclose(first, ratio + order / k, rtol=1e-12, atol=0.0)
    second = np.asarray(jax.vmap(jax.hessian(lambda x: log_bessel_iv(order, x)))(k))
    terms = (1.0, (2 * order + 1) * ratio / k, ratio**2, order / k**2)
    exact = terms[0] - terms[1] - terms[2] - terms[3]
    # The identity cancels to O(1/κ²) for large κ: SciPy's own error is ~1e−16 × the terms.
    assert np.all(np.abs(second - exact) <= 1e-12 * sum(np.abs(t) for t in terms))


def test_closed_forms_and_the_limit_at_zero():
    k = np.geomspace(1e-3, 700.0, 50)
    # I_{1/2}(κ) = √(2/(πκ)) sinh κ, exactly.
    assert np.allclose(
        log_bessel_iv(0.5, k), 0.5 * np.log(2 / (np.pi * k)) + np.log(np.sinh(k)), rtol=1e-14
    )
    for order in (0.0, 1.5, 4.0):  # smooth and even at 0: value 0, slope 0, curvature 1/(2(ν+1))
        f = lambda x: log_bessel_iv_reduced(order, x)  # noqa: E731
        assert float(f(0.0)) == 0.0 and float(jax.grad(f)(0.0)) == 0.0
        assert float(jax.hessian(f)(0.0)) == pytest.approx(0.5 / (order + 1.0), rel=1e-15)
        assert float(bessel_iv_ratio(order, 0.0)) == 0.0
    assert float(log_bessel_iv(0.0, 0.0)) == 0.0 and float(log_bessel_iv(1.0, 0.0)) == -np.inf
    with pytest.raises(ValueError, match="order must be >= 0"):
        log_bessel_iv(-1.0, 2.0)


# ---------------------------------------------------------------------- the vMF distribution

pytest.importorskip("numpyro")
from liesample.interop import numpyro_distributions  # noqa: E402
from liesample.interop.numpyro_distributions import VonMisesFisher  # noqa: E402


def _scipy_log_normalizer(d, k):
    """``log C_d(κ)`` through SciPy's ``ive``."""
    nu = d / 2.0 - 1.0
    return nu * np.log(k) - (d / 2.0) * np.log(2 * np.pi) - np.log(special.ive(nu, k)) - k


@pytest.mark.parametrize("d", [2, 3, 4, 5, 10])
def test_vmf_normaliser_matches_scipy_and_its_derivatives(d):
    k = np.geomspace(1e-8, 1e5, 300)
    mu = jnp.zeros(d).at[0].set(1.0)
    log_c = lambda x: VonMisesFisher(mu, x).log_normalizer()  # noqa: E731
    expected = _scipy_log_normalizer(d, k)
    out = np.asarray(jax.vmap(log_c)(k))
    assert np.all(np.abs(out - expected) <= 1e-13 * np.maximum(1.0, np.abs(expected)))
    # d/dκ log C_d = ν/κ − (log I_ν)' = −R, R = I_{d/2}/I_{d/2−1} = E[μ·x].
    ratio = special.ive(d / 2.0, k) / special.ive(d / 2.0 - 1.0, k)
    assert np.allclose(jax.vmap(jax.grad(log_c))(k), -ratio, rtol=1e-12, atol=1e-300)
    assert np.allclose(jax.vmap(lambda x: VonMisesFisher(mu, x).mean[0])(k), ratio, rtol=1e-12)
    # κ = 0: the uniform law, −log|S^{d−1}| = log Γ(d/2) − log 2 − (d/2) log π; slope 0.
    uniform = special.gammaln(d / 2.0) - np.log(2.0) - (d / 2.0) * np.log(np.pi)
    assert float(log_c(0.0)) == pytest.approx(uniform, rel=1e-15, abs=1e-15)
    assert float(jax.grad(log_c)(0.0)) == 0.0


def test_vmf_log_prob_has_a_hessian_in_kappa_and_no_callback():
    mu = jnp.array([0.0, 0.6, 0.8])
    x = jnp.array([0.0, 1.0, 0.0])
    for kappa in (1e-6, 0.05, 3.0, 80.0):
        # d²/dκ² log C_3(κ) = 1/sinh²κ − 1/κ² (closed form on S²).
        hess = jax.jit(jax.hessian(lambda k: VonMisesFisher(mu, k).log_prob(x)))(kappa)
        exact = 1.0 / np.sinh(kappa) ** 2 - 1.0 / kappa**2 if kappa > 1e-3 else -1.0 / 3.0
        assert float(hess) == pytest.approx(exact, rel=1e-8, abs=1e-12)
    d5 = jnp.array([0.0, 0.0, 0.6, 0.0, 0.8])
    hess = jax.hessian(lambda k: VonMisesFisher(d5, k).log_prob(d5))(jnp.array(2.5))
    ratio = special.ive(2.5, 2.5) / special.ive(1.5, 2.5)
    exact = -(1.0 - 4.0 * ratio / 2.5 - ratio**2)  # −R' with ν = 3/2
    assert float(hess) == pytest.approx(exact, rel=1e-12)
    jaxpr = str(jax.make_jaxpr(lambda k: VonMisesFisher(d5, k).log_prob(d5))(2.5))
    assert "callback" not in jaxpr
    assert "pure_callback" not in inspect.getsource(numpyro_distributions)
