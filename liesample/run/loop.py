"""The chunked loop of a run: the sampler's starts checked, its step chosen or tuned, one
program compiled for the warm-up's steps and every chunk (``jax.jit``'s own cache, keyed by the
sampler's structure, the chunk length and the chains' shapes), then run chunk by chunk with a
progress bar, each chunk saved to the run file (:mod:`liesample.run.store`) as soon as it is
done.

:func:`run_chains` is :func:`liesample.run.runner.sample_chains` with its keywords gathered as a
:class:`RunOptions` and the names of the draws in their ``DataTree`` as a :class:`TreeSpec`.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import json
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from liesample.foundation.compile import jit
from liesample.foundation.types import PyTree
from liesample.foundation.validation import is_single_array, single_key
from liesample.integrators.chain_loop import run_draws
from liesample.run import arguments
from liesample.run.agreement import agreement
from liesample.run.checks import DEFAULT_MIN_ACCEPTANCE_RATE, check_run, record_casimir_drift
from liesample.run.provenance import adapted_fingerprint, run_fingerprint
from liesample.run.sharding import (
    CHAIN_AXIS,
    LatticeSharding,
    check_output,
    run_sharding,
    shard_chains,
    spans_processes,
    to_host,
)
from liesample.run.store import Layout, RunFile, check_same_file
from liesample.samplers.contract import (
    HOOKS,
    SAMPLE_STATS_NAMES,
    Sampler,
    Tunable,
    as_sampler,
    energy_name,
    reduce_over_thinning,
)
from liesample.tuning.protocol import CHAINS
from liesample.tuning.warmup import (
    choose_from_starts,
    dual_averaging_plan,
    dual_averaging_stepper,
    tuned_by_dual_averaging,
    warm_up,
)


@dataclass(frozen=True)
class ChainsResult:
    """Draws of ``positions`` with shape ``(chains, draws, *event_shape)`` (a pytree of such
    arrays for pytree positions; ``None`` for a run with ``keep_positions=False``), per-draw
    ``info`` arrays with shape ``(chains, draws)``, the sampling wall time in seconds
    (compilation excluded; on a resumed run, the time of this session only), the sampler's
    ``settings`` after warm-up (step size and how it was chosen, stability mode, …), and the
    ``observables`` recorded at each draw (the pytree the ``observables`` option returns, each
    leaf ``(chains, draws, *shape)``; ``None`` without that option), and the pointwise
    ``log_likelihood`` (name -> ``(chains, draws, *shape)``; ``None`` without that option)."""

    positions: np.ndarray
    info: dict[str, np.ndarray]
    wall_time: float
    num_steps: int
    settings: dict | None = None
    observables: PyTree = None
    log_likelihood: dict | None = None


@dataclass(frozen=True)
class RunOptions:
    """The keywords of :func:`sample_chains` after ``num_draws`` (documented there)."""

    num_warmup: int = 0
    thinning: int = 1
    progress_bar: bool = True
    chunk_draws: int | None = None
    on_nonfinite: str = "warn"
    devices: object = None
    lattice_sharding: object = None
    output: object = None
    resume: bool = False
    adapt: bool | None = None
    min_acceptance_rate: float = DEFAULT_MIN_ACCEPTANCE_RATE
    observables: object = None
    keep_positions: bool = True
    callback: Callable | None = None
    log_likelihood: Mapping | None = None


@dataclass(frozen=True)
class TreeSpec:
    """How a run's draws are named and labelled in its ``DataTree`` (the ``var_name``,
    ``event_dims``, ``coords`` and ``attrs`` of :func:`sample`; the defaults for
    :func:`sample_chains`' file)."""

    var_name: str | None = None
    event_dims: Sequence[str] | Mapping[str, Sequence[str]] | None = None
    coords: Mapping | None = None
    attrs: Mapping | None = None
    energy_name: str | None = None

    def named_for(self, sampler: Sampler, positions, keep_positions) -> TreeSpec:
        """The sampler's declared name and dims for single-array positions, unless given; and
        the ``sample_stats`` name of its ``info.energy`` (:func:`energy_name`), unless adopted
        from a saved run."""
        spec = self
        if spec.energy_name is None:
            first = jax.tree.map(lambda leaf: leaf[0], positions)
            try:  # the first use of a start: its errors name it, as the checks of all do
                name = energy_name(sampler, first)
            except (ValueError, TypeError) as error:
                raise type(error)(f"initial_positions[0]: {error}") from None
            spec = dataclasses.replace(spec, energy_name=name)
        names = sampler.draw_names
        if (
            keep_positions
            and spec.var_name is None
            and spec.event_dims is None
            and names is not None
            and is_single_array(positions)
            and np.ndim(positions) - 1 == len(names.event_dims)
        ):
            return dataclasses.replace(spec, var_name=names.var_name, event_dims=names.event_dims)
        return spec

    def build(
        self, positions, info, observables, settings, *, thinning, attrs, log_likelihood=None
    ):
        """The ``DataTree`` of these draws: ``attrs`` (the run's) then the spec's own; a
        ``log_likelihood`` group (ArviZ's, for ``loo`` and ``compare``) when it is given."""
        from liesample.analysis.diagnostics import to_datatree

        tree = to_datatree(
            positions,
            info,
            var_name=self.var_name,
            event_dims=self.event_dims,
            coords=self.coords,
            observables=observables,
            thinning=thinning,
            step_size=settings.get("step_size"),
            attrs={**attrs, **(self.attrs or {})},
            energy_name=self.energy_name or "energy",
        )
        if log_likelihood is not None:
            from arviz_base import from_dict

            dims = {name: [f"{name}_dim_{k}" for k in range(np.ndim(v) - 2)]
                    for name, v in log_likelihood.items()}  # fmt: skip
            group = from_dict({"log_likelihood": log_likelihood}, dims=dims)["log_likelihood"]
            group.attrs.update(tree["posterior"].attrs)
            tree["log_likelihood"] = group
        return tree

    def example(self, positions, observable_shapes, log_likelihood_shapes=None):
        """A tree of one draw per chain: the names, dims and coords checked on the starts."""
        if positions is not None:
            positions = jax.tree.map(lambda leaf: np.asarray(leaf)[:, None], positions)
        observable_shapes, log_likelihood_shapes = jax.tree.map(
            lambda leaf: np.zeros((leaf.shape[0], 1, *leaf.shape[1:]), leaf.dtype),
            (observable_shapes, log_likelihood_shapes),
        )
        with warnings.catch_warnings():  # ArviZ remarks on a tree of one draw
            warnings.simplefilter("ignore", UserWarning)
            tree = self.build(positions, None, observable_shapes, {}, thinning=1, attrs={},
                              log_likelihood=log_likelihood_shapes)  # fmt: skip
        return tree, positions, observable_shapes, log_likelihood_shapes


