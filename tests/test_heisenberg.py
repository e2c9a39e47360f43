"""Classical Heisenberg spins (stochastic LLG) and the single-spin Metropolis baseline.

Statistical tests compare with Fisher's exact open-chain correlations ``E[s_k·s_{k+n}] = u^n``
(MATH.md §2, "Classical spins") with standard errors from the spread of per-chain time averages
over independent chains, and fixed keys.
"""

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from spin_runs import per_chain_averages as time_averages

import liesample
from liesample.samplers.spins._lattice import local_energy_change
from liesample.samplers.spins.heisenberg_metropolis import heisenberg_metropolis
from liesample.systems import rigid_body
from liesample.systems.heisenberg import (
    colouring,
    heisenberg,
    neighbour_sum,
    noise_groups,
)
from liesample.targets import heisenberg_chain_correlation

BETA = 2.0  # βJ = 2: u = 0.537, u³ = 0.155
CHAIN = (16,)
LAGS = (1, 2, 3)
# One open chain (J = 1) for the module's samplers: its stiffness on the unit-spin orbit, which
# every step-size check computes, is computed once.
CHAIN_SYSTEM = heisenberg(CHAIN)


def random_spins(shape, seed, chains=None):
    lead = () if chains is None else (chains,)
    x = np.random.default_rng(seed).normal(size=(*lead, *shape, 3))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def adjacent(a, b, shape, periodic):
    """Naive nearest-neighbour test: the sites differ by one step along exactly one axis."""
    steps = []
    for i, j, n in zip(a, b, shape, strict=True):
        d = abs(i - j)
        steps.append(d == 1 or (periodic and d == n - 1))
        if d not in (0, 1) and not (periodic and d == n - 1):
            return False
    return sum(steps) == 1 and sum(i != j for i, j in zip(a, b, strict=True)) == 1


def naive_energy(s, shape, coupling, periodic, field, anisotropy):
    """``h`` by a double loop over all unordered pairs of sites."""
    sites = list(itertools.product(*(range(n) for n in shape)))
    h = 0.0
    for p, a in enumerate(sites):
        for b in sites[p + 1 :]:
            if adjacent(a, b, shape, periodic):
                h -= coupling * float(np.dot(s[a], s[b]))
        h -= float(np.dot(field, s[a])) + anisotropy * float(s[a][2]) ** 2
    return h


def naive_neighbour_sum(s, shape, periodic):
    sites = list(itertools.product(*(range(n) for n in shape)))
    out = np.zeros_like(s)
    for a in sites:
        for b in sites:
            if adjacent(a, b, shape, periodic):
                out[a] += s[b]
    return out


# ---------------------------------------------------------------------------------------------
# The Hamiltonian and the lattice helpers against naive loops
# ---------------------------------------------------------------------------------------------

GEOMETRIES = [
    ((5,), False),
    ((5,), True),
    ((3, 3), False),
    ((3, 3), True),
    ((3, 4), True),
    ((3, 4, 3), True),
    ((2, 3, 2), False),
    ((3, 3, 3, 3), True),
]


@pytest.mark.parametrize(("shape", "periodic"), GEOMETRIES)
def test_hamiltonian_matches_naive_double_loop(shape, periodic):
    params = {"coupling": -0.7, "field": (0.3, -1.1, 0.4), "anisotropy": 0.9}
    system = heisenberg(shape, periodic=periodic, **params)
    for seed in range(3):
        s = random_spins(shape, seed)
        expected = naive_energy(s, shape, params["coupling"], periodic, params["field"], 0.9)
        assert float(system.hamiltonian(jnp.asarray(s))) == pytest.approx(expected, abs=1e-12)
    # The bond count is right: all spins aligned along e_x gives −J·(number of bonds).
    aligned = np.zeros((*shape, 3))
    aligned[..., 0] = 1.0
    bonds = sum(
        adjacent(a, b, shape, periodic)
        for a, b in itertools.combinations(itertools.product(*(range(n) for n in shape)), 2)
    )
    flat = heisenberg(shape, periodic=periodic, coupling=1.0)
    assert float(flat.hamiltonian(jnp.asarray(aligned))) == pytest.approx(-bonds, abs=1e-12)


