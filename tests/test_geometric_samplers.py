"""Geometric HMC and kinetic Langevin on spheres, SO(3), U(1), SU(2) and products with R:
ergodic averages against exact references, within 5 Monte-Carlo standard errors (MCSE from
independent chains)."""

import blackjax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import vonmises_fisher

import liesample
from liesample import spaces as S
from liesample.targets.groups import (
    MatrixFisherLaw,
    VonMisesFisherPosterior,
    su2_plaquette_mean,
    u1_plaquette_mean,
    vmf_mean_resultant_length,
)
from liesample.tuning.adaptation import window_adaptation

NUM_CHAINS = 16


def chain_means(sampler, key, starts, num_steps, observables, burn_in=100):
    """Per-chain averages of ``observables(position)`` (a 1-D array) after ``burn_in``."""

    def run(key, start):
        state = sampler.init(start)

        def body(carry, xs):
            state, total = carry
            key, keep = xs
            state, info = sampler.step(key, state)
            return (state, total + keep * observables(state.position)), keep * info.acceptance_rate

        keys = jax.random.split(key, burn_in + num_steps)
        keep = jnp.arange(burn_in + num_steps) >= burn_in
        zero = jnp.zeros_like(observables(start))
        (_, total), acceptance = jax.lax.scan(body, (state, zero), (keys, keep))
        return total / num_steps, acceptance.sum() / num_steps

    keys = jax.random.split(key, jax.tree.leaves(starts)[0].shape[0])
    means, acceptance = liesample.jit(jax.vmap(run))(keys, starts)
    return np.asarray(means), np.asarray(acceptance)


def assert_within_mcse(means, exact, factor=5.0):
    estimate = means.mean(0)
    mcse = means.std(0, ddof=1) / np.sqrt(means.shape[0])
    z = (estimate - np.asarray(exact)) / mcse
    print("z-scores:", np.round(z, 2))  # shown with pytest -s
    assert np.all(np.abs(z) < factor), (estimate, exact, mcse, z)
    return z


# --------------------------------------------------------------------------- a product target

MU2 = np.array([0.0, 0.6, 0.8])
MU5 = np.array([0.5, -0.5, 0.5, 0.5, 0.0, 0.0])
KAPPA2, KAPPA5, KAPPA_E3 = 4.0, 10.0, 3.0
F = np.diag([2.0, 1.0, -0.5])
M_E3 = np.array([0.6, 0.0, 0.8])
M4 = np.array([0.0, 0.8, 0.0, 0.6])  # on SO(4), a potential of R e₄ only
M3 = np.array([0.6j, 0.0, 0.8])  # on SU(3), a potential of the first column U e₁ ∈ S⁵ ⊂ C³
KAPPA4, KAPPA_SU3 = 2.0, 3.0
PRODUCT = {
    "s2": S.Sphere(2),
    "s5": S.Sphere(5),
    "fisher": S.SO(3),
    "top": S.SO(3),
    "so4": S.SO(4),
    "su3": S.SU(3),
    "x": S.Euclidean((2,)),
}


# Per block: its log-density, its observables and their exact means (the blocks are
# independent). Haar pushes a column of a group element forward to the uniform law on its
# sphere, so under exp(κ m·R e_k) dHaar the column R e_k is vMF(m, κ) on S² (SO(3)), S³ (SO(4))
# or S⁵ (SU(3), C³ = R⁶).
BLOCKS = {
    "s2": (
        lambda x: KAPPA2 * jnp.dot(MU2, x),
        lambda x: jnp.dot(MU2, x)[None],
        lambda: [vmf_mean_resultant_length(KAPPA2, 3)],
    ),
    "s5": (
        lambda x: KAPPA5 * jnp.dot(MU5, x),
        lambda x: jnp.dot(MU5, x)[None],
        lambda: [vmf_mean_resultant_length(KAPPA5, 6)],
    ),
    "fisher": (
        lambda R: jnp.sum(F * R),
        jnp.diagonal,
        lambda: np.diag(MatrixFisherLaw(F).mean()),
    ),
    "top": (
        lambda R: KAPPA_E3 * jnp.dot(M_E3, R[:, 2]),
        lambda R: jnp.dot(M_E3, R[:, 2])[None],
        lambda: [vmf_mean_resultant_length(KAPPA_E3, 3)],
    ),
    "so4": (
        lambda R: KAPPA4 * jnp.dot(M4, R[:, 3]),
        lambda R: jnp.dot(M4, R[:, 3])[None],
        lambda: [vmf_mean_resultant_length(KAPPA4, 4)],
    ),
    "su3": (
        lambda U: KAPPA_SU3 * jnp.real(jnp.vdot(M3, U[:, 0])),
        lambda U: jnp.real(jnp.vdot(M3, U[:, 0]))[None],
        lambda: [vmf_mean_resultant_length(KAPPA_SU3, 6)],
    ),
    "x": (  # a Gaussian on R², sd 0.5 and 2
        lambda x: -0.5 * jnp.sum((x / jnp.array([0.5, 2.0])) ** 2),
        lambda x: x**2,
        lambda: [0.25, 4.0],
    ),
}


