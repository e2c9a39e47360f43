"""The Polyakov-loop observables (liesample.analysis.polyakov): exact values on synthetic series
and on Haar-random SU(2) fields (the β = 0 law), errors that see the autocorrelation, refusals.

Tolerances: 4 standard errors (jackknife or blocking), fixed seeds."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from liesample.analysis.polyakov import (
    polyakov_binder_cumulant,
    polyakov_modulus,
    polyakov_summary,
    polyakov_susceptibility,
)
from liesample.systems import wilson_gauge


def within(result, value, factor=4.0):
    z = (result.estimate - value) / result.error
    print(f"estimate {result.estimate:.5f} exact {value:.5f} error {result.error:.2g} z {z:.2f}")
    assert abs(z) < factor, (result.estimate, value, result.error)


def test_an_ordered_series_has_no_fluctuation_and_the_ordered_cumulant():
    loops = 0.4 * np.sign(np.random.default_rng(1).normal(size=(2, 256)))  # both centre sectors
    summary = polyakov_summary(loops, spatial_volume=64, block_size=16)
    assert summary.modulus.mean == pytest.approx(0.4)
    assert summary.susceptibility.estimate == pytest.approx(0.0, abs=1e-12)
    assert summary.binder.estimate == pytest.approx(2.0 / 3.0)


@pytest.mark.parametrize("complex_loop", [False, True])
def test_gaussian_loops_give_the_disordered_cumulant_and_susceptibility(complex_loop):
    # P Gaussian (real: SU(2); complex, circular: U(1), SU(3)) of variance s² per component:
    # U = 0 (real) or 1/3 (complex); χ = V s² (1 − 2/π) (real) or V s² (2 − π/2) (complex)
    rng, s, volume = np.random.default_rng(2), 0.05, 216
    shape = (4, 4096)
    loops = s * rng.normal(size=shape)
    if complex_loop:
        loops = loops + 1j * s * rng.normal(size=shape)
    u, chi = (1.0 / 3.0, 2.0 - math.pi / 2) if complex_loop else (0.0, 1.0 - 2.0 / math.pi)
    within(polyakov_binder_cumulant(loops), u)
    within(polyakov_susceptibility(loops, volume), volume * s**2 * chi)


@pytest.mark.slow
def test_haar_fields_give_the_exact_beta_zero_moments():
    # at β = 0 every link is Haar: on N_s³ × 2 each site's loop ½ tr(U₁U₂) is ½ tr of a Haar
    # SU(2) matrix (moments E a² = 1/4, E a⁴ = 1/8), independent over the n = N_s³ sites, so
    # ⟨P²⟩ = 1/(4n) and U = 1 − ⟨P⁴⟩/(3⟨P²⟩²) = 1/(3n) exactly (n = 8 here)
    system = wilson_gauge("SU2", (2, 2, 2, 2))
    n = 2**3

    @jax.jit
    def loops(keys):
        return jax.vmap(lambda k: system.polyakov_loop(system.hot_start(k)))(keys)

    p = np.asarray(loops(jax.random.split(jax.random.key(3), 8000))).reshape(2, 4000)
    assert np.max(np.abs(p.imag)) < 1e-12  # SU(2) traces are real
    within(polyakov_binder_cumulant(p.real, block_size=1), 1.0 / (3.0 * n))
    modulus = polyakov_modulus(p.real)  # |P| of independent draws: no autocorrelation
    assert modulus.mean > 0 and modulus.tau_int < 2.0
    mean_square = np.mean(p.real**2)
    error = np.std(p.real**2, ddof=1) / math.sqrt(p.size)
    assert abs(mean_square - 1.0 / (4 * n)) < 4.0 * error


def test_the_modulus_error_includes_the_autocorrelation():
    # an AR(1) loop with ρ = 0.9: τ_int ≈ (1 + ρ)/(1 − ρ) = 19; the blocking error is some √τ
    # times the naive one
    rng, rho = np.random.default_rng(4), 0.9
    x = np.zeros((2, 2**15))
    x[:, 0] = rng.normal(size=2)
    noise = rng.normal(size=x.shape) * math.sqrt(1 - rho**2)
    for t in range(1, x.shape[1]):
        x[:, t] = rho * x[:, t - 1] + noise[:, t]
    loops = 0.3 + 0.05 * x  # one sector: |P| follows the AR(1) process
    result = polyakov_modulus(loops)
    naive = np.std(loops, ddof=1) / math.sqrt(loops.size)
    assert 10.0 < result.tau_int < 30.0
    assert result.error > 3.0 * naive


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: polyakov_modulus(np.zeros((2, 3, 4))), ValueError, "loops must hold one"),
        (lambda: polyakov_modulus(np.zeros(1)), ValueError, "at least 2 draws"),
        (lambda: polyakov_modulus([0.1, np.nan, 0.2]), ValueError, "loops must be finite"),
        (lambda: polyakov_modulus(np.array(["a", "b"])), TypeError, "real or complex"),
        (lambda: polyakov_susceptibility(np.ones(8), 0), ValueError, "spatial_volume must be"),
        (lambda: polyakov_susceptibility(np.ones(8), "V"), ValueError, "math.prod"),
        (lambda: polyakov_summary(np.ones(8), math.inf), ValueError, "spatial_volume must"),
    ],
)
def test_bad_input_is_refused_by_name(call, error, match):
    with pytest.raises(error, match=match):
        call()
