"""What every sampler promises, checked over the registry of ``tests/cases.py``.

For each sampler row (a new sampler is one new row there):

- the Info contract: the ``info`` of each of a few steps passes ``check_info``, one scalar per
  field and step, ``is_divergent`` a bool (false from a good start), ``acceptance_rate`` in
  [0, 1], ``energy`` finite;
- the batched-step guard: steps vmapped over the chains and compiled by ``liesample.jit`` (the
  runner's own chunk program, whose draws the other tests also read) give each chain its
  single-chain steps to round-off (the runner and every statistical test rely on it; an XLA:CPU
  miscompile once broke it, ``tests/stability/test_stability.py``);
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
from liesample.integrators.chain_loop import run_steps
from liesample.samplers.contract import CONTRACT_FIELDS, check_info, energy_name

KEY = jax.random.key(17)
NUM_DRAWS = 10  # also the steps of the batched-step guard
CHUNK_DRAWS = 5  # one chunk length: the run, the saved run and its resume share one program

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


def _abstract_step(case, sampler):
    """The shapes and dtypes of one chain's state and of one step's info (nothing compiled)."""
    state = jax.eval_shape(sampler.init, _chain(case.starts(), 0))
    return state, jax.eval_shape(sampler.step, jax.random.key(0), state)[1]


@pytest.fixture(scope="module")
def single_chains(case, sampler):
    """Each chain of the runner's loop compiled alone by ``liesample.jit`` (no ``vmap``): the
    ``NUM_DRAWS`` steps of ``run_steps`` from step 0 with the runner's chain key
    (``split(KEY)[c]``, noise blocks included), every step's position and info."""
    state, info = _abstract_step(case, sampler)
    empty = jax.tree.map(
        lambda v: jnp.zeros((NUM_DRAWS, *v.shape), v.dtype), (state.position, info)
    )

    @liesample.jit
    def steps(key, position):
        def update(step, state, info, carry):
            return jax.tree.map(
                lambda out, leaf: out.at[step].set(leaf), carry, (state.position, info)
            )

        return run_steps(sampler, key, sampler.init(position), 0, NUM_DRAWS, update, empty)[1]

    keys = jax.random.split(KEY, cases.NUM_CHAINS)
    starts = case.starts()
    return [steps(keys[chain], _chain(starts, chain)) for chain in range(cases.NUM_CHAINS)]


def test_every_step_meets_the_info_contract(case, sampler, single_chains):
    """Each step the runner takes (``run_steps``: through noise blocks where the sampler has
    them) meets the contract; ``sampler.step`` itself returns the same fields, one scalar each."""
    _, info = _abstract_step(case, sampler)
    check_info(info)
    assert info._fields == single_chains[0][1]._fields
    for field in CONTRACT_FIELDS:
        assert getattr(info, field).shape == (), field
    assert info.is_divergent.dtype == jnp.bool_
    for _, infos in single_chains:
        check_info(infos)
        assert set(CONTRACT_FIELDS) <= set(infos._fields)
        for field in CONTRACT_FIELDS:  # one scalar per step
            assert jnp.shape(getattr(infos, field)) == (NUM_DRAWS,), field
        assert infos.is_divergent.dtype == jnp.bool_ and not np.any(infos.is_divergent)
        rates = np.asarray(infos.acceptance_rate)
        assert np.all((rates >= 0.0) & (rates <= 1.0))
        assert np.all(np.isfinite(np.asarray(infos.energy)))


def test_batched_steps_equal_the_single_chain_steps(uninterrupted, single_chains):
    """The runner's steps, vmapped over both chains and compiled by ``liesample.jit`` (its
    chunk program), equal each chain's own steps compiled alone, to round-off."""
    for chain, (single, infos) in enumerate(single_chains):
        _assert_trees_equal(_chain(uninterrupted.positions, chain), single, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(uninterrupted.info["is_divergent"][chain], infos.is_divergent)


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
