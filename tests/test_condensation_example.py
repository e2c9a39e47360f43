"""The negative-temperature condensation example (``examples/condensation.py``): as β decreases
through 0 the energy moves into ℓ = 1, and at β = 0 the mean spectrum is the exact one of the
uniform law on the orbit."""

import json

import numpy as np
import pytest

from liesample.targets.zeitlin import uniform_orbit_energy_spectrum


# a sweep of statistical runs; negative β by the default path: tests/test_negative_temperature.py
@pytest.mark.slow
def test_condensation_example(tmp_path, capsys, run_example):
    assert run_example("condensation", ["--output", str(tmp_path)]) == 0
    for name in ("spectra", "fraction", "vorticity"):
        assert (tmp_path / f"condensation_{name}.png").stat().st_size > 10_000
    assert "E[h] ± MCSE" in capsys.readouterr().out
    summary = json.loads((tmp_path / "condensation_summary.json").read_text())
    rows = summary["rows"]
    b = np.array([row["b"] for row in rows])
    assert np.all(np.diff(b) > 0) and b[0] < 0 < b[-1] and 0.0 in b
    assert all(row["r_hat"] < 1.1 for row in rows)

    # the ℓ = 1 share of the energy never falls as β decreases (each step within 2 MCSE),
    # rises far beyond the errors over the sweep, and at the most negative β holds most of h
    share = np.array([row["fraction_l1"] for row in rows])
    error = np.array([row["mcse_fraction_l1"] for row in rows])
    assert np.all(share[:-1] - share[1:] > -2 * np.hypot(error[:-1], error[1:]))
    assert share[0] - share[-1] > 10 * np.hypot(error[0], error[-1])
    assert share[0] > 0.5

    # β = 0: the exact uniform-orbit spectrum per degree and E[h], within 4 MCSE
    exact = uniform_orbit_energy_spectrum(summary["size"], summary["squared_norm"])
    np.testing.assert_allclose(summary["exact_spectrum_beta0"], exact, rtol=1e-12)
    zero = rows[int(np.flatnonzero(b == 0.0)[0])]
    z = (np.array(zero["spectrum"]) - exact) / np.array(zero["mcse_spectrum"])
    assert np.all(np.abs(z) < 4), z
    assert abs(zero["mean_h"] - exact.sum()) < 4 * zero["mcse_h"]
