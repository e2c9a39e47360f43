"""Chains that adapt together cannot drag each other down.

The NumPyro kernel's window adaptation (``liesample.tuning.windows`` with
``numpyro_hmc.POOLING``) pools the chains' rates by the harmonic rule in the initial fast
window (a chain stuck at its start is freed) and by the median of their running rates after it
(``protocol.step_size_adaptation(..., pooling="harmonic_then_median")``): a minority of chains
stuck later cannot lower the shared step, and the odd chain is named after the warm-up
(``protocol.odd_chains``, the kernel's warning). The orbit samplers' dual averaging and the
native window adaptations keep the harmonic rule throughout.
Checked on the rule itself (no sampler), on a synthetic stuck chain through NumPyro's ``MCMC``
with vectorized chains, and (slow) on posteriordb's ``low_dim_gauss_mix``.
"""

import sys
import warnings
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from liesample.tuning.protocol import (
    STEP_POOLINGS,
    odd_chains,
    pooled_rate,
    row_at,
    schedule,
    step_size_adaptation,
)

TARGET = 0.8


# --------------------------------------------------------------------------- the rule


def test_a_stuck_minority_cannot_move_the_median_pooled_rate():
    rates = jnp.array([0.8, 0.8, 0.8, 0.0])
    rate, smoothed = pooled_rate(rates, rates, "median")
    assert float(rate) == pytest.approx(0.8)
    assert np.allclose(smoothed, rates)
    harmonic, _ = pooled_rate(rates, rates, "harmonic")
    assert float(harmonic) < 1e-6  # the harmonic rule lowers the step for the stuck chain


def test_an_eager_minority_cannot_move_the_median_pooled_rate():
    rates = jnp.array([0.5, 0.5, 1.0, 0.5])
    rate, _ = pooled_rate(rates, rates, "median")
    assert float(rate) == pytest.approx(0.5)


@pytest.mark.parametrize("pooling", ["median", "harmonic"])
def test_chains_that_accept_alike_read_their_mean_rate(pooling):
    smoothed = jnp.full(4, 0.7)
    rates = jnp.array([0.9, 0.6, 0.7, 1.0])
    rate, new = pooled_rate(rates, smoothed, pooling)
    assert np.allclose(new, 0.9 * 0.7 + 0.1 * rates)
    level = {"median": np.median(new), "harmonic": 1 / np.mean(1 / new)}[pooling]
    assert float(rate) == pytest.approx(np.mean(rates) * level / np.mean(new))


def test_one_or_two_chains_read_their_mean_rate_under_the_median():
    for rates in (jnp.array([0.3]), jnp.array([0.9, 0.0])):
        rate, _ = pooled_rate(rates, jnp.array([0.5, 0.8][: len(rates)]), "median")
        assert float(rate) == pytest.approx(float(jnp.mean(rates)))


def test_a_non_finite_rate_counts_as_zero():
    rate, smoothed = pooled_rate(jnp.array([jnp.nan, 0.8, 0.8]), jnp.full(3, 0.8), "median")
    assert np.isfinite(float(rate)) and np.all(np.isfinite(smoothed))
    assert float(smoothed[0]) == pytest.approx(0.72)


def test_a_pooling_that_does_not_exist_is_refused_by_name():
    with pytest.raises(ValueError, match=r"pooling must be one of \('harmonic', 'median', "):
        step_size_adaptation(TARGET, pooling="mean")
    with pytest.raises(ValueError, match="pooling must be one of"):
        pooled_rate(jnp.ones(2), jnp.ones(2), "trimmed")


def test_odd_chains_names_the_chain_left_behind():
    assert odd_chains([0.8, 0.75, 0.01, 0.82]) == [(2, 0.01, 0.8)]
    assert odd_chains([0.8, 0.75, 0.7, 0.82]) == []
    assert odd_chains([0.8, 0.0]) == []  # two chains: neither is the majority
    assert [chain for chain, _, _ in odd_chains([0.8, np.nan, 0.75, 0.7])] == [1]


class _Info(NamedTuple):
    acceptance_rate: jax.Array


def _rates(step):
    """Three chains whose rate falls through the target near a step of 1, and one stuck in a
    region that accepts only steps below 1e-3."""
    healthy = jnp.exp(-0.2231 * step**2)  # 0.8 at a step of 1
    stuck = jnp.minimum(1.0, (1e-3 / step) ** 2)
    return jnp.array([healthy, healthy, healthy, stuck])


@jax.jit
def _dual_averaging():
    """Each pooling's tuned step and last running rates after 400 transitions of the rates
    :func:`_rates`, the stuck chain stuck from the start (Stan's windows for the rows)."""
    rows = schedule(400)
    out = {}
    for pooling in STEP_POOLINGS:
        adaptation = step_size_adaptation(TARGET, pooling=pooling)
        state = adaptation.init(jnp.zeros((4, 1)), {"step_size": jnp.asarray(0.1)})

        def update(state, index, adaptation=adaptation):
            step = adaptation.current(state)["step_size"]
            info = _Info(_rates(step))
            row = row_at(rows, index)
            return adaptation.update(state, row, None, None, None, info), None

        state, _ = jax.lax.scan(update, state, jnp.arange(400))
        out[pooling] = (adaptation.final(state)["step_size"], state.smoothed)
    return out


