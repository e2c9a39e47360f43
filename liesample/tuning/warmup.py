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
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.compile import jit
from liesample.integrators.chain_loop import run_steps
from liesample.samplers.contract import Recipe, Sampler, SamplingAPI, Tunable
from liesample.samplers.cotangent.magnetic_hmc import jittered_magnetic_hmc
from liesample.tuning.adaptation import magnetic_window_adaptation, window_adaptation
from liesample.tuning.protocol import (
    CHAINS,
    StepSizeState,
    carried_sampler,
    fixed,
    step_size_adaptation,
)

__all__ = [
    "WARM_UP_METHODS",
    "Adapted",
    "DualAveraging",
    "Tuned",
    "Tuning",
    "adaptation_of",
    "choose_from_starts",
    "dual_averaging_plan",
    "dual_averaging_stepper",
    "tuned_by_dual_averaging",
    "warm_up",
    "window_warm_up",
]

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


class DualAveraging(NamedTuple):
    """The static half of ``"dual_averaging"`` in a compiled program: the structure's value it
    tunes (``name``: ``step_size``, ``proposal_scale``) and the target acceptance rate."""

    name: str
    target: float


class Tuning(NamedTuple):
    """The traced half: transitions ``0 … until − 1`` adapt (none with ``until = 0``), from
    the step ``initial``, under the ``cap``."""

    until: jax.Array
    cap: jax.Array
    initial: jax.Array


class Adapted(NamedTuple):
    """What one chain carries through the adapting transitions: the chains' shared dual
    averaging (``step``), its tuned step so far (``final``: its average, under the cap), and
    this chain's summed acceptance over the adapting transitions' second half."""

    step: StepSizeState
    final: jax.Array
    accepted: jax.Array


class Tuned(NamedTuple):
    """One chain's state in a program that may adapt: the sampler's state, the
    :class:`Adapted` numbers, the transition's index."""

    chain: Any
    adapted: Adapted
    index: jax.Array  # type: ignore[assignment]  # the transition's index (shadows tuple.index)

    @property
    def position(self):
        return self.chain.position


def dual_averaging_plan(sampler: Sampler, initial_positions, dtype):
    """``(DualAveraging, Tuning)`` for a sampler whose warm-up is ``"dual_averaging"``, from
    its starts (the starting step: the given one, else the sampler's choice for them), adapting
    no transition yet; ``None`` for any other warm-up."""
    tunable = _declared(sampler)
    if tunable.method != "dual_averaging":
        return None
    _, initial, _ = adaptation_of(sampler, initial_positions, None)
    spec = DualAveraging(tunable.adapted[0], float(tunable.target_acceptance_rate))
    cap = jnp.asarray(_step_cap(tunable), dtype)
    return spec, Tuning(jnp.asarray(0), cap, jnp.asarray(initial, dtype))


def dual_averaging_stepper(build: Callable, values: dict, spec: DualAveraging, tuning: Tuning):
    """``(sampler, start)``: the sampler ``build(**values)`` on :class:`Tuned` states for
    chains vmapped with axis :data:`liesample.tuning.protocol.CHAINS`, and ``start(state,
    index, num_chains)``, a chain's first :class:`Tuned` state. A transition that adapts uses
    the shared step of dual averaging (:func:`liesample.tuning.protocol.step_size_adaptation`,
    pooled over every chain's acceptance rate) and updates it; any other uses
    ``values[spec.name]``. Its info is the sampler's, so one program runs the warm-up and the
    sampling."""
    others = {k: v for k, v in values.items() if k != spec.name}
    reference = build(**values)
    adaptation = step_size_adaptation(spec.target, "acceptance_rate", tuning.cap)

    def start(state, index, num_chains):
        step = adaptation.init(jnp.zeros(num_chains), {"step_size": tuning.initial})
        zero = jnp.zeros((), tuning.initial.dtype)
        final = adaptation.final(step)["step_size"]
        return Tuned(state, Adapted(step, final, zero), jnp.asarray(index))

    def move(advance, carry: Tuned):
        adapted = carry.adapted
        adapting = carry.index < tuning.until
        now = jnp.where(adapting, adaptation.current(adapted.step)["step_size"], values[spec.name])
        chain, info = advance(build(**{spec.name: now}, **others), carry.chain)

        def update(adapted):
            infos = jax.lax.all_gather(info, CHAINS)
            step = cast(Callable, adaptation.update)(adapted.step, None, None, None, None, infos)
            late = carry.index >= tuning.until // 2
            accepted = adapted.accepted + jnp.where(late, info.acceptance_rate, 0.0)
            return Adapted(step, adaptation.final(step)["step_size"], accepted)

        # the same index in every chain: a sampling transition skips the update
        adapted = jax.lax.cond(adapting, update, lambda adapted: adapted, adapted)
        return Tuned(chain, adapted, carry.index + 1), info

    return carried_sampler(reference, move), start


