"""Chains across processes (``jax.distributed``): two processes on the loopback interface, one
CPU device each, run ``liesample.sample(..., devices="all")`` and both return the draws of one
process running every chain itself, bitwise: each chain runs the same compiled step on the same
key on either side, and the gather (``process_allgather``) copies values without arithmetic.
A run file (``output=``) over several processes is refused by name, before any compilation.

Also: importing liesample and reading ``liesample.sharding`` start no XLA backend, so
``initialize_distributed`` can follow ``import liesample``.
"""

import os
import socket
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import liesample

SYSTEM_ARGS = (1.0, 2.0, 4.0)
STARTS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [0.3, 0.3, 0.3]])
RUN = {"num_warmup": 3, "progress_bar": False}

WORKER = (
    textwrap.dedent(
        """
    import sys
    import warnings

    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import liesample

    port, process_id, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    liesample.sharding.initialize_distributed(
        coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=process_id
    )
    assert jax.process_count() == 2 and len(jax.devices()) == 2, jax.devices()
    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body(SYSTEM_ARGS), beta=2.0, sigma=1.0, step_size=0.05
    )
    with warnings.catch_warnings():  # 20 draws: the convergence checks remark on them
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(algorithm, jax.random.key(3), STARTS, 20, devices="all", **RUN)
    np.save(out + ".npy", np.asarray(tree["posterior"]["mu"]))
    try:
        liesample.sample(
            algorithm, jax.random.key(3), STARTS, 20, devices="all", output=out + ".nc", **RUN
        )
    except ValueError as error:
        message = str(error)
    else:
        message = "not refused"
    with open(out + ".txt", "w") as f:
        f.write(message)
    """
    )
    .replace("SYSTEM_ARGS", repr(SYSTEM_ARGS))
    .replace("STARTS", repr(STARTS.tolist()))
    .replace("**RUN", "num_warmup=3, progress_bar=False")
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


def test_import_starts_no_backend():
    code = (
        "import jax._src.xla_bridge as xb; import liesample; liesample.sharding; "
        "from liesample.sharding import initialize_distributed; "
        "assert not xb._backends, xb._backends"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60, env=_environment())


@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_two_processes_give_the_single_process_draws(tmp_path):
    script = tmp_path / "worker.py"
    script.write_text(WORKER)
    port = _free_port()
    outs = [str(tmp_path / f"process{i}") for i in range(2)]
    workers = [
        subprocess.Popen(
            [sys.executable, str(script), str(port), str(i), outs[i]],
            env=_environment(),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(2)
    ]
    try:
        logs = [w.communicate(timeout=120)[0] for w in workers]
    finally:
        for w in workers:
            w.kill()
    for w, log in zip(workers, logs, strict=True):
        assert w.returncode == 0, log[-3000:]

    algorithm = liesample.lie_poisson_langevin(
        liesample.systems.rigid_body(SYSTEM_ARGS), beta=2.0, sigma=1.0, step_size=0.05
    )
    with pytest.warns(UserWarning):  # 20 draws: the convergence checks remark on them
        tree = liesample.sample(algorithm, jax.random.key(3), STARTS, 20, **RUN)
    single = np.asarray(tree["posterior"]["mu"])
    for out in outs:
        np.testing.assert_array_equal(np.load(out + ".npy"), single)
        message = open(out + ".txt").read()
        assert message.startswith("output=") and "2 processes" in message, message
        assert "jax.process_index() == 0" in message and "output=None" in message
    assert not any(os.path.exists(out + ".nc") for out in outs)