def _library_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("liesample")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown"


def run_attrs(settings, *, on_nonfinite, wall_time, num_steps) -> dict:
    """The attributes of a run's tree: ArviZ's ``sampling_time`` (seconds, compilation
    excluded) and ``inference_library`` (and its version), the steps, the warm-up, the sampler's
    settings. (NetCDF has no boolean attribute: ``adapted`` is stored as 0 or 1.)"""
    return {
        "sampling_time": wall_time,
        "inference_library": "liesample",
        "inference_library_version": _library_version(),
        "num_steps": num_steps,
        "num_warmup": settings.get("num_warmup"),
        "on_nonfinite": on_nonfinite,
        **{k: v for k, v in settings.items() if k not in ("num_warmup", "step_size")},
    }


def _observe(observables):
    """The function ``position -> pytree`` recorded for ``observables`` (a callable, or a tuple
    of ``(name, function)`` pairs: hashable, so that it can be a static argument)."""
    if observables is None or callable(observables):
        return observables
    functions = dict(observables)
    return lambda position: {name: f(position) for name, f in functions.items()}


def scalar_info(sampler: Sampler, position) -> Sampler:
    """``sampler`` whose ``info`` keeps only the fields that are one number per step (a scalar
    array), in a named tuple: a plain BlackJAX algorithm's info may hold nested states and
    per-coordinate arrays (NUTS: the trajectory's end states, the momentum), which are dropped
    by this rule. A sampler whose info is already all scalars, or that steps through noise
    blocks, is returned as it is."""
    if sampler.noise_blocks is not None:
        return sampler
    static, values = program(sampler, position)  # traced once per structure (jit's cache)
    _, info = _first_step.eval_shape(position, jax.random.key(0), values, sampler=static)
    fields = info._asdict() if hasattr(info, "_asdict") else dict(vars(info))
    kept = tuple(name for name, v in fields.items() if getattr(v, "shape", None) == ())
    if hasattr(info, "_asdict") and len(kept) == len(fields):
        return sampler
    hooks = {name: getattr(sampler, name) for name in HOOKS}
    return Sampler(sampler.init, _ScalarInfoStep(sampler.step, kept), **hooks)


