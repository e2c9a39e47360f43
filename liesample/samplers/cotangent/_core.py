"""The geometric samplers' core on ``T*G`` (left-trivialised, ``G × g*``): chain state, Info
contract, ``init``, the Metropolis test and the two transitions every sampler is built from.

The Hamiltonian is ``H(g, p) = −log π(g) + ½ pᵀM⁻¹p`` on a space (or product of spaces) from
:mod:`liesample.geometry.spaces`; ``log π`` is a log-density with respect to the product of Haar
(groups), uniform (spheres) and Lebesgue (``Euclidean``) measures. An optional constant
antisymmetric magnetic field ``G`` acts on the ``Euclidean`` coordinates. The moves are the
one-effect steps of :mod:`liesample.geometry.cotangent` (kick ``B``, exact kinetic–magnetic drift
``A``, exact OU refresh ``O``) composed by coefficient lists:

- :func:`hamiltonian_transition`: a momentum (fresh, partially refreshed or OU-refreshed),
  ``L`` steps of a palindromic scheme of ``B`` and ``A`` (the leapfrog ``B A B`` by default;
  :func:`hamiltonian_scheme`), the Metropolis test and the flip. With a field the proposal
  ``(g, p, s) ↦ (g', −p', −s)`` (``s = ±1`` the sign of ``G``) is an involution that preserves
  the Liouville measure (running the flow of ``−sG`` from ``(g', −p')`` retraces the path), so
  the test keeps ``exp(−H)`` exactly at any step size; the flip ``(p, s) ↦ (−p, −s)`` after it
  (Horowitz 1991) keeps the direction of motion on acceptance. Without a field ``s`` is inert.
  Geometric HMC, adjusted geometric Langevin and magnetic HMC are this transition.
- :func:`unadjusted_transition`: one step of a scheme containing ``O`` (``OBAB`` for geometric
  Langevin, ``BAOAB`` for magnetic Langevin by default), every finite step taken.

The scheme travels in the :class:`Move` (:func:`make_move`): the samplers' ``integrator=``
argument, a name of :data:`liesample.geometry.cotangent.SCHEMES` or a coefficient list.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from liesample.foundation.types import PyTree
from liesample.foundation.validation import concrete_array
from liesample.geometry import spaces
from liesample.geometry.cotangent import (
    CotangentBundle,
    PhasePoint,
    check_scheme,
    compose,
    cotangent_bundle,
    drift,
    evaluated,
    fractions,
    gradient_evaluations,
    kick,
    refresh,
)
from liesample.samplers.contract import DrawNames, Sampler, setting

__all__ = [
    "GeometricInfo",
    "GeometricState",
    "Move",
    "check_logdensity_fn",
    "check_logdensity_value",
    "check_positive_step_size",
    "check_starts",
    "drift_flows",
    "energy",
    "energy_errors",
    "hamiltonian_scheme",
    "hamiltonian_transition",
    "init",
    "kernel_move",
    "make_move",
    "metropolis",
    "model_values",
    "ravelled",
    "scheme_setting",
    "scheme_step",
    "select",
    "space_sampler",
    "space_settings",
    "trajectory_cost",
    "unadjusted_transition",
    "with_model_arguments",
]


class GeometricState(NamedTuple):
    """State of a chain.

    position : a point of the space (pytree like the space).
    logdensity : ``log π(position)``.
    logdensity_grad : the trivialised gradient (algebra coordinates, pytree like the space).
    momentum : the momentum carried between transitions (Langevin, and HMC with partial
        refreshment; full-refresh HMC redraws it).
    magnetic_sign : ``s = ±1``, the sign of the magnetic field for the next move (inert
        without a field).
    """

    position: PyTree
    logdensity: jax.Array
    logdensity_grad: PyTree
    momentum: PyTree
    magnetic_sign: jax.Array | float = 1.0


class GeometricInfo(NamedTuple):
    """What one transition did.

    acceptance_rate : ``min(1, e^{−ΔH})`` (0 for a non-finite proposal); for the unadjusted
        Langevin sampler 1 for a step taken and 0 for a step rejected as non-finite (the
        library's Info contract for unadjusted samplers).
    is_accepted : whether the proposal was taken.
    is_divergent : the proposal's state or energy is non-finite, or ``ΔH`` exceeds the
        divergence threshold; for HMC at any step of the trajectory
        (:func:`hamiltonian_transition`).
    energy : ``H`` of the proposal for HMC (as in BlackJAX), of the new state for Langevin
        (``inf`` when non-finite).
    num_integration_steps : steps of the integration scheme in the transition.
    metropolis_rate : ``min(1, e^{−ΔH})`` of the proposal, also for unadjusted chains (what
        step-size adaptation targets; there ``ΔH`` leaves out the energy the ``O`` step
        exchanged with the heat bath, so it measures the error of the Hamiltonian pieces).
    num_gradient_evaluations : gradients of ``log π`` the transition evaluated (its cost:
        ``num_integration_steps`` times the scheme's
        :func:`~liesample.geometry.cotangent.gradient_evaluations`).
    """

    acceptance_rate: jax.Array
    is_accepted: jax.Array
    is_divergent: jax.Array
    energy: jax.Array
    num_integration_steps: jax.Array
    metropolis_rate: jax.Array
    num_gradient_evaluations: jax.Array


def check_logdensity_fn(logdensity_fn) -> Callable:
    """``logdensity_fn`` if callable, else a ``TypeError`` that says what is expected."""
    if not callable(logdensity_fn):
        raise TypeError(
            f"logdensity_fn must be a callable position -> log π(position) (a real scalar), "
            f"got {logdensity_fn!r}"
        )
    return logdensity_fn


def with_model_arguments(logdensity_fn: Callable, model_args=(), model_kwargs=None) -> Callable:
    """``position ↦ logdensity_fn(position, *model_args, **model_kwargs)``: the log density of
    a model at its data and constants (NumPyro's ``model_args`` / ``model_kwargs``), which a
    sampler passes as numbers of its compiled program, so that the same ``logdensity_fn`` at
    other data or constants reuses it. ``logdensity_fn`` itself without arguments."""
    check_logdensity_fn(logdensity_fn)
    if not isinstance(model_args, (tuple, list)):
        raise TypeError(
            f"model_args must be a tuple of the log density's arguments after the position, "
            f"got {type(model_args).__name__}; e.g. model_args=(data,)"
        )
    if model_kwargs is not None and not isinstance(model_kwargs, Mapping):
        raise TypeError(
            f"model_kwargs must be a dict of the log density's keyword arguments, got "
            f"{type(model_kwargs).__name__}; e.g. model_kwargs={{'scale': 2.0}}"
        )
    if not model_args and not model_kwargs:
        return logdensity_fn
    args, kwargs = tuple(model_args), dict(model_kwargs or {})
    return lambda position: logdensity_fn(position, *args, **kwargs)


def model_values(model_args, model_kwargs) -> dict:
    """The model's arguments as a structure's values (numbers of the compiled program; none
    when the model takes none)."""
    values: dict[str, Any] = {}
    if model_args:
        values["model_args"] = tuple(model_args)
    if model_kwargs:
        values["model_kwargs"] = dict(model_kwargs)
    return values


def check_logdensity_value(logdensity_fn: Callable, position) -> None:
    """A ``TypeError`` unless ``logdensity_fn(position)`` is one real floating scalar; only its
    shape and dtype are read (``jax.eval_shape``), so it serves under ``jit`` and ``vmap``."""
    check_logdensity_fn(logdensity_fn)
    value = jax.eval_shape(logdensity_fn, position)
    leaves = jax.tree.leaves(value)
    if len(leaves) != 1 or leaves[0].shape != () or leaves[0].dtype.kind != "f":
        got = (
            f"shape {leaves[0].shape} and dtype {leaves[0].dtype}" if len(leaves) == 1
            else f"{value!r}"
        )  # fmt: skip
        raise TypeError(
            f"logdensity_fn must return one real floating scalar log π(position), got {got}; "
            "reduce it to a scalar (e.g. jnp.sum over independent terms) and return its real "
            "log density as a float"
        )


def init(position, logdensity_fn: Callable, space) -> GeometricState:
    """Initial state; raises if ``position`` is off the space or ``log π`` is not finite there."""
    spaces.check_position(space, position)
    check_logdensity_value(logdensity_fn, position)
    value_and_grad = spaces.trivialised_value_and_grad(logdensity_fn, space)
    logdensity, grad = value_and_grad(position)
    values = concrete_array(
        jnp.concatenate([jnp.ravel(g) for g in jax.tree.leaves(grad)] + [jnp.ravel(logdensity)])
    )
    if values is not None and not np.all(np.isfinite(values)):
        raise ValueError(
            "logdensity_fn or its gradient is not finite at the initial position; start the "
            "chain where log π is finite"
        )
    momentum = spaces.zero_momentum(space, position)
    return GeometricState(position, logdensity, grad, momentum, jnp.ones((), logdensity.dtype))


def check_starts(space):
    """The runner's ``check_positions`` hook: every chain's start (leading axis) on the space,
    the first bad one named ``initial_positions[c]``."""

    def check_positions(positions, **_):
        leaves = jax.tree.leaves(positions)
        num_chains = np.shape(leaves[0])[0] if leaves and np.ndim(leaves[0]) else 0
        for chain in range(num_chains):
            start = jax.tree.map(lambda a, chain=chain: a[chain], positions)
            spaces.check_position(space, start, f"initial_positions[{chain}]")

    return check_positions


def check_positive_step_size(step_size):
    """``step_size`` must be a scalar, finite and > 0 (checked when concrete)."""
    if np.ndim(step_size) != 0:
        raise ValueError(f"step_size must be a scalar, got shape {np.shape(step_size)}")
    value = concrete_array(step_size)
    if value is not None and value.dtype.kind not in "iuf":  # bool, complex, str: no step
        raise TypeError(f"step_size must be a real scalar, got {step_size!r}")
    if value is not None and not (np.isfinite(value) and value > 0):
        raise ValueError(f"step_size must be finite and > 0, got {float(value)}")


def hamiltonian_scheme(integrator) -> tuple:
    """The scheme of an HMC trajectory from ``integrator=``: a name of
    :data:`liesample.geometry.cotangent.SCHEMES` or a coefficient list of ``B`` and ``A`` only,
    palindromic (the proposal must be an involution for the Metropolis test to be exact)."""
    scheme = check_scheme(integrator, "AB")
    if scheme != scheme[::-1]:
        raise ValueError(
            "integrator must be palindromic (the same read backwards) for the Metropolis test "
            f"to be exact, got {scheme}; e.g. 'leapfrog' or 'minimal_norm'"
        )
    return scheme


def scheme_setting(integrator, default: str = "leapfrog") -> dict:
    """``{"integrator": …}`` for :attr:`~liesample.samplers.contract.Sampler.settings` (a name,
    or the coefficient list as text); empty for the sampler's default scheme."""
    if isinstance(integrator, str):
        return {} if integrator == default else {"integrator": integrator}
    return {"integrator": repr(check_scheme(integrator))}


def check_divergence_threshold(divergence_threshold):
    if not (np.ndim(divergence_threshold) == 0 and float(divergence_threshold) > 0):
        raise ValueError(f"divergence_threshold must be > 0, got {divergence_threshold!r}")


def energy(bundle: CotangentBundle, logdensity, momentum):
    """``H = −log π + ½ pᵀM⁻¹p``."""
    return -logdensity + bundle.kinetic_energy(momentum)


def _all_finite(tree):
    return jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(tree)]))


