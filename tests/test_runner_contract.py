"""The Info contract, safe defaults and loud failures, end to end through ``liesample.sample``.

- the Info contract (every sampler meets it: ``tests/test_registry.py``); the runner writes its
  fields under ArviZ's names (a magnetic divergence reaches ``diverging``);
- a run beyond the stability bound is refused naming the largest step; ``"warn"`` is recorded;
- stuck chains are named; a start whose energy is NaN is refused naming the chain; many starts
  are checked in one vectorised call;
- both key styles work; ``help()`` shows the real docstring;
- the von Mises–Fisher posterior of the new-user trial (κ = 800 on S², noise the coordinates):
  as written (step 0.05) it raises naming the bound; without a step size, through the adapted
  warm-up, both orbit samplers match its exact mean and sd within MCSE (the unadjusted one
  within MCSE plus the bias tolerance it was given).
"""

import pydoc
import warnings
from collections import namedtuple

import arviz_stats as azs
import blackjax
import cases
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import algebras, systems
from liesample.integrators.stability import check_precision
from liesample.samplers.contract import CONTRACT_FIELDS, check_info
from liesample.samplers.orbit.lie_poisson_langevin import DEFAULT_BIAS_TOLERANCE

RIGID = systems.rigid_body((1.0, 2.0, 4.0))
STARTS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])

# The new-user trial's posterior: vMF on S² with κ = 800 about μ̂ ∝ (0.31, 0.63, 0.71).
KAPPA = 800.0
MU_HAT = np.array([0.31, 0.63, 0.71]) / np.linalg.norm([0.31, 0.63, 0.71])


def _vmf_energy(m):
    return -KAPPA * jnp.dot(jnp.asarray(MU_HAT), m)


def _coordinates(m):
    return m


VMF = systems.lie_poisson_system(algebras.so3, _vmf_energy, _coordinates, MU_HAT, name="vMF")


def vmf_moments():
    """Exact vMF on S²: ``E[m] = A μ̂``, ``E[m mᵀ] = (A/κ) I + (1 − 3A/κ) μ̂μ̂ᵀ``,
    ``A = coth κ − 1/κ``."""
    a = 1.0 / np.tanh(KAPPA) - 1.0 / KAPPA
    mean = a * MU_HAT
    second = (a / KAPPA) * np.eye(3) + (1.0 - 3.0 * a / KAPPA) * np.outer(MU_HAT, MU_HAT)
    return mean, np.sqrt(np.diag(second) - mean**2)


# --------------------------------------------------------------------------- the contract


def test_check_info_names_the_missing_contract_fields():
    """The contract itself; every sampler's ``info`` is checked against it over the registry
    (``tests/test_registry.py``, rows in ``tests/cases.py``)."""
    with pytest.raises(TypeError, match=r"lacks the Info contract's fields \['is_divergent', 'acc"):
        check_info(namedtuple("OldInfo", ["energy", "nonfinite"]))
    assert CONTRACT_FIELDS == ("is_divergent", "acceptance_rate", "energy")


def test_energy_is_named_for_what_it_is():
    """ArviZ's ``energy`` only for HMC's total energy (a state with a momentum, or a plain
    BlackJAX algorithm); ``hamiltonian`` for h of a momentum-free state."""
    from liesample.samplers.contract import as_sampler, energy_name

    position = jnp.asarray(STARTS[0])
    orbit = liesample.lie_poisson_langevin(RIGID, beta=1.0, step_size=0.05)
    assert energy_name(orbit, position) == "hamiltonian"
    spins = liesample.heisenberg_metropolis(systems.heisenberg((4,)), beta=1.0)
    assert energy_name(spins, jnp.tile(position, (4, 1))) == "hamiltonian"
    hmc = liesample.magnetic_hmc(lambda q: -0.5 * q @ q, 0.1, jnp.ones(3), 3, jnp.zeros((3, 3)))
    assert energy_name(hmc, position) == "energy"
    plain = blackjax.hmc(lambda q: -0.5 * q @ q, 0.1, jnp.ones(3), 3)
    assert energy_name(as_sampler(plain), position) == "energy"