@functools.partial(jit, static_argnames=("sampler",))
def _first_step(position, rng_key, values, *, sampler):
    """One step from ``position`` (:func:`scalar_info` reads the shapes of its info)."""
    stepper = _stepper(sampler, values)
    return stepper.step(rng_key, stepper.init(position))


@dataclass(frozen=True)
class _ScalarInfoStep:
    """``step`` whose info keeps the fields ``kept`` (equal for equal steps and fields, so
    that ``jax.jit``'s cache serves a second run of the same algorithm)."""

    step: Callable
    kept: tuple

    def __call__(self, rng_key, state):
        state, info = self.step(rng_key, state)
        values = [getattr(info, name) for name in self.kept]
        return state, collections.namedtuple("ScalarInfo", self.kept)(*values)


def program(sampler: Sampler, positions):
    """``(sampler, values)`` for the compiled programs of a run: a sampler that declares a
    :class:`liesample.samplers.contract.Structure` gives its ``build`` and its ``values`` as
    arrays of the positions' dtype (traced: one program for every value); any other sampler
    itself and ``None``."""
    structure = sampler.structure
    if structure is None:
        return sampler, None
    dtype = _dtype(positions)
    if not jnp.issubdtype(dtype, jnp.floating):
        return sampler, None
    return structure.build, {k: _traced(v, dtype) for k, v in structure.values.items()}


def _dtype(positions):
    """The dtype of a run's real numbers: the positions' (a gauge field's complex links: their
    real part's)."""
    dtype = jnp.result_type(*jax.tree.leaves(positions))
    if jnp.issubdtype(dtype, jnp.complexfloating):
        return jnp.finfo(dtype).dtype
    return dtype


def _traced(value, dtype):
    """A structure's value as the array the program traces: a Python number or a real 0-d
    array (``β``, a step size) in the positions' dtype; NumPy integers (a step count), arrays
    and pytrees of them (a mass, a field, a model's data) in their own dtype."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return jnp.asarray(value, dtype)
    if isinstance(value, (np.floating, np.ndarray, jax.Array)) and np.ndim(value) == 0:
        if jnp.issubdtype(jnp.result_type(value), jnp.floating):
            return jnp.asarray(value, dtype)
    return jax.tree.map(jnp.asarray, value)


def _stepper(sampler, values):
    """The sampler a compiled program steps: ``sampler``, or ``sampler(**values)`` when
    ``sampler`` is a structure's ``build`` (:func:`program`)."""
    return sampler if values is None else sampler(**values)


@functools.partial(jit, static_argnames=("sampler",))
def _init_states(positions, values, *, sampler):
    """Every chain's initial state, in one compiled call (an eager ``vmap`` would compile each
    of ``init``'s operations on its own)."""
    return jax.vmap(_stepper(sampler, values).init)(positions)


DRAWS = ("positions", "observables", "log_likelihood")
"""What a chunk records besides ``info``."""


def _recorder(observables, log_likelihood, keep_positions):
    """What is recorded at each draw: ``None`` for the positions alone (the default loop), else
    a function of the position giving a dict with ``"positions"`` (if kept),
    ``"observables"`` and ``"log_likelihood"`` (if asked for)."""
    observe, pointwise = _observe(observables), _observe(log_likelihood)
    if observe is None and pointwise is None:
        return None

    def record(position):
        recorded = {"positions": position} if keep_positions else {}
        if observe is not None:
            recorded["observables"] = observe(position)
        if pointwise is not None:
            recorded["log_likelihood"] = pointwise(position)
        return recorded

    return record


