"""Accuracy as a knob (``liesample.integrators.accuracy``): ask for a bias tolerance, get it.

- :func:`richardson_romberg`: the arithmetic on synthetic data with a known bias, its MCSE
  (independent and paired), and parameter checks;
- :func:`coupled_ergodic_averages`: the levels share one Brownian path (level 0 of a 2-level
  run equals a 1-level run with the same key);
- :func:`choose_step_size` on targets it was not tuned on (a rigid body with another inertia,
  β and radius than the benchmarks; the heavy top; slow: the spin chain's ``u^n``): a
  production run at the chosen step (new keys) has ``|error| ≤ tolerance + 4 MCSE`` on every
  observable, while the pilot's own coarse step misses the tolerance (so the test has power).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from liesample import accuracy
from liesample.systems import heavy_top, heisenberg, rigid_body
from liesample.targets import RestrictedGaussian, heisenberg_chain_correlation

# ---------------------------------------------------------------------------------------------
# Richardson–Romberg arithmetic
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", [1, 2])
def test_richardson_romberg_cancels_a_known_bias(order):
    """A(h) = 1 + 0.3 h^p + noise: the combination of h = 0.4 and 0.2 recovers 1 within 4 MCSE,
    and its MCSE matches the independent-runs formula."""
    rng = np.random.default_rng(0)
    chains, h = 4000, 0.4
    coarse = 1.0 + 0.3 * h**order + 0.05 * rng.normal(size=(chains, 2))
    fine = 1.0 + 0.3 * (h / 2) ** order + 0.05 * rng.normal(size=(chains, 2))
    result = accuracy.richardson_romberg(coarse, fine, order)
    weight = 2.0**order
    expected_se = np.hypot(weight * 0.05, 0.05) / (weight - 1) / np.sqrt(chains)
    np.testing.assert_allclose(result.mcse, expected_se, rtol=0.05)
    assert np.all(np.abs(result.estimate - 1.0) < 4 * result.mcse)
    assert np.all(np.abs(result.fine - 1.0) > 10 * result.fine_mcse)  # the bias was real


def test_richardson_romberg_paired_uses_the_per_chain_combination():
    """Paired (coupled) chains: a noise shared by both levels enters ``2A(h/2) − A(h)`` with weight
    1 instead of ``√(2² + 1)``; the MCSE is that of the per-chain combinations."""
    rng = np.random.default_rng(1)
    common = rng.normal(size=(1000, 1))
    coarse = 2.0 + 0.1 + common + 0.01 * rng.normal(size=(1000, 1))
    fine = 2.0 + 0.05 + common + 0.01 * rng.normal(size=(1000, 1))
    paired = accuracy.richardson_romberg(coarse, fine, 1, paired=True)
    independent = accuracy.richardson_romberg(coarse, fine, 1, paired=False)
    combined = 2 * fine - coarse
    assert paired.mcse[0] == pytest.approx(combined.std(ddof=1) / np.sqrt(1000), rel=1e-12)
    assert paired.mcse[0] == pytest.approx(independent.mcse[0] / np.sqrt(5), rel=0.05)
    assert abs(paired.estimate[0] - 2.0) < 4 * paired.mcse[0]


@pytest.mark.parametrize(
    "coarse, fine, order, paired, error, match",
    [
        (np.ones((5, 2)), np.ones((5, 3)), 2, False, ValueError, "same k"),
        (np.ones((1, 2)), np.ones((1, 2)), 2, False, ValueError, "at least 2 chains"),
        (np.ones((5, 2)), np.ones((6, 2)), 2, True, ValueError, "same shape"),
        (np.ones((5, 2)), np.ones((5, 2)), 0, False, ValueError, "order must be > 0"),
        (np.ones((5, 2)), np.ones((5, 2)), float("nan"), False, ValueError, "order must be finite"),
    ],
)
def test_richardson_romberg_bad_input(coarse, fine, order, paired, error, match):
    with pytest.raises(error, match=match):
        accuracy.richardson_romberg(coarse, fine, order, paired=paired)


# ---------------------------------------------------------------------------------------------
# Coupled levels and the step-size choice
# ---------------------------------------------------------------------------------------------

INERTIA, BETA, RADIUS = (1.0, 3.0, 5.0), 2.0, 1.2  # not the benchmarks' (1, 2, 4), 3, 1.5
BODY = rigid_body(INERTIA)


def squares(mu):
    return mu**2


def test_coupled_levels_share_one_brownian_path():
    """Levels h and h/2 of one run follow the same Brownian path: over a short time their
    per-chain averages differ much less than those of two independent runs. (Not by round-off:
    without Lévy areas the schemes are strong order 1/2 under non-commuting noise.)"""
    starts = np.asarray(RestrictedGaussian(INERTIA, BETA, RADIUS).sample(jax.random.key(0), 64))

    def run(seed):
        return accuracy.coupled_ergodic_averages(
            BODY,
            BETA,
            squares,
            levels=2,
            step_size=0.01,
            initial_positions=starts,
            rng_key=jax.random.key(seed),
            total_time=1.0,
        )

    first, second = run(1), run(2)
    assert first.step_sizes == (0.01, 0.005)
    coupled = np.sqrt(np.mean((first.chain_means[:, 0] - first.chain_means[:, 1]) ** 2))
    independent = np.sqrt(np.mean((first.chain_means[:, 0] - second.chain_means[:, 1]) ** 2))
    assert coupled < 0.3 * independent, (coupled, independent)


def test_parameter_checks():
    # Four exact draws; drawn as test_coupled_levels_share_one_brownian_path draws its 64, so
    # the sampler (compiled per number of draws) is compiled once for both.
    draws = RestrictedGaussian(INERTIA, BETA, RADIUS).sample(jax.random.key(0), 64)
    starts = np.asarray(draws)[:4]
    common = {"observables": squares, "initial_positions": starts, "rng_key": jax.random.key(0)}
    with pytest.raises(ValueError, match="tolerance must be > 0"):
        accuracy.choose_step_size(BODY, BETA, 0.0, **common)
    with pytest.raises(ValueError, match=r"sigmas\[1\] must be > 0"):
        accuracy.choose_step_size(BODY, BETA, 0.01, sigmas=(1.0, -1.0), **common)
    with pytest.raises(ValueError, match="sigmas must be a non-empty sequence"):
        accuracy.choose_step_size(BODY, BETA, 0.01, sigmas=(), **common)
    with pytest.raises(ValueError, match="chains >= 2"):
        accuracy.coupled_ergodic_averages(
            BODY,
            BETA,
            squares,
            step_size=0.1,
            initial_positions=starts[:1],
            rng_key=jax.random.key(0),
            total_time=1.0,
        )
    with pytest.raises(ValueError, match="burn_in"):
        accuracy.coupled_ergodic_averages(
            BODY,
            BETA,
            squares,
            step_size=0.1,
            initial_positions=starts,
            rng_key=jax.random.key(0),
            total_time=1.0,
            burn_in=2.0,
        )
    with pytest.raises(ValueError, match="levels must be an integer >= 1"):
        accuracy.coupled_ergodic_averages(
            BODY,
            BETA,
            squares,
            step_size=0.1,
            levels=0,
            initial_positions=starts,
            rng_key=jax.random.key(0),
            total_time=1.0,
        )
    with pytest.raises(ValueError, match="beta is required"):
        accuracy.coupled_ergodic_averages(
            BODY,
            None,
            squares,
            step_size=0.1,
            initial_positions=starts,
            rng_key=jax.random.key(0),
            total_time=1.0,
        )


def _delivered(system, beta, choice, observables, starts, exact, total_time, seed):
    """Production run at the chosen setting with fresh keys: a coupled 3-level run at
    ``4h*, 2h*, h*`` (it reuses the pilot's compiled executable); level 2 is the production run
    at ``h*``, level 0 a 4× larger step. Returns (errors, mcses), each of shape (levels, k)."""
    run = accuracy.coupled_ergodic_averages(
        system,
        beta,
        observables,
        step_size=4 * choice.step_size,
        levels=3,
        integrator=choice.integrator,
        sigma=choice.sigma,
        initial_positions=starts,
        rng_key=jax.random.key(seed),
        total_time=total_time,
        burn_in=5.0,
    )
    assert not np.any(run.nonfinite_steps)
    return run.estimate - exact, run.mcse


@pytest.mark.slow  # a long statistical run (pilot and production ensembles); the knob's parts
# (Richardson–Romberg, the coupled levels, the parameter checks) run by default above
def test_chosen_step_delivers_the_tolerance_on_another_rigid_body():
    """Tolerance 0.004 on E[μ_i²] of a rigid body the defaults were not tuned on, σ chosen among
    (0.5, 1, 2). Pilot: 256 chains × 40 time units at h, h/2, h/4 (coupled). Production: the same
    chains × 200 time units at the chosen (h*, σ), new keys: |error| ≤ 0.004 + 4 MCSE; at 4h* the
    error exceeds the tolerance by more than 4 MCSE (the choice matters)."""
    tolerance = 0.004
    target = RestrictedGaussian(INERTIA, BETA, RADIUS)
    exact = np.diag(np.asarray(target.second_moments()))
    starts = np.asarray(target.sample(jax.random.key(3), 256))
    choice = accuracy.choose_step_size(
        BODY,
        BETA,
        tolerance,
        observables=squares,
        initial_positions=starts,
        rng_key=jax.random.key(4),
        sigmas=(0.5, 1.0, 2.0),
        pilot_time=40.0,
    )
    assert choice.integrator == "splitting"
    assert np.all(choice.predicted_bias_bound <= tolerance * (1 + 1e-9))
    assert len(choice.candidates) == 3 and choice.pilot_wall_time > 0
    errors, mcses = _delivered(BODY, BETA, choice, squares, starts, exact, 200.0, 5)
    assert np.all(np.abs(errors[2]) <= tolerance + 4 * mcses[2]), (errors, mcses, choice)
    # Power: a step 4× larger than the chosen one misses the tolerance by more than 4 MCSE.
    assert np.max(np.abs(errors[0]) - 4 * mcses[0]) > tolerance, (errors, mcses)


HT_INERTIA, HT_CHI, HT_BETA = (1.0, 1.5, 2.5), (0.2, 0.0, 1.0), 2.0
HT_MU0 = np.array([0.5, 0.0, 0.0, 1.0, 0.0, 0.0])


@pytest.mark.slow  # a second system beside the rigid-body case
def test_chosen_step_delivers_the_tolerance_on_the_heavy_top():
    """Heavy top (observables Γ·χ and Π_i²), tolerance 0.01, σ = 1: pilot 128 chains × 40 time
    units; production 128 chains × 200 time units from exact draws: |error| ≤ 0.01 + 4 MCSE."""
    tolerance = 0.01
    system = heavy_top(HT_INERTIA, mgl=1.0, chi=HT_CHI)
    reference = system.reference(HT_BETA, HT_MU0)
    exact = np.r_[reference.mean_gamma_chi(), reference.pi_second_moments()]
    chi = jnp.asarray(HT_CHI)

    def observables(mu):
        return jnp.concatenate([jnp.dot(mu[3:], chi)[None], mu[:3] ** 2])

    starts = np.asarray(reference.sample(jax.random.key(7), 128))
    choice = accuracy.choose_step_size(
        system,
        HT_BETA,
        tolerance,
        observables=observables,
        initial_positions=starts,
        rng_key=jax.random.key(8),
        pilot_step_size=0.8,
        pilot_time=40.0,
    )
    assert np.all(choice.predicted_bias_bound <= tolerance * (1 + 1e-9))
    errors, mcses = _delivered(system, HT_BETA, choice, observables, starts, exact, 200.0, 9)
    assert np.all(np.abs(errors[2]) <= tolerance + 4 * mcses[2]), (errors, mcses, choice)


@pytest.mark.slow
def test_chosen_step_delivers_the_tolerance_on_the_spin_chain():
    """Open Heisenberg chain of 8 spins, β = 2, J = 1: E[s_k·s_{k+n}] for n = 1, 2 averaged over
    k against Fisher's u^n. Tolerance 0.005; pilot 128 chains × 40 time units, production
    128 chains × 400: |error| ≤ 0.005 + 4 MCSE."""
    tolerance, beta, length = 0.005, 2.0, 8
    system = heisenberg((length,))
    exact = heisenberg_chain_correlation(np.array([1, 2]), beta)

    def observables(s):
        return jnp.stack(
            [jnp.mean(jnp.sum(s[:-1] * s[1:], -1)), jnp.mean(jnp.sum(s[:-2] * s[2:], -1))]
        )

    x = np.random.default_rng(10).normal(size=(128, length, 3))
    starts = x / np.linalg.norm(x, axis=-1, keepdims=True)
    choice = accuracy.choose_step_size(
        system,
        beta,
        tolerance,
        observables=observables,
        initial_positions=starts,
        rng_key=jax.random.key(11),
        pilot_time=40.0,
    )
    errors, mcses = _delivered(system, beta, choice, observables, starts, exact, 400.0, 12)
    assert np.all(np.abs(errors[2]) <= tolerance + 4 * mcses[2]), (errors, mcses, choice)
