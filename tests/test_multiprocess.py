"""Chains across processes (``jax.distributed``): processes on the loopback interface, one CPU
device each, run ``liesample.sample(..., devices="all")``; each chain runs the same compiled
step on the same key as in one process, and the gathers copy values without arithmetic, so the
draws, and the run file, are one process's, bitwise.

Two worker processes run, in their own working directories (process 0's holds the run files;
process 1's stands for a node's local disk, so a relative ``output=`` there finds nothing):

1. a run without ``output=``, and one with ``output="full.nc"``: both give the draws of one
   process running every chain, and ``full.nc`` (written by process 0 alone; process 1 takes
   no lock and writes nothing) equals the one-process run's file: every chunk's checksum, the
   saved chain states', the draws;
2. a run into ``part.nc`` stopped by its ``callback`` after the first chunk;
3. its resume, refused on both processes: process 1 cannot find ``part.nc``, and the message
   says where the file must be; and a run given ``output=`` on process 0 only, refused on both;
4. a run whose ``callback`` raises on process 1 only, and one whose writer (process 0) fails
   while saving its second chunk: the process that failed raises its error, the other an
   ``OtherProcessError`` naming it (neither waits for the other).

Then two new processes, both in process 0's directory, resume ``part.nc``: the draws, and the
file, are those of one uninterrupted one-process run, bitwise. They are started as the tasks of
a SLURM job step (its variables, on this machine), and ``initialize_distributed()`` without
arguments reads the job from them.

The workers also check that importing liesample and reading ``liesample.sharding`` start no
XLA backend, so that ``initialize_distributed`` can follow ``import liesample``.
"""

import json
import os
import socket
import subprocess
import sys
import textwrap
import warnings
from types import SimpleNamespace

import h5py
import jax
import numpy as np
import pytest

import liesample
from liesample.run import agreement
from liesample.run.store import RUN_GROUP, load_chains

SYSTEM_ARGS = (1.0, 2.0, 4.0)
STARTS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [0.3, 0.3, 0.3]])
NUM_DRAWS, CHUNK = 20, 5
RUN = {"num_warmup": 3, "chunk_draws": CHUNK, "progress_bar": False}

WORKER = (
    textwrap.dedent(
        """
    import json
    import os
    import sys
    import warnings

    import jax
    jax.config.update("jax_enable_x64", True)
    import jax._src.xla_bridge as xb
    import numpy as np
    import liesample
    liesample.sharding
    from liesample.sharding import initialize_distributed
    assert not xb._backends, xb._backends  # initialize_distributed can still follow

    port, process_id, phase, results = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    if phase == "resume":  # the job read from (simulated) SLURM variables
        assert initialize_distributed()
    else:
        initialize_distributed(
            coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=process_id
        )
    assert jax.process_index() == process_id
    assert jax.process_count() == 2 and len(jax.devices()) == 2, jax.devices()
    warnings.simplefilter("ignore", UserWarning)  # 20 draws: the convergence checks remark
    from liesample.run import atomic, store
    calls = {"lock": 0, "write": 0}
    acquire, replacing = store.OutputLock.acquire, atomic.replacing

    def counted(name, function):
        def wrapped(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)
        return wrapped

    store.OutputLock.acquire = counted("lock", acquire)
    atomic.replacing = counted("write", replacing)
    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body(SYSTEM_ARGS), beta=2.0, sigma=1.0, step_size=0.05
    )
    record = {}

    def run(output=None, **options):
        tree = liesample.sample(
            algorithm, jax.random.key(3), STARTS, NUM_DRAWS, devices="all", output=output,
            **options, **RUN
        )
        return np.asarray(tree["posterior"]["mu"]).tolist()

    def failure(**options):
        try:
            run(**options)
        except Exception as error:
            return [type(error).__name__, str(error)]
        return None

    class Stop(Exception):
        pass

    def stop(draws_done):
        raise Stop(f"stopped after {draws_done} draws")

    if phase == "write":
        # an array of this process alone stays its own (it is not stacked with the others')
        record["local"] = liesample.sharding.to_host(jax.numpy.arange(3.0)).tolist()
        record["draws"] = run()
        record["full"] = run("full.nc")
        record["stopped"] = failure(output="part.nc", callback=stop)
        record["not_shared"] = failure(output="part.nc", resume=True)
        record["one_callback"] = failure(callback=stop if process_id == 1 else None)
        record["one_output"] = failure(output="mixed.nc" if process_id == 0 else None)
        if process_id == 0:  # the writer fails on its second chunk
            append = store.RunFile.append

            def failing(run_file, first, *args):
                if first > 0:
                    raise OSError(28, "No space left on device (a test's failure)")
                return append(run_file, first, *args)

            store.RunFile.append = failing
        record["failed_write"] = failure(output="broken.nc")
    else:
        record["resumed"] = run("part.nc", resume=True)
    record["calls"] = calls
    with open(f"{results}/{phase}-{process_id}.json", "w") as f:
        json.dump(record, f)
    jax.distributed.shutdown()
    os._exit(0)  # done: the interpreter's teardown of JAX's objects only costs time
    """
    )
    .replace("SYSTEM_ARGS", repr(SYSTEM_ARGS))
    .replace("STARTS", repr(STARTS.tolist()))
    .replace("NUM_DRAWS", str(NUM_DRAWS))
    .replace("**RUN", ", ".join(f"{k}={v!r}" for k, v in RUN.items()))
)


