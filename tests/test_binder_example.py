"""``examples/binder_3d.py``: the crossing of two fitted lines, and the example end to end with
tiny settings (two small lattices, two temperatures)."""

import numpy as np
import pytest

from conftest import load_example


def example():
    return load_example("binder_3d")


def test_crossing_of_two_exact_lines():
    betas = np.array([0.68, 0.69, 0.70, 0.71])
    error = np.full(4, 0.01)
    beta_star, beta_error, u_star = example().crossing(
        betas, 0.6 + 1.0 * (betas - 0.693), error, 0.6 + 3.0 * (betas - 0.693), error
    )
    assert beta_star == pytest.approx(0.693, abs=1e-12)
    assert u_star == pytest.approx(0.6, abs=1e-12)
    assert 0.0 < beta_error < 0.05


def test_binder_example_runs(tmp_path, capsys, run_example):
    plot = tmp_path / "binder.png"
    argv = ["--sizes", "3,4", "--betas", "0.6,0.8", "--chains", "2", "--draws", "40"]
    assert run_example("binder_3d", [*argv, "--warmup", "10", "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "crossing L = 3/4: beta* =" in out
    values = [
        float(line.split("U = ")[1].split()[0]) for line in out.splitlines() if "U = " in line
    ]
    assert len(values) == 4 and all(0.0 < u <= 1.0 for u in values), values
    assert plot.stat().st_size > 0
