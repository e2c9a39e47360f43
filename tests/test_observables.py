"""Observables recorded while sampling, and honest errors of variance-type observables.

- ``observables=`` of ``sample_chains`` / ``sample``: values of functions of the position at
  every draw, computed inside the compiled loop, without changing the draws; saved with
  ``output=``, restored on ``resume=``, posterior variables of the DataTree; with
  ``keep_positions=False`` the states are not stored.
- Blocking and jackknife errors (:mod:`liesample.analysis.diagnostics`) against exact values:
  an AR(1) series of known integrated autocorrelation time, i.i.d. Gaussian draws (the
  jackknife against the delta method, the Binder cumulant of a Gaussian), and the open
  Heisenberg chain's exact energy variance and spin correlations (specific heat,
  susceptibility) from a heat-bath run that records only its observables.
"""

import math

import arviz_stats as azs
import jax
import numpy as np
import pytest
import scipy.signal

import liesample
from liesample.analysis.diagnostics import (
    binder_cumulant,
    blocking_error,
    jackknife,
    specific_heat,
    susceptibility,
    to_datatree,
)
from liesample.run.runner import load_chains, sample_chains

LENGTH = 6
SYSTEM = liesample.systems.heisenberg((LENGTH,))
ALGORITHM = liesample.heisenberg_heat_bath(SYSTEM, beta=1.0)
STARTS = np.tile(np.array([0.0, 0.0, 1.0]), (3, LENGTH, 1))
KEY = jax.random.key(5)
RUN = {"num_warmup": 5, "thinning": 2, "chunk_draws": 4, "progress_bar": False}
NUM_DRAWS = 12


def magnetisation(spins):
    return spins.mean(axis=0)


OBSERVABLES = {"m": magnetisation, "h": SYSTEM.hamiltonian}


def on_draws(function, positions):
    return jax.vmap(jax.vmap(function))(positions)


# --------------------------------------------------------------------------- the runner


def test_observables_leave_the_draws_unchanged_and_are_functions_of_them():
    plain = sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, **RUN)
    both = sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, observables=OBSERVABLES, **RUN)
    only = sample_chains(
        ALGORITHM,
        KEY,
        STARTS,
        NUM_DRAWS,
        observables=OBSERVABLES,
        keep_positions=False,
        **RUN,
    )
    assert plain.observables is None and only.positions is None
    np.testing.assert_array_equal(both.positions, plain.positions)
    for name in plain.info:
        np.testing.assert_array_equal(both.info[name], plain.info[name])
        np.testing.assert_array_equal(only.info[name], plain.info[name])
    assert both.observables["m"].shape == (3, NUM_DRAWS, 3)
    assert both.observables["h"].shape == (3, NUM_DRAWS)
    for name, function in OBSERVABLES.items():
        # at the kept draw of each thinning window (thinning=2), not at the step before it
        expected = on_draws(function, plain.positions)
        np.testing.assert_allclose(both.observables[name], expected, rtol=0, atol=1e-13)
        np.testing.assert_array_equal(only.observables[name], both.observables[name])


def test_bad_observables_are_refused_before_sampling():
    with pytest.raises(ValueError, match="keep_positions=False"):
        sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, keep_positions=False, **RUN)
    with pytest.raises(TypeError, match="observables must be a function"):
        sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, observables=[magnetisation], **RUN)
    with pytest.raises(TypeError, match=r"observables\['m'\]"):
        sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, observables={"m": 1.0}, **RUN)
    with pytest.raises(ValueError, match="empty"):
        sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, observables={}, **RUN)