@functools.partial(
    jit,
    static_argnames=(
        "sampler", "count", "thinning", "observables", "log_likelihood", "keep_positions", "tuned"
    ),
)  # fmt: skip
def _run_chunk(
    states, keys, first_step, num_steps, values, tuning, *, sampler, count, thinning,
    observables, log_likelihood, keep_positions, tuned,
):  # fmt: skip
    """``num_steps`` steps of every chain from ``first_step``, keeping the first of ``count``
    draws ``thinning`` steps apart that they span: ``(states, (recorded, info), tuning)``, what
    :func:`_recorder` records and the per-draw info. ``num_steps`` is traced, so one program
    runs every chunk, a shorter last one (``num_steps < count · thinning``) and the warm-up
    (more steps, nothing kept). A sampler tuned by dual averaging (``tuned``, a
    :class:`liesample.tuning.warmup.DualAveraging`) steps through
    :func:`liesample.tuning.warmup.dual_averaging_stepper`: the warm-up's transitions adapt
    (``tuning.until``) in the same program, and the third result is every chain's
    :class:`liesample.tuning.warmup.Adapted` (``None`` without ``tuned``)."""
    record = _recorder(observables, log_likelihood, keep_positions)

    def run(stepper, state, key):
        return run_draws(
            stepper, key, state, first_step, count, thinning, reduce_over_thinning, record,
            num_steps,
        )  # fmt: skip

    if tuned is None:
        states, recorded = jax.vmap(functools.partial(run, _stepper(sampler, values)))(states, keys)
        return states, recorded, None
    stepper, start = dual_averaging_stepper(sampler, values, tuned, tuning)
    num_chains = keys.shape[0]

    def chain(state, key):
        end, recorded = run(stepper, start(state, first_step, num_chains), key)
        return end.chain, recorded, end.adapted

    return jax.vmap(chain, axis_name=CHAINS)(states, keys)


ONE_KEY = (
    "a run takes one key and splits it over the chains itself (chain c steps with "
    "split(rng_key, num_chains)[c]): pass one, e.g. jax.random.key(0)"
)


