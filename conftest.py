"""The docstrings' examples, run by ``make doctest`` (``pytest --doctest-modules liesample``).

The examples are written for float64, as the README's example runs: x64 is on before any of
them runs, and each finds ``jax``, ``jnp`` (``jax.numpy``) and ``liesample`` imported. They
compile with XLA's cheap back-end setting, as the test suite does (``tests/conftest.py``),
which changes only round-off; the examples print nothing that depends on round-off. A run of
the test suite (no ``--doctest-modules``) is left untouched.
"""

import os

import pytest

FAST_COMPILE_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"


class _DoctestNames:
    @pytest.fixture(autouse=True)
    def _names(self, doctest_namespace):
        import jax
        import jax.numpy as jnp

        import liesample

        doctest_namespace.update(jax=jax, jnp=jnp, liesample=liesample)


def pytest_configure(config):
    if not config.getoption("doctestmodules", False):
        return
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {FAST_COMPILE_FLAGS}".strip()
    import jax  # after XLA_FLAGS: the CPU back end reads them once

    jax.config.update("jax_enable_x64", True)
    config.pluginmanager.register(_DoctestNames(), "liesample-doctest-names")
