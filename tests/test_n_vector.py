"""O(n) spin lattices (``systems.n_vector``) and their exact open-chain references.

References, written independently of the samplers:

- the bond law of the open chain without field: the bond cosines are i.i.d. with density
  ``∝ exp(K c)(1 − c²)^{(n−3)/2}`` on ``[−1, 1]``, ``K = βJ`` (module docstring of
  ``liesample.targets.n_vector``), so ``E[s_x·s_{x+r}] = uʳ`` with ``u = E[c]`` and the energy
  per bond is ``−J u``. The Bessel-ratio formula for ``u`` is checked here against direct
  quadrature of that density;
- the von Mises–Fisher law on ``S^{n−1}``: its mean cosine is the same ``u`` (one bond of a
  two-site chain), its variance ``Var(c)``, and the part orthogonal to the mean is isotropic.

Errors of the chain averages are Monte Carlo standard errors (ArviZ's ``mcse`` of the mean,
from the effective sample size of 4 chains); keys are fixed.
"""

import math

import arviz_stats
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import liesample
from liesample.systems import heisenberg, n_vector
from liesample.targets import (
    NVectorChainReference,
    NVectorRingReference,
    langevin_function,
    n_vector_bond_mean,
)
from liesample.targets.n_vector import n_vector_bond_variance, von_mises_fisher_sphere
from liesample.targets.spins import HeisenbergRingReference

Z_MAX = 4.5
BETA = 2.0
LENGTH = 16
CHAINS = 4


def quadrature_bond_moments(n, k):
    """``(E[c], Var c)`` of the density ``∝ exp(K c)(1 − c²)^{(n−3)/2}`` by quadrature."""

    def moment(p):
        exponent = (n - 3) / 2  # (1 − c)^a (1 + c)^a: scipy's algebraic end-point weight
        return integrate.quad(
            lambda c: c**p * np.exp(k * (c - 1.0)), -1, 1, weight="alg", wvar=(exponent, exponent)
        )[0]

    z = moment(0)
    mean = moment(1) / z
    return mean, moment(2) / z - mean**2


# ---------------------------------------------------------------------------------------------
# References
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3, 4, 5])
@pytest.mark.parametrize("k", [-1.5, 1e-6, 0.3, 2.0, 40.0])
def test_bessel_ratio_is_the_mean_bond_of_the_chain(n, k):
    mean, variance = quadrature_bond_moments(n, k)
    assert n_vector_bond_mean(n, beta=k) == pytest.approx(mean, rel=1e-9, abs=1e-12)
    assert n_vector_bond_variance(n, beta=k) == pytest.approx(variance, rel=1e-7)


def test_n3_reference_is_the_heisenberg_chain():
    assert n_vector_bond_mean(3, beta=1.7) == pytest.approx(float(langevin_function(1.7)), 1e-14)
    reference = NVectorChainReference(length=5, n=3, beta=1.7, coupling=0.5)
    heisenberg_reference = heisenberg((5,), coupling=0.5).reference(1.7)
    assert reference.energy_mean() == pytest.approx(heisenberg_reference.energy_mean(), 1e-14)
    assert reference.energy_variance() == pytest.approx(
        heisenberg_reference.energy_variance(), 1e-6
    )


@pytest.mark.parametrize(
    "n",
    [
        # slow: S¹'s draws are checked in the default suite through the O(2) chain's law
        # (test_recommended_sampler_samples_the_exact_open_chain[2])
        pytest.param(2, marks=pytest.mark.slow),
        5,
    ],
)
def test_von_mises_fisher_on_every_sphere(n):
    """Mean cosine and variance to the mean, isotropy orthogonal to it, unit norms, for
    ``κ < 0``, ``κ = 0`` with a zero direction (uniform) and ``κ > 0``, on ``S¹`` and ``S⁴``."""
    num = 5_000
    mean = np.zeros(n)
    mean[0], mean[-1] = 0.6, 0.8
    kappas = np.repeat([-3.0, 0.0, 0.7, 25.0], num)
    directions = np.tile(mean, (kappas.size, 1))
    directions[num : 2 * num] = 0.0  # F = 0: the uniform law whatever the direction
    draws = np.asarray(
        liesample.jit(von_mises_fisher_sphere)(jax.random.key(n), directions, kappas)
    )
    np.testing.assert_allclose(np.linalg.norm(draws, axis=-1), 1.0, atol=1e-5)
    for block, kappa in enumerate((-3.0, 0.0, 0.7, 25.0)):
        s = draws[block * num : (block + 1) * num]
        axis = mean if kappa != 0.0 else np.eye(n)[-1]
        c = s @ axis
        u, var = n_vector_bond_mean(n, kappa), n_vector_bond_variance(n, kappa)
        assert abs(c.mean() - u) < Z_MAX * math.sqrt(var / num), (n, kappa)
        # orthogonal part: isotropic, each of the n − 1 directions (1 − E[c²])/(n − 1)
        other = np.linalg.svd(np.eye(n) - np.outer(axis, axis))[0][:, : n - 1]
        second = np.mean((s @ other) ** 2, axis=0)
        expected = (1.0 - var - u**2) / (n - 1)
        np.testing.assert_allclose(second, expected, atol=Z_MAX * expected / math.sqrt(num / 3))


