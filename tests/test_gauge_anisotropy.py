"""The anisotropic Wilson action ``β/ξ Σ_spatial + βξ Σ_temporal`` (docs/gauge.md): its
structure, the isotropic limit, the samplers' laws against exact references.

Statistical tests use fixed keys, independent chains (each chain's mean one sample) and a
tolerance of 4 Monte-Carlo standard errors; the references are exact (the 2-D torus law at
``βξ``, the single-plaquette law of each plane at its own coupling at strong coupling) or, for
heat bath against HMC, each other with errors from blocking (``tau_int`` included)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

import liesample
from liesample.diagnostics import blocking_error
from liesample.samplers.gauge.flow import wilson_flow
from liesample.samplers.gauge.hmc import gauge_hmc, stability_limit
from liesample.systems import wilson_gauge
from liesample.targets import gauge as exact


def staple_action(system, links, mu):
    """Σ_x Re tr(U_μ(x) A_μ(x)) / N."""
    a = system.staples(links, mu)
    if system.abelian:
        return jnp.sum(jnp.real(jnp.exp(1j * links[mu]) * a))
    return jnp.sum(jnp.real(jnp.einsum("...ij,...ji->...", links[mu], a))) / system.n


def plane_sum(system, links, mu, nu):
    return jnp.sum(1.0 - system.retrace(system.plaquette(links, mu, nu)))


# --------------------------------------------------------------------------- structure (fast)


def test_the_time_direction_is_the_last_axis_and_planes_carry_their_weights():
    system = wilson_gauge("SU2", (2, 2, 2, 4), anisotropy=2.0)
    assert system.time_axis == 3 == system.dim - 1
    assert system.temporal_planes == ((0, 3), (1, 3), (2, 3))
    assert system.spatial_planes == ((0, 1), (0, 2), (1, 2))
    assert {system.plane_weight(*p) for p in system.temporal_planes} == {2.0}
    assert {system.plane_weight(*p) for p in system.spatial_planes} == {0.5}
    two_d = wilson_gauge("U1", (4, 4), anisotropy=3.0)
    assert two_d.spatial_planes == () and two_d.plane_weight(0, 1) == 3.0


def test_systems_compare_by_value_with_their_anisotropy():
    a, b = wilson_gauge("SU2", (4, 4), anisotropy=2), wilson_gauge("SU2", (4, 4), anisotropy=2.0)
    assert a == b and hash(a) == hash(b)
    assert a != wilson_gauge("SU2", (4, 4), anisotropy=1.5)
    assert wilson_gauge("SU2", (4, 4)) == wilson_gauge("SU2", (4, 4), anisotropy=1.0)


@pytest.mark.parametrize(("group", "xi"), [("U1", 0.5), ("SU2", 2.0), ("SU3", 1.5)])
def test_action_and_staples_weigh_each_plane(group, xi):
    system = wilson_gauge(group, (2, 2, 4), anisotropy=xi)
    links = jax.jit(system.hot_start)(jax.random.key(0))

    def sums(u):
        planes = {p: plane_sum(system, u, *p) for p in system.planes}
        staples = sum(staple_action(system, u, mu) for mu in range(system.dim))
        return planes, staples, system.action(u)

    planes, staples, action = jax.jit(sums)(links)
    weighted = sum(system.plane_weight(*p) * float(v) for p, v in planes.items())
    np.testing.assert_allclose(float(action), weighted, rtol=1e-10)
    # each plaquette holds 4 links: Σ_μ Σ_x Re tr(U A)/N = 4 Σ_P w_P Re tr U_P / N
    weighted_retrace = sum(
        system.plane_weight(*p) * (system.num_plaquettes / 3 - float(v)) for p, v in planes.items()
    )
    np.testing.assert_allclose(float(staples), 4.0 * weighted_retrace, rtol=1e-10)
    # the observables stay unweighted means
    mean = 1.0 - sum(float(v) for v in planes.values()) / system.num_plaquettes
    np.testing.assert_allclose(float(system.mean_plaquette(links)), mean, rtol=1e-10)
    temporal = 1.0 - sum(float(planes[p]) for p in system.temporal_planes) / (2 * 16)
    np.testing.assert_allclose(float(system.temporal_plaquette(links)), temporal, rtol=1e-10)


def test_isotropic_draws_are_the_plain_actions_draws_bitwise():
    # ξ = 1 multiplies no weight in: the action, its observables and every sampler's draws are
    # those of the system without an anisotropy, operation for operation
    for group, shape, kind in (("SU2", (4, 4, 2), "heat bath"), ("U1", (4, 4), "hmc")):
        plain, isotropic = wilson_gauge(group, shape), wilson_gauge(group, shape, anisotropy=1.0)
        links = plain.hot_start(jax.random.key(1))
        assert float(plain.mean_plaquette(links)) == float(
            1.0 - isotropic.action(links) / isotropic.num_plaquettes
        )
        if kind == "heat bath":
            a = liesample.wilson_heat_bath(plain, beta=2.0)
            b = liesample.wilson_heat_bath(isotropic, beta=2.0)
        else:
            a = gauge_hmc(plain, beta=2.0, step_size=0.1, num_integration_steps=3)
            b = gauge_hmc(isotropic, beta=2.0, step_size=0.1, num_integration_steps=3)
        sa, _ = jax.jit(a.step)(jax.random.key(2), a.init(links))
        sb, _ = jax.jit(b.step)(jax.random.key(2), b.init(links))
        np.testing.assert_array_equal(np.asarray(sa.position), np.asarray(sb.position))


@pytest.mark.parametrize(("shape", "xi"), [((2, 2), 3.0), ((2, 2, 2), 0.5), ((2, 2, 2, 2), 2.0)])
def test_the_hmc_stability_limit_is_the_weighted_stiffest_mode(shape, xi):
    # at the identity the U(1) action is the quadratic form ½ Σ_P w_P (dθ)_P²: its Hessian's
    # largest eigenvalue λ gives the leapfrog limit 2/√(βλ)
    system, beta = wilson_gauge("U1", shape, anisotropy=xi), 1.7
    hessian = jax.hessian(lambda t: beta * system.action(t.reshape(system.cold_start().shape)))
    h = np.asarray(hessian(jnp.zeros(system.cold_start().size, jnp.float64)))
    lam = np.linalg.eigvalsh(h).max()
    assert stability_limit(system, beta) == pytest.approx(2.0 / np.sqrt(lam), rel=1e-9)


def test_the_flow_uses_the_isotropic_action():
    anisotropic = wilson_gauge("SU2", (2, 2, 2, 2), anisotropy=2.5)
    isotropic = wilson_gauge("SU2", (2, 2, 2, 2))
    links = anisotropic.hot_start(jax.random.key(3))
    a, ea = wilson_flow(anisotropic, links, 0.2, 4)
    b, eb = wilson_flow(isotropic, links, 0.2, 4)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(ea), np.asarray(eb))


class _Compiles:
    count = 0

    def __call__(self, event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            self.count += 1


@pytest.mark.filterwarnings("ignore::UserWarning")  # 20 draws: the convergence checks speak
def test_an_anisotropic_sweep_in_beta_compiles_at_its_first_point_only():
    # the anisotropy is part of the system (a value): an equal system rebuilt at another β
    # compiles nothing; another ξ is another structure
    def run(beta):
        system = wilson_gauge("U1", (4, 4), anisotropy=2.0)
        starts = np.stack([system.cold_start()] * 2)
        sampler = liesample.wilson_heat_bath(system, beta=beta)
        return liesample.sample(
            sampler, jax.random.key(0), starts, 20, num_warmup=0, progress_bar=False
        )

    run(0.5)
    compiles = _Compiles()
    jax.monitoring.register_event_duration_secs_listener(compiles)
    try:
        run(3.0)
    finally:
        jax.monitoring.unregister_event_duration_listener(compiles)
    assert compiles.count == 0
    hmc = lambda xi, beta: gauge_hmc(
        wilson_gauge("SU2", (4, 4), anisotropy=xi), beta=beta, step_size=0.1,
        num_integration_steps=3,
    ).structure.build  # fmt: skip
    assert hmc(2.0, 1.0) == hmc(2.0, 3.0) != hmc(1.5, 1.0)


# --------------------------------------------------------------------------- laws


def chain_means(system, sampler, observables, num_draws, num_chains=8, seed=0, num_warmup=50):
    starts = jax.vmap(system.hot_start)(jax.random.split(jax.random.key(seed), num_chains))
    tree = liesample.sample(
        sampler, jax.random.key(seed + 1), starts, num_draws, num_warmup=num_warmup,
        observables=observables, keep_positions=False, progress_bar=False,
    )  # fmt: skip
    return {name: np.asarray(tree.posterior[name].values) for name in observables}


def assert_within_mcse(draws, value, factor=4.0):
    means = draws.mean(1)  # one mean per independent chain
    mcse = means.std(ddof=1) / np.sqrt(means.size)
    z = (means.mean() - value) / mcse
    print(f"estimate {means.mean():.5f} exact {value:.5f} mcse {mcse:.2g} z {z:.2f}")
    assert abs(z) < factor, (means.mean(), value, mcse)


def test_2d_heat_bath_samples_the_torus_law_at_beta_xi():
    # a 2-D lattice has only the space–time plane: S = βξ Σ_P (…), the torus law at βξ
    beta, xi = 1.0, 2.0
    system = wilson_gauge("SU2", (4, 4), anisotropy=xi)
    sampler = liesample.wilson_heat_bath(system, beta=beta)
    draws = chain_means(system, sampler, {"p": system.mean_plaquette}, 300)
    assert_within_mcse(draws["p"], exact.su2_torus_plaquette_mean(beta * xi, 16))


def single_su2(beta_p):
    """E[½ tr U] under exp(β_P ½ tr U) dHaar: I₂(β_P)/I₁(β_P) = β_P/4 + O(β_P³)."""
    return float(special.iv(2, beta_p) / special.iv(1, beta_p))


@pytest.mark.slow
def test_4d_heat_bath_at_strong_coupling_gives_each_plane_its_own_coupling():
    # SU(2), β = 0.2, ξ = 2: β_s = 0.1, β_t = 0.4. At strong coupling each plaquette follows
    # its single-plaquette law up to the corrections of closed surfaces through it (a cube, a
    # tube around the time extent 2): O(u⁵) with u = I₂/I₁(β_P) < 0.1, a few 1e-5, under a
    # tenth of the MC standard error here.
    beta, xi = 0.2, 2.0
    system = wilson_gauge("SU2", (4, 4, 4, 2), anisotropy=xi)
    sampler = liesample.wilson_heat_bath(system, beta=beta)
    observables = {"s": system.spatial_plaquette, "t": system.temporal_plaquette}
    draws = chain_means(system, sampler, observables, 100, num_warmup=10)
    assert_within_mcse(draws["s"], single_su2(beta / xi))
    assert_within_mcse(draws["t"], single_su2(beta * xi))


@pytest.mark.slow
def test_2d_hmc_samples_the_torus_law_at_beta_xi():
    beta, xi = 4.0, 0.5
    system = wilson_gauge("SU2", (4, 4), anisotropy=xi)
    sampler = gauge_hmc(system, beta=beta, step_size=0.15, num_integration_steps=10)
    draws = chain_means(system, sampler, {"p": system.mean_plaquette}, 400, num_warmup=100)
    assert_within_mcse(draws["p"], exact.su2_torus_plaquette_mean(beta * xi, 16))


@pytest.mark.slow
def test_4d_heat_bath_and_hmc_agree_on_spatial_and_temporal_plaquettes():
    # no closed form at β = 2, ξ = 1.5: the two samplers (exact local draws; exact-exponential
    # HMC with a Metropolis test) must agree within 4 combined standard errors, each from
    # blocking over its chains (tau_int included)
    beta, xi = 2.0, 1.5
    system = wilson_gauge("SU2", (4, 4, 4, 4), anisotropy=xi)
    observables = {"s": system.spatial_plaquette, "t": system.temporal_plaquette}
    heat = liesample.wilson_heat_bath(system, beta=beta)
    limit = stability_limit(system, beta)
    hmc = gauge_hmc(system, beta=beta, step_size=0.3 * limit, num_integration_steps=8)
    a = chain_means(system, heat, observables, 400, num_chains=4, num_warmup=100)
    b = chain_means(system, hmc, observables, 400, num_chains=4, num_warmup=200)
    for name in observables:
        ra, rb = blocking_error(a[name]), blocking_error(b[name])
        sigma = np.hypot(ra.error, rb.error)
        print(name, ra.mean, ra.error, ra.tau_int, rb.mean, rb.error, rb.tau_int)
        assert abs(ra.mean - rb.mean) < 4.0 * sigma, (name, ra, rb)
    # and the anisotropy is seen: β_t > β_s orders the temporal plaquettes more
    assert blocking_error(a["t"]).mean > blocking_error(a["s"]).mean + 0.05