def _gloo_available() -> bool:
    from jax._src.lib import _jax

    return hasattr(_jax, "make_gloo_tcp_collectives")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _environment() -> dict:
    """This process's environment (its XLA flags: the same compiled programs), on the CPU."""
    return os.environ | {"JAX_PLATFORMS": "cpu", "PYTHONWARNINGS": "ignore"}


def _slurm(process_id, port) -> dict:
    """The variables of task ``process_id`` of a SLURM job step of two tasks on this machine
    (``jax.distributed.initialize`` reads them; JAX_COORDINATOR_PORT sets its port)."""
    return {
        "SLURM_JOB_ID": "4242",
        "SLURM_STEP_NODELIST": "127.0.0.1",
        "SLURM_NTASKS": "2",
        "SLURM_PROCID": str(process_id),
        "SLURM_LOCALID": str(process_id),
        "JAX_COORDINATOR_PORT": str(port),
    }


def _run_pair(script, phase, directories, results, slurm=False) -> list[dict]:
    """Start two workers of ``phase``, process ``i`` in ``directories[i]`` (the job given by
    arguments, or by SLURM's variables); their records."""
    port = _free_port()
    workers = [
        subprocess.Popen(
            [sys.executable, str(script), str(port), str(i), phase, str(results)],
            cwd=directories[i],
            env=_environment() | (_slurm(i, port) if slurm else {}),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(2)
    ]
    try:
        logs = [w.communicate(timeout=150)[0] for w in workers]
    finally:
        for w in workers:
            w.kill()
    for w, log in zip(workers, logs, strict=True):
        assert w.returncode == 0, log[-3000:]
    return [json.loads((results / f"{phase}-{i}.json").read_text()) for i in range(2)]


def _file_record(path):
    """What a run file commits to: its chunk table and every chunk's checksum, the saved
    states' checksum, and the draws and sample stats as ``load_chains`` reads them."""
    with h5py.File(path, "r") as h5:
        run = h5[RUN_GROUP]
        commit = json.loads(run.attrs["commit"])
        chunks = (np.asarray(run["chunk_end"]).tolist(), np.asarray(run["chunk_sha256"]).tolist())
        slot = commit["state_slot"]
        states = [np.asarray(run[n]) for n in sorted(run) if n.startswith(f"state_{slot}_")]
    tree = load_chains(path)
    arrays = {
        f"{group}/{name}": np.asarray(tree[group][name])
        for group in ("posterior", "sample_stats")
        for name in tree[group].data_vars
    }
    return chunks, commit["draws_done"], commit["state_sha256"], states, arrays


def _assert_same_file(path, reference):
    found, expected = _file_record(path), _file_record(reference)
    assert found[:3] == expected[:3]
    for a, b in zip(found[3], expected[3], strict=True):
        np.testing.assert_array_equal(a, b)
    assert found[4].keys() == expected[4].keys()
    for name, value in expected[4].items():
        np.testing.assert_array_equal(found[4][name], value, err_msg=name)


@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_two_processes_give_the_single_process_draws_and_run_file(tmp_path):
    shared, local, results = (tmp_path / name for name in ("shared", "local", "results"))
    for directory in (shared, local, results):
        directory.mkdir()
    script = tmp_path / "worker.py"
    script.write_text(WORKER)
    written = _run_pair(script, "write", [shared, local], results)

    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body(SYSTEM_ARGS), beta=2.0, sigma=1.0, step_size=0.05
    )
    with warnings.catch_warnings():  # 20 draws: the convergence checks remark on them
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(
            algorithm, jax.random.key(3), STARTS, NUM_DRAWS, output=tmp_path / "one.nc", **RUN
        )
    single = np.asarray(tree["posterior"]["mu"])

    # 1. the draws, and process 0's file, are one process's; process 1 locks and writes nothing
    for record in written:
        assert record["local"] == [0.0, 1.0, 2.0]
        np.testing.assert_array_equal(np.asarray(record["draws"]), single)
        np.testing.assert_array_equal(np.asarray(record["full"]), single)
    _assert_same_file(shared / "full.nc", tmp_path / "one.nc")
    assert written[1]["calls"] == {"lock": 0, "write": 0}
    assert written[0]["calls"]["write"] == 4 + 1 + 1  # full.nc, part.nc, broken.nc's first
    assert sorted(os.listdir(local)) == []
    assert sorted(os.listdir(shared)) == ["broken.nc", "full.nc", "part.nc"]
    # 2. the callback stopped both processes after the first chunk
    for record in written:
        assert record["stopped"] == ["Stop", f"stopped after {CHUNK} draws"]
    # 3. the resume is refused on both: process 1 does not see the file
    for record in written:
        kind, message = record["not_shared"]
        assert kind == "RunFileError", message
        assert "process 1 finds no file at" in message and str(local) in message, message
        assert "file system that every process sees" in message, message
    for record in written:
        kind, message = record["one_output"]
        assert kind == "ValueError", message
        assert "process 0: output=<path>, resume=False; process 1: output=None" in message
    assert written[0]["calls"]["lock"] == 5  # process 0 took the lock of mixed.nc, then refused
    # 4. an error on one process stops both: process 1's callback, process 0's writing
    assert written[1]["one_callback"] == ["Stop", f"stopped after {CHUNK} draws"]
    kind, message = written[0]["one_callback"]
    assert kind == "OtherProcessError", message
    assert message.startswith(f"process 1 of 2 failed while running callback({CHUNK})"), message
    assert message.endswith(f"its error: Stop: stopped after {CHUNK} draws"), message
    kind, message = written[0]["failed_write"]
    assert kind == "OSError" and "No space left on device" in message, message
    kind, message = written[1]["failed_write"]
    assert kind == "OtherProcessError", message
    assert "process 0 of 2 failed while saving draws 5 to 9" in message, message
    assert "No space left on device" in message, message

    # the stopped run resumed by two new processes: one uninterrupted run's draws and file
    resumed = _run_pair(script, "resume", [shared, shared], results, slurm=True)
    for record in resumed:
        np.testing.assert_array_equal(np.asarray(record["resumed"]), single)
    assert resumed[1]["calls"] == {"lock": 0, "write": 0}
    _assert_same_file(shared / "part.nc", tmp_path / "one.nc")


def test_output_refused_for_chains_over_some_of_the_processes(monkeypatch):
    """A run file needs the chains over every process (process 0 writes it, all resume it)."""
    devices = [SimpleNamespace(process_index=i) for i in (1, 2)]
    sharding = SimpleNamespace(is_fully_addressable=False, device_set=devices)
    monkeypatch.setattr(jax, "process_count", lambda: 4)
    with pytest.raises(ValueError, match=r"processes \[1, 2\] of the 4") as refused:
        liesample.sharding.check_output("run.nc", sharding)
    assert "devices='all'" in str(refused.value) and "output=None" in str(refused.value)
    liesample.sharding.check_output(None, sharding)


def test_a_long_error_message_is_shortened_to_fit_its_record():
    row = agreement._record("é" * 5000, "draws_done=10")
    assert row.shape == (agreement.RECORD_BYTES,)
    record = agreement._read(row)
    assert record["value"] == "draws_done=10"
    assert record["error"].startswith("ééé") and record["error"].endswith(" …")
