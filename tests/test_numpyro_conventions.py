"""GeometricHMC keeps numpyro.infer.HMC's conventions (issue 23, item 4).

``extra_fields`` with NUTS's names (so ``arviz.plot_energy`` works), ``init_strategy``,
``potential_fn``, ``dense_mass``, ``find_heuristic_step_size``, ``num_steps`` and
``trajectory_length``, the refusals of what the kernel cannot do, and the shapes settled in
``init``. Statistical checks: exact Gaussian references, 5 MCSE (ArviZ, from the chains), fixed
keys; short runs, so that each test takes seconds.
"""

import inspect
import warnings

import arviz_stats
import jax
import jax.numpy as jnp
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.infer import MCMC, init_to_median, init_to_sample, init_to_value

from liesample.geometry.spaces import SO
from liesample.interop.numpyro_distributions import VonMisesFisher, rotation
from liesample.interop.numpyro_kernel import GeometricHMC
from liesample.tuning.trajectory import halton

NORTH = np.array([0.0, 0.0, 1.0])
FISHER = np.diag([2.0, 1.0, -0.5])


def direction_model():
    mu = numpyro.sample("mu", VonMisesFisher(NORTH, 1.0))
    scale = numpyro.sample("scale", dist.LogNormal(0.0, 0.5))
    numpyro.sample("y", dist.Normal(mu, scale), obs=np.array([0.0, 0.6, 0.8]))


def _within(draws, exact, name, method="mean", z=5.0):
    """``draws`` (chain, draw): the mean (or sd) within ``z`` MCSE of ``exact``."""
    draws = np.asarray(draws)
    mcse = float(arviz_stats.mcse(draws, method=method))
    value = float(np.mean(draws) if method == "mean" else np.std(draws, ddof=1))
    assert abs(value - exact) < z * mcse, (name, method, value, exact, mcse)


# ------------------------------------------------------------------ extra fields


NUTS_FIELDS = ("energy", "diverging", "accept_prob", "num_steps", "adapt_state")


def test_extra_fields_have_nuts_names_and_arviz_plot_energy_works():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    az = pytest.importorskip("arviz")
    fields = (*NUTS_FIELDS, "potential_energy", "mean_accept_prob", "trajectory_length")
    fields += ("adapt_state.step_size", "step_size")
    mcmc = MCMC(
        GeometricHMC(direction_model),
        num_warmup=60,
        num_samples=50,
        num_chains=2,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(0), extra_fields=fields)
    extra = mcmc.get_extra_fields(group_by_chain=True)
    for name in fields:
        if name != "adapt_state":
            assert np.shape(extra[name]) == (2, 50), name
    kinetic = np.asarray(extra["energy"]) - np.asarray(extra["potential_energy"])
    assert np.all(kinetic >= 0.0) and np.all(np.isfinite(kinetic)) and np.any(kinetic > 0.0)
    assert extra["diverging"].dtype == bool
    accept = np.asarray(extra["accept_prob"])
    assert np.all((accept >= 0.0) & (accept <= 1.0))
    running = np.cumsum(accept, axis=1) / np.arange(1, 51)  # NumPyro's mean over the samples
    assert np.allclose(extra["mean_accept_prob"], running, rtol=1e-12)
    step = np.asarray(extra["step_size"])
    assert np.allclose(extra["trajectory_length"], step * np.asarray(extra["num_steps"]))
    # adapt_state: the step size and inverse mass after warm-up, keyed by tuples of site names.
    adapt = extra["adapt_state"]
    assert np.array_equal(adapt.step_size, step) and np.array_equal(
        extra["adapt_state.step_size"], step
    )
    assert set(adapt.inverse_mass_matrix) == {("mu",), ("scale",)}
    assert np.shape(adapt.inverse_mass_matrix[("scale",)]) == (2, 50)
    assert np.all(np.ptp(np.asarray(adapt.inverse_mass_matrix[("scale",)]), axis=1) == 0.0)
    # the learnt integration time, fixed after warm-up; each transition integrates u T
    times = np.asarray(adapt.trajectory_length)
    assert np.all(np.isfinite(times) & (times > 0)) and np.all(np.ptp(times, axis=1) == 0.0)
    assert np.all(np.asarray(extra["trajectory_length"]) <= times + step)

    tree = az.from_numpyro(mcmc)
    stats = tree.sample_stats
    assert {"energy", "diverging", "acceptance_rate", "n_steps", "lp"} <= set(stats.data_vars)
    assert stats["energy"].shape == (2, 50) and stats["diverging"].dtype == bool
    az.plot_energy(tree)  # NUTS's diagnostic reads GeometricHMC's energy
    matplotlib.pyplot.close("all")