@pytest.mark.parametrize(("shape", "periodic"), GEOMETRIES)
def test_neighbour_sum_and_local_energy_change(shape, periodic):
    s, new = random_spins(shape, 10), random_spins(shape, 11)
    got = np.asarray(neighbour_sum(jnp.asarray(s), periodic))
    np.testing.assert_allclose(got, naive_neighbour_sum(s, shape, periodic), atol=1e-13)
    system = heisenberg(
        shape, periodic=periodic, coupling=1.3, field=(0.2, 0.0, -0.5), anisotropy=-0.4
    )
    delta = np.asarray(local_energy_change(system, jnp.asarray(s), jnp.asarray(new)))
    h0 = float(system.hamiltonian(jnp.asarray(s)))
    for site in itertools.product(*(range(n) for n in shape)):
        moved = s.copy()
        moved[site] = new[site]
        assert delta[site] == pytest.approx(
            float(system.hamiltonian(jnp.asarray(moved))) - h0, abs=1e-12
        )


@pytest.mark.parametrize(
    ("shape", "periodic"), [*GEOMETRIES, ((4, 4), True), ((6,), True), ((1,), False)]
)
def test_colouring_is_proper(shape, periodic):
    colours, k = colouring(shape, periodic)
    assert set(np.unique(colours)) == set(range(k)) or colours.size < k
    for a, b in itertools.combinations(itertools.product(*(range(n) for n in shape)), 2):
        if adjacent(a, b, shape, periodic):
            assert colours[a] != colours[b], (a, b)


