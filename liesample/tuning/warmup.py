"""The warm-up :func:`liesample.sample` runs: what an orbit sampler declares tunable, chosen or
tuned through the adaptation protocol (:mod:`liesample.tuning.protocol`).

A sampler declares what its warm-up tunes (``Sampler.adaptation``, a
:class:`liesample.samplers.contract.Tunable`); :func:`adaptation_of` makes the
:class:`liesample.tuning.protocol.Adaptation` of that declaration and
:func:`liesample.tuning.protocol.run_adaptation` runs it:

- ``"dual_averaging"``: :func:`liesample.tuning.protocol.step_size_adaptation`, the step shared
  by the chains tuned to a target of their pooled acceptance rate;
- ``"rule"``: :func:`liesample.tuning.protocol.fixed`, the step computed from the starts with a
  key of the run (``choose(positions, fold_in(rng_key, 1))``), nothing learnt from the
  transitions (the unadjusted sampler's bias model);
- ``"window"`` (the T*G samplers, :func:`window_warm_up`): Stan's windows of
  :func:`liesample.window_adaptation` (:func:`liesample.tuning.windows.windows_adaptation` run
  by :func:`liesample.tuning.protocol.run_adaptation`), all chains together: one step size,
  the mass pooled over the chains and, for HMC, one integration time;
- ``"chees"`` (``magnetic_hmc(logdensity_fn)``, :func:`window_warm_up`):
  :func:`liesample.magnetic_window_adaptation` on every chain together, then
  :func:`liesample.samplers.cotangent.magnetic_hmc.jittered_magnetic_hmc`.

:func:`choose_from_starts` is the same declaration without a warm-up (the step size left unset):
the sampler's own automatic step for the run's starts (``choose(positions, None)``).

Each ends in numbers; the tuned sampler is the sampler's recipe called with them
(:class:`liesample.samplers.contract.Recipe`: the chosen step, and how it was chosen, in its
``settings``); the sampler given is not changed.
"""

from __future__ import annotations

import functools
import json
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.compile import jit
from liesample.samplers.contract import Recipe, Sampler, SamplingAPI, Tunable
from liesample.samplers.cotangent.magnetic_hmc import jittered_magnetic_hmc
from liesample.tuning.adaptation import magnetic_window_adaptation, window_adaptation
from liesample.tuning.protocol import fixed, run_adaptation, step_size_adaptation

__all__ = ["WARM_UP_METHODS", "adaptation_of", "choose_from_starts", "warm_up", "window_warm_up"]

WARM_UP_METHODS = ("dual_averaging", "rule", "window", "chees")
"""The values of ``Tunable.method`` that :func:`adaptation_of` builds."""


def _declared(sampler: Sampler):
    tunable = sampler.adaptation
    if tunable is None:
        raise ValueError("this sampler declares nothing to tune (Sampler.adaptation is None)")
    if tunable.method not in WARM_UP_METHODS:
        raise ValueError(
            f"unknown adaptation method {tunable.method!r}; liesample.tuning.warmup runs "
            f"{WARM_UP_METHODS}"
        )
    return tunable


def _host(positions):
    return jax.tree.map(np.asarray, positions)


def choose_from_starts(sampler: Sampler, initial_positions) -> Sampler:
    """The sampler with its automatic step for these starts (chains first), without warm-up."""
    tunable = _declared(sampler)
    if tunable.choose is None:
        name = sampler.settings.get("sampler", "this sampler")
        raise ValueError(
            f"{name} was built without step_size and num_warmup=0 (or adapt=False): nothing "
            "sets its step. Pass num_warmup > 0 (the warm-up tunes it, with the mass) or "
            "build it with step_size"
        )
    step_size, source = tunable.choose(_host(initial_positions), None)
    return _recipe(sampler)(source, **{tunable.adapted[0]: step_size})


def _recipe(sampler: Sampler) -> Recipe:
    if sampler.recipe is None:
        raise ValueError("this sampler declares no recipe (Sampler.recipe): nothing remakes it")
    return sampler.recipe


