"""CP(N−1) lattices (``systems.cp_model``), their heat bath and the geometric charge.

References, written independently of the samplers:

- the bond law of the open chain: ``t = |z_x^† z_{x+1}|²`` are i.i.d. with density
  ``∝ (1 − t)^{N−2} e^{Kt}`` on ``[0, 1]``, ``K = βJ``; its moments are checked here against
  the confluent hypergeometric closed form ``E[tᵖ] ∝ d^p/dK^p ₁F₁(1; N; K)``, and for
  ``N = 2`` against the O(3) chain of coupling ``J/2`` (``t = (1 + s·s')/2``);
- the split-envelope simplex draw against the plain rejection of independent truncated
  exponentials (accepted when their sum is at most 1), sampled with NumPy;
- the charge of ``N = 2`` against the O(3) charge of the Hopf image ``s = z^† σ z``.

Errors of the chain averages are Monte Carlo standard errors (ArviZ's ``mcse`` of the mean,
from the effective sample size of 4 chains); keys are fixed.
"""

import itertools
import math

import arviz_stats
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special, stats

import liesample
from liesample.analysis.topology import cp_topological_charge, topological_charge
from liesample.systems import cp_model
from liesample.targets import (
    CPChainReference,
    CPRingReference,
    cp_bond_moments,
    langevin_function,
    n_vector_bond_variance,
    tilted_simplex,
)

Z_MAX = 4.5
BETA = 3.0
LENGTH = 12
CHAINS = 4
PAULI = np.array([[[0, 1], [1, 0]], [[0, -1j], [1j, 0]], [[1, 0], [0, -1]]])


def random_rays(shape, n, seed):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(*shape, n)) + 1j * rng.normal(size=(*shape, n))
    return z / np.linalg.norm(z, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------------
# References
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3, 4, 6])
@pytest.mark.parametrize("k", [-2.5, 0.0, 0.7, 6.0])
def test_bond_moments_are_the_confluent_hypergeometric_ones(n, k):
    # E[tᵖ] under Beta(1, N−1) tilted by e^{Kt}: p!(N−1)!/(N+p−1)! ₁F₁(1+p; N+p; K)/₁F₁(1; N; K)
    f = [
        math.factorial(p) * special.hyp1f1(1 + p, n + p, k) / math.prod(range(n, n + p))
        for p in (0, 1, 2)
    ]
    mean, variance = f[1] / f[0], f[2] / f[0] - (f[1] / f[0]) ** 2
    assert cp_bond_moments(n, beta=k) == pytest.approx((mean, variance), rel=1e-10, abs=1e-14)


@pytest.mark.parametrize("k", [-1.0, 0.5, 3.0, 40.0])
def test_cp1_chain_is_the_o3_chain_of_half_the_coupling(k):
    mean, variance = cp_bond_moments(2, beta=k, coupling=1.0)
    assert mean == pytest.approx((1.0 + float(langevin_function(k / 2))) / 2, rel=1e-12)
    assert variance == pytest.approx(n_vector_bond_variance(3, beta=k / 2) / 4, rel=1e-8)
    system = cp_model((5,), N=2, coupling=0.5)
    assert system.reference(2.0) == CPChainReference(length=5, n=2, beta=2.0, coupling=0.5)
    bond = cp_bond_moments(2, beta=2.0, coupling=0.5)[0]  # K = 1
    assert system.reference(2.0).energy_mean() == pytest.approx(-0.5 * 4 * bond, rel=1e-14)


def test_the_simplex_draw_against_plain_rejection():
    """Mixed small and large rates (where the envelope splits them), mean and second moments."""
    rates = np.array([0.0, 0.5, 1.0, 30.0, 30.0])
    num = 10_000
    draws = np.asarray(
        liesample.jit(tilted_simplex)(jax.random.key(3), jnp.tile(jnp.asarray(rates), (num, 1)))
    )
    np.testing.assert_allclose(draws.sum(-1), 1.0, atol=1e-12)
    assert np.all(draws >= 0.0)
    rng = np.random.default_rng(4)
    u = rng.random((200_000, rates.size - 1))
    r = rates[1:]
    x = -np.log1p(-u * -np.expm1(-r)) / r  # truncated exponentials on [0, 1]
    x = x[x.sum(1) <= 1.0]
    reference = np.column_stack([1.0 - x.sum(1), x])
    for f in (lambda t: t, lambda t: t**2):
        a, b = f(draws), f(reference)
        z = (a.mean(0) - b.mean(0)) / np.sqrt(a.var(0) / len(a) + b.var(0) / len(b))
        assert np.all(np.abs(z) < Z_MAX), z


# ---------------------------------------------------------------------------------------------
# The system
# ---------------------------------------------------------------------------------------------


