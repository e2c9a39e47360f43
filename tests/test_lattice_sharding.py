"""One lattice over several devices (``lattice_sharding=`` of ``liesample.sample_chains``) gives
the draws of the unsharded run, bitwise on CPU.

The sites of a spin lattice or a gauge field are split along lattice axes over a device mesh
(``liesample.run.sharding.LatticeSharding``, with the chains on a mesh axis of their own); XLA's
SPMD partitioner turns the neighbour shifts into collective permutes. Every site draws the
same random numbers (JAX's partitionable Threefry gives each element its own bits, whatever the
split) and runs the same arithmetic, so the positions are bitwise those of the unsharded run.
A chain's energy is a sum over its sites, added in another order when the sites are split: the
energies agree to round-off (1e-12 of about 100).

Several CPU devices need ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` before JAX
starts, so the comparisons run in a subprocess (as in ``tests/test_sharding.py``): the default
suite runs the spin heat bath on 2 devices; the slow tests run every lattice sampler on 4
devices, with the chains and the lattice split together. The refusals are checked here, before
anything is compiled.
"""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import liesample
from liesample.run.sharding import lattice_layout, run_sharding

SCRIPT = textwrap.dedent(
    """
    import sys

    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample
    from liesample.samplers.gauge.hmc import gauge_hmc
    from liesample.run.sharding import run_sharding, shard_chains

    DEVICES, CASES = int(sys.argv[1]), sys.argv[2].split(",")
    assert len(jax.devices()) == DEVICES, jax.devices()
    spins = liesample.systems.heisenberg((8, 8), periodic=True)
    gauge = liesample.systems.wilson_gauge("SU2", (8, 8))
    keys = jax.random.split(jax.random.key(7), 4)
    spin_starts = np.array(jax.random.normal(jax.random.key(8), (4, 8, 8, 3)))
    spin_starts /= np.linalg.norm(spin_starts, axis=-1, keepdims=True)  # random unit spins
    gauge_starts = np.stack([np.asarray(gauge.hot_start(k)) for k in keys])
    samplers = {
        "heat_bath": (liesample.heisenberg_heat_bath(spins, beta=1.1), spin_starts),
        "overrelaxation": (
            liesample.heisenberg_heat_bath(spins, beta=1.1, heat_bath_sweeps=0, overrelaxation=2),
            spin_starts,
        ),
        "metropolis": (liesample.heisenberg_metropolis(spins, beta=1.1), spin_starts),
        "swendsen_wang": (liesample.heisenberg_cluster(spins, beta=1.1), spin_starts),
        "wolff": (liesample.heisenberg_wolff(spins, beta=1.1), spin_starts),
        "gauge_heat_bath": (liesample.wilson_heat_bath(gauge, beta=2.0), gauge_starts),
        "gauge_hmc": (
            gauge_hmc(gauge, beta=2.0, step_size=0.1, num_integration_steps=4), gauge_starts
        ),
    }
    splits = {2: [(None, 2)], 4: [(None, {0: 2, 1: 2}), (2, 2)]}[DEVICES]  # (devices, lattice)
    # 2 devices (the default suite): one chunk, no warm-up; 4: a warm-up, thinning, two chunks
    run = dict(num_warmup=2, thinning=2, chunk_draws=3, progress_bar=False)
    if DEVICES == 2:
        run = dict(chunk_draws=3, progress_bar=False)
        spin_starts = spin_starts[:2]
    draws = 5 if DEVICES == 4 else 3
    plains = {}
    for case in CASES:
        sampler, starts = samplers[case]
        starts = starts[: len(spin_starts)]
        plain = liesample.sample_chains(sampler, jax.random.key(3), starts, draws, **run)
        for devices, lattice in splits:
            split = liesample.sample_chains(
                sampler, jax.random.key(3), starts, draws, devices=devices,
                lattice_sharding=lattice, **run,
            )
            np.testing.assert_array_equal(split.positions, plain.positions)
            assert split.info.keys() == plain.info.keys()
            for name, value in plain.info.items():
                if value.dtype.kind in "biu":
                    np.testing.assert_array_equal(split.info[name], value, err_msg=name)
                else:
                    np.testing.assert_allclose(split.info[name], value, rtol=1e-12, err_msg=name)
            # the states really are split: each device holds its share of every chain's sites
            sharding = run_sharding(devices, lattice, len(starts), sampler)
            placed = shard_chains(starts, sharding)
            assert len({shard.device for shard in placed.addressable_shards}) == DEVICES
            sizes = {shard.data.size for shard in placed.addressable_shards}
            assert sizes == {starts.size // DEVICES}, sizes
        plains[case] = plain
        print(case, "ok", flush=True)
    if "gauge_hmc" in CASES:  # the window warm-up on the split lattice: its sums (the
        # energies it adapts to) are added in another order, so the tuned step and the draws
        # agree to round-off
        window = dict(num_warmup=20, adapt=True, progress_bar=False)
        sampler, starts = samplers["gauge_hmc"]
        plain = liesample.sample_chains(sampler, jax.random.key(4), starts, 2, **window)
        split = liesample.sample_chains(
            sampler, jax.random.key(4), starts, 2, lattice_sharding=4, **window
        )
        step, tuned = plain.settings["step_size"], split.settings["step_size"]
        np.testing.assert_allclose(tuned, step, rtol=1e-9)
        np.testing.assert_allclose(split.positions, plain.positions, rtol=0, atol=1e-9)
    if "heat_bath" in CASES and DEVICES == 4:  # the DataTree path, its programs compiled
        tree = liesample.sample(
            samplers["heat_bath"][0], jax.random.key(3), spin_starts, 5, devices=2,
            lattice_sharding=2, **run,
        )
        mu = np.asarray(tree.posterior["mu"])
        np.testing.assert_array_equal(mu, plains["heat_bath"].positions)
    print("ALL OK")
    """
)


