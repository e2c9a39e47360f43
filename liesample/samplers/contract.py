"""What every liesample sampler promises: one ``Info`` contract, one sampler object, one help().

**The Info contract.** The ``info`` that ``step(rng_key, state) -> (state, info)`` returns is a
NamedTuple with at least these scalar fields (per chain), in these meanings:

``is_divergent`` (bool)
    The step went wrong: its proposed state, or the energy there, was not finite (NaN/inf).
    The step was rejected (the chain kept its previous state). Magnetic HMC also flags a
    trajectory whose energy error exceeds its ``divergence_threshold``.
``acceptance_rate`` (float in [0, 1])
    The probability with which the step's proposal was accepted. **Rule for unadjusted
    samplers** (no Metropolis test): ``1.0`` for every step taken and ``0.0`` for a step
    rejected because it diverged, so the field is present for every sampler and a chain that
    only diverges reads as stuck.
``energy`` (float)
    The energy of the chain's state after the step: ``h`` on an orbit, ``H = −log π + ½pᵀM⁻¹p``
    on ``T*Rⁿ`` (magnetic HMC: of the proposal, as in BlackJAX). In a ``DataTree`` it is
    ArviZ's ``energy`` only where it is that total energy of a state with a momentum, which
    ArviZ's BFMI and energy plot assume; ``h`` of a state without one is ``hamiltonian``
    (:func:`energy_name`).

Samplers add their own fields after these (``casimir_error``, ``is_accepted``, …); the
reduction of a field over the ``thinning`` steps of one stored draw is in
:data:`REDUCE_OVER_THINNING` (``any`` for divergences, mean for acceptance, max for the Casimir
drift, the last step otherwise) and ArviZ's ``sample_stats`` names in
:data:`SAMPLE_STATS_NAMES`. :func:`check_info` verifies a sampler against the contract.

**The sampler object.** ``as_top_level_api`` returns a :class:`Sampler`: BlackJAX's
``SamplingAlgorithm`` (``init``, ``step``; unpacks and duck-types as one) that declares, as
attributes with defaults, what the runner and the step loop read: ``settings`` (recorded in
the ``DataTree`` attributes), ``check_positions`` (checks every start in one vectorised call),
``adaptation`` (a :class:`Tunable`: what the warm-up tunes and how, an instance of the
adaptation protocol of :mod:`liesample.tuning.protocol`), ``noise_blocks``
(:class:`liesample.integrators.chain_loop.NoiseBlocks`), ``structure`` (:class:`Structure`:
what decides its compiled program, and the numbers it traces) and ``recipe``
(:class:`Recipe`: the factory call that made it).
:func:`as_sampler` reads a plain BlackJAX ``SamplingAlgorithm`` as a :class:`Sampler` with the
defaults. ``step`` is pure: a sampler's numbers are fixed when it is built; tuning returns numbers,
and the tuned sampler is its ``recipe`` called with them, stepped by the same compiled
program (its ``structure``, with the numbers traced).

**help().** :func:`sampling_api` builds the module-level ``liesample.<sampler>`` object, a
``blackjax.GenerateSamplingAPI`` whose ``help()`` is the top-level docstring.

**Precision.** Samplers run in the precision of their inputs: JAX's default is float32; call
``jax.config.update("jax_enable_x64", True)`` at start-up for float64 (what every test and
benchmark here uses). :func:`liesample.integrators.stability.check_precision` states when float32
is not enough and warns once.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, cast, runtime_checkable

import blackjax
import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.identity import Program
from liesample.foundation.validation import single_key
from liesample.integrators.chain_loop import DeclaresNoiseBlocks

__all__ = [
    "CONTRACT_FIELDS",
    "REDUCE_OVER_THINNING",
    "SAMPLE_STATS_NAMES",
    "BasicInfo",
    "DrawNames",
    "Rebuild",
    "Recipe",
    "Sampler",
    "SamplerInfo",
    "Structure",
    "Tunable",
    "as_sampler",
    "check_info",
    "energy_name",
    "first_bad_chain",
    "sampling_api",
    "setting",
    "step_key",
]

CONTRACT_FIELDS = ("is_divergent", "acceptance_rate", "energy")
"""The fields every sampler's ``info`` has (module docstring)."""


