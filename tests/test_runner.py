"""``liesample.run.runner.sample_chains``: shapes, determinism independent of chunking, thinning and
warm-up as exact sub-sequences of the plain run, and argument checks."""

import math

import blackjax
import jax
import numpy as np
import pytest

import liesample
from liesample.run import loop
from liesample.run.runner import sample_chains

SYSTEM = liesample.systems.rigid_body((1.0, 2.0, 4.0))
# The runner does not care which integrator steps; Lie–Euler compiles fastest.
ALGORITHM = liesample.lie_poisson_langevin(
    SYSTEM, beta=3.0, sigma=1.0, step_size=0.05, integrator="lie_euler"
)
POSITIONS = np.array([[0.6, 1.0, 0.8], [1.0, 0.0, 0.0], [0.0, -2.0, 0.5]])
KEY = jax.random.key(17)
NUM_DRAWS = 12


def run(num_draws=NUM_DRAWS, **kwargs):
    kwargs.setdefault("progress_bar", False)
    return sample_chains(ALGORITHM, KEY, POSITIONS, num_draws, **kwargs)


@pytest.fixture(scope="module")
def plain():
    """Thinning 1, no warm-up, 60 draws in the default chunks (3 draws each): the reference."""
    return run(num_draws=60)


def test_shapes(plain):
    assert plain.positions.shape == (3, 60, 3)
    assert set(plain.info) == {"is_divergent", "acceptance_rate", "energy", "casimir_error"}
    for value in plain.info.values():
        assert value.shape == (3, 60)
    assert plain.num_steps == 60
    assert plain.wall_time > 0
    # Draws are states on each chain's own orbit, and the chains move.
    radii = np.linalg.norm(plain.positions, axis=-1)
    expected_radii = np.broadcast_to(np.linalg.norm(POSITIONS, axis=-1)[:, None], radii.shape)
    np.testing.assert_allclose(radii, expected_radii, rtol=1e-13)
    assert np.all(np.ptp(plain.positions, axis=1).max(axis=-1) > 0.05)
    # info["energy"] is h at the recorded draw.
    energy = 0.5 * np.sum(plain.positions**2 / np.array([1.0, 2.0, 4.0]), axis=-1)
    np.testing.assert_allclose(plain.info["energy"], energy, rtol=1e-13)


def test_chains_are_independent_streams(plain):
    """Chains started at the same point with the runner's per-chain keys still differ."""
    # Three chains of 5 draws in chunks of 1: the program of test_draws_do_not_depend_on_chunking
    # (chunk_draws=None), compiled once.
    same_start = sample_chains(ALGORITHM, KEY, np.stack([POSITIONS[0]] * 3), 5, progress_bar=False)
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert not np.allclose(same_start.positions[a], same_start.positions[b]), (a, b)


@pytest.mark.parametrize("chunk_draws", [None, 5, NUM_DRAWS, 50])
def test_draws_do_not_depend_on_chunking(plain, chunk_draws):
    """Draw d of chain c uses key fold_in(key_c, step): the chunk size cannot change it.

    Each chunk size is a separately compiled scan of the same step with the same keys, so the
    draws are bit-identical. The per-draw diagnostics are recomputed from them and may be fused
    differently by XLA (a length-1 scan is inlined): they agree to round-off — one ulp of the
    O(1) energy, and ~2e-16 on a relative Casimir drift that is itself round-off.
    """
    result = run(chunk_draws=chunk_draws)
    np.testing.assert_array_equal(result.positions, plain.positions[:, :NUM_DRAWS])
    np.testing.assert_allclose(
        result.info["energy"], plain.info["energy"][:, :NUM_DRAWS], rtol=4e-16, atol=0
    )
    np.testing.assert_allclose(
        result.info["casimir_error"], plain.info["casimir_error"][:, :NUM_DRAWS], rtol=0, atol=1e-15
    )
    np.testing.assert_array_equal(
        result.info["is_divergent"], plain.info["is_divergent"][:, :NUM_DRAWS]
    )