def test_both_key_styles_give_the_same_draws():
    sampler = liesample.adjusted_lie_poisson(RIGID, beta=2.0, step_size=0.2)
    state = sampler.init(STARTS[0])
    typed, _ = sampler.step(jax.random.key(5), state)
    raw, _ = sampler.step(jax.random.PRNGKey(5), state)
    np.testing.assert_array_equal(typed.position, raw.position)
    runs = [  # chunks of 100 draws: the program of the R-hat test below (a β, a step: values)
        liesample.sample_chains(
            sampler, key, STARTS, 100, chunk_draws=100, progress_bar=False
        ).positions
        for key in (jax.random.key(9), jax.random.PRNGKey(9))
    ]
    np.testing.assert_array_equal(*runs)
    averages = [
        liesample.integrators.accuracy.coupled_ergodic_averages(
            RIGID, 1.0, _coordinates, step_size=0.1, levels=1, integrator="lie_euler",
            initial_positions=STARTS, rng_key=key, total_time=1.0,
        ).chain_means
        for key in (jax.random.key(7), jax.random.PRNGKey(7))
    ]  # fmt: skip
    np.testing.assert_array_equal(*averages)


def test_help_shows_the_real_docstring():
    apis = [getattr(liesample, name) for name in cases.SAMPLER_NAMES]
    apis = [api for api in apis if hasattr(api, "differentiable")]  # GenerateSamplingAPI objects
    assert len(apis) >= len(cases.SAMPLER_NAMES) - 1  # all but jittered_magnetic_hmc
    for api in apis:
        text = pydoc.render_doc(api, renderer=pydoc.plaintext)
        assert api.differentiable.__doc__.strip().splitlines()[0] in text
        assert "jax_enable_x64" in text and "GenerateSamplingAPI(differentiable" not in text
    doc = liesample.lie_poisson_langevin.__doc__
    assert 'default ``"splitting"``' in doc and "rkmk_heun" not in doc
    assert '"raise"`` (default)' in doc


# --------------------------------------------------------------------------- divergences


def test_magnetic_divergences_reach_sample_stats_and_are_reduced_with_any():
    """A log-density that is NaN beyond |q| = 1.5: the magnetic Langevin steps that land there
    are divergent; over a thinning window of 5 the draw is divergent if any step was."""

    def walled(q):
        return jnp.where(jnp.sum(q * q) < 2.25, -0.5 * jnp.sum(q * q), jnp.nan)

    field = np.array([[0.0, 1.0], [-1.0, 0.0]])
    sampler = liesample.magnetic_langevin(walled, 0.3, np.ones(2), 1.0, field)
    starts = np.zeros((2, 2))
    key = jax.random.key(3)
    with pytest.warns(RuntimeWarning, match=r"chains 0, 1\).*divergent"):
        steps = liesample.sample_chains(sampler, key, starts, 100, progress_bar=False)
    with pytest.warns(RuntimeWarning, match="divergent"):
        tree = liesample.sample(sampler, key, starts, 20, thinning=5, progress_bar=False,
                                num_warmup=0, event_dims=("coordinate",))  # fmt: skip
    diverging = tree.sample_stats["diverging"].values
    assert diverging.dtype == bool and diverging.any()
    np.testing.assert_array_equal(
        diverging, steps.info["is_divergent"].reshape(2, 20, 5).any(axis=-1)
    )
    np.testing.assert_allclose(
        tree.sample_stats["acceptance_rate"].values,
        steps.info["acceptance_rate"].reshape(2, 20, 5).mean(axis=-1),
    )
    # H(q, p) of a state with a momentum: ArviZ's HMC energy, for its BFMI and energy plot.
    assert "energy" in tree.sample_stats and "hamiltonian" not in tree.sample_stats


def test_stuck_chains_are_named():
    """The chains are named and the advice is the sampler's own (a call that works for it)."""
    sampler = liesample.adjusted_lie_poisson(VMF, beta=1.0, step_size=1.0)
    starts = np.tile(MU_HAT, (4, 1))
    with pytest.warns(
        RuntimeWarning, match=r"4 chain\(s\) are stuck.*chains 0, 1, 2, 3.*smaller"
    ) as caught:  # 4 chains, thinning 2, chunks of 50: the vMF test's program (β, step: values)
        liesample.sample_chains(sampler, jax.random.key(0), starts, 50, thinning=2,
                                chunk_draws=50, progress_bar=False)  # fmt: skip
    assert any(sampler.stuck_advice in str(w.message) for w in caught)


