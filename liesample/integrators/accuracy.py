"""Accuracy as a knob: ask for a bias tolerance, not a step size.

The unadjusted samplers' ergodic averages carry a discretisation bias ``A(h) − A(0) ≈ C h^q``
(``q`` → the integrator's weak order, ``liesample.integrators.INTEGRATORS[name].weak_order``,
as ``h → 0``). This module measures it instead of guessing: :func:`choose_step_size` turns
short coupled pilots into a step size (and a noise strength ``σ``, which at fixed ``β`` trades
mixing against stiffness) whose predicted bias is below a tolerance, allowing for
pre-asymptotic slopes, and :func:`default_step_size` is the choice
:func:`liesample.lie_poisson_langevin` makes when no step size is given.

The rest of the knob lives next to it and is importable from here too (as
``liesample.accuracy``):

- :mod:`liesample.integrators.chain_averages`: :func:`coupled_ergodic_averages`, chains at
  ``h, h/2, h/4, …`` on one Brownian path each (what the pilots run), and
  :func:`ergodic_averages`, vmapped chains of any BlackJAX-style sampler, both keeping only
  running sums, with standard errors from the spread of independent chains;
- :mod:`liesample.integrators.extrapolation`: :func:`richardson_romberg`,
  ``(2^p A(h/2) − A(h)) / (2^p − 1)`` with its MCSE, and :func:`richardson_romberg_run`, both
  runs coupled;
- :mod:`liesample.integrators.linear_bias`: :func:`linear_sd_bias` and
  :func:`warn_given_step`, the bias of a given step from the linearised dynamics.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.poisson_langevin import make_dynamics
from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.types import PRNGKey
from liesample.foundation.validation import finite_float, prng_key
from liesample.integrators.chain_averages import (
    ChainAverages,
    CoupledAverages,
    _CoupledRun,
    _positive_int,
    coupled_ergodic_averages,
    ergodic_averages,
)
from liesample.integrators.extrapolation import (
    RichardsonRomberg,
    richardson_romberg,
    richardson_romberg_run,
)
from liesample.integrators.linear_bias import (
    largest_accurate_stability_number,
    linear_sd_bias,
    warn_given_step,
)
from liesample.integrators.orbit import DEFAULT_INTEGRATOR, Integrator, get_integrator
from liesample.integrators.stability import stiffness

__all__ = [
    "DEFAULT_RELATIVE_TOLERANCE",
    "ChainAverages",
    "CoupledAverages",
    "RichardsonRomberg",
    "StepSizeChoice",
    "choose_step_size",
    "coupled_ergodic_averages",
    "default_step_size",
    "ergodic_averages",
    "largest_accurate_stability_number",
    "linear_sd_bias",
    "richardson_romberg",
    "richardson_romberg_run",
    "warn_given_step",
]

# A difference counts as measured when it is at least this many standard errors from zero.
_RESOLVED_Z = 2.0
# The slope used to extrapolate the bias down is never taken below this (a flatter observed
# slope is noise or a regime far from asymptotic; the user should lower the pilot step sizes).
_MIN_SLOPE = 0.5

DEFAULT_RELATIVE_TOLERANCE = 0.05
"""Default bias tolerance of :func:`default_step_size`: ``|bias| ≤ 0.05 × posterior sd`` of each
observable (about 1/20 of the spread: well below the MCSE of runs with fewer than ~400 effective
draws)."""


# --------------------------------------------------------------------------- step-size choice


@dataclass(frozen=True)
class StepSizeChoice:
    """The step size (and σ) :func:`choose_step_size` picked, and the evidence for it.

    Attributes
    ----------
    step_size, sigma, integrator : what to pass to :func:`liesample.lie_poisson_langevin`.
    tolerance : the requested absolute bound on ``|bias|`` of every observable (or ``None``).
    relative_tolerance : the requested bound in posterior sd (or ``None``).
    tolerances : array (k,), the absolute bound applied per observable (``inf``: not bounded).
    predicted_bias_bound : array (k,)
        Upper bound (2 SE) on ``|bias|`` at ``step_size`` from the model ``C h^q``.
    slope : array (k,)
        The exponent ``q`` used per observable: ``min(observed, weak order)`` when the pilot
        resolved the slope, else the weak order.
    steps_per_effective_sample : float
        Predicted cost: ``max_k τ_int,k / step_size`` (τ from the finest pilot).
    candidates : list of dict
        Per σ tried: its step size, bounds, slopes, τ and cost.
    pilot_wall_time : float
        Seconds spent in pilots (compilation excluded).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.default_step_size(system, 3.0)  # pilots, then the bias model
    >>> choice.integrator, choice.relative_tolerance, bool(choice.step_size > 0)
    ('splitting', 0.05, True)
    """

    step_size: float
    sigma: float
    integrator: str
    tolerance: float | None
    predicted_bias_bound: np.ndarray
    slope: np.ndarray
    steps_per_effective_sample: float
    candidates: list[dict[str, Any]] = field(default_factory=list)
    pilot_wall_time: float = 0.0
    relative_tolerance: float | None = None
    tolerances: np.ndarray | None = None

    def sampler_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for :func:`liesample.lie_poisson_langevin` (with ``beta``)."""
        return {"step_size": self.step_size, "sigma": self.sigma, "integrator": self.integrator}