class _Run:
    """One call of :func:`sample_chains`: its checked arguments, sampler, states and file."""

    def __init__(self, algorithm, rng_key, initial_positions, num_draws, options, spec):
        o = options
        # Every argument checked before anything is traced or compiled.
        arguments.check_algorithm(algorithm)
        self.rng_key = single_key(rng_key, batch_fix=ONE_KEY)
        arguments.check_options(num_draws, o)
        self.sampler = as_sampler(algorithm)  # its info reduced to scalars in start()
        arguments.check_steps(self.sampler, int(num_draws), o)
        self.positions, self.num_chains = arguments.as_positions(initial_positions)
        self.observe, self.observables_key = arguments.as_observables(
            o.observables, o.keep_positions
        )
        self.observable_shapes = (
            None
            if self.observe is None
            else arguments.observable_shapes(self.observe, self.positions)
        )
        self.log_likelihood_key = arguments.as_log_likelihood(o.log_likelihood)
        self.log_likelihood_shapes = (
            None
            if self.log_likelihood_key is None
            else arguments.observable_shapes(_observe(self.log_likelihood_key), self.positions)
        )
        arguments.check_finite_starts(self.positions, self.num_chains)
        self.sharding = run_sharding(o.devices, o.lattice_sharding, self.num_chains, self.sampler)
        check_output(o.output, self.sharding)
        # chains over several processes: process 0 alone writes the run file, and every
        # process agrees at each step of the file (liesample.run.agreement)
        self.across = spans_processes(self.sharding)
        self.writer = not self.across or jax.process_index() == 0
        self._check_memory(algorithm, int(num_draws), o)
        self.algorithm, self.num_draws, self.options = algorithm, int(num_draws), o
        self.spec, self.store = spec, None
        # set in start() and compile()
        self.program: Any = None
        self.executable: Any = None
        # shown from the start: the phases before the first draw take most of a short run
        self.bar = tqdm(
            total=self.num_draws, disable=not o.progress_bar, unit="draw", dynamic_ncols=True
        )
        self.phase("checking the starts")

    def _check_memory(self, algorithm, num_draws, options):
        """The kept draws fit the host's memory and one chunk the devices'."""
        info = arguments.info_bytes(self.positions, isinstance(algorithm, Sampler))
        recorded = (self.observable_shapes, self.log_likelihood_shapes)
        per_draw = arguments.draw_bytes(self.positions, options.keep_positions, recorded, info)
        devices = [jax.devices()[0]] if self.sharding is None else list(self.sharding.device_set)
        sizes, parts = (self.num_chains, per_draw, info), 1
        if isinstance(self.sharding, LatticeSharding):  # a chain's lattice over several devices
            parts = len(devices) // self.sharding.mesh.shape[CHAIN_AXIS]
        arguments.check_memory(sizes, num_draws, options, devices, parts)

    def phase(self, name):
        """Name what the run is doing now on the progress bar."""
        self.bar.set_description(f"{self.num_chains} chains: {name}", refresh=True)

    def _open(self):
        """Open the run file (refused here, before any compilation, if it cannot be ours), and
        name the draws: as given, else as the saved run named them, else by default."""
        o = self.options
        where = "checking the run's options" if o.output is None else f"opening {o.output!r}"
        with agreement(where, self.across) as agreed:
            if o.output is not None:
                opened = RunFile.open if self.writer else RunFile.reader
                self.store = opened(o.output, o.resume)
                self.spec = self.store.names(self.spec)
            self.spec = self.spec.named_for(self.sampler, self.positions, o.keep_positions)
            self.example = self.spec.example(
                self.positions if o.keep_positions else None,
                self.observable_shapes,
                self.log_likelihood_shapes,
            )
            if self.store is not None:
                self.fingerprint = self._fingerprint()
                self.store.check(self.fingerprint)
            view = None if self.store is None else self.store.view()
            agreed.value = json.dumps([o.output is not None, bool(o.resume), view])
        if self.across:
            _check_same_output([json.loads(value) for value in agreed.values], o.output)

    def start(self):
        """Open the file, check every start, choose or tune the step (the warm-up)."""
        self._open()
        o, sampler = self.options, self.sampler
        adapting = arguments.wants_adaptation(
            sampler, o.adapt, o.num_warmup, type(self.algorithm).__name__
        )
        # The step size left unset and not adapted: the sampler's own choice for these starts.
        choosing = not adapting and sampler.adaptation is not None and not sampler.adaptation.given
        # Concrete checks (shape, orbit, constraints, energy, step size) of every start.
        arguments.check_starts(
            sampler, self.positions, self.num_chains, step_size_checks=not (adapting or choosing)
        )
        if choosing:
            sampler = choose_from_starts(sampler, self.positions)
            arguments.check_starts(sampler, self.positions, self.num_chains)
        self.chain_keys = shard_chains(
            jax.random.split(self.rng_key, self.num_chains), self.sharding
        )
        # A rule's warm-up reads the starts only: the states are those of the sampler it builds.
        rule = adapting and cast(Tunable, sampler.adaptation).method == "rule"
        states = None if rule else self._init_states(sampler)
        self.run_warmup = o.num_warmup > 0
        self.tuned, self.tuning = None, None
        if adapting:
            self.phase("warm-up (adapting)")
            # From the initial states and deterministic given rng_key: a resumed run re-derives
            # the same parameters.
            starts = self.placed_positions()
            plan = dual_averaging_plan(sampler, starts, _dtype(self.positions))
            if plan is not None:  # in the program of the chunks
                sampler, adapted = self._dual_averaging(sampler, states, plan)
            else:
                sampler, adapted = warm_up(
                    sampler, self.rng_key, self.chain_keys, states, starts, o.num_warmup
                )
            arguments.check_starts(sampler, self.positions, self.num_chains)
            if adapted is not None:
                self.run_warmup = False
                states = shard_chains(adapted, self.sharding)
        if states is None:
            states = self._init_states(sampler)
        # after the names are checked and the step is set: tracing the step
        self.sampler = scalar_info(sampler, arguments.take_chain(self.positions, 0))
        # the compiled programs' static sampler and traced values
        program_now = program(self.sampler, self.positions)
        if self.executable is not None and program_now[0] != self.program[0]:
            self.executable = None  # not the program the warm-up compiled (never expected)
        self.program = program_now
        self.states = states
        self.settings = dict(sampler.settings, num_warmup=o.num_warmup, adapted=adapting)

    def _dual_averaging(self, sampler, states, plan):
        """``(tuned, states)``: dual averaging's warm-up run by the program that then runs the
        chunks (:func:`_run_chunk`), compiled here."""
        self.tuned, start = plan
        self.sampler = scalar_info(sampler, arguments.take_chain(self.positions, 0))
        self.program = program(self.sampler, self.positions)
        values = self.program[1]
        if values is None:
            raise ValueError("dual averaging steps the sampler's Structure: it declares none")
        values = dict(values, **{self.tuned.name: start.initial})
        self.states, self.tuning = states, start  # the chunks adapt nothing (until = 0)
        self.compile(0)
        self.phase("warm-up (adapting)")
        run = cast(Callable, self.executable)
        warm = start._replace(until=jnp.asarray(self.options.num_warmup))
        moved, _, ends = run(states, self.chain_keys, 0, self.options.num_warmup, values, warm)
        until = self.options.num_warmup
        return tuned_by_dual_averaging(sampler, start.initial, ends, until), moved

    def _init_states(self, sampler):
        """Every chain's initial state, placed as the run is sharded."""
        static, values = program(sampler, self.positions)
        states = _init_states(self.placed_positions(), values, sampler=static)
        return shard_chains(states, self.sharding)

    def placed_positions(self):
        """The starts, split over the devices for a lattice run (each device then inits and
        warms up its own sites); else as given (the chains' programs place them)."""
        if isinstance(self.sharding, LatticeSharding):
            return shard_chains(self.positions, self.sharding)
        return self.positions

    def _fingerprint(self):
        tree = self.example[0]
        variables = {
            f"{group}/{name}": list(tree[group][name].dims)
            for group in tree.children
            for name in tree[group].data_vars
        }
        return run_fingerprint(
            self.algorithm,
            dict(self.sampler.settings),
            rng_key=self.rng_key,
            initial_positions=self.positions,
            num_warmup=self.options.num_warmup,
            thinning=self.options.thinning,
            keep_positions=self.options.keep_positions,
            observe=self.observe,
            log_likelihood=_observe(self.log_likelihood_key),
            variables=variables,
            names=[self.spec.var_name, self.spec.event_dims],
        )

    def resume(self):
        """``(draws_done, saved draws)``: the saved run's, after checking what made it."""
        if self.store is None:
            return 0, None
        first = jax.tree.map(lambda leaf: leaf[0], (self.states, self.chain_keys))
        adapted = adapted_fingerprint(self.sampler, first[0], first[1])
        self.fingerprint.update(adapted)
        done, states, previous = 0, None, None
        with agreement(f"reading the saved run {self.store.path!r}", self.across) as agreed:
            self.store.check(self.fingerprint, required=adapted)
            if self.store.exists:
                _, positions, observables, log_likelihood = self.example
                layout = Layout(positions, observables, log_likelihood, self.spec.var_name or "mu")
                done, states, previous = self.store.resume(self.states, layout, self.num_draws)
            agreed.value = self.store.view()
        if self.across:
            check_same_file(agreed.values, self.store.path)
        if done:
            self.states = shard_chains(states, self.sharding)
            self.run_warmup = False
        return done, previous

    def compile(self, done):
        """The one executable of this run, compiled before the timed loop: a chunk of
        ``self.chunk`` draws, which runs the warm-up's steps and a shorter last chunk too
        (:func:`_run_chunk`); ``jax.jit``'s cache keeps it for a next run."""
        o = self.options
        self.phase("compiling")
        self.chunk = arguments.chunk_length(self.num_draws, o.chunk_draws)
        static, values = self.program
        if self.executable is None and (self.run_warmup or done < self.num_draws):
            self.executable = _run_chunk.lower(
                self.states, self.chain_keys, 0, 0, values, self.tuning,
                sampler=static,
                count=min(self.chunk, self.num_draws),
                thinning=o.thinning,
                observables=self.observables_key,
                log_likelihood=self.log_likelihood_key,
                keep_positions=o.keep_positions,
                tuned=self.tuned,
            ).compile()  # fmt: skip

    def _split(self, recorded, info):
        """One chunk's draws: ``positions``, ``info``, ``observables``, ``log_likelihood``."""
        if self.observables_key is None and self.log_likelihood_key is None:
            recorded = {"positions": recorded}  # the default loop records the positions alone
        return {name: recorded.get(name) for name in DRAWS} | {"info": info}

    def loop(self, done, previous):
        """Run the chunks from draw ``done``, saving each; the list of chunks (the saved run's
        first: dicts as :meth:`_split` makes them) and the wall time."""
        o = self.options
        chunks = [] if previous is None else [previous]
        if previous is not None:
            record_casimir_drift(self.settings, previous["info"])
        start = time.perf_counter()
        states, bar = self.states, self.bar
        values = self.program[1]
        run = cast(Callable, self.executable)  # compiled wherever a step is to run
        if self.run_warmup:
            self.phase("warm-up")
            steps = run(states, self.chain_keys, 0, o.num_warmup, values, self.tuning)
            states = jax.block_until_ready(steps[0])
        self.phase("sampling")
        if done:
            bar.update(done)  # the draws already saved
        wall_time = None  # until the last chunk: the file's attributes record the same
        while done < self.num_draws:
            count = min(self.chunk, self.num_draws - done)
            first_step = o.num_warmup + done * o.thinning
            states, recorded, _ = run(
                states, self.chain_keys, first_step, count * o.thinning, values, self.tuning
            )
            recorded = to_host(recorded)
            if count < self.chunk:  # the last chunk, shorter: its first draws
                recorded = jax.tree.map(lambda leaf, n=count: leaf[:, :n], recorded)
            chunks.append(self._split(*cast(tuple, recorded)))
            record_casimir_drift(self.settings, chunks[-1]["info"])  # the file records it
            wall_time = time.perf_counter() - start
            done += count
            if self.store is not None:
                self._save(done - count, done, chunks[-1], states, wall_time)
            bar.update(count)
            # over several processes, every process agrees here (a callback may be given on
            # some of them only, e.g. to report from process 0)
            with agreement(f"running callback({done})", self.across):
                if o.callback is not None:
                    o.callback(done)
        if wall_time is None:  # nothing ran (a finished run resumed): the warm-up's time
            wall_time = time.perf_counter() - start
        return chunks, wall_time

    def _save(self, first, end, draws, states, wall_time):
        """Write the draws ``first … end`` to the run file, with the tree's attributes then
        (over several processes: the states gathered on every process, written by process 0,
        which tells the others whether it succeeded)."""
        states = to_host(states)  # a collective over several processes: every process takes it
        saving = f"saving draws {first} to {end - 1} of the run to {self.options.output!r}"
        with agreement(saving, self.across):
            if self.writer:
                self._write(first, end, draws, states, wall_time)

    def _write(self, first, end, draws, states, wall_time):
        """The writer's part of :meth:`_save` (``states`` on the host)."""
        o = self.options
        attrs = run_attrs(
            self.settings,
            on_nonfinite=o.on_nonfinite,
            wall_time=wall_time,
            num_steps=o.num_warmup + end * o.thinning,
        )
        with warnings.catch_warnings():  # ArviZ remarks on a chunk with few draws
            warnings.filterwarnings("ignore", "Found chain dimension", UserWarning)
            tree = self.spec.build(
                draws["positions"],
                draws["info"],
                draws["observables"],
                self.settings,
                thinning=o.thinning,
                attrs=attrs,
                log_likelihood=draws["log_likelihood"],
            )
        stats_names = {**SAMPLE_STATS_NAMES, "energy": self.spec.energy_name or "energy"}
        names = {
            stats_names.get(k, k): [k, np.asarray(v).dtype.str] for k, v in draws["info"].items()
        }
        store = cast(RunFile, self.store)  # a chunk is stored only when the run has a file
        store.append(first, tree, names, states, self.fingerprint)

    def finish(self, chunks, wall_time, convergence) -> ChainsResult:
        """The result of the whole run, after the post-run checks (with the convergence checks
        of every variable if ``convergence``)."""
        o = self.options

        def joined(name):
            pieces = [chunk[name] for chunk in chunks]
            if pieces[0] is None:
                return None
            return jax.tree.map(lambda *parts: np.concatenate(parts, axis=1), *pieces)

        result = ChainsResult(
            joined("positions"),
            joined("info"),
            wall_time,
            o.num_warmup + self.num_draws * o.thinning,
            self.settings,
            joined("observables"),
            joined("log_likelihood"),
        )
        groups = self.sampler.law_groups
        groups = None if groups is None else groups(self.positions)
        check_run(
            result.info,
            _variables(result, self.spec.var_name or "mu"),
            groups,
            on_nonfinite=o.on_nonfinite,
            min_acceptance_rate=o.min_acceptance_rate,
            stuck_advice=self.sampler.stuck_advice,
            divergence_advice=self.sampler.divergence_advice,
            convergence=convergence,
            stacklevel=5,
        )
        return result


