import importlib.util
import os
import shutil
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

import jax  # after XLA_FLAGS: the CPU back end reads them once
import pytest

# Tests run in float64 (ARCHITECTURE.md, "Habits"); float32 has its own stability tests.
jax.config.update("jax_enable_x64", True)

# The xdist workers of one run share one compilation cache: a program that both compile (the same
# operation on the same shapes, mostly) is compiled once. It lives in the run's pytest base
# temporary directory and is removed at the run's end, so no test reads a program compiled by
# another run. LIESAMPLE_TEST_SHARED_CACHE=0 turns it off.
SHARED_CACHE = os.environ.get("LIESAMPLE_TEST_SHARED_CACHE", "1") == "1"


def _shared_cache_dir(config) -> Path:
    base = config._tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "jax-cache"


@pytest.fixture(scope="session", autouse=True)
def shared_compilation_cache(request):
    if SHARED_CACHE and os.environ.get("PYTEST_XDIST_WORKER"):
        jax.config.update("jax_compilation_cache_dir", str(_shared_cache_dir(request.config)))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def pytest_sessionfinish(session):
    """The controller removes the run's shared cache once every worker is done."""
    if SHARED_CACHE and not os.environ.get("PYTEST_XDIST_WORKER"):
        shutil.rmtree(_shared_cache_dir(session.config), ignore_errors=True)


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
