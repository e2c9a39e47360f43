"""The integration scheme is a parameter: a scheme written here, as coefficient lists only, runs
through every sampler on ``T*G`` and the NumPyro kernel and keeps the exact law; so does every
named scheme of :data:`liesample.geometry.cotangent.SCHEMES`. Fixed keys, exact references,
tolerances of 5 Monte Carlo standard errors (between independent chains)."""

import blackjax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import spaces as S
from liesample.geometry.cotangent import SCHEMES, gradient_evaluations
from liesample.targets.groups import vmf_mean_resultant_length

# A palindromic scheme that starts and ends with a drift (not shipped): each kick follows a
# drift, and the gradient is evaluated at the end of every step, three evaluations per step.
DRIFT_FIRST = (("A", 0.25), ("B", 0.5), ("A", 0.5), ("B", 0.5), ("A", 0.25))
# A Langevin splitting (A B O B A, Leimkuhler & Matthews' ABOBA) and, for the adjusted
# sampler, uneven OU steps around the scheme above.
ABOBA = (("A", 0.5), ("B", 0.5), ("O", 1.0), ("B", 0.5), ("A", 0.5))
UNEVEN_REFRESH = (("O", 0.25), *DRIFT_FIRST, ("O", 0.75))

CHAINS, DRAWS, BURN_IN = 16, 1000, 100
KAPPA, MEAN_DIRECTION = 3.0, np.array([0.0, 0.6, 0.8])
VARIANCES = np.array([1.0, 4.0])
FIELD = jnp.array([[0.0, 0.8], [-0.8, 0.0]])


def product_logdensity(p):
    """vMF(κ, μ) on S² times N(0, diag(VARIANCES)) on R², independent."""
    return KAPPA * p["s"] @ MEAN_DIRECTION - 0.5 * jnp.sum(p["x"] ** 2 / VARIANCES)


def gaussian_logdensity(x):
    return -0.5 * jnp.sum(x**2 / VARIANCES)


PRODUCT = {"s": S.Sphere(2), "x": S.Euclidean((2,))}
PRODUCT_START = {"s": jnp.array([0.0, 0.0, 1.0]), "x": jnp.zeros(2)}
# E[s], E[x], E[x²]
PRODUCT_EXACT = np.concatenate(
    [vmf_mean_resultant_length(KAPPA, 3) * MEAN_DIRECTION, np.zeros(2), VARIANCES]
)
GAUSSIAN_EXACT = np.concatenate([np.zeros(2), VARIANCES])


def product_observables(p):
    return jnp.concatenate([p["s"], p["x"], p["x"] ** 2])


def gaussian_observables(x):
    return jnp.concatenate([x, x**2])


def chain_means(sampler, start, observables, key):
    """Per-chain means of ``observables`` after a burn-in, and the gradients of every step."""

    def run(key):
        state = sampler.init(start)

        def body(carry, xs):
            state, total = carry
            key, keep = xs
            state, info = sampler.step(key, state)
            total = total + keep * observables(state.position)
            return (state, total), info.num_gradient_evaluations

        keys = jax.random.split(key, BURN_IN + DRAWS)
        keep = jnp.arange(BURN_IN + DRAWS) >= BURN_IN
        (_, total), cost = jax.lax.scan(body, (state, 0.0 * observables(start)), (keys, keep))
        return total / DRAWS, cost

    means, cost = liesample.jit(jax.vmap(run))(jax.random.split(jax.random.key(key), CHAINS))
    return np.asarray(means), np.asarray(cost)


def assert_exact(means, exact, factor=5.0):
    mcse = means.std(0, ddof=1) / np.sqrt(means.shape[0])
    z = (means.mean(0) - exact) / mcse
    assert np.all(np.abs(z) < factor), (means.mean(0), exact, z)


