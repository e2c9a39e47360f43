"""``liesample.sample``, ``sample_chains`` and every sampler's ``step`` refuse bad arguments by
name, before XLA sees them (liesample issue 43, item 2).

Each case a user met is a test named after it: a run too long for the step counter (it aborted
the interpreter inside XLA), draws that cannot fit in memory, keys of the wrong form, an object
that is not a sampler, a start without its chain axis, and out-of-range options. The runner's
first compilation is in ``_Run.start``; the autouse fixture replaces it with a sentinel, so a
refusal is shown to come before any compilation, and a run whose arguments pass reaches the
sentinel. Steps are checked with ``jax.eval_shape`` (traced, never compiled).
"""

import cases
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.run import arguments, loop

RIGID = liesample.systems.rigid_body()
ALGORITHM = liesample.lie_poisson_langevin(RIGID, beta=1.0, step_size=0.1, integrator="lie_euler")
KEY = jax.random.key(0)
STARTS = np.tile(RIGID.default_position, (2, 1))


class _Compiling(Exception):
    """Raised where the run would compile its first program: the arguments passed."""


_START = loop._Run.start  # the checks of the starts, then the first compilation


@pytest.fixture(autouse=True)
def _no_compilation(monkeypatch):
    def start(self):
        raise _Compiling

    monkeypatch.setattr(loop._Run, "start", start)


def _chains(num_draws=4, algorithm=ALGORITHM, key=KEY, starts=STARTS, **options):
    options.setdefault("progress_bar", False)
    return liesample.sample_chains(algorithm, key, starts, num_draws, **options)


def _sample(num_draws=4, **options):
    options.setdefault("progress_bar", False)
    options.setdefault("num_warmup", 0)
    options.setdefault("exact_starts", True)
    return liesample.sample(ALGORITHM, KEY, STARTS, num_draws, **options)


# --------------------------------------------------------------------------- sizes


def test_a_typo_of_10_to_the_12_draws_is_refused_before_xla():
    """The call that aborted the interpreter (SIGABRT in XLA) raises a Python error naming
    num_draws and the steps it asks for, before any compilation."""
    with pytest.raises(ValueError, match=r"num_draws=1000000000000.*steps per chain.*lower"):
        _sample(10**12)


@pytest.mark.parametrize(
    ("options", "named"),
    [
        ({"num_draws": 2**32 + 1}, r"num_draws=4294967297"),
        ({"thinning": 2**31}, r"thinning=2147483648"),
        ({"num_warmup": 2**32}, r"num_warmup=4294967296"),
    ],
)
def test_steps_beyond_the_step_counter_are_refused(options, named):
    """``num_warmup + num_draws * thinning`` must fit the chain's step counter (its index is
    folded into each step's key as 32 bits)."""
    options = {"num_draws": 4, **options}
    with pytest.raises(ValueError, match=f"{named}.*step counter"):
        _chains(**options)


def test_the_step_counter_limit_follows_the_integer_dtype_and_the_noise_blocks():
    """int32 (without x64) counts to 2**31 - 1 less a noise block's slack; int64 to 2**32."""
    blocks = ALGORITHM.noise_blocks.size
    assert arguments.max_steps(ALGORITHM) == 2**32
    with jax.enable_x64(False):
        assert arguments.max_steps(ALGORITHM) == 2**31 - 1 - (blocks - 1)
        plain = liesample.samplers.contract.Sampler(ALGORITHM.init, ALGORITHM.step)
        assert arguments.max_steps(plain) == 2**31 - 1


