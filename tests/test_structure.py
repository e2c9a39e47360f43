"""Compile once per structure: a sampler that declares a ``Structure`` (``Sampler.structure``)
is compiled by ``liesample.sample`` once for every value of its numeric parameters, so a sweep
over ``β`` (or ``σ``, or the step size) compiles at its first point only, and gives the draws of
a sampler compiled for one value (``tests/test_draws_unchanged.py`` holds them bit for bit)."""

import contextlib

import jax
import numpy as np
import pytest

import liesample
from liesample.samplers.contract import Structure

SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
STARTS = np.tile(np.array([0.9, 1.2, 0.0]), (4, 1))


class _Compiles:
    """Counts XLA backend compilations while active."""

    def __init__(self):
        self.count = 0

    def __call__(self, event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            self.count += 1


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