@runtime_checkable
class SamplerInfo(Protocol):
    """The Info contract as a protocol (the module docstring gives the meanings)."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array


class BasicInfo(NamedTuple):
    """An ``info`` with the contract's fields only, for samplers that report nothing more (the
    spin and vortex sweeps): ``is_divergent`` (the step produced a non-finite state or energy,
    and the chain kept its state), ``acceptance_rate`` (the fraction of the step's proposals
    accepted: 1 for rejection-free moves, 0 for a divergent step), ``energy`` (``h`` of the
    chain's state after the step)."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array


def _mean(values):
    return jnp.mean(values.astype(jnp.result_type(float)), axis=0)


def _last(values):
    return values[-1]


REDUCE_OVER_THINNING = {
    "is_divergent": functools.partial(jnp.any, axis=0),
    "acceptance_rate": _mean,
    "casimir_error": functools.partial(jnp.max, axis=0),
}
"""How a per-step field is summarised over the steps one thinned draw spans (default: last)."""


def reduce_over_thinning(name: str):
    """The reduction of info field ``name`` over a thinning window (leading axis: steps)."""
    return REDUCE_OVER_THINNING.get(name, _last)


SAMPLE_STATS_NAMES = {
    "is_divergent": "diverging",
    "acceptance_rate": "acceptance_rate",
    "energy": "energy",
    "casimir_error": "casimir_error",
}
"""Info field -> ArviZ ``sample_stats`` name (other fields keep their own names)."""


def check_info(info) -> None:
    """Raise ``TypeError`` unless ``info`` (an instance or a NamedTuple class) has the contract's
    fields."""
    fields = getattr(info, "_fields", None)
    if fields is None:
        raise TypeError(f"info must be a NamedTuple, got {type(info).__name__}")
    missing = [name for name in CONTRACT_FIELDS if name not in fields]
    if missing:
        raise TypeError(
            f"{getattr(info, '__name__', type(info).__name__)} lacks the Info contract's "
            f"fields {missing} (liesample.samplers.contract)"
        )


class Tunable(NamedTuple):
    """What a sampler's warm-up tunes, and how: the one declaration the tuning layer reads.

    A declaration of numbers only: :mod:`liesample.tuning` (a higher layer) makes of it an
    instance of the one adaptation protocol (:mod:`liesample.tuning.protocol`), whose result is
    numbers, and the tuned sampler is the sampler's :class:`Recipe` called with them. An orbit
    sampler declares it as ``Sampler.adaptation`` (:mod:`liesample.tuning.warmup` reads it, for
    :func:`liesample.sample`'s warm-up); a T*G sampler's API object as
    ``sampling_api(adaptation=…)`` (:func:`liesample.window_adaptation` and the NumPyro kernel
    read it; ``given`` and ``choose`` are then unused), and the sampler it builds as
    ``Sampler.adaptation`` with ``given`` set (read by :func:`liesample.sample`'s warm-up).

    method : str
        ``"dual_averaging"`` (the shared step of all chains tuned to a target of their pooled
        acceptance rate, :func:`liesample.tuning.protocol.step_size_adaptation`, stepping the
        sampler's :class:`Structure` with the step traced), ``"rule"`` (the step computed from
        the run's starts by ``choose``, nothing learnt from the transitions,
        :func:`liesample.tuning.protocol.fixed`), ``"window"`` (Stan's windows: step size, mass
        and, for HMC, the integration time, :func:`liesample.tuning.windows.windows_adaptation`)
        or ``"chees"`` (the same on several chains with the field of magnetic HMC,
        :func:`liesample.magnetic_window_adaptation`, then its jittered sampler).
    given : bool
        The user gave the step size: without ``adapt=True`` the warm-up keeps it.
    choose : callable
        ``(positions, rng_key) -> (step_size, source)``: the sampler's automatic step for the
        starts ``positions`` (chains first) and a description of how it was chosen.
        ``rng_key=None`` is the choice without warm-up; a key, the warm-up's choice.
    target_acceptance_rate : float or None
        What ``"dual_averaging"`` aims at.
    max_step_size : float or None
        The largest step ``"dual_averaging"`` may use (where every proposal is accepted, at
        ``β = 0`` say, it would grow the step without bound); ``None``: no bound.
    adapted : tuple of str
        The numbers the warm-up tunes, by their keyword in the sampler's :class:`Recipe` and
        :class:`Structure` (``("step_size",)`` for the orbit samplers, ``("proposal_scale",)``
        for the vortices' Metropolis; ``step_size``, ``inverse_mass_matrix``,
        ``num_integration_steps``, ``magnetic_field``); ``"rule"`` and ``"dual_averaging"``
        tune the first.
    accepts : tuple of str
        The kernel's parameters a caller of the window adaptation may give.
    options : tuple of str
        ``build_kernel``'s keywords (the integration scheme ``integrator`` among them).
    defaults : dict
        Values used for parameters not given (e.g. ``friction``).
    """

    method: str
    given: bool = False
    choose: Callable | None = None
    target_acceptance_rate: float | None = None
    max_step_size: float | None = None
    adapted: tuple = ("step_size",)
    accepts: tuple = ()
    options: tuple = ()
    defaults: Mapping = MappingProxyType({})


class DrawNames(NamedTuple):
    """How a sampler's single-array positions are named in a ``DataTree``."""

    var_name: str
    event_dims: tuple[str, ...]


class Structure(NamedTuple):
    """A sampler split into what decides its compiled program and what may be traced.

    build : callable
        ``build(**values) -> Sampler`` whose ``init``, ``step`` and ``noise_blocks`` are those
        of the sampler declaring it, for traced ``values``; hashable, and equal for two samplers
        that differ only in ``values`` (a frozen dataclass of the system, the integrator, …).
    values : dict
        The sampler's numeric parameters (name -> float): ``β``, ``σ``, the step size.
    """

    build: Callable
    values: Mapping


class Rebuild(Program):
    """A :class:`Structure`'s ``build`` for a sampler built by one call of its factory:
    ``build(**values)`` is ``factory(*args, **options, **values)`` (without the
    :class:`ValidityWarning` its first build gave), and two are equal when their factories are
    and their ``args`` and ``options`` are canonically equal
    (:class:`liesample.foundation.identity.Program`): the same log density and space, the same
    scheme and options, whatever the numbers in ``values``."""

    __slots__ = ()

    def __init__(self, factory: Callable, args: tuple, options: Mapping):
        super().__init__(factory, tuple(args), dict(options))

    def __call__(self, **values):  # type: ignore[override]
        args, options = self.static
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityWarning)
            return self.make(*args, **options, **values)