# ------------------------------------------------------------------ init_strategy


def sphere_and_scale_model():
    numpyro.sample("mu", VonMisesFisher(NORTH, 2.0))
    numpyro.sample("scale", dist.LogNormal(0.0, 1.0))


class _RotationDensity(dist.Distribution):
    """``exp tr(Fᵀ R)`` on SO(3), unnormalised: cheaper to compile than ``MatrixFisher``."""

    support = rotation

    def __init__(self):
        super().__init__((), (3, 3))

    def log_prob(self, value):
        return jnp.sum(FISHER * value, (-2, -1))


def rotation_model():
    numpyro.sample("mu", VonMisesFisher(NORTH, 2.0))
    numpyro.sample("R", _RotationDensity())
    numpyro.sample("scale", dist.LogNormal(0.0, 1.0))


def _start(strategy, model=sphere_and_scale_model, key=0, init_params=None):
    kernel = GeometricHMC(model, init_strategy=strategy)
    return kernel.init(jax.random.key(key), 10, init_params, (), {}), kernel


def test_init_to_value_starts_where_told():
    """Values on the manifold are kept; one off it (a rotation scaled by 2) is taken to its
    nearest point, as NumPyro's strategies go through a bijection that SO(3) lacks."""
    mu = np.array([0.6, 0.0, 0.8])
    rotation = np.asarray(SO(3).uniform(jax.random.key(5)))
    values = {"mu": mu, "R": 2.0 * rotation, "scale": 2.0}
    state, kernel = _start(init_to_value(values=values), model=rotation_model)
    assert np.allclose(state.z["mu"], mu, rtol=0, atol=1e-15)
    assert np.allclose(state.z["R"], rotation, rtol=0, atol=1e-14)
    assert float(state.z["scale"]) == pytest.approx(np.log(2.0), abs=1e-15)  # unconstrained
    logdensity = kernel._logdensity_fn((), {})(state.z)
    assert float(state.potential_energy) == pytest.approx(-float(logdensity), rel=1e-12)


@pytest.mark.slow  # the refusals, init_to_value and the extra fields run by default
def test_other_init_strategies_start_on_the_manifold():
    state, _ = _start(init_to_value(values={"scale": 0.5}), key=2)  # mu: init_to_uniform
    assert float(state.z["scale"]) == pytest.approx(np.log(0.5), abs=1e-15)
    assert np.isclose(np.linalg.norm(state.z["mu"]), 1.0, atol=1e-14)
    for strategy in (init_to_median(num_samples=15), init_to_sample):
        state, _ = _start(strategy, key=1)
        assert np.isclose(np.linalg.norm(state.z["mu"]), 1.0, atol=1e-14)
        assert np.isfinite(state.z["scale"])
        if strategy is not init_to_sample:  # 15 draws of LogNormal(0, 1): median near 1
            assert abs(float(state.z["scale"])) < 1.5
            assert float(state.z["mu"][2]) > 0.0  # the prior median of mu leans to NORTH
    # init_params given to MCMC.run win over the strategy, as in NumPyro.
    given = {"mu": NORTH, "scale": 0.25}
    state, _ = _start(init_to_value(values={"scale": 2.0}), init_params=given)
    assert np.array_equal(state.z["mu"], NORTH) and float(state.z["scale"]) == 0.25


# ------------------------------------------------------------------ potential_fn, dense mass