def test_a_nan_log_density_is_named_as_such():
    """A NaN log-density is treated as −∞: the divergence message says NaN was seen and points
    at the model, not at the step size."""

    def logdensity(x):
        return jnp.where(x[0] > 0.5, jnp.nan, -0.5 * jnp.sum(x**2))

    sampler = liesample.magnetic_hmc(logdensity, 0.5, jnp.ones(2), 5, jnp.zeros((2, 2)))
    starts = np.zeros((2, 2))
    with pytest.warns(RuntimeWarning, match="energy was NaN.*treated as −∞.*domain error"):
        liesample.sample_chains(sampler, jax.random.key(0), starts, 30, progress_bar=False)


# --------------------------------------------------------------------------- starts


def test_many_starts_are_checked_in_one_call_naming_the_first_bad_chain(monkeypatch):
    rng = np.random.default_rng(1)
    starts = rng.normal(size=(4096, 3))
    sampler = liesample.adjusted_lie_poisson(RIGID, beta=1.0, step_size=0.1)
    calls = []
    original = type(RIGID).check_position

    def counted(self, *args, **kwargs):
        calls.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(type(RIGID), "check_position", counted)
    sampler.check_positions(starts)
    assert len(calls) == 0  # no per-start Python loop
    bad = starts.copy()
    bad[1234] = 0.0
    bad[2000] = np.nan
    with pytest.raises(ValueError, match=r"initial_positions\[2000\].*finite"):
        liesample.sample_chains(sampler, jax.random.key(0), bad, 2, progress_bar=False)
    bad[2000] = 1.0
    with pytest.raises(ValueError, match=r"initial_positions\[1234\].*degenerate"):
        liesample.sample_chains(sampler, jax.random.key(0), bad, 2, progress_bar=False)


def test_a_start_with_nan_energy_is_refused():
    system = systems.lie_poisson_system(
        algebras.so3, lambda m: jnp.log(m[2]), _coordinates, np.array([0.0, 0.0, 1.0])
    )
    sampler = liesample.lie_poisson_langevin(system, beta=1.0, step_size=0.01, stability="off")
    with pytest.raises(ValueError, match="energy h = nan"):
        sampler.init(jnp.array([0.0, 0.0, -1.0]))
    starts = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match=r"initial_positions\[2\].*energy h = nan"):
        liesample.sample_chains(sampler, jax.random.key(0), starts, 2, progress_bar=False)


# --------------------------------------------------------------------------- settings, precision


def test_settings_and_explicit_stability_modes_are_recorded():
    sampler = liesample.lie_poisson_langevin(RIGID, beta=1.0, step_size=10.0, stability="warn")
    with pytest.warns(UserWarning, match=r"step_size must be <= "):
        tree = liesample.sample(sampler, jax.random.key(0), STARTS, 4, progress_bar=False)
    attrs = tree.attrs
    assert attrs["stability"] == "warn" and attrs["step_size"] == 10.0
    assert attrs["step_size_source"] == "given" and attrs["stability_number"] > 2.0
    assert attrs["sampler"] == "lie_poisson_langevin" and attrs["adapted"] == 0
    assert set(tree.sample_stats.data_vars) >= {"diverging", "acceptance_rate", "hamiltonian"}


def test_float32_warning_rule():
    """Spread 1/√(β max|h''|) below 1e-3 of the state's size: float32 is not enough; the
    message does not change between calls, so Python's default filter shows it once a line."""
    stiff = systems.lie_poisson_system(
        algebras.so3, lambda m: -1e7 * m[2], _coordinates, np.array([0.6, 0.0, 0.8]),
        name="stiff vMF",
    )  # fmt: skip
    start = np.array([0.6, 0.0, 0.8])
    assert not check_precision(stiff, 1.0, 0.5, start, jnp.float64)
    with pytest.warns(UserWarning, match=r"float32.*jax_enable_x64") as first:
        assert check_precision(stiff, 1.0, 0.5, start, jnp.float32)
    with pytest.warns(UserWarning) as again:
        assert check_precision(stiff, 1.0, 0.5, start, jnp.float32)
    assert [str(w.message) for w in again] == [str(w.message) for w in first]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not check_precision(RIGID, 1.0, 0.5, start, jnp.float32)


# --------------------------------------------------------------------------- the vMF case


def test_vmf_as_written_raises_naming_the_bound():
    sampler = liesample.lie_poisson_langevin(VMF, beta=1.0, sigma=1.0, step_size=0.05)
    with pytest.raises(ValueError, match=r"κ = .* > 2 .*step_size must be <= 0\.00"):
        liesample.sample(
            sampler, jax.random.key(0), np.tile(MU_HAT, (2, 1)), 10, progress_bar=False
        )


