"""The checks run on a finished run: divergences, stuck chains, chains that disagree, chains
that left their orbits, and the per-variable checks of the draws.

Each check warns (or raises, for divergences with ``on_nonfinite="raise"``) with a message that
names the chains and a fix; none changes the draws. :func:`check_run` runs them all on a
:class:`liesample.run.runner.ChainsResult`; :func:`check_variables` is the one place that
receives every recorded variable (positions and observables, named as in the ``DataTree``) and
runs the convergence checks of :mod:`liesample.analysis.convergence` on them.
"""

from __future__ import annotations

import math
import warnings

import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.analysis.convergence import convergence_warnings
from liesample.foundation.precision import (
    ROUNDOFF_ULPS,
    X64_SWITCH,
    check_dtype,
    roundoff_tolerance,
)
from liesample.foundation.validation import raise_or_warn

DEFAULT_MIN_ACCEPTANCE_RATE = 0.05
"""A chain whose mean acceptance rate over the run is below this is reported as stuck."""
MAX_ENERGY_RHAT = 1.05
"""Chains whose energies have a split R-hat above this are reported as not converged."""
CASIMIR_DRIFT_FLOOR = 1e-9
"""The float64 floor of :func:`casimir_drift_bound`."""


class NonFiniteStateError(FloatingPointError):
    """A chain diverged: a step produced a non-finite state or energy (the sampler kept the
    previous state and flagged ``info.is_divergent``)."""


def check_run(
    info,
    variables,
    groups,
    *,
    on_nonfinite,
    min_acceptance_rate,
    stuck_advice=None,
    divergence_advice=None,
    convergence=True,
    stacklevel=2,
):
    """Every post-run check: :func:`report_divergences`, :func:`report_stuck_chains`,
    :func:`report_unconverged`, :func:`report_casimir_drift` (on ``info``, per-draw arrays
    ``(chains, draws)``) and :func:`check_variables` (on ``variables``, name ->
    ``(chains, draws, ...)``).

    ``groups``: the sampler's law groups (a label per chain, chains with one label sample one
    law), or ``None`` (one law). ``stacklevel`` as for ``warnings.warn`` called here."""
    level = stacklevel + 1
    report_divergences(info, on_nonfinite, level, advice=divergence_advice)
    report_stuck_chains(info, min_acceptance_rate, stuck_advice, level)
    report_unconverged(info, groups, level)
    report_casimir_drift(info, level)
    check_variables(variables, groups, convergence=convergence, stacklevel=level)


def check_variables(
    variables: dict[str, np.ndarray], groups, *, convergence=True, stacklevel=2
) -> list[str]:
    """Check each recorded variable, ``name -> array (chains, draws, ...)`` (the positions and
    observables under their ``DataTree`` names), given the law ``groups`` (``None``: one law).

    Warns (``RuntimeWarning``) for each variable with non-finite draws, naming it and its
    chains; then (``convergence=True``) one ``UserWarning`` with the messages of
    :func:`liesample.analysis.convergence.convergence_warnings` (rank-normalised split R-hat
    above 1.01, bulk or tail ESS below 100 per chain, on every element within each law group:
    a large variable's elements screened and the most suspicious ranked, as that module says;
    or why the checks were impossible). Returns every message."""
    messages = []
    for name, values in variables.items():
        values = np.asarray(values)
        finite = np.isfinite(values).reshape(values.shape[0], -1).all(axis=1)
        if not finite.all():
            chains = np.flatnonzero(~finite)
            messages.append(
                f"variable {name!r} has non-finite draws in {len(chains)} chain(s) (chains "
                f"{chain_list(chains)}): those chains left the target's domain; check the "
                "starts and the step size"
            )
    for message in messages:
        warnings.warn(message, RuntimeWarning, stacklevel=stacklevel)
    if not convergence:
        return messages
    convergence = convergence_warnings(variables, groups)
    if convergence:
        warnings.warn(
            "convergence checks: " + "; ".join(convergence) + ".",
            UserWarning,
            stacklevel=stacklevel,
        )
    return messages + convergence


def chain_list(chains, limit=10) -> str:
    """``"0, 3, 5"``, cut after ``limit`` chains."""
    shown = ", ".join(str(int(c)) for c in chains[:limit])
    return shown + (f", … ({len(chains)} in all)" if len(chains) > limit else "")