def test_kept_draws_beyond_host_memory_are_refused_with_the_bytes(monkeypatch):
    monkeypatch.setattr(arguments, "host_memory", lambda: 10**6)
    per_draw = 3 * 8 + 1 + 2 * 8  # the position, and the Info contract's fields
    need = 2 * 10**5 * per_draw
    with pytest.raises(ValueError, match=rf"num_draws=100000.*{need} bytes.*1000000 bytes") as e:
        _chains(10**5)
    for fix in ("num_draws", "thinning", "keep_positions=False with observables="):
        assert fix in str(e.value)
    with pytest.raises(ValueError, match="fewer or smaller observables"):
        _chains(10**5, keep_positions=False, observables=lambda mu: mu)
    with pytest.raises(_Compiling):  # a scalar observable a draw fits
        _chains(10**4, keep_positions=False, observables=lambda mu: mu[0])


def test_a_chunk_beyond_device_memory_is_refused_naming_chunk_draws(monkeypatch):
    monkeypatch.setattr(arguments, "device_memory", lambda devices: (10**5, "gpu device memory"))
    with pytest.raises(ValueError, match=r"chunk_draws=10000 .*gpu device memory.*100000 bytes"):
        _chains(10**4, chunk_draws=10**4)
    with pytest.raises(ValueError, match=r"thinning=100000.*window of 100000 steps"):
        _chains(4, thinning=10**5)
    with pytest.raises(_Compiling):  # the fix the message names
        _chains(10**4, chunk_draws=100)


def test_device_memory_reads_memory_stats_else_the_host():
    class Device:
        platform = "gpu"

        def __init__(self, stats):
            self.stats = stats

        def memory_stats(self):
            return self.stats

    devices = [Device({"bytes_limit": 100, "bytes_in_use": 30}), Device({"bytes_limit": 50})]
    assert arguments.device_memory(devices) == (50, "gpu device memory")
    assert arguments.device_memory([Device(None)]) == (arguments.host_memory(), "host memory")
    assert arguments.host_memory() > 0


# --------------------------------------------------------------------------- keys


@pytest.mark.parametrize(
    "key", [jax.random.key(3), jax.random.PRNGKey(3), np.asarray(jax.random.PRNGKey(3))]
)
def test_a_run_accepts_either_key_style(key):
    with pytest.raises(_Compiling):
        _chains(key=key)


@pytest.mark.parametrize(
    ("key", "error", "match"),
    [
        (jax.random.split(KEY, 2), ValueError, r"one key, got a batch.*splits it over the chains"),
        (jax.random.split(jax.random.PRNGKey(0), 2), ValueError, r"one key, got a batch"),
        (0, TypeError, r"integer 0, a seed, not a key: pass jax.random.key\(0\)"),
        (np.zeros(3, np.uint32), TypeError, r"rng_key must be a JAX random key"),
        (None, TypeError, r"rng_key must be a JAX random key"),
    ],
)
def test_a_run_refuses_a_batch_of_keys_or_a_seed_by_name(key, error, match):
    with pytest.raises(error, match=match):
        _chains(key=key)
    with pytest.raises(error, match=match):
        liesample.sample(ALGORITHM, key, STARTS, 4, progress_bar=False)


@pytest.fixture(scope="module")
def registry():
    """Every registered sampler, built once."""
    return {case.name: case.build() for case in cases.SAMPLERS}


def _abstract_starts(name):
    """A registry row's starts as shapes and dtypes, traced: the hot starts of the
    ``wilson_heat_bath`` row are not drawn (that would compile the Haar draw)."""
    if name == "wilson_heat_bath":
        one = jax.eval_shape(liesample.systems.wilson_gauge("SU2", (4, 4)).hot_start, KEY)
        return jax.ShapeDtypeStruct((2, *one.shape), one.dtype)  # the row's two starts
    return jax.eval_shape({case.name: case for case in cases.SAMPLERS}[name].starts)


TRACED = {"wilson_heat_bath", "lie_poisson_langevin"}
"""The samplers whose traced steps the default suite checks: the one whose step an old key
crashed, and the runner tests' own; the others are traced by ``make test-slow``."""