class Recipe(NamedTuple):
    """The call that made a sampler, ``factory(*args, **options, **numbers)``: what a warm-up
    remakes it with, its tuned numbers in place of the old (:meth:`__call__`).

    ``numbers`` are the keywords a warm-up may tune or a sweep vary (the step size, ``β``, a
    mass, a model's arguments), ``options`` the others (the scheme, a threshold); a number left
    ``None`` is unset (a step the warm-up is to choose).
    """

    factory: Callable
    args: tuple
    options: Mapping
    numbers: Mapping

    def __call__(self, source: str | None = None, **numbers) -> Sampler:
        """The sampler with ``numbers`` in place of the recipe's, ``source`` (how they were
        chosen) recorded as its ``step_size_source`` setting; without the
        :class:`ValidityWarning` the user's build gave."""
        unknown = sorted(set(numbers) - set(self.numbers))
        if unknown:
            raise TypeError(f"{unknown} are not numbers of this sampler: {sorted(self.numbers)}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ValidityWarning)
            sampler = self.factory(*self.args, **self.options, **{**self.numbers, **numbers})
        if source is not None:
            sampler.settings["step_size_source"] = source
        return sampler

    def structure(self) -> Structure | None:
        """The :class:`Structure` of a factory whose numbers can be traced (the ``T*G`` and
        magnetic samplers): ``build`` a :class:`Rebuild` of the factory, ``values`` the numbers
        that are set; ``None`` where ``args`` or ``options`` have no canonical form (the sampler
        is then compiled for its own object)."""
        numbers = {k: v for k, v in self.numbers.items() if v is not None}
        unset = {k: v for k, v in self.numbers.items() if v is None}
        build = Rebuild(self.factory, self.args, {**self.options, **unset})
        return Structure(build, numbers) if build.by_value else None


class Sampler(blackjax.base.SamplingAlgorithm, DeclaresNoiseBlocks):
    """``SamplingAlgorithm(init, step)`` plus what the runner and the step loop read.

    Every attribute below is declared, with its default; a sampler sets those it has.

    Attributes
    ----------
    settings : dict
        What the sampler was built with (name, step size, how it was chosen, …), recorded in
        the attributes of the ``DataTree`` that :func:`liesample.sample` returns. Default: empty
        (``Sampler(...)`` gives each sampler its own dict).
    check_positions : callable or None
        ``positions (chains, ...), *, step_size_checks=True -> None``: every start checked in
        one vectorised call, raising an error that names the first bad chain
        (``initial_positions[c]: …``). ``None`` (default): the runner calls ``init`` on every
        distinct start.
    adaptation : Tunable or None
        What the warm-up tunes and how; ``None`` (default): nothing to tune.
    noise_blocks : liesample.integrators.chain_loop.NoiseBlocks or None
        How ``step`` consumes noise drawn in blocks; ``None`` (default): one key per step.
    law_groups : callable or None
        ``positions (chains, ...) -> labels (chains,)``: chains with one label sample one law
        (the orbit samplers: one orbit), so the runner compares their energies (split R-hat)
        only within a label. ``None`` (default): every chain samples the same law.
    draw_names : DrawNames or None
        The name and event dims of a single-array position in the ``DataTree`` of
        :func:`liesample.sample` (e.g. ``R`` with dims ``(row, col)`` on ``SO(3)``); ``None``
        (default): named from the event's rank.
    stuck_advice : str or None
        What to do when a chain is stuck (its acceptance rate near 0): a call that works for
        this sampler, which the runner's stuck-chain warning quotes. ``None`` (default): the
        runner's generic advice.
    divergence_advice : str or None
        What to do when steps diverge and the model is not at fault (no NaN energy), which the
        runner's divergence warning quotes: an unadjusted sampler names its Metropolis-adjusted
        sibling, since it cannot sample a density that is −∞ or jumps somewhere (a bounded
        support, a discontinuity). ``None`` (default): the runner's generic advice (a smaller
        step).
    energy_name : str or None
        The ``sample_stats`` name of ``info.energy`` (:func:`energy_name`): ``"energy"`` for
        HMC's total energy ``H(q, p)``, ``"hamiltonian"`` for ``h`` of a state. ``None``
        (default): decided by whether the state carries a ``momentum``.
    structure : Structure or None
        The sampler as a structure and numeric values (:class:`Structure`), so that the runner
        compiles one program for every sampler of the same structure (a sweep over ``β``, a
        step size chosen per run). ``None`` (default): the runner compiles for this object.
    recipe : Recipe or None
        The factory call that made the sampler (:class:`Recipe`): a warm-up's tuned numbers
        give the tuned sampler ``recipe(source, **numbers)``. ``None`` (default): nothing
        remakes it (a sampler without an ``adaptation``).
    """

    if TYPE_CHECKING:  # a sampler's own dict (the hooks give each one); read-only placeholder
        settings: dict[str, Any]
    else:
        settings = MappingProxyType({})
    check_positions: Callable | None = None
    adaptation: Tunable | None = None
    draw_names: DrawNames | None = None
    law_groups: Callable | None = None
    stuck_advice: str | None = None
    divergence_advice: str | None = None
    energy_name: str | None = None
    structure: Structure | None = None
    recipe: Recipe | None = None

    def __new__(cls, init, step, **hooks):
        unknown = sorted(set(hooks) - set(HOOKS))
        if unknown:
            raise TypeError(f"Sampler declares no hook {unknown}; its hooks are {list(HOOKS)}")
        self = super().__new__(cls, init, step)
        for name, default in HOOKS.items():
            value = hooks.get(name)
            setattr(self, name, default() if value is None and default else value)
        return self


HOOKS = {
    "settings": dict,
    "check_positions": None,
    "adaptation": None,
    "noise_blocks": None,
    "draw_names": None,
    "law_groups": None,
    "stuck_advice": None,
    "divergence_advice": None,
    "energy_name": None,
    "structure": None,
    "recipe": None,
}
"""The hooks a :class:`Sampler` declares, each with the factory of its default (``None``:
the default is ``None``); keyword arguments of ``Sampler(init, step, **hooks)``."""


class ValidityWarning(UserWarning):
    """A sampler built where it is known not to sample its target reliably (the message says
    why and what to do instead); given once, when the user builds it, not again when the
    warm-up remakes it with a tuned step (:class:`Recipe`)."""


def as_sampler(algorithm) -> Sampler:
    """``algorithm`` as a :class:`Sampler`: itself if it is one, else a ``Sampler`` with its
    ``init`` and ``step`` and the defaults (a plain BlackJAX ``SamplingAlgorithm``, whose
    ``info.energy``, where it has one, is HMC's total energy: ``energy_name="energy"``)."""
    if isinstance(algorithm, Sampler):
        return algorithm
    return Sampler(algorithm.init, algorithm.step, energy_name="energy")


STEP_KEY_FIX = (
    "a step moves one chain with one key; to step several chains at once, vmap it: "
    "jax.vmap(sampler.step)(jax.random.split(key, num_chains), states)"
)


def step_key(rng_key) -> jax.Array:
    """The ``rng_key`` a sampler's ``step`` was given, as one typed key: either key style
    (``jax.random.key``, the older ``jax.random.PRNGKey``), a batch of keys or anything else
    refused by name (:func:`liesample.foundation.validation.single_key`). Every liesample
    ``step`` reads its key through this; it reads only shapes and dtypes (traced keys pass)."""
    return single_key(rng_key, "rng_key", batch_fix=STEP_KEY_FIX)


def energy_name(sampler: Sampler, position) -> str:
    """The ``sample_stats`` name of ``sampler``'s ``info.energy`` in a ``DataTree``.

    ``"energy"`` (ArviZ's name) where it is HMC's total energy ``H(q, p) = −log π(q) +
    kinetic(p)``: ArviZ's ``bfmi`` and ``plot_energy`` read that variable and assume it is.
    ``"hamiltonian"`` where it is ``h`` of a state without a momentum (the orbit, spin and
    gauge heat-bath samplers): a function of the position, on which those diagnostics would
    report a number that means nothing. The sampler's ``energy_name`` hook decides where it is
    set; otherwise the state that ``sampler.init(position)`` returns does: ``"energy"`` if it
    has a ``momentum`` field, else ``"hamiltonian"``.
    """
    if sampler.energy_name is not None:
        return sampler.energy_name
    state = jax.eval_shape(sampler.init, position)
    return "energy" if hasattr(state, "momentum") else "hamiltonian"


def setting(value):
    """A scalar parameter as a plain number for :attr:`Sampler.settings` (``None`` if traced)."""
    try:
        return np.asarray(value).item()
    except (jax.errors.TracerArrayConversionError, ValueError, TypeError):
        return None


def first_bad_chain(ok) -> int | None:
    """Index of the first ``False`` in a boolean per-chain array, or ``None``."""
    bad = np.flatnonzero(~np.asarray(ok, dtype=bool))
    return int(bad[0]) if bad.size else None


_PRECISION_NOTE = """
Notes
-----
Precision: the sampler computes in the dtype of its inputs. JAX defaults to float32; for
float64 call ``jax.config.update("jax_enable_x64", True)`` before creating arrays.

Info contract (:mod:`liesample.samplers.contract`): ``info.is_divergent``,
``info.acceptance_rate`` and ``info.energy``, plus the sampler's own fields.

Low-level pieces: ``{name}.init``, ``{name}.build_kernel`` (BlackJAX-shaped).
"""


class SamplingAPI[**P](Protocol):
    """What :func:`sampling_api` returns: called as its ``as_top_level_api`` (same parameters)
    for a :class:`Sampler`, with BlackJAX's low-level ``init`` and ``build_kernel`` and the
    warm-up's declaration ``adaptation``."""

    init: Callable[..., Any]
    build_kernel: Callable[..., Any]
    differentiable: Callable[P, Sampler]
    adaptation: Tunable | None

    def __call__(self, *args: P.args, **kwargs: P.kwargs) -> Sampler: ...


def sampling_api[**P](
    as_top_level_api: Callable[P, Sampler],
    init: Callable[..., Any],
    build_kernel: Callable[..., Any],
    name: str,
    module: str,
    *,
    adaptation: Tunable | None = None,
) -> SamplingAPI[P]:
    """``blackjax.GenerateSamplingAPI(as_top_level_api, init, build_kernel)`` whose ``help()``
    and ``__doc__`` are ``as_top_level_api``'s docstring (plus the precision rule) and whose
    call signature is that of ``as_top_level_api``.

    ``adaptation``, a :class:`Tunable` stored as the object's ``.adaptation`` (``None``:
    none), declares how :func:`liesample.window_adaptation` (and the NumPyro kernel) tunes the
    sampler."""
    doc = inspect.cleandoc(as_top_level_api.__doc__ or "")
    head, examples, tail = doc.partition("\nExamples\n--------\n")  # the examples stay last
    doc = head + "\n" + _PRECISION_NOTE.format(name=name) + examples + tail

    @functools.wraps(as_top_level_api)
    def __call__(self, *args, **kwargs):
        return self.differentiable(*args, **kwargs)

    __call__.__doc__ = doc
    cls = type(
        name,
        (blackjax.GenerateSamplingAPI,),
        {
            "__doc__": doc,
            "__module__": module,
            "__qualname__": name,
            "__call__": __call__,
            # help() shows how the sampler is called, not the dataclass fields.
            "__signature__": inspect.signature(as_top_level_api),
        },
    )
    api = cls(as_top_level_api, init, build_kernel)
    if adaptation is not None and not isinstance(adaptation, Tunable):
        raise TypeError(f"adaptation must be a Tunable, got {type(adaptation).__name__}")
    api.adaptation = adaptation
    return cast(SamplingAPI[P], api)  # blackjax's class, with the call and attribute above


class PositionCheck(NamedTuple):
    """Per-chain results of a vectorised start check (used by :func:`raise_first_bad`)."""

    ok: np.ndarray
    message: str


def raise_first_bad(checks, positions, recheck=None, exception=ValueError):
    """Raise for the first chain failing any of ``checks`` (``PositionCheck``s, in order).

    ``recheck(position, name)`` (e.g. ``system.check_position``) is called on that chain first
    so that the error is the system's own message; otherwise ``exception(message)``.
    """
    for check in checks:
        chain = first_bad_chain(check.ok)
        if chain is None:
            continue
        name = f"initial_positions[{chain}]"
        if recheck is not None:
            recheck(positions[chain], name)
        raise exception(f"{name}: {check.message}")
