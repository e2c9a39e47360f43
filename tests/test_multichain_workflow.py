"""The multi-chain workflow of the README: warm up every chain together, then sample; and
``liesample.sample`` warms up by default, so fresh starts cannot pass for posterior draws."""

import json

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.geometry.spaces import Euclidean, Sphere

KAPPA, SD = 20.0, 0.03
SPACE = {"mu": Sphere(2), "x": Euclidean((2,))}


def logdensity(position):
    """vMF(e₃, κ) on S² times N(0, SD²) on R², both exact."""
    return KAPPA * position["mu"][2] - 0.5 * jnp.sum(position["x"] ** 2) / SD**2


def starts(num_chains, seed=0):
    """Arbitrary starts, far from the mass: uniform directions, x in [-2, 2]²."""
    k1, k2 = jax.random.split(jax.random.key(seed))
    mu = jax.vmap(lambda k: Sphere(2).uniform(k))(jax.random.split(k1, num_chains))
    return {"mu": mu, "x": jax.random.uniform(k2, (num_chains, 2), minval=-2.0, maxval=2.0)}


def vmf_mean_cosine(kappa):
    return 1.0 / np.tanh(kappa) - 1.0 / kappa


def check_exact(tree):
    """Mean cosine and the Gaussian sd against their exact values, within 4.5 MCSE."""
    mcse_mean = az.mcse(tree, var_names=["mu"], method="mean")["mu"].values
    cosine = tree.posterior["mu"].values[..., 2]
    assert abs(cosine.mean() - vmf_mean_cosine(KAPPA)) < 4.5 * mcse_mean[2]
    mcse_sd = az.mcse(tree, var_names=["x"], method="sd")["x"].values
    sd = tree.posterior["x"].values.reshape(-1, 2).std(axis=0)
    np.testing.assert_array_less(np.abs(sd - SD), 4.5 * mcse_sd)
    assert float(az.rhat(tree, var_names=["x"])["x"].max()) < 1.05


@pytest.mark.slow  # a long statistical run; by default README.md's multi-chain block runs this
# workflow, and test_adapt_on_one_chain_then_sample_fresh_chains_by_default checks the exact law
def test_window_adaptation_adapts_a_batch_of_starts_and_hands_them_on():
    """``window_adaptation(...).run`` on 4 starts adapts the chains together and returns every
    chain's state; sampling from them (no further warm-up) gives the exact law."""
    warmup = liesample.window_adaptation(liesample.geometric_hmc, logdensity, SPACE)
    (state, parameters), info = warmup.run(jax.random.key(1), starts(4), 400)
    assert state.position["mu"].shape == (4, 3) and state.position["x"].shape == (4, 2)
    assert np.shape(parameters["step_size"]) == ()
    assert info.info.acceptance_rate.shape == (400, 4)
    sampler = liesample.geometric_hmc(logdensity, SPACE, **parameters)
    tree = liesample.sample(
        sampler, jax.random.key(2), state.position, 1000, num_warmup=0, exact_starts=True,
        progress_bar=False,
    )  # fmt: skip
    check_exact(tree)


@pytest.fixture(scope="module")
def one_chain_warm_up():
    """``window_adaptation(...).run`` from one start (no chain axis), 400 steps: compiled once
    for the two tests below."""
    warmup = liesample.window_adaptation(liesample.geometric_hmc, logdensity, SPACE)
    one = jax.tree.map(lambda leaf: leaf[0], starts(1))
    return warmup.run(jax.random.key(1), one, 400)


def test_one_start_keeps_the_single_chain_warm_up(one_chain_warm_up):
    """One start still gives one chain's state (the BlackJAX shape)."""
    (state, _), info = one_chain_warm_up
    assert state.position["x"].shape == (2,)
    assert state.position["mu"].shape == (3,)
    assert info.info.acceptance_rate.shape == (400,)


def test_adapt_on_one_chain_then_sample_fresh_chains_by_default(one_chain_warm_up):
    """The trap: tune on one chain, then sample 4 fresh chains from arbitrary starts. The
    default warm-up of ``liesample.sample`` forgets the starts, and the sd is exact."""
    (_, parameters), _ = one_chain_warm_up
    sampler = liesample.geometric_hmc(logdensity, SPACE, **parameters)
    tree = liesample.sample(sampler, jax.random.key(3), starts(4, seed=7), 1000,
                            progress_bar=False)  # fmt: skip
    assert tree.attrs["num_warmup"] == 1000
    check_exact(tree)


def test_draw_names_come_from_the_space_and_are_checked_before_sampling():
    """A bare SO(3) array is named ``R`` with dims (row, col); dims that do not fit the starts
    fail before any step is taken."""
    space = liesample.spaces.SO(3)
    sampler = liesample.geometric_hmc(lambda r: 3.0 * jnp.trace(r), space, 0.2, 3)
    rotations = jnp.stack([jnp.eye(3)] * 2)
    with pytest.warns(UserWarning, match="num_warmup=0"):  # no warm-up program: names only
        tree = liesample.sample(sampler, jax.random.key(0), rotations, 4, num_warmup=0,
                                progress_bar=False)  # fmt: skip
    assert tree.posterior["R"].dims == ("chain", "draw", "row", "col")
    calls = []
    counting = liesample.samplers.contract.Sampler(
        sampler.init, lambda *a: calls.append(1) or sampler.step(*a)
    )
    with pytest.raises(ValueError, match="event_dims must name each event axis"):
        liesample.sample(counting, jax.random.key(0), rotations, 4, event_dims=("c",),
                         progress_bar=False)  # fmt: skip
    assert not calls


