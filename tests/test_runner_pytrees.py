"""sample_chains / sample with pytree positions (dicts, tuples): draws, chunking, naming, errors."""

import blackjax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import liesample
from liesample.analysis.diagnostics import to_datatree
from liesample.geometry.spaces import SU, Euclidean, Sphere
from liesample.run.runner import load_chains, sample_chains

jax.config.update("jax_enable_x64", True)

KEY = jax.random.key(3)
FIELD = jnp.array([1.0, -2.0, 3.0])
SPACE = {"mu": Sphere(2), "log_kappa": Euclidean(())}


def vmf_logdensity(x):
    return jnp.dot(FIELD, x)


def product_logdensity(p):  # a vMF direction and a Gaussian log-concentration, coupled
    return jnp.exp(0.3 * p["log_kappa"]) * jnp.dot(FIELD, p["mu"]) - 0.5 * p["log_kappa"] ** 2


PRODUCT = liesample.geometric_hmc(product_logdensity, SPACE, 0.3, 4)


def product_starts(num_chains=3):
    mu = np.tile([0.0, 0.0, 1.0], (num_chains, 1))
    mu[1] = [1.0, 0.0, 0.0]
    return {"mu": mu, "log_kappa": np.linspace(-0.5, 0.5, num_chains)}


def test_one_leaf_dict_gives_the_draws_of_the_plain_array():
    starts = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    plain = sample_chains(
        liesample.geometric_hmc(vmf_logdensity, Sphere(2), 0.4, 3),
        KEY, starts, 12, thinning=2, chunk_draws=6, progress_bar=False,
    )  # fmt: skip
    tree = sample_chains(
        liesample.geometric_hmc(lambda p: vmf_logdensity(p["mu"]), {"mu": Sphere(2)}, 0.4, 3),
        KEY, {"mu": starts}, 12, thinning=2, chunk_draws=6, progress_bar=False,
    )  # fmt: skip
    assert set(tree.positions) == {"mu"}
    np.testing.assert_array_equal(tree.positions["mu"], plain.positions)
    assert tree.info.keys() == plain.info.keys()
    for name in plain.info:
        np.testing.assert_array_equal(tree.info[name], plain.info[name])


@pytest.fixture(scope="module")
def product_run():
    """In chunks of 2 draws: the program of test_output_and_resume_with_pytree_positions."""
    return sample_chains(
        PRODUCT, KEY, product_starts(), 10, thinning=2, chunk_draws=2, progress_bar=False
    )


def test_pytree_draws_have_the_structure_of_the_starts(product_run):
    positions = product_run.positions
    assert positions["mu"].shape == (3, 10, 3) and positions["log_kappa"].shape == (3, 10)
    np.testing.assert_allclose(np.linalg.norm(positions["mu"], axis=-1), 1.0, atol=1e-12)
    assert product_run.info["acceptance_rate"].shape == (3, 10)
    assert np.mean(product_run.info["acceptance_rate"]) > 0.3


def test_pytree_draws_do_not_depend_on_chunking_or_sharding(product_run):
    # One chunk shape each (10 = 5 × 2 and 10 × 1 draws, the default chunks): one compilation.
    other = sample_chains(PRODUCT, KEY, product_starts(), 10, thinning=2, progress_bar=False,
                          devices=1)  # fmt: skip
    for name in ("mu", "log_kappa"):
        np.testing.assert_array_equal(other.positions[name], product_run.positions[name])


def test_starts_are_checked_without_the_hook_and_named():
    bare = blackjax.base.SamplingAlgorithm(PRODUCT.init, PRODUCT.step)  # no check_positions
    starts = product_starts()
    starts["mu"][2] = [0.0, 0.0, 2.0]  # off the sphere
    with pytest.raises(ValueError, match=r"initial_positions\[2\]"):
        sample_chains(bare, KEY, starts, 2, progress_bar=False)


