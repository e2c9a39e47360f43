"""The run file cannot splice two laws or lose a run (``output=`` of ``sample_chains``/``sample``).

- a resume with another sampler, setting or system parameter is refused, naming each field;
- an edited, truncated, empty or foreign file is refused with its path, by the resume and by
  ``load_chains``; an edited setting or fingerprint field is named; a refused resume leaves
  the file as it was;
- one writer per path: a second is refused at once, naming the path and the holder (in one
  process, and two processes started together: exactly one succeeds);
- a missing directory or an existing file without ``resume=True`` is refused before compiling;
- the file is the ArviZ ``DataTree`` that ``sample`` returns (groups, names, attributes).
"""

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import time

import h5py
import jax
import numpy as np
import pytest
import xarray as xr

import liesample
from liesample.run import loop
from liesample.run.lock import OutputLockedError
from liesample.run.runner import load_chains, sample_chains
from liesample.run.store import RunFileError

INERTIA = (1.0, 2.0, 4.0)
SETTINGS = {"beta": 3.0, "sigma": 1.0, "step_size": 0.05, "integrator": "lie_euler"}
ALGORITHM = liesample.lie_poisson_langevin(liesample.systems.rigid_body(INERTIA), **SETTINGS)
STARTS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5]])
KEY = jax.random.key(5)
RUN = {"chunk_draws": 4, "progress_bar": False}


def run(path, num_draws=8, algorithm=ALGORITHM, **kwargs):
    return sample_chains(algorithm, KEY, STARTS, num_draws, output=path, **{**RUN, **kwargs})


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A run of 8 draws in 2 chunks, and its draws."""
    path = tmp_path_factory.mktemp("saved") / "run.nc"
    return path, run(path)


def copy_of(saved, tmp_path):
    path = tmp_path / "copy.nc"
    shutil.copy(saved[0], path)
    return path


def file_bytes(path):
    return open(path, "rb").read()


@pytest.mark.parametrize(
    ("changed", "field"),
    [
        ({"beta": 5.0}, "beta"),
        ({"step_size": 0.04}, "step_size"),
        ({"sigma": 0.5}, "sigma"),
        ({"integrator": "splitting"}, "integrator"),
        ({"noise_block_size": 16}, "noise_block_size"),
        # a system parameter: the settings do not name it, the step's computation does
        ({"inertia": (1.0, 2.0, 4.5)}, "step_jaxpr_sha256"),
        ({"sampler": "adjusted"}, "sampler"),
    ],
)
def test_a_resume_with_another_law_is_refused_by_name(saved, tmp_path, changed, field):
    path = copy_of(saved, tmp_path)
    before = file_bytes(path)
    settings = {**SETTINGS, **changed}
    system = liesample.systems.rigid_body(settings.pop("inertia", INERTIA))
    if settings.pop("sampler", None):
        settings.pop("integrator")
        algorithm = liesample.adjusted_lie_poisson(system, **settings)
    else:
        algorithm = liesample.lie_poisson_langevin(system, **settings)
    with pytest.raises(RunFileError, match=rf"{re.escape(str(path))}.*different {field} \(saved"):
        run(path, 12, algorithm, resume=True)
    assert file_bytes(path) == before  # a refused resume changes nothing
    assert not os.path.exists(f"{path}.lock")


@pytest.mark.filterwarnings("ignore:the chains disagree")  # two short chains
def test_a_resume_with_another_log_density_is_refused_by_its_jaxpr(tmp_path):
    """Nothing in the settings of ``geometric_hmc`` names the log-density: the hash of the
    step's jaxpr does."""
    from liesample.geometry.spaces import Euclidean

    def sampler(scale):
        return liesample.geometric_hmc(lambda x: -0.5 * scale * x**2, Euclidean(()), 0.3, 2)

    path, starts = tmp_path / "hmc.nc", np.zeros(2)
    sample_chains(sampler(1.0), KEY, starts, 4, output=path, **RUN)
    # The same log-density, built again, is accepted (the finished run resumed to its own
    # length: checked like any resume, with nothing left to compile).
    sample_chains(sampler(1.0), KEY, starts, 4, output=path, resume=True, **RUN)
    with pytest.raises(RunFileError, match=r"different step_jaxpr_sha256 \(saved"):
        sample_chains(sampler(2.0), KEY, starts, 12, output=path, resume=True, **RUN)


def edit(path, change):
    with h5py.File(path, "r+") as f:
        change(f)


