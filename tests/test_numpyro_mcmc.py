"""liesample.interop.numpyro_kernel.GeometricHMC: a NumPyro MCMC kernel against exact references.

(a) vMF data with a mean direction on S² and a LogNormal concentration (an Euclidean site in
unconstrained coordinates, so the log-Jacobian matters), through
examples/numpyro_directional.py: the exact posterior by quadrature over log κ; (b) a matrix
Fisher prior on SO(3): exact E[R]; (c) a Bingham prior on S²: exact E[x xᵀ]. Tolerances:
5 MCSE (ArviZ, from the chains); fixed keys. Then the refusals.
"""

import importlib.util
import warnings
from pathlib import Path

import arviz_stats
import jax
import jax.numpy as jnp
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.distributions import constraints
from numpyro.infer import MCMC

from liesample.geometry.spaces import SO
from liesample.interop.numpyro_distributions import Bingham, MatrixFisher, VonMisesFisher
from liesample.interop.numpyro_kernel import GeometricHMC
from liesample.targets.groups import MatrixFisherLaw
from liesample.tuning.windows import far_adapted

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "numpyro_directional.py"


def _within(draws, exact, name, z=5.0):
    """``draws`` (chain, draw): the mean within ``z`` MCSE of ``exact``, chains mixed."""
    mcse = float(arviz_stats.mcse(np.asarray(draws), method="mean"))
    assert float(arviz_stats.rhat(np.asarray(draws))) < 1.05, name
    assert abs(float(np.mean(draws)) - exact) < z * mcse, (name, float(np.mean(draws)), exact, mcse)


def _example():
    spec = importlib.util.spec_from_file_location("numpyro_directional", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_vmf_posterior_matches_quadrature_and_arviz_reads_the_run(capsys):
    """(a), through examples/numpyro_directional.py: mu uniform on S², kappa LogNormal."""
    mcmc, tree, exact = _example().main(seed=0, num_warmup=200, num_samples=300, progress=False)
    samples = mcmc.get_samples(group_by_chain=True)
    assert samples["mu"].shape == (4, 300, 3) and samples["kappa"].shape == (4, 300)
    assert np.allclose(np.linalg.norm(samples["mu"], axis=-1), 1.0, atol=1e-12)
    assert np.allclose(samples["log_kappa"], np.log(samples["kappa"]))
    for i in range(3):
        _within(samples["mu"][..., i], exact["direction"][i], f"mu[{i}]")
    _within(samples["log_kappa"], exact["log_kappa"], "log_kappa")

    extra = mcmc.get_extra_fields(group_by_chain=True)
    assert not np.any(extra["diverging"])
    assert 0.6 < float(np.mean(extra["accept_prob"])) < 0.97
    assert np.all(np.ptp(np.asarray(extra["step_size"]), axis=1) == 0.0)  # fixed after warm-up
    printed = capsys.readouterr().out
    assert "mu[0]" in printed and "Number of divergences: 0" in printed  # print_summary
    assert "ess_bulk" in printed and "kappa" in printed  # the ArviZ summary

    assert tree.posterior["mu"].shape == (4, 300, 3)
    assert {"diverging", "acceptance_rate", "step_size"} <= set(tree.sample_stats.data_vars)
    assert tree.log_likelihood["x"].shape == (4, 300, 40)
    assert tree.observed_data["x"].shape == (40, 3)


def rotation_and_axis_model():
    numpyro.sample("R", MatrixFisher(F))
    numpyro.sample("axis", Bingham(LAM, ORIENTATION))


F = np.diag([2.0, 1.0, -0.5]) @ np.asarray(SO(3).uniform(jax.random.key(7)))
LAM = np.array([0.0, 2.0, 6.0])
ORIENTATION = np.asarray(SO(3).uniform(jax.random.key(8)))


@pytest.mark.slow  # the kernel's law on S² runs by default (the vMF posterior)
def test_prior_only_matrix_fisher_and_bingham_match_exact_moments():
    mcmc = MCMC(
        GeometricHMC(rotation_and_axis_model),
        num_warmup=200,
        num_samples=400,
        num_chains=4,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(1))
    samples = mcmc.get_samples(group_by_chain=True)
    R, x = np.asarray(samples["R"]), np.asarray(samples["axis"])
    assert np.allclose(np.swapaxes(R, -1, -2) @ R, np.eye(3), atol=1e-10)
    mean = MatrixFisherLaw(F).mean()  # exact E[R]
    for i in range(3):
        for j in range(3):
            _within(R[..., i, j], mean[i, j], f"R[{i},{j}]")
    second = np.asarray(Bingham(LAM, ORIENTATION).second_moment())  # exact E[x xᵀ]
    for i in range(3):
        for j in range(i, 3):
            _within(x[..., i] * x[..., j], second[i, j], f"xx[{i},{j}]")


# ------------------------------------------------------------------ refusals


def _init(model, *args, **kwargs):
    GeometricHMC(model, **kwargs).init(jax.random.key(0), 10, None, args, {})


def test_a_discrete_site_is_refused_by_name():
    def model():
        numpyro.sample("mu", VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 1.0))
        numpyro.sample("count", dist.Poisson(3.0))

    with pytest.raises(ValueError, match="site 'count' has the discrete support"):
        _init(model)


