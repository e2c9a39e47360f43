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
import signal
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
SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
ALGORITHM = liesample.lie_poisson_langevin(SYSTEM, **SETTINGS)
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
def recorded(tmp_path_factory):
    """A whole run file, the store's writes that made it, in order, and its size after each
    chunk."""
    path, sizes = tmp_path_factory.mktemp("recorded") / "run.nc", []
    with pytest.MonkeyPatch.context() as monkeypatch:
        layer = FileLayer(monkeypatch, path)
        run(path, callback=lambda done: sizes.append(os.path.getsize(path)))
    return path, layer.calls, sizes


@pytest.fixture(scope="module")
def writes(recorded):
    return recorded[1]


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
    resumed = run(path, resume=True)  # (its file is what it returns: tests/test_resume.py)
    np.testing.assert_array_equal(resumed.positions, uninterrupted.positions)
    for name, values in uninterrupted.info.items():
        np.testing.assert_array_equal(resumed.info[name], values, err_msg=name)
    assert sorted(os.listdir(path.parent)) == ["run.nc"]


# One failure of each sort in the default suite; every first and last write of each kind, in
# the file's creation (chunk 0) and in a later chunk (1), with each fault, in make test-slow.
DEFAULT = {
    (1, "attribute", "last", "full disk"),  # the commit record of a later chunk
    (1, "write", "first", "kill"),  # a later chunk's draws, half written
    (0, "create", "first", "full disk"),  # the file's creation
    (1, "replace", "first", "interrupt"),  # the rename
    (1, "sync", "last", "full disk"),  # the directory's sync, after the rename: committed
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


def test_a_disk_without_room_is_refused_before_the_copy(tmp_path, monkeypatch):
    path = tmp_path / "run.nc"
    committed = {}

    def disk_fills(draws_done):  # after the first chunk: 1000 bytes free
        committed["bytes"] = path.read_bytes()
        monkeypatch.setattr(atomic, "free_bytes", lambda where: 1000)

    with pytest.raises(OSError) as error:
        run(path, callback=disk_fills)
    needed = len(committed["bytes"]) + 3 * CHUNK * 8 * 3  # the copy, and more than mu's bytes
    message = str(error.value)
    assert error.value.errno == errno.ENOSPC
    assert re.search(
        rf"not enough free space to save draws 4 to 7 of the run in {re.escape(repr(str(path)))}"
        r": about (\d+) bytes are needed .* and 1000 are free .* still holds its 4 committed "
        r"draws; free some space \(or move the file .*\), then pass resume=True",
        message,
    ), message
    assert int(re.search(r"about (\d+) bytes", message)[1]) > needed
    assert path.read_bytes() == committed["bytes"]  # refused before anything was written
    assert sorted(os.listdir(tmp_path)) == ["run.nc"]


def stray_files(folder, run_file):
    """Files that hold no committed chunk: what a kill at a file's creation leaves (by an
    earlier liesample, which created the file in place: HDF5's first bytes, then its first
    groups without the run's), a run file cut short, and HDF5 and text files of another kind."""
    strays = {}
    with h5py.File(folder / "creating.nc", "w") as f:
        strays["killed at creation"] = (folder / "creating.nc").read_bytes()  # as on disk now
        f.create_group("posterior").attrs["beta"] = 3.0
        f.flush()
        strays["killed before the first commit"] = (folder / "creating.nc").read_bytes()
    whole = run_file.read_bytes()
    strays |= {"96 bytes of a run": whole[:96], "9.5 kB of a run": whole[:9500]}
    with h5py.File(folder / "foreign.nc", "w") as f:
        f["x"] = np.zeros(3)
    strays["foreign HDF5"] = (folder / "foreign.nc").read_bytes()
    strays["text"] = b"not a run\n"
    return strays


def test_a_file_without_a_committed_chunk_is_refused_saying_what_to_do(
    tmp_path, monkeypatch, recorded
):
    def no_compiling(*args):
        raise AssertionError("compiled before refusing the file")

    monkeypatch.setattr(liesample.run.loop._Run, "compile", no_compiling)
    for what, data in stray_files(tmp_path, recorded[0]).items():
        path = tmp_path / f"{what}.nc"
        path.write_bytes(data)
        pattern = (
            rf"{re.escape(repr(str(path)))}.*(holds no draws that liesample can read|holds no "
            r"committed draws).*delete it \(or move it away\) to start the run afresh"
        )
        with pytest.raises(RunFileError, match=pattern):
            load_chains(path)
        with pytest.raises(RunFileError, match=pattern):
            run(path, resume=True)
        assert path.read_bytes() == data, what


LIMITED = textwrap.dedent(
    f"""
    import resource, signal, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample

    # a real write failure inside HDF5: past this size a write fails (EFBIG, as ENOSPC would)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[2]), int(sys.argv[2])))
    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body((1.0, 2.0, 4.0)), **{SETTINGS!r}
    )
    liesample.sample_chains(algorithm, jax.random.key(5), np.array({STARTS.tolist()}),
                            {NUM_DRAWS}, output=sys.argv[1], **{RUN!r})
    print("NOT STOPPED")
    """
)


def size_limit(recorded):
    """A file size that the run's file of two chunks fits in, and of three does not."""
    sizes = recorded[2]
    return (sizes[1] + sizes[2]) // 2


def check_the_failure(path, message, uninterrupted):
    pattern = (
        rf"\[Errno {errno.EFBIG}\] cannot save draws 8 to 11 of the run in "
        rf"{re.escape(repr(str(path)))}: .*File too large.*\. The file is unchanged and still "
        r"holds its 8 committed draws; .* pass resume=True to continue the run"
    )
    assert re.fullmatch(pattern, message), message
    np.testing.assert_array_equal(load_chains(path).posterior["mu"], uninterrupted.positions[:, :8])


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX resource limits")
def test_a_real_write_failure_closes_every_hdf5_handle(tmp_path, recorded, uninterrupted):
    import resource

    path = tmp_path / "run.nc"
    opened = len(h5py.h5f.get_obj_ids())
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size_limit(recorded), hard))
        with pytest.raises(OSError) as error:
            run(path)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)
    assert len(h5py.h5f.get_obj_ids()) == opened  # none left to fail again at exit
    check_the_failure(path, str(error.value), uninterrupted)
    assert sorted(os.listdir(tmp_path)) == ["run.nc"]