MEAN = np.array([1.0, -2.0])
SD = np.array([1.0, 2.0])
RHO = 0.9
COVARIANCE = np.array([[SD[0] ** 2, RHO * SD[0] * SD[1]], [RHO * SD[0] * SD[1], SD[1] ** 2]])
PRECISION = np.linalg.inv(COVARIANCE)


def gaussian_potential(x):
    delta = x - MEAN
    return 0.5 * delta @ PRECISION @ delta


@pytest.mark.slow  # the refusals, init_to_value and the extra fields run by default
def test_potential_fn_with_dense_mass_recovers_a_correlated_gaussian():
    """Model-free use as in numpyro.infer.HMC: init_params per chain, draws are ``z``; the
    dense mass adapts to the covariance; find_heuristic_step_size and trajectory_length."""
    kernel = GeometricHMC(
        potential_fn=gaussian_potential,
        dense_mass=True,
        find_heuristic_step_size=True,
        step_size=1e-3,
        trajectory_length=1.5,
    )
    mcmc = MCMC(
        kernel,
        num_warmup=300,
        num_samples=600,
        num_chains=2,
        chain_method="vectorized",
        progress_bar=False,
    )
    starts = np.array([[3.0, 3.0], [-3.0, 0.0]])
    mcmc.run(
        jax.random.key(4),
        init_params=starts,
        extra_fields=("adapt_state", "num_steps", "step_size", "trajectory_length"),
    )
    draws = np.asarray(mcmc.get_samples(group_by_chain=True))
    assert draws.shape == (2, 600, 2)
    for i in range(2):
        _within(draws[..., i], MEAN[i], f"x[{i}]")
        _within(draws[..., i], SD[i], f"x[{i}]", method="sd")
    assert float(arviz_stats.rhat(draws[..., 1])) < 1.05
    extra = mcmc.get_extra_fields(group_by_chain=True)
    mass = np.asarray(extra["adapt_state"].inverse_mass_matrix[("z",)])[:, -1]
    assert mass.shape == (2, 2, 2)
    correlation = mass[:, 0, 1] / np.sqrt(mass[:, 0, 0] * mass[:, 1, 1])
    assert np.all(correlation > 0.6), correlation  # a diagonal mass would have 0
    steps, step = np.asarray(extra["num_steps"]), np.asarray(extra["step_size"])
    # T = 1.5 fixed (not learnt), jittered: L = ceil(u T / ε), u in (0, 1)
    np.testing.assert_allclose(extra["adapt_state"].trajectory_length, 1.5)
    u = np.asarray(halton(np.arange(300, 900)))  # the Halton points of the draws' transitions
    assert np.array_equal(steps, np.maximum(np.ceil(u * 1.5 / step), 1).astype(int))
    assert np.all(step > 1e-2)  # the heuristic left 1e-3 behind
    tree = pytest.importorskip("arviz").from_numpyro(mcmc)  # no model: ArviZ still converts
    assert tree.posterior["Param:0"].shape[:2] == (2, 600)


def correlated_sites_model():
    a = numpyro.sample("a", dist.Normal(MEAN[0], SD[0]))
    conditional_sd = SD[1] * np.sqrt(1 - RHO**2)
    numpyro.sample("b", dist.Normal(MEAN[1] + RHO * SD[1] / SD[0] * (a - MEAN[0]), conditional_sd))
    numpyro.sample("mu", VonMisesFisher(NORTH, 2.0))