def _one(leaf):
    """One element of an array of the chains (each chain holds the same value), on the host
    without a compiled program, also where the chains span several processes."""
    return np.asarray(leaf.addressable_shards[0].data).ravel()[0]


def tuned_by_dual_averaging(sampler: Sampler, initial_step, ends: Adapted, until: int):
    """The sampler's recipe at the step the warm-up of ``until`` transitions tuned (``ends``:
    every chain's :class:`Adapted` after it), its source naming the chains' mean acceptance
    over the warm-up's second half."""
    tunable = _declared(sampler)
    accepted = ends.accepted
    # chains spread over several processes: their sum is computed on the devices
    total = np.sum(np.asarray(accepted)) if accepted.is_fully_addressable else jnp.sum(accepted)
    mean = float(total) / (accepted.shape[0] * max(until - until // 2, 1))
    source = (
        f"warm-up dual averaging to mean acceptance {tunable.target_acceptance_rate:g} over "
        f"chains, from {float(initial_step):.4g}; mean acceptance in the second half of the "
        f"warm-up {mean:.3f}"
    )
    return _recipe(sampler)(source, **{tunable.adapted[0]: float(_one(ends.final))})


@functools.partial(jit, static_argnames=("build", "spec"))
def _dual_averaging(chain_keys, states, values, tuning, *, build, spec):
    """The warm-up of ``"dual_averaging"`` on its own (:func:`warm_up`); a run of
    :func:`liesample.sample` runs the same stepper in the program of its chunks."""
    stepper, start = dual_averaging_stepper(build, values, spec, tuning)
    num_chains = chain_keys.shape[0]

    def chain(key, state):
        end, _ = run_steps(stepper, key, start(state, 0, num_chains), 0, tuning.until)
        return end

    end = jax.vmap(chain, axis_name=CHAINS)(chain_keys, states)
    return end.chain, end.adapted


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
    if tunable.method == "rule":
        adaptation, _, source = adaptation_of(sampler, initial_positions, rng_key)
        step_size = adaptation.final(adaptation.init(states, {}))["step_size"]
        return _recipe(sampler)(source, **{tunable.adapted[0]: float(step_size)}), None
    if sampler.structure is None:
        raise ValueError("dual averaging steps the sampler's Structure: it declares none")
    dtype = jax.tree.leaves(states.position)[0].dtype
    spec, tuning = cast(tuple, dual_averaging_plan(sampler, initial_positions, dtype))
    values = {k: jnp.asarray(v, dtype) for k, v in sampler.structure.values.items()}
    values[spec.name] = tuning.initial
    tuning = tuning._replace(until=jnp.asarray(num_warmup))
    moved, ends = _dual_averaging(
        chain_keys, states, values, tuning, build=sampler.structure.build, spec=spec
    )
    return tuned_by_dual_averaging(sampler, tuning.initial, ends, num_warmup), moved


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
