"""What every sampler promises, checked over the registry of ``tests/cases.py``.

For each sampler row (a new sampler is one new row there):

- the Info contract: the ``info`` of each of a few steps passes ``check_info``, one scalar per
  field and step, ``is_divergent`` a bool (false from a good start), ``acceptance_rate`` in
  [0, 1], ``energy`` finite;
- the batched-step guard: steps vmapped over the chains and compiled by ``liesample.jit`` give
  each chain its single-chain steps to round-off (the runner and every statistical test rely on
  it; an XLA:CPU miscompile once broke it, ``tests/stability/test_stability.py``);
- array and pytree positions through ``liesample.sample``: one posterior variable per leaf with
  dims ``(chain, draw, …)`` (complex leaves split into ``.real`` and ``.imag``), holding the
  draws of ``sample_chains``, and the contract's fields in ``sample_stats``;
- resume: a run saved with ``output=`` and continued with ``resume=True`` gives exactly the
  draws and info of one uninterrupted run, and the file then holds the whole run.
"""

import cases
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.samplers.contract import CONTRACT_FIELDS, check_info, energy_name

KEY = jax.random.key(17)
NUM_DRAWS = 6
CHUNK_DRAWS = 2
GUARD_STEPS = 10

SAMPLERS = {case.name: case for case in cases.SAMPLERS}


@pytest.fixture(scope="module", params=cases.SAMPLER_NAMES)
def case(request):
    return SAMPLERS[request.param]


@pytest.fixture(scope="module")
def sampler(case):
    return case.build()


@pytest.fixture(scope="module")
def uninterrupted(case, sampler):
    return liesample.sample_chains(
        sampler, KEY, case.starts(), NUM_DRAWS, chunk_draws=CHUNK_DRAWS, progress_bar=False
    )


def _chain(tree, index):
    return jax.tree.map(lambda leaf: leaf[index], tree)


def _assert_trees_equal(actual, expected, **tolerance):
    assert jax.tree.structure(actual) == jax.tree.structure(expected)
    for a, e in zip(jax.tree.leaves(actual), jax.tree.leaves(expected), strict=True):
        if tolerance:
            np.testing.assert_allclose(np.asarray(a), np.asarray(e), **tolerance)
        else:
            assert np.asarray(a).dtype == np.asarray(e).dtype
            np.testing.assert_array_equal(np.asarray(a), np.asarray(e))


# --------------------------------------------------------------------------- the registry


def test_the_registry_lists_every_public_sampler_and_system_once():
    samplers = {
        name for name in liesample.__all__ if hasattr(getattr(liesample, name), "differentiable")
    }  # the GenerateSamplingAPI objects
    samplers.add("jittered_magnetic_hmc")  # a function returning a sampler
    assert sorted(cases.SAMPLER_NAMES) == sorted(samplers)
    systems = set(liesample.systems.__all__) - {"LiePoissonSystem"} - set(cases.NOT_SAMPLED)
    assert sorted(cases.SYSTEM_NAMES) == sorted(systems)


# --------------------------------------------------------------------------- steps


def _steps(sampler):
    """``GUARD_STEPS`` steps of one chain, step ``k`` keyed ``fold_in(key, k)``: the final
    position and every step's info."""

    def steps(key, state):
        def one(state, index):
            return sampler.step(jax.random.fold_in(key, index), state)

        state, infos = jax.lax.scan(one, state, jnp.arange(GUARD_STEPS))
        return state.position, infos

    return steps


GUARD_KEYS = jax.random.split(jax.random.key(1), cases.NUM_CHAINS)


@pytest.fixture(scope="module")
def single_chains(case, sampler):
    """Each chain's steps, compiled alone by ``liesample.jit``."""
    steps = liesample.jit(_steps(sampler))
    starts = case.starts()
    return [
        steps(GUARD_KEYS[chain], sampler.init(_chain(starts, chain)))
        for chain in range(cases.NUM_CHAINS)
    ]


def test_every_step_meets_the_info_contract(single_chains):
    for _, infos in single_chains:
        check_info(infos)
        assert set(CONTRACT_FIELDS) <= set(infos._fields)
        for field in CONTRACT_FIELDS:  # one scalar per step
            assert jnp.shape(getattr(infos, field)) == (GUARD_STEPS,), field
        assert infos.is_divergent.dtype == jnp.bool_ and not np.any(infos.is_divergent)
        rates = np.asarray(infos.acceptance_rate)
        assert np.all((rates >= 0.0) & (rates <= 1.0))
        assert np.all(np.isfinite(np.asarray(infos.energy)))


