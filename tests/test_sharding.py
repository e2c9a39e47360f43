"""Chains sharded over devices (``devices=`` of ``liesample.sample_chains``) give the draws of the
unsharded run for the same keys, to round-off.

Two CPU devices need ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` before JAX starts,
so the comparison runs in a subprocess. Each chain executes the same operations on the same key
``fold_in(key_c, step)`` whether or not the chain axis is split, with the default integrator;
XLA may compile a batch of 2 chains per device and a batch of 4 differently, so positions are
compared to 1e-13 (a miscompile, as once caught by
``tests/stability/test_stability.py::test_batched_step_equals_one_chain``, would differ by far
more). The non-finite flags are equal; the per-draw diagnostics (``energy``, ``casimir_error``)
agree to round-off (energies to 1e-13, ~1e-16 absolute on a Casimir drift
that is itself round-off), as across chunk sizes in ``tests/test_runner.py``.
"""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import liesample
from liesample.run.sharding import chain_sharding

SCRIPT = textwrap.dedent(
    """
    import sys

    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample

    FULL = sys.argv[1] == "full"  # else the default suite's subset
    assert len(jax.devices()) == 2, jax.devices()
    key = jax.random.key(3)
    cases = {
        "rigid body": (
            liesample.systems.rigid_body((1.0, 2.0, 4.0)),
            np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [0.3, 0.3, 0.3]]),
        ),
        "heavy top": (
            liesample.systems.heavy_top(mgl=2.0),
            np.tile(np.array([0.2, -0.1, 0.3, 0.0, 0.6, -0.8]), (4, 1)),
        ),
    }
    if not FULL:  # the default suite: the rigid body over both devices, in device order
        del cases["heavy top"]
    run = dict(num_warmup=3, thinning=2, chunk_draws=4, progress_bar=False)
    made = {}  # label: (algorithm, its unsharded run)
    for label, (system, starts) in cases.items():
        algorithm = liesample.lie_poisson_langevin(system, beta=2.0, sigma=1.0, step_size=0.05)
        plain = liesample.sample_chains(algorithm, key, starts, 12, **run)
        made[label] = algorithm, plain
        choices = ("all", jax.devices()[::-1]) if label == "rigid body" else (2,)
        if not FULL:
            choices = ("all",)
        for devices in choices:
            sharded = liesample.sample_chains(algorithm, key, starts, 12, devices=devices, **run)
            np.testing.assert_allclose(sharded.positions, plain.positions, rtol=0, atol=1e-13)
            np.testing.assert_array_equal(sharded.info["is_divergent"], plain.info["is_divergent"])
            np.testing.assert_allclose(
                sharded.info["energy"], plain.info["energy"], rtol=0, atol=1e-13
            )
            np.testing.assert_allclose(
                sharded.info["casimir_error"], plain.info["casimir_error"], rtol=0, atol=1e-15
            )
        print(label, "ok", flush=True)
    # The DataTree path (liesample.sample) with devices=2: the rigid body's run again (its
    # programs are compiled already: "all" is the same two devices).
    algorithm, plain = made["rigid body"]
    tree = liesample.sample(algorithm, key, cases["rigid body"][1], 12, devices=2, **run)
    np.testing.assert_allclose(np.asarray(tree.posterior["mu"]), plain.positions, atol=1e-13)
    # The chunk really is split: each device holds half of the chains' states.
    sharding = liesample.run.sharding.chain_sharding(2, 4)
    placed = jax.device_put(np.zeros((4, 3)), sharding)
    assert len({s.device for s in placed.addressable_shards}) == 2
    assert all(s.data.shape == (2, 3) for s in placed.addressable_shards)
    print("ALL OK")
    """
)


def _run_on_two_devices(full: bool):
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    completed = subprocess.run(
        [sys.executable, "-c", SCRIPT, "full" if full else "quick"],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "ALL OK" in completed.stdout


def test_sharded_draws_equal_unsharded_on_two_cpu_devices():
    """The rigid body over both devices ("all"), the DataTree path and the placement."""
    _run_on_two_devices(full=False)


@pytest.mark.slow
def test_sharded_draws_equal_unsharded_every_device_choice():
    """Also the heavy top, ``devices=2`` and the devices in reverse order."""
    _run_on_two_devices(full=True)


SYSTEM = liesample.systems.rigid_body()
ALGORITHM = liesample.lie_poisson_langevin(SYSTEM, beta=1.0, step_size=0.1, integrator="lie_euler")
STARTS = np.tile(SYSTEM.default_position, (3, 1))


@pytest.mark.parametrize(
    ("devices", "error", "match"),
    [
        ("gpu0", ValueError, "devices must be None, 'all'"),
        (0, ValueError, "devices must be between 1"),
        (99, ValueError, "devices must be between 1"),
        ([], TypeError, "non-empty sequence of jax.Device"),
        (["cpu"], TypeError, "non-empty sequence of jax.Device"),
        (1.5, TypeError, "devices must be None"),
    ],
)
def test_bad_devices(devices, error, match):
    with pytest.raises(error, match=match):
        liesample.sample_chains(ALGORITHM, jax.random.key(0), STARTS, 2, devices=devices)


def test_chains_must_divide_over_devices():
    with pytest.raises(ValueError, match=r"number of chains \(3\) must be a multiple"):
        chain_sharding(jax.devices() * 2, 3)  # the same device twice stands for two devices


# devices=1 gives the plain draws bitwise: by default in
# test_runner_pytrees.py::test_pytree_draws_do_not_depend_on_chunking_or_sharding
@pytest.mark.slow
def test_one_device_sharding_is_the_plain_run():
    key = jax.random.key(5)
    plain = liesample.sample_chains(ALGORITHM, key, STARTS, 5, progress_bar=False)
    sharded = liesample.sample_chains(ALGORITHM, key, STARTS, 5, progress_bar=False, devices=1)
    np.testing.assert_array_equal(sharded.positions, plain.positions)
