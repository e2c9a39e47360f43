"""The functional core of :class:`liesample.interop.numpyro_kernel.GeometricHMC`.

Pure functions of a :class:`Core` (what the kernel's keywords settled, :class:`Settings`; the
sites' :class:`liesample.interop.numpyro_sites.Layout`; the warm-up's adaptation and its
schedule), in the shape of NumPyro's own ``hmc`` (an init and a sample function under a thin
``MCMCKernel`` class): :func:`init_state` starts one chain, :func:`sample_batch` moves every
chain of a batch one transition and runs the shared warm-up's ``update`` on it,
:func:`sample_one` is one chain as a batch of one. The warm-up is the one adaptation protocol
(:mod:`liesample.tuning.protocol`) with :func:`liesample.tuning.windows.windows_adaptation`,
driven by NumPyro's loop: :func:`parameters` is its ``current`` (``final`` after the warm-up),
:func:`adapt` its ``update``. What the kernel does is described in
:mod:`liesample.interop.numpyro_kernel`.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.geometry.cotangent import cotangent_bundle
from liesample.interop.numpyro_sites import Layout, find_start
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.tuning.protocol import Adaptation, odd_chains, restart_step_size, row_at
from liesample.tuning.trajectory import chain_move, euclidean_size, halton, jittered_steps
from liesample.tuning.windows import (
    DenseBlocks,
    Windows,
    WindowState,
    far_adapted,
    inverse_mass,
    statistic,
    windows_adaptation,
)

__all__ = [
    "HEURISTIC_ACCEPT_PROB",
    "POOLING",
    "AdaptState",
    "Core",
    "GeometricHMCState",
    "Settings",
    "adapt",
    "adapt_state",
    "core",
    "heuristic_step_size",
    "init_state",
    "parameters",
    "record_chain",
    "sample_batch",
    "sample_one",
    "warn_odd_chains",
    "warn_unadapted",
    "windows",
]

HEURISTIC_ACCEPT_PROB = 0.8
"""The one-step rate NumPyro's ``find_reasonable_step_size`` aims at."""

POOLING = "harmonic_then_median"
"""How the warm-up pools the rates of chains adapted together
(:func:`liesample.tuning.protocol.step_size_adaptation`): the harmonic rule in the initial fast
window frees chains stuck at their starts; the median after it keeps the step of the majority,
so a minority that falls into a degenerate mode or a funnel's neck cannot stop the others
(vectorized chains; :func:`warn_odd_chains` names it)."""


class AdaptState(NamedTuple):
    """``extra_fields=("adapt_state",)`` (the names of NumPyro's ``HMCAdaptState``): what the
    warm-up adapted, as the next transition uses it: the step size, the inverse mass (keyed by
    tuples of site names: one per site, one per ``dense_mass`` group) and the integration time
    ``T`` (each transition integrates ``u T`` when jittered, ``u`` in ``(0, 1)``; ``ε L`` for a
    fixed ``L``)."""

    step_size: jax.Array
    inverse_mass_matrix: dict
    trajectory_length: jax.Array


class GeometricHMCState(NamedTuple):
    """One chain's state; ``z`` is the sample field, the others are ``extra_fields``
    (:mod:`liesample.interop.numpyro_kernel`). ``inner`` is the sampler's state,
    ``adaptation`` the warm-up's (the protocol's state; each chain carries a copy, with its
    own running rate)."""

    i: jax.Array
    z: dict
    potential_energy: jax.Array
    energy: jax.Array
    diverging: jax.Array
    accept_prob: jax.Array
    mean_accept_prob: jax.Array
    num_steps: jax.Array
    step_size: jax.Array
    trajectory_length: jax.Array
    adapt_state: AdaptState
    inner: object  # the liesample.geometric_hmc state
    adaptation: WindowState
    rng_key: jax.Array
    # the decomposition of a dense inverse mass (liesample.geometry.cotangent.Metric), kept
    # while the mass is unchanged: None without a dense block
    metric: object = None
    # the parameters of the next transition (parameters()), computed at the end of the last one
    parameters: object = None
    # the post-run checks' buffer of the run's kept draws (RunChecks.buffer), or None
    kept: object = None


class Settings(NamedTuple):
    """What :class:`liesample.interop.numpyro_kernel.GeometricHMC`'s keywords settled (checked
    there): the starting ``step_size``, a fixed ``num_integration_steps`` or ``None``,
    ``jitter``, the integration-time adaptation ``lengths``
    (:func:`liesample.tuning.trajectory.trajectory_adaptation`), what the warm-up adapts, dual
    averaging's ``target``, the transition ``kernel`` (``geometric_hmc.build_kernel``) and
    NumPyro's ``num_warmup``."""

    step_size: float
    num_integration_steps: int | None
    jitter: bool
    lengths: Any
    adapt_step_size: bool
    adapt_mass: bool
    find_heuristic: bool
    target: float
    kernel: Callable
    num_warmup: int = 0