@pytest.mark.parametrize(("shape", "periodic"), [((6,), False), ((5,), True), ((3, 4), True)])
def test_noise_groups_hold_commuting_directions(shape, periodic):
    """Two directions share a group only on distinct, non-adjacent sites; 3 axes × colours."""
    labels = noise_groups(shape, periodic)
    sites = list(itertools.product(*(range(n) for n in shape)))
    assert labels.shape == (3 * len(sites),)
    assert set(labels) == set(range(3 * colouring(shape, periodic)[1]))
    for p, q in itertools.combinations(range(labels.size), 2):
        if labels[p] == labels[q]:
            a, b = sites[p // 3], sites[q // 3]
            assert a != b and not adjacent(a, b, shape, periodic), (a, b)


def test_noise_hamiltonians_are_the_spin_components():
    system = heisenberg((2, 3))
    s = jnp.asarray(random_spins((2, 3), 4))
    assert system.num_noises == 18
    np.testing.assert_array_equal(
        np.asarray(system.noise_hamiltonians(s)), np.asarray(s).reshape(-1)
    )
    assert system.event_shape == (2, 3, 3)
    np.testing.assert_array_equal(np.linalg.norm(system.default_position, axis=-1), 1.0)


# ---------------------------------------------------------------------------------------------
# Orbit preservation
# ---------------------------------------------------------------------------------------------


# slow: a 10⁴-step long run of the unit-spin (orbit) check; the default suite checks this with
# test_properties.py::test_one_step_stays_on_the_orbit[spin chain-splitting]
@pytest.mark.slow
def test_unit_spins_are_preserved_over_ten_thousand_steps():
    num_steps = 10_000
    algorithm = liesample.lie_poisson_langevin(CHAIN_SYSTEM, beta=BETA, sigma=1.0, step_size=0.05)

    @liesample.jit
    def run(state):
        def body(carry, step):
            state, worst = carry
            state, info = algorithm.step(jax.random.fold_in(jax.random.key(3), step), state)
            error = jnp.max(jnp.abs(jnp.linalg.norm(state.position, axis=-1) - 1.0))
            return (state, jnp.maximum(worst, error)), info.is_divergent

        return jax.lax.scan(body, (state, 0.0), jnp.arange(num_steps))

    start = random_spins(CHAIN, 0)
    (final, worst), nonfinite = run(algorithm.init(start))
    assert float(worst) < 1e-10
    assert not np.any(np.asarray(nonfinite))
    assert np.max(np.abs(np.asarray(final.position) - start)) > 0.5  # the spins did move


# ---------------------------------------------------------------------------------------------
# Fisher's exact chain correlations
# ---------------------------------------------------------------------------------------------


def chain_correlations(s):
    """``mean_k s_k·s_{k+n}`` for n in LAGS (open chain)."""
    return jnp.stack([jnp.mean(jnp.sum(s[:-n] * s[n:], axis=-1)) for n in LAGS])


def per_chain_averages(
    algorithm, num_chains, num_warmup, num_steps, seed, shape=CHAIN, observe=chain_correlations
):
    """Time averages of ``observe(s)`` (default: the chain correlations), one row per chain."""
    starts = random_spins(shape, seed, chains=num_chains)
    return time_averages(algorithm, starts, num_warmup, num_steps, seed, observe)


def assert_matches_fisher(averages):
    exact = heisenberg_chain_correlation(np.array(LAGS), BETA)
    estimate = averages.mean(0)
    se = averages.std(0, ddof=1) / np.sqrt(len(averages))
    z = (estimate - exact) / se
    assert np.all(np.abs(z) < 3.5), (estimate, exact, se, z)
    # Power: a factor-2 error in the dissipation (sampling at 2β) would be rejected by far.
    wrong = heisenberg_chain_correlation(np.array(LAGS), 2 * BETA)
    assert np.all(np.abs(estimate - wrong) > 10 * se), (estimate, wrong, se)


# the Metropolis chain against Fisher's law and the heat bath's exact chain run by default
@pytest.mark.slow
def test_langevin_chain_correlations_match_fisher():
    """Open chain, N = 16, βJ = 2, σ = 1, default (splitting) integrator at dt = 0.05.

    Step-size bias of E[s_k·s_{k+1}], measured with 1024 chains × 200 time units (SE 2.4e-4)
    with the sublattice-grouped splitting: +3.5e-3 at dt = 0.2, +7.7e-4 at dt = 0.1 (second
    order), −2.2e-4 ± 2.4e-4 at dt = 0.05; for n = 2, 3 it is below 1e-3 at dt = 0.05 (SE 4.5e-4,
    5.9e-4). This test's SEs are about 1.4e-3, 2.5e-3, 3.3e-3: the bias is a small fraction of
    them. (The ungrouped, one-direction-at-a-time splitting was also unbiased at this resolution
    at dt = 0.05: 256 chains, SE 4.7e-4.)
    """
    dt = 0.05
    algorithm = liesample.lie_poisson_langevin(CHAIN_SYSTEM, beta=BETA, sigma=1.0, step_size=dt)
    averages = per_chain_averages(
        algorithm, num_chains=64, num_warmup=round(10 / dt), num_steps=round(100 / dt), seed=21
    )
    assert_matches_fisher(averages)


@pytest.mark.parametrize("proposal", ["uniform", pytest.param("rotation", marks=pytest.mark.slow)])
def test_metropolis_chain_correlations_match_fisher(proposal):
    """64 chains × 1000 sweeps (after 200): the SEs (from the chains' spread) are a few 1e-3,
    so the z-test stays honest and the 2β law (0.21 away in E[s_k·s_{k+1}]) is rejected by far
    more than the 10 SE asked. Each chain is the first 1200 sweeps of the former 3200-sweep
    run (key ``fold_in(key_c, step)``)."""
    algorithm = heisenberg_metropolis(CHAIN_SYSTEM, beta=BETA, proposal=proposal)
    averages = per_chain_averages(algorithm, num_chains=64, num_warmup=200, num_steps=1000, seed=22)
    assert_matches_fisher(averages)


@pytest.mark.slow
def test_langevin_and_metropolis_agree_on_a_periodic_lattice_with_field_and_anisotropy():
    """3×3 periodic lattice (an odd cycle: three colours), J = 1, B = 0.5 e_z, D = 0.8, β = 1.

    No exact law here: the two independent samplers must agree on E[h]/N, E[s_z], E[s_z²].
    The Langevin bias is second order with a large constant on this stiff lattice: for E[h]/N,
    measured against 512 Metropolis chains × 2·10⁴ sweeps, −0.078 at dt = 0.2, −0.017 at 0.1,
    −0.0039 ± 0.002 at 0.05, so ≈ −0.001 at dt = 0.025, against a combined SE of ≈ 0.009 here.
    """
    shape, beta = (3, 3), 1.0
    system = heisenberg(shape, periodic=True, field=(0.0, 0.0, 0.5), anisotropy=0.8)

    def observables(s):
        return jnp.stack([system.hamiltonian(s) / 9, jnp.mean(s[..., 2]), jnp.mean(s[..., 2] ** 2)])

    dt = 0.025
    langevin = liesample.lie_poisson_langevin(system, beta=beta, sigma=1.0, step_size=dt)
    metropolis = heisenberg_metropolis(system, beta=beta)
    runs = [
        per_chain_averages(langevin, 64, round(10 / dt), round(100 / dt), 31, shape, observables),
        per_chain_averages(metropolis, 64, 200, 5000, 32, shape, observables),
    ]
    (a, se_a), (b, se_b) = [(r.mean(0), r.std(0, ddof=1) / np.sqrt(len(r))) for r in runs]
    z = (a - b) / np.hypot(se_a, se_b)
    assert np.all(np.abs(z) < 3.5), (a, b, se_a, se_b, z)
    assert b[1] > 0.5 and b[2] > 1 / 3 + 0.2  # field and easy axis visibly polarise the spins


@functools.partial(liesample.jit, static_argnames=("build",))
def one_step(key, state, values, *, build):
    """A sampler's step compiled as the runner compiles it: its structure's ``build`` static,
    its values (β, the proposal scale) traced, so the rotation proposals share one program."""
    return build(**values).step(key, state)


def test_metropolis_reports_acceptance_and_energy():
    system = heisenberg((4, 4), periodic=True, field=(0.0, 0.0, 0.5))
    start = random_spins((4, 4), 5)
    rates = {}
    for proposal, scale in (("uniform", 0.5), ("rotation", 0.2), ("rotation", 2.0)):
        algorithm = heisenberg_metropolis(system, beta=1.0, proposal=proposal, proposal_scale=scale)
        build, values = algorithm.structure
        state, info = one_step(jax.random.key(0), algorithm.init(start), values, build=build)
        assert 0.0 <= float(info.acceptance_rate) <= 1.0
        assert float(info.energy) == pytest.approx(float(system.hamiltonian(state.position)))
        np.testing.assert_allclose(
            np.linalg.norm(np.asarray(state.position), axis=-1), 1.0, atol=1e-14
        )
        rates[(proposal, scale)] = float(info.acceptance_rate)
    assert rates[("rotation", 0.2)] > rates[("rotation", 2.0)]  # smaller moves are accepted more


# ---------------------------------------------------------------------------------------------
# Pure dissipation: energy descent to the aligned state
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "hamiltonian",
    [
        # slow: the same descent with the precession added; the step with the precession runs
        # by default in tests/stability/test_stability.py (the batched Heisenberg step)
        pytest.param(True, marks=pytest.mark.slow),
        False,
    ],
    ids=["with-drift", "dissipation-only"],
)
def test_pure_dissipation_aligns_the_ferromagnetic_chain(hamiltonian):
    """Double-bracket descent from a random start (θ = 1) to the aligned ground state.

    The slowest mode is the longest magnon of the open chain, k = π/N, relaxing at rate
    θJ·2(1 − cos(π/16)) ≈ 0.038, so the energy gap decays like e^{−0.077 t}: ~1e-7 at t = 200
    and ~1e-12 at t = 400 (observed with and without the Hamiltonian drift).
    """
    dt, num_steps = 0.1, 4000  # t = 400
    system = CHAIN_SYSTEM  # coupling J = 1
    algorithm = liesample.lie_poisson_langevin(
        system, sigma=0.0, theta=1.0, step_size=dt, hamiltonian=hamiltonian
    )

    @liesample.jit
    def run(state):
        def body(state, _):
            state, info = algorithm.step(jax.random.key(0), state)
            return state, info.energy

        return jax.lax.scan(body, state, None, length=num_steps)

    start = random_spins(CHAIN, 1)
    final, energies = run(algorithm.init(start))
    energies = np.concatenate(
        [[float(system.hamiltonian(jnp.asarray(start)))], np.asarray(energies)]
    )
    assert np.max(np.diff(energies)) <= 1e-13  # monotone (energies are O(10): ~1e2 ulp)
    assert energies[0] - energies[-1] > 5.0  # a genuine descent from a disordered start
    s = np.asarray(final.position)
    assert energies[-1] == pytest.approx(-(CHAIN[0] - 1), abs=1e-9)  # the ground state −J(N−1)
    assert np.linalg.norm(s.mean(0)) > 1 - 1e-9  # all spins aligned


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"shape": 16}, TypeError, "shape"),
        ({"shape": ()}, ValueError, "shape"),
        ({"shape": (2, 2, 2), "periodic": True}, ValueError, "periodic"),
        ({"shape": (0,)}, ValueError, "shape"),
        ({"shape": (4, -1)}, ValueError, "shape"),
        ({"shape": (2.5,)}, TypeError, "shape"),
        ({"shape": (True,)}, TypeError, "shape"),
        ({"shape": (4,), "coupling": float("nan")}, ValueError, "coupling"),
        ({"shape": (4,), "coupling": (1.0, 2.0)}, TypeError, "coupling"),
        ({"shape": (4,), "field": (0.0, 1.0)}, ValueError, "field"),
        ({"shape": (4,), "field": (0.0, float("inf"), 0.0)}, ValueError, r"field\[1\]"),
        ({"shape": (4,), "anisotropy": float("-inf")}, ValueError, "anisotropy"),
        ({"shape": (4,), "periodic": "yes"}, TypeError, "periodic"),
        ({"shape": (2,), "periodic": True}, ValueError, "periodic"),
        ({"shape": (4, 2), "periodic": True}, ValueError, "periodic"),
    ],
)
def test_bad_parameters_are_rejected(kwargs, error, match):
    with pytest.raises(error, match=match):
        heisenberg(**kwargs)


