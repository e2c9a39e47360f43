"""The sampler as a BlackJAX algorithm: interop, jit/vmap, clear errors on bad input, and the
non-finite guard (a step that produces NaN/inf is rejected and flagged)."""

import math
import warnings

import blackjax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from blackjax.util import run_inference_algorithm

import liesample
from liesample import lie_poisson_langevin
from liesample.integrators import INTEGRATORS
from liesample.run.runner import NonFiniteStateError, sample_chains
from liesample.samplers.orbit import lie_poisson_langevin as module
from liesample.samplers.orbit.lie_poisson_langevin import LiePoissonInfo, LiePoissonState

SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
MU0 = np.array([0.6, 1.0, 0.8])
KEY = jax.random.key(42)


def algorithm(**kwargs):
    options = {"beta": 3.0, "sigma": 1.0, "step_size": 0.05}
    options.update(kwargs)
    return lie_poisson_langevin(SYSTEM, **options)


# ---------------------------------------------------------------------------------------------
# BlackJAX interop
# ---------------------------------------------------------------------------------------------


def test_top_level_api_is_a_blackjax_sampling_algorithm():
    sampler = algorithm()
    assert isinstance(sampler, blackjax.base.SamplingAlgorithm)
    assert isinstance(lie_poisson_langevin, blackjax.GenerateSamplingAPI)
    assert lie_poisson_langevin.init is module.init
    assert lie_poisson_langevin.build_kernel is module.build_kernel


def test_init_needs_no_key_and_ignores_one():
    sampler = algorithm()
    state = sampler.init(MU0)
    assert isinstance(state, LiePoissonState)
    np.testing.assert_array_equal(state.position, MU0)
    assert state.position.dtype == jnp.float64
    assert float(state.reference_casimirs) == pytest.approx(float(np.sum(MU0**2)), rel=1e-15)
    keyed = sampler.init(MU0, jax.random.key(1))
    np.testing.assert_array_equal(keyed.position, state.position)
    np.testing.assert_array_equal(keyed.reference_casimirs, state.reference_casimirs)
    # The module-level init, GenerateSamplingAPI style.
    np.testing.assert_array_equal(lie_poisson_langevin.init(MU0, SYSTEM).position, MU0)


def test_step_is_reproducible_and_matches_build_kernel():
    sampler = algorithm(integrator="rkmk_heun")
    state = sampler.init(MU0)
    step = sampler.step  # eager: one step shares compiled operations, a jit compiles its own
    new_state, _ = step(KEY, state)
    again, _ = step(KEY, state)
    np.testing.assert_array_equal(new_state.position, again.position)
    assert not np.allclose(new_state.position, MU0)
    kernel = lie_poisson_langevin.build_kernel(SYSTEM, "rkmk_heun", liesample.Scene())
    direct, _ = kernel(KEY, state, 0.05, 1.0, 0.5 * 3.0 * 1.0**2)
    np.testing.assert_allclose(direct.position, new_state.position, rtol=0, atol=1e-15)
    # A different key gives a different move.
    other, _ = step(jax.random.key(43), state)
    assert not np.allclose(other.position, new_state.position)


def test_info_fields():
    assert LiePoissonInfo._fields == ("is_divergent", "acceptance_rate", "energy", "casimir_error")
    sampler = algorithm()
    state, info = sampler.step(KEY, sampler.init(MU0))
    mu = np.asarray(state.position)
    assert float(info.energy) == pytest.approx(0.5 * np.sum(mu**2 / [1.0, 2.0, 4.0]), rel=1e-14)
    expected_drift = abs(np.sum(mu**2) - np.sum(MU0**2)) / np.sum(MU0**2)
    assert float(info.casimir_error) == pytest.approx(expected_drift, abs=1e-16)
    assert info.is_divergent.dtype == jnp.bool_ and not bool(info.is_divergent)


def test_run_inference_algorithm():
    """BlackJAX's driver passes a key to ``init``; the sampler accepts and ignores it."""
    sampler = algorithm()
    final, (states, infos) = run_inference_algorithm(KEY, sampler, 200, initial_position=MU0)
    assert states.position.shape == (200, 3)
    assert infos.energy.shape == infos.casimir_error.shape == infos.is_divergent.shape == (200,)
    np.testing.assert_array_equal(final.position, states.position[-1])
    assert not np.any(infos.is_divergent)
    assert np.max(infos.casimir_error) < 1e-13  # 200 steps of round-off
    # It moved around the orbit.
    assert np.ptp(np.asarray(states.position), axis=0).min() > 0.1


def test_jit_and_vmap_over_chains():
    sampler = algorithm(integrator="splitting")
    positions = jnp.asarray(np.random.default_rng(0).normal(size=(5, 3)))
    keys = jax.random.split(KEY, 5)
    states = liesample.jit(jax.vmap(sampler.init))(positions)
    np.testing.assert_array_equal(states.position, positions)
    new_states, infos = liesample.jit(jax.vmap(sampler.step))(keys, states)
    assert new_states.position.shape == (5, 3)
    assert infos.energy.shape == infos.casimir_error.shape == infos.is_divergent.shape == (5,)
    # Each chain is the unbatched step with its own key (batching may reorder float ops:
    # agree to ~ulp, 1e-13 absolute on O(1) numbers).
    step = sampler.step  # the unbatched step, eager (operations shared with the eager steps below)
    for c in range(5):
        single, _ = step(keys[c], sampler.init(positions[c]))
        np.testing.assert_allclose(new_states.position[c], single.position, rtol=0, atol=1e-13)
    # Chains with different positions/keys do differ.
    assert len({tuple(np.round(np.asarray(p), 6)) for p in new_states.position}) == 5


