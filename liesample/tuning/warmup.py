"""The warm-up the runner runs: the step size a sampler declares tunable, chosen or tuned.

A sampler declares how its step size is chosen (``Sampler.tuning``, a
:class:`liesample.samplers.contract.StepSizeTuning`); this module runs that declaration, and
:func:`liesample.sample` calls it:

- :func:`choose_from_starts` (no warm-up adaptation, step size left unset): the sampler's own
  automatic step for the run's starts (``tuning.choose(positions, None)``);
- :func:`warm_up` (adaptation): ``"dual_averaging"`` tunes the step over the warm-up steps
  (:func:`liesample.tuning.dual_averaging.dual_averaging`) and returns the chains' states after
  them; ``"rule"`` computes it from the starts with a key of the run
  (``tuning.choose(positions, fold_in(rng_key, 1))``) and leaves the warm-up steps to the
  runner.

Either returns a new sampler built by ``tuning.rebuild`` (the chosen step and how it was chosen
in its ``settings``); the sampler given is not changed.
"""

from __future__ import annotations

import jax
import numpy as np

from liesample.samplers.contract import Sampler
from liesample.tuning.dual_averaging import dual_averaging

__all__ = ["WARM_UP_METHODS", "choose_from_starts", "warm_up"]

WARM_UP_METHODS = ("dual_averaging", "rule")
"""The values of ``StepSizeTuning.method`` that :func:`warm_up` runs."""


def _tuning(sampler: Sampler):
    tuning = sampler.tuning
    if tuning is None:
        raise ValueError("this sampler declares no step-size tuning (Sampler.tuning is None)")
    if tuning.method not in WARM_UP_METHODS:
        raise ValueError(
            f"unknown tuning method {tuning.method!r}; liesample.tuning.warmup runs "
            f"{WARM_UP_METHODS}"
        )
    return tuning


def _host(positions):
    return jax.tree.map(np.asarray, positions)


def choose_from_starts(sampler: Sampler, initial_positions) -> Sampler:
    """The sampler with its automatic step for these starts (chains first), without warm-up."""
    tuning = _tuning(sampler)
    return tuning.rebuild(*tuning.choose(_host(initial_positions), None))


def warm_up(sampler: Sampler, rng_key, chain_keys, states, initial_positions, num_warmup: int):
    """Tune ``sampler``'s step size in a warm-up of ``num_warmup`` steps.

    Returns ``(tuned, states)``: the tuned sampler and the chains' states after the warm-up, or
    ``None`` when the warm-up steps are still to be run (with ``tuned``). ``rng_key`` is the
    run's key, ``chain_keys`` the chains' (``split(rng_key, chains)``), ``states`` the initial
    states; from these alone, so a resumed run derives the same step.
    """
    tuning = _tuning(sampler)
    positions = _host(initial_positions)
    if tuning.method == "rule":
        step_size, source = tuning.choose(positions, jax.random.fold_in(rng_key, 1))
        return tuning.rebuild(step_size, "warm-up " + source), None
    if tuning.given:
        initial = sampler.settings["step_size"]
    else:
        initial, _ = tuning.choose(positions, None)
    result = dual_averaging(
        tuning.at,
        chain_keys,
        states,
        initial,
        num_warmup,
        tuning.target_acceptance_rate,
        tuning.parameters,
        tuning.max_step_size,
    )
    target = tuning.target_acceptance_rate
    source = (
        f"warm-up dual averaging to mean acceptance {target:g} over chains, from "
        f"{initial:.4g}; mean acceptance in the second half of the warm-up "
        f"{float(result.mean_acceptance):.3f}"
    )
    return tuning.rebuild(float(result.step_size), source), result.states