def _tolerances(averages: CoupledAverages, tolerance, relative_tolerance):
    """Per-observable absolute tolerances, and the averages the bias model is applied to.

    Absolute: ``tolerance`` on each observable's mean. Relative: ``relative_tolerance × sd`` on
    each mean and ``2 × relative_tolerance × variance`` on each variance (so the sd is within
    ``relative_tolerance`` of itself), the variance taken per chain (``E[f²] − E[f]²`` of its
    time averages: coupled levels share its finite-time bias, which cancels in the
    differences) and the stationary sd from the finest level. Observables constant to
    round-off are not bounded (``inf``). Returns ``(tolerances, averages)``.
    """
    if relative_tolerance is None:
        return np.full(averages.chain_means.shape[-1], tolerance), averages
    means = averages.chain_means
    variances = np.maximum(averages.chain_square_means - means**2, 0.0)
    finest = means[:, -1].mean(0)
    variance = np.maximum(averages.chain_square_means[:, -1].mean(0) - finest**2, 0.0)
    sd = np.sqrt(variance)
    constant = sd <= 1e-7 * (np.abs(finest) + np.max(sd, initial=0.0) + 1e-300)
    tolerances = np.concatenate(
        [
            np.where(constant, np.inf, relative_tolerance * sd),
            np.where(constant, np.inf, 2.0 * relative_tolerance * variance),
        ]
    )
    augmented = replace(averages, chain_means=np.concatenate([means, variances], axis=-1))
    return tolerances, augmented


