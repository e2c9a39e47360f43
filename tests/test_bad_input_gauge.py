"""What the gauge tools refuse, by name, before any compilation; and β < 0, which they support."""

import math

import jax
import numpy as np
import pytest

import liesample
from liesample.samplers.gauge.flow import RK3_STABILITY, flow_scale, max_flow_step, wilson_flow
from liesample.samplers.gauge.heat_bath import GaugeState, build_kernel
from liesample.samplers.gauge.hmc import gauge_hmc, stability_limit
from liesample.systems import wilson_gauge
from liesample.targets import gauge as exact

U1 = wilson_gauge("U1", (4, 4))
LINKS = U1.cold_start()


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        # wilson_flow: the flow time, the steps, the step's stability, the links
        (lambda: wilson_flow(U1, LINKS, -1.0, 10), ValueError, "flow_time must be > 0"),
        (lambda: wilson_flow(U1, LINKS, 0.0, 10), ValueError, "flow_time must be > 0"),
        (lambda: wilson_flow(U1, LINKS, math.nan, 10), ValueError, "flow_time must be finite"),
        (lambda: wilson_flow(U1, LINKS, 1.0, 0), ValueError, "num_steps must be an integer"),
        (lambda: wilson_flow(U1, LINKS, 1.0, 2.5), ValueError, "num_steps must be an integer"),
        (lambda: wilson_flow(U1, LINKS, 1.0, math.nan), ValueError, "num_steps must be an int"),
        (lambda: wilson_flow(U1, LINKS, 1e4, 1), ValueError, "use num_steps >= 31838"),
        (lambda: wilson_flow(U1, LINKS[0], 1.0, 10), ValueError, "links must have shape"),
        (lambda: wilson_flow(U1, LINKS * np.nan, 1.0, 10), ValueError, "links must be finite"),
        (lambda: wilson_flow(U1, LINKS, 1.0, 10, "E"), TypeError, "observable must be"),
        # observables: loop extents, axes, planes, boundaries, link shapes and dtypes
        (lambda: U1.wilson_loop(LINKS, 0, 1), ValueError, "r must be an extent in 1 … 3"),
        (lambda: U1.wilson_loop(LINKS, -1, 1), ValueError, "r must be an extent"),
        (lambda: U1.wilson_loop(LINKS, 1, 4), ValueError, "t must be an extent .* wraps"),
        (lambda: U1.wilson_loop(LINKS, 1.5, 1), TypeError, "r must be an int"),
        (lambda: U1.wilson_loop(LINKS, 1, 1, mu=1), ValueError, "mu and nu must be two diff"),
        (lambda: U1.wilson_loop(LINKS, 1, 1, nu=2), ValueError, "nu must be a lattice direc"),
        (lambda: U1.polyakov_loop(LINKS, axis=5), ValueError, "axis must be a lattice direc"),
        (lambda: U1.polyakov_loop(LINKS, axis=True), TypeError, "axis must be an int"),
        (
            lambda: wilson_gauge("U1", (4, 4), "open").polyakov_loop(LINKS),
            ValueError,
            "polyakov_loop needs boundary='periodic'",
        ),
        (lambda: U1.plaquette(LINKS, 0, 3), ValueError, "nu must be a lattice direction"),
        (lambda: U1.staples(LINKS, -1), ValueError, "mu must be a lattice direction"),
        (lambda: U1.mean_plaquette(LINKS[:, :2]), ValueError, "links must have shape"),
        (lambda: U1.action(LINKS.astype(int)), TypeError, "links must be a real floating"),
        (
            lambda: wilson_gauge("SU2", (4, 4)).action(LINKS),
            ValueError,
            r"links must have shape \(2, 4, 4, 2, 2\)",
        ),
        (lambda: U1.cold_start(dtype=np.int32), TypeError, "dtype must be a real floating"),
        (lambda: U1.hot_start(0), TypeError, "rng_key must be a JAX random key"),
        (lambda: U1.logdensity(math.nan), ValueError, "beta must be finite"),
        # the anisotropy: a finite number > 0, named with what it is and a value that works
        (lambda: wilson_gauge("SU2", (4, 4), anisotropy=0.0), ValueError, "anisotropy must be >"),
        (lambda: wilson_gauge("U1", (4, 4), anisotropy=-2.0), ValueError, "anisotropy=1.0"),
        (lambda: wilson_gauge("U1", (4, 4), anisotropy=math.nan), ValueError, "anisotropy must "),
        (lambda: wilson_gauge("U1", (4, 4), anisotropy=math.inf), ValueError, "be finite.*β_t"),
        (lambda: wilson_gauge("U1", (4, 4), anisotropy="2"), TypeError, "anisotropy must be a"),
        (lambda: wilson_gauge("U1", (4, 4), anisotropy=True), TypeError, "anisotropy must be a"),
        (lambda: U1.spatial_plaquette(LINKS), ValueError, "spatial_plaquette needs a plane"),
        # flow_scale: one length, finite, increasing
        (lambda: flow_scale([1, 2, 3], [1, 2]), ValueError, "times and energies must have one"),
        (lambda: flow_scale([1, 2], [1, np.inf]), ValueError, "energies must be finite"),
        (lambda: flow_scale([2, 1], [1, 1]), ValueError, "times must be >= 0 and strictly"),
        (lambda: flow_scale([[1, 2]], [[1, 2]]), ValueError, "times must be a non-empty 1-D"),
        (lambda: flow_scale([1, 2], [1, 2], 0.0), ValueError, "reference must be > 0"),
        # samplers
        (
            lambda: gauge_hmc(U1, beta=1.0, step_size=-0.1, num_integration_steps=5),
            ValueError,
            "step_size must be > 0",
        ),
        (lambda: stability_limit(U1, math.inf), ValueError, "beta must be finite"),
    ],
)
def test_gauge_tools_refuse_bad_input_by_name(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_the_flow_step_bound_is_rk3s_stability_interval_over_4d():
    # 1 + z + z²/2 + z³/6 = −1 at z = −r₃: the bound of the staggered mode's rate 4d
    z = -RK3_STABILITY
    assert 1 + z + z**2 / 2 + z**3 / 6 == pytest.approx(-1.0, abs=1e-12)
    assert max_flow_step(wilson_gauge("SU3", (4, 4, 4, 4))) == pytest.approx(RK3_STABILITY / 16)
    # just inside the bound is taken (checked before any compilation, so only the refusal is
    # exercised at the edge; the smoothing itself is tested in tests/test_wilson_gauge.py)
    limit = max_flow_step(U1)
    with pytest.raises(ValueError, match="num_steps >= 11"):
        wilson_flow(U1, LINKS, 10 * limit, 10)


def test_wilson_loop_extents_up_to_the_lattice_size_minus_one():
    hot = U1.hot_start(jax.random.key(0))
    assert float(U1.wilson_loop(LINKS, 3, 3)) == pytest.approx(1.0)
    np.testing.assert_allclose(U1.wilson_loop(hot, 1, 1), U1.mean_plaquette(hot))
    # on an open lattice only the rectangles inside it are averaged: 1×1 is the plaquette mean
    open_lattice = wilson_gauge("U1", (4, 4), "open")
    np.testing.assert_allclose(
        open_lattice.wilson_loop(hot, 1, 1), open_lattice.mean_plaquette(hot), rtol=1e-12
    )


def test_negative_beta_is_supported_and_its_hmc_limit_is_that_of_abs_beta():
    assert stability_limit(U1, -2.0) == stability_limit(U1, 2.0)
    sampler = gauge_hmc(U1, beta=-2.0, step_size=0.1, num_integration_steps=5)
    assert sampler.settings["beta"] == -2.0
    assert liesample.wilson_heat_bath(U1, beta=-2.0).settings["beta"] == -2.0
    # the exact U(1) torus law at β < 0: by a brute-force integral over the 3 plaquettes of a
    # torus with V = 3 (Σθ_P = 0), and for even V minus the law at |β|
    phi = np.linspace(-np.pi, np.pi, 401)[:-1]
    a, b = np.meshgrid(phi, phi, indexing="ij")
    weight = np.exp(-1.3 * (np.cos(a) + np.cos(b) + np.cos(a + b)))
    brute = float(np.sum(weight * np.cos(a)) / np.sum(weight))
    assert exact.u1_torus_plaquette_mean(-1.3, 3) == pytest.approx(brute, abs=1e-12)
    assert exact.u1_torus_plaquette_mean(-1.3, 16) == pytest.approx(
        -exact.u1_torus_plaquette_mean(1.3, 16), abs=1e-15
    )


def _heat_bath_plaquettes(system, beta, num_chains, num_steps, burn_in=10):
    kernel = build_kernel(system, 1, 0)
    starts = jax.vmap(system.hot_start)(jax.random.split(jax.random.key(0), num_chains))

    def chain(key, links):
        def one(state, k):
            state, _ = kernel(k, state, beta)
            return state, system.mean_plaquette(state.position)

        return jax.lax.scan(one, GaugeState(links), jax.random.split(key, num_steps))[1]

    keys = jax.random.split(jax.random.key(1), num_chains)
    return np.asarray(jax.jit(jax.vmap(chain))(keys, starts))[:, burn_in:]


def test_heat_bath_at_negative_beta_matches_the_2x2_u1_torus():
    # the 2×2 torus (V = 4) differs from independent plaquettes by many standard errors
    system, beta = wilson_gauge("U1", (2, 2)), -1.5
    means = _heat_bath_plaquettes(system, beta, 64, 110).mean(axis=1)
    error = means.std(ddof=1) / math.sqrt(means.size)
    value = exact.u1_torus_plaquette_mean(beta, 4)
    assert abs(means.mean() - value) < 4 * error, (means.mean(), value, error)
    assert abs(means.mean() - exact.single_plaquette_mean(beta, 1)) > 8 * error


# slow: SU(2)'s negated-a₀ draw; the default suite checks U(1) with
# test_bad_input_gauge.py::test_heat_bath_at_negative_beta_matches_the_2x2_u1_torus
@pytest.mark.slow
def test_heat_bath_at_negative_beta_matches_the_su2_torus():
    # even extents: flipping U_0 on every other row flips every plaquette, so E_β = −E_|β|
    # From a hot start |P| overshoots for about a hundred sweeps at either sign of β (the same
    # transient at β = ±1.5), so the chains are thermalised for 200 sweeps before 600 are kept.
    system, beta = wilson_gauge("SU2", (4, 4)), -1.5
    means = _heat_bath_plaquettes(system, beta, 16, 800, burn_in=200).mean(axis=1)
    error = means.std(ddof=1) / math.sqrt(means.size)
    value = -exact.su2_torus_plaquette_mean(-beta, 16)
    assert abs(means.mean() - value) < 4 * error, (means.mean(), value, error)


def test_a_flow_to_non_finite_links_raises():
    # finite angles so large that their sums overflow: the flowed links are NaN
    huge = np.full(U1.space.position_array_shape, 1e308)
    with pytest.raises(FloatingPointError, match="wilson_flow produced non-finite links"):
        wilson_flow(U1, huge, 0.1, 1)
