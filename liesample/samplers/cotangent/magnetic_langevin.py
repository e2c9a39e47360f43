"""Unadjusted magnetic (underdamped) Langevin: the charged Brownian particle as a sampler.

A BlackJAX-shaped module (``MagneticLangevinState``/``MagneticLangevinInfo``, ``init``,
``build_kernel``, ``as_top_level_api``). The SDE is the charged Brownian particle (paper,
``sec:brownian-particle``) with ``β = 1``, ``V = −log π``, ``θ`` = ``friction`` and
``σ = √(2θ)``::

    dq = M⁻¹p dt,   dp = (∇log π(q) + G M⁻¹p − θ M⁻¹p) dt + √(2θ) dW,

whose invariant law is ``π(q) · N(p; 0, M)`` for every antisymmetric ``G``.

**Integrator.** Unadjusted geometric Langevin
(:mod:`liesample.samplers.cotangent.geometric_langevin`) on ``spaces.Euclidean((d,))`` (the
raveled position) with the field, run by default with the symmetric Strang splitting
``B A O A B`` of :mod:`liesample.geometry.cotangent` (``integrator=`` picks another:
``"obabo"``, ``"obab"`` or a coefficient list; BAOAB of Leimkuhler & Matthews with the drift
``A`` replaced by the exact kinetic+magnetic flow): ``B`` = half kick ``p += ε/2 ∇log π``,
``A`` = exact flow of ``q̇ = M⁻¹p, ṗ = GM⁻¹p`` over ``ε/2``
(:func:`liesample.geometry.cotangent.kinetic_magnetic_flow`), ``O`` = exact OU step of the
friction and noise over ``ε``. Every piece is solved exactly, so the scheme is weak order 2
(its stationary law differs from ``π ⊗ N(0, M)`` by ``O(ε²)``); one gradient per step. On a
Gaussian target the step is affine, and :func:`liesample.targets.gaussian.linear_step_moments`
gives the exact stationary law of the discretisation itself (used by the tests).

A step that produces a non-finite state is flagged ``is_divergent`` (with
``acceptance_rate = 0``; 1 for every other step: the Info contract's rule for unadjusted
samplers, :mod:`liesample.samplers.contract`) and the state is kept.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from liesample.foundation.types import LogDensityFn
from liesample.samplers.contract import (
    Recipe,
    Sampler,
    sampling_api,
    setting,
    step_key,
)
from liesample.samplers.cotangent._core import (
    model_values,
    ravelled,
    scheme_setting,
    unadjusted_advice,
    with_model_arguments,
)
from liesample.samplers.cotangent._euclidean import (
    check_parameters,
    check_starts,
    euclidean_move,
    initial_values,
    ravel,
)
from liesample.samplers.cotangent.geometric_langevin import (
    check_friction,
    langevin_scheme,
    transition,
)

__all__ = [
    "MagneticLangevinInfo",
    "MagneticLangevinState",
    "as_top_level_api",
    "build_kernel",
    "init",
    "magnetic_langevin",
]


class MagneticLangevinState(NamedTuple):
    """State: ``position`` (pytree), flat ``momentum`` (``(d,)``), ``log π`` and its gradient."""

    position: jax.Array
    momentum: jax.Array
    logdensity: jax.Array
    logdensity_grad: jax.Array


class MagneticLangevinInfo(NamedTuple):
    """What one step did (the Info contract of :mod:`liesample.samplers.contract`).

    is_divergent : the step produced NaN/inf; the previous state was kept.
    acceptance_rate : 1.0 for a step taken, 0.0 for a divergent (rejected) one (unadjusted).
    energy : ``H = −log π(q) + ½pᵀM⁻¹p`` at the chain's state after the step.
    num_gradient_evaluations : gradients of ``log π`` the step evaluated.
    metropolis_rate : ``min(1, e^{−ΔH})`` the step would have as a Metropolis proposal (``ΔH``
        without the energy the ``O`` step exchanged with the heat bath): what a step-size
        adaptation targets (an unadjusted sampler's ``acceptance_rate`` is 1 whatever its step
        and bias; tuned by it, the step would grow without bound).
    """

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array
    num_gradient_evaluations: jax.Array
    metropolis_rate: jax.Array


def init(position, logdensity_fn: Callable, rng_key=None) -> MagneticLangevinState:
    """Initial state with zero momentum (no key needed; ``rng_key`` is ignored).

    Raises when ``log π`` or its gradient is not finite at ``position`` (checked when concrete).
    """
    del rng_key
    logdensity, grad, momentum = initial_values(position, logdensity_fn)
    return MagneticLangevinState(position, momentum, logdensity, grad)


def _step(rng_key, state, logdensity_fn, move, friction):
    """One step of the scheme: unadjusted geometric Langevin on the raveled position."""

    def flat_transition(flat_state, flat_move):
        return transition(rng_key, flat_state, flat_move, friction, False, jnp.inf)

    new, info, unravel = ravelled(state, logdensity_fn, move, flat_transition)
    new_state = MagneticLangevinState(
        unravel(new.position), new.momentum, new.logdensity, unravel(new.logdensity_grad)
    )
    info = MagneticLangevinInfo(
        info.is_divergent,
        info.acceptance_rate,
        info.energy,
        info.num_gradient_evaluations,
        info.metropolis_rate,
    )
    return new_state, info


def build_kernel(integrator="baoab"):
    """Build ``kernel(rng_key, state, logdensity_fn, step_size, inverse_mass_matrix, friction,
    magnetic_field) -> (state, info)``; the flow ``e^{εGM⁻¹/2}`` is recomputed per call.

    A callable ``integrator`` is refused: ``blackjax.window_adaptation`` passes its own
    integrator function here, and it tunes the step by ``acceptance_rate``, which an
    unadjusted sampler reports as 1 whatever its bias."""
    if callable(integrator):
        raise TypeError(
            "magnetic_langevin.build_kernel got a function as integrator (as "
            "blackjax.window_adaptation passes): magnetic_langevin is unadjusted, its "
            "acceptance_rate is 1 at any step size, so an adaptation by acceptance cannot tune "
            "it. Tune its step by info.metropolis_rate (the rate the step would have), e.g. "
            "liesample.window_adaptation(liesample.geometric_langevin, logdensity_fn, "
            "liesample.spaces.Euclidean((d,))) on a flat position, then pass its step_size, "
            "inverse_mass_matrix and friction here; integrator takes 'baoab', 'obabo', 'obab' "
            "or a coefficient list"
        )
    scheme = langevin_scheme(integrator)

    def kernel(
        rng_key,
        state: MagneticLangevinState,
        logdensity_fn: Callable,
        step_size,
        inverse_mass_matrix,
        friction,
        magnetic_field,
    ):
        check_parameters(step_size, inverse_mass_matrix, magnetic_field, state.momentum.shape[0])
        check_friction(friction)
        move = euclidean_move(
            step_size, inverse_mass_matrix, magnetic_field, scheme, state.momentum.dtype, False
        )
        return _step(rng_key, state, logdensity_fn, move, friction)

    return kernel


def as_top_level_api(
    logdensity_fn: LogDensityFn,
    step_size: float | jax.Array,
    inverse_mass_matrix: ArrayLike,
    friction: float | jax.Array,
    magnetic_field: ArrayLike | None,
    *,
    integrator: str | Sequence[tuple[str, float]] = "baoab",
    model_args: tuple = (),
    model_kwargs: dict | None = None,
) -> Sampler:
    """Unadjusted magnetic Langevin sampler (weak order 2; bias ``O(ε²)``, not corrected).

    Parameters
    ----------
    logdensity_fn : callable
        ``log π`` of a pytree position.
    step_size : float
        Time step ``ε > 0``.
    inverse_mass_matrix : array, (d,) or (d, d)
        Diagonal (> 0) or dense (symmetric positive definite) ``M⁻¹``.
    friction : float
        ``θ > 0``; the noise is ``σ = √(2θ)`` (``θ = βσ²/2`` at ``β = 1``).
    magnetic_field : array, (d, d)
        Antisymmetric ``G``; see
        :func:`liesample.samplers.cotangent._euclidean.default_magnetic_field`.
    integrator : str or sequence of (effect, fraction) pairs
        The splitting of one step: ``"baoab"`` (default), ``"obabo"``, ``"obab"``, or a
        coefficient list of ``"B"``, ``"A"`` and ``"O"`` as for
        :func:`liesample.geometric_langevin`.
    model_args, model_kwargs : tuple, dict
        Arguments of ``logdensity_fn`` after the position, numbers of the compiled program
        (:func:`liesample.geometric_hmc`).

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position, rng_key=None)`` and ``step(rng_key, state) -> (state, info)``.

    Examples
    --------
    >>> logdensity_fn = lambda x: -0.5 * x @ x
    >>> field = liesample.default_magnetic_field(jnp.ones(4), strength=1.0)
    >>> sampler = liesample.magnetic_langevin(logdensity_fn, 0.1, jnp.ones(4), 1.0, field)
    >>> state = sampler.init(jnp.zeros(4))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, float(info.acceptance_rate)  # unadjusted: reported as 1
    ((4,), 1.0)
    """
    density = with_model_arguments(logdensity_fn, model_args, model_kwargs)
    d = check_parameters(step_size, inverse_mass_matrix, magnetic_field)
    check_friction(friction)
    scheme = langevin_scheme(integrator)
    move = euclidean_move(step_size, inverse_mass_matrix, magnetic_field, scheme)

    def init_fn(position, rng_key=None):
        dimension = ravel(position).shape[0]
        if dimension != d:
            raise ValueError(
                f"position has {dimension} coordinates but inverse_mass_matrix and "
                f"magnetic_field are for {d}"
            )
        return init(position, density, rng_key)

    def step_fn(rng_key, state):
        return _step(step_key(rng_key), state, density, move, friction)

    settings = {
        "sampler": "magnetic_langevin",
        "step_size": setting(step_size),
        "step_size_source": "given",
        "friction": setting(friction),
        **scheme_setting(integrator, "baoab"),
    }
    check_positions = check_starts(logdensity_fn, d, (model_args, model_kwargs))
    numbers = {"step_size": step_size, "inverse_mass_matrix": inverse_mass_matrix,
               "friction": friction, "magnetic_field": magnetic_field}  # fmt: skip
    numbers.update(model_values(model_args, model_kwargs))
    fixed = {"integrator": integrator}
    return Sampler(
        init_fn,
        step_fn,
        settings=settings,
        check_positions=check_positions,
        stuck_advice=(
            "Give a smaller step_size: an unadjusted step is rejected only where it diverges "
            "(info.metropolis_rate is the rate the step would have as a Metropolis proposal)."
        ),
        divergence_advice=unadjusted_advice("liesample.magnetic_hmc(logdensity_fn, ...)"),
        structure=Recipe(magnetic_langevin, (logdensity_fn,), fixed, numbers).structure(),
    )


magnetic_langevin = sampling_api(
    as_top_level_api, init, build_kernel, "magnetic_langevin", __name__
)