@pytest.mark.slow  # the refusals, init_to_value and the extra fields run by default
def test_dense_mass_joins_euclidean_sites_of_a_model():
    """``dense_mass=[("a", "b")]``: one dense block over two sites (a sphere site beside it);
    exact moments of the Gaussian and of the vMF's ``E[μ_z] = coth κ − 1/κ``; num_steps."""
    kernel = GeometricHMC(correlated_sites_model, dense_mass=[("a", "b")], num_steps=4)
    mcmc = MCMC(
        kernel,
        num_warmup=300,
        num_samples=500,
        num_chains=2,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(6), extra_fields=("adapt_state", "num_steps"))
    samples = mcmc.get_samples(group_by_chain=True)
    for i, site in enumerate("ab"):
        _within(samples[site], MEAN[i], site)
        _within(samples[site], SD[i], site, method="sd")
    _within(np.asarray(samples["mu"])[..., 2], 1 / np.tanh(2.0) - 1 / 2.0, "mu_z")
    extra = mcmc.get_extra_fields(group_by_chain=True)
    assert np.all(np.asarray(extra["num_steps"]) == 4)
    masses = extra["adapt_state"].inverse_mass_matrix
    assert set(masses) == {("a", "b"), ("mu",)}
    mass = np.asarray(masses[("a", "b")])[:, -1]
    assert mass.shape == (2, 2, 2)
    assert np.all(mass[:, 0, 1] / np.sqrt(mass[:, 0, 0] * mass[:, 1, 1]) > 0.6)


def test_a_given_dense_inverse_mass_and_its_refusals():
    given = {("a", "b"): COVARIANCE, "mu": 0.5}
    kernel = GeometricHMC(
        correlated_sites_model, dense_mass=[("a", "b")], inverse_mass_matrix=given
    )
    state = kernel.init(jax.random.key(0), 0, None, (), {})
    assert np.array_equal(state.adapt_state.inverse_mass_matrix[("a", "b")], COVARIANCE)
    assert np.array_equal(state.adapt_state.inverse_mass_matrix[("mu",)], [0.5])
    with pytest.raises(ValueError, match=r"inverse_mass_matrix has the key 'a', which names no"):
        GeometricHMC(
            correlated_sites_model,
            dense_mass=[("a", "b")],
            inverse_mass_matrix={"a": 1.0, "b": 1.0, "mu": 1.0},
        ).init(jax.random.key(0), 0, None, (), {})
    with pytest.raises(ValueError, match=r"misses the sites or groups \[\('mu',\)\]"):
        GeometricHMC(
            correlated_sites_model,
            dense_mass=[("a", "b")],
            inverse_mass_matrix={("a", "b"): COVARIANCE},
        ).init(jax.random.key(0), 0, None, (), {})
    diagonal = {("a", "b"): np.array([1.0, 4.0]), "mu": 1.0}
    state = GeometricHMC(
        correlated_sites_model, dense_mass=[("a", "b")], inverse_mass_matrix=diagonal
    ).init(jax.random.key(0), 0, None, (), {})
    assert np.array_equal(state.adapt_state.inverse_mass_matrix[("a", "b")], np.diag([1.0, 4.0]))
    with pytest.raises(ValueError, match=r"inverse mass of \('a', 'b'\) must have leading size 2"):
        GeometricHMC(
            correlated_sites_model,
            dense_mass=[("a", "b")],
            inverse_mass_matrix={("a", "b"): np.ones(3), "mu": 1.0},
        ).init(jax.random.key(0), 0, None, (), {})
    with pytest.raises(ValueError, match="positive definite"):
        GeometricHMC(
            correlated_sites_model,
            dense_mass=[("a", "b")],
            inverse_mass_matrix={("a", "b"): -COVARIANCE, "mu": 1.0},
        ).init(jax.random.key(0), 0, None, (), {})


# ------------------------------------------------------------------ refusals and shapes


def test_dense_mass_on_a_manifold_site_is_refused_by_name_in_init():
    def init(**kwargs):
        GeometricHMC(correlated_sites_model, **kwargs).init(jax.random.key(0), 10, None, (), {})

    with pytest.raises(
        ValueError,
        match=r"dense_mass: site 'mu' moves on Sphere.*Euclidean "
        r"sites only: allowed dense_mass=\[\('a', 'b'\)\]",
    ):
        init(dense_mass=True)
    with pytest.raises(ValueError, match="dense_mass names 'c', which is not a latent site"):
        init(dense_mass=[("a", "c")])
    with pytest.raises(ValueError, match="dense_mass names the site 'a' in two groups"):
        init(dense_mass=[("a",), ("a", "b")])
    with pytest.raises(TypeError, match="dense_mass must be 'auto', a bool or a list of tuples"):
        GeometricHMC(correlated_sites_model, dense_mass="a")