# ---------------------------------------------------------------------------------------------
# Bad input gets a clear error
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "inertia",
    [
        (0.0, 2.0, 4.0),
        (1.0, -2.0, 4.0),
        (1.0, 2.0),
        (1.0, 2.0, 3.0, 4.0),
        ((1.0, 2.0, 3.0),),
        (1.0, math.nan, 4.0),
        (1.0, 2.0, math.inf),
        (-math.inf, 2.0, 4.0),
    ],
)
def test_bad_inertia(inertia):
    with pytest.raises(ValueError, match="inertia"):
        liesample.systems.rigid_body(inertia)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"beta": math.nan}, "beta"),
        ({"beta": math.inf}, "beta"),
        ({"beta": -math.inf}, "beta"),
        ({"sigma": -0.5}, "sigma"),
        ({"sigma": math.nan}, "sigma"),
        ({"sigma": math.inf}, "sigma"),
        ({"beta": None, "sigma": 1.0}, "beta"),
        ({"beta": 2.0, "sigma": 1.0, "theta": 1.0}, "theta"),
        ({"beta": 2.0, "sigma": 0.0}, "beta"),
        ({"beta": None, "sigma": 0.0, "theta": -1.0}, "theta"),
        ({"beta": None, "sigma": 0.0, "theta": math.nan}, "theta"),
        ({"step_size": 0.0}, "step_size"),
        ({"step_size": -0.1}, "step_size"),
        ({"step_size": math.nan}, "step_size"),
        ({"step_size": math.inf}, "step_size"),
        ({"integrator": "runge_kutta_17"}, "integrator"),
        ({"beta": None, "sigma": 0.0, "hamiltonian": False}, "effect"),
    ],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        algorithm(**kwargs)


def test_bad_parameter_types():
    with pytest.raises(TypeError, match="hamiltonian"):
        algorithm(hamiltonian="yes")
    with pytest.raises(TypeError, match="system"):
        lie_poisson_langevin("rigid body", beta=1.0, step_size=0.1)
    with pytest.raises(TypeError, match="step_size"):
        algorithm(step_size=np.array([0.1, 0.2]))


@pytest.mark.parametrize(
    ("position", "match"),
    [
        (np.zeros(3), "degenerate"),
        (np.array([0.0, math.nan, 1.0]), "finite"),
        (np.array([math.inf, 0.0, 1.0]), "finite"),
        (np.array([1.0, 2.0]), "shape"),
        (np.ones((3, 1)), "shape"),
        (np.ones((2, 3)), "shape"),
    ],
)
def test_bad_initial_position(position, match):
    sampler = algorithm()
    with pytest.raises(ValueError, match=match) as error:
        sampler.init(position)
    assert "position" in str(error.value)


@pytest.mark.parametrize("beta", [-5.0, -1e-3, 0.0, 0, 1e-8, 2, 3.0, 1e4, np.float32(1.5)])
def test_every_finite_beta_is_valid(beta):
    # β = 1e4 is far beyond the stability bound at this step: only validity is tested here.
    sampler = lie_poisson_langevin(
        SYSTEM, beta=beta, sigma=0.5, step_size=0.01, integrator="lie_euler", stability="off"
    )
    # Eager: the cases share the compiled operations (same shapes), where a jit of each
    # sampler's step compiled its own program (~0.6 s of CPU a case); test_jit_and_vmap_over_chains
    # checks the step under jit.
    state, info = sampler.step(KEY, sampler.init(MU0))
    assert np.all(np.isfinite(np.asarray(state.position)))
    assert not bool(info.is_divergent)


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_every_integrator_by_name(integrator):
    sampler = algorithm(integrator=integrator)
    state, info = sampler.step(KEY, sampler.init(MU0))  # eager, as above
    assert np.all(np.isfinite(np.asarray(state.position))) and not bool(info.is_divergent)


# ---------------------------------------------------------------------------------------------
# Non-finite guard
# ---------------------------------------------------------------------------------------------


def unstable():
    """Ambient Euler–Heun at dt = 50 with θ = 500: |μ| grows ~cubically and overflows in ~3
    steps."""
    return lie_poisson_langevin(
        SYSTEM, beta=1e3, sigma=1.0, step_size=50.0, integrator="euler_heun"
    )


def test_nonfinite_step_is_flagged_and_rejected():
    _, (states, infos) = run_inference_algorithm(KEY, unstable(), 20, initial_position=MU0)
    flags = np.asarray(infos.is_divergent)
    positions = np.asarray(states.position)
    assert flags.any()
    assert np.all(np.isfinite(positions))
    # A flagged step keeps the previous state exactly.
    previous = np.concatenate([MU0[None], positions[:-1]])
    np.testing.assert_array_equal(positions[flags], previous[flags])
    # And an accepted step does move.
    assert not np.array_equal(positions[~flags][0], MU0)


def test_runner_warns_on_nonfinite():
    positions = np.stack([MU0, 2.0 * MU0])
    with pytest.warns(RuntimeWarning, match="non-finite"):
        result = sample_chains(
            unstable(), KEY, positions, 10, progress_bar=False, on_nonfinite="warn"
        )
    assert result.info["is_divergent"].any()
    assert np.all(np.isfinite(result.positions))


def test_runner_raises_on_nonfinite():
    positions = np.stack([MU0, 2.0 * MU0])
    with pytest.raises(NonFiniteStateError, match="non-finite"):
        sample_chains(unstable(), KEY, positions, 10, progress_bar=False, on_nonfinite="raise")


def test_runner_is_silent_on_a_stable_run():
    positions = np.stack([MU0, 2.0 * MU0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = sample_chains(
            algorithm(), KEY, positions, 10, progress_bar=False, on_nonfinite="raise"
        )
    assert not result.info["is_divergent"].any()