class Core(NamedTuple):
    """The settings, the sites' layout, the warm-up's adaptation and its schedule (``rows``:
    :func:`liesample.tuning.protocol.schedule` of ``num_warmup``; ``None`` without a
    warm-up)."""

    settings: Settings
    layout: Layout
    adaptation: Adaptation
    rows: Any


def _chain_move(space, before, after, infos, inverse_mass):
    return chain_move(space, before, after, infos, inverse_mass, batched=True)


def windows(settings: Settings, layout: Layout) -> Windows:
    """What the warm-up adapts (:class:`liesample.tuning.windows.Windows`), as
    :func:`liesample.window_adaptation` does for ``liesample.geometric_hmc``."""
    space = layout.inner_space
    fixed = settings.num_integration_steps
    return Windows(
        settings.target,
        "metropolis_rate",
        jax.vmap(functools.partial(statistic, space)),
        functools.partial(inverse_mass, space),
        settings.adapt_mass,
        lengths=settings.lengths if fixed is None else None,
        move=functools.partial(_chain_move, space),
        dimension=euclidean_size(space),
        fixed_steps=fixed,
        dense=DenseBlocks(tuple(layout.dense_keys)) if layout.dense_keys else None,
        jitter=settings.jitter,
        step_size=None if settings.adapt_step_size else settings.step_size,
        pooling=POOLING,
    )


def core(settings: Settings, layout: Layout, rows=None) -> Core:
    """The :class:`Core` of ``settings`` on ``layout``, with the window adaptation."""
    return Core(settings, layout, windows_adaptation(windows(settings, layout)), rows)


def warn_unadapted(settings: Settings) -> None:
    """``num_warmup=0`` while something is to be adapted: say what the run keeps (the warning
    points at the caller of the kernel's ``init``)."""
    unadapted = [
        name
        for name, adapted in (
            (f"step_size={settings.step_size:g}", settings.adapt_step_size),
            ("the starting inverse_mass_matrix", settings.adapt_mass),
            ("the starting integration_time", settings.lengths.learn),
        )
        if adapted
    ]
    if unadapted:
        warnings.warn(
            "GeometricHMC with num_warmup=0 runs unadapted, with "
            + ", ".join(unadapted)
            + ", from starts that are not draws from the target: the draws may be biased "
            "and the chains far from converged. Pass num_warmup > 0 to MCMC (e.g. "
            "num_warmup=1000), or give step_size, inverse_mass_matrix and "
            "trajectory_length with adapt_step_size=False, adapt_mass_matrix=False.",
            UserWarning,
            stacklevel=4,
        )


def adapt_state(layout: Layout, parameters) -> AdaptState:
    """The ``adapt_state`` field of ``parameters`` (the inverse mass keyed by site names)."""
    masses = {layout.blocks[key]: m for key, m in parameters["inverse_mass_matrix"].items()}
    return AdaptState(parameters["step_size"], masses, parameters["integration_time"])


def heuristic_step_size(c: Core, key, inner, logdensity, mass, step_size):
    """NumPyro's ``find_heuristic_step_size``: from ``step_size``, double (or halve) the
    step while one step's ``min(1, e^{−ΔH})`` stays above (below) 0.8; the step at which
    that flips."""
    step_size = jnp.asarray(step_size)
    finfo = jnp.finfo(step_size.dtype)

    def body(carry):
        step, _, direction, key = carry
        key, key_move = jax.random.split(key)
        step = step * jnp.power(2.0, direction).astype(step.dtype)
        _, info = c.settings.kernel(
            key_move,
            inner,
            logdensity,
            c.layout.inner_space,
            step_size=step,
            num_integration_steps=1,
            inverse_mass_matrix=mass,
        )
        new_direction = jnp.where(info.metropolis_rate > HEURISTIC_ACCEPT_PROB, 1, -1)
        return step, direction, new_direction, key

    def cond(carry):
        step, last, direction, _ = carry
        in_range = ((step > finfo.tiny) | (direction >= 0)) & (
            (step < finfo.max) | (direction <= 0)
        )
        return in_range & ((last == 0) | (direction == last))

    zero = jnp.asarray(0)
    return jax.lax.while_loop(cond, body, (step_size, zero, zero, key))[0]