def set_commit(f, **fields):
    commit = json.loads(f["liesample_run"].attrs["commit"])
    f["liesample_run"].attrs["commit"] = json.dumps({**commit, **fields})


EDITS = {
    "a draw": (lambda f: f["posterior/mu"].__setitem__((0, 5, 0), 7.0), "chunk 1 .*checksum"),
    "the state": (
        lambda f: [
            f[f"liesample_run/{name}"].__setitem__(
                Ellipsis, f[f"liesample_run/{name}"][...] * 1.001
            )
            for name in f["liesample_run"]
            if name.startswith("state_") and f[f"liesample_run/{name}"].dtype.kind == "f"
        ],
        "states do not match their checksum",
    ),
    "draws_done": (lambda f: set_commit(f, draws_done=12), "draws_done = 12 disagrees"),
    "a negative draws_done": (lambda f: set_commit(f, draws_done=-5), "draws_done -5 .* invalid"),
    # the checksums cover the settings: every attribute the run wrote, each fingerprint field
    "a setting": (
        lambda f: f["posterior"].attrs.__setitem__("beta", 5.0),
        r"posterior\.attrs\['beta'\] was changed since the run wrote it",
    ),
    "a root attribute": (
        lambda f: f.attrs.__setitem__("integrator", "splitting"),
        r": attrs\['integrator'\] was changed",
    ),
    "an added attribute": (
        lambda f: f["sample_stats"].attrs.__setitem__("note", "edited"),
        r"sample_stats\.attrs\['note'\] was added",
    ),
    "the fingerprint": (
        lambda f: edit_fingerprint(f, num_warmup=7),
        r"fingerprint\['num_warmup'\] was changed since the run wrote it",
    ),
    "an older format": (
        lambda f: f["liesample_run"].attrs.__setitem__("format", "liesample-run-2"),
        r"written by an older liesample \(run format 'liesample-run-2', whose checksums do not "
        r"cover the run's settings\).*xarray.open_datatree",
    ),
}


def edit_fingerprint(f, **fields):
    fingerprint = json.loads(f["liesample_run"].attrs["fingerprint"])
    f["liesample_run"].attrs["fingerprint"] = json.dumps({**fingerprint, **fields})


@pytest.mark.parametrize("what", list(EDITS))
def test_an_edited_file_is_refused_with_its_path(saved, tmp_path, what):
    path = copy_of(saved, tmp_path)
    change, match = EDITS[what]
    edit(path, change)
    before = file_bytes(path)
    pattern = rf"{re.escape(str(path))}.*{match}"
    with pytest.raises(RunFileError, match=pattern):
        load_chains(path)
    with pytest.raises(RunFileError, match=pattern):
        run(path, 12, resume=True)
    assert file_bytes(path) == before


def test_an_edited_num_warmup_is_refused_when_sample_reads_it(saved, tmp_path):
    """``sample`` without ``num_warmup`` takes the saved run's: from a verified fingerprint."""
    path = copy_of(saved, tmp_path)
    edit(path, lambda f: edit_fingerprint(f, num_warmup=7))
    with pytest.raises(RunFileError, match=r"fingerprint\['num_warmup'\] was changed"):
        liesample.sample(ALGORITHM, KEY, STARTS, 12, output=path, resume=True, **RUN)


