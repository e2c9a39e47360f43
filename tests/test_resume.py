"""Long runs lose nothing: ``output=`` saves every chunk, ``resume=True`` continues after a kill.

The interrupted run is a subprocess that kills itself with SIGKILL right after chunk ``k`` has
been saved (``sample_chains``' ``callback``), which is deterministic and as abrupt as a crash or
a pre-empted job: no ``finally`` runs, nothing is flushed. Resuming from the file
must then give the draws of one uninterrupted run *exactly*, because draw ``d`` of chain ``c``
uses the key ``fold_in(key_c, step)`` and the saved state is the exact state after the last
saved chunk.
"""

import os
import signal
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest
import xarray as xr

import liesample
from liesample.run import loop
from liesample.run.runner import load_chains, sample_chains

SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
STARTS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5]])
KEY_SEED = 11
RUN = {"num_warmup": 4, "thinning": 3, "chunk_draws": 4}
# Whole chunks only (each call compiles one chunk shape: keeps the test fast).
NUM_DRAWS = 20
KILL_AFTER = 2  # chunks saved before the kill

SCRIPT = textwrap.dedent(
    f"""
    import os, signal, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample

    def kill(draws_done):
        if draws_done >= {KILL_AFTER} * {RUN["chunk_draws"]}:
            os.kill(os.getpid(), signal.SIGKILL)

    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body((1.0, 2.0, 4.0)), beta=3.0, step_size=0.05,
        integrator="lie_euler",
    )
    liesample.sample_chains(
        algorithm, jax.random.key({KEY_SEED}), np.array({STARTS.tolist()}), {NUM_DRAWS},
        output=sys.argv[1], progress_bar=False, callback=kill, **{RUN!r},
    )
    print("NOT KILLED")
    """
)

# The same run killed in the middle of writing chunk KILL_AFTER + 1: its draws and the state
# after it are written to the copy of the file that would replace it, the commit is not (the
# checksums of the attributes are the store's last step before the commit).
MIDWRITE = SCRIPT.replace(
    "def kill(draws_done):",
    textwrap.dedent(
        f"""
        from liesample.run import store
        write, calls = store.RunFile._write_chunk, []

        def dying_write(run_file, *args):
            calls.append(1)
            if len(calls) == {KILL_AFTER} + 1:
                store._attribute_sums = lambda fields: os.kill(os.getpid(), signal.SIGKILL)
            return write(run_file, *args)

        store.RunFile._write_chunk = dying_write

        def kill(draws_done):"""
    ),
).replace("if draws_done >=", "if False and draws_done >=")

ALGORITHM = liesample.lie_poisson_langevin(SYSTEM, beta=3.0, step_size=0.05, integrator="lie_euler")


def run(num_draws=NUM_DRAWS, **kwargs):
    kwargs = {**RUN, "progress_bar": False, **kwargs}
    return sample_chains(ALGORITHM, jax.random.key(KEY_SEED), STARTS, num_draws, **kwargs)


@pytest.fixture(scope="module")
def uninterrupted():
    return run()