def _bias_model(averages: CoupledAverages, weak_order: float, tolerance: float):
    """Step size meeting ``tolerance`` from three coupled levels ``h, h/2, h/4``.

    ``D₁ = A(h) − A(h/2)``, ``D₂ = A(h/2) − A(h/4)`` (per-chain, so their SEs include the
    coupling). Under ``b(h) = C h^q``: ``D₁/D₂ = 2^q`` and ``b(h/4) = D₂/(2^q − 1)``. The slope
    is ``min(observed, weak order)`` when both differences are resolved with the same sign (a
    pre-asymptotic slope below the order steepens as ``h`` falls, one above it flattens, so the
    smaller is the cautious one), else the weak order. The bias bound at ``h/4`` uses
    ``|D₂| + 2 SE(D₂)``, and then ``h* = (h/4) (tolerance / bound)^{1/q}``, capped at ``h``.
    """
    means = averages.chain_means
    d1 = means[:, 0] - means[:, 1]
    d2 = means[:, 1] - means[:, 2]
    n = means.shape[0]
    m1, s1 = d1.mean(0), d1.std(0, ddof=1) / math.sqrt(n)
    m2, s2 = d2.mean(0), d2.std(0, ddof=1) / math.sqrt(n)
    resolved = (np.abs(m1) > _RESOLVED_Z * s1) & (np.abs(m2) > _RESOLVED_Z * s2) & (m1 * m2 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        observed = np.where(resolved, np.log2(np.abs(m1 / m2)), np.nan)
    slope = np.where(resolved, np.clip(observed, _MIN_SLOPE, weak_order), weak_order)
    finest = averages.step_sizes[2]
    bound = (np.abs(m2) + _RESOLVED_Z * s2) / (2.0**slope - 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.nan_to_num(finest * (tolerance / bound) ** (1.0 / slope), nan=np.inf)
    step = float(min(np.min(steps), averages.step_sizes[0]))
    predicted = bound * (step / finest) ** slope
    return step, predicted, slope, observed, (m1, s1, m2, s2)


def choose_step_size(
    system: LiePoissonSystem,
    beta: float,
    tolerance: float | None = None,
    *,
    relative_tolerance: float | None = None,
    observables: Callable[[jax.Array], jax.Array],
    initial_positions: ArrayLike,
    rng_key: PRNGKey,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    sigmas: Sequence[float] = (1.0,),
    pilot_step_size: float = 0.4,
    pilot_time: float = 50.0,
    burn_in: float = 5.0,
    max_refinements: int = 2,
) -> StepSizeChoice:
    """Pick the step size (and σ) whose bias on every observable is at most ``tolerance``
    (absolute) or ``relative_tolerance`` × its posterior sd.

    For each σ in ``sigmas``, one coupled pilot
    (:func:`liesample.integrators.chain_averages.coupled_ergodic_averages`, levels
    ``h, h/2, h/4`` with ``h = pilot_step_size / σ²``: noise and dissipation scale with
    ``σ² dt``) measures the differences between levels; the
    bias model ``C h^q`` (see :func:`_bias_model`: ``q`` the integrator's weak order, or the
    observed slope where it is smaller) gives the largest step with predicted
    ``|bias| ≤ tolerance`` (never larger than the pilot's). Among the σ, the one with the fewest
    steps per effective sample (``max_k τ_int,k / h*``, τ from the finest level) wins.

    Parameters
    ----------
    tolerance : float, optional
        Bound on the absolute bias of each observable (> 0). The statistical error of the
        production run comes on top; size the run for it.
    relative_tolerance : float, optional
        Bound on the bias of each observable relative to its stationary standard deviation
        (measured on the pilot's finest level); observables constant to round-off are not
        bounded; the variance of each observable is bounded too (by ``2 × relative_tolerance ×
        variance``, i.e. its sd is within ``relative_tolerance`` of itself), so the arrays of
        the result list the means' entries, then the variances'. Give this or ``tolerance``;
        with neither,
        :data:`DEFAULT_RELATIVE_TOLERANCE` (0.05 sd) applies.
    rng_key : jax.random.key or jax.random.PRNGKey
    observables : callable
        ``μ ↦`` array (k,): the expectations that must be accurate.
    initial_positions : array (chains, *event_shape)
        Starts of the pilot chains (≥ 2; a few hundred give a usable bias constant).
    sigmas : sequence of float
        Noise strengths to try (each > 0).
    pilot_step_size, pilot_time, burn_in : float
        The coarsest pilot step at ``σ = 1`` (divided by ``σ²`` for other σ), and the pilot's
        physical time and discarded start per chain.
    max_refinements : int
        When the chosen step is below half the pilot's finest step, the pilot is repeated
        closer to it (coarse step ``max(4 h*, h/8)``), at most this many times: a slope
        measured at larger steps is not trusted over a range it was not seen on.

    Returns
    -------
    StepSizeChoice

    Examples
    --------
    A short pilot (a real one runs longer: ``pilot_time=50``) for a bias of at most 0.1
    posterior sd in each coordinate of ``μ``:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.choose_step_size(
    ...     system, 3.0, relative_tolerance=0.1, observables=lambda mu: mu,
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]),
    ...     rng_key=jax.random.key(0), pilot_time=2.0, burn_in=0.5)
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=choice.step_size,
    ...                                          sigma=choice.sigma, integrator=choice.integrator)
    """
    if tolerance is not None and relative_tolerance is not None:
        raise ValueError("give tolerance (absolute) or relative_tolerance, not both")
    if tolerance is None and relative_tolerance is None:
        relative_tolerance = DEFAULT_RELATIVE_TOLERANCE
    if tolerance is not None:
        tolerance = finite_float("tolerance", tolerance, positive=True)
    else:
        relative_tolerance = finite_float("relative_tolerance", relative_tolerance, positive=True)
    rng_key = prng_key(rng_key)
    integrator = get_integrator(integrator)
    if np.ndim(sigmas) != 1 or len(sigmas) < 1:
        raise ValueError(f"sigmas must be a non-empty sequence of floats > 0, got {sigmas!r}")
    sigmas = [finite_float(f"sigmas[{i}]", s, positive=True) for i, s in enumerate(sigmas)]
    pilot_step_size = finite_float("pilot_step_size", pilot_step_size, positive=True)
    pilot_time = finite_float("pilot_time", pilot_time, positive=True)
    burn_in = finite_float("burn_in", burn_in, nonnegative=True)
    max_refinements = _positive_int("max_refinements", max_refinements, low=0)
    run = _CoupledRun(system, beta, observables, integrator, 3, initial_positions)
    candidates, wall = [], 0.0
    for i, sigma in enumerate(sigmas):
        # Noise and dissipation scale with σ²·dt: the same stiffness at every σ.
        coarse = pilot_step_size / sigma**2
        pilots = []
        for attempt in range(max_refinements + 1):
            pilot = run(
                step_size=coarse,
                sigma=sigma,
                rng_key=jax.random.fold_in(jax.random.fold_in(rng_key, i), attempt),
                total_time=pilot_time,
                burn_in=burn_in,
            )
            wall += pilot.wall_time
            tolerances, modelled = _tolerances(pilot, tolerance, relative_tolerance)
            step, predicted, slope, observed, (m1, s1, m2, s2) = _bias_model(
                modelled, integrator.weak_order, tolerances
            )
            pilots.append(
                {
                    "pilot_step_size": coarse,
                    "step_size": step,
                    "observed_slope": observed,
                    "difference_coarse": m1,
                    "difference_coarse_se": s1,
                    "difference_fine": m2,
                    "difference_fine_se": s2,
                    "wall_time": pilot.wall_time,
                }
            )
            # Far below the pilot's finest step, the extrapolation spans a range whose slope
            # was not seen: measure again closer to the candidate (at most 8× lower per round).
            if step >= 0.5 * pilot.step_sizes[2] or attempt == max_refinements:
                break
            coarse = max(4.0 * step, coarse / 8.0)
        tau = pilot.tau_int[2]
        candidates.append(
            {
                "sigma": sigma,
                "step_size": step,
                "predicted_bias_bound": predicted,
                "slope": slope,
                "observed_slope": observed,
                "tau_int": tau,
                "steps_per_effective_sample": float(np.max(tau) / step),
                "nonfinite_steps": int(pilot.nonfinite_steps.sum()),
                "tolerances": tolerances,
                "pilots": pilots,
            }
        )
    best = min(candidates, key=lambda c: c["steps_per_effective_sample"])
    return StepSizeChoice(
        step_size=best["step_size"],
        sigma=best["sigma"],
        integrator=integrator.name,
        tolerance=tolerance,
        relative_tolerance=relative_tolerance,
        tolerances=best["tolerances"],
        predicted_bias_bound=best["predicted_bias_bound"],
        slope=best["slope"],
        steps_per_effective_sample=best["steps_per_effective_sample"],
        candidates=candidates,
        pilot_wall_time=wall,
    )


# --------------------------------------------------------------------------- default step size

_PILOT_CHAINS = 16
_PILOT_COARSE_STEPS = 2000
_MAX_PILOT_TIME = 50.0


def _coordinates(mu):
    return jnp.ravel(mu)


def default_step_size(
    system: LiePoissonSystem,
    beta: float,
    *,
    sigma: float = 1.0,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    initial_positions: ArrayLike | None = None,
    rng_key: PRNGKey | None = None,
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
) -> StepSizeChoice:
    """The step size :func:`liesample.lie_poisson_langevin` uses when none is given.

    :func:`choose_step_size` on the coordinates of ``μ`` with ``relative_tolerance`` (bias at
    most 0.05 posterior sd by default), with pilots scaled to the problem: the coarsest pilot
    step is ``min(0.4/σ², 1/s)`` with ``s = θ·max_i|h''_i|`` the stiffness on the orbit
    (:mod:`liesample.integrators.stability`), i.e. half the stability bound ``κ ≤ 2``, so every
    level of the pilot and the chosen step are stable; the pilot runs ``min(50, 2000 h)`` time units
    (10 % burn-in) on 16 chains started from ``initial_positions`` (cycled; default: the
    system's default position), ``rng_key`` default ``jax.random.key(0)``.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> choice = liesample.accuracy.default_step_size(system, 3.0)
    >>> sampler = liesample.lie_poisson_langevin(system, beta=3.0, step_size=choice.step_size)
    >>> choice.relative_tolerance  # the bias bound, in posterior sd
    0.05
    """
    integrator = get_integrator(integrator)
    sigma, theta, _ = make_dynamics(system, beta=beta, sigma=sigma)
    if initial_positions is None:
        initial_positions = np.asarray(system.default_position)[None]
    starts = np.asarray(initial_positions, dtype=float)
    if starts.ndim != len(system.event_shape) + 1 or starts.shape[0] < 1:
        raise ValueError(
            f"initial_positions must have shape (chains, *{tuple(system.event_shape)}), got "
            f"{starts.shape}"
        )
    starts = starts[np.arange(_PILOT_CHAINS) % starts.shape[0]]
    stiff = max(
        stiffness(system, theta, start) if system.curvature_bound else 0.0
        for start in _distinct(starts)
    )
    coarse = 0.4 / sigma**2 if stiff == 0.0 else min(0.4 / sigma**2, 1.0 / stiff)
    pilot_time = min(_MAX_PILOT_TIME, _PILOT_COARSE_STEPS * coarse)
    return choose_step_size(
        system,
        beta,
        relative_tolerance=relative_tolerance,
        observables=_coordinates,
        initial_positions=starts,
        rng_key=jax.random.key(0) if rng_key is None else rng_key,
        integrator=integrator,
        sigmas=(sigma,),
        pilot_step_size=coarse * sigma**2,
        pilot_time=pilot_time,
        burn_in=0.1 * pilot_time,
    )


def _distinct(starts):
    _, first = np.unique(starts.reshape(len(starts), -1), axis=0, return_index=True)
    return starts[np.sort(first)]