def report_divergences(info, on_nonfinite: str, stacklevel=2, advice=None):
    """A ``RuntimeWarning`` (or :class:`NonFiniteStateError` for ``on_nonfinite="raise"``)
    naming the chains whose ``info["is_divergent"]`` flags a step; when the energy recorded at
    such draws is NaN, the message says so (a NaN log-density, treated as −∞, is a fault of the
    model, not of the step size); otherwise it quotes the sampler's ``advice``
    (``Sampler.divergence_advice``) or the generic one."""
    flags = info.get("is_divergent")
    if flags is None or not np.any(flags):
        return
    chains = np.flatnonzero(np.any(flags, axis=1))
    message = (
        f"{int(np.sum(flags))} draws in {len(chains)} chain(s) (chains {chain_list(chains)}) "
        "contain a divergent step (a non-finite state or energy, or for the Metropolis-adjusted "
        "samplers an energy error above the divergence threshold); those steps were rejected "
        "and flagged in info['is_divergent'] (sample_stats 'diverging')."
    )
    energy = info.get("energy")
    nan = 0 if energy is None else int(np.sum(np.isnan(np.asarray(energy, float)) & flags))
    if nan:
        message += (
            f" At {nan} of them the energy was NaN: the log-density (or Hamiltonian) returned "
            "NaN there, and a NaN is treated as −∞ (zero probability). That is a domain error "
            "in the model (a log or sqrt of a negative number, 0/0, an overflow), not a step "
            "too large: make the log-density return -inf (or a finite value) outside its "
            "support, or constrain the parameter."
        )
    else:
        message += " " + (advice or "Reduce step_size or sigma, or let the warm-up adapt it.")
    raise_or_warn(message, on_nonfinite == "raise", NonFiniteStateError, RuntimeWarning, stacklevel)


def report_stuck_chains(info, threshold: float, advice=None, stacklevel=2):
    """A ``RuntimeWarning`` naming the chains whose mean acceptance rate is below
    ``threshold`` (0 disables it), with the sampler's own ``advice``
    (``Sampler.stuck_advice``) or a generic one."""
    rates = info.get("acceptance_rate")
    if rates is None or threshold == 0.0:
        return
    per_chain = np.mean(rates, axis=1)
    chains = np.flatnonzero(per_chain < threshold)
    if chains.size == 0:
        return
    worst = ", ".join(f"chain {int(c)}: {per_chain[c]:.3f}" for c in chains[:5])
    warnings.warn(
        f"{len(chains)} chain(s) are stuck: their mean acceptance rate is below "
        f"{threshold:g} (chains {chain_list(chains)}; {worst}). "
        + (advice or "Use a smaller step_size, or let the warm-up adapt it."),
        RuntimeWarning,
        stacklevel=stacklevel,
    )


def split_rhat(values: ArrayLike) -> float:
    """Split R-hat (Gelman et al.) of ``values (chains, draws)``: NaN where it is undefined (one
    chain, few draws, or no spread within chains)."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[0] < 2 or values.shape[1] < 8:
        return math.nan
    half = values.shape[1] // 2
    halves = np.concatenate([values[:, :half], values[:, -half:]])
    within = np.mean(np.var(halves, axis=1, ddof=1))
    between = half * np.var(np.mean(halves, axis=1), ddof=1)
    if not (np.isfinite(within) and within > 0):
        return math.nan
    return float(np.sqrt(((half - 1) / half * within + between / half) / within))


def _varies(values) -> bool:
    """Whether ``values`` vary by more than ``1e-9`` of their size (more than round-off)."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    return finite.size > 0 and np.ptp(finite) > 1e-9 * max(np.max(np.abs(finite)), 1e-300)


def casimir_drift_bound(dtype) -> float:
    """The largest Casimir drift a run in ``dtype`` shows without a warning: ``max(1e-9,
    1000 ε)``, ``ε`` the round-off unit of ``dtype``: as far as a start may be off its orbit
    (:func:`liesample.foundation.precision.roundoff_tolerance`). In float64 only a scheme
    that leaves the orbit reaches it; in float32 the round-off of many steps does (it grows like
    ``ε √n`` over ``n`` steps)."""
    return roundoff_tolerance(dtype, floor=CASIMIR_DRIFT_FLOOR)