def test_system_energy_and_identity():
    system = cp_model((3, 4), N=3, coupling=0.7, periodic=True)
    same = cp_model((3, 4), 3, 0.7, True)
    assert system == same and hash(system) == hash(same)
    assert system != cp_model((3, 4), N=4, coupling=0.7, periodic=True)
    assert system.name == "CP(2) square lattice 3x4"
    assert float(system.hamiltonian(system.default_position)) == pytest.approx(-0.7 * 24)
    z = random_rays((3, 4), 3, 0)
    bonds = sum(np.sum(np.abs(np.sum(z.conj() * np.roll(z, -1, axis=a), -1)) ** 2) for a in (0, 1))
    assert float(system.hamiltonian(jnp.asarray(z))) == pytest.approx(-0.7 * bonds, rel=1e-12)
    phases = np.exp(1j * np.random.default_rng(1).uniform(0, 2 * np.pi, (3, 4, 1)))
    assert float(system.hamiltonian(jnp.asarray(z * phases))) == pytest.approx(-0.7 * bonds)
    ring = cp_model((4,), 3, coupling=0.7, periodic=True).reference(1.0)
    assert ring == CPRingReference(length=4, n=3, beta=1.0, coupling=0.7)  # the ring's energy
    assert cp_model((4, 4), 3).reference(1.0) is None
    assert cp_model((4, 4), 3, periodic=True).reference(1.0) is None


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (lambda: cp_model((4,), 1), ValueError, "N must be an int >= 2"),
        (lambda: cp_model((4,), 3.0), TypeError, "N must be an int >= 2"),
        (lambda: cp_model((4,), True), TypeError, "N must be an int >= 2"),
        (lambda: cp_model(4, 3), TypeError, "shape must be a tuple"),
        (lambda: cp_model((0,), 3), ValueError, "shape entries must be positive"),
        (lambda: cp_model((4,), 3, coupling=math.nan), ValueError, "coupling"),
        (lambda: cp_model((4,), 3, periodic="yes"), TypeError, "periodic must be a bool"),
        (lambda: cp_model((2,), 3, periodic=True), ValueError, "extent of shape to be >= 3"),
        (lambda: cp_model((4,), 3).check_position(np.ones((4, 2))), ValueError, r"shape \(4, 3\)"),
        (lambda: cp_model((4,), 3).check_position(np.ones((4, 3))), ValueError, "unit spins"),
        (lambda: cp_model((4,), 3).check_position(np.full((4, 3), "a")), TypeError, "complex"),
        (lambda: liesample.cp_heat_bath(cp_model((4,), 3), beta=math.inf), ValueError, "beta"),
        (
            lambda: liesample.cp_heat_bath(cp_model((4,), 3), beta=1.0, overrelaxation=-1),
            ValueError,
            "overrelaxation",
        ),
        (
            lambda: liesample.cp_heat_bath(
                cp_model((4,), 3), beta=1.0, overrelaxation=0, heat_bath_sweeps=0
            ),
            ValueError,
            "heat_bath_sweeps \\+ overrelaxation",
        ),
        (
            lambda: liesample.cp_heat_bath(liesample.systems.n_vector((4,), 2), beta=1.0),
            TypeError,
            "CPModelSystem",
        ),
        (lambda: CPChainReference(length=0, n=3, beta=1.0), ValueError, "length"),
        (lambda: cp_bond_moments(1, beta=1.0), ValueError, "N must"),
        (lambda: cp_topological_charge(np.ones((4, 4, 3))), TypeError, "complex"),
        (lambda: cp_topological_charge(np.ones((4, 3), complex)), ValueError, "shape"),
        (lambda: cp_topological_charge(np.ones((4, 4, 3), complex)), ValueError, "unit"),
    ],
)
def test_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()


# ---------------------------------------------------------------------------------------------
# The sampler
# ---------------------------------------------------------------------------------------------


def test_the_heat_bath_draws_the_exact_local_law():
    """A two-site chain from a fixed start: one heat-bath sweep draws site 1 given the new site
    0, so the bond ``t`` has the exact law ``∝ (1 − t)^{N−2} e^{βJt}`` (KS test)."""
    n, beta = 3, 2.5
    system = cp_model((2,), N=n, coupling=1.2)
    sampler = liesample.cp_heat_bath(system, beta=beta, overrelaxation=0)
    state = sampler.init(jnp.asarray(random_rays((2,), n, 5)))

    def bond(key):
        z = sampler.step(key, state)[0].position
        return jnp.abs(jnp.vdot(z[0], z[1])) ** 2

    t = np.asarray(liesample.jit(jax.vmap(bond))(jax.random.split(jax.random.key(6), 4000)))
    k = beta * 1.2
    grid = np.linspace(0.0, 1.0, 401)
    density = lambda u: (1 - u) ** (n - 2) * np.exp(k * (u - 1))
    pieces = [integrate.quad(density, a, b)[0] for a, b in itertools.pairwise(grid)]
    cdf = np.concatenate([[0.0], np.cumsum(pieces)]) / np.sum(pieces)
    assert stats.kstest(t, lambda x: np.interp(x, grid, cdf)).pvalue > 1e-3