def test_truncated_empty_and_foreign_files_are_refused_with_their_path(saved, tmp_path):
    truncated = tmp_path / "truncated.nc"
    truncated.write_bytes(file_bytes(saved[0])[: os.path.getsize(saved[0]) // 2])
    empty = tmp_path / "empty.nc"
    empty.write_bytes(b"")
    text = tmp_path / "text.nc"
    text.write_text("not a run\n")
    plain = tmp_path / "plain.nc"
    liesample.analysis.diagnostics.to_datatree(np.zeros((2, 4, 3))).to_netcdf(
        plain, engine="h5netcdf"
    )
    for path, match in (
        (truncated, "not a readable NetCDF-4|incomplete or corrupt"),
        (empty, "not a readable NetCDF-4"),
        (text, "not a readable NetCDF-4"),
        (plain, "no 'liesample_run' group"),
    ):
        pattern = rf"{re.escape(str(path))}.*({match})"
        with pytest.raises(RunFileError, match=pattern):
            load_chains(path)
        with pytest.raises(RunFileError, match=pattern):
            run(path, 12, resume=True)


def test_a_second_writer_is_refused_at_once_naming_the_holder(tmp_path):
    path = tmp_path / "run.nc"
    refused = []

    def second_writer(draws_done):
        for resume in (True, False):
            with pytest.raises(
                OutputLockedError, match=rf"{re.escape(str(path))}.*pid {os.getpid()}"
            ):
                run(path, 12, resume=resume)
            refused.append(resume)

    first = run(path, callback=second_writer)
    assert refused == [True, False] * 2
    np.testing.assert_array_equal(load_chains(path).posterior["mu"], first.positions)


def test_a_missing_directory_or_an_existing_file_is_refused_before_compiling(
    saved, tmp_path, monkeypatch
):
    def no_compiling(*args):
        raise AssertionError("compiled before refusing the output")

    monkeypatch.setattr(loop._Run, "compile", no_compiling)
    missing = tmp_path / "no such folder" / "run.nc"
    with pytest.raises(FileNotFoundError, match=re.escape(repr(str(missing)))):
        run(missing)
    with pytest.raises(FileExistsError, match=re.escape(repr(str(saved[0])))):
        run(saved[0])
    with pytest.raises(IsADirectoryError, match=re.escape(repr(str(tmp_path)))):
        run(tmp_path)
    with pytest.raises(FileNotFoundError, match="no run file"):
        load_chains(missing)


@pytest.mark.filterwarnings("ignore:num_warmup=0")
def test_the_file_is_the_tree_that_sample_returns(tmp_path):
    path = tmp_path / "tree.nc"
    # No warm-up: the chunk program of ``saved``, nothing else to compile.
    tree = liesample.sample(
        ALGORITHM, KEY, STARTS, 8, num_warmup=0, output=path, attrs={"seed": 5}, **RUN
    )
    saved = load_chains(path)
    assert isinstance(saved, xr.DataTree)
    assert set(saved.children) == set(tree.children) == {"posterior", "sample_stats"}
    stamps = {"created_at"}
    assert dict(saved.attrs) == dict(tree.attrs)
    for name in tree.children:
        mine, theirs = saved[name].to_dataset(), tree[name].to_dataset()
        xr.testing.assert_identical(mine.drop_attrs(), theirs.drop_attrs())
        strip = lambda attrs: {k: v for k, v in attrs.items() if k not in stamps}
        assert strip(mine.attrs).keys() == strip(theirs.attrs).keys()
        for key, value in strip(theirs.attrs).items():
            np.testing.assert_equal(np.asarray(mine.attrs[key]), np.asarray(value), err_msg=key)
    assert saved.attrs["seed"] == 5 and saved.posterior["mu"].dims == ("chain", "draw", "component")
    # h of an orbit sampler (no momentum) is not ArviZ's HMC energy.
    assert "hamiltonian" in saved.sample_stats and "energy" not in saved.sample_stats


TWO_WRITERS = textwrap.dedent(
    """
    import os, sys, time
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample
    from liesample.run.lock import OutputLockedError

    path, ready, go = sys.argv[1:]
    open(ready, "w").close()
    while not os.path.exists(go):
        time.sleep(0.01)
    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body((1.0, 2.0, 4.0)), beta=3.0, step_size=0.05,
        integrator="lie_euler",
    )
    try:
        liesample.sample_chains(algorithm, jax.random.key(5), np.array([[0.6, 1.0, 0.8]]), 8,
                                chunk_draws=4, progress_bar=False, output=path)
    except OutputLockedError as error:
        print("REFUSED", error)
        sys.exit(3)
    print("WROTE")
    """
)


@pytest.mark.slow  # two interpreters compiling at once; the refusal itself is tested above
def test_two_writers_started_together_exactly_one_succeeds(tmp_path):
    path, go = tmp_path / "run.nc", tmp_path / "go"
    readies = [tmp_path / f"ready{i}" for i in range(2)]
    processes = [
        subprocess.Popen(
            [sys.executable, "-c", TWO_WRITERS, str(path), str(ready), str(go)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for ready in readies
    ]
    try:
        while not all(ready.exists() for ready in readies):  # both imported: start together
            assert all(p.poll() is None for p in processes), [p.communicate() for p in processes]
            time.sleep(0.01)
        go.touch()
        outputs = [p.communicate(timeout=300) for p in processes]
    finally:
        for p in processes:
            p.kill()
    codes = sorted(p.returncode for p in processes)
    assert codes == [0, 3], outputs
    refused = next(out for out, _ in outputs if out.startswith("REFUSED"))
    assert str(path) in refused and "being written by another run (pid" in refused
    assert load_chains(path).posterior["mu"].shape == (1, 8, 3)