# ---------------------------------------------------------------------------------------------
# The system
# ---------------------------------------------------------------------------------------------


def test_n3_is_heisenberg():
    for arguments in [((8,),), ((4, 4), 3, -0.5, True, (0.0, 0.1, 0.2))]:
        shape, rest = arguments[0], arguments[2:]
        system = n_vector(shape, 3, *rest)
        assert system == heisenberg(shape, *rest)
        assert hash(system) == hash(heisenberg(shape, *rest))


def test_equal_arguments_give_equal_systems():
    a, b = n_vector((6, 6), n=2, periodic=True), n_vector((6, 6), n=2, periodic=True)
    assert a == b and hash(a) == hash(b)
    assert a != n_vector((6, 6), n=4, periodic=True)
    assert a.event_shape == (6, 6, 2) and a.name == "O(2) square lattice 6x6"


def test_energy_of_aligned_and_random_spins():
    system = n_vector((3, 4), n=4, coupling=0.7, periodic=True, field=(0.0, 0.5, 0.0, -1.0))
    # all along e_4: −J per bond (2 per site on the torus), −h·e_4 = +1 per site
    assert float(system.hamiltonian(system.default_position)) == pytest.approx(-0.7 * 24 + 12)
    s = np.random.default_rng(0).normal(size=(3, 4, 4))
    s /= np.linalg.norm(s, axis=-1, keepdims=True)
    bonds = sum(np.sum(s * np.roll(s, -1, axis=a)) for a in range(2))
    expected = -0.7 * bonds - np.sum(s @ np.array([0.0, 0.5, 0.0, -1.0]))
    assert float(system.hamiltonian(jnp.asarray(s))) == pytest.approx(expected, rel=1e-5)


def test_reference_only_where_exact():
    assert isinstance(n_vector((8,), 2).reference(1.0), NVectorChainReference)
    assert n_vector((8,), 2, field=(0.0, 0.1)).reference(1.0) is None
    assert n_vector((8,), 2, periodic=True, field=(0.0, 0.1)).reference(1.0) is None
    assert n_vector((4, 4), 2).reference(1.0) is None
    assert n_vector((4, 4), 2, periodic=True).reference(1.0) is None


@pytest.mark.parametrize("n", [2, 4, 5])
def test_periodic_chain_reference_is_the_ring(n):
    ring = n_vector((8,), n, coupling=-0.6, periodic=True).reference(1.5)
    assert ring == NVectorRingReference(length=8, n=n, beta=1.5, coupling=-0.6)


def test_periodic_heisenberg_chain_reference_is_the_o3_ring():
    """``n = 3`` is ``heisenberg``'s ring reference, the same law as the O(3) ring."""
    ring = n_vector((7,), 3, coupling=0.8, periodic=True).reference(2.0)
    assert ring == HeisenbergRingReference(length=7, beta=2.0, coupling=0.8)
    o3 = NVectorRingReference(length=7, n=3, beta=2.0, coupling=0.8)
    r = np.arange(8)
    np.testing.assert_allclose(ring.correlation(r), o3.correlation(r), rtol=1e-12)
    assert ring.energy_mean() == pytest.approx(o3.energy_mean(), rel=1e-12)


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (lambda: n_vector((4,), 1), ValueError, "n must be an int >= 2"),
        (lambda: n_vector((4,), 2.0), TypeError, "n must be an int >= 2"),
        (lambda: n_vector((4,), True), TypeError, "n must be an int >= 2"),
        (lambda: n_vector((4,), "2"), TypeError, "n must be an int >= 2"),
        (lambda: n_vector(4, 2), TypeError, "shape must be a tuple"),
        (lambda: n_vector((0,), 2), ValueError, "shape entries must be positive"),
        (lambda: n_vector((4,), 2, coupling=math.inf), ValueError, "coupling"),
        (lambda: n_vector((4,), 2, periodic=1), TypeError, "periodic must be a bool"),
        (lambda: n_vector((2,), 2, periodic=True), ValueError, "extent of shape to be >= 3"),
        (
            lambda: n_vector((4,), 2, field=(0.0, 0.0, 1.0)),
            ValueError,
            "field must be a sequence of 2",
        ),
        (lambda: n_vector((4,), 4, field=(0.0, np.nan, 0.0, 0.0)), ValueError, r"field\[1\]"),
        (lambda: n_vector((4,), 3, field=(1.0, 0.0)), ValueError, "field must be a sequence of 3"),
        (lambda: n_vector((4,), 2).check_position(np.ones((4, 3))), ValueError, r"shape \(4, 2\)"),
        (lambda: n_vector((4,), 2).check_position(np.ones((4, 2))), ValueError, "unit spins"),
        (
            lambda: liesample.heisenberg_heat_bath(
                n_vector((4,), 2), beta=1.0, precession_angle=1.0
            ),
            ValueError,
            "precession_angle must be math.pi for an O\\(2\\) system",
        ),
        (
            lambda: liesample.heisenberg_cluster(n_vector((4,), 4, coupling=-1.0), beta=1.0),
            ValueError,
            "coupling J = -1",
        ),
        (
            lambda: liesample.lie_poisson_langevin(n_vector((4,), 2), beta=1.0),
            TypeError,
            "LiePoissonSystem",
        ),
        (lambda: NVectorChainReference(length=0, n=2, beta=1.0), ValueError, "length"),
        (lambda: NVectorChainReference(length=4, n=1, beta=1.0), ValueError, "n must"),
        (
            lambda: NVectorChainReference(length=4, n=2, beta=1.0).correlation(4),
            ValueError,
            "r must",
        ),
        (lambda: n_vector_bond_mean(2, beta=math.nan), ValueError, "beta"),
    ],
)
def test_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()


