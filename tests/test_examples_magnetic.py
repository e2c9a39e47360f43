"""The magnetic HMC NumPyro example runs and its ArviZ output is sane."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numpyro")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "numpyro_magnetic_hmc.py"


def test_numpyro_magnetic_hmc_example_runs(capsys):
    spec = importlib.util.spec_from_file_location("numpyro_magnetic_hmc", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tree = module.main(seed=0, num_draws=200)
    printed = capsys.readouterr().out
    assert "magnetic HMC" in printed and "tau" in printed
    posterior = tree.posterior
    assert posterior["theta"].shape == (module.NUM_CHAINS, 200, 8)
    tau = np.asarray(posterior["tau"])
    assert np.all(np.isfinite(tau)) and np.all(tau > 0)  # constrained space
    assert not np.any(np.asarray(tree.sample_stats["diverging"]))
    # The posterior mean of mu for eight schools is about 4.4 (sd about 3.3).
    assert abs(float(posterior["mu"].mean()) - 4.4) < 2.0