SAMPLERS = {
    "geometric_hmc": lambda scheme: (
        liesample.geometric_hmc(product_logdensity, PRODUCT, 0.3, 4, integrator=scheme),
        4,
    ),
    "geometric_langevin_adjusted": lambda scheme: (
        liesample.geometric_langevin(
            product_logdensity, PRODUCT, 0.3, 1.0, adjusted=True, integrator=scheme
        ),
        1,
    ),
    "geometric_langevin": lambda scheme: (
        liesample.geometric_langevin(product_logdensity, PRODUCT, 0.1, 1.0, integrator=scheme),
        1,
    ),
    "magnetic_hmc": lambda scheme: (
        liesample.magnetic_hmc(gaussian_logdensity, 0.4, jnp.ones(2), 4, FIELD, integrator=scheme),
        4,
    ),
    "jittered_magnetic_hmc": lambda scheme: (
        liesample.jittered_magnetic_hmc(
            gaussian_logdensity, 0.4, jnp.ones(2), 4, FIELD, integrator=scheme
        ),
        None,
    ),
    "magnetic_langevin": lambda scheme: (
        liesample.magnetic_langevin(
            gaussian_logdensity, 0.1, jnp.ones(2), 1.0, FIELD, integrator=scheme
        ),
        1,
    ),
}
ON_PRODUCT = {"geometric_hmc", "geometric_langevin", "geometric_langevin_adjusted"}
SLOW = pytest.mark.slow
CASES = [
    # The scheme written here, through every sampler (the magnetic ones with a field); by
    # default through one HMC and one Langevin sampler of each family, the rest in test-slow.
    pytest.param("geometric_hmc", DRIFT_FIRST),
    pytest.param("geometric_langevin_adjusted", UNEVEN_REFRESH),
    pytest.param("geometric_langevin", ABOBA, marks=SLOW),
    pytest.param("magnetic_hmc", DRIFT_FIRST, marks=SLOW),
    pytest.param("jittered_magnetic_hmc", DRIFT_FIRST, marks=SLOW),
    pytest.param("magnetic_langevin", ABOBA),
    # Every named scheme (the magnetic samplers are geometric ones on R^d; the leapfrog, every
    # HMC sampler's default, is checked by their own tests, BAOAB by magnetic Langevin's).
    pytest.param("magnetic_hmc", "minimal_norm"),
    pytest.param("magnetic_langevin", "baoab", marks=SLOW),
    pytest.param("magnetic_langevin", "obabo"),
    pytest.param("magnetic_langevin", "obab", marks=SLOW),
]


@pytest.mark.parametrize(
    ("sampler", "scheme"), CASES, ids=[f"{c.values[0]}-{c.values[1]}"[:40] for c in CASES]
)
def test_scheme_keeps_the_exact_law_and_counts_its_gradients(sampler, scheme):
    built, steps = SAMPLERS[sampler](scheme)
    if sampler in ON_PRODUCT:
        means, cost = chain_means(built, PRODUCT_START, product_observables, 1)
        assert_exact(means, PRODUCT_EXACT)
    else:
        means, cost = chain_means(built, jnp.array([0.5, -0.5]), gaussian_observables, 2)
        assert_exact(means, GAUSSIAN_EXACT)
    per_step = gradient_evaluations(SCHEMES.get(scheme, scheme))
    if steps is None:  # jittered length
        assert np.all(cost % per_step == 0) and np.all(cost <= 4 * per_step)
        assert len(np.unique(cost)) > 1
    else:
        np.testing.assert_array_equal(cost, steps * per_step)


def test_gradient_evaluations_follow_the_scheme():
    counts = {name: gradient_evaluations(scheme) for name, scheme in SCHEMES.items()}
    assert counts == {"leapfrog": 1, "minimal_norm": 2, "baoab": 1, "obabo": 1, "obab": 1}
    assert gradient_evaluations(DRIFT_FIRST) == 3  # two kicks after drifts, then the end
    assert gradient_evaluations(ABOBA) == 2  # after the first drift, and at the end of the step


def test_magnetic_hmc_is_geometric_hmc_on_rd_for_any_scheme():
    """The front adds nothing: same keys, same draws, for a scheme written here."""
    magnetic = liesample.magnetic_hmc(
        gaussian_logdensity, 0.4, jnp.ones(2), 3, FIELD, integrator=DRIFT_FIRST
    )
    geometric = liesample.geometric_hmc(
        gaussian_logdensity, S.Euclidean((2,)), 0.4, 3, magnetic_field=FIELD,
        integrator=DRIFT_FIRST,
    )  # fmt: skip
    start = jnp.array([0.5, -0.5])

    @liesample.jit
    def draws(keys):
        def run(sampler):
            def step(state, key):
                state = sampler.step(key, state)[0]
                return state, state.position

            return jax.lax.scan(step, sampler.init(start), keys)[1]

        return run(magnetic), run(geometric)

    np.testing.assert_array_equal(*draws(jax.random.split(jax.random.key(3), 5)))