def test_recommended_sampler_by_n():
    assert liesample.recommended_sampler(n_vector((8,), 2), beta=1.0).settings["sampler"] == (
        "heisenberg_heat_bath"
    )
    big = n_vector((32, 32, 32), 4, periodic=True)  # O(4): β below its cluster window
    assert liesample.recommended_sampler(big, beta=0.7).settings["sampler"] == (
        "heisenberg_heat_bath"
    )
    big3 = n_vector((32, 32, 32), 3, periodic=True)  # O(3): today's measured choice
    assert liesample.recommended_sampler(big3, beta=0.7).settings["sampler"] == (
        "heisenberg_cluster"
    )


@pytest.mark.parametrize("n", [pytest.param(2, marks=pytest.mark.slow), 3])
def test_a_spin_without_local_field_is_redrawn_on_the_sphere(n):
    """A site without neighbours or field (``F = 0``) is redrawn uniformly, as a unit vector
    (on ``S²`` the closed-form draw once returned ``|s| < 1`` there; slow for ``S¹``, whose
    zero-direction draw is checked by test_von_mises_fisher_on_every_sphere)."""
    system = n_vector((1,), n)
    sampler = liesample.heisenberg_heat_bath(system, beta=1.0, overrelaxation=0)
    keys = jax.random.split(jax.random.key(n), 2000)
    state = sampler.init(system.default_position)
    draws = np.asarray(liesample.jit(jax.vmap(lambda k: sampler.step(k, state)[0].position))(keys))
    np.testing.assert_allclose(np.linalg.norm(draws, axis=-1), 1.0, atol=1e-5)
    assert np.all(np.abs(draws.mean(axis=(0, 1))) < Z_MAX / math.sqrt(n * draws.shape[0]))


# ---------------------------------------------------------------------------------------------
# Open chains against the exact law
# ---------------------------------------------------------------------------------------------


def chain_observables(s):
    """``(mean s_x·s_{x+1}, mean s_x·s_{x+2})`` over the pairs of one open chain."""
    return jnp.stack([jnp.mean(jnp.sum(s[:-r] * s[r:], -1)) for r in (1, 2)])


def chain_series(algorithm, starts, num_warmup, num_steps, seed):
    """Per step and chain after ``num_warmup`` steps: the two correlations and the energy per
    bond, ``(chains, steps, 3)``; chain ``c`` uses ``split(key(seed), chains)[c]``, step ``s``
    ``fold_in(key_c, s)``. One scan over all steps (the step compiles once)."""

    def chain(key, position):
        def body(state, step):
            state, info = algorithm.step(jax.random.fold_in(key, step), state)
            bond_energy = info.energy / (LENGTH - 1)
            return state, jnp.append(chain_observables(state.position), bond_energy)

        steps = jnp.arange(num_warmup + num_steps)
        return jax.lax.scan(body, algorithm.init(position), steps)[1][num_warmup:]

    keys = jax.random.split(jax.random.key(seed), starts.shape[0])
    return np.asarray(liesample.jit(jax.vmap(chain))(keys, jnp.asarray(starts)), dtype=float)