def test_batched_steps_equal_the_single_chain_steps(case, sampler, single_chains):
    """The steps vmapped over both chains (``liesample.jit``, the runner's compile path) equal
    each chain's own steps to round-off."""
    states = jax.vmap(sampler.init)(jax.tree.map(jnp.asarray, case.starts()))
    batched, batched_infos = liesample.jit(jax.vmap(_steps(sampler)))(GUARD_KEYS, states)
    for chain, (single, infos) in enumerate(single_chains):
        _assert_trees_equal(_chain(batched, chain), single, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(_chain(batched_infos, chain).is_divergent, infos.is_divergent)


# --------------------------------------------------------------------------- positions, resume


def _variable_names(starts):
    """The posterior variables ``liesample.sample`` makes of the leaves of ``starts``: ``mu``
    for a plain array; dict keys and ``x<i>`` for tuple entries, joined by dots; ``.real`` and
    ``.imag`` for a complex leaf."""
    names = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(starts)[0]:
        parts = [
            str(entry.key) if isinstance(entry, jax.tree_util.DictKey) else f"x{entry.idx}"
            for entry in path
        ]
        name = ".".join(parts) or "mu"
        if np.iscomplexobj(leaf):
            names[f"{name}.real"] = (path, np.real)
            names[f"{name}.imag"] = (path, np.imag)
        else:
            names[name] = (path, np.asarray)
    return names


def _leaf(tree, path):
    for entry in path:
        tree = tree[entry.key if isinstance(entry, jax.tree_util.DictKey) else entry.idx]
    return tree


def _first_draws(tree, num_draws):
    return jax.tree.map(lambda leaf: leaf[:, :num_draws], tree)


def _event_dims(starts):
    """A plain array with several event axes (a spin lattice) needs its axes named."""
    if isinstance(starts, np.ndarray) and starts.ndim != 2:
        return tuple(f"axis_{k}" for k in range(starts.ndim - 1))
    return None


def test_sample_then_resume(case, sampler, uninterrupted, tmp_path):
    """``liesample.sample`` with ``output=`` names and shapes the draws of ``sample_chains``;
    resuming the saved run to more draws gives exactly the uninterrupted run."""
    starts, path = case.starts(), tmp_path / "run.nc"
    saved_draws = NUM_DRAWS - CHUNK_DRAWS
    options = {"chunk_draws": CHUNK_DRAWS, "progress": False, "output": path}
    tree = liesample.sample(
        sampler, KEY, starts, saved_draws, num_warmup=0, event_dims=_event_dims(starts), **options
    )
    expected = _first_draws(uninterrupted.positions, saved_draws)
    names = _variable_names(starts)
    assert set(tree.posterior.data_vars) == set(names)
    for name, (leaf_path, part) in names.items():
        variable = tree.posterior[name]
        event_shape = np.shape(_leaf(starts, leaf_path))[1:]
        assert variable.dims[:2] == ("chain", "draw"), name
        assert variable.shape == (cases.NUM_CHAINS, saved_draws, *event_shape), name
        np.testing.assert_array_equal(variable.values, part(_leaf(expected, leaf_path)))
    stats = tree.sample_stats
    assert {"diverging", "acceptance_rate"} <= set(stats.data_vars)
    if "energy" in uninterrupted.info:  # HMC's total energy keeps ArviZ's name; h does not
        start = jax.tree.map(lambda leaf: leaf[0], starts)
        assert energy_name(sampler, start) in stats.data_vars
        assert ("energy" in stats.data_vars) == hasattr(sampler.init(start), "momentum")
    assert stats["diverging"].dtype == bool
    assert stats["acceptance_rate"].shape == (cases.NUM_CHAINS, saved_draws)
    assert tree.attrs["sampler"] == case.name

    resumed = liesample.sample_chains(sampler, KEY, starts, NUM_DRAWS, resume=True, **options)
    _assert_trees_equal(resumed.positions, uninterrupted.positions)
    assert resumed.info.keys() == uninterrupted.info.keys()
    for name in uninterrupted.info:
        np.testing.assert_array_equal(resumed.info[name], uninterrupted.info[name], err_msg=name)
    assert resumed.num_steps == uninterrupted.num_steps
    saved = liesample.load_chains(path).posterior
    for name, (leaf_path, part) in names.items():
        np.testing.assert_array_equal(saved[name], part(_leaf(uninterrupted.positions, leaf_path)))