def parameters(c: Core, adaptation, i):
    """The parameters of transition ``i``: the adaptation's ``current`` in the warm-up, its
    ``final`` after it (``L`` then the fixed one, or ``ceil(u T / ε)``). Only the phase's
    branch runs (``lax.cond`` on ``i``)."""
    settings = c.settings

    def after():
        tuned = c.adaptation.final(adaptation)
        step_size = tuned["step_size"]
        if settings.num_integration_steps is not None:
            steps = jnp.asarray(settings.num_integration_steps)
            time = step_size * steps
        else:
            time = tuned["integration_time"]
            u = halton(i) if settings.jitter else 1.0
            steps = jittered_steps(u, time, step_size)
        return {**tuned, "num_integration_steps": steps, "integration_time": time}

    if settings.num_warmup == 0:
        return after()

    def during():
        current = c.adaptation.current(adaptation, row_at(c.rows, i))
        current.setdefault(
            "integration_time", current["step_size"] * current["num_integration_steps"]
        )
        return current

    # the types jnp.where of the two would give, so either branch returns the same numbers
    types = jax.tree.map(
        lambda a, b: jax.ShapeDtypeStruct(jnp.broadcast_shapes(a.shape, b.shape),
                                          jnp.result_type(a, b)),
        jax.eval_shape(during), jax.eval_shape(after),
    )  # fmt: skip
    typed = lambda branch: (
        lambda: jax.tree.map(
            lambda x, t: jnp.broadcast_to(jnp.asarray(x, t.dtype), t.shape), branch(), types
        )
    )
    return jax.lax.cond(i < settings.num_warmup, typed(during), typed(after))


def adapt(c: Core, adaptation, i, parameters, before, inner, info, logdensity, key_step):
    """The shared warm-up's ``update`` after transition ``i`` of every chain; with
    ``find_heuristic_step_size`` dual averaging restarts from NumPyro's search at a mass
    window's end. After the warm-up nothing changes, and nothing is computed (``lax.cond``)."""
    settings = c.settings
    row = row_at(c.rows, i)
    update = cast(Callable, c.adaptation.update)  # the window adaptation has one

    def updated(adaptation):
        new = update(adaptation, row, parameters, before, inner, info)
        if settings.find_heuristic and settings.adapt_mass:

            def restart(state):  # NumPyro's search, from the first chain
                step = c.adaptation.current(state, row)["step_size"]
                first = jax.tree.map(lambda x: x[0], inner)
                step = heuristic_step_size(c, key_step, first, logdensity, state.inverse_mass, step)
                return state._replace(step=restart_step_size(state.step, settings.target, step))

            new = jax.lax.cond(row.window_end, restart, lambda state: state, new)
        # the types of the state carried, so both branches agree
        return jax.tree.map(lambda a, b: jnp.asarray(a, jnp.result_type(b)), new, adaptation)

    return jax.lax.cond(i < settings.num_warmup, updated, lambda state: state, adaptation)


def _metric(layout: Layout, mass, dtype):
    """The :class:`liesample.geometry.cotangent.Metric` a transition at inverse mass ``mass``
    decomposes, for the state to keep; ``None`` when the mass has no dense block (nothing to
    decompose)."""
    metric = cotangent_bundle(layout.inner_space, mass, None, dtype).metric
    return None if metric is None or metric.eigenvectors is None else metric


def _next_metric(layout: Layout, metric, mass, next_mass, dtype):
    """The metric of the next transition's ``next_mass``: ``metric`` (that of ``mass``) again
    while the mass is unchanged (after the warm-up, and between its mass windows), so that the
    ``eigh`` of a dense mass runs only when it changes."""
    if metric is None:
        return None
    leaves = zip(jax.tree.leaves(next_mass), jax.tree.leaves(mass), strict=True)
    changed = jnp.any(jnp.array([jnp.any(a != b) for a, b in leaves]))
    return jax.lax.cond(changed, lambda: _metric(layout, next_mass, dtype), lambda: metric)