def metropolis(rng_key, bundle, initial: PhasePoint, proposal: PhasePoint, divergence_threshold,
               accept=True, heat=0.0):  # fmt: skip
    """Accept/reject ``proposal`` from ``initial`` (both evaluated).

    Returns ``(is_accepted, acceptance_rate, is_divergent, initial energy, proposal energy)``
    with ``acceptance_rate = min(1, e^{−(ΔH − heat)})`` (0 when non-finite; ``heat`` is what the
    OU steps put in, so the rate measures the error of the Hamiltonian pieces only). With
    ``accept=False`` (unadjusted chains) every finite proposal is taken. A non-finite proposal
    (state or energy) is always rejected and flagged divergent; its energy is reported as
    ``inf``, or ``NaN`` where the log-density was NaN (treated as −∞), so the runner can say so.
    """
    start = energy(bundle, initial.logdensity, initial.momentum)
    final = energy(bundle, proposal.logdensity, proposal.momentum)
    delta = final - start - heat
    finite = (
        jnp.isfinite(delta)
        & _all_finite(proposal.position)
        & _all_finite(proposal.momentum)
        & _all_finite(proposal.logdensity_grad)
    )
    delta = jnp.where(finite, delta, jnp.inf)
    acceptance_rate = jnp.where(finite, jnp.minimum(1.0, jnp.exp(-delta)), 0.0)
    is_divergent = ~finite | (delta > divergence_threshold)
    if accept:
        u = jax.random.uniform(rng_key, (), acceptance_rate.dtype)
        is_accepted = u < acceptance_rate
    else:
        is_accepted = finite
    final = jnp.where(finite | jnp.isnan(final), final, jnp.inf)
    return is_accepted, acceptance_rate, is_divergent, start, final


