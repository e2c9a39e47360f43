"""liesample.interop.numpyro_distributions: the Bingham distribution (exact normaliser and draws) and vMF at κ = 0."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("numpyro")
from numpyro.distributions import constraints  # noqa: E402

from liesample.geometry.spaces import SO, Sphere  # noqa: E402
from liesample.interop.numpyro_distributions import Bingham, VonMisesFisher  # noqa: E402
from liesample.targets.orbits import bingham_second_moments  # noqa: E402

LAM = np.array([0.5, 3.0, -1.0])
ORIENTATION = np.asarray(SO(3).uniform(jax.random.key(4)))


def test_bingham_log_prob_is_normalised_and_rotates_with_its_axes():
    law = Bingham(LAM, ORIENTATION)
    assert law.support is constraints.sphere is VonMisesFisher.support
    x = np.asarray(Sphere(2, shape=(40000,)).uniform(jax.random.key(0)))
    density = 4.0 * np.pi * np.exp(np.asarray(law.log_prob(x)))  # E_uniform[p / (1/4π)] = 1
    assert abs(density.mean() - 1.0) < 5.0 * density.std() / np.sqrt(len(density))
    # In the frame of its axes it is the axis-aligned law.
    aligned = Bingham(LAM)
    assert np.allclose(law.log_prob(x[:5] @ ORIENTATION.T), aligned.log_prob(x[:5]), atol=1e-12)
    second = np.asarray(law.second_moment())
    exact = ORIENTATION @ np.diag(np.asarray(bingham_second_moments(LAM))) @ ORIENTATION.T
    assert np.allclose(second, exact, atol=1e-12) and np.trace(second) == pytest.approx(1.0)


def test_bingham_draws_have_the_exact_second_moments():
    law = Bingham(np.stack([LAM, np.zeros(3)]), ORIENTATION)  # batch of 2: the second uniform
    x = np.asarray(law.sample(jax.random.key(1), (4000,)))
    assert x.shape == (4000, 2, 3) and np.allclose(np.linalg.norm(x, axis=-1), 1.0)
    exact = np.asarray(law.second_moment())
    assert np.allclose(exact[1], np.eye(3) / 3.0, atol=1e-12)
    for b in range(2):
        outer = x[:, b, :, None] * x[:, b, None, :]
        se = outer.std(0) / np.sqrt(len(x))
        assert np.all(np.abs(outer.mean(0) - exact[b]) < 5.0 * se), b


def test_bingham_bad_parameters_are_refused():
    with pytest.raises(ValueError, match=r"concentration must have shape \(\.\.\., 3\)"):
        Bingham(np.zeros(4))
    with pytest.raises(ValueError, match=r"orientation must be a rotation matrix of shape"):
        Bingham(LAM, np.eye(2))


def test_vmf_at_zero_concentration_is_the_uniform_law():
    mu = jnp.array([0.0, 0.0, 1.0])
    x = jnp.array([[0.6, 0.8, 0.0], [0.0, 0.0, -1.0]])
    assert np.allclose(VonMisesFisher(mu, 0.0).log_prob(x), -np.log(4.0 * np.pi), rtol=1e-14)
    grad = jax.grad(lambda k: VonMisesFisher(mu, k).log_prob(x[1]))(0.0)
    assert np.isfinite(grad)
    d6 = jnp.zeros(6).at[0].set(1.0)  # |S⁵| = π³
    assert float(VonMisesFisher(d6, 0.0).log_prob(d6)) == pytest.approx(-3 * np.log(np.pi))
    draws = np.asarray(VonMisesFisher(mu, 0.0).sample(jax.random.key(2), (4000,)))
    assert np.all(np.abs(draws.mean(0)) < 5.0 / np.sqrt(3.0 * len(draws)))