def _check_same_output(found: list, output) -> None:
    """Refuse a run over several processes unless every process gives ``output=`` and
    ``resume=`` alike (``found``: each process's ``[output given, resume, file view]``), and
    then, with ``output=``, finds the same file (:func:`check_same_file`)."""
    differ = [i for i, (given, resume, _) in enumerate(found) if [given, resume] != found[0][:2]]
    if differ:
        described = "; ".join(
            f"process {i}: {'output=<path>' if given else 'output=None'}, resume={resume}"
            for i, (given, resume, _) in enumerate(found)
        )
        raise ValueError(
            f"output= and resume= differ between the processes of this run ({described}): in a "
            "run over several processes every process passes the same output= and resume= "
            "(process 0 writes the file, every process reads it on a resume and waits for "
            "process 0 at each chunk); pass them alike on every process"
        )
    if found[0][0]:
        check_same_file([view for *_, view in found], output)


def _variables(result: ChainsResult, var_name: str) -> dict[str, np.ndarray]:
    """The recorded variables of ``result`` by their ``DataTree`` names (positions, then
    observables; complex leaves as their real and imaginary parts)."""
    from liesample.analysis.diagnostics import pytree_variables

    variables = {}
    for tree, single in ((result.positions, var_name), (result.observables, "observable")):
        if tree is None:
            continue
        tree = {single: tree} if is_single_array(tree) else tree
        variables.update({name: value for name, (value, _) in pytree_variables(tree).items()})
    return variables


def run_chains(algorithm, rng_key, initial_positions, num_draws, options, spec, convergence):
    """:func:`liesample.run.runner.sample_chains` with its keywords as ``options``
    (:class:`RunOptions`) and the names of the draws as ``spec`` (:class:`TreeSpec`);
    ``(result, spec)``, the spec as the run named the draws (completed by the sampler's
    declared names, or on a resume the saved run's). ``convergence``: run the convergence
    checks of every variable after the run (:func:`liesample.sample` does; the low-level
    :func:`liesample.sample_chains` leaves them to its caller)."""
    run = _Run(algorithm, rng_key, initial_positions, num_draws, options, spec)
    try:
        try:
            run.start()
        except (ValueError, TypeError) as error:
            # a start without its chain axis fails the checks of the starts: named as such
            # (probed only then, with the shapes of init)
            arguments.check_chain_axis(run.sampler, run.positions, error)
            raise
        done, previous = run.resume()
        run.compile(done)
        chunks, wall_time = run.loop(done, previous)
    finally:
        run.bar.close()
        if run.store is not None:
            run.store.close()
    return run.finish(chunks, wall_time, convergence), run.spec
