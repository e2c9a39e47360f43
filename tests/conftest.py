import importlib.util
from pathlib import Path

import jax
import pytest

# Tests run in float64 (ARCHITECTURE.md, "Habits"); float32 has its own stability tests.
jax.config.update("jax_enable_x64", True)


@pytest.fixture
def run_example():
    """``run_example(name, argv) -> exit status``: ``examples/<name>.py``'s ``main(argv)``, run in
    this process (as its command line would run it, without paying for a new interpreter)."""

    def run(name, argv):
        path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(f"example_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module.main(argv)

    return run