@pytest.mark.parametrize("thinning", [3, 5])
def test_thinning_keeps_every_kth_state(plain, thinning):
    num_draws = 60 // thinning
    result = run(num_draws=num_draws, thinning=thinning, chunk_draws=4)
    assert result.positions.shape == (3, num_draws, 3)
    assert result.num_steps == 60
    # Draw d is the state after (d + 1)·k steps, i.e. plain draw (d + 1)·k − 1.
    # Thinning compiles a nested loop: the same operations, fused differently, so round-off.
    np.testing.assert_allclose(
        result.positions, plain.positions[:, thinning - 1 :: thinning], rtol=0, atol=1e-14
    )
    # Diagnostics to round-off (see test_draws_do_not_depend_on_chunking): the energies of
    # states that agree to 1e-14 (h is O(1) with an O(1) gradient) agree to 1e-14.
    np.testing.assert_allclose(
        result.info["energy"], plain.info["energy"][:, thinning - 1 :: thinning], rtol=0, atol=1e-14
    )
    # casimir_error is the worst over the k steps a draw spans; is_divergent is their "any".
    blocks = plain.info["casimir_error"].reshape(3, num_draws, thinning)
    np.testing.assert_allclose(
        result.info["casimir_error"], blocks.max(axis=-1), rtol=0, atol=1e-15
    )
    # …and it is the max, not the last step's value (they differ somewhere in this run).
    assert np.any(blocks.max(axis=-1) != blocks[..., -1])
    np.testing.assert_array_equal(
        result.info["is_divergent"],
        plain.info["is_divergent"].reshape(3, num_draws, thinning).any(axis=-1),
    )


def test_warmup_is_the_start_of_the_same_run(plain):
    result = run(num_draws=10, num_warmup=25, chunk_draws=3)
    assert result.num_steps == 35
    np.testing.assert_array_equal(result.positions, plain.positions[:, 25:35])
    np.testing.assert_allclose(result.info["energy"], plain.info["energy"][:, 25:35], rtol=4e-16)


def test_warmup_with_thinning(plain):
    # The warm-up of test_warmup_is_the_start_of_the_same_run and the chunks of
    # test_thinning_keeps_every_kth_state[3]: programs compiled once.
    result = run(num_draws=8, num_warmup=25, thinning=3, chunk_draws=4)
    assert result.num_steps == 49
    np.testing.assert_allclose(
        result.positions, plain.positions[:, 25 + 2 : 49 : 3], rtol=0, atol=1e-14
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"num_draws": 0}, "num_draws"),
        ({"num_draws": -3}, "num_draws"),
        ({"num_draws": 2.5}, "num_draws"),
        ({"num_draws": "10"}, "num_draws"),
        ({"num_warmup": -1}, "num_warmup"),
        ({"num_warmup": 1.5}, "num_warmup"),
        ({"thinning": 0}, "thinning"),
        ({"thinning": -2}, "thinning"),
        ({"thinning": 2.0}, "thinning"),
        ({"on_nonfinite": "ignore"}, "on_nonfinite"),
    ],
)
def test_bad_arguments(kwargs, match):
    arguments = {"num_draws": 4}
    arguments.update(kwargs)
    num_draws = arguments.pop("num_draws")
    with pytest.raises(ValueError, match=match):
        sample_chains(ALGORITHM, KEY, POSITIONS, num_draws, progress_bar=False, **arguments)


@pytest.mark.parametrize(
    ("positions", "match"),
    [
        (np.float64(1.0), "initial_positions"),
        (np.array([[0.6, 1.0, 0.8], [math.nan, 0.0, 1.0]]), "finite"),
        (np.array([[0.6, 1.0, 0.8], [0.0, 0.0, math.inf]]), "finite"),
        (np.zeros((2, 3)), "position"),
        (np.ones((2, 2)), "position"),
    ],
)
def test_bad_initial_positions(positions, match):
    with pytest.raises(ValueError, match=match):
        sample_chains(ALGORITHM, KEY, positions, 4, progress_bar=False)