def test_blackjax_mclachlan_is_the_minimal_norm_scheme():
    draws = []
    for integrator in (blackjax.mcmc.integrators.mclachlan, "minimal_norm"):
        sampler = liesample.magnetic_hmc(
            gaussian_logdensity, 0.4, jnp.ones(2), 3, FIELD, integrator=integrator
        )
        state = sampler.init(jnp.array([0.5, -0.5]))
        draws.append(sampler.step(jax.random.key(4), state)[0].position)
    np.testing.assert_array_equal(*draws)


def test_numpyro_kernel_runs_a_scheme_written_here():
    numpyro = pytest.importorskip("numpyro")
    from numpyro.infer import MCMC

    from liesample.interop.numpyro_distributions import VonMisesFisher
    from liesample.interop.numpyro_kernel import GeometricHMC

    def model():
        numpyro.sample("s", VonMisesFisher(jnp.asarray(MEAN_DIRECTION), KAPPA))

    mcmc = MCMC(
        GeometricHMC(model, integrator=DRIFT_FIRST, num_integration_steps=4),
        num_warmup=100,
        num_samples=1000,
        num_chains=8,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(5))
    draws = np.asarray(mcmc.get_samples(group_by_chain=True)["s"])
    assert_exact(draws.mean(1), vmf_mean_resultant_length(KAPPA, 3) * MEAN_DIRECTION)


def test_warmup_passes_the_scheme_through():
    space = S.Euclidean((2,))
    warmup = liesample.window_adaptation(
        liesample.geometric_hmc, gaussian_logdensity, space, integrator="minimal_norm"
    )
    (_, parameters), info = warmup.run(jax.random.key(6), jnp.zeros(2), num_steps=20)
    assert parameters["integrator"] == "minimal_norm"
    np.testing.assert_array_equal(
        info.info.num_gradient_evaluations, 2 * info.info.num_integration_steps
    )
    assert (
        liesample.geometric_hmc(gaussian_logdensity, space, **parameters).settings["integrator"]
        == "minimal_norm"
    )


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: liesample.geometric_hmc(gaussian_logdensity, S.Euclidean((2,)), 0.1, 3,
                                         integrator="verlet"), "unknown name 'verlet'"),
        (lambda: liesample.geometric_hmc(gaussian_logdensity, S.Euclidean((2,)), 0.1, 3,
                                         integrator=(("B", 0.5), ("A", 1.0))), "fractions of 'B'"),
        (lambda: liesample.magnetic_hmc(gaussian_logdensity, 0.1, jnp.ones(2), 3, FIELD,
                                        integrator=(("B", 0.3), ("A", 1.0), ("B", 0.7))),
         "palindromic"),
        (lambda: liesample.magnetic_hmc(gaussian_logdensity, 0.1, jnp.ones(2), 3, FIELD,
                                        integrator="baoab"), "only use the effects"),
        (lambda: liesample.geometric_langevin(gaussian_logdensity, S.Euclidean((2,)), 0.1, 1.0,
                                              integrator="leapfrog"), "lacks"),
        (lambda: liesample.geometric_langevin(gaussian_logdensity, S.Euclidean((2,)), 0.1, 1.0,
                                              adjusted=True, integrator="baoab"), "at the ends"),
        (lambda: liesample.magnetic_langevin(gaussian_logdensity, 0.1, jnp.ones(2), 1.0, FIELD,
                                             integrator=(("O", -1.0),)), "finite and > 0"),
        (lambda: liesample.geometric_hmc.build_kernel(integrator=3), "tuple of"),
    ],
)  # fmt: skip
def test_bad_schemes_are_refused_when_built(build, message):
    with pytest.raises(ValueError, match=message):
        build()