def select(condition, new, old):
    """``new`` where ``condition`` else ``old``, leaf by leaf."""
    return jax.tree.map(lambda a, b: jnp.where(condition, a, b), new, old)


def drift_flows(bundle: CotangentBundle, step_size, scheme, precompute: bool = True):
    """``sign ↦ {fraction: kinetic flow}`` for the drifts of ``scheme``.

    With a field and ``precompute`` (fixed parameters) the flows of ``+G`` and ``−G`` are
    computed here, once, and each move selects one; otherwise (traced parameters, as in
    adaptation) one ``expm`` per move, for the sign it uses. Without a field the sign is inert.
    """
    times = fractions(scheme, "A")

    def flows(sign):
        return {f: bundle.kinetic_flow(f * step_size, sign) for f in times}

    if bundle.magnetic_field is None:
        fixed = flows(1.0)
        return lambda sign: fixed
    if not precompute:
        return flows
    plus, minus = flows(1.0), flows(-1.0)
    return lambda sign: select(sign > 0, plus, minus)


class Move(NamedTuple):
    """What a move needs at fixed parameters: ``value_and_grad`` (trivialised), the
    :class:`~liesample.geometry.cotangent.CotangentBundle`, ``flows`` (:func:`drift_flows`), the
    step size and the scheme one step follows (``((effect, fraction), …)``)."""

    value_and_grad: Callable
    bundle: CotangentBundle
    flows: Callable
    step_size: jax.Array | float
    scheme: tuple

    def effects(self, sign, friction=None):
        """The one-effect steps ``B``, ``A`` (field sign ``sign``) and, with a friction, ``O``."""
        bundle, step_size = self.bundle, self.step_size
        effects = {"B": kick(self.value_and_grad, step_size), "A": drift(bundle, self.flows(sign))}
        if friction is not None:
            effects["O"] = refresh(bundle, step_size, friction)
        return effects