@pytest.mark.slow  # an interpreter of its own; the handles are checked above in this process
@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX resource limits")
def test_a_real_write_failure_exits_as_python_does(tmp_path, recorded, uninterrupted):
    """After HDF5 failed to write, no handle is left to fail again, or crash, at exit: the
    process ends with Python's status for an uncaught error."""
    path = tmp_path / "run.nc"
    completed = subprocess.run(
        [sys.executable, "-c", LIMITED, str(path), str(size_limit(recorded))],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert completed.returncode == 1, completed.stdout + completed.stderr[-3000:]
    last = completed.stderr.strip().splitlines()[-1]
    assert last.startswith("OSError: "), last
    check_the_failure(path, last.removeprefix("OSError: "), uninterrupted)
    assert sorted(os.listdir(tmp_path)) == ["run.nc"]


@pytest.fixture
def small_disk(tmp_path):
    """A 700 KiB file system (tmpfs), where the machine lets this process mount one."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if sys.platform != "linux" or shutil.which("mount") is None:
        pytest.skip("needs Linux's mount")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=700k", "tmpfs", str(disk)],
                             capture_output=True, text=True, check=False)  # fmt: skip
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {mounted.stderr.strip()}")
    yield disk
    subprocess.run(["umount", str(disk)], check=False)


@pytest.mark.slow  # thousands of draws until a real disk is full; the faults are injected above
@pytest.mark.parametrize("checked", [True, False], ids=["refused early", "failed writing"])
def test_a_full_disk_keeps_every_committed_draw_and_the_moved_file_resumes(
    tmp_path, small_disk, monkeypatch, checked
):
    """A run fills a 700 KiB disk: it stops with ENOSPC (refused by the free-space check, or,
    with the check off, failed inside HDF5), keeps every chunk it committed, and the file,
    moved to a disk with room, resumes to the draws of an uninterrupted run."""
    kwargs = {"chunk_draws": 100, "progress_bar": False}
    whole = sample_chains(ALGORITHM, KEY, STARTS, 6000, **kwargs)
    path = small_disk / "run.nc"
    if not checked:
        monkeypatch.setattr(atomic, "check_space", lambda *args: None)
    with pytest.raises(OSError) as error:
        sample_chains(ALGORITHM, KEY, STARTS, 6000, output=path, **kwargs)
    assert error.value.errno == errno.ENOSPC, error.value
    assert "resume=True" in str(error.value)
    saved = load_chains(path)
    done = saved.posterior.sizes["draw"]
    assert done >= 1000 and done % 100 == 0
    np.testing.assert_array_equal(saved.posterior["mu"], whole.positions[:, :done])
    assert sorted(os.listdir(small_disk)) == ["run.nc"]
    moved = tmp_path / "moved.nc"
    shutil.move(path, moved)
    resumed = sample_chains(ALGORITHM, KEY, STARTS, 6000, output=moved, resume=True, **kwargs)
    np.testing.assert_array_equal(resumed.positions, whole.positions)
    for name, values in whole.info.items():
        np.testing.assert_array_equal(resumed.info[name], values, err_msg=name)