def casimir_drift(info) -> float | None:
    """The run's Casimir drift: the largest finite ``info["casimir_error"]`` over chains and
    draws (each a step's ``|C(μ) − C(μ₀)|`` relative to the Casimir's scale, the largest over
    the steps a draw spans), or ``None`` for a sampler that records none."""
    errors = info.get("casimir_error")
    if errors is None:
        return None
    errors = np.asarray(errors)
    finite = errors[np.isfinite(errors)]
    return float(np.max(finite)) if finite.size else None


def record_casimir_drift(settings: dict, info) -> None:
    """Keep in ``settings["casimir_drift"]`` the largest :func:`casimir_drift` of the chunks
    seen so far (``info`` is one chunk's; nothing for a sampler that records none)."""
    drift = casimir_drift(info)
    if drift is not None:
        settings["casimir_drift"] = max(drift, settings.get("casimir_drift", 0.0))


def report_casimir_drift(info, stacklevel=2) -> float | None:
    """A ``RuntimeWarning`` when the run's :func:`casimir_drift` is above
    :func:`casimir_drift_bound` of the dtype it was recorded in, naming the chains, the causes
    and their fixes (float32 round-off: ``jax_enable_x64``); returns the drift."""
    drift = casimir_drift(info)
    if drift is None:
        return None
    errors = np.asarray(info["casimir_error"])
    dtype = check_dtype(errors)
    bound = casimir_drift_bound(dtype)
    if not drift > bound:
        return drift
    per_chain = np.max(np.where(np.isfinite(errors), errors, 0.0).reshape(len(errors), -1), 1)
    chains = np.flatnonzero(per_chain > bound)
    message = (
        f"the chains left their orbits: the largest Casimir drift |C(μ) − C(μ₀)| (relative to "
        f"the Casimir's scale) over the draws is {drift:.3g} (chains {chain_list(chains)}), "
        f"above the bound {bound:.2g} ({ROUNDOFF_ULPS} units of {dtype.name} round-off, at "
        "least 1e-9: as far as a start may be off its orbit); sample_stats 'casimir_error' "
        "holds it per draw."
    )
    if float(jnp.finfo(dtype).eps) > float(np.finfo(np.float64).eps):
        message += (
            f" In {dtype.name} the round-off of the steps adds up (like ε √n over n steps): to "
            f"run in float64, call {X64_SWITCH} at start-up, before any array is made; or "
            "run fewer steps per chain, with more chains."
        )
    message += (
        " A scheme that does not move by coadjoint actions (integrator='euler_heun') drifts by "
        "its step error: use an orbit-preserving integrator (the default 'splitting')."
    )
    warnings.warn(message, RuntimeWarning, stacklevel=stacklevel)
    return drift


def report_unconverged(info, groups, stacklevel=2):
    """A ``RuntimeWarning`` when the split R-hat of the chains' energies, within each law
    group, is above :data:`MAX_ENERGY_RHAT`."""
    energy = info.get("energy")
    if energy is None or np.ndim(energy) != 2:
        return
    groups = np.zeros(len(energy), int) if groups is None else np.asarray(groups)
    # An energy constant to round-off (a Casimir, as for the isotropic rigid body) says nothing
    # about mixing: its R-hat would compare round-off.
    chains = [energy[groups == label] for label in np.unique(groups)]
    rhats = [split_rhat(group) for group in chains if _varies(group)]
    rhat = max((r for r in rhats if np.isfinite(r)), default=math.nan)
    if rhat > MAX_ENERGY_RHAT:
        shown = f"{rhat:.3g}" if float(f"{rhat:.3g}") > MAX_ENERGY_RHAT else f"{rhat:.6g}"
        warnings.warn(
            f"the chains disagree: the split R-hat of their energy is {shown} > "
            f"{MAX_ENERGY_RHAT:g}, so they have not forgotten their starts or do not sample one "
            "law. Run longer (num_warmup, num_draws), start the chains from more spread-out "
            "points, or for an unadjusted sampler reduce step_size.",
            RuntimeWarning,
            stacklevel=stacklevel,
        )