def random_spins(n, seed):
    x = np.random.default_rng(seed).normal(size=(CHAINS, LENGTH, n))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def assert_exact_chain_law(series, n):
    """Within ``Z_MAX`` MCSEs of ``(u, u², −J u)`` and more than ``Z_MAX`` MCSEs from the law at
    ``1.25 β`` (a sampler of the wrong temperature is caught)."""
    exact, wrong = (NVectorChainReference(LENGTH, n, beta) for beta in (BETA, 1.25 * BETA))
    estimate = series.mean(axis=(0, 1))
    mcse = np.array([float(arviz_stats.mcse(series[..., i], method="mean")) for i in range(3)])
    for reference, inside in ((exact, True), (wrong, False)):
        target = np.append(reference.correlation([1, 2]), reference.bond_energy_mean())
        z = (estimate - target) / mcse
        assert np.all(np.abs(z) < Z_MAX) == inside, (n, inside, estimate, target, z)


@pytest.mark.parametrize("n", [2, 4])
def test_recommended_sampler_samples_the_exact_open_chain(n):
    system = n_vector((LENGTH,), n)
    sampler = liesample.recommended_sampler(system, beta=BETA)
    assert sampler.settings["sampler"] == "heisenberg_heat_bath"
    series = chain_series(sampler, random_spins(n, n), 50, 1000, 10 + n)
    assert_exact_chain_law(series, n)


@pytest.mark.slow
@pytest.mark.parametrize("n", [2, 4])
@pytest.mark.parametrize(
    "sampler",
    [
        pytest.param(
            lambda system: liesample.heisenberg_heat_bath(system, beta=BETA, overrelaxation=0),
            id="heat bath",
        ),
        pytest.param(
            lambda system: liesample.heisenberg_cluster(system, beta=BETA), id="swendsen-wang"
        ),
        pytest.param(
            lambda system: liesample.heisenberg_metropolis(
                system, beta=BETA, proposal="rotation", proposal_scale=0.8
            ),
            id="metropolis",
        ),
    ],
)
def test_every_spin_sampler_samples_the_exact_open_chain(sampler, n):
    system = n_vector((LENGTH,), n)
    series = chain_series(sampler(system), random_spins(n, 20 + n), 200, 3000, 30 + n)
    assert_exact_chain_law(series, n)


@pytest.mark.slow
@pytest.mark.parametrize("n", [2, 4])
def test_wolff_samples_the_exact_open_chain(n):
    system = n_vector((LENGTH,), n)
    algorithm = liesample.heisenberg_wolff(system, beta=BETA)
    series = chain_series(algorithm, random_spins(n, 40 + n), 500, 8000, 50 + n)
    assert_exact_chain_law(series, n)


# The chain without field turns as a whole slowly (a zero mode), so single spin components
# mix slowly and the run's convergence checks say so; the law tested is of rotation-invariant
# observables, which mix fast.
@pytest.mark.filterwarnings("ignore:convergence checks:UserWarning")
@pytest.mark.parametrize("n", [2, 4])
def test_geometric_hmc_on_the_product_of_spheres_samples_the_exact_open_chain(n):
    """The T*G path: ``geometric_hmc(system.logdensity(β), system.space)`` through
    ``liesample.sample`` (its window warm-up tunes the step), on the O(n) open chain."""
    system = n_vector((LENGTH,), n)
    sampler = liesample.geometric_hmc(system.logdensity(BETA), system.space)
    tree = liesample.sample(
        sampler, jax.random.key(60 + n), random_spins(n, 60 + n), 1000, progress_bar=False
    )
    spins = jnp.asarray(tree.posterior["mu"].values)  # (chains, draws, sites, n)
    correlations = jax.vmap(jax.vmap(chain_observables))(spins)
    energy = jax.vmap(jax.vmap(system.hamiltonian))(spins) / (LENGTH - 1)
    series = np.concatenate([np.asarray(correlations), np.asarray(energy)[..., None]], -1)
    assert_exact_chain_law(series, n)


def test_spin_lattices_offer_the_product_of_spheres():
    """``space`` and ``logdensity`` of an O(n) and an O(3) lattice: one sphere per site, −βh."""
    for system in (n_vector((3, 4), 2, periodic=True), liesample.systems.heisenberg((3, 4))):
        n = system.default_position.shape[-1]
        assert system.space == liesample.spaces.Sphere(n - 1, shape=(3, 4))
        spins = random_spins(n, 1)[0, :12].reshape(3, 4, n)
        value = system.logdensity(0.7)(jnp.asarray(spins))
        np.testing.assert_allclose(value, -0.7 * system.hamiltonian(jnp.asarray(spins)))
    with pytest.raises(ValueError, match="beta"):
        n_vector((4,), 2).logdensity(float("nan"))