@pytest.mark.parametrize(
    "name",
    [
        name if name in TRACED else pytest.param(name, marks=pytest.mark.slow)
        for name in cases.SAMPLER_NAMES
    ],
)
def test_every_sampler_step_takes_old_keys_even_traced(registry, name):
    """Old-style ``PRNGKey`` data (which crashed ``wilson_heat_bath``'s step with a reshape
    error) vmapped over the chains: the step is traced with each chain's key as a uint32
    tracer of shape (2,), and steps as with a typed key."""
    sampler = registry[name]
    states = jax.eval_shape(jax.vmap(sampler.init), _abstract_starts(name))
    num_chains = jax.tree.leaves(states)[0].shape[0]
    old = jax.random.split(jax.random.PRNGKey(0), num_chains)  # uint32 data (chains, 2)
    typed = jax.random.split(jax.random.key(0), num_chains)
    stepped = [jax.eval_shape(jax.vmap(sampler.step), keys, states) for keys in (old, typed)]
    assert stepped[0] == stepped[1]


@pytest.mark.parametrize("name", cases.SAMPLER_NAMES)
def test_every_sampler_step_refuses_a_seed_or_a_batch_of_keys_by_name(registry, name):
    """The key is read before the state: nothing is traced."""
    sampler = registry[name]
    with pytest.raises(TypeError, match=r"rng_key must be a JAX random key.*jax.random.key\(0\)"):
        sampler.step(0, None)
    for keys in (jax.random.split(KEY, 2), jax.random.split(jax.random.PRNGKey(0), 2)):
        with pytest.raises(ValueError, match=r"rng_key must be one key.*jax.vmap\(sampler.step\)"):
            sampler.step(keys, None)


# --------------------------------------------------------------------------- the algorithm


@pytest.mark.parametrize(
    ("algorithm", "match"),
    [
        (lambda k, s: s, r"got the function '<lambda>'.*SamplingAlgorithm\(init, step\)"),
        (liesample.lie_poisson_langevin, r"sampler family lie_poisson_langevin itself.*call it"),
        (RIGID, r"algorithm must be a sampler.*got LiePoissonSystem"),
        (None, r"algorithm must be a sampler.*got NoneType"),
    ],
)
def test_an_object_that_is_not_a_sampler_is_refused_naming_what_is_expected(algorithm, match):
    with pytest.raises(TypeError, match=match) as e:
        _chains(algorithm=algorithm)
    assert "a liesample sampler" in str(e.value) and "BlackJAX SamplingAlgorithm" in str(e.value)


# --------------------------------------------------------------------------- starts


def test_a_start_without_a_chain_axis_shows_the_fix(monkeypatch):
    """One start of shape (3,) is read as 3 chains of scalars; the error says so and shows how
    to add the chain axis (which then passes). The probe runs only when ``_Run.start`` fails (the
    checks of the starts, before the chains' states are built)."""

    def init_states(self, sampler):
        raise _Compiling

    monkeypatch.setattr(loop._Run, "start", _START)
    monkeypatch.setattr(loop._Run, "_init_states", init_states)
    with pytest.raises(ValueError, match=r"needs a leading chain axis.*shape \(3,\)") as e:
        _chains(starts=RIGID.default_position)
    assert "x[None]" in str(e.value) and "jnp.tile(x, (num_chains, 1))" in str(e.value)
    x = jnp.asarray(RIGID.default_position)
    for starts in (x[None], jnp.tile(x, (2, 1))):
        with pytest.raises(_Compiling):
            _chains(starts=starts)


