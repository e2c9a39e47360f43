"""liesample.interop.numpyro_distributions: von Mises–Fisher and matrix Fisher distributions
(log_prob, exact draws)."""

import importlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import vonmises_fisher

pytest.importorskip("numpyro")

from liesample.interop.numpyro_distributions import MatrixFisher, VonMisesFisher, log_bessel_iv
from liesample.targets.groups import MatrixFisherLaw, vmf_mean_resultant_length


@pytest.mark.parametrize("d, kappa", [(3, 4.0), (6, 10.0), (3, 500.0)])
def test_vmf_log_prob_matches_scipy_and_is_differentiable(d, kappa):
    mu = np.zeros(d)
    mu[0], mu[-1] = 0.6, 0.8
    x = np.random.default_rng(0).normal(size=(5, d))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    law = VonMisesFisher(mu, kappa)
    expected = vonmises_fisher(mu, kappa).logpdf(x)
    assert np.allclose(law.log_prob(jnp.asarray(x)), expected, rtol=1e-12, atol=1e-10)
    grad = jax.grad(lambda k: VonMisesFisher(mu, k).log_prob(jnp.asarray(x[0])))(kappa)
    h = 1e-5 * kappa
    numeric = (
        vonmises_fisher(mu, kappa + h).logpdf(x[0]) - vonmises_fisher(mu, kappa - h).logpdf(x[0])
    ) / (2 * h)
    assert float(grad) == pytest.approx(numeric, rel=1e-6)
    assert float(log_bessel_iv(1.5, 2.0)) == pytest.approx(
        np.log(np.sqrt(2 / (np.pi * 2.0)) * (np.cosh(2.0) - np.sinh(2.0) / 2.0)), rel=1e-13
    )


@pytest.mark.parametrize("d, kappa", [(3, 4.0), pytest.param(6, 10.0, marks=pytest.mark.slow)])
def test_vmf_draws_are_exact(d, kappa):
    mu = np.zeros(d)
    mu[1], mu[2] = 0.8, -0.6
    # One compiled program: drawn eagerly, the sampler's loop costs a compile per operation.
    sample = jax.jit(lambda key: VonMisesFisher(mu, kappa).sample(key, (4000,)))
    x = np.asarray(sample(jax.random.key(0)))
    assert x.shape == (4000, d) and np.allclose(np.linalg.norm(x, axis=1), 1.0)
    t = x @ mu
    exact = vmf_mean_resultant_length(kappa, d)
    assert abs(t.mean() - exact) < 5 * t.std() / np.sqrt(len(t))
    # The component orthogonal to μ has mean zero.
    other = x[:, 0]
    assert abs(other.mean()) < 5 * other.std() / np.sqrt(len(other))


# slow: exact draws at one F and a normalised log_prob; the default suite checks this with
# test_geometric_numpyro.py::test_matrix_fisher_exact_sampler_for_concentrated_and_rotated_F and
# test_numpyro_distributions.py::test_parameters_may_be_traced_under_jit_and_match_the_references
@pytest.mark.slow
def test_matrix_fisher_draws_and_log_prob():
    F = np.diag([2.0, 1.0, -0.5])
    law = MatrixFisher(F)
    R = np.asarray(law.sample(jax.random.key(1), (4000,)))
    assert np.allclose(np.swapaxes(R, 1, 2) @ R, np.eye(3), atol=1e-12)
    exact = MatrixFisherLaw(F).mean()
    se = R.std(0) / np.sqrt(len(R))
    assert np.all(np.abs(R.mean(0) - exact) < 5 * se + 1e-12)
    # exp(log_prob) integrates to 1 against Haar: its Haar mean over uniform rotations is 1.
    from liesample.geometry.spaces import SO

    haar = SO(3, shape=(20000,)).uniform(jax.random.key(2))
    density = np.exp(np.asarray(law.log_prob(haar)))
    assert abs(density.mean() - 1.0) < 5 * density.std() / np.sqrt(len(density))


@pytest.mark.parametrize("singular_values", [(30.0, 20.0, -5.0), (0.0, 0.0, 0.0), (8.0, 8.0, 8.0)])
def test_matrix_fisher_exact_sampler_for_concentrated_and_rotated_F(singular_values):
    # Bingham draws of the quaternion: exact for any F, including concentrated ones that
    # rejection from Haar could not reach.
    q, p = np.linalg.qr(np.random.default_rng(0).standard_normal((2, 3, 3)))[0]
    q, p = q * np.sign(np.linalg.det(q)), p * np.sign(np.linalg.det(p))
    F = q @ np.diag(singular_values) @ p.T
    R = np.asarray(MatrixFisher(F).sample(jax.random.key(3), (20000,)))
    assert np.allclose(np.swapaxes(R, 1, 2) @ R, np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    exact = MatrixFisherLaw(F).mean()
    se = R.std(0) / np.sqrt(len(R))
    assert np.all(np.abs(R.mean(0) - exact) < 5 * se + 1e-12)


def test_missing_numpyro_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "numpyro", None)
    monkeypatch.delitem(sys.modules, "liesample.interop.numpyro_distributions", raising=False)
    with pytest.raises(ImportError, match="pip install numpyro"):
        importlib.import_module("liesample.interop.numpyro_distributions")