def adaptation_of(sampler: Sampler, initial_positions, rng_key):
    """``(adaptation, starting step size, source)``: the protocol's instance for the sampler's
    declaration (module docstring), from the run's starts and key."""
    tunable = _declared(sampler)
    positions = _host(initial_positions)
    if tunable.method == "rule":
        step_size, source = tunable.choose(positions, jax.random.fold_in(rng_key, 1))
        return fixed({"step_size": step_size}), step_size, "warm-up " + source
    if tunable.given:
        initial = sampler.settings["step_size"]
    else:
        initial, _ = tunable.choose(positions, None)
    adaptation = step_size_adaptation(
        tunable.target_acceptance_rate, "acceptance_rate", _step_cap(tunable)
    )
    return adaptation, initial, None


def _step_cap(tunable) -> float:
    return np.inf if tunable.max_step_size is None else float(tunable.max_step_size)


@functools.partial(jit, static_argnames=("build", "name", "target", "num_warmup"))
def _dual_averaging(chain_keys, states, initial, others, cap, *, build, name, target, num_warmup):
    """The warm-up of ``"dual_averaging"``: one program for every value of the step (the
    structure's value ``name``), of its ``others`` and of the ``cap`` (traced), for a
    structure's ``build`` (hashable)."""
    adaptation = step_size_adaptation(target, "acceptance_rate", cap)
    return run_adaptation(
        adaptation, lambda step_size: build(**{name: step_size}, **others), chain_keys, states,
        {"step_size": initial}, num_warmup, _acceptance,
    )  # fmt: skip


def _acceptance(parameters, state, info):
    del parameters, state
    return info.acceptance_rate


