"""Convergence checks on every posterior variable (liesample.analysis.convergence).

The vectorised R-hat and ESS agree with ArviZ's; through ``liesample.sample``, chains in mirror
modes, a split mixture and a flat (improper) target each raise the warning, naming the
variables, and a well-mixed run raises none.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from arviz_stats.base import array_stats

import liesample
from liesample.analysis.convergence import (
    MAX_RHAT,
    convergence_warnings,
    rank_diagnostics,
)
from liesample.spaces import Euclidean, Sphere


def _convergence_messages(record):
    return [str(w.message) for w in record if "convergence checks" in str(w.message)]


def _sample(sampler, starts, num_draws, **options):
    """``liesample.sample`` and its convergence messages. The warning tests with a given step
    run no warm-up (``num_warmup=0``, one compiled program fewer): their chains start in the
    modes they stay in, or drift from the start, so discarding steps first changes nothing the
    checks see."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        tree = liesample.sample(
            sampler, jax.random.key(3), starts, num_draws, progress_bar=False, **options
        )
    return tree, _convergence_messages(record)


@pytest.mark.parametrize("chains, draws", [(4, 200), (1, 101), (3, 5), (2, 4), (8, 51)])
def test_rank_diagnostics_agree_with_arviz(chains, draws):
    rng = np.random.default_rng(7)
    noise = rng.normal(size=(5, chains, draws))
    walk = np.cumsum(noise, axis=-1) * 0.3 + noise  # autocorrelated
    x = np.concatenate(
        [noise, walk, np.round(walk), walk + np.arange(chains)[:, None], -walk], axis=0
    )
    r_hat, bulk, tail = rank_diagnostics(x)
    with np.errstate(all="ignore"):
        expected = (
            array_stats.rhat(x),
            array_stats.ess(x, method="bulk"),
            array_stats.ess(x, method="tail", prob=(0.05, 0.95)),
        )
    for mine, theirs in zip((r_hat, bulk, tail), expected, strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-10, equal_nan=True)


def test_messages_name_elements_and_say_what_cannot_be_checked():
    rng = np.random.default_rng(0)
    iid = rng.normal(size=(4, 1000, 3))
    assert convergence_warnings({"mu": iid, "casimir": np.ones((4, 1000))}) == []
    modes = iid + 8.0 * np.array([1, 1, 1, -1])[:, None, None]
    (rhat, ess) = convergence_warnings({"mu": modes})
    assert rhat.startswith(f"R-hat > {MAX_RHAT:g} for 3 element(s): mu[")
    assert "ESS below 100 per chain" in ess
    # within law groups (one per mode) the same draws are well mixed
    assert convergence_warnings({"mu": modes}, groups=[0, 0, 0, 1]) == []
    assert convergence_warnings({"mu": modes}, groups=[[3], [0, 1, 2]]) == []
    (one,) = convergence_warnings({"mu": iid[:1]})
    assert "R-hat cannot be computed: the run has one chain" in one
    (alone,) = convergence_warnings({"mu": iid}, groups=[0, 1, 2, 3])
    assert "no two chains sample one law" in alone
    (few,) = convergence_warnings({"mu": iid[:, :3]})
    assert "cannot be checked with 3 draw(s)" in few
    broken = iid.copy()
    broken[0, 5, 1] = np.nan
    assert convergence_warnings({"mu": broken}) == [
        "1 element(s) hold non-finite draws and were not checked"
    ]
    complex_draws = iid + 1j * modes
    assert "U.imag[" in convergence_warnings({"U": complex_draws})[0]


def test_mirror_modes_on_the_sphere_warn():
    """An axial (Watson) law on S², κ = 50: chains started at ±e₃ stay in their modes."""

    def logdensity(x):
        return 50.0 * x[2] ** 2

    sampler = liesample.geometric_hmc(logdensity, Sphere(2), 0.1, 5)
    starts = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] * 2)
    tree, messages = _sample(sampler, starts, 300, num_warmup=0)
    assert abs(float(tree.posterior["mu"].sel(component="z").mean())) < 0.5  # pooled: ~0
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "mu[2]" in messages[0]


@pytest.mark.slow
def test_rigid_body_chains_at_opposite_minima_warn():
    """β = 40, chains at ±e₃ (equal energies, so the energy's R-hat cannot see it): the pooled
    E[μ₃] of a 3/1 split is ~0.5, the exact one 0."""
    system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    sampler = liesample.adjusted_lie_poisson(system, beta=40.0)
    starts = jnp.array([[0.0, 0.0, 1.0]] * 3 + [[0.0, 0.0, -1.0]])
    tree, messages = _sample(sampler, starts, 200, num_warmup=200)
    assert float(tree.posterior["mu"].sel(component="z").mean()) > 0.3
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "mu[2]" in messages[0]


def test_split_mixture_warns():
    """Equal Gaussians at ±8, chains split 3/1: the pooled mean is ~4, the exact one 0."""

    def logdensity(x):
        return jnp.logaddexp(-0.5 * (x[0] - 8.0) ** 2, -0.5 * (x[0] + 8.0) ** 2)

    sampler = liesample.geometric_hmc(logdensity, Euclidean((1,)), 0.5, 4)
    starts = jnp.array([[8.0], [8.0], [8.0], [-8.0]])
    tree, messages = _sample(sampler, starts, 300, num_warmup=0, var_name="x")
    assert float(tree.posterior["x"].mean()) > 3.0
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "x[0]" in messages[0]


def test_flat_target_warns():
    """A flat (improper) log-density: the chains drift apart."""
    sampler = liesample.geometric_hmc(lambda x: 0.0 * x.sum(), Euclidean((2,)), 0.5, 4)
    starts = jnp.zeros((4, 2))
    _, messages = _sample(sampler, starts, 300, num_warmup=0, var_name="x")
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "drift" in messages[0]


def test_well_mixed_run_is_quiet():
    """A standard Gaussian in R² by HMC (time 1.5, far from the resonance at π where each
    draw is nearly minus the last: that one the check reports): no convergence warning."""
    sampler = liesample.geometric_hmc(lambda x: -0.5 * jnp.sum(x**2), Euclidean((2,)), 0.5, 3)
    starts = jax.random.normal(jax.random.key(0), (4, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tree = liesample.sample(
            sampler, jax.random.key(3), starts, 500, num_warmup=100, progress_bar=False
        )
    assert tree.posterior["mu"].shape == (4, 500, 2)