def product_target(names):
    """``(space, logdensity, observables, exact)`` of the product of the named blocks."""
    space = {k: PRODUCT[k] for k in names}

    def logdensity(p):
        return sum(BLOCKS[k][0](p[k]) for k in names)

    def observables(p):
        return jnp.concatenate([BLOCKS[k][1](p[k]) for k in names])

    return space, logdensity, observables, np.concatenate([BLOCKS[k][2]() for k in names])


def _dispersed_starts(space, key):
    """Haar starts on the manifold blocks, ``x = 0``: one compiled draw (run eagerly, the QR
    draws of SO(n) and SU(n) compile each of their small operations on its own)."""
    batched = {k: type(v)(v.n, shape=(NUM_CHAINS,)) for k, v in space.items() if k != "x"}
    starts = dict(liesample.jit(lambda k: S.uniform(batched, k))(key))
    starts["x"] = jnp.zeros((NUM_CHAINS, 2))
    return starts


@pytest.mark.slow  # a long statistical run; default siblings: GeometricHMC's exact law through
# test_numpyro_mcmc.py's vMF posterior, the product space's by the "adjusted langevin" case of
# test_a_magnetic_field_and_a_dense_mass_on_the_euclidean_block_keep_the_exact_law, and the
# SO(3) flow by test_spaces.py::test_flow_is_reversible_and_stays_on_the_manifold
def test_hmc_on_spheres_rotations_and_r2_matches_exact_moments():
    space, logdensity, observables, exact = product_target(list(PRODUCT))
    sampler = liesample.geometric_hmc(logdensity, space, step_size=0.25, num_integration_steps=6)
    starts = _dispersed_starts(space, jax.random.key(1))
    means, acceptance = chain_means(sampler, jax.random.key(0), starts, 1000, observables)
    assert 0.6 < acceptance.mean() < 1.0
    assert_within_mcse(means, exact)


@pytest.mark.slow  # default sibling: the "adjusted langevin" case of
# test_a_magnetic_field_and_a_dense_mass_on_the_euclidean_block_keep_the_exact_law (the adjusted
# chain's exact law on S² × R²; its SO(3) blocks' in make test-slow)
def test_adjusted_langevin_matches_exact_moments():
    space, logdensity, observables, exact = product_target(["s2", "fisher", "x"])
    sampler = liesample.geometric_langevin(
        logdensity, space, step_size=0.25, friction=1.0, adjusted=True
    )
    starts = _dispersed_starts(space, jax.random.key(3))
    means, acceptance = chain_means(sampler, jax.random.key(2), starts, 3000, observables)
    assert 0.8 < acceptance.mean() < 1.0
    assert_within_mcse(means, exact)


# --------------------------------------------------------------------------- a magnetic field

FIELD_X = np.array([[0.0, 2.0], [-2.0, 0.0]])  # on the two coordinates of "x"
DENSE_X = np.array([[0.25, 0.3], [0.3, 4.0]])


