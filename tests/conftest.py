import importlib.util
import os
import shutil
import tempfile
from pathlib import Path

# The suite is compile-bound: thousands of small programs, each run briefly. XLA's LLVM back end
# then spends more time optimising machine code than the tests spend running it, so the tests
# compile with its cheap setting. This changes rounding (FMA contraction), never the HLO passes
# (liesample.jit's miscompile guard is one), so every test still checks the same programs;
# tests/test_draws_unchanged.py compares draws the way a user's process compiles them.
# LIESAMPLE_TEST_FULL_OPTIMIZATION=1 runs the suite with XLA's default optimisation.
FAST_COMPILE_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
USER_XLA_FLAGS = os.environ.setdefault("LIESAMPLE_USER_XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))
if os.environ.get("LIESAMPLE_TEST_FULL_OPTIMIZATION") != "1":
    os.environ["XLA_FLAGS"] = f"{USER_XLA_FLAGS} {FAST_COMPILE_FLAGS}".strip()

# The test workers (pytest-xdist) and the tests' subprocesses compile many of the same programs:
# one session's persistent compilation cache, in a temporary folder the first process makes and
# its children inherit, compiles each once. Its key holds the program, the XLA flags and the
# versions, so a hit runs the very executable a compilation would have made. Only programs whose
# compilation took 0.3 s or more are stored: writing and reading a small one costs more than
# compiling it again. A cache the user set is left as it is.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    SESSION_CACHE = tempfile.mkdtemp(prefix="liesample-test-xla-cache-")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = SESSION_CACHE
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.3")
    os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "-1"
else:
    SESSION_CACHE = None

import jax  # after XLA_FLAGS: the CPU back end reads them once
import pytest

# Tests run in float64 (ARCHITECTURE.md, "Habits"); float32 has its own stability tests.
jax.config.update("jax_enable_x64", True)


def pytest_unconfigure(config):
    """The session's compilation cache goes with the process that made it."""
    if SESSION_CACHE is not None:
        shutil.rmtree(SESSION_CACHE, ignore_errors=True)


def load_example(name):
    """``examples/<name>.py`` as a module (the examples are scripts, not a package)."""
    path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"example_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def run_example():
    """``run_example(name, argv) -> exit status``: ``examples/<name>.py``'s ``main(argv)``, run in
    this process (as its command line would run it, without paying for a new interpreter)."""

    def run(name, argv):
        return load_example(name).main(argv)

    return run