def test_auto_dense_mass_joins_the_euclidean_sites_when_the_warm_up_can_estimate_it():
    """The default ``dense_mass="auto"``: one dense block over the ``Euclidean`` sites (the
    sphere site keeps its own) when the warm-up has ``AUTO_DENSE_WARMUP_PER_DIMENSION``
    iterations per coordinate; diagonal with a shorter warm-up or a given mass."""
    from liesample.interop.numpyro_kernel import AUTO_DENSE_WARMUP_PER_DIMENSION

    def masses(num_warmup, **kwargs):
        kernel = GeometricHMC(correlated_sites_model, **kwargs)
        state = kernel.init(jax.random.key(0), num_warmup, None, (), {})
        return state.adapt_state.inverse_mass_matrix

    enough = 2 * AUTO_DENSE_WARMUP_PER_DIMENSION
    dense = masses(enough)
    assert set(dense) == {("a", "b"), ("mu",)}
    assert np.shape(dense[("a", "b")]) == (2, 2)
    assert set(masses(enough - 1)) == {("a",), ("b",), ("mu",)}
    assert set(masses(enough, dense_mass=False)) == {("a",), ("b",), ("mu",)}
    given = {"a": 1.0, "b": 1.0, "mu": 1.0}
    assert set(masses(enough, inverse_mass_matrix=given)) == {("a",), ("b",), ("mu",)}


def test_numpyro_keywords_out_of_reach_are_refused_naming_what_is_allowed():
    model = correlated_sites_model
    with pytest.raises(ValueError, match=r"kinetic_fn is not supported.*allowed: kinetic_fn=None"):
        GeometricHMC(model, kinetic_fn=lambda m, r: 0.0)
    with pytest.raises(ValueError, match="allowed: forward_mode_differentiation=False"):
        GeometricHMC(model, forward_mode_differentiation=True)
    with pytest.raises(ValueError, match="allowed: regularize_mass_matrix=True"):
        GeometricHMC(model, regularize_mass_matrix=False)
    with pytest.raises(ValueError, match="give model or potential_fn, not both"):
        GeometricHMC(model, potential_fn=gaussian_potential)
    with pytest.raises(TypeError, match=r"model must be a NumPyro model .*or give potential_fn"):
        GeometricHMC()
    with pytest.raises(ValueError, match="init_strategy needs a model"):
        GeometricHMC(potential_fn=gaussian_potential, init_strategy=init_to_median())
    with pytest.raises(TypeError, match="init_strategy must be a NumPyro initialisation"):
        GeometricHMC(model, init_strategy="median")
    with pytest.raises(ValueError, match="num_steps is NumPyro's name for num_integration_steps"):
        GeometricHMC(model, num_steps=3, num_integration_steps=3)
    with pytest.raises(ValueError, match="trajectory_length is NumPyro's name for integration"):
        GeometricHMC(model, trajectory_length=1.0, integration_time=1.0)
    with pytest.raises(ValueError, match=r"integration_time \(trajectory_length\) or num_int"):
        GeometricHMC(model, num_steps=3, trajectory_length=1.0)
    with pytest.raises(ValueError, match=r"num_integration_steps \(num_steps\) must be an int"):
        GeometricHMC(model, num_steps=0)
    with pytest.raises(ValueError, match=r"with potential_fn, give init_params to MCMC\.run"):
        GeometricHMC(potential_fn=gaussian_potential).init(jax.random.key(0), 10, None, (), {})
    with pytest.raises(TypeError, match="init_params must be an array or a dict of arrays"):
        GeometricHMC(potential_fn=gaussian_potential).init(
            jax.random.key(0), 10, {"x": {"y": MEAN}}, (), {}
        )