class _Stiefel(constraints.Constraint):
    """Orthonormal 3×2 frames: a manifold support with no space and no bijection to Rᵈ."""

    event_dim = 2

    def __call__(self, x):
        return jnp.all(jnp.abs(jnp.swapaxes(x, -1, -2) @ x - jnp.eye(2)) < 1e-6, (-2, -1))


class _Frame(dist.Distribution):
    support = _Stiefel()

    def __init__(self):
        super().__init__((), (3, 2))

    def sample(self, key, sample_shape=()):
        return jnp.broadcast_to(jnp.eye(3)[:, :2], tuple(sample_shape) + (3, 2))

    def log_prob(self, value):
        return jnp.zeros(jnp.shape(value)[:-2])


def test_an_unknown_support_is_refused_with_what_is_supported():
    def model():
        numpyro.sample("frame", _Frame())

    with pytest.raises(ValueError, match=r"site 'frame' has the support .*cannot handle; suppo"):
        _init(model)


def test_bad_settings_and_starts_are_refused():
    def model():
        numpyro.sample("mu", VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 1.0))

    with pytest.raises(TypeError, match="model must be a NumPyro model"):
        GeometricHMC(None)
    with pytest.raises(ValueError, match="step_size"):
        GeometricHMC(model, step_size=-1.0)
    with pytest.raises(ValueError, match="not both"):
        GeometricHMC(model, num_integration_steps=4, integration_time=1.0)
    with pytest.raises(ValueError, match=r"target_accept_prob must be in \(0, 1\)"):
        GeometricHMC(model, target_accept_prob=1.5)
    kernel = GeometricHMC(model)
    with pytest.raises(ValueError, match=r"init_params\['mu'\] is off Sphere"):
        kernel.init(jax.random.key(0), 10, {"mu": jnp.array([0.0, 0.0, 2.0])}, (), {})
    with pytest.raises(ValueError, match="init_params must be a dict with the latent sites"):
        kernel.init(jax.random.key(0), 10, {"nu": jnp.array([0.0, 0.0, 1.0])}, (), {})
    with pytest.raises(ValueError, match="no latent sample sites"):
        _init(lambda: numpyro.sample("y", dist.Normal(), obs=1.0))


@pytest.mark.slow
def test_vectorized_chains_equal_chains_run_alone():
    """NumPyro compiles the vmapped chains with plain jax.jit (liesample.foundation.compile): each
    chain must still give the draws of the same chain run alone, to round-off. Short runs: HMC
    amplifies round-off (1e-16 after 10 transitions, ~1e-5 after 90, measured). Nothing is
    adapted: vectorized chains adapt together (pooled), so with adaptation they differ from
    chains run alone by design."""
    kwargs = {"num_warmup": 10, "num_samples": 10, "progress_bar": False}
    fixed = {"adapt_step_size": False, "adapt_mass_matrix": False, "integration_time": 1.0}
    mcmc = MCMC(GeometricHMC(rotation_and_axis_model, **fixed), num_chains=3,
                chain_method="vectorized", **kwargs)  # fmt: skip
    mcmc.run(jax.random.key(2))
    together = mcmc.get_samples(group_by_chain=True)
    for chain, key in enumerate(jax.random.split(jax.random.key(2), 3)):
        alone = MCMC(GeometricHMC(rotation_and_axis_model, **fixed), **kwargs)
        alone.run(key)
        for site, draws in alone.get_samples().items():
            assert np.allclose(together[site][chain], draws, rtol=0, atol=1e-10), (chain, site)