def make_move(logdensity_fn, space, step_size, inverse_mass_matrix, magnetic_field, scheme,
              dtype=None, precompute=True, metric=None):  # fmt: skip
    """:class:`Move` of a sampler on ``space`` (``scheme`` already checked);
    ``precompute=False`` in kernels (traced parameters); ``metric`` the
    :class:`~liesample.geometry.cotangent.Metric` of ``inverse_mass_matrix`` when already
    computed (:func:`~liesample.geometry.cotangent.cotangent_bundle`)."""
    bundle = cotangent_bundle(space, inverse_mass_matrix, magnetic_field, dtype, metric)
    flows = drift_flows(bundle, step_size, scheme, precompute)
    value_and_grad = spaces.trivialised_value_and_grad(logdensity_fn, space)
    return Move(value_and_grad, bundle, flows, step_size, tuple(scheme))


def kernel_move(state: GeometricState, logdensity_fn, space, step_size, inverse_mass_matrix,
                magnetic_field, scheme, metric=None) -> Move:  # fmt: skip
    """:class:`Move` of one kernel call, in the dtype of ``state``: the parameters may be traced
    (adaptation), so the kinetic–magnetic exponential is computed per transition, and the
    decomposition of a dense ``M⁻¹`` too unless ``metric`` gives it (:func:`make_move`)."""
    dtype = jnp.asarray(state.logdensity).dtype
    return make_move(
        logdensity_fn,
        space,
        step_size,
        inverse_mass_matrix,
        magnetic_field,
        scheme,
        dtype,
        precompute=False,
        metric=metric,
    )