def test_find_heuristic_step_size_sets_the_first_step_as_numpyro_does():
    """From a tiny step, doubling until one leapfrog step's acceptance falls below 0.8: on a
    Gaussian with unit mass that is a step of order its smallest sd."""

    def init(**kwargs):
        kernel = GeometricHMC(potential_fn=gaussian_potential, step_size=1e-4, **kwargs)
        return kernel.init(jax.random.key(0), 10, np.zeros(2), (), {})

    step = float(init(find_heuristic_step_size=True).step_size)
    assert 0.05 < step < 4.0
    assert np.log2(step / 1e-4) == pytest.approx(round(np.log2(step / 1e-4)), abs=1e-9)
    assert float(init().step_size) == 1e-4  # off by default, as in NumPyro
    assert float(init(find_heuristic_step_size=True, adapt_step_size=False).step_size) == 1e-4


def test_shapes_are_checked_in_init_before_any_transition(monkeypatch):
    """A start of the wrong shape, or off its manifold, is refused by ``init``: ``sample`` is
    never reached. Deterministic sites are evaluated (abstractly) in ``init`` too."""
    calls = []
    monkeypatch.setattr(GeometricHMC, "sample", lambda *args: calls.append(args))

    def run(model, init_params):
        mcmc = MCMC(GeometricHMC(model), num_warmup=5, num_samples=5, progress_bar=False)
        mcmc.run(jax.random.key(0), init_params=init_params)

    bad_shape = {"a": jnp.zeros(3), "b": 0.0, "mu": NORTH}
    with pytest.raises(ValueError, match=r"init_params\['a'\]"):
        run(correlated_sites_model, bad_shape)
    off_sphere = {"a": 0.0, "b": 0.0, "mu": 2.0 * NORTH}
    with pytest.raises(ValueError, match=r"init_params\['mu'\] is off Sphere"):
        run(correlated_sites_model, off_sphere)

    def deterministic_model():
        a = numpyro.sample("a", dist.Normal())
        numpyro.deterministic("twice", 2.0 * a)

    kernel = GeometricHMC(deterministic_model)
    state = kernel.init(jax.random.key(0), 5, None, (), {})
    shapes = jax.eval_shape(kernel.postprocess_fn((), {}), state.z)
    assert shapes["twice"].shape == () and shapes["a"].shape == ()
    assert calls == []


def test_class_docstring_lists_every_parameter():
    doc = GeometricHMC.__doc__  # numpydoc: __init__'s parameters on the class
    assert doc is not None and "Parameters\n    ----------" in doc
    for name in inspect.signature(GeometricHMC.__init__).parameters:
        if name != "self":
            assert name in doc, name


def test_num_steps_counts_gradients_and_an_unadapted_run_warns():
    """``num_steps`` counts gradient evaluations (two per ``minimal_norm`` step), so ESS per
    gradient from it is right for every scheme; ``num_warmup=0`` with something to adapt warns
    (it ran unadapted and silently: E[log κ] 0.35 against 2.74, R-hat 7.5), and stays quiet
    when everything is given."""
    kernel = GeometricHMC(
        potential_fn=gaussian_potential, integrator="minimal_norm", num_steps=3, step_size=0.3
    )
    mcmc = MCMC(kernel, num_warmup=0, num_samples=5, progress_bar=False)
    fields = ("num_steps", "trajectory_length", "adapt_state")
    with pytest.warns(UserWarning, match="num_warmup=0 runs unadapted, with step_size=0.3"):
        mcmc.run(jax.random.key(0), init_params=np.zeros(2), extra_fields=fields)
    extra = mcmc.get_extra_fields()
    assert np.all(np.asarray(extra["num_steps"]) == 6)
    np.testing.assert_allclose(extra["trajectory_length"], 0.9)
    given = GeometricHMC(
        potential_fn=gaussian_potential, num_steps=3, adapt_step_size=False,
        adapt_mass_matrix=False, check_convergence=False,  # 5 draws: the post-run checks'd warn
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        MCMC(given, num_warmup=0, num_samples=5, progress_bar=False).run(
            jax.random.key(0), init_params=np.zeros(2)
        )