class _Runaway(RuntimeError):
    """Raised by the guard bar below instead of letting a non-terminating run hang the suite."""


class _GuardBar:
    """Stands in for tqdm: fails fast if the draw loop stops making progress."""

    def __init__(self, *args, **kwargs):
        self.calls = 0

    def update(self, count):
        self.calls += 1
        if count <= 0 or self.calls > 100:
            raise _Runaway(f"draw loop advanced by {count} (call {self.calls})")

    def set_description(self, text, refresh=True):
        pass

    def close(self):
        pass


@pytest.mark.parametrize("chunk_draws", [-1, 0, 2.5, True])
def test_bad_chunk_draws(monkeypatch, chunk_draws):
    monkeypatch.setattr(loop, "tqdm", _GuardBar)
    with pytest.raises(ValueError, match="chunk_draws"):
        sample_chains(ALGORITHM, KEY, POSITIONS, 6, progress_bar=False, chunk_draws=chunk_draws)


def test_every_distinct_start_is_checked_concretely():
    """A degenerate start in any chain (not just the first) is refused, naming the chain."""
    starts = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"initial_positions\[1\].*degenerate"):
        sample_chains(ALGORITHM, KEY, starts, 4, progress_bar=False)


def test_a_plain_blackjax_algorithm_runs_as_a_sampler_with_the_defaults(plain):
    """The runner reads a plain ``SamplingAlgorithm`` as a ``Sampler`` with the declared
    defaults (no start check, no tuning, no noise blocks): one key per step."""
    bare = liesample.samplers.contract.as_sampler(
        blackjax.base.SamplingAlgorithm(ALGORITHM.init, ALGORITHM.step)
    )
    assert bare.settings == {} and bare.check_positions is None
    assert bare.adaptation is None and bare.noise_blocks is None
    result = sample_chains(bare, KEY, POSITIONS, 4, progress_bar=False)
    settings = dict(result.settings)
    # the orbit step's info carries casimir_error, so the run records its drift (round-off)
    assert 0.0 <= settings.pop("casimir_drift") < 1e-12
    assert result.positions.shape == (3, 4, 3) and settings == {
        "num_warmup": 0,
        "adapted": False,
    }
    with pytest.raises(ValueError, match="has no warm-up adaptation"):
        sample_chains(bare, KEY, POSITIONS, 2, num_warmup=2, adapt=True, progress_bar=False)


# The Langevin sampler with the integrator of ALGORITHM (compiles fastest; its warm-up takes the
# same path, the bias model, with that integrator's order).
TUNED_OPTIONS = {"adjusted_lie_poisson": {}, "lie_poisson_langevin": {"integrator": "lie_euler"}}


@pytest.mark.parametrize(
    "name",
    [
        # slow: the same promise for a second sampler; the default suite checks this with the
        # [lie_poisson_langevin] case of
        # test_runner.py::test_the_warm_up_tunes_a_new_sampler_and_leaves_the_given_one
        pytest.param("adjusted_lie_poisson", marks=pytest.mark.slow),
        "lie_poisson_langevin",
    ],
)
def test_the_warm_up_tunes_a_new_sampler_and_leaves_the_given_one(name):
    """The step size the sampler declares tunable is chosen by the tuning layer into a new
    sampler (recorded in its settings); the sampler passed in is not changed, and its step
    never changes its settings."""
    sampler = getattr(liesample, name)(SYSTEM, beta=3.0, **TUNED_OPTIONS[name])
    assert sampler.adaptation is not None and not sampler.adaptation.given
    before = dict(sampler.settings)
    result = sample_chains(sampler, KEY, POSITIONS, 4, num_warmup=20, progress_bar=False)
    assert result.settings["adapted"] and result.settings["step_size"] > 0
    assert result.settings["step_size_source"].startswith("warm-up ")
    assert sampler.settings == before
    state = sampler.init(POSITIONS[0])
    settings = dict(sampler.settings)
    sampler.step(KEY, state)
    assert sampler.settings == settings
