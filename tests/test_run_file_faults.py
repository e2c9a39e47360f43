"""A committed chunk of a run file stays readable whatever happens after it, and the run resumes.

A fake file layer wraps every call through which the store writes — the copy of the committed
file, the HDF5 file opened for writing, each group, variable, dimension and attribute written
(the last attribute of a chunk is its commit record), the flush and the close, the syncs to disk
and the rename — and fails one of them: a full disk (``OSError(ENOSPC)``), an interrupt
(``KeyboardInterrupt``), or a kill (what is on disk at that moment is left behind, as a killed
process leaves it, and the run stops). After each, ``load_chains`` returns exactly the draws
committed before the failure, and ``resume=True`` finishes the run to exactly the draws of an
uninterrupted one. Also here: the refusal before copying when the disk has no room, a file too
damaged to hold a chunk, and a real write failure in a subprocess, which exits as Python does.
"""

import errno
import os
import re
import shutil
import subprocess
import sys
import textwrap

import h5netcdf
import h5netcdf.attrs
import h5py
import jax
import numpy as np
import pytest

import liesample
from liesample.run import atomic, store
from liesample.run.runner import load_chains, sample_chains
from liesample.run.store import RunFileError

# The sampler, starts, key and chunk of tests/test_run_file.py: the same compiled programs.
SETTINGS = {"beta": 3.0, "sigma": 1.0, "step_size": 0.05, "integrator": "lie_euler"}
ALGORITHM = liesample.lie_poisson_langevin(liesample.systems.rigid_body((1.0, 2.0, 4.0)), **SETTINGS)
STARTS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5]])
KEY = jax.random.key(5)
CHUNK, NUM_DRAWS = 4, 12  # three chunks: the file's creation, then two copies
RUN = {"chunk_draws": CHUNK, "progress_bar": False}
pytestmark = pytest.mark.filterwarnings("ignore:step_size=0.05 \\(given\\) has the stability")


def run(path, **kwargs):
    return sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, output=path, **RUN, **kwargs)


@pytest.fixture(scope="module")
def uninterrupted():
    return sample_chains(ALGORITHM, KEY, STARTS, NUM_DRAWS, **RUN)


class Killed(BaseException):
    """The process dies here (raised past every ``except Exception``)."""


def _writable(file):
    return file.id.valid and file.mode != "r"


# kind: (owner, attribute, whether a call is the store's writing the run file at `path`)
WRITES = {
    "copy": (shutil, "copyfile", lambda path, src, *a, **k: os.fspath(src) == path),
    "open": (h5py.File, "__init__", lambda path, self, name, mode="r", *a, **k: mode != "r"),
    "create": (h5netcdf.Group, "create_variable", None),
    "resize": (h5netcdf.Group, "resize_dimension", None),
    "write": (h5netcdf.Variable, "__setitem__", None),
    "attribute": (h5netcdf.attrs.Attributes, "__setitem__", None),
    "flush": (h5py.File, "flush", lambda path, self, *a: _writable(self)),
    "close": (h5py.File, "close", lambda path, self, *a: _writable(self)),
    "sync": (atomic, "_sync", None),
    "replace": (os, "replace", lambda path, src, dst, *a, **k: os.fspath(dst) == path),
}


class FileLayer:
    """The store's writes, wrapped: each recorded as ``(chunk, kind)`` (``chunk``: the how
    many-th ``RunFile.append``), and the ``fail_at``-th one replaced by ``fault``."""

    def __init__(self, monkeypatch, path, fault=None, fail_at=None):
        self.path, self.fault, self.fail_at, self.calls = str(path), fault, fail_at, []
        self.chunk = -1
        self.copyfile = shutil.copyfile
        append = store.RunFile.append

        def counted_append(run_file, *args):
            self.chunk += 1
            return append(run_file, *args)

        monkeypatch.setattr(store.RunFile, "append", counted_append)
        for kind, (owner, name, ours) in WRITES.items():
            monkeypatch.setattr(owner, name, self.wrapped(kind, getattr(owner, name), ours))

    def wrapped(self, kind, original, ours):
        def call(*args, **kwargs):
            if ours is None or ours(self.path, *args, **kwargs):
                self.calls.append((self.chunk, kind))
                if len(self.calls) - 1 == self.fail_at:
                    self.fail(kind)
            return original(*args, **kwargs)

        return call

    def fail(self, kind):
        if self.fault == "full disk":
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        if self.fault == "interrupt":
            raise KeyboardInterrupt
        work = atomic.temporary_path(self.path)  # a kill leaves what is on disk now
        if os.path.exists(work):
            self.copyfile(work, os.path.join(os.path.dirname(work), ".run.nc.tmp-999999999"))
        raise Killed


@pytest.fixture(scope="module")
def writes(tmp_path_factory):
    """The store's writes in an uninterrupted run, in order."""
    path = tmp_path_factory.mktemp("recorded") / "run.nc"
    with pytest.MonkeyPatch.context() as monkeypatch:
        layer = FileLayer(monkeypatch, path)
        run(path)
    return layer.calls


