"""The geometric topological charge of 2-D O(3) configurations
(:mod:`liesample.analysis.topology`): integer on every configuration, invariant under global
rotations and translations, odd under reflections, the winding of smooth instantons, refused
inputs by name; the susceptibility; and ``examples/topology_o3.py`` end to end (slow)."""

import jax
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import load_example
from liesample.analysis.topology import (
    topological_charge,
    topological_charge_density,
    topological_susceptibility,
)
from liesample.systems import heisenberg

charge = jax.jit(topological_charge)  # compiled once per shape, shared by the tests
density_of = jax.jit(topological_charge_density)


def random_spins(shape, seed):
    s = np.random.default_rng(seed).normal(size=(*shape, 3))
    return s / np.linalg.norm(s, axis=-1, keepdims=True)


def instanton(size, winding):
    """A lattice discretisation of the stereographic instanton ``w(z)`` (``z = x₁ + i x₂`` from
    the lattice centre) on a ``size × size`` torus: ``s = (2 Re w, 2 Im w, 1 − |w|²)/(1 + |w|²)``,
    whose continuum charge is the degree of ``w``, negative for an anti-holomorphic ``w``."""
    x = np.arange(size) - (size - 1) / 2  # the centre in the middle of a plaquette
    z = x[:, None] + 1j * x[None, :]
    scale = size / 6
    w = {
        1: z / scale,
        -1: np.conj(z) / scale,
        2: (z - size / 5) * (z + size / 5) / scale**2,
    }[winding]
    norm = 1 + np.abs(w) ** 2
    return np.stack([2 * w.real / norm, 2 * w.imag / norm, (1 - np.abs(w) ** 2) / norm], -1)


@pytest.mark.parametrize("shape", [(3, 3), (4, 5), (8, 8), (16, 12)])
def test_the_charge_is_an_integer_on_random_configurations(shape):
    spins = random_spins((6, *shape), seed=sum(shape))  # a batch of six
    q = np.asarray(charge(spins))
    assert q.shape == (6,)
    assert np.max(np.abs(q - np.round(q))) < 1e-9, q
    density = np.asarray(density_of(spins))
    assert density.shape == (6, *shape) and np.all(np.abs(density) < 1)
    np.testing.assert_allclose(density.sum(axis=(-2, -1)), q, atol=1e-12)
    if shape == (16, 12):  # rough configurations: many sectors
        assert len(set(np.round(q))) > 1, q


def test_the_charge_is_invariant_under_rotations_and_odd_under_reflections():
    spins = random_spins((4, 8, 8), seed=1)
    q = np.asarray(charge(spins))
    assert np.any(q != 0)
    rotation = Rotation.random(random_state=2).as_matrix()
    np.testing.assert_allclose(charge(spins @ rotation.T), q, atol=1e-9)
    np.testing.assert_allclose(charge(-spins), -q, atol=1e-9)
    mirror = np.diag([1.0, -1.0, 1.0]) @ rotation  # determinant −1
    np.testing.assert_allclose(charge(spins @ mirror.T), -q, atol=1e-9)
    moved = np.roll(spins, (3, -2), axis=(1, 2))  # a lattice translation
    np.testing.assert_allclose(charge(moved), q, atol=1e-9)


@pytest.mark.parametrize("winding", [1, -1, 2])
def test_a_smooth_instanton_has_its_winding(winding):
    spins = instanton(24, winding)
    assert float(charge(spins)) == pytest.approx(winding, abs=1e-9)
    # a reflection of the lattice reverses the orientation of a smooth configuration
    assert float(charge(spins[::-1])) == pytest.approx(-winding, abs=1e-9)


def test_the_cold_start_has_no_charge():
    system = heisenberg((8, 8), periodic=True)
    assert float(charge(system.default_position)) == 0.0


def test_an_exceptional_configuration_gives_nan():
    """Spins in one plane winding around a triangle: a hemisphere, its area ±2π undecided."""
    angles = np.zeros((4, 4))
    angles[0, 0], angles[1, 0], angles[1, 1] = 0.0, 2 * np.pi / 3, 4 * np.pi / 3
    spins = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], -1)
    assert np.isnan(float(charge(spins)))
    density = np.asarray(density_of(spins))
    assert np.isnan(density[0, 0]) and np.isfinite(density[2:, 2:]).all()


@pytest.mark.parametrize(
    ("spins", "error", "match"),
    [
        (np.ones((4, 4, 2)) / np.sqrt(2), ValueError, "last axis must have length 3"),
        (np.tile([0.0, 0.0, 1.0], (8, 1)), ValueError, r"shape \(L1, L2, 3\)"),
        (np.tile([0.0, 0.0, 1.0], (1, 4, 1)), ValueError, "extents >= 2"),
        (np.tile([0.0, 0.0, 2.0], (4, 4, 1)), ValueError, "unit vectors.*normalise"),
        (np.tile([0, 0, 1], (4, 4, 1)), TypeError, "real floating"),
    ],
    ids=["two-components", "one-dimensional", "extent-one", "not-unit", "integers"],
)
def test_bad_spins_are_refused_by_name(spins, error, match):
    with pytest.raises(error, match=match) as raised:
        topological_charge(spins)
    assert "spins" in str(raised.value)


def test_the_susceptibility_is_the_mean_square_charge_per_site():
    q = np.random.default_rng(3).integers(-2, 3, size=(2, 256)).astype(float)
    chi = topological_susceptibility(q, volume=64, block_size=16)
    assert chi.estimate == pytest.approx(np.mean(q**2) / 64)
    assert 0 < chi.error < chi.estimate
    one_chain = topological_susceptibility(q[0], volume=64, block_size=16)
    assert one_chain.estimate == pytest.approx(np.mean(q[0] ** 2) / 64)


@pytest.mark.parametrize(
    ("charge_", "volume", "match"),
    [
        (np.zeros((2, 8)), 0.0, "volume must be a finite number > 0"),
        (np.zeros((2, 8, 1)), 16, r"shape \(chains, draws\)"),
        (np.array([[0.0, np.nan]]), 16, "charge must be finite"),
    ],
    ids=["volume", "shape", "nan"],
)
def test_bad_susceptibility_arguments_are_refused(charge_, volume, match):
    with pytest.raises(ValueError, match=match):
        topological_susceptibility(charge_, volume)


@pytest.mark.slow  # liesample.sample compiles two samplers: about 10 s on two shared cores
def test_topology_example_runs(tmp_path, capsys, run_example):
    plot = tmp_path / "topology.png"
    assert run_example("topology_o3", ["--quick", "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if "chi_t = " in line]
    assert len(rows) == 4 and all("tau_int(Q) = " in row for row in rows), out
    assert plot.stat().st_size > 0


def test_topology_example_summary():
    summary = load_example("topology_o3").summarise(
        np.array([[0.0, 1.0, 1.0, -1.0] * 8, [0.0] * 32]), volume=16
    )
    assert summary["chi"] == pytest.approx(np.mean([0.75, 0.0]) / 16)
    assert summary["changes"].tolist() == [23, 0] and summary["tau"] > 0