def warm_up(sampler: Sampler, rng_key, chain_keys, states, initial_positions, num_warmup: int):
    """Tune ``sampler``'s declared parameters in a warm-up of ``num_warmup`` steps.

    Returns ``(tuned, states)``: the tuned sampler and the chains' states after the warm-up, or
    ``None`` when the adaptation learns nothing from transitions (a rule) and the warm-up steps
    are still to be run, as ordinary steps of ``tuned``. ``rng_key`` is the run's key,
    ``chain_keys`` the chains' (``split(rng_key, chains)``), ``states`` the initial states; from
    these alone, so a resumed run derives the same step.
    """
    tunable = _declared(sampler)
    if tunable.method in ("window", "chees"):
        return window_warm_up(sampler, rng_key, initial_positions, num_warmup)
    adaptation, initial, source = adaptation_of(sampler, initial_positions, rng_key)
    name = tunable.adapted[0]
    if adaptation.update is None:
        step_size = adaptation.final(adaptation.init(states, {}))["step_size"]
        return _recipe(sampler)(source, **{name: float(step_size)}), None
    if sampler.structure is None:
        raise ValueError("dual averaging steps the sampler's Structure: it declares none")
    dtype = jax.tree.leaves(states.position)[0].dtype
    values = sampler.structure.values
    others = {k: jnp.asarray(v, dtype) for k, v in values.items() if k != name}
    moved, parameters, rates = _dual_averaging(
        chain_keys, states, jnp.asarray(initial, dtype), others,
        jnp.asarray(_step_cap(tunable), dtype), build=sampler.structure.build, name=name,
        target=tunable.target_acceptance_rate, num_warmup=num_warmup,
    )  # fmt: skip
    step_size = float(parameters["step_size"])
    target = tunable.target_acceptance_rate
    kept = rates[:, num_warmup // 2 :]
    # chains spread over several processes: their mean is computed on the devices
    mean = np.mean(np.asarray(kept)) if kept.is_fully_addressable else jnp.mean(kept)
    source = (
        f"warm-up dual averaging to mean acceptance {target:g} over chains, from "
        f"{initial:.4g}; mean acceptance in the second half of the warm-up "
        f"{float(mean):.3f}"
    )
    return _recipe(sampler)(source, **{name: step_size}), moved


MODEL = ("model_args", "model_kwargs")
"""The keywords of a log-density sampler that carry its model's arguments (the warm-up passes
them on as numbers of its program)."""

INITIAL_STEP_SIZE = 0.1
"""Where dual averaging starts for a T*G sampler built without a step
(:func:`liesample.window_adaptation`'s ``initial_step_size``)."""


def window_warm_up(sampler: Sampler, rng_key, initial_positions, num_warmup: int):
    """The warm-up of a T*G sampler (``Tunable.method == "window"``): ``(tuned, states)``.

    :func:`liesample.window_adaptation` of the sampler's API object with the arguments it was
    built with (its :class:`~liesample.samplers.contract.Recipe`), on every chain together
    (chain ``c`` with key ``split(rng_key, chains)[c]``, as the sampling that follows). It
    tunes the step size (from a given one with ``adapt=True``, else from
    :data:`INITIAL_STEP_SIZE`), the inverse mass unless one was given, and for HMC the
    integration time unless ``num_integration_steps`` was given. ``tuned`` is the recipe called
    with the tuned numbers (``"chees"``: :func:`liesample.jittered_magnetic_hmc`'s, with the
    recipe's arguments); its settings record what was adapted (``adapted_parameters``,
    ``inverse_mass_matrix`` as JSON, ``step_size_source``).
    """
    if isinstance(num_warmup, bool) or int(num_warmup) != num_warmup or num_warmup < 20:
        raise ValueError(
            f"num_warmup={num_warmup!r}: the window adaptation of "
            f"{sampler.settings.get('sampler')} needs num_warmup >= 20 (Stan's windows; a few "
            "hundred is typical), or give step_size and adapt=False"
        )
    tunable = cast(Tunable, sampler.adaptation)  # a T*G sampler built by its API object has one
    recipe = _recipe(sampler)
    given = {**recipe.options, **recipe.numbers}
    kept = {k: v for k, v in given.items() if v is not None and k not in ("jitter", "step_size")}
    initial = sampler.settings["step_size"] if tunable.given else INITIAL_STEP_SIZE
    adapt_mass = "inverse_mass_matrix" not in kept
    if tunable.method == "chees":  # magnetic HMC: every parameter, then the jittered sampler
        options = {k: kept[k] for k in (*tunable.options, *MODEL) if k in kept}
        warm = magnetic_window_adaptation(*recipe.args, initial_step_size=initial, **options)
        adapted = list(tunable.adapted)
        recipe = recipe._replace(factory=jittered_magnetic_hmc)
    else:
        api = cast(SamplingAPI[...], recipe.factory)  # the sampler's API object
        warm = window_adaptation(
            api, *recipe.args, initial_step_size=initial, adapt_mass=adapt_mass, **kept
        )
        adapted = ["step_size"] + ["inverse_mass_matrix"] * adapt_mass
    (states, parameters), _ = warm.run(rng_key, initial_positions, int(num_warmup))
    target = tunable.target_acceptance_rate
    source = (
        f"warm-up {tunable.method} adaptation (all chains together) to target rate "
        f"{target:g}, from {initial:.4g}"
    )
    tuned = _remade(recipe, source, parameters)
    if parameters.get("jitter"):
        adapted.append("num_integration_steps")
    tuned.settings.update(
        adapted_parameters=", ".join(adapted),
        inverse_mass_matrix=_as_json(parameters["inverse_mass_matrix"]),
    )
    return tuned, states


def _remade(recipe: Recipe, source: str, parameters: dict) -> Sampler:
    """The recipe's sampler at the tuned ``parameters``: those it has as numbers replace its
    own, the others (a tuned integration time where the sampler was built without one, the
    jitter that goes with it) are given as keywords beside its options."""
    numbers = {k: v for k, v in parameters.items() if k in recipe.numbers}
    options = {**recipe.options, **{k: v for k, v in parameters.items() if k not in numbers}}
    return recipe._replace(options=options)(source, **numbers)


def _as_json(tree) -> str:
    """A pytree of arrays as JSON text (a NetCDF attribute): ``{"path": values}``."""
    leaves = jax.tree_util.tree_flatten_with_path(tree)[0]
    return json.dumps(
        {jax.tree_util.keystr(path) or "": np.asarray(leaf).tolist() for path, leaf in leaves}
    )