def points(writes, chunk):
    """The first and the last write of each kind in ``chunk`` (the how many-th append), as
    indices into ``writes``."""
    found = {}
    for index, (at, kind) in enumerate(writes):
        if at == chunk:
            found.setdefault(kind, []).append(index)
    return {(kind, which): indices[0 if which == "first" else -1]
            for kind, indices in found.items() for which in ("first", "last")}  # fmt: skip


def committed_draws(writes, fail_at):
    """The draws committed before the write ``fail_at`` failed: one chunk per rename."""
    return CHUNK * sum(kind == "replace" for _, kind in writes[:fail_at])


def fail_and_resume(monkeypatch, path, writes, fault, fail_at, uninterrupted):
    """Run with the write ``fail_at`` failing with ``fault``; check what it raised, that
    ``load_chains`` returns exactly the committed draws and that ``resume=True`` finishes the
    run to the uninterrupted draws, leaving the run file alone in its folder."""
    raised = {"full disk": OSError, "interrupt": KeyboardInterrupt, "kill": Killed}[fault]
    with monkeypatch.context() as patched:
        layer = FileLayer(patched, path, fault, fail_at)
        with pytest.raises(raised) as error:
            run(path)
    # nothing was written after the failure; the copy's HDF5 handle was closed
    assert layer.calls[: fail_at + 1] == writes[: fail_at + 1]
    assert {kind for _, kind in layer.calls[fail_at + 1 :]} <= {"close"}, layer.calls[fail_at:]
    done = committed_draws(writes, fail_at)
    if fault == "full disk":
        assert error.value.errno == errno.ENOSPC and repr(str(path)) in str(error.value)
        assert "resume=True" in str(error.value) or "run again" in str(error.value)
    # the copy is removed (a kill leaves it), and the lock (the run's finally ran)
    left = set(os.listdir(path.parent)) - ({".run.nc.tmp-999999999"} if fault == "kill" else set())
    assert left == ({"run.nc"} if done else set()), left
    if done:
        saved = load_chains(path)
        np.testing.assert_array_equal(saved.posterior["mu"], uninterrupted.positions[:, :done])
        np.testing.assert_array_equal(saved.sample_stats["hamiltonian"],
                                      uninterrupted.info["energy"][:, :done])  # fmt: skip
    else:
        with pytest.raises(FileNotFoundError, match="no run file"):
            load_chains(path)
    resumed = run(path, resume=True)
    np.testing.assert_array_equal(resumed.positions, uninterrupted.positions)
    for name, values in uninterrupted.info.items():
        np.testing.assert_array_equal(resumed.info[name], values, err_msg=name)
    np.testing.assert_array_equal(load_chains(path).posterior["mu"], uninterrupted.positions)
    assert sorted(os.listdir(path.parent)) == ["run.nc"]


# One failure of each sort in the default suite; every first and last write of each kind, in
# the file's creation (chunk 0) and in a later chunk (1), with each fault, in make test-slow.
DEFAULT = {
    (1, "attribute", "last", "full disk"),  # the commit record of a later chunk
    (1, "write", "first", "kill"),  # a later chunk's draws, half written
    (0, "create", "first", "full disk"),  # the file's creation
    (1, "replace", "first", "interrupt"),  # the rename
    (1, "sync", "last", "full disk"),  # the directory's sync, after the rename
}
KINDS = {
    0: ("open", "create", "resize", "write", "attribute", "flush", "close", "sync", "replace"),
    1: ("copy", "open", "resize", "write", "attribute", "flush", "close", "sync", "replace"),
}
CASES = [
    pytest.param(*case, id="-".join(map(str, case)),
                 marks=() if case in DEFAULT else pytest.mark.slow)
    for chunk, kinds in KINDS.items() for kind in kinds for which in ("first", "last")
    for fault in ("full disk", "interrupt", "kill")
    if (case := (chunk, kind, which, fault))
]  # fmt: skip


def test_the_recorded_writes_are_those_the_cases_name(writes):
    assert {kind for _, kind in writes} == set(KINDS[0]) | set(KINDS[1])
    for chunk, kinds in KINDS.items():
        assert {kind for at, kind in writes if at == chunk} == set(kinds)
    assert [kind for _, kind in writes if kind in ("copy", "replace")] == [
        "replace", "copy", "replace", "copy", "replace"
    ]  # fmt: skip
    assert writes[points(writes, 1)["attribute", "last"] + 1][1] == "flush"  # the commit: last


@pytest.mark.parametrize(("chunk", "kind", "which", "fault"), CASES)
def test_a_failed_write_loses_no_committed_draw(
    tmp_path, monkeypatch, writes, uninterrupted, chunk, kind, which, fault
):
    fail_at = points(writes, chunk)[kind, which]
    fail_and_resume(monkeypatch, tmp_path / "run.nc", writes, fault, fail_at, uninterrupted)


@pytest.mark.slow  # every write of a later chunk, one at a time; the default suite has five
def test_every_write_of_a_later_chunk_fails_cleanly(tmp_path, monkeypatch, writes, uninterrupted):
    for fail_at, (chunk, _) in enumerate(writes):
        if chunk == 1:
            folder = tmp_path / str(fail_at)
            folder.mkdir()
            fail_and_resume(monkeypatch, folder / "run.nc", writes, "full disk", fail_at,
                            uninterrupted)  # fmt: skip
