"""The Wilson gauge system, its exact 2-D laws, heat bath, HMC/SMD and flow (docs/gauge.md).

Default tests are cheap (structure, identities, refusals); the exact-law checks through
``liesample.sample`` from hot starts are ``slow`` (``make test-slow``), with tolerances from the
Monte-Carlo standard error over independent chains."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special

import liesample
from liesample.samplers.gauge.flow import flow_scale, wilson_flow
from liesample.samplers.gauge.hmc import gauge_hmc, stability_limit
from liesample.systems import wilson_gauge
from liesample.targets import gauge as exact


def staple_action(system, links, mu):
    """Σ_x Re tr(U_μ(x) A_μ(x)) / N."""
    a = system.staples(links, mu)
    if system.abelian:
        return float(jnp.sum(jnp.real(jnp.exp(1j * links[mu]) * a)))
    return float(jnp.sum(jnp.real(jnp.einsum("...ij,...ji->...", links[mu], a))) / system.n)


@pytest.mark.parametrize(
    ("group", "boundary"), [("U1", "open"), ("SU2", "periodic"), ("SU3", "open")]
)
def test_staples_hold_every_plaquette_of_a_link(group, boundary):
    # in d dimensions each plaquette holds two links of each of its two directions
    system = wilson_gauge(group, (4, 2, 2), boundary)
    links = system.hot_start(jax.random.key(0))
    system.space.check(links)
    total = sum(staple_action(system, links, mu) for mu in range(system.dim))
    plaquettes = system.num_plaquettes - float(system.action(links))
    np.testing.assert_allclose(total, 4.0 * plaquettes, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("group", ["U1", "SU3"])
def test_cold_start_and_loops(group):
    system = wilson_gauge(group, (4, 4))
    cold = system.cold_start()
    assert float(system.mean_plaquette(cold)) == pytest.approx(1.0)
    assert complex(system.polyakov_loop(cold)) == pytest.approx(1.0)
    hot = system.hot_start(jax.random.key(1))
    np.testing.assert_allclose(system.wilson_loop(hot, 1, 1), system.mean_plaquette(hot))
    starts = jax.vmap(system.hot_start)(jax.random.split(jax.random.key(2), 3))
    assert starts.shape == (3, *system.space.position_array_shape)


def test_geometric_charge_is_an_integer_on_the_torus():
    system = wilson_gauge("U1", (6, 4))
    charges = jax.vmap(lambda k: system.topological_charge(system.hot_start(k)))(
        jax.random.split(jax.random.key(3), 20)
    )
    np.testing.assert_allclose(charges, np.round(charges), atol=1e-9)
    assert np.any(np.round(charges) != 0)


def test_bad_arguments_are_refused_with_the_fix():
    with pytest.raises(ValueError, match="group must be"):
        wilson_gauge("SO3", (4, 4))
    with pytest.raises(ValueError, match="2 to 4"):
        wilson_gauge("U1", (4,))
    with pytest.raises(ValueError, match="boundary"):
        wilson_gauge("U1", (4, 4), "twisted")
    with pytest.raises(ValueError, match="even lattice extents"):
        liesample.recommended_sampler(wilson_gauge("U1", (3, 4)), beta=1.0)
    with pytest.raises(ValueError, match="topological_charge"):
        wilson_gauge("SU2", (4, 4)).topological_charge(wilson_gauge("SU2", (4, 4)).cold_start())


def test_recommended_sampler_is_the_heat_bath():
    sampler = liesample.recommended_sampler(wilson_gauge("SU3", (4, 4)), beta=2.0)
    assert sampler.settings["sampler"] == "wilson_heat_bath"
    assert sampler.settings["overrelaxation"] == 1


def test_a_step_past_the_leapfrog_stability_limit_is_refused():
    system = wilson_gauge("SU3", (4, 4, 4, 4))
    limit = stability_limit(system, 6.0)
    with pytest.raises(ValueError, match="stability limit"):
        gauge_hmc(system, beta=6.0, step_size=1.01 * limit, num_integration_steps=10)
    sampler = gauge_hmc(system, beta=6.0, step_size=0.5 * limit, num_integration_steps=10)
    assert sampler.settings["sampler"] == "geometric_hmc"


def test_float32_links_are_refused_by_the_group_check():
    system = wilson_gauge("SU2", (4, 4))
    links = system.cold_start().astype(jnp.complex64)
    off = links.at[0, 0, 0].multiply(1.0 + 1e-3)
    with pytest.raises(ValueError, match="off SU"):
        system.space.check(off)


def test_exact_laws_agree_with_direct_integration():
    beta = 2.3
    def haar(f):
        return integrate.quad(lambda a: f(a) * np.sin(a) ** 2 * np.exp(beta * np.cos(a)), 0, np.pi)[
            0
        ]

    direct = haar(np.cos) / haar(lambda a: 1.0)
    assert exact.single_plaquette_mean(beta, 2) == pytest.approx(direct, rel=1e-12)
    bessel = special.iv(2, beta) / special.iv(1, beta)
    assert exact.single_plaquette_mean(beta, 2) == pytest.approx(bessel)
    # the torus tends to independent plaquettes as V grows
    assert exact.su2_torus_plaquette_mean(beta, 400) == pytest.approx(direct, rel=1e-10)
    open_u1 = exact.single_plaquette_mean(1.0, 1)
    assert exact.u1_torus_plaquette_mean(1.0, 400) == pytest.approx(open_u1)
    # SU(3) at small β: E[Re tr U/3] = β/18 + O(β²) (E|tr U|² = 1 under Haar)
    assert exact.single_plaquette_mean(1e-3, 3) == pytest.approx(1e-3 / 18, rel=1e-3)
    law = exact.u1_torus_charge_law(1.0, 16, 6)
    assert law.sum() == pytest.approx(1.0) and np.allclose(law, law[::-1])


# --------------------------------------------------------------------------- exact checks (slow)


def chain_means(system, sampler, observables, num_draws, num_chains=8, seed=0, num_warmup=100):
    starts = jax.vmap(system.hot_start)(jax.random.split(jax.random.key(seed), num_chains))
    tree = liesample.sample(
        sampler, jax.random.key(seed + 1), starts, num_draws, num_warmup=num_warmup,
        observables=observables, keep_positions=False, progress=False,
    )  # fmt: skip
    return {name: np.asarray(tree.posterior[name].values).mean(1) for name in observables}


def assert_within_mcse(means, value, factor=4.0):
    mcse = means.std(ddof=1) / np.sqrt(means.size)
    z = (means.mean() - value) / mcse
    print(f"estimate {means.mean():.5f} exact {value:.5f} mcse {mcse:.2g} z {z:.2f}")
    assert abs(z) < factor, (means.mean(), value, mcse)


@pytest.mark.slow
def test_u1_torus_plaquette_and_charge_through_sample():
    system, beta = wilson_gauge("U1", (4, 4)), 1.0
    sampler = liesample.recommended_sampler(system, beta=beta)
    observables = {
        "plaquette": system.mean_plaquette,
        "q2": lambda u: system.topological_charge(u) ** 2,
    }
    means = chain_means(system, sampler, observables, 600)
    law = exact.u1_torus_charge_law(beta, 16, 10)
    assert_within_mcse(means["plaquette"], exact.u1_torus_plaquette_mean(beta, 16))
    assert_within_mcse(means["q2"], float(np.sum(law * np.arange(-10, 11) ** 2)))


@pytest.mark.slow
def test_small_tori_feel_the_global_constraint():
    # on 2×2 the torus laws differ from independent plaquettes by many MCSE
    for group, beta, law in (
        ("U1", 1.0, exact.u1_torus_plaquette_mean),
        ("SU2", 2.0, exact.su2_torus_plaquette_mean),
    ):
        system = wilson_gauge(group, (2, 2))
        sampler = liesample.recommended_sampler(system, beta=beta)
        means = chain_means(system, sampler, {"plaquette": system.mean_plaquette}, 800, 16)
        assert_within_mcse(means["plaquette"], law(beta, 4))


@pytest.mark.slow
def test_su3_open_lattice_plaquettes_are_independent_weyl_laws():
    system, beta = wilson_gauge("SU3", (4, 4), "open"), 3.0
    sampler = liesample.recommended_sampler(system, beta=beta)
    means = chain_means(system, sampler, {"plaquette": system.mean_plaquette}, 400)
    assert_within_mcse(means["plaquette"], exact.single_plaquette_mean(beta, 3))


@pytest.mark.slow
@pytest.mark.parametrize("persistence", [0.0, 0.9])
def test_hmc_and_smd_on_the_links_match_the_torus_law(persistence):
    system, beta = wilson_gauge("SU2", (4, 4)), 2.0
    steps = 10 if persistence == 0 else 1
    sampler = gauge_hmc(
        system, beta=beta, step_size=0.15, num_integration_steps=steps,
        momentum_persistence=persistence,
    )  # fmt: skip
    # SMD moves one short step per update: it needs a longer warm-up from hot starts
    draws, warmup = (2000, 1000) if steps == 1 else (400, 100)
    means = chain_means(system, sampler, {"plaquette": system.mean_plaquette}, draws, 8, 0, warmup)
    assert_within_mcse(means["plaquette"], exact.su2_torus_plaquette_mean(beta, 16))


@pytest.mark.slow
def test_links_stay_in_the_group_over_many_heat_bath_updates():
    system = wilson_gauge("SU3", (4, 4))
    sampler = liesample.wilson_heat_bath(system, beta=4.0, overrelaxation=3)
    state = sampler.init(system.hot_start(jax.random.key(5)))
    run = jax.jit(lambda s, k: jax.lax.scan(lambda s, k: (sampler.step(k, s)[0], None), s, k)[0])
    state = run(state, jax.random.split(jax.random.key(6), 500))  # 500 × 4 sweeps × 32 links
    error = system.space.constraint_error(np.asarray(state.position))
    print("SU(3) unitarity error after 64 000 link updates:", error)
    assert error < 1e-12


@pytest.mark.slow
def test_wilson_flow_lowers_the_energy_and_finds_t0_on_a_smooth_field():
    system = wilson_gauge("SU3", (4, 4, 4, 4))
    links = system.hot_start(jax.random.key(7))
    flowed, energies = jax.jit(lambda u: wilson_flow(system, u, 2.0, 40))(links)
    assert np.all(np.diff(np.asarray(energies)) < 0)
    assert system.space.constraint_error(np.asarray(flowed)) < 1e-12
    times = np.linspace(0.05, 2.0, 40)
    assert np.isfinite(flow_scale(times, energies)) or np.all(times**2 * energies < 0.3)