@pytest.mark.parametrize(
    "script",
    [  # the kill between chunks in make test-slow (the in-process resumes below cover that file)
        pytest.param(SCRIPT, marks=pytest.mark.slow),
        MIDWRITE,
    ],
    ids=["between chunks", "while writing"],
)
def test_killed_run_resumes_to_the_same_draws(tmp_path, uninterrupted, script):
    path = tmp_path / "run.nc"
    completed = subprocess.run(
        [sys.executable, "-c", script, str(path)],
        check=False,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert completed.returncode == -signal.SIGKILL, completed.stdout + completed.stderr
    assert "NOT KILLED" not in completed.stdout
    # What survived the kill: exactly the first KILL_AFTER chunks, readable as they are.
    saved = load_chains(path)
    saved_draws = KILL_AFTER * RUN["chunk_draws"]
    assert saved.posterior["mu"].shape == (3, saved_draws, 3)
    np.testing.assert_array_equal(saved.posterior["mu"], uninterrupted.positions[:, :saved_draws])
    assert saved.attrs["num_steps"] == RUN["num_warmup"] + saved_draws * RUN["thinning"]
    if script is SCRIPT:  # killed between chunks: the file as the last chunk closed it
        with xr.open_datatree(path, engine="h5netcdf") as tree:
            assert tree["posterior"].sizes["draw"] == saved_draws
    assert os.path.exists(f"{path}.lock")  # the killed run's lock file is left: it blocks nothing
    # killed while writing: the copy it wrote is left beside the file, ignored, and removed
    # by the resume
    copies = [name for name in os.listdir(tmp_path) if name.startswith(".run.nc.tmp-")]
    assert len(copies) == (script is MIDWRITE), copies

    resumed = run(output=path, resume=True)
    np.testing.assert_array_equal(resumed.positions, uninterrupted.positions)
    np.testing.assert_array_equal(resumed.info["is_divergent"], uninterrupted.info["is_divergent"])
    np.testing.assert_allclose(resumed.info["energy"], uninterrupted.info["energy"], rtol=4e-16)
    assert resumed.num_steps == uninterrupted.num_steps
    # …and the file now holds the whole run; the lock is gone.
    np.testing.assert_array_equal(load_chains(path).posterior["mu"], uninterrupted.positions)
    assert not os.path.exists(f"{path}.lock")
    assert sorted(os.listdir(tmp_path)) == ["run.nc"]


def test_saved_run_equals_returned_run_and_can_be_extended(tmp_path, uninterrupted, monkeypatch):
    path = tmp_path / "run.nc"
    first = run(num_draws=12, output=path)
    np.testing.assert_array_equal(first.positions, uninterrupted.positions[:, :12])
    saved = load_chains(path)
    np.testing.assert_array_equal(saved.posterior["mu"], first.positions)
    np.testing.assert_array_equal(saved.sample_stats["diverging"], first.info["is_divergent"])
    assert saved.sample_stats["diverging"].dtype == bool
    # Extend the same run to more draws; the progress bar starts at the saved draws.
    bars = []

    class RecordingBar:
        """What the bar shows: each phase, then the draws (the saved ones first)."""

        def __init__(self, *args, total, **kwargs):
            self.total, self.shown = total, []
            bars.append(self)

        def set_description(self, text, refresh=True):
            self.shown.append(text)

        def update(self, count):
            self.shown.append(count)

        def close(self):
            pass

    monkeypatch.setattr(loop, "tqdm", RecordingBar)
    extended = run(output=path, resume=True, progress_bar=True)
    np.testing.assert_array_equal(extended.positions, uninterrupted.positions)
    (bar,) = bars
    assert bar.total == NUM_DRAWS
    assert bar.shown == [
        "3 chains: checking the starts", "3 chains: compiling", "3 chains: sampling", 12, 4, 4
    ]  # fmt: skip
    again = run(output=path, resume=True)  # nothing left to do: the saved run comes back
    np.testing.assert_array_equal(again.positions, uninterrupted.positions)


def test_resume_checks_the_run_is_the_same(tmp_path):
    path = tmp_path / "run.nc"
    run(num_draws=4, output=path)
    with pytest.raises(FileExistsError, match="resume=True"):
        run(num_draws=4, output=path)
    with pytest.raises(ValueError, match="different rng_key"):
        sample_chains(
            ALGORITHM, jax.random.key(KEY_SEED + 1), STARTS, 9, output=path, resume=True, **RUN
        )
    with pytest.raises(ValueError, match="different initial_positions"):
        sample_chains(
            ALGORITHM,
            jax.random.key(KEY_SEED),
            STARTS[::-1],
            9,
            output=path,
            resume=True,
            **RUN,
        )
    with pytest.raises(ValueError, match="different thinning"):
        run(num_draws=9, output=path, resume=True, thinning=2)
    with pytest.raises(ValueError, match="different num_warmup"):
        run(num_draws=9, output=path, resume=True, num_warmup=0)
    with pytest.raises(ValueError, match="already holds 4 draws"):
        run(num_draws=3, output=path, resume=True)
    with pytest.raises(ValueError, match="resume=True needs output"):
        run(num_draws=3, resume=True)
    with pytest.raises(TypeError, match="resume must be a bool"):
        run(num_draws=3, output=tmp_path / "other.nc", resume="yes")


def test_sample_writes_and_resumes(tmp_path, uninterrupted):
    """``liesample.sample`` passes ``output``/``resume`` through; resuming a file that does not
    exist yet starts afresh."""
    path = tmp_path / "tree.nc"
    assert not os.path.exists(path)
    kwargs = {"output": path, "resume": True, "progress_bar": False, **RUN}
    liesample.sample(ALGORITHM, jax.random.key(KEY_SEED), STARTS, 8, **kwargs)
    tree = liesample.sample(ALGORITHM, jax.random.key(KEY_SEED), STARTS, NUM_DRAWS, **kwargs)
    np.testing.assert_array_equal(np.asarray(tree.posterior["mu"]), uninterrupted.positions)


def test_an_adapted_run_resumes_to_the_same_draws(tmp_path):
    """Warm-up adaptation is deterministic given the key: a resumed run re-derives the same step
    size (dual averaging of the adjusted sampler) and continues to the uninterrupted draws."""
    algorithm = liesample.adjusted_lie_poisson(SYSTEM, beta=3.0)
    kwargs = {"num_warmup": 30, "thinning": 2, "chunk_draws": 4, "progress_bar": False}
    key = jax.random.key(KEY_SEED)
    whole = sample_chains(algorithm, key, STARTS, 12, **kwargs)
    assert whole.settings["step_size_source"].startswith("warm-up dual averaging")
    path = tmp_path / "adapted.nc"
    sample_chains(algorithm, key, STARTS, 4, output=path, **kwargs)
    resumed = sample_chains(algorithm, key, STARTS, 12, output=path, resume=True, **kwargs)
    assert resumed.settings["step_size"] == whole.settings["step_size"]
    np.testing.assert_array_equal(resumed.positions, whole.positions)


@pytest.mark.slow  # three compilations; the new name is checked by default in test_run_file
def test_a_file_that_names_h_energy_resumes_under_that_name(tmp_path, uninterrupted):
    """A run file written when ``h`` of an orbit sampler was ``sample_stats/energy`` (here: the
    same sampler declaring that name) resumes with the name it has; a new file names it
    ``hamiltonian``, and ArviZ's HMC ``energy`` is absent."""
    from liesample.samplers.contract import HOOKS, Sampler

    hooks = {name: getattr(ALGORITHM, name) for name in HOOKS} | {"energy_name": "energy"}
    old = Sampler(ALGORITHM.init, ALGORITHM.step, **hooks)
    path = tmp_path / "old.nc"
    kwargs = {"output": path, "progress_bar": False, **RUN}
    sample_chains(old, jax.random.key(KEY_SEED), STARTS, 8, **kwargs)
    resumed = liesample.sample(
        ALGORITHM, jax.random.key(KEY_SEED), STARTS, NUM_DRAWS, resume=True, **kwargs
    )
    assert "hamiltonian" not in resumed.sample_stats
    np.testing.assert_array_equal(
        np.asarray(resumed.sample_stats["energy"]), uninterrupted.info["energy"]
    )
    assert "energy" in load_chains(path).sample_stats
    new = liesample.sample(
        ALGORITHM, jax.random.key(KEY_SEED), STARTS, 8, progress_bar=False, **RUN
    )
    assert "energy" not in new.sample_stats
    np.testing.assert_array_equal(
        np.asarray(new.sample_stats["hamiltonian"]), uninterrupted.info["energy"][:, :8]
    )