def space_settings(sampler: str, space, step_size, **parameters) -> dict:
    """The :attr:`~liesample.samplers.contract.Sampler.settings` that every sampler on ``space``
    records (its name, the space, the given step or ``None``), then ``parameters`` in order."""
    return {
        "sampler": sampler,
        "space": repr(space),
        "step_size": setting(step_size),
        "step_size_source": "given" if step_size is not None else UNSET,
        **parameters,
    }


UNSET = "unset: tuned by the warm-up of liesample.sample"
"""The ``step_size_source`` of a T*G sampler built without a step."""


def unset_step(sampler: str, arguments: str = "logdensity_fn, space") -> Callable:
    """The ``step`` of a T*G sampler built without ``step_size``: it refuses to run, saying
    what tunes it."""

    def step(rng_key, state):
        raise ValueError(
            f"{sampler} was built without step_size, so it cannot step: run it through "
            "liesample.sample with num_warmup > 0 (the warm-up tunes the step size, mass and, "
            "for HMC, the trajectory length), or give step_size (e.g. from "
            f"liesample.window_adaptation(liesample.{sampler}, {arguments}))"
        )

    return step


def space_sampler(logdensity_fn, space, step_fn: Callable, settings: dict,
                  adaptation=None, divergence_advice=None, recipe=None) -> Sampler:  # fmt: skip
    """The :class:`~liesample.samplers.contract.Sampler` of ``step_fn`` on ``space``: keyless
    :func:`init` and :func:`check_starts`; ``adaptation`` its
    :class:`~liesample.samplers.contract.Tunable`; ``divergence_advice`` its
    ``Sampler.divergence_advice`` (:func:`unadjusted_advice` for an unadjusted step);
    ``recipe`` its :class:`~liesample.samplers.contract.Recipe`, and the
    :class:`~liesample.samplers.contract.Structure` that gives."""
    check_logdensity_fn(logdensity_fn)

    def init_fn(position, rng_key=None):
        del rng_key
        return init(position, logdensity_fn, space)

    names = None
    if isinstance(space, spaces.Space):
        names = DrawNames(space.draw_name, space.draw_dims())
    return Sampler(
        init_fn,
        step_fn,
        settings=settings,
        check_positions=check_starts(space),
        draw_names=names,
        adaptation=adaptation,
        stuck_advice=window_advice(settings["sampler"], "logdensity_fn, space"),
        divergence_advice=divergence_advice,
        structure=None if recipe is None else recipe.structure(),
        recipe=recipe,
    )


def unadjusted_advice(adjusted: str) -> str:
    """The divergence advice of an unadjusted sampler (``Sampler.divergence_advice``), naming
    ``adjusted``, the call of its Metropolis-adjusted sibling."""
    return (
        "This sampler is unadjusted: it has no Metropolis test, so a step it must reject (a "
        "proposal where the log-density or its gradient is not finite: a bounded support, a "
        "discontinuity, a region where the model is undefined) biases its law near there, "
        "whatever the step size. For such a density use the Metropolis-adjusted "
        f"{adjusted}, or reparametrise onto an unbounded space (a constrained parameter "
        "through a bijection); a density that is smooth and finite everywhere needs only a "
        "smaller step_size."
    )


def window_advice(sampler: str, arguments: str) -> str:
    """The stuck-chain advice of a sampler that :func:`liesample.window_adaptation` tunes."""
    return (
        f"Leave step_size unset, liesample.{sampler}({arguments}), and pass num_warmup > 0 "
        "to liesample.sample (its warm-up tunes the step size and mass), or tune it "
        "separately: (state, parameters), _ = "
        f"liesample.window_adaptation(liesample.{sampler}, {arguments}).run(rng_key, "
        f"initial_positions, 1000), then liesample.{sampler}({arguments}, **parameters) "
        "started from state.position with num_warmup=0, exact_starts=True."
    )