def test_overrelaxation_keeps_the_energy():
    system = cp_model((4, 4), N=4, periodic=True)
    sampler = liesample.cp_heat_bath(system, beta=1.0, heat_bath_sweeps=0)
    z = jnp.asarray(random_rays((4, 4), 4, 7))
    state, info = liesample.jit(sampler.step)(jax.random.key(0), sampler.init(z))
    assert float(info.energy) == pytest.approx(float(system.hamiltonian(z)), rel=1e-12)
    assert not np.allclose(np.abs(np.sum(state.position.conj() * z, -1)), 1.0)  # it moved


def chain_series(sampler, starts, num_warmup, num_steps, seed):
    """Per step and chain: the mean bond ``t`` and the energy per bond, ``(chains, steps, 2)``."""

    def chain(key, position):
        def body(state, step):
            state, info = sampler.step(jax.random.fold_in(key, step), state)
            z = state.position
            t = jnp.mean(jnp.abs(jnp.sum(jnp.conj(z[:-1]) * z[1:], -1)) ** 2)
            return state, jnp.stack([t, info.energy / (LENGTH - 1)])

        steps = jnp.arange(num_warmup + num_steps)
        return jax.lax.scan(body, sampler.init(position), steps)[1][num_warmup:]

    keys = jax.random.split(jax.random.key(seed), starts.shape[0])
    return np.asarray(liesample.jit(jax.vmap(chain))(keys, jnp.asarray(starts)), dtype=float)


SLOW = pytest.mark.slow


@pytest.mark.parametrize("n", [pytest.param(2, marks=SLOW), 3, pytest.param(4, marks=SLOW)])
def test_recommended_sampler_samples_the_exact_open_chain(n):
    """Within ``Z_MAX`` MCSEs of ``(E[t], −J E[t])`` and more than ``Z_MAX`` from the law at
    ``1.25 β`` (a sampler of the wrong temperature is caught); ``n = 2`` is CP¹ = S²."""
    system = cp_model((LENGTH,), N=n)
    sampler = liesample.recommended_sampler(system, beta=BETA)
    assert sampler.settings["sampler"] == "cp_heat_bath"
    series = chain_series(sampler, random_rays((CHAINS, LENGTH), n, n), 50, 1000, 10 + n)
    estimate = series.mean(axis=(0, 1))
    mcse = np.array([float(arviz_stats.mcse(series[..., i], method="mean")) for i in range(2)])
    for beta, inside in ((BETA, True), (1.25 * BETA, False)):
        reference = system.reference(beta)
        target = np.array([reference.bond_mean(), reference.bond_energy_mean()])
        z = (estimate - target) / mcse
        assert np.all(np.abs(z) < Z_MAX) == inside, (n, inside, estimate, target, z)


# ---------------------------------------------------------------------------------------------
# Topological charge
# ---------------------------------------------------------------------------------------------


def test_charge_is_an_integer_and_invariant():
    z = random_rays((6, 5, 5), 3, 8)  # 6 random CP(2) configurations on a 5×5 torus
    q = np.asarray(cp_topological_charge(z))
    np.testing.assert_allclose(q, np.round(q), atol=1e-9)
    assert np.any(q != 0)
    rng = np.random.default_rng(9)
    u = np.linalg.qr(rng.normal(size=(3, 3)) + 1j * rng.normal(size=(3, 3)))[0]  # in U(3)
    rotated = z @ u.T
    phased = z * np.exp(1j * rng.uniform(0, 2 * np.pi, (*z.shape[:-1], 1)))
    np.testing.assert_allclose(np.asarray(cp_topological_charge(rotated)), q, atol=1e-9)
    np.testing.assert_allclose(np.asarray(cp_topological_charge(phased)), q, atol=1e-9)
    assert float(cp_topological_charge(cp_model((4, 4), 3, periodic=True).default_position)) == 0


def test_cp1_charge_is_the_o3_charge_of_the_hopf_image():
    z = random_rays((8, 6, 6), 2, 10)
    s = np.real(np.einsum("...a,iab,...b->...i", z.conj(), PAULI, z))
    q = np.asarray(cp_topological_charge(z))
    np.testing.assert_allclose(q, np.asarray(topological_charge(s)), atol=1e-9)
    assert len(set(np.round(q))) > 1


def test_charge_is_nan_on_an_exceptional_configuration():
    z = np.zeros((3, 3, 3), complex)
    z[..., 0] = 1.0
    z[0, 0] = [0.0, 1.0, 0.0]  # orthogonal to its neighbours: a zero overlap
    assert np.isnan(float(cp_topological_charge(z)))