def _run_on_devices(count: int, cases: str):
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={count}"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    completed = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(count), cases],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "ALL OK" in completed.stdout


def test_spin_heat_bath_on_two_devices_is_the_unsharded_run():
    """The heat bath with over-relaxation on an 8 × 8 torus, lattice axis 0 over 2 devices."""
    _run_on_devices(2, "heat_bath")


@pytest.mark.slow
def test_spin_moves_on_four_devices_are_the_unsharded_run():
    """Heat bath, over-relaxation alone, Metropolis, Swendsen–Wang and Wolff, over both lattice
    axes (2 × 2) and over chains × lattice axis 0 (2 × 2); the DataTree path."""
    _run_on_devices(4, "heat_bath,overrelaxation,metropolis,swendsen_wang,wolff")


@pytest.mark.slow
def test_gauge_samplers_on_four_devices_are_the_unsharded_run():
    """The SU(2) heat bath with over-relaxation and gauge HMC on an 8 × 8 torus, split as
    above; gauge HMC's window warm-up on lattice axis 0 over 4 devices (to round-off)."""
    _run_on_devices(4, "gauge_heat_bath,gauge_hmc")


SPINS = liesample.systems.heisenberg((8, 8), periodic=True)
HEAT_BATH = liesample.heisenberg_heat_bath(SPINS, beta=1.0)
STARTS = np.tile(np.asarray(SPINS.default_position), (2, 1, 1, 1))


def _sample(sampler=HEAT_BATH, starts=STARTS, **options):
    return liesample.sample_chains(sampler, jax.random.key(0), starts, 2, progress_bar=False,
                                   **options)  # fmt: skip


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"lattice_sharding": 3}, ValueError, r"lattice axis 0 has 8 sites.*\(2, 4, 8\)"),
        ({"lattice_sharding": {2: 2}}, ValueError, "lattice axis 2 does not exist"),
        ({"lattice_sharding": {0: 0}}, ValueError, "positive int number of devices"),
        ({"lattice_sharding": {-1: 2}}, ValueError, "its keys are lattice axes"),
        ({"lattice_sharding": "x"}, TypeError, "lattice_sharding must be None, a device count"),
        ({"lattice_sharding": {}}, TypeError, "non-empty dict"),
        ({"lattice_sharding": {0: 8, 1: 8}}, ValueError, "needs 1 × 8 × 8 = 64 devices"),
        ({"lattice_sharding": 2, "devices": "all"}, ValueError, "devices='all' with lattice"),
        ({"lattice_sharding": 2, "devices": jax.devices()}, ValueError, "with lattice_sharding"),
        ({"lattice_sharding": 1, "devices": 4}, ValueError, r"chains \(2\) must be a multiple"),
    ],
)
def test_bad_lattice_sharding_is_refused_by_name(options, error, match):
    with pytest.raises(error, match=match):
        _sample(**options)


def test_a_sampler_of_no_lattice_is_refused():
    system = liesample.systems.rigid_body()
    sampler = liesample.lie_poisson_langevin(system, beta=1.0, step_size=0.1)
    starts = np.tile(system.default_position, (2, 1))
    with pytest.raises(ValueError, match=r"lie_poisson_langevin samples no lattice.*devices="):
        _sample(sampler, starts, lattice_sharding=1)


def test_the_layout_of_each_lattice_family():
    """Spins hold the lattice first, a gauge field after its direction axis; a leaf without
    the lattice (a key, an energy) is split along the chains only."""
    from liesample.samplers.gauge.hmc import gauge_hmc

    def placed(sampler):
        layout = lattice_layout(sampler)
        return layout.shape, layout.offset

    gauge = liesample.systems.wilson_gauge("SU2", (4, 6))
    assert placed(HEAT_BATH) == ((8, 8), 0)
    assert placed(liesample.heisenberg_wolff(SPINS, beta=1.0)) == ((8, 8), 0)
    assert placed(liesample.wilson_heat_bath(gauge, beta=1.0)) == ((4, 6), 1)
    hmc = gauge_hmc(gauge, beta=1.0, step_size=0.1, num_integration_steps=2)
    assert placed(hmc) == ((4, 6), 1)
    sharding = run_sharding(1, {1: 1}, 2, hmc)
    assert tuple(sharding.of(np.zeros((2, 2, 4, 6, 2, 2))).spec) == (
        "chain", None, None, "lattice1", None, None
    )  # fmt: skip
    assert tuple(sharding.of(np.zeros(2)).spec) == ("chain",)
