"""GeometricHMC under NumPyro's MCMC: the post-run checks of liesample.sample fire through plain
``MCMC.run`` (liesample.interop.numpyro_checks), NumPyro's init strategies start manifold sites,
and BlackJAX's window adaptation is refused with liesample's as the fix.

One vectorized MCMC (``jit_model_args``, so its loop compiles once) runs a two-mode model whose
modes merge at ``a = 0`` (a 2-D normal: quiet) and are 12 sd apart at ``a = 6`` with its chains
started in different modes (R-hat of x[0] far above 1.01: a warning naming it). Sequential
chains of 20 unadapted draws warn too. Fixed keys.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")
import blackjax
import numpyro.distributions as dist
from numpyro.infer import (
    MCMC,
    init_to_feasible,
    init_to_mean,
    init_to_median,
    init_to_sample,
    init_to_uniform,
    init_to_value,
)

import liesample
from liesample.interop import numpyro_checks
from liesample.interop.numpyro_checks import RunChecks, check_mcmc
from liesample.interop.numpyro_distributions import MatrixFisher, VonMisesFisher
from liesample.interop.numpyro_kernel import GeometricHMC

STARTS = {"x": jnp.array([[6.0, 0.0], [-6.0, 0.0]])}  # one chain in each mode at a = 6


def two_modes(a):
    """``x`` in R²: modes at ``±(a, 0)`` (unit sd), under a wide normal prior."""
    x = numpyro.sample("x", dist.Normal(0.0, 10.0).expand([2]).to_event(1))
    shift = jnp.stack([a, 0.0])
    near = [-0.5 * jnp.sum((x - shift) ** 2), -0.5 * jnp.sum((x + shift) ** 2)]
    numpyro.factor("modes", jnp.logaddexp(*near))


def _user_warnings(record):
    return [w for w in record if issubclass(w.category, (UserWarning, RuntimeWarning))]


@pytest.fixture(scope="module")
def vectorized():
    """One MCMC for both runs (``jit_model_args``: ``a`` is traced, the loop compiles once)."""
    return MCMC(
        GeometricHMC(two_modes), num_warmup=300, num_samples=1000,
        num_chains=2, chain_method="vectorized", progress_bar=False, jit_model_args=True,
    )  # fmt: skip


def test_a_well_mixed_run_is_quiet(vectorized):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        vectorized.run(jax.random.key(0), jnp.asarray(0.0), init_params=STARTS)
    assert not _user_warnings(record), [str(w.message) for w in record]
    assert vectorized.get_samples(group_by_chain=True)["x"].shape == (2, 1000, 2)


def test_chains_in_different_modes_warn_naming_the_site(vectorized):
    with pytest.warns(UserWarning, match=r"R-hat > 1\.01 for \d element\(s\): x\[0\]: \d"):
        vectorized.run(jax.random.key(0), jnp.asarray(6.0), init_params=STARTS)
    samples = vectorized.get_samples(group_by_chain=True)["x"]
    assert np.all(samples[0, :, 0] > 0) and np.all(samples[1, :, 0] < 0)  # they stayed
    # The explicit call, for drivers the kernel cannot see: the same check on the same draws.
    with pytest.warns(UserWarning, match=r"x\[0\]"):
        messages = check_mcmc(vectorized)
    assert any("R-hat > 1.01" in m and "x[0]" in m for m in messages)


def test_sequential_chains_of_20_unadapted_draws_warn():
    def model():
        numpyro.sample("theta", dist.Normal(jnp.zeros(2), jnp.array([1.0, 3.0])).to_event(1))

    kernel = GeometricHMC(model)  # the checks are on by default
    mcmc = MCMC(kernel, num_warmup=0, num_samples=20, num_chains=2, chain_method="sequential",
                progress_bar=False)  # fmt: skip
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        mcmc.run(jax.random.key(1))
    convergence = [str(w.message) for w in record if "convergence checks" in str(w.message)]
    assert len(convergence) == 1, [str(w.message) for w in record]  # once, after both chains
    assert "(20 draws per chain)" in convergence[0] and "theta[1]" in convergence[0]
    assert "check_convergence=False" in convergence[0]


@pytest.mark.skipif(jax.local_device_count() < 2, reason="parallel chains need 2 devices")
def test_parallel_chains_warn():  # pragma: no cover - one CPU device here
    def model():
        numpyro.sample("theta", dist.Normal(0.0, 1.0))

    kernel = GeometricHMC(model, check_convergence=True)
    mcmc = MCMC(kernel, num_warmup=0, num_samples=20, num_chains=2, chain_method="parallel",
                progress_bar=False)  # fmt: skip
    with pytest.warns(UserWarning, match="theta"):
        mcmc.run(jax.random.key(1))


def test_the_kept_draws_are_buffered_as_mcmc_keeps_them_and_sent_once_per_run(monkeypatch):
    """Two chains, a warm-up of 2, then 5 draws thinned by 2, twice (a continued run): the
    buffer holds the draws MCMC keeps, and the host gets one call per run, after its last
    draw."""
    seen = []
    monkeypatch.setattr(numpyro_checks, "check_draws", lambda *run: seen.append(run))
    checks = RunChecks(num_warmup=2, num_samples=5, num_chains=2, thinning=2)
    latent = lambda z: {"x": z}
    draw = lambda i: jnp.array([[10.0 * chain + i] for chain in (0, 1)])
    fields = lambda i: {"diverging": jnp.array([i == 6, False])}
    kept = checks.buffer(latent, draw(0), fields(0))
    step = jax.jit(checks.trace, static_argnums=1)
    for i in range(12):
        kept = step(i, latent, draw(i), fields(i), kept)
        jax.effects_barrier()
        assert len(seen) == (i >= 6) + (i >= 11)
    (first, _, scales), (second, _, _) = seen
    assert scales == {}  # no model: no hierarchical scale
    # Of 5 draws thinned by 2 MCMC keeps draws 2 and 4 of each run (transitions 4 and 6 of
    # the first, 9 and 11 of the second): it skips the first num_samples % 2, then keeps the
    # last of each pair.
    np.testing.assert_array_equal(first["x"], [[[4.0], [6.0]], [[14.0], [16.0]]])
    np.testing.assert_array_equal(second["x"], [[[9.0], [11.0]], [[19.0], [21.0]]])
    np.testing.assert_array_equal(seen[0][1]["diverging"], [[False, True], [False, False]])


@pytest.mark.slow  # the run's own checks run by default (tests above)
def test_warmup_then_run_and_a_continued_run_are_each_checked_on_the_kept_draws(monkeypatch):
    seen = []
    monkeypatch.setattr(numpyro_checks, "check_draws", lambda *run: seen.append(run))

    def model():
        numpyro.sample("theta", dist.Normal(jnp.zeros(2), 1.0).to_event(1))

    kernel = GeometricHMC(model, check_convergence=True)
    mcmc = MCMC(kernel, num_warmup=50, num_samples=30, num_chains=2, thinning=3,
                chain_method="vectorized", progress_bar=False)  # fmt: skip
    mcmc.warmup(jax.random.key(0))
    assert not seen  # the warm-up alone is not a run
    mcmc.run(jax.random.key(1))
    mcmc.post_warmup_state = mcmc.last_state
    mcmc.run(mcmc.post_warmup_state.rng_key)
    assert len(seen) == 2
    np.testing.assert_array_equal(
        seen[1][0]["theta"], mcmc.get_samples(group_by_chain=True)["theta"]
    )
    assert seen[1][1]["diverging"].shape == (2, 10)


def test_check_convergence_must_be_a_bool():
    with pytest.raises(TypeError, match=r"check_convergence must be a bool \(True or False\)"):
        GeometricHMC(two_modes, check_convergence="no")


def directions():
    numpyro.sample("mu", VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 3.0))
    numpyro.sample("R", MatrixFisher(jnp.diag(jnp.array([2.0, 1.0, 0.5]))))


STRATEGIES = {
    "feasible": init_to_feasible(),
    "median": init_to_median(),
    "mean": init_to_mean(),
    "sample": init_to_sample(),
    "uniform": init_to_uniform(),
    "value": init_to_value(values={"mu": jnp.array([0.0, 0.6, 0.8]), "R": jnp.eye(3)}),
}


def _check_start(name):
    kernel = GeometricHMC(directions, init_strategy=STRATEGIES[name], check_convergence=False)
    state = kernel.init(jax.random.key(0), 10, None, (), {})
    mu, rotation = np.asarray(state.z["mu"]), np.asarray(state.z["R"])
    assert np.isfinite(float(state.potential_energy)), name
    np.testing.assert_allclose(np.linalg.norm(mu), 1.0, atol=1e-12)
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, atol=1e-12)
    return mu, rotation


def test_init_to_feasible_starts_manifold_sites():
    """Regression: init_to_feasible gave the sphere site the zero vector (its identity view's
    origin), and every one of 100 starts was NaN."""
    mu, rotation = _check_start("feasible")
    np.testing.assert_array_equal(mu, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(rotation, np.eye(3))


@pytest.mark.slow  # one init compile each (the feasible one runs by default)
@pytest.mark.parametrize("name", ["median", "mean", "sample", "uniform", "value"])
def test_every_init_strategy_starts_manifold_sites(name):
    mu, rotation = _check_start(name)
    if name == "value":
        np.testing.assert_allclose(mu, [0.0, 0.6, 0.8], atol=1e-12)
        np.testing.assert_allclose(rotation, np.eye(3), atol=1e-12)


def test_blackjax_window_adaptation_is_refused_with_liesamples_as_the_fix():
    with pytest.raises(TypeError) as error:
        blackjax.window_adaptation(liesample.geometric_hmc, lambda x: -0.5 * jnp.sum(x**2))
    message = str(error.value)
    assert "divergence_threshold" in message
    assert "liesample.window_adaptation(liesample.geometric_hmc, logdensity_fn, space)" in message