@pytest.mark.parametrize(
    ("positions", "error", "match"),
    [
        (
            {"mu": np.zeros((3, 3)), "log_kappa": np.zeros(2)},
            ValueError,
            r"same leading chain axis.*\['log_kappa'\] has 2 chains.*\['mu'\] has 3",
        ),
        ({"mu": np.zeros((3, 3)), "log_kappa": np.float64(0.0)}, ValueError,
         r"initial_positions\['log_kappa'\] must have a leading chain axis"),
        ({}, ValueError, "empty pytree"),
        ({"mu": np.tile([0.0, 0.0, 1.0], (2, 1)), "log_kappa": np.array([0.0, np.nan])},
         ValueError, r"initial_positions\[1\] must be finite"),
    ],
)  # fmt: skip
def test_bad_pytree_positions(positions, error, match):
    with pytest.raises(error, match=match):
        sample_chains(PRODUCT, KEY, positions, 2, progress_bar=False)


class _Interrupt(Exception):
    pass


def _interrupt_after(draws):
    def hook(done):
        if done >= draws:
            raise _Interrupt

    return hook


def test_output_and_resume_with_pytree_positions(tmp_path, product_run):
    path = tmp_path / "run.nc"
    with pytest.raises(_Interrupt):  # stopped after 2 of 5 chunks were saved
        sample_chains(PRODUCT, KEY, product_starts(), 10, thinning=2, chunk_draws=2,
                      progress_bar=False, output=path, callback=_interrupt_after(4))  # fmt: skip
    saved = load_chains(path)
    assert set(saved.posterior.data_vars) == {"mu", "log_kappa"}
    assert saved.posterior["mu"].shape == (3, 4, 3)
    resumed = sample_chains(PRODUCT, KEY, product_starts(), 10, thinning=2, chunk_draws=2,
                            progress_bar=False, output=path, resume=True)  # fmt: skip
    for name in ("mu", "log_kappa"):  # bitwise the uninterrupted run
        np.testing.assert_array_equal(resumed.positions[name], product_run.positions[name])
        np.testing.assert_array_equal(load_chains(path).posterior[name], resumed.positions[name])
    for name in product_run.info:
        np.testing.assert_array_equal(resumed.info[name], product_run.info[name])
    other = product_starts()
    other["log_kappa"] = other["log_kappa"] + 0.1
    with pytest.raises(ValueError, match="initial_positions_sha256"):
        sample_chains(PRODUCT, KEY, other, 12, progress_bar=False, output=path, resume=True)


def su2_logdensity(p):
    return 2.0 * jnp.real(jnp.trace(p[0])) - 0.5 * p[1]["x"] ** 2


# A tuple of a complex SU(2) leaf and a dict: one sampler (and chunks of 2 draws) for the two
# tests below, so that their programs are compiled once.
SU2 = liesample.geometric_hmc(su2_logdensity, (SU(2), {"x": Euclidean(())}), 0.3, 3)


def su2_starts():
    return (np.tile(np.eye(2, dtype=complex), (2, 1, 1)), {"x": np.zeros(2)})


def test_output_keeps_tuples_and_complex_leaves(tmp_path):
    sampler, starts = SU2, su2_starts()
    path = tmp_path / "su2.nc"
    run = sample_chains(sampler, KEY, starts, 4, progress_bar=False, output=path, chunk_draws=2)
    saved = load_chains(path).posterior
    assert set(saved.data_vars) == {"x0.real", "x0.imag", "x1.x"}
    np.testing.assert_array_equal(saved["x0.real"] + 1j * saved["x0.imag"], run.positions[0])
    np.testing.assert_array_equal(saved["x1.x"], run.positions[1]["x"])
    resumed = sample_chains(sampler, KEY, starts, 6, progress_bar=False, output=path, resume=True,
                            chunk_draws=2)  # fmt: skip
    assert resumed.positions[0].dtype == np.complex128
    np.testing.assert_array_equal(resumed.positions[0][:, :4], run.positions[0])


def test_output_saves_any_pytree_with_named_leaves(tmp_path):
    """The file holds the tree's variables (named from key paths), so any pytree is saved."""
    sampler = liesample.geometric_hmc(lambda p: -0.5 * p[1] ** 2, {1: Euclidean(())}, 0.3, 2)
    sample_chains(sampler, KEY, {1: np.zeros(2)}, 2, progress_bar=False, output=tmp_path / "run.nc")
    assert set(load_chains(tmp_path / "run.nc").posterior.data_vars) == {"1"}