SDS = np.array([1e-3, 10.0])


def scaled_logdensity(x):
    """N(0, diag(SDS²)) on R²: scales 1e4 apart, which unit mass and one step cannot sample."""
    return -0.5 * jnp.sum((x / SDS) ** 2)


def test_sample_tunes_a_geometric_hmc_built_without_a_step():
    """``liesample.sample(geometric_hmc(logdensity, space), …)`` with the default warm-up runs
    the window adaptation (chains together) and samples with what it tuned: both sds exact
    within 4.5 MCSE, and the run records what was adapted."""
    x0 = jnp.array([[0.01, 1.0], [-0.01, -3.0], [0.002, 5.0], [0.0, 0.5]])
    sampler = liesample.geometric_hmc(scaled_logdensity, Euclidean((2,)))
    tree = liesample.sample(sampler, jax.random.key(0), x0, 300, progress_bar=False)
    draws = tree.posterior["mu"].values.reshape(-1, 2)
    mcse_sd = az.mcse(tree, var_names=["mu"], method="sd")["mu"].values
    np.testing.assert_array_less(np.abs(draws.std(axis=0) - SDS), 4.5 * mcse_sd)
    attrs = tree.posterior.attrs
    assert attrs["adapted"] == 1 and attrs["num_warmup"] == 300
    assert attrs["step_size_source"].startswith("warm-up window adaptation (all chains")
    assert attrs["adapted_parameters"] == "step_size, inverse_mass_matrix, num_integration_steps"
    mass = np.asarray(json.loads(attrs["inverse_mass_matrix"])[""])
    assert mass[1] / mass[0] > 1e3  # the pooled variances, 1e8 apart (the small one shrunk)


# One sampler with a given step for the two tests below (its programs compiled once).
GIVEN = liesample.geometric_hmc(scaled_logdensity, Euclidean((2,)), 5e-4, 3)


def test_no_warm_up_from_arbitrary_starts_warns():
    """``num_warmup=0`` keeps the starts in the draws: it warns unless the starts are exact."""
    arbitrary = jnp.array([[0.5, -3.0], [-0.2, 4.0]])
    with pytest.warns(UserWarning, match="num_warmup=0"):
        liesample.sample(GIVEN, jax.random.key(3), arbitrary, 5, num_warmup=0, progress_bar=False)


def test_a_given_step_is_kept_and_an_unset_one_needs_a_warm_up():
    """A step given to the factory is kept (no warm-up: exactly as given); one left unset
    cannot be sampled without a warm-up, and says so."""
    x0 = jnp.zeros((2, 2))
    given = GIVEN
    with pytest.warns(UserWarning, match="convergence checks") as caught:  # 5 draws
        tree = liesample.sample(given, jax.random.key(1), x0, 5, num_warmup=0,
                                exact_starts=True, progress_bar=False)  # fmt: skip
    # exact starts: no warning that the starts are kept (test_no_warm_up_from_arbitrary_starts)
    assert not [w for w in caught if "num_warmup=0" in str(w.message)]
    attrs = tree.posterior.attrs
    assert attrs["step_size"] == 5e-4 and attrs["step_size_source"] == "given"
    assert attrs["adapted"] == 0 and "adapted_parameters" not in attrs
    unset = liesample.geometric_hmc(scaled_logdensity, Euclidean((2,)))
    with pytest.raises(ValueError, match="without step_size and num_warmup=0"):
        liesample.sample(unset, jax.random.key(1), x0, 5, num_warmup=0, exact_starts=True)
    with pytest.raises(ValueError, match="built without step_size, so it cannot step"):
        unset.step(jax.random.key(0), unset.init(x0[0]))
    with pytest.raises(ValueError, match="num_integration_steps is unset"):
        liesample.geometric_hmc(scaled_logdensity, Euclidean((2,)), 0.1)


@pytest.mark.slow  # a second warm-up compilation; the default sibling is the geometric_hmc one
def test_sample_tunes_a_magnetic_hmc_built_without_parameters():
    """``magnetic_hmc(logdensity_fn)``: the warm-up runs the magnetic window adaptation (ChEES)
    on the chains together and samples with ``jittered_magnetic_hmc``; both sds exact."""
    x0 = jnp.array([[0.01, 1.0], [-0.01, -3.0], [0.002, 5.0], [0.0, 0.5]])
    tree = liesample.sample(liesample.magnetic_hmc(scaled_logdensity), jax.random.key(0), x0,
                            300, progress_bar=False)  # fmt: skip
    draws = tree.posterior["mu"].values.reshape(-1, 2)
    mcse_sd = az.mcse(tree, var_names=["mu"], method="sd")["mu"].values
    np.testing.assert_array_less(np.abs(draws.std(axis=0) - SDS), 4.5 * mcse_sd)
    assert tree.attrs["sampler"] == "jittered_magnetic_hmc" and tree.attrs["adapted"] == 1
    assert tree.attrs["step_size_source"].startswith("warm-up chees adaptation (all chains")


def test_an_unset_magnetic_hmc_needs_a_warm_up_and_all_four_parameters_or_none():
    unset = liesample.magnetic_hmc(scaled_logdensity)
    x0 = jnp.zeros((2, 2))
    with pytest.raises(ValueError, match="without step_size and num_warmup=0"):
        liesample.sample(unset, jax.random.key(1), x0, 5, num_warmup=0, exact_starts=True)
    with pytest.raises(ValueError, match="or none of them"):
        liesample.magnetic_hmc(scaled_logdensity, 0.1)
