"""The analysis of ``benchmarks/critical_points.py`` on exact inputs: the crossing of two
lines, the jackknife over chains, and the crossing of the helicity modulus with ``2T/π``."""

import numpy as np
import pytest

from benchmarks.critical_points import helicity_crossing, jackknife_over_chains, line_crossing


def test_crossing_of_two_exact_lines():
    betas = np.array([0.44, 0.45, 0.46])
    small, large = 0.6 + 2.0 * (betas - 0.452), 0.6 + 5.0 * (betas - 0.452)
    assert line_crossing(betas, small, large) == pytest.approx(0.452, abs=1e-12)


def test_jackknife_over_chains():
    rng = np.random.default_rng(0)
    runs = {"a": rng.normal(size=(8, 50)), "b": rng.normal(size=(8, 50))}
    value, error = jackknife_over_chains(lambda r: float(r["a"].mean() - r["b"].mean()), runs)
    assert value == pytest.approx(runs["a"].mean() - runs["b"].mean())
    # for a difference of means the jackknife is the standard error over the chains' means
    per_chain = runs["a"].mean(axis=1) - runs["b"].mean(axis=1)
    assert error == pytest.approx(per_chain.std(ddof=1) / np.sqrt(8), rel=1e-10)


def test_helicity_crossing_of_exact_sums():
    # Υ = 1 − T/2 (zero S) on a 4x4 lattice crosses 2T/π at T = 1/(1/2 + 2/π)
    side, temperatures = 4, [0.8, 0.9, 1.0]
    runs = {}
    for t in temperatures:
        sums = np.zeros((2, 10, 2, 2))
        sums[..., 0] = side**2 * (1 - t / 2)
        runs[(side, t)] = sums
    expected = 1 / (0.5 + 2 / np.pi)
    assert helicity_crossing(temperatures, runs, side) == pytest.approx(expected, rel=1e-12)
    assert np.isnan(helicity_crossing(temperatures[:1], runs, side))  # not bracketed