def _check_vmf(tree, bias_tolerance=0.0):
    """Mean and sd of each coordinate within 5 MCSE (ArviZ) of the exact vMF values, plus the
    bias the sampler was asked to allow (``bias_tolerance`` sd on the mean, ``bias_tolerance``
    relative on the sd; 0 for the exact adjusted sampler)."""
    mean, sd = vmf_moments()
    draws = tree.posterior["mu"].values
    for i in range(3):
        x = draws[..., i]
        mcse_mean = float(azs.mcse(x, method="mean"))
        mcse_sd = float(azs.mcse(x, method="sd"))
        allowed = bias_tolerance * sd[i]
        assert abs(x.mean() - mean[i]) < 5 * mcse_mean + allowed, (i, x.mean(), mean[i], mcse_mean)
        assert abs(x.std() - sd[i]) < 5 * mcse_sd + allowed, (i, x.std(), sd[i], mcse_sd)
    assert not tree.sample_stats["diverging"].values.any()


STARTS_S2 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-0.6, 0.0, 0.8]])


# slow: the unadjusted default path's law again, on the vMF; the default suite checks this with
# test_negative_temperature.py::test_unadjusted_rigid_body_at_negative_beta_by_the_default_path
@pytest.mark.slow
def test_vmf_unadjusted_without_step_size_matches_the_exact_law():
    sampler = liesample.lie_poisson_langevin(VMF, beta=1.0)
    tree = liesample.sample(
        sampler, jax.random.key(1), STARTS_S2, 1000, num_warmup=200, thinning=2, progress_bar=False
    )
    assert tree.attrs["adapted"] == 1 and tree.attrs["stability_number"] <= 1.0
    assert tree.attrs["step_size_source"].startswith("warm-up bias model")
    # Unadjusted: exact up to the default bias tolerance (0.05 sd; κ = 1 missed it by 2×).
    _check_vmf(tree, bias_tolerance=DEFAULT_BIAS_TOLERANCE)


def test_vmf_adjusted_with_dual_averaging_matches_the_exact_law():
    sampler = liesample.adjusted_lie_poisson(VMF, beta=1.0)
    tree = liesample.sample(
        sampler, jax.random.key(2), STARTS_S2, 1000, num_warmup=400, thinning=2, chunk_draws=50,
        progress_bar=False,
    )  # fmt: skip
    assert tree.attrs["step_size_source"].startswith("warm-up dual averaging")
    rate = float(tree.sample_stats["acceptance_rate"].values.mean())
    assert abs(rate - 0.574) < 0.1, rate
    _check_vmf(tree)


def test_chains_that_disagree_are_reported_as_not_converged():
    """Chains that stay where they started (a tiny step, no warm-up) disagree on the energy:
    the runner warns with the split R-hat; chains that mix do not warn."""
    starts = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
    # One compiled chunk (100 draws; the step size is a value) for both runs.
    frozen = liesample.adjusted_lie_poisson(RIGID, beta=3.0, step_size=1e-4)
    with pytest.warns(RuntimeWarning, match="split R-hat of their energy"):
        liesample.sample_chains(frozen, jax.random.key(0), starts, 200, chunk_draws=100,
                                progress_bar=False)  # fmt: skip
    mixing = liesample.adjusted_lie_poisson(RIGID, beta=3.0, step_size=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        liesample.sample_chains(mixing, jax.random.key(0), starts, 2000, num_warmup=500,
                                chunk_draws=100, progress_bar=False)  # fmt: skip


def test_an_energy_constant_on_the_orbit_raises_no_convergence_warning():
    """The isotropic body's h is a Casimir: constant along every chain up to round-off, so its
    R-hat compares round-off and must not be reported (the demo's autocorrelation run)."""
    system = liesample.systems.rigid_body((2.0, 2.0, 2.0))
    starts = 1.5 * np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
    sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        run = liesample.sample_chains(sampler, jax.random.key(0), starts, 200, progress_bar=False)
    assert 0 < np.ptp(run.info["energy"]) < 1e-12  # round-off only


def test_split_rhat_against_hand_values():
    from liesample.run.runner import split_rhat

    rng = np.random.default_rng(0)
    same = rng.standard_normal((4, 1000))
    assert abs(split_rhat(same) - 1.0) < 0.01
    shifted = same + np.arange(4)[:, None]
    assert split_rhat(shifted) > 1.5
    assert np.isnan(split_rhat(same[:1])) and np.isnan(split_rhat(np.ones((4, 100))))