def test_a_parameter_with_a_small_sd_is_not_frozen_by_a_resonance():
    """Regression (issue 28): ``x ~ Normal(0, 0.003)`` with the defaults. A fixed T = π/2 and
    Stan's mass shrinkage put x's whitened frequency near 2, so ωT ≈ π: each draw was nearly
    minus the previous one (lag-1 autocorrelation −0.9) and the chains' amplitudes froze where
    the warm-up left them (sd 13 % low, one chain 59 % low, R-hat 1.09). Jittered lengths and
    the ChEES-learnt T: every chain's sd within 5 of its MCSE, the pooled one within 10 %.
    The vectorized chains share their adapted parameters."""

    def model():
        numpyro.sample("x", dist.Normal(0.0, 0.003))

    mcmc = MCMC(
        GeometricHMC(model), num_warmup=500, num_samples=500, num_chains=4,
        chain_method="vectorized", progress_bar=False,
    )  # fmt: skip
    mcmc.run(jax.random.key(0), extra_fields=("adapt_state",))
    draws = np.asarray(mcmc.get_samples(group_by_chain=True)["x"])
    for chain in draws:
        mcse = float(arviz_stats.mcse(chain[None], method="sd"))
        assert abs(np.std(chain) - 0.003) < 5 * mcse, (np.std(chain), mcse)
    mcse = float(arviz_stats.mcse(draws, method="sd"))
    assert mcse < 0.03 * 0.003  # the 10 % criterion below is over 3 MCSE
    assert abs(np.std(draws) / 0.003 - 1.0) < 0.1
    assert abs(np.std(draws) - 0.003) < 5 * mcse
    assert float(arviz_stats.rhat(draws)) < 1.01
    lag1 = [np.corrcoef(chain[:-1], chain[1:])[0, 1] for chain in draws]
    assert min(lag1) > -0.5, lag1  # no draw is nearly minus the previous one
    # Chains that run together adapt together: one step size, one mass (pooled moments) and
    # one T in every chain (alone, one chain's step once ended 200 times below the others').
    adapted = mcmc.get_extra_fields(group_by_chain=True)["adapt_state"]
    assert np.all(np.isfinite(np.asarray(adapted.trajectory_length)))
    for leaf in jax.tree.leaves(adapted):
        leaf = np.asarray(leaf)
        assert np.all(leaf == leaf[:1]), leaf


def test_chains_adapted_alone_far_apart_are_named():
    """Issue 28: a chain adapted alone whose step or mass ends > 10x from the others' median
    is named (synthetic adaptations: the escape of ``low_dim_gauss_mix``, a step 300x below)."""
    steps = [0.6, 0.55, 0.002, 0.62]
    masses = np.ones((4, 3))
    assert [chain for chain, _ in far_adapted(steps, masses)] == [2]
    ((_, message),) = far_adapted(steps, masses)
    assert "chain 2: step_size 0.002 against the others' median 0.6" in message
    masses[0, 1] = 50.0  # one coordinate of chain 0's inverse mass
    found = dict(far_adapted(steps, masses))
    assert set(found) == {0, 2} and "inverse mass 50 at coordinate 1" in found[0]
    assert far_adapted([0.6, 0.1, 0.3], np.ones((3, 2))) == []  # 6x apart: within 10x
    assert [c for c, _ in far_adapted([0.6, np.nan, 0.5], np.ones((3, 1)))] == [1]
    assert [c for c, _ in far_adapted([0.6, 0.001], np.ones((2, 1)))] == [1]  # two: the second


@pytest.mark.slow  # the far-off check itself runs by default (test above)
def test_sequential_chains_record_their_adaptations_and_stay_quiet_when_close():
    def model():
        numpyro.sample("x", dist.Normal(0.0, 2.0))

    kernel = GeometricHMC(model, check_convergence=False)  # 5 draws: the post-run checks'd warn
    mcmc = MCMC(kernel, num_warmup=60, num_samples=5, num_chains=2, chain_method="sequential",
                progress_bar=False)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # nothing to report
        mcmc.run(jax.random.key(0))
    recorded = kernel.chain_adaptations
    assert len(recorded) == 2 and all(mass.shape == (1,) for _, mass in recorded)
    final = np.asarray(mcmc.last_state.adapt_state.step_size)
    np.testing.assert_allclose([step for step, _ in recorded], final)