@pytest.mark.parametrize("pooling", ["median", "harmonic_then_median"])
def test_dual_averaging_keeps_the_step_of_the_majority_and_the_stuck_chain_is_named(pooling):
    tuned = _dual_averaging()
    step, smoothed = tuned[pooling]
    assert 0.7 < float(step) < 1.4  # where the three healthy chains accept at about 0.8
    assert [chain for chain, _, _ in odd_chains(smoothed)] == [3]
    assert float(tuned["harmonic"][0]) < 0.01  # the rule before: the stuck chain set the step


def test_the_initial_window_is_before_the_first_slow_window():
    rows = schedule(1000)
    first_slow = int(np.flatnonzero(rows.stage == 1)[0])
    assert np.array_equal(rows.initial, np.arange(1000) < first_slow)
    assert np.array_equal(schedule(10).initial, np.arange(10) < 5)  # no slow window: half


# --------------------------------------------------------------------------- through NumPyro

numpyro = pytest.importorskip("numpyro")
from numpyro.infer import MCMC

from liesample.interop.numpyro_checks import check_mcmc
from liesample.interop.numpyro_kernel import GeometricHMC

NARROW = 1e-3


def _potential(z):
    """Half the mass in N(0, 1), half in N(4, 1e-3²): a chain started in the narrow mode
    cannot leave it, and accepts nothing at the wide mode's step."""
    x = z["x"]
    narrow = -0.5 * ((x - 4.0) / NARROW) ** 2 - jnp.log(NARROW)
    return -jnp.logaddexp(-0.5 * x**2, narrow)


def _run(mcmc, starts):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mcmc.run(jax.random.key(0), init_params={"x": jnp.asarray(starts)},
                 extra_fields=("adapt_state", "accept_prob"))  # fmt: skip
    return [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def vectorized():
    """One MCMC (compiled once), run from a stuck start and from healthy starts."""
    kernel = GeometricHMC(potential_fn=_potential)
    mcmc = MCMC(kernel, num_warmup=200, num_samples=100, num_chains=4,
                chain_method="vectorized", progress_bar=False)  # fmt: skip
    stuck = _run(mcmc, [-0.5, 0.3, 1.0, 4.0])
    fields = mcmc.get_extra_fields(group_by_chain=True)
    stuck_fields = {k: np.asarray(fields[k]) for k in ("accept_prob",)}
    stuck_fields["step_size"] = np.asarray(fields["adapt_state"].step_size)
    healthy = _run(mcmc, [-0.5, 0.3, 1.0, -1.2])
    return stuck, stuck_fields, healthy


def test_a_stuck_vectorized_chain_keeps_the_others_step_and_is_named(vectorized):
    messages, fields, _ = vectorized
    step = fields["step_size"][0, -1]
    assert step > 0.1, step  # the harmonic rule took it to ~1e-3
    healthy_rates = fields["accept_prob"][:3].mean(1)
    assert np.all((healthy_rates > 0.6) & (healthy_rates < 0.99)), healthy_rates
    named = [m for m in messages if "chains warmed up together" in m]
    assert len(named) == 1, messages
    assert "chain 3:" in named[0] and "chain 0:" not in named[0]
    assert "init_strategy" in named[0] and "LocScaleReparam" in named[0]


def test_healthy_vectorized_chains_are_quiet(vectorized):
    _, _, messages = vectorized
    assert not [m for m in messages if "chains warmed up together" in m], messages


# --------------------------------------------------------------------------- posteriordb

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_low_dim_gauss_mix_with_vectorized_chains_is_right_or_warned(seed):
    """posteriordb's two-component mixture, 4 vectorized chains x (1000 + 1000), the kernel's
    defaults: every posterior mean within 5 combined MCSE (the run's and the reference's) of
    the reference, or a warning (an odd chain, or the post-run convergence checks)."""
    import arviz_stats

    from benchmarks import posteriordb_models as pdb

    posterior = pdb.load("low_dim_gauss_mix-low_dim_gauss_mix")
    mcmc = MCMC(GeometricHMC(posterior.model), num_warmup=1000, num_samples=1000,
                num_chains=4, chain_method="vectorized", progress_bar=False)  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mcmc.run(jax.random.key(seed), **posterior.model_kwargs())
        check_mcmc(mcmc)
    samples = mcmc.get_samples(group_by_chain=True)
    values = {k: np.asarray(v) for k, v in samples.items() if k in posterior.reported}
    draws = pdb.flatten(values, posterior.keys, batch_ndim=2)  # (chains, draws, keys)
    mcse = np.array([float(arviz_stats.mcse(draws[..., k], method="mean"))
                     for k in range(draws.shape[-1])])  # fmt: skip
    error = np.abs(draws.mean((0, 1)) - posterior.mean)
    right = np.all(error <= 5.0 * np.sqrt(mcse**2 + posterior.mcse_mean**2))
    warned = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    assert right or warned, (posterior.keys, error, mcse)