def test_variable_names_dims_and_complex_split():
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2, 5, 2, 2)) + 1j * rng.standard_normal((2, 5, 2, 2))
    positions = {
        "mu": rng.standard_normal((2, 5, 3)),
        "log_kappa": rng.standard_normal((2, 5)),
        "pair": (rng.standard_normal((2, 5, 4)), {"inner": rng.standard_normal((2, 5))}),
        "U": u,
    }
    tree = to_datatree(positions, {"acceptance_rate": np.ones((2, 5))})
    posterior = tree.posterior
    assert set(posterior.data_vars) == {
        "mu", "log_kappa", "pair.x0", "pair.x1.inner", "U.real", "U.imag",
    }  # fmt: skip
    assert posterior["mu"].dims == ("chain", "draw", "mu_dim_0")
    assert list(posterior["mu"].coords["mu_dim_0"].values) == ["x", "y", "z"]
    assert posterior["log_kappa"].dims == ("chain", "draw")
    assert posterior["pair.x0"].dims == ("chain", "draw", "pair.x0_dim_0")
    assert posterior["U.real"].dims == posterior["U.imag"].dims == (
        "chain", "draw", "U_dim_0", "U_dim_1",
    )  # fmt: skip
    np.testing.assert_array_equal(posterior["U.real"], u.real)
    np.testing.assert_array_equal(posterior["U.imag"], u.imag)
    assert all(not np.iscomplexobj(v) for v in posterior.data_vars.values())
    # ArviZ diagnostics run on every (real) variable.
    import arviz_stats

    ess = arviz_stats.ess(tree, group="posterior")
    assert set(ess.data_vars) == set(posterior.data_vars)
    # Event dims may be renamed per leaf.
    renamed = to_datatree(positions, event_dims={"mu": ("component",)})
    assert renamed.posterior["mu"].dims == ("chain", "draw", "component")


def test_tuple_positions_and_naming_errors():
    rng = np.random.default_rng(1)
    tree = to_datatree((rng.standard_normal((2, 4, 2)), rng.standard_normal((2, 4))))
    assert set(tree.posterior.data_vars) == {"x0", "x1"}
    with pytest.raises(ValueError, match=r"both named 'a\.b'"):
        to_datatree({"a.b": np.zeros((1, 4)), "a": {"b": np.zeros((1, 4))}})
    with pytest.raises(ValueError, match="var_name names a single array"):
        to_datatree({"a": np.zeros((1, 4))}, var_name="a")
    with pytest.raises(ValueError, match="same \\(chains, draws\\)"):
        to_datatree({"a": np.zeros((1, 4)), "b": np.zeros((1, 5))})
    with pytest.raises(ValueError, match="names no leaf"):
        to_datatree({"a": np.zeros((1, 4))}, event_dims={"b": ()})


def test_sample_splits_complex_su2_leaves():
    # The sampler and chunks of test_output_keeps_tuples_and_complex_leaves, without warm-up
    # (no third program): liesample.sample says the starts are kept.
    with pytest.warns(UserWarning, match="num_warmup=0"):
        tree = liesample.sample(SU2, KEY, su2_starts(), 6, num_warmup=0, chunk_draws=2,
                                progress_bar=False)  # fmt: skip
    posterior = tree.posterior
    assert set(posterior.data_vars) == {"x0.real", "x0.imag", "x1.x"}
    assert posterior["x0.real"].shape == (2, 6, 2, 2)
    u = np.asarray(posterior["x0.real"]) + 1j * np.asarray(posterior["x0.imag"])
    unitary = u @ np.conj(np.swapaxes(u, -1, -2))
    np.testing.assert_allclose(unitary, np.broadcast_to(np.eye(2), unitary.shape), atol=1e-10)
    assert isinstance(tree, xr.DataTree) and "diverging" in tree.sample_stats