# --------------------------------------------------------------------------- options


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"min_acceptance_rate": 2}, ValueError, r"min_acceptance_rate must be in \[0, 1\)"),
        ({"min_acceptance_rate": 1.0}, ValueError, r"min_acceptance_rate must be in \[0, 1\)"),
        ({"min_acceptance_rate": -0.1}, ValueError, "min_acceptance_rate"),
        ({"min_acceptance_rate": "0.1"}, TypeError, "min_acceptance_rate"),
        ({"on_nonfinite": "ignore"}, ValueError, r"on_nonfinite must be 'warn' or 'raise'"),
        ({"on_nonfinite": ["warn"]}, ValueError, r"on_nonfinite must be 'warn' or 'raise'"),
        ({"progress_bar": "yes"}, TypeError, "progress_bar must be a bool, True or False"),
        ({"progress_bar": None}, TypeError, "progress_bar must be a bool, True or False"),
        ({"devices": "gpu"}, ValueError, r"devices must be None, 'all'"),
        ({"devices": 0}, ValueError, "devices must be between 1 and"),
        ({"devices": [1]}, TypeError, "devices must be a non-empty sequence of jax.Device"),
        ({"chunk_draws": 0}, ValueError, r"chunk_draws must be None or an integer >= 1"),
        ({"thinning": 0}, ValueError, r"thinning must be an integer >= 1"),
        ({"num_warmup": -1}, ValueError, r"num_warmup must be an integer >= 0"),
        ({"num_draws": 0}, ValueError, r"num_draws must be an integer >= 1"),
        ({"adapt": 1}, TypeError, "adapt must be None, True or False"),
        ({"adapt": True}, ValueError, r"adapt=True needs warm-up steps"),
        ({"resume": 1}, TypeError, "resume must be a bool, True or False"),
        ({"resume": True}, ValueError, r"resume=True needs output="),
        ({"output": 3}, TypeError, r"output must be None or the path of the run file"),
        ({"keep_positions": 0}, TypeError, "keep_positions must be a bool, True or False"),
        ({"keep_positions": False}, ValueError, r"pass observables="),
        ({"observables": 3}, TypeError, "observables must be a function of the position"),
        ({"observables": {}}, ValueError, "observables is an empty dict"),
        ({"log_likelihood": 3}, TypeError, "log_likelihood must be a non-empty dict"),
        ({"callback": 3}, TypeError, "callback must be a function of draws_done"),
    ],
)
def test_every_option_of_sample_chains_is_refused_by_name(options, error, match):
    """``min_acceptance_rate=2`` was accepted (every chain then read as stuck); each bad value
    of each keyword is refused with what is allowed, before compilation."""
    options = {"num_draws": 4, **options}
    with pytest.raises(error, match=match):
        _chains(**options)


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"min_acceptance_rate": 2}, ValueError, r"min_acceptance_rate must be in \[0, 1\)"),
        ({"num_warmup": 2.5}, ValueError, r"num_warmup must be an integer >= 0"),
        ({"exact_starts": 1}, TypeError, "exact_starts must be a bool"),
        ({"var_name": 3}, TypeError, "var_name must be None or a non-empty string"),
        ({"event_dims": "component"}, TypeError, "event_dims must be a list or tuple"),
        ({"event_dims": {"mu": 3}}, TypeError, r"event_dims\['mu'\] must be a list or tuple"),
        ({"coords": 3}, TypeError, r"coords must be None or a mapping \{dim name"),
        ({"coords": {"component": 3}}, TypeError, r"coords\['component'\] must be the 1-D"),
        ({"attrs": 3}, TypeError, "attrs must be None or a mapping"),
        ({"num_draw": 4}, TypeError, r"unknown keywords \['num_draw'\]"),
        ({"output": 3, "resume": True}, TypeError, "output must be None or the path"),
    ],
)
def test_every_keyword_of_sample_is_refused_by_name(options, error, match):
    with pytest.raises(error, match=match):
        _sample(**options)


def test_good_options_reach_compilation():
    """The checks refuse only what is wrong: every keyword at a good value passes them."""
    with pytest.raises(_Compiling):
        _sample(
            thinning=2, chunk_draws=2, min_acceptance_rate=0.0, on_nonfinite="raise",
            devices=1, adapt=False, observables={"m": lambda mu: mu[0]}, callback=print,
            var_name="m_vec", event_dims=("axis",), coords={"axis": ["a", "b", "c"]},
            attrs={"note": "ok"}, log_likelihood={"y": lambda mu: -jnp.sum(mu**2)},
        )  # fmt: skip