@pytest.mark.parametrize(
    "which",
    [
        # default siblings of "hmc": test_magnetic_hmc_is_geometric_hmc_on_a_euclidean_space
        # (the field and a dense mass, key for key magnetic_hmc) with test_magnetic.py's exact
        # moments of magnetic_hmc under a strong field and a dense mass
        pytest.param("hmc", marks=pytest.mark.slow),
        "adjusted langevin",
    ],
)
def test_a_magnetic_field_and_a_dense_mass_on_the_euclidean_block_keep_the_exact_law(which):
    """``G`` on R² (next to S²) changes the dynamics, not the law: exact moments within 5 MCSE."""
    space, logdensity, observables, exact = product_target(["s2", "x"])
    mass = {"s2": 1.0, "x": DENSE_X}
    if which == "hmc":
        sampler = liesample.geometric_hmc(logdensity, space, 0.3, 6, mass, FIELD_X)
    else:
        sampler = liesample.geometric_langevin(
            logdensity, space, 0.3, 1.0, mass, FIELD_X, adjusted=True
        )
    starts = _dispersed_starts(space, jax.random.key(13))
    means, acceptance = chain_means(sampler, jax.random.key(14), starts, 1500, observables)
    assert 0.6 < acceptance.mean() < 1.0
    assert_within_mcse(means, exact)