def init_state(c: Core, key, params, logdensity, inner_logdensity, draw, starting_mass):
    """One chain's first state: from ``params`` (site values), or from ``draw`` (a key ↦ site
    values) until ``logdensity`` (of site values) and its gradient are finite; the step size
    from NumPyro's search with ``find_heuristic_step_size``."""
    settings, layout = c.settings, c.layout
    key, key_init = jax.random.split(key)
    if params is None:
        params = find_start(key_init, logdensity, draw)
    inner = geometric_hmc.init(layout.pack(params), inner_logdensity, layout.inner_space)
    dtype = inner.logdensity.dtype
    step_size = jnp.asarray(settings.step_size, dtype)
    if settings.find_heuristic:
        key, key_step = jax.random.split(key)
        step_size = heuristic_step_size(
            c, key_step, inner, inner_logdensity, starting_mass, step_size
        )
    one = jax.tree.map(lambda x: jnp.asarray(x)[None], inner)  # a batch of one
    start = {"step_size": step_size, "inverse_mass_matrix": starting_mass}
    adaptation = c.adaptation.init(one, start)
    first = parameters(c, adaptation, jnp.asarray(0))
    zero = jnp.asarray(0.0, dtype)
    return GeometricHMCState(
        jnp.asarray(0),
        layout.to_user(layout.unpack(inner.position)),
        -inner.logdensity,
        -inner.logdensity,
        jnp.asarray(False),
        zero,
        zero,
        jnp.asarray(0),
        first["step_size"],
        zero,
        adapt_state(layout, first),
        inner,
        adaptation,
        key,
        _metric(layout, first["inverse_mass_matrix"], dtype),
        first,
    )


def _shared_adaptation(state):
    """The chains' shared adaptation state, each chain's running rate gathered, one per
    chain."""
    shared = jax.tree.map(lambda x: x[0], state.adaptation)
    smoothed = state.adaptation.step.smoothed[:, 0]
    return shared._replace(step=shared.step._replace(smoothed=smoothed))


def _running_mean(c: Core, state, i, rate, dtype):
    """NumPyro's running mean of the acceptance rate, restarted when sampling begins."""
    num_warmup = c.settings.num_warmup
    count = jnp.where(i < num_warmup, i + 1, i + 1 - num_warmup)
    return state.mean_accept_prob + (rate - state.mean_accept_prob) / count.astype(dtype)


def sample_batch(c: Core, state, logdensity, on_draw=None):
    """One transition of every chain (a leading chain axis), ``logdensity`` of the sampler's
    position. The chains share the warm-up: one step size (dual averaging of their pooled
    rate), one mass (their pooled moments) and one ``T`` (ChEES centred on their mean); each
    chain carries a copy of the adaptation state (and its own running rate). ``on_draw(i, z,
    fields, kept)``, when given, is called (traced) with each draw and returns the state's new
    ``kept``."""
    settings, layout = c.settings, c.layout
    space = layout.inner_space
    i = state.i[0]
    keys = jax.vmap(jax.random.split)(state.rng_key)
    rng_key, key = keys[:, 0], keys[:, 1]
    key_step = jax.random.fold_in(key[0], 1) if settings.find_heuristic else None
    shared = _shared_adaptation(state)
    if state.parameters is None:
        current = parameters(c, shared, i)
    else:  # computed by the last transition from the same adaptation state
        current = jax.tree.map(lambda x: x[0], state.parameters)
    options = {name: current[name] for name in ("step_size", "num_integration_steps")}
    mass = current["inverse_mass_matrix"]
    metric = None if state.metric is None else jax.tree.map(lambda x: x[0], state.metric)

    def transition(key, inner):
        return settings.kernel(key, inner, logdensity, space, **options, inverse_mass_matrix=mass,
                               metric=metric)  # fmt: skip

    inner, info = jax.vmap(transition)(key, state.inner)
    dtype = inner.logdensity.dtype
    kinetic = cotangent_bundle(space, mass, None, dtype, metric).kinetic_energy
    energy = -inner.logdensity + jax.vmap(kinetic)(inner.momentum)
    new = shared
    if settings.num_warmup > 0:
        new = adapt(c, shared, i, current, state.inner, inner, info, logdensity, key_step)
    mean_accept = _running_mean(c, state, i, info.acceptance_rate, dtype)
    num_chains = state.i.shape[0]
    share = lambda tree: jax.tree.map(
        lambda x: jnp.broadcast_to(x, (num_chains, *jnp.shape(x))), tree
    )
    smoothed = new.step.smoothed
    adaptation = share(new._replace(step=new.step._replace(smoothed=smoothed[:1])))
    adaptation = adaptation._replace(step=adaptation.step._replace(smoothed=smoothed[:, None]))
    following = parameters(c, new, i + 1)
    new_metric = _next_metric(layout, metric, mass, following["inverse_mass_matrix"], dtype)
    new_state = GeometricHMCState(
        state.i + 1,
        jax.vmap(lambda p: layout.to_user(layout.unpack(p)))(inner.position),
        -inner.logdensity,
        energy,
        info.is_divergent,
        info.acceptance_rate,
        mean_accept,
        jnp.asarray(info.num_gradient_evaluations),
        share(current["step_size"]),
        share(current["step_size"] * current["num_integration_steps"]),
        share(adapt_state(layout, following)),
        inner,
        adaptation,
        rng_key,
        share(new_metric),
        share(following),
    )
    if settings.num_warmup > 0 and settings.adapt_step_size and num_chains >= 3:
        jax.lax.cond(
            i == settings.num_warmup - 1,
            lambda: jax.debug.callback(_warn_odd_chains, new.step.smoothed),
            lambda: None,
        )
    if on_draw is not None:  # the draw, to the post-run checks
        fields = {"diverging": info.is_divergent, "accept_prob": info.acceptance_rate,
                  "energy": energy}  # fmt: skip
        new_state = new_state._replace(kept=on_draw(i, new_state.z, fields, state.kept))
    return new_state