def scheme_step(move: Move, sign, friction=None) -> Callable:
    """One step of ``move.scheme`` (field sign ``sign``) ending at an evaluated point."""
    step = compose(move.scheme, move.effects(sign, friction))
    return lambda point, rng_key=None: evaluated(step(point, rng_key), move.value_and_grad)


def _point(state: GeometricState, momentum) -> PhasePoint:
    return PhasePoint(state.position, momentum, state.logdensity, state.logdensity_grad)


def hamiltonian_transition(
    rng_key,
    state: GeometricState,
    momentum,
    move: Move,
    num_integration_steps,
    divergence_threshold,
    persistent: bool = True,
):
    """``L`` steps of ``move.scheme`` from ``(state.position, momentum)``, the Metropolis test
    and the flip. Returns ``(state, (is_accepted, acceptance_rate, is_divergent, initial energy,
    proposal energy))``.

    The involution ``(g, p, s) ↦ (g', −p', −s)`` then, if ``persistent``, the flip
    ``(p, s) ↦ (−p, −s)``: accepted ``(g', p', s)``, rejected ``(g, −p, −s)``. With
    ``persistent=False``: accepted ``(g', −p', −s)``, rejected ``(g, p, s)``.

    Divergences are watched at every step, as NUTS does (:func:`energy_errors`): the transition
    is flagged divergent when the energy error ``H(z_k) − H(z_0)`` of any step ``k`` exceeds
    ``divergence_threshold``, so a trajectory that overshoots and comes back is counted; the
    energy of each step comes with the gradient its last kick evaluated (no second evaluation).
    The test itself is the one of the end point, except that a trajectory passing through a
    non-finite energy is rejected: the reversed trajectory passes through the same states, so
    the condition is symmetric under the involution and the chain keeps ``exp(−H)``.
    """
    sign = state.magnetic_sign
    initial = _point(state, momentum)
    proposal, worst, finite = energy_errors(move, initial, num_integration_steps, sign)
    outcome = metropolis(rng_key, move.bundle, initial, proposal, divergence_threshold)
    is_accepted = outcome[0] & finite
    acceptance_rate = jnp.where(finite, outcome[1], jnp.zeros_like(outcome[1]))
    is_divergent = outcome[2] | ~finite | (worst > divergence_threshold)
    outcome = (is_accepted, acceptance_rate, is_divergent, *outcome[3:])
    negate = lambda tree: jax.tree.map(jnp.negative, tree)
    new_momentum = select(is_accepted, proposal.momentum, negate(momentum))
    new_sign = jnp.where(is_accepted, sign, -sign)
    if not persistent:
        new_momentum, new_sign = negate(new_momentum), -new_sign
    new_state = GeometricState(
        select(is_accepted, proposal.position, state.position),
        jnp.where(is_accepted, proposal.logdensity, state.logdensity),
        select(is_accepted, proposal.logdensity_grad, state.logdensity_grad),
        new_momentum,
        jnp.asarray(new_sign).astype(jnp.result_type(sign)),
    )
    return new_state, outcome


def energy_errors(move: Move, initial: PhasePoint, num_integration_steps, sign):
    """``num_integration_steps`` steps of ``move.scheme`` from ``initial`` (evaluated):
    ``(end point, max_k (H(z_k) − H(z_0)), every H(z_k) finite)`` over the steps ``k ≥ 1``.

    Each step ends at an evaluated point (:func:`scheme_step`), so ``H(z_k)`` is its ``−log π``,
    already computed with the gradient, plus the kinetic energy: watching costs no gradient.
    A non-finite ``H(z_k)`` counts as an infinite error.
    """
    step = scheme_step(move, sign)
    start = energy(move.bundle, initial.logdensity, initial.momentum)
    dtype = jnp.result_type(start)

    def body(_, carry):
        point, worst, finite = carry
        point = step(point)
        error = energy(move.bundle, point.logdensity, point.momentum) - start
        ok = jnp.isfinite(error)
        worst = jnp.maximum(worst, jnp.where(ok, error, jnp.inf))
        return point, worst, finite & ok

    carry = (initial, jnp.full((), -jnp.inf, dtype), jnp.ones((), bool))
    return jax.lax.fori_loop(0, num_integration_steps, body, carry)


