"""The lattice gauge example (``examples/lattice_gauge.py``): its 2-D U(1) part against the exact
torus laws, and the whole ``--quick`` run (both ``slow``: ``liesample.sample`` compiles for tens
of seconds on two shared cores)."""

import json

import numpy as np
import pytest

from conftest import load_example


def load():
    return load_example("lattice_gauge")


@pytest.mark.slow
def test_u1_part_matches_the_torus_laws():
    out = load().u1_topology(2, 1.0, 200, 4)
    for name in ("plaquette", "chi"):
        assert abs(out[name] - out[f"{name}_exact"]) < 5 * out[f"{name}_mcse"], out


@pytest.mark.slow
def test_quick_run_writes_its_numbers(tmp_path, run_example):
    output = tmp_path / "gauge.json"
    assert run_example("lattice_gauge", ["--quick", "--output", str(output)]) == 0
    numbers = json.loads(output.read_text())
    assert 0.0 < numbers["su3"]["plaquette"] < 1.0
    assert np.isfinite(numbers["u1"]["chi"]) and np.isfinite(numbers["su3"]["Q_flowed"])