ODD_CHAIN_ADVICE = (
    "Look at that chain's draws (mcmc.get_samples(group_by_chain=True)); start the chains "
    "elsewhere (init_strategy=numpyro.infer.init_to_median(), or init_params near the "
    "posterior), give a longer num_warmup, or reparametrise the model (a hierarchical scale: "
    "numpyro.infer.reparam.LocScaleReparam)."
)


def _warn_odd_chains(smoothed) -> None:
    """:func:`warn_odd_chains` as a ``jax.debug.callback`` (which returns nothing)."""
    warn_odd_chains(smoothed)


def warn_odd_chains(smoothed) -> list:
    """After a shared warm-up (on the host): warn, naming each, of the chains whose running
    rate ended far below the others' (:func:`liesample.tuning.protocol.odd_chains`); returns
    them. The shared step is the majority's (the window adaptation pools by the median), so
    such a chain did not drag the others down, but its own draws are suspect."""
    odd = odd_chains(smoothed)
    if odd:
        described = "; ".join(
            f"chain {chain}: {rate:.3g} against the other chains' median {median:.3g}"
            for chain, rate, median in odd
        )
        warnings.warn(
            "GeometricHMC: chains warmed up together (chain_method='vectorized') share one "
            "step size, the one most of them accept at; at the end of the warm-up some "
            f"accepted far less often (running acceptance rate {described}). Such a chain "
            "sits where that step cannot move it (a degenerate mode, the neck of a funnel) "
            "or is stuck, and its draws are likely wrong. " + ODD_CHAIN_ADVICE,
            UserWarning,
            stacklevel=2,
        )
    return odd


def sample_one(c: Core, state, logdensity, record, on_draw=None):
    """One chain's transition: :func:`sample_batch` on a batch of one. After the last warm-up
    transition, when something was adapted, ``record(step_size, inverse_mass_diagonal)`` is
    called on the host (:func:`record_chain`)."""
    settings = c.settings
    batch = jax.tree.map(lambda x: jnp.asarray(x)[None], state)
    new = jax.tree.map(lambda x: x[0], sample_batch(c, batch, logdensity, on_draw))
    if settings.num_warmup > 0 and (settings.adapt_step_size or settings.adapt_mass):
        adapted = new.adapt_state  # after the last warm-up transition: the final ones
        leaves = jax.tree.leaves(adapted.inverse_mass_matrix)
        diagonal = [jnp.ravel(jnp.diagonal(m) if m.ndim == 2 else m) for m in leaves]
        jax.lax.cond(
            state.i == settings.num_warmup - 1,
            lambda: jax.debug.callback(record, adapted.step_size, jnp.concatenate(diagonal)),
            lambda: None,
        )
    return new


def record_chain(records: list, reported: set, step_size, inverse_mass) -> None:
    """Keep in ``records`` what a chain adapted alone ended with; warn for each chain far from
    the others (:func:`liesample.tuning.windows.far_adapted`), once per chain (``reported``
    holds the chains warned of). Bind ``records`` and ``reported`` with ``functools.partial``
    to give :func:`sample_one` its ``record``."""
    records.append((float(step_size), np.asarray(inverse_mass)))
    steps, masses = zip(*records, strict=True)
    if len({m.shape for m in masses}) != 1:
        return
    for chain, message in far_adapted(steps, np.stack(masses)):
        if chain in reported:
            continue
        reported.add(chain)
        warnings.warn(
            f"GeometricHMC: chains adapted alone (chain_method='sequential', or 'parallel' "
            f"on one device) ended far apart: {message} (chain = the order in which this "
            "kernel warmed chains up). That chain costs many more gradients per draw, or "
            "adapted to a different region, and its draws may be wrong. Use "
            "chain_method='vectorized' (the chains then adapt together: one step size, "
            "pooled mass), a longer num_warmup, or init_params near the posterior.",
            UserWarning,
            stacklevel=2,
        )