def unadjusted_transition(
    rng_key, state: GeometricState, move: Move, friction, divergence_threshold
):
    """One step of ``move.scheme`` (``B``, ``A`` and ``O`` pieces), taken when finite; a non-finite
    step keeps the state. Returns ``(state, (is_accepted, metropolis_rate, is_divergent,
    energy of the new state))``; ``metropolis_rate`` is ``min(1, e^{−(ΔH − heat)})``, the rate
    the step's Hamiltonian pieces would be accepted at (what step-size adaptation targets)."""
    step = scheme_step(move, state.magnetic_sign, friction)
    initial = _point(state, state.momentum)._replace(heat=jnp.zeros_like(state.logdensity))
    proposal = step(initial, rng_key)
    is_accepted, rate, is_divergent, start, final = metropolis(
        None,
        move.bundle,
        initial,
        proposal,
        divergence_threshold,
        accept=False,
        heat=proposal.heat,
    )
    new_state = GeometricState(
        select(is_accepted, proposal.position, state.position),
        jnp.where(is_accepted, proposal.logdensity, state.logdensity),
        select(is_accepted, proposal.logdensity_grad, state.logdensity_grad),
        select(is_accepted, proposal.momentum, state.momentum),
        state.magnetic_sign,
    )
    return new_state, (is_accepted, rate, is_divergent, jnp.where(is_accepted, final, start))


def ravelled(state, logdensity_fn, move: Move, transition: Callable):
    """Run ``transition(flat_state, move)`` on the raveled position of ``state`` (any
    state with ``position``, ``logdensity``, ``logdensity_grad`` and a flat ``momentum``):
    ``(flat new state, info, unravel)``. How the magnetic samplers run on ``Euclidean((d,))``."""
    flat_q, unravel = ravel_pytree(state.position)
    value_and_grad = jax.value_and_grad(lambda x: logdensity_fn(unravel(x)))
    flat_state = GeometricState(
        flat_q,
        state.logdensity,
        ravel_pytree(state.logdensity_grad)[0],
        state.momentum,
        getattr(state, "magnetic_sign", 1.0),
    )
    new, info = transition(flat_state, move._replace(value_and_grad=value_and_grad))
    return new, info, unravel


def trajectory_cost(move: Move, num_integration_steps):
    """Gradient evaluations of ``num_integration_steps`` steps of ``move.scheme``."""
    return jnp.asarray(num_integration_steps) * gradient_evaluations(move.scheme)


def partial_refresh(fresh, momentum, momentum_persistence):
    """``α p + √(1 − α²) ξ`` (``α = 0``: the fresh draw ``ξ ~ N(0, M)`` itself).

    A carried momentum that is exactly zero (what :func:`init` sets: none drawn yet) is replaced
    by ``ξ``, a null set of ``N(0, M)``, so the chain's law is unchanged. Refreshing it partially
    would start the dynamics with almost no kinetic energy: the leapfrog then turns about half of
    the potential energy into kinetic energy (a quench; a thermalised lattice gauge field orders),
    and where steps are accepted rarely the chain stays trapped there.
    """
    if isinstance(momentum_persistence, (int, float)) and momentum_persistence == 0:
        return fresh
    alpha = jnp.asarray(momentum_persistence, jnp.result_type(*jax.tree.leaves(fresh)))
    drawn = jnp.any(jnp.array([jnp.any(p != 0) for p in jax.tree.leaves(momentum)]))
    alpha = jnp.where(drawn, alpha, jnp.zeros_like(alpha))
    scale = jnp.sqrt(1.0 - alpha**2)
    return jax.tree.map(lambda p, xi: alpha * p + scale * xi, momentum, fresh)