def test_observables_are_saved_and_a_resumed_run_equals_an_uninterrupted_one(tmp_path):
    path = tmp_path / "run.nc"
    options = dict(RUN, observables=OBSERVABLES, keep_positions=False)
    whole = sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, **options)

    class Interrupted(Exception):
        pass

    def interrupt(draws_done):
        raise Interrupted

    with pytest.raises(Interrupted):
        sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, output=path, callback=interrupt, **options)
    saved = load_chains(path).posterior
    assert set(saved.data_vars) == set(OBSERVABLES)  # no positions
    assert saved["h"].shape == (3, RUN["chunk_draws"])
    # a resume that records other observables, or the positions too, is refused
    for changed, match in (({"observables": {"h": SYSTEM.hamiltonian}}, "observables"),
                           ({"keep_positions": True}, "keep_positions")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, output=path, resume=True,
                          **{**options, **changed})  # fmt: skip
    resumed = sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, output=path, resume=True, **options)
    for name in OBSERVABLES:
        np.testing.assert_array_equal(resumed.observables[name], whole.observables[name])
        np.testing.assert_array_equal(load_chains(path).posterior[name], whole.observables[name])
    for name in whole.info:
        np.testing.assert_array_equal(resumed.info[name], whole.info[name])


def test_sample_puts_the_observables_in_the_posterior(tmp_path):
    tree = liesample.sample(
        ALGORITHM, KEY, STARTS, NUM_DRAWS, observables=OBSERVABLES, exact_starts=True, **RUN
    )
    posterior = tree["posterior"]
    assert set(posterior.data_vars) == {"mu", "m", "h"}
    assert posterior["m"].dims == ("chain", "draw", "m_dim_0")
    np.testing.assert_allclose(
        posterior["h"].values, on_draws(SYSTEM.hamiltonian, posterior["mu"].values), atol=1e-13
    )
    assert np.isfinite(azs.ess(posterior["h"].values))

    only = liesample.sample(
        ALGORITHM,
        KEY,
        STARTS,
        NUM_DRAWS,
        observables=SYSTEM.hamiltonian,
        keep_positions=False,
        output=tmp_path / "only.nc",
        exact_starts=True,
        **RUN,
    )
    assert set(only["posterior"].data_vars) == {"observable"}
    np.testing.assert_array_equal(only["posterior"]["observable"].values, posterior["h"].values)
    assert "diverging" in only["sample_stats"].data_vars

    with pytest.raises(ValueError, match="names of position variables"):
        liesample.sample(
            ALGORITHM, KEY, STARTS, NUM_DRAWS, observables={"mu": magnetisation}, **RUN
        )


def test_to_datatree_names_the_observables_from_their_key_paths():
    observed = (np.zeros((2, 5)), {"end": np.ones((2, 5, 3))})
    tree = to_datatree(np.zeros((2, 5, 3)), observables=observed)
    assert set(tree["posterior"].data_vars) == {"mu", "x0", "x1.end"}
    assert tree["posterior"]["x1.end"].dims == ("chain", "draw", "x1.end_dim_0")
    with pytest.raises(ValueError, match="neither"):
        to_datatree(None)
    with pytest.raises(ValueError, match="same"):
        to_datatree(np.zeros((2, 5, 3)), observables={"h": np.zeros((2, 4))})


# --------------------------------------------------------------------------- blocking


def ar1(rng, phi, num_chains, num_draws):
    """Stationary AR(1) chains ``x_t = phi x_{t-1} + e_t``, ``e_t ~ N(0, 1)``."""
    noise = rng.standard_normal((num_chains, num_draws))
    start = rng.standard_normal(num_chains) / math.sqrt(1 - phi**2)
    return scipy.signal.lfilter([1.0], [1.0, -phi], noise, axis=1, zi=phi * start[:, None])[0]


def ar1_error_of_mean(phi, num_chains, num_draws):
    """Exact standard error of the mean of ``num_chains`` independent stationary AR(1)
    chains."""
    lags = np.arange(1, num_draws)
    factor = 1 + 2 * np.sum((1 - lags / num_draws) * phi**lags)
    return math.sqrt(factor / (1 - phi**2) / num_draws / num_chains)


@pytest.mark.parametrize("phi", [0.0, 0.9])
def test_blocking_error_of_an_ar1_series_is_the_exact_one(phi):
    num_chains, num_draws = 4, 2**15
    x = ar1(np.random.default_rng(7), phi, num_chains, num_draws)
    result = blocking_error(x)
    exact = ar1_error_of_mean(phi, num_chains, num_draws)
    own_error = result.errors_error[result.level]
    assert abs(result.error - exact) < 3 * own_error, (result.error, exact, own_error)
    # tau_int = (1 + phi) / (1 - phi), within the error's own relative error (doubled: squared)
    tau = (1 + phi) / (1 - phi)
    assert abs(result.tau_int - tau) < 3 * 2 * tau * own_error / result.error
    assert result.num_blocks == num_chains * num_draws // 2**result.level
    # the jackknife of the mean, with the blocking's block size, gives the same error
    mean = jackknife(lambda m: m, x)
    assert mean.block_size == 2**result.level
    assert abs(mean.error - result.error) < own_error


