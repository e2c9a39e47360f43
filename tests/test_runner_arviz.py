"""``liesample.sample`` speaks ArviZ and BlackJAX: NUTS through the same runner, a
``log_likelihood`` group for ``loo``, ArviZ's standard attributes, ``progress_bar=``."""

import blackjax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from arviz_stats import loo

import liesample

Y = np.array([0.3, -0.2, 1.1, 0.5])  # observations of y ~ N(x, 1), prior x ~ N(0, 1)
STARTS = np.zeros((2, 1))
KEY = jax.random.key(3)


def logdensity(x):
    return -0.5 * jnp.sum(x**2) - 0.5 * jnp.sum((Y - x) ** 2)


def pointwise(x):
    return -0.5 * (Y - x) ** 2 - 0.5 * np.log(2 * np.pi)


NUTS = blackjax.nuts(logdensity, 0.8, np.ones(1))  # one object: its executables are reused


@pytest.fixture(scope="module")
def nuts_tree(tmp_path_factory):
    path = tmp_path_factory.mktemp("nuts") / "run.nc"
    tree = liesample.sample(NUTS, KEY, STARTS, 100, log_likelihood={"y": pointwise},
                            output=path, chunk_draws=50, progress_bar=False)  # fmt: skip
    return tree, path


def test_nuts_runs_with_its_nested_info_dropped_by_rule(nuts_tree):
    """NUTS' info holds the trajectory's end states and the momentum: only the fields that are
    one number per step are kept."""
    stats = nuts_tree[0].sample_stats
    assert {"diverging", "acceptance_rate", "energy", "num_integration_steps"} <= set(stats)
    assert not {"momentum", "trajectory_leftmost_state"} & set(stats)
    assert stats["diverging"].dtype == bool
    mu = nuts_tree[0].posterior["mu"].values  # the posterior is N(Σy / 5, 1 / 5)
    assert abs(mu.mean() - Y.sum() / 5) < 5 * np.sqrt(0.2 / 40)  # a loose check: ESS >= 40


@pytest.mark.filterwarnings("ignore:Estimated shape parameter")  # four observations
def test_log_likelihood_group_makes_loo_work_and_is_saved(nuts_tree):
    tree, path = nuts_tree
    assert tree["log_likelihood"]["y"].shape == (2, 100, 4)
    np.testing.assert_allclose(
        tree["log_likelihood"]["y"].values, pointwise(tree.posterior["mu"].values), atol=1e-12
    )
    assert np.isfinite(loo(tree).elpd)
    saved = liesample.load_chains(path)
    np.testing.assert_array_equal(saved["log_likelihood"]["y"], tree["log_likelihood"]["y"])
    with pytest.raises(TypeError, match="log_likelihood must be a non-empty dict"):
        liesample.sample(NUTS, KEY, STARTS, 4, log_likelihood=pointwise, progress_bar=False)


def test_standard_arviz_attributes(nuts_tree):
    attrs = nuts_tree[0].attrs
    assert attrs["inference_library"] == "liesample"
    assert attrs["sampling_time"] > 0 and "inference_library_version" in attrs
    assert nuts_tree[0].posterior.attrs["creation_library"] == "ArviZ"


def test_progress_is_the_deprecated_name_of_progress_bar():
    # The chunks of nuts_tree (50 draws, with its log-likelihood): compiled once.
    run = {"chunk_draws": 50, "log_likelihood": {"y": pointwise}}
    with pytest.warns(DeprecationWarning, match="progress_bar="):
        old = liesample.sample_chains(NUTS, KEY, STARTS, 50, progress=False, **run)
    with pytest.warns(DeprecationWarning, match="progress_bar="):
        liesample.sample(
            NUTS, KEY, STARTS, 50, num_warmup=0, exact_starts=True, progress=False, **run
        )
    new = liesample.sample_chains(NUTS, KEY, STARTS, 50, progress_bar=False, **run)
    np.testing.assert_array_equal(old.positions, new.positions)


def test_a_thermalised_configuration_comes_with_one_warning_only():
    """A one-draw run (a thermalised configuration after a warm-up) warns once, that its
    convergence cannot be checked, and ArviZ's guess at swapped axes (two chains, one draw)
    does not speak: the tree's axes are named."""
    import warnings

    system = liesample.systems.heisenberg((4,), periodic=True)
    sampler = liesample.heisenberg_heat_bath(system, beta=1.0)
    starts = np.stack([system.default_position] * 2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tree = liesample.sample(
            sampler, jax.random.key(0), starts, 1, num_warmup=20, progress_bar=False
        )
    messages = [str(w.message) for w in caught]
    assert len(messages) == 1 and "convergence cannot be checked with 1 draw" in messages[0]
    assert tree.posterior.sizes["draw"] == 1 and tree.posterior.sizes["chain"] == 2
