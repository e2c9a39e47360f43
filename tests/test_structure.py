"""Compile once per structure: a sampler that declares a ``Structure`` (``Sampler.structure``)
is compiled by ``liesample.sample`` once for every value of its numeric parameters, so a sweep
over ``β`` (or ``σ``, or the step size) compiles at its first point only, and gives the draws of
a sampler compiled for one value (``tests/test_draws_unchanged.py`` holds them bit for bit)."""

import contextlib

import jax
import numpy as np
import pytest

import liesample
from liesample.integrators.chain_loop import run_draws
from liesample.samplers.contract import Structure, reduce_over_thinning
from liesample.tuning.warmup import warm_up

SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
STARTS = np.tile(np.array([0.9, 1.2, 0.0]), (4, 1))


class _Compiles:
    """Counts XLA backend compilations while active, and the names of the programs."""

    def __init__(self):
        self.count, self.names = 0, []

    def __call__(self, event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            self.count += 1
            self.names.append(kwargs.get("fun_name", ""))


@contextlib.contextmanager
def counted_compiles():
    """``with counted_compiles() as compiles:`` counts the compilations of the block."""
    compiles = _Compiles()
    jax.monitoring.register_event_duration_secs_listener(compiles)
    try:
        yield compiles
    finally:
        jax.monitoring.unregister_event_duration_listener(compiles)


def _sample(sampler, starts=STARTS, num_draws=40, num_warmup=20):
    return liesample.sample(
        sampler, jax.random.key(0), starts, num_draws, num_warmup=num_warmup, progress_bar=False
    )


@pytest.mark.filterwarnings("ignore::UserWarning")  # 40 draws: the convergence checks speak
def test_a_beta_sweep_compiles_at_its_first_point_only():
    first = _sample(liesample.lie_poisson_langevin(SYSTEM, beta=1.0))
    with counted_compiles() as compiles:
        second = _sample(liesample.lie_poisson_langevin(SYSTEM, beta=3.0))
    assert compiles.count == 0
    assert first.attrs["beta"] == 1.0 and second.attrs["beta"] == 3.0
    # the second point ran at its own β: the law concentrates on the largest axis
    assert np.mean(second.posterior["mu"].values[..., 2] ** 2) > np.mean(
        first.posterior["mu"].values[..., 2] ** 2
    )


@pytest.mark.filterwarnings("ignore::UserWarning")  # 7 draws: the convergence checks speak
def test_a_first_call_compiles_the_step_once_for_its_warm_up_and_every_chunk():
    """The warm-up's steps, the chunks and a shorter last chunk run in one program: a lattice
    new to the process compiles the heat bath's step into one program only."""
    system = liesample.systems.wilson_gauge("U1", (6, 4))  # a shape no other test here uses
    sampler = liesample.wilson_heat_bath(system, beta=1.0)
    starts = np.stack([system.cold_start()] * 2)
    with counted_compiles() as compiles:
        tree = liesample.sample(
            sampler, jax.random.key(0), starts, 7, num_warmup=5, chunk_draws=3,
            progress_bar=False,
        )  # fmt: skip
    stepping = [name for name in compiles.names if "_run" in name]
    assert stepping == ["jit(_run_chunk)"], compiles.names
    # the same steps as one chunk of every draw: the shorter last chunk keeps its own draws
    whole = liesample.sample(
        sampler, jax.random.key(0), starts, 7, num_warmup=5, chunk_draws=7, progress_bar=False
    )
    np.testing.assert_array_equal(tree.posterior["theta"].values, whole.posterior["theta"].values)


@pytest.mark.filterwarnings("ignore::UserWarning")  # 7 draws: the convergence checks speak
def test_a_dual_averaging_warm_up_runs_in_the_program_of_the_chunks():
    """Dual averaging's warm-up adapts in the chunks' program: a first call compiles the
    step into one program, and its tuned step and draws are those of the warm-up run alone
    (``liesample.tuning.warmup.warm_up``) followed by chunks at that step."""
    system = liesample.systems.rigid_body((1.0, 3.0, 5.0))  # inertia no other test here uses
    sampler = liesample.adjusted_lie_poisson(system, beta=2.0, sigma=1.0)
    starts = np.tile(np.array([0.3, 1.1, 0.2]), (3, 1))
    with counted_compiles() as compiles:
        tree = liesample.sample(
            sampler, jax.random.key(2), starts, 7, num_warmup=23, chunk_draws=3,
            progress_bar=False,
        )  # fmt: skip
    stepping = [name for name in compiles.names if "_run" in name or "dual" in name]
    assert stepping == ["jit(_run_chunk)"], compiles.names
    chain_keys = jax.random.split(jax.random.key(2), 3)
    states = jax.vmap(sampler.init)(starts)
    tuned, moved = warm_up(sampler, jax.random.key(2), chain_keys, states, starts, 23)
    assert tree.attrs["step_size"] == tuned.settings["step_size"]
    assert tree.attrs["step_size_source"] == tuned.settings["step_size_source"]
    assert "mean acceptance in the second half of the warm-up" in tree.attrs["step_size_source"]
    fixed = liesample.adjusted_lie_poisson(
        system, beta=2.0, sigma=1.0, step_size=tuned.settings["step_size"]
    )
    draws = [
        run_draws(fixed, key, jax.tree.map(lambda leaf, c=c: leaf[c], moved), 23, 7, 1,
                  reduce_over_thinning)[1][0]
        for c, key in enumerate(chain_keys)
    ]  # fmt: skip
    np.testing.assert_allclose(tree.posterior["mu"].values, np.stack(draws), rtol=1e-12)


def test_the_structure_rebuilds_the_sampler_it_declares():
    sampler = liesample.lie_poisson_langevin(SYSTEM, beta=2.0, sigma=0.7, step_size=0.05)
    structure = sampler.structure
    assert isinstance(structure, Structure)
    assert structure.values == {"step_size": 0.05, "sigma": 0.7, "theta": 0.5 * 2.0 * 0.7**2}
    other = liesample.lie_poisson_langevin(SYSTEM, beta=5.0, sigma=0.7, step_size=0.02)
    assert other.structure.build == structure.build  # one program for both
    rebuilt = structure.build(**structure.values)
    state = sampler.init(STARTS[0])
    key = jax.random.key(1)
    np.testing.assert_array_equal(
        rebuilt.step(key, state)[0].position, sampler.step(key, state)[0].position
    )
    # a system rebuilt from equal arguments is the same structure; another system or
    # integrator is another one
    assert (
        liesample.lie_poisson_langevin(
            liesample.systems.rigid_body((1.0, 2.0, 4.0)), beta=2.0, step_size=0.05
        ).structure.build
        == structure.build
    )
    assert (
        liesample.lie_poisson_langevin(
            liesample.systems.rigid_body((1.0, 2.0, 5.0)), beta=2.0, step_size=0.05
        ).structure.build
        != structure.build
    )
    assert (
        liesample.lie_poisson_langevin(
            SYSTEM, beta=2.0, step_size=0.05, integrator="lie_euler"
        ).structure.build
        != structure.build
    )


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_an_adjusted_sweep_with_a_given_step_compiles_at_its_first_point_only():
    first = liesample.adjusted_lie_poisson(SYSTEM, beta=1.0, step_size=0.2)
    _sample(first, num_warmup=0)  # 40 draws: the chunk program of the warm-up sweep below
    with counted_compiles() as compiles:
        second = liesample.adjusted_lie_poisson(SYSTEM, beta=4.0, step_size=0.2)
        _sample(second, num_warmup=0)
    assert compiles.count == 0
    assert second.structure.values["beta"] == 4.0


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_an_adjusted_sweep_with_its_warm_up_compiles_at_its_first_point_only():
    first = liesample.adjusted_lie_poisson(SYSTEM, beta=1.0)
    _sample(first)
    with counted_compiles() as compiles:
        tree = _sample(liesample.adjusted_lie_poisson(SYSTEM, beta=4.0))
    assert compiles.count == 0
    assert tree.attrs["beta"] == 4.0
    assert tree.attrs["step_size_source"].startswith("warm-up dual averaging")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_vortex_sweep_with_its_warm_up_compiles_at_its_first_point_only():
    system = liesample.systems.point_vortices([1.0, 1.0, -1.0, -1.0])
    starts = np.stack([system.default_position] * 4)

    _sample(liesample.vortex_metropolis(system, beta=-1.0), starts, num_draws=20)
    with counted_compiles() as compiles:
        tree = _sample(liesample.vortex_metropolis(system, beta=2.0), starts, num_draws=20)
    assert compiles.count == 0
    assert tree.attrs["beta"] == 2.0


@pytest.mark.filterwarnings("ignore::UserWarning")  # 40 draws: the convergence checks speak
def test_a_spin_sweep_compiles_at_its_first_point_only():
    """Every spin sampler declares its structure (``samplers/spins/_lattice.spin_sampler``):
    the heat bath (the recommended one) at a second β compiles nothing."""
    chain = liesample.systems.heisenberg((16,), coupling=1.0)
    starts = np.tile(chain.default_position, (2, 1, 1))
    first = _sample(liesample.heisenberg_heat_bath(chain, beta=0.5), starts, num_warmup=0)
    with counted_compiles() as compiles:
        second = _sample(liesample.heisenberg_heat_bath(chain, beta=4.0), starts, num_warmup=0)
    assert compiles.count == 0
    # the second point ran at its own β: neighbours align more when it is colder
    energies = [float(np.mean(t.sample_stats["hamiltonian"].values)) for t in (first, second)]
    assert energies[1] < energies[0]
    assert liesample.heisenberg_metropolis(chain, beta=1.0).structure.build == (
        liesample.heisenberg_metropolis(chain, beta=2.0, proposal_scale=0.3).structure.build
    )


def test_a_gauge_sweep_compiles_at_its_first_point_only():
    """``wilson_heat_bath`` declares its structure, and a lattice is a value: the same lattice
    built again at another β compiles nothing."""
    lattice = liesample.systems.wilson_gauge("U1", (4, 4))
    starts = np.stack([lattice.cold_start()] * 2)
    first = _sample(liesample.wilson_heat_bath(lattice, beta=0.5), starts, num_warmup=0)
    again = liesample.systems.wilson_gauge("U1", (4, 4))
    with counted_compiles() as compiles:
        second = _sample(liesample.wilson_heat_bath(again, beta=4.0), starts, num_warmup=0)
    assert compiles.count == 0
    # each point ran at its own β: the plaquettes order more when it is larger
    name = next(iter(first.posterior.data_vars))
    plaquettes = [
        float(jax.vmap(lattice.mean_plaquette)(t.posterior[name].values[:, -1]).mean())
        for t in (first, second)
    ]
    assert plaquettes[1] > plaquettes[0]


# --------------------------------------------------------------------------- rebuilt by a user
# A user's ``def run(beta): system = ...; sampler = ...; return sample(...)``: every call builds
# the system and the sampler anew from equal arguments, at another β or step size. The systems
# are equal by value (liesample.foundation.identity) and the samplers declare their structure,
# so only the first call compiles, for one sampler of every family.


def _gauss(x):
    return -0.5 * x @ x


def _sphere(x, kappa=3.0):
    return kappa * x[2]


def _rigid(beta, step):
    return liesample.lie_poisson_langevin(
        liesample.systems.rigid_body((1.0, 2.0, 4.0)), beta=beta, step_size=step
    ), STARTS


def _adjusted(beta, step):
    return liesample.adjusted_lie_poisson(
        liesample.systems.rigid_body((1.0, 2.0, 4.0)), beta=beta, step_size=step
    ), STARTS


def _vortices(beta, step):
    system = liesample.systems.point_vortices([1.0, 1.0, -1.0, -1.0])
    return liesample.vortex_metropolis(system, beta=beta), np.stack([system.default_position] * 2)


def _spins(beta, step):
    chain = liesample.systems.heisenberg((8,), coupling=1.0)
    return liesample.heisenberg_heat_bath(chain, beta=beta), np.stack([chain.default_position] * 2)


def _cluster(beta, step):
    chain = liesample.systems.heisenberg((8,), coupling=1.0)
    return liesample.heisenberg_wolff(chain, beta=beta), np.stack([chain.default_position] * 2)


def _gauge(beta, step):
    lattice = liesample.systems.wilson_gauge("SU2", (2, 2))
    return liesample.wilson_heat_bath(lattice, beta=beta), np.stack([lattice.cold_start()] * 2)


def _gauge_hmc(beta, step):
    from liesample.samplers.gauge.hmc import gauge_hmc

    lattice = liesample.systems.wilson_gauge("U1", (2, 2))
    sampler = gauge_hmc(lattice, beta=beta, step_size=step, num_integration_steps=3)
    return sampler, np.stack([lattice.cold_start()] * 2)


def _geometric(beta, step):
    sampler = liesample.geometric_hmc(
        _sphere, liesample.spaces.Sphere(2), step_size=step, num_integration_steps=3,
        model_args=(beta,),
    )  # fmt: skip
    return sampler, np.tile([0.0, 0.0, 1.0], (2, 1))


def _magnetic(beta, step):
    sampler = liesample.magnetic_hmc(
        _gauss, step, np.ones(2) / beta, 3, liesample.default_magnetic_field(np.ones(2), 1.0)
    )
    return sampler, np.zeros((2, 2))


FAMILIES = {
    "orbit": _rigid,
    "adjusted orbit": _adjusted,
    "vortex": _vortices,
    "spins heat bath": _spins,
    "spins cluster": _cluster,
    "gauge heat bath": _gauge,
    "gauge hmc": _gauge_hmc,
    "geometric hmc": _geometric,
    "magnetic hmc": _magnetic,
}


@pytest.mark.filterwarnings("ignore::UserWarning")  # a few draws: the convergence checks speak
@pytest.mark.parametrize("family", FAMILIES)
def test_a_rebuilt_sampler_at_another_beta_and_step_compiles_nothing(family):
    build = FAMILIES[family]
    sampler, starts = build(1.0, 0.1)
    _sample(sampler, starts, num_draws=4, num_warmup=0)
    with counted_compiles() as compiles:
        sampler, starts = build(2.0, 0.05)
        _sample(sampler, starts, num_draws=4, num_warmup=0)
    assert compiles.count == 0


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_log_density_sweep_over_model_args_with_its_warm_up_compiles_nothing():
    """The same log density at other data (``model_args``), warm-up and all, reuses every
    program; each point samples its own law."""
    space = liesample.spaces.Sphere(2)
    starts = np.tile([0.0, 0.0, 1.0], (2, 1))
    first = _sample(liesample.geometric_hmc(_sphere, space, model_args=(0.5,)), starts)
    with counted_compiles() as compiles:
        second = _sample(liesample.geometric_hmc(_sphere, space, model_args=(8.0,)), starts)
    assert compiles.count == 0
    # κ = 8 concentrates x_z near 1 (its mean is coth κ − 1/κ ≈ 0.875); κ = 0.5 does not
    name = next(iter(first.posterior.data_vars))
    means = [float(t.posterior[name].values[..., 2].mean()) for t in (first, second)]
    assert means[1] > 0.7 > means[0]


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_magnetic_hmc_warm_up_sweep_over_model_args_compiles_nothing():
    def scaled(x, scale):
        return -0.5 * x @ x / scale

    starts = np.zeros((2, 2))
    _sample(liesample.magnetic_hmc(scaled, model_args=(1.0,)), starts, num_draws=100)
    with counted_compiles() as compiles:
        tree = _sample(liesample.magnetic_hmc(scaled, model_args=(4.0,)), starts, num_draws=100)
    assert compiles.count == 0
    name = next(iter(tree.posterior.data_vars))
    assert float(tree.posterior[name].values.var()) > 1.5  # variance 4, not 1


def test_model_args_are_refused_by_name():
    with pytest.raises(TypeError, match="model_args must be a tuple"):
        liesample.geometric_hmc(_sphere, liesample.spaces.Sphere(2), model_args=3.0)
    with pytest.raises(TypeError, match="model_kwargs must be a dict"):
        liesample.magnetic_hmc(_gauss, model_kwargs=(1.0,))