def test_blocking_warns_when_the_draws_are_too_few():
    x = ar1(np.random.default_rng(3), 0.999, 2, 256)
    with pytest.warns(RuntimeWarning, match="run longer chains"):
        blocking_error(x)


# --------------------------------------------------------------------------- jackknife


def test_jackknife_matches_the_delta_method_on_iid_gaussian_draws():
    rng = np.random.default_rng(11)
    sigma = 2.0
    x = sigma * rng.standard_normal((4, 4000))
    result = jackknife(lambda m1, m2: m2 - m1**2, x, x**2, block_size=1)
    num = x.size
    # delta method for f(m1, m2) = m2 - m1^2 from the sample covariance of (x, x^2)
    gradient = np.array([-2 * x.mean(), 1.0])
    covariance = np.cov(np.stack([x.ravel(), x.ravel() ** 2]))
    delta = math.sqrt(gradient @ covariance @ gradient / num)
    own_error = result.error / math.sqrt(2 * (result.num_blocks - 1))
    assert abs(result.error - delta) < own_error
    # and the exact error of the variance of a Gaussian, sqrt(2 / n) sigma^2
    assert abs(result.error - math.sqrt(2 / num) * sigma**2) < 3 * own_error
    assert abs(result.estimate - sigma**2) < 4 * result.error
    assert result.per_chain.shape == (4,) and np.all(result.per_chain_error > 0)
    # blocks change nothing for independent draws (within the error's own error)
    blocked = jackknife(lambda m1, m2: m2 - m1**2, x, x**2, block_size=40)
    assert abs(blocked.error - delta) < 3 * blocked.error / math.sqrt(2 * blocked.num_blocks)
    with pytest.raises(ValueError, match="fewer than 2 blocks"):
        jackknife(lambda m: m, x[:1], block_size=4000)


@pytest.mark.parametrize(("components", "exact"), [(1, 0.0), (3, 4.0 / 9.0)])
def test_binder_cumulant_of_a_gaussian_magnetisation(components, exact):
    rng = np.random.default_rng(components)
    m = rng.standard_normal((4, 3000, components))
    result = binder_cumulant(m[..., 0] if components == 1 else m)
    assert abs(result.estimate - exact) < 4 * result.error, (result, exact)


# --------------------------------------------------------------------------- physics, exact


def test_specific_heat_and_susceptibility_of_the_heisenberg_chain_from_its_observables():
    length, beta = LENGTH, 1.0
    reference = SYSTEM.reference(beta)
    starts = liesample.targets.spins.sample_heisenberg_chain(jax.random.key(2), 3, length, beta)
    # the run options of the tests above: their compiled chunks are reused
    result = sample_chains(
        ALGORITHM,
        jax.random.key(3),
        np.asarray(starts),
        3000,
        observables=OBSERVABLES,
        keep_positions=False,
        **RUN,
    )
    heat = specific_heat(result.observables["h"], beta, length)
    exact_heat = beta**2 * reference.energy_variance() / length
    assert abs(heat.estimate - exact_heat) < 4 * heat.error, (heat, exact_heat)
    assert heat.per_chain.shape == (3,)
    # <|M|^2> = sum_kl u^|k-l| for the open chain: chi = beta N <m^2> = beta/N sum_kl u^|k-l|
    sites = np.arange(length)
    exact_chi = beta / length * np.sum(reference.correlation(abs(sites[:, None] - sites)))
    chi = susceptibility(result.observables["m"], beta, length, connected=False)
    assert abs(chi.estimate - exact_chi) < 4 * chi.error, (chi, exact_chi)
    connected = susceptibility(result.observables["m"], beta, length)
    assert 0 < connected.estimate < chi.estimate