def test_non_unit_or_misshapen_spins_are_rejected():
    system = heisenberg((3, 3))
    algorithm = liesample.lie_poisson_langevin(system, beta=1.0, sigma=1.0, step_size=0.05)
    spins = random_spins((3, 3), 0)
    algorithm.init(spins)  # unit spins are fine
    bad = spins.copy()
    bad[1, 2] *= 1.0 + 1e-6
    with pytest.raises(ValueError, match=r"position.*\(1, 2\)"):
        algorithm.init(bad)
    with pytest.raises(ValueError, match="position"):
        algorithm.init(spins[:2])
    with pytest.raises(ValueError, match=r"position.*\(0, 0\)"):
        heisenberg_metropolis(system, beta=1.0).init(np.zeros((3, 3, 3)) + [0.0, 0.0, 2.0])


def test_bad_metropolis_and_reference_arguments():
    system = heisenberg((4,))
    with pytest.raises(ValueError, match="proposal"):
        heisenberg_metropolis(system, beta=1.0, proposal="gibbs")
    with pytest.raises(ValueError, match="proposal_scale"):
        heisenberg_metropolis(system, beta=1.0, proposal="rotation", proposal_scale=0.0)
    with pytest.raises(ValueError, match="beta"):
        heisenberg_metropolis(system, beta=float("nan"))
    with pytest.raises(TypeError, match="system"):
        heisenberg_metropolis(rigid_body(), beta=1.0)
    with pytest.raises(ValueError, match="n must"):
        heisenberg_chain_correlation(-1, 1.0)
    with pytest.raises(ValueError, match="beta"):
        heisenberg_chain_correlation(1, float("inf"))


def test_exact_reference():
    # u = L(βJ); small βJ uses the series; the reference exists only for the open, field-free chain.
    assert heisenberg_chain_correlation(1, 2.0) == pytest.approx(1 / np.tanh(2.0) - 0.5, rel=1e-14)
    assert heisenberg_chain_correlation(2, 1e-4) == pytest.approx((1e-4 / 3) ** 2, rel=1e-8)
    assert heisenberg_chain_correlation(1, -2.0, coupling=1.0) == pytest.approx(
        -(1 / np.tanh(2.0) - 0.5)
    )
    reference = heisenberg((8,), coupling=0.5).reference(3.0)
    assert reference.correlation(3) == pytest.approx(heisenberg_chain_correlation(3, 1.5))
    assert reference.energy_mean() == pytest.approx(-0.5 * 7 * reference.u)
    assert heisenberg((8,), field=(0.0, 0.0, 1.0)).reference(1.0) is None
    assert heisenberg((3, 3)).reference(1.0) is None