def test_magnetic_hmc_is_geometric_hmc_on_a_euclidean_space():
    """Key for key the same chain: ``magnetic_hmc`` is ``geometric_hmc`` on ``Euclidean((d,))``
    with the field (dense mass, partial refreshment, the sign flips included)."""

    def banana(x):
        return -0.5 * x[0] ** 2 - 2.0 * (x[1] - x[0] ** 2) ** 2 - 0.5 * x[2] ** 2

    field = np.array([[0.0, 1.0, -2.0], [-1.0, 0.0, 0.5], [2.0, -0.5, 0.0]])
    imm = np.array([[1.0, 0.2, 0.0], [0.2, 0.5, 0.1], [0.0, 0.1, 2.0]])
    options = {"momentum_persistence": 0.5, "divergence_threshold": 50.0}
    magnetic = liesample.magnetic_hmc(banana, 0.3, imm, 5, field, **options)
    geometric = liesample.geometric_hmc(banana, S.Euclidean((3,)), 0.3, 5, imm, field, **options)
    runs = [
        blackjax.util.run_inference_algorithm(
            jax.random.key(15), sampler, num_steps=200, initial_position=jnp.zeros(3),
            transform=lambda state, info: (state.position, state.magnetic_sign, info.is_accepted),
        )[1]
        for sampler in (magnetic, geometric)
    ]  # fmt: skip
    (q1, s1, a1), (q2, s2, a2) = runs
    np.testing.assert_allclose(q1, q2, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(s1, s2)
    np.testing.assert_array_equal(a1, a2)
    assert 0 < np.mean(np.asarray(s1) > 0) < 1 and 0 < np.mean(a1) < 1


def _persistent_gaussian_run(step_size, num_steps, dimension=400, omega=8.0):
    """Geometric HMC with ``α = e^{−ε}`` and one leapfrog step per update on ``N(0, I_d/ω²)``
    (the frequency of the stiffest lattice gauge modes), started from an exact draw: per update
    ``mean(ω²q²)``, whether it was accepted and whether the position (and log-density) stayed
    bitwise the same."""
    sampler = liesample.geometric_hmc(
        lambda q: -0.5 * omega**2 * jnp.sum(q**2), S.Euclidean((dimension,)), step_size, 1,
        momentum_persistence=float(np.exp(-step_size)),
    )  # fmt: skip
    start = jax.random.normal(jax.random.key(21), (dimension,)) / omega

    def body(state, key):
        new, info = sampler.step(key, state)
        same = jnp.all(new.position == state.position) & (new.logdensity == state.logdensity)
        return new, (jnp.mean((omega * new.position) ** 2), info.is_accepted, same)

    keys = jax.random.split(jax.random.key(22), num_steps)
    return jax.jit(lambda s: jax.lax.scan(body, s, keys)[1])(sampler.init(start))


def test_persistent_momentum_starts_from_a_full_refresh_and_rejections_stay_put():
    """From an exact draw of the target, GHMC keeps the law exactly at every update, so
    ``mean(ω²q²)`` stays within a few ``√(2/d)`` of 1. The zero momentum ``init`` sets is refreshed
    fully: refreshed partially (``α = e^{−0.05}``), the first steps carry almost no kinetic
    energy and the dynamics turns the potential energy into kinetic energy (``mean(ω²q²)`` falls
    to about 0.26 within a quarter period), the quench that ordered 4-D SU(3) in the benchmark.
    Every rejected update keeps the position and log-density bitwise, every accepted one moves."""
    second_moment, accepted, same = _persistent_gaussian_run(0.05, 15)
    accepted, same = np.asarray(accepted), np.asarray(same)
    assert 0.5 < np.mean(accepted) < 1
    np.testing.assert_array_less(np.abs(np.asarray(second_moment) - 1.0), 5 * np.sqrt(2 / 400))
    assert np.all(same[~accepted]) and not np.any(same[accepted])


# --------------------------------------------------------------------------- lattice gauge

L = 4
BETA_U1, BETA_SU2 = 2.0, 2.5
LATTICE = {
    "u1": {"h": S.U1((L - 1, L)), "v": S.U1((L, L - 1))},
    "su2": {"h": S.SU(2, shape=(L - 1, L)), "v": S.SU(2, shape=(L, L - 1))},
}


def u1_plaquettes(links):
    """θ_P = θ_h(x) + θ_v(x + ê₁) − θ_h(x + ê₂) − θ_v(x) on the (L−1)² open-lattice plaquettes."""
    h, v = links["h"], links["v"]
    return h[:, :-1] + v[1:, :] - h[:, 1:] - v[:-1, :]


def su2_plaquettes(links):
    """½ tr U_h(x) U_v(x + ê₁) U_h(x + ê₂)† U_v(x)†."""
    h, v = links["h"], links["v"]
    dagger = lambda u: jnp.conj(jnp.swapaxes(u, -1, -2))
    u = h[:, :-1] @ v[1:, :] @ dagger(h[:, 1:]) @ dagger(v[:-1, :])
    return 0.5 * jnp.real(jnp.trace(u, axis1=-2, axis2=-1))


def lattice_logdensity(p):
    """−S: U(1) with S = −β Σ cos θ_P, SU(2) with S = −(β/2) Σ tr U_P (independent theories)."""
    return BETA_U1 * jnp.sum(jnp.cos(u1_plaquettes(p["u1"]))) + BETA_SU2 * jnp.sum(
        su2_plaquettes(p["su2"])
    )


@pytest.mark.slow  # a long statistical run
def test_hmc_on_2d_u1_and_su2_lattice_gauge_theories_matches_bessel_ratios():
    sampler = liesample.geometric_hmc(
        lattice_logdensity, LATTICE, step_size=0.2, num_integration_steps=8
    )
    batched = jax.tree.map(
        lambda s: type(s)(*([s.n] if hasattr(s, "n") else []), shape=(NUM_CHAINS, *s.shape)),
        LATTICE,
        is_leaf=S.is_space,
    )
    starts = jax.jit(lambda k: S.uniform(batched, k))(jax.random.key(4))

    def observables(p):
        return jnp.array(
            [jnp.mean(jnp.cos(u1_plaquettes(p["u1"]))), jnp.mean(su2_plaquettes(p["su2"]))]
        )

    means, acceptance = chain_means(sampler, jax.random.key(5), starts, 500, observables)
    assert 0.6 < acceptance.mean() < 1.0
    assert_within_mcse(means, [u1_plaquette_mean(BETA_U1), su2_plaquette_mean(BETA_SU2)])


# --------------------------------------------------------------------------- a posterior


@pytest.mark.slow  # default sibling: test_multichain_workflow.py's
# test_window_adaptation_adapts_a_batch_of_starts_and_hands_them_on (window adaptation of
# geometric HMC on S² × R², then the tuned sampler's exact law)
def test_window_adaptation_then_hmc_on_a_vmf_posterior_over_direction_and_log_concentration():
    data = vonmises_fisher(MU2, 5.0).rvs(20, random_state=np.random.default_rng(1))
    posterior = VonMisesFisherPosterior(data, prior_mean=1.0, prior_sd=1.0)
    exact = posterior.expectations()
    space = {"direction": S.Sphere(2), "log_kappa": S.Euclidean(())}
    start = {"direction": jnp.array([1.0, 0.0, 0.0]), "log_kappa": jnp.asarray(0.0)}
    warmup = window_adaptation(liesample.geometric_hmc, posterior.logdensity, space)
    (state, parameters), info = warmup.run(jax.random.key(6), start, num_steps=400)
    assert 0.6 < float(info.info.acceptance_rate[-100:].mean()) <= 1.0
    # Mass from the warm-up: the direction's precision is about κR (gradient variance + 1).
    assert parameters["inverse_mass_matrix"]["direction"].shape == (1,)
    sampler = liesample.geometric_hmc(posterior.logdensity, space, **parameters)
    starts = jax.tree.map(lambda a: jnp.broadcast_to(a, (NUM_CHAINS, *a.shape)), state.position)

    def observables(p):
        return jnp.concatenate([p["direction"], p["log_kappa"][None]])

    means, _ = chain_means(sampler, jax.random.key(7), starts, 600, observables)
    assert_within_mcse(means, np.append(exact["direction"], exact["log_kappa"]))


# --------------------------------------------------------------------------- the API


def test_blackjax_driver_info_contract_and_divergences_are_rejected():
    space = S.Sphere(2)

    def logdensity(x):  # defined on the cap x₃ > −0.2 only: NaN outside
        return jnp.where(x[2] > -0.2, 2.0 * x[2], jnp.nan)

    sampler = liesample.geometric_hmc(logdensity, space, step_size=0.7, num_integration_steps=5)
    _, (positions, infos) = blackjax.util.run_inference_algorithm(
        jax.random.key(8),
        sampler,
        num_steps=300,
        initial_position=jnp.array([0.0, 0.0, 1.0]),
        transform=lambda state, info: (state.position, info),
    )
    assert set(liesample.samplers.cotangent._core.GeometricInfo._fields) >= {
        "acceptance_rate",
        "is_divergent",
        "energy",
    }
    assert np.all(np.isfinite(positions)) and np.all(positions[:, 2] > -0.2)
    divergent = np.asarray(infos.is_divergent)
    assert divergent.any() and not divergent.all()
    assert np.all(np.asarray(infos.acceptance_rate)[divergent] == 0.0)
    assert np.all(~np.asarray(infos.is_accepted)[divergent])
    # Unadjusted Langevin: acceptance_rate is 1 for a step taken, 0 for a rejected one.
    langevin = liesample.geometric_langevin(logdensity, space, step_size=0.7, friction=0.2)
    _, infos = blackjax.util.run_inference_algorithm(
        jax.random.key(9),
        langevin,
        num_steps=300,
        initial_position=jnp.array([0.0, 0.0, 1.0]),
        transform=lambda state, info: info,
    )
    rate = np.asarray(infos.acceptance_rate)
    assert set(np.unique(rate)) <= {0.0, 1.0} and np.all((rate == 0) == infos.is_divergent)
    assert np.all(np.isfinite(infos.energy))


@pytest.mark.slow  # three long chains (~30 s); default sibling: test_schemes.py runs the
# unadjusted chain on S² against exact moments at one step size
def test_unadjusted_langevin_bias_is_second_order_in_the_step():
    """The kinetic Langevin chain's error on E[μ·x] (vMF, S²) is ``c h² + d h⁴ + …``: no h term.

    O B A B (exact O steps, a leapfrog B A B) has the position law of the symmetric splitting
    O/2 B A B O/2, whose stationary error expands in even powers of h. A check of
    ``e(h/2) = e(h)/4`` alone ignores the h⁴ term, a few MCSE at h = 0.4; instead
    ``e(h) = a h + c h² + d h⁴`` is solved through h = 0.4, 0.2, 0.1 and ``a`` must be 0 within
    5 MCSE, with an MCSE small enough to see a first-order term carrying half of ``e(0.4)``.
    """
    space = S.Sphere(2)
    logdensity = lambda x: KAPPA2 * jnp.dot(MU2, x)
    exact = vmf_mean_resultant_length(KAPPA2, 3)
    starts = S.Sphere(2, shape=(64,)).uniform(jax.random.key(10))
    steps = np.array([0.4, 0.2, 0.1])
    errors = []  # (step sizes, chains)
    for h in steps:
        sampler = liesample.geometric_langevin(logdensity, space, step_size=h, friction=1.0)
        means, _ = chain_means(
            sampler,
            jax.random.key(11),
            starts,
            round(16000 / h),
            lambda x: jnp.dot(MU2, x)[None],
            burn_in=500,
        )
        errors.append(means[:, 0] - exact)
    errors = np.stack(errors)
    # Each chain's (a, c, d): chain i uses the same key at every h, so the MCSE of the fit is
    # taken from the spread of the per-chain fits, which carries their correlation.
    design = np.stack([steps, steps**2, steps**4], axis=1)
    per_chain = np.linalg.solve(design, errors)
    coefficients = per_chain.mean(1)
    mcse = per_chain.std(1, ddof=1) / np.sqrt(per_chain.shape[1])
    e1, s1 = errors[0].mean(), errors[0].std(ddof=1) / np.sqrt(errors.shape[1])
    assert abs(e1) > 5 * s1  # the bias at h = 0.4 is resolved
    assert 5 * mcse[0] < 0.5 * abs(e1) / steps[0], mcse  # a first-order term would show
    assert abs(coefficients[0]) < 5 * mcse[0], (coefficients, mcse)  # and there is none


@pytest.mark.slow
def test_window_adaptation_on_an_8x8_su2_lattice_matches_the_bessel_ratio():
    """112 SU(2) links (336 dimensions), tuned by window adaptation from a Haar start."""
    size, beta = 8, 2.5
    space = {"h": S.SU(2, shape=(size - 1, size)), "v": S.SU(2, shape=(size, size - 1))}

    def logdensity(links):
        return beta * jnp.sum(su2_plaquettes(links))

    start = S.uniform(space, jax.random.key(12))
    warmup = window_adaptation(liesample.geometric_hmc, logdensity, space)
    (state, parameters), _ = warmup.run(jax.random.key(13), start, num_steps=500)
    sampler = liesample.geometric_hmc(logdensity, space, **parameters)
    starts = jax.tree.map(lambda a: jnp.broadcast_to(a, (NUM_CHAINS, *a.shape)), state.position)
    means, acceptance = chain_means(
        sampler, jax.random.key(14), starts, 1000, lambda p: jnp.mean(su2_plaquettes(p))[None]
    )
    assert 0.6 < acceptance.mean() <= 1.0
    assert_within_mcse(means, [su2_plaquette_mean(beta)])


def test_window_adaptation_refuses_bad_parameters():
    space = S.Sphere(2)

    def logdensity(x):
        return x[2]

    with pytest.raises(TypeError, match="initial_step_size"):
        window_adaptation(liesample.geometric_hmc, logdensity, space, step_size=0.1)
    with pytest.raises(ValueError, match="not both"):
        window_adaptation(
            liesample.geometric_hmc,
            logdensity,
            space,
            num_integration_steps=3,
            integration_time=1.0,
        )
    with pytest.raises(ValueError, match="HMC parameters"):
        window_adaptation(liesample.geometric_langevin, logdensity, space, integration_time=1.0)
    with pytest.raises(TypeError, match="unknown parameters"):
        window_adaptation(liesample.geometric_hmc, logdensity, space, friction=1.0)
    with pytest.raises(ValueError, match="target_acceptance_rate"):
        window_adaptation(liesample.geometric_hmc, logdensity, space, target_acceptance_rate=1.5)
    with pytest.raises(ValueError, match="num_steps"):
        window_adaptation(liesample.geometric_hmc, logdensity, space).run(
            jax.random.key(0), jnp.array([0.0, 0.0, 1.0]), num_steps=5
        )


@pytest.mark.slow
def test_window_adaptation_of_adjusted_langevin_on_the_vmf_posterior():
    data = vonmises_fisher(MU2, 5.0).rvs(20, random_state=np.random.default_rng(1))
    posterior = VonMisesFisherPosterior(data, prior_mean=1.0, prior_sd=1.0)
    exact = posterior.expectations()
    space = {"direction": S.Sphere(2), "log_kappa": S.Euclidean(())}
    start = {"direction": jnp.array([1.0, 0.0, 0.0]), "log_kappa": jnp.asarray(0.0)}
    warmup = window_adaptation(
        liesample.geometric_langevin, posterior.logdensity, space, adjusted=True, friction=0.5
    )
    (state, parameters), _ = warmup.run(jax.random.key(15), start, num_steps=600)
    assert parameters["adjusted"] is True and parameters["friction"] == 0.5
    sampler = liesample.geometric_langevin(posterior.logdensity, space, **parameters)
    starts = jax.tree.map(lambda a: jnp.broadcast_to(a, (NUM_CHAINS, *a.shape)), state.position)

    def observables(p):
        return jnp.concatenate([p["direction"], p["log_kappa"][None]])

    means, acceptance = chain_means(sampler, jax.random.key(16), starts, 4000, observables)
    assert 0.8 < acceptance.mean() <= 1.0
    assert_within_mcse(means, np.append(exact["direction"], exact["log_kappa"]))
