"""The classical-spin samplers: exact von Mises–Fisher draws, heat bath, over-relaxation
(precession), single-spin Metropolis and Wolff clusters, each against exact laws.

Invariance of each move alone: start from exact i.i.d. draws of the open chain (sequential
von Mises–Fisher bonds, Fisher 1964), apply the move a few times and compare the bond
correlations ``mean_k s_k·s_{k+n}`` (n = 1, 2) with ``uⁿ``; the draws stay independent, so the
standard error is the spread over draws. Ergodic runs start from random spins and use the
spread of per-chain time averages over independent chains. Fixed keys throughout.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from spin_runs import per_chain_averages

import liesample
from liesample.samplers.contract import check_info
from liesample.samplers.spins._lattice import SpinInfo, SpinState, finish_step
from liesample.samplers.spins.heisenberg_wolff import WolffInfo, bond_table
from liesample.systems import heisenberg, rigid_body
from liesample.systems.heisenberg import neighbour_table
from liesample.targets.spins import (
    HeisenbergRingReference,
    heisenberg_chain_correlation,
    langevin_function,
    sample_heisenberg_chain,
    von_mises_fisher,
    von_mises_fisher_cosine,
)

BETA = 2.0  # βJ = 2: u = 0.537, u² = 0.289
LENGTH = 8
LAGS = np.array([1, 2])
Z_MAX = 4.5


# The exact draws compiled once per shape (κ is an argument), not dispatched op by op.
exact_von_mises_fisher = jax.jit(von_mises_fisher)


def random_spins(shape, seed, chains=None):
    lead = () if chains is None else (chains,)
    x = np.random.default_rng(seed).normal(size=(*lead, *shape, 3))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def bond_correlations(s):
    """``mean_k s_k·s_{k+n}`` for n in LAGS over the open chain (last axes: sites, 3)."""
    return jnp.stack([jnp.mean(jnp.sum(s[..., :-n, :] * s[..., n:, :], -1), -1) for n in LAGS], -1)


def assert_close(samples, exact, wrong=None):
    """Rows of i.i.d. (or per-chain) estimates against ``exact``, within Z_MAX standard errors;
    ``wrong`` (a law the test must tell apart) must be > 10 standard errors away."""
    estimate = samples.mean(0)
    se = samples.std(0, ddof=1) / math.sqrt(len(samples))
    z = (estimate - exact) / se
    assert np.all(np.abs(z) < Z_MAX), (estimate, exact, se, z)
    if wrong is not None:
        assert np.all(np.abs(estimate - wrong) > 10 * se), (estimate, wrong, se)


# ---------------------------------------------------------------------------------------------
# Exact von Mises–Fisher draws
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kappa", [1e-6, 0.5, 50.0, 1e4, -3.0])
def test_von_mises_fisher_moments(kappa):
    """``E[w] = coth κ − 1/κ``, ``E[w²] = 1 − 2L(κ)/κ``, azimuth uniform, unit norm."""
    n = 100_000
    mean = np.array([0.48, -0.6, 0.64])
    mean = mean / np.linalg.norm(mean)
    draws = np.asarray(
        exact_von_mises_fisher(jax.random.key(7), jnp.tile(mean, (n, 1)), jnp.full(n, kappa))
    )
    np.testing.assert_allclose(np.linalg.norm(draws, axis=-1), 1.0, atol=1e-15)
    w = draws @ mean
    k = abs(kappa)
    lk = float(langevin_function(k))
    second = 1.0 / 3.0 if k < 1e-3 else 1.0 - 2.0 * lk / k
    variance = second - lk**2
    z = (np.sign(kappa) * w.mean() - lk) / math.sqrt(variance / n)
    assert abs(z) < Z_MAX, (w.mean(), lk, z)
    # E[w²] via its own spread; the transverse part is isotropic: E[(s·e)²] = (1 − E[w²])/2
    assert abs(np.mean(w**2) - second) < Z_MAX * np.std(w**2) / math.sqrt(n) + 1e-15
    e = np.cross(mean, [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)
    t = draws @ e
    assert abs(t.mean()) < Z_MAX * t.std() / math.sqrt(n)
    assert abs(np.mean(t**2) - (1 - second) / 2) < Z_MAX * np.std(t**2) / math.sqrt(n)


def test_von_mises_fisher_cosine_is_finite_at_the_ends():
    u = jnp.array([0.0, 0.5, 1.0 - 2.0**-53])
    for kappa in (0.0, 1e-300, 1e-6, 1.0, 1e4, 1e300):
        one_minus_w = np.asarray(von_mises_fisher_cosine(u, jnp.full(3, kappa)))
        assert np.all(np.isfinite(one_minus_w)) and np.all((0 <= one_minus_w) & (one_minus_w <= 2))
        assert one_minus_w[0] == 0.0  # u = 0 is the mean direction
    # the inverse distribution function: tiny κ is uniform in w, huge κ is −log(1 − u)/κ
    np.testing.assert_allclose(von_mises_fisher_cosine(u, jnp.full(3, 1e-12)), 2 * u, rtol=1e-9)
    np.testing.assert_allclose(
        von_mises_fisher_cosine(u[:2], jnp.full(2, 1e4)), -np.log1p(-u[:2]) / 1e4, rtol=1e-12
    )


# ---------------------------------------------------------------------------------------------
# Each move alone keeps the exact law (from exact draws)
# ---------------------------------------------------------------------------------------------

CHAIN = heisenberg((LENGTH,))


def apply_steps(algorithm, starts, num_steps, seed):
    """``num_steps`` steps of ``algorithm`` from each start (vmapped); final spins and infos."""

    def chain(key, position):
        def body(state, step):
            return algorithm.step(jax.random.fold_in(key, step), state)

        return jax.lax.scan(body, algorithm.init(position), jnp.arange(num_steps))

    keys = jax.random.split(jax.random.key(seed), starts.shape[0])
    final, infos = liesample.jit(jax.vmap(chain))(keys, starts)
    return np.asarray(final.position), infos


@pytest.fixture(scope="module")
def exact_chain_draws():
    """4000 exact i.i.d. open chains (N = 8, βJ = 2), and their correlations match ``uⁿ``."""
    draws = sample_heisenberg_chain(jax.random.key(11), 4000, LENGTH, BETA)
    assert_close(np.asarray(bond_correlations(draws)), heisenberg_chain_correlation(LAGS, BETA))
    return draws


MOVES = {
    "heat bath": lambda: liesample.heisenberg_heat_bath(CHAIN, beta=BETA, overrelaxation=0),
    "over-relaxation": lambda: liesample.heisenberg_heat_bath(
        CHAIN, beta=BETA, heat_bath_sweeps=0, overrelaxation=1
    ),
    "precession 1 rad": lambda: liesample.heisenberg_heat_bath(
        CHAIN, beta=BETA, heat_bath_sweeps=0, overrelaxation=1, precession_angle=1.0
    ),
    "metropolis": lambda: liesample.heisenberg_metropolis(CHAIN, beta=BETA),
    "wolff": lambda: liesample.heisenberg_wolff(CHAIN, beta=BETA),
}


# Metropolis is also checked against Fisher's law in test_heisenberg.py, and a precession by any
# angle keeps h (test_precession_keeps_the_energy_to_round_off) and area: both in the slow suite.
SLOW_MOVES = {"metropolis", "precession 1 rad"}


@pytest.mark.parametrize(
    "move", [pytest.param(m, marks=pytest.mark.slow) if m in SLOW_MOVES else m for m in MOVES]
)
def test_each_move_keeps_the_exact_chain_law(move, exact_chain_draws):
    """4000 exact draws, 3 steps of one move: bond correlations still ``u, u²``.

    Power: the microcanonical moves keep E[s_k·s_{k+1}] by construction but must keep
    E[s_k·s_{k+2}] too, which a wrong reflection (e.g. about the bond partner only) changes;
    the heat bath and Metropolis at the wrong β would drift towards another u within 3 sweeps.
    """
    starts = exact_chain_draws
    final, infos = apply_steps(MOVES[move](), starts, 3, seed=12)
    assert np.max(np.abs(np.linalg.norm(final, axis=-1) - 1.0)) < 1e-13
    assert not np.any(np.asarray(infos.is_divergent))
    moved = np.mean(np.abs(final - np.asarray(starts)) > 1e-6)
    assert moved > 0.1, moved  # the move did move the spins
    exact = heisenberg_chain_correlation(LAGS, BETA)
    assert_close(np.asarray(bond_correlations(jnp.asarray(final))), exact)


def test_wrong_beta_heat_bath_is_detected_from_exact_draws(exact_chain_draws):
    """The invariance test has power: a heat bath at β/2 leaves the law within 3 sweeps."""
    starts = exact_chain_draws
    wrong = liesample.heisenberg_heat_bath(CHAIN, beta=BETA / 2, overrelaxation=0)
    final, _ = apply_steps(wrong, starts, 3, seed=12)
    samples = np.asarray(bond_correlations(jnp.asarray(final)))
    se = samples.std(0, ddof=1) / math.sqrt(len(samples))
    assert np.all(np.abs(samples.mean(0) - heisenberg_chain_correlation(LAGS, BETA)) > 10 * se)


def test_precession_keeps_the_energy_to_round_off():
    """Over-relaxation and any precession angle keep h exactly, on a lattice with a field."""
    system = heisenberg((4, 5), periodic=True, coupling=0.7, field=(0.3, -0.2, 0.9))
    starts = jnp.asarray(random_spins((4, 5), 3, chains=8))
    energies = np.asarray(jax.jit(jax.vmap(system.hamiltonian))(starts))  # one compile, not eager
    kernel = liesample.heisenberg_heat_bath.build_kernel(system, 0, 5)  # 5 precession sweeps

    @liesample.jit
    def run(starts, angle):
        def chain(s):
            def body(state, _):
                state, info = kernel(jax.random.key(0), state, 1.0, angle)
                return state, info

            return jax.lax.scan(body, SpinState(s), None, length=20)

        return jax.vmap(chain)(starts)

    for angle in (-2.0, 0.3):  # the Rodrigues path (π, the reflection, is in test_each_move)
        final, infos = run(starts, angle)
        np.testing.assert_allclose(np.asarray(infos.energy)[:, -1], energies, rtol=0, atol=1e-12)
        assert np.max(np.abs(np.asarray(final.position) - np.asarray(starts))) > 0.5
        np.testing.assert_array_equal(np.asarray(infos.acceptance_rate), 1.0)
    reflect = liesample.heisenberg_heat_bath(system, beta=1.0, heat_bath_sweeps=0)
    _, info = liesample.jit(reflect.step)(jax.random.key(0), reflect.init(starts[0]))
    assert float(info.energy) == pytest.approx(float(energies[0]), abs=1e-12)


def test_heat_bath_in_a_field_is_the_exact_von_mises_fisher_law():
    """One spin in a field B: one heat-bath step from anywhere is an exact draw,
    ``E[s·B̂] = L(β|B|)``; Metropolis keeps that law (from exact draws)."""
    field = np.array([0.0, 1.2, -1.6])  # |B| = 2
    system = heisenberg((1,), field=tuple(field))
    beta, n = 0.8, 10_000
    b = field / 2.0
    exact = float(langevin_function(beta * 2.0))
    starts = jnp.tile(jnp.array([[0.0, 0.0, 1.0]]), (n, 1, 1))
    final, _ = apply_steps(
        liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=1), starts, 1, seed=2
    )
    w = final[:, 0] @ b
    assert abs(w.mean() - exact) < Z_MAX * w.std() / math.sqrt(n), (w.mean(), exact)
    exact_draws = exact_von_mises_fisher(
        jax.random.key(3), jnp.tile(b, (n, 1)), jnp.full(n, 2 * beta)
    )
    final, _ = apply_steps(
        liesample.heisenberg_metropolis(system, beta=beta), exact_draws[:, None], 5, seed=4
    )
    w = final[:, 0] @ b
    assert abs(w.mean() - exact) < Z_MAX * w.std() / math.sqrt(n), (w.mean(), exact)


# ---------------------------------------------------------------------------------------------
# Ergodic runs from random starts
# ---------------------------------------------------------------------------------------------


def ring_correlations(s):
    return jnp.stack([jnp.mean(jnp.sum(s * jnp.roll(s, -n, axis=-2), -1), -1) for n in LAGS], -1)


@pytest.mark.parametrize(
    ("sampler", "length", "periodic"),
    [
        # slow: the heat bath's chain law again; the default suite checks this with the
        # [heat bath + over-relaxation-5-True] case of
        # test_spin_samplers.py::test_samplers_match_the_exact_chain_and_ring
        pytest.param("heat bath + over-relaxation", 16, False, marks=pytest.mark.slow),
        ("heat bath + over-relaxation", 5, True),  # odd ring: three colour classes
        ("wolff", 16, False),
        pytest.param("wolff", 4, True, marks=pytest.mark.slow),
    ],
)
def test_samplers_match_the_exact_chain_and_ring(sampler, length, periodic):
    """From random starts, 32 chains: Fisher's ``uⁿ`` (open) or the ring's transfer-matrix
    correlations (periodic); a sampler at 2β would be rejected by far."""
    system = heisenberg((length,), periodic=periodic)
    if sampler == "wolff":
        algorithm = liesample.heisenberg_wolff(system, beta=BETA)
        num_steps = 1500
    else:
        algorithm = liesample.heisenberg_heat_bath(system, beta=BETA, overrelaxation=1)
        num_steps = 600
    observe = ring_correlations if periodic else bond_correlations
    starts = random_spins((length,), 5, chains=32)
    averages = per_chain_averages(algorithm, starts, 100, num_steps, 6, observe)
    reference = system.reference(BETA)
    wrong = heisenberg((length,), periodic=periodic).reference(2 * BETA).correlation(LAGS)
    assert_close(averages, reference.correlation(LAGS), wrong)


# ---------------------------------------------------------------------------------------------
# Info contract, cluster bookkeeping, refusals
# ---------------------------------------------------------------------------------------------


def test_info_contract_and_cluster_size():
    system = heisenberg((5, 4), periodic=False)
    start = jnp.asarray(random_spins((5, 4), 9))
    for algorithm, info_class in (
        (liesample.heisenberg_heat_bath(system, beta=1.0), SpinInfo),
        (liesample.heisenberg_metropolis(system, beta=1.0), SpinInfo),
    ):
        state, info = algorithm.step(jax.random.key(0), algorithm.init(start))  # eager
        assert isinstance(info, info_class)
        check_info(info)  # the package's Info contract
        assert algorithm.settings["beta"] == 1.0
        assert not bool(info.is_divergent)
        assert 0.0 <= float(info.acceptance_rate) <= 1.0
        assert float(info.energy) == pytest.approx(float(system.hamiltonian(state.position)))
    check_info(WolffInfo)
    kernel = liesample.jit(liesample.heisenberg_wolff.build_kernel(system))  # β traced
    # the reflected sites are exactly the cluster: a hot lattice (β = 0) flips one site only
    state, info = kernel(jax.random.key(1), SpinState(start), 0.0)
    assert isinstance(info, WolffInfo) and float(info.acceptance_rate) == 1.0
    assert int(info.cluster_size) == 1
    assert int(np.sum(np.any(np.asarray(state.position) != np.asarray(start), axis=-1))) == 1
    assert float(info.energy) == pytest.approx(float(system.hamiltonian(state.position)))
    # a cold aligned lattice (huge β) is one cluster
    state, info = kernel(jax.random.key(2), SpinState(jnp.asarray(system.default_position)), 1e6)
    assert int(info.cluster_size) == 20


def test_non_finite_step_is_rejected_and_flagged():
    system = heisenberg((4,))
    old = jnp.asarray(random_spins((4,), 0))
    new = old.at[1, 0].set(jnp.nan)
    state, info = finish_step(system, old, new, 1.0)
    assert bool(info.is_divergent) and float(info.acceptance_rate) == 0.0
    np.testing.assert_array_equal(np.asarray(state.position), np.asarray(old))
    assert float(info.energy) == pytest.approx(float(system.hamiltonian(old)))
    state, info = finish_step(system, old, old, 0.25)
    assert not bool(info.is_divergent) and float(info.acceptance_rate) == 0.25


def test_neighbour_table():
    table = neighbour_table((3, 4), periodic=True)
    assert table.shape == (12, 4)
    assert sorted(table[0]) == sorted([4, 8, 1, 3])  # (0,0): (1,0), (2,0), (0,1), (0,3)
    open_table = neighbour_table((3,), periodic=False)
    np.testing.assert_array_equal(open_table, [[3, 1], [0, 2], [1, 3]])
    # every bond once, both ends see the same id, missing bonds get the id B
    for shape, periodic, count in (((3, 4), True, 24), ((3, 4), False, 17), ((3,), False, 2)):
        neighbours, bonds, ends = bond_table(shape, periodic)
        assert ends.shape == (count, 2)
        n = neighbours.shape[0]
        for i, d in np.ndindex(*neighbours.shape):
            j = neighbours[i, d]
            if j == n:
                assert bonds[i, d] == count
            else:
                assert sorted(ends[bonds[i, d]]) == sorted((i, j))


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (
            lambda: liesample.heisenberg_heat_bath(heisenberg((4,), anisotropy=0.5), beta=1.0),
            ValueError,
            "anisotropy",
        ),
        (lambda: liesample.heisenberg_heat_bath(rigid_body(), beta=1.0), TypeError, "system"),
        (
            lambda: liesample.heisenberg_heat_bath(heisenberg((4,)), beta=math.inf),
            ValueError,
            "beta",
        ),
        (
            lambda: liesample.heisenberg_heat_bath(heisenberg((4,)), beta=1.0, overrelaxation=-1),
            ValueError,
            "overrelaxation",
        ),
        (
            lambda: liesample.heisenberg_heat_bath(heisenberg((4,)), beta=1.0, overrelaxation=1.5),
            TypeError,
            "overrelaxation",
        ),
        (
            lambda: liesample.heisenberg_heat_bath(
                heisenberg((4,)), beta=1.0, overrelaxation=0, heat_bath_sweeps=0
            ),
            ValueError,
            "move",
        ),
        (
            lambda: liesample.heisenberg_heat_bath(
                heisenberg((4,)), beta=1.0, precession_angle=math.nan
            ),
            ValueError,
            "precession_angle",
        ),
        (
            lambda: liesample.heisenberg_wolff(heisenberg((4,), coupling=-1.0), beta=1.0),
            ValueError,
            "coupling",
        ),
        (
            lambda: liesample.heisenberg_wolff(heisenberg((4,), field=(0.0, 0.0, 0.1)), beta=1.0),
            ValueError,
            "field",
        ),
        (
            lambda: liesample.heisenberg_wolff(heisenberg((4,), anisotropy=0.1), beta=1.0),
            ValueError,
            "anisotropy",
        ),
        (lambda: liesample.heisenberg_wolff(heisenberg((4,)), beta=-1.0), ValueError, "beta"),
        (lambda: liesample.heisenberg_wolff(rigid_body(), beta=1.0), TypeError, "system"),
        (lambda: HeisenbergRingReference(2, 1.0, 1.0), ValueError, "length"),
    ],
)
def test_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()


def test_ring_reference_tends_to_the_open_chain():
    ring = HeisenbergRingReference(200, 1.3, 0.8)
    np.testing.assert_allclose(
        ring.correlation(np.arange(5)),
        heisenberg_chain_correlation(np.arange(5), 1.3, 0.8),
        rtol=1e-12,
    )
    small = HeisenbergRingReference(5, 2.0, 1.0).correlation(np.arange(6))
    np.testing.assert_allclose(small, small[::-1], rtol=1e-12)  # n ↔ N − n
    assert small[0] == pytest.approx(1.0)
