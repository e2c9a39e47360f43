"""Single-vortex Metropolis for point vortices on the sphere: exact, with no step bias.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``) for a
:func:`liesample.systems.point_vortices` system. A step is one *sweep*: each vortex ``k`` in turn
(``k = 0 … N−1``) gets one proposal ``x_k → x_k'`` on its sphere, accepted with probability
``min(1, exp(−β Δh))``. Every move is reversible for the Gibbs law ``∝ exp(−βh)`` times the area
measure on ``(S²)^N`` (:mod:`liesample.targets.vortices`), so a sweep leaves it invariant
exactly, at either sign of ``β`` where the law is normalisable. Only the pairs of vortex ``k``
change, so

    Δh = −(Γ_k/4π) Σ_{j≠k} Γ_j [log |x_k' − x_j|² − log |x_k − x_j|²]

costs ``O(N)`` and a sweep ``O(N²)`` (the same as one evaluation of ``h``). The chain carries
``h`` (updated by the accepted ``Δh``), so ``info.energy`` costs nothing extra.

Proposals (both symmetric in the area measure, so the acceptance needs no proposal ratio):

- ``"rotation"`` (default): ``u' = (u + ε g)/|u + ε g|`` for the unit vector ``u = x_k/R``,
  ``g ~ N(0, I₃)``; its law depends only on ``u·u'`` (isotropy), hence is symmetric. The scale
  ``ε = proposal_scale`` is the sampler's step size: tuned in the warm-up of
  ``liesample.sample(..., num_warmup=n)`` by dual averaging to a mean acceptance (default 0.4).
  Beyond :data:`MAX_PROPOSAL_SCALE` the proposal is uniform to round-off and the scale is capped
  there (at ``β`` near 0 every proposal is accepted and the tuning would grow it without bound).
- ``"uniform"``: ``u'`` uniform on the sphere, independent of ``u``.

A proposal that lands on another vortex (``Δh`` not finite) is rejected.

**Where it mixes.** A pair ``j, k`` with exponent ``p = βΓ_jΓ_k/(4π) < 0`` attracts: its chord
``d`` has the Gibbs density ``∝ d^{2p}`` in the area measure. From a pair at ``d`` much below
the proposal's reach ``ε``, a proposal of either vortex lands at distance ``r ~ ε`` and is
accepted with probability ``(d/r)^{2|p|}`` on average, so the chain stays put for a time
``∝ d^{−2|p|}``, whose mean under the Gibbs law, ``∫ d^{−2|p|} d^{2p} d(d²)``, is finite only for
``p > −1/2`` (the same bound as the finite variance of the importance-sampling reference
:func:`liesample.targets.vortices.gibbs_expectation`). For ``−1 < p < −1/2`` the law is
normalisable but the chain's averages converge more slowly than ``1/√n`` and their MCSE, ESS
and R-hat are unreliable: :func:`as_top_level_api` warns (:func:`mixing_warning`; at
``p = −1/2`` itself the divergence is only logarithmic, and it does not warn). The check
takes pairs only; a collapsing cluster of more vortices has a stricter bound of the same kind,
met only by deep clusters that carry little of the law's mass.
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.dynamics.system import checked_beta
from liesample.foundation.validation import finite_float
from liesample.samplers.contract import (
    BasicInfo,
    Recipe,
    Sampler,
    Structure,
    Tunable,
    ValidityWarning,
    sampling_api,
    step_key,
)
from liesample.samplers.orbit._starts import orbit_settings, plain_init_fn
from liesample.systems.point_vortices import PointVortexSystem
from liesample.targets.vortices import pair_exponents

__all__ = [
    "DEFAULT_PROPOSAL_SCALE",
    "MAX_PROPOSAL_SCALE",
    "PROPOSALS",
    "VortexInfo",
    "VortexState",
    "as_top_level_api",
    "build_kernel",
    "init",
    "mixing_warning",
    "vortex_metropolis",
]

PROPOSALS = ("rotation", "uniform")

DEFAULT_PROPOSAL_SCALE = 0.5
"""``ε`` used when none is given and there is no warm-up (a move of about half a radian)."""

MAX_PROPOSAL_SCALE = 1e3
"""Beyond this ``ε`` the rotation proposal is uniform on the sphere to round-off."""

_SOURCE_DEFAULT = f"default proposal_scale {DEFAULT_PROPOSAL_SCALE:g} (no warm-up)"


class VortexState(NamedTuple):
    """The positions (``position``, shape ``(N, 3)``) and ``h`` there (``energy``)."""

    position: jax.Array
    energy: jax.Array


VortexInfo = BasicInfo
"""What one sweep did: the Info contract's fields only (``acceptance_rate``: the fraction of the
``N`` single-vortex proposals accepted)."""


def _check_system(system) -> PointVortexSystem:
    if not isinstance(system, PointVortexSystem):
        raise TypeError(
            f"system must be a point_vortices(...) PointVortexSystem, got {type(system).__name__}"
        )
    return system


_PACKAGE = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))  # warn the caller

MIXING_EXPONENT = -0.5
"""The pair exponent ``p = βΓ_jΓ_k/(4π)`` below which the mean holding time of a collapsed pair
grows without bound under the Gibbs law (module notes, "Where it mixes")."""


def mixing_warning(
    system: PointVortexSystem, beta: float, sampler: str = "vortex_metropolis"
) -> str | None:
    """Why ``sampler``'s local moves do not mix at ``beta`` (module notes, "Where it mixes"), or
    ``None``. The bound is derived for this module's sweeps; the orbit samplers' steps are local
    too, and a collapsed pair holds them as well (:func:`warn_if_unmixing`)."""
    gamma = np.asarray(system.circulations, dtype=float)
    if gamma.size < 2:
        return None
    p = pair_exponents(gamma, beta)
    j, k = np.unravel_index(np.argmin(p), p.shape)
    if p[j, k] >= MIXING_EXPONENT:
        return None
    bound = MIXING_EXPONENT * 4.0 * math.pi / (gamma[j] * gamma[k])
    moves = (
        "The sweeps mix"
        if sampler == "vortex_metropolis"
        else "Its steps are local too: vortex_metropolis's sweeps, whose bound this is, mix"
    )
    side = ">" if bound < 0 else "<"
    message = (
        f"{sampler} at beta = {beta:g}: the pair of vortices ({j}, {k}) has the exponent "
        f"p = beta*Γ_jΓ_k/(4π) = {p[j, k]:.3g} < -1/2. The Gibbs law is normalisable (p > -1), "
        "but a collapsed pair holds the chain for a time whose mean under that law is infinite, "
        "so chain averages converge more slowly than 1/sqrt(n) and their MCSE, ESS and R-hat "
        f"are unreliable. {moves} for beta {side}= {bound:.6g}"
    )
    if gamma.size == 2:
        return message + (
            "; for this pair draw the exact law instead: "
            "system.reference(beta).sample(rng_key, num_samples) (the law of x1·x2)"
        )
    return message + "; at this beta run far more sweeps and compare independent runs"


def warn_if_unmixing(system, beta: float | None, sampler: str) -> None:
    """A :class:`~liesample.samplers.contract.ValidityWarning` at the caller's line when
    ``system`` is a point-vortex system and ``beta`` beyond where local moves mix
    (:func:`mixing_warning`); nothing otherwise."""
    if beta is None or not isinstance(system, PointVortexSystem):
        return
    message = mixing_warning(system, beta, sampler)
    if message is not None:
        warnings.warn(message, ValidityWarning, skip_file_prefixes=(_PACKAGE,))


def init(position, system: PointVortexSystem, rng_key=None) -> VortexState:
    """Initial state: the checked positions and ``h`` there (``rng_key`` is ignored)."""
    del rng_key
    _check_system(system)
    system.check_position(position)
    position = jnp.asarray(position, dtype=jnp.result_type(float))
    return VortexState(position, system.hamiltonian(position))


def _pair_log_chords(y, x):
    """``log |y − x_j|²`` for one point ``y`` (3,) and every ``x_j`` (N, 3)."""
    diff = x - y
    return jnp.log(jnp.sum(diff * diff, axis=-1))


def build_kernel(system: PointVortexSystem, proposal: str = "rotation"):
    """``kernel(rng_key, state, beta, proposal_scale) -> (state, VortexInfo)``, one sweep.

    ``proposal`` is structural; ``beta`` and ``proposal_scale`` may be traced.
    """
    _check_system(system)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    num_vortices = int(system.event_shape[0])
    radius = float(system.radius)
    gamma_np = np.asarray(system.circulations, dtype=float)

    def kernel(rng_key, state: VortexState, beta, proposal_scale):
        x0 = state.position
        dtype = x0.dtype
        gamma = jnp.asarray(gamma_np, dtype=dtype)
        scale = jnp.minimum(jnp.asarray(proposal_scale, dtype), MAX_PROPOSAL_SCALE)
        key_move, key_accept = jax.random.split(rng_key)
        steps = jax.random.normal(key_move, (num_vortices, 3), dtype=dtype)
        log_u = jnp.log(jax.random.uniform(key_accept, (num_vortices,), dtype=dtype))
        indices = jnp.arange(num_vortices)

        def move(k, carry):
            x, energy, accepted = carry
            old = x[k]
            if proposal == "rotation":
                moved = old / radius + scale * steps[k]
            else:
                moved = steps[k]
            new = radius * moved / jnp.linalg.norm(moved)
            others = jnp.where(indices == k, 0.0, gamma)  # the self pair drops out
            change = _pair_log_chords(new, x) - _pair_log_chords(old, x)
            change = jnp.where(indices == k, 0.0, change)
            delta = -gamma[k] * jnp.sum(others * change) / (4.0 * math.pi)
            accept = jnp.isfinite(delta) & (log_u[k] < -beta * delta)
            x = x.at[k].set(jnp.where(accept, new, old))
            energy = energy + jnp.where(accept, delta, 0.0)
            return x, energy, accepted + accept.astype(jnp.int32)

        x, energy, accepted = jax.lax.fori_loop(
            0, num_vortices, move, (x0, state.energy, jnp.zeros((), jnp.int32))
        )
        divergent = ~(jnp.all(jnp.isfinite(x)) & jnp.isfinite(energy))
        x = jnp.where(divergent, x0, x)
        energy = jnp.where(divergent, state.energy, energy)
        accepted = jnp.where(divergent, 0, accepted)
        rate = accepted.astype(dtype) / num_vortices
        return VortexState(x, energy), VortexInfo(divergent, rate, energy)

    return kernel


def as_top_level_api(
    system: PointVortexSystem,
    *,
    beta: float,
    proposal: str = "rotation",
    proposal_scale: float | None = None,
    target_acceptance_rate: float = 0.4,
) -> Sampler:
    """Exact single-vortex Metropolis sampler of ``exp(−βh)`` for point vortices (module notes).

    Parameters
    ----------
    system : PointVortexSystem
        From :func:`liesample.systems.point_vortices` (any circulations, radius; the noise
        degree plays no part: the law does not depend on the noise).
    beta : float
        Inverse temperature, either sign, inside the normalisable range
        (:func:`liesample.targets.vortices.beta_bounds`; ``β < 0``: Onsager's clustered states).
    proposal : {"rotation", "uniform"}
        A random rotation of size ``proposal_scale`` of one vortex, or an independent uniform
        point.
    proposal_scale : float or None
        ``ε > 0`` of the rotation proposal, the sampler's step size (any value is exact; it sets
        the acceptance). ``None`` (default): tuned in the warm-up of
        ``liesample.sample(..., num_warmup=n)`` by dual averaging to
        ``target_acceptance_rate``; without warm-up, :data:`DEFAULT_PROPOSAL_SCALE`. A given
        scale is kept unless ``liesample.sample(..., adapt=True)``.
    target_acceptance_rate : float in (0, 1)
        What the warm-up aims at (default 0.4).

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position) -> VortexState`` and ``step(rng_key, state) -> (state, VortexInfo)``,
        one step being one sweep over the vortices; jit- and vmap-able, usable with
        ``liesample.sample``. It declares ``adaptation`` (dual averaging of ``proposal_scale``).

    Examples
    --------
    >>> system = liesample.systems.point_vortices([1.0, 1.0, -1.0])
    >>> sampler = liesample.vortex_metropolis(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((3, 3), False)
    """
    _check_system(system)
    beta = checked_beta(system, beta)
    warn_if_unmixing(system, beta, "vortex_metropolis")
    return _build(system, beta, proposal, proposal_scale, target_acceptance_rate)


def _build(system, beta, proposal, proposal_scale, target_acceptance_rate) -> Sampler:
    """:func:`as_top_level_api` after its checks of ``system`` and ``beta`` (the factory of its
    :class:`Recipe`, so the mixing warning is given once)."""
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    given = proposal_scale is not None
    if given:
        proposal_scale = finite_float("proposal_scale", proposal_scale, positive=True)
    target = finite_float("target_acceptance_rate", target_acceptance_rate, rate=True)
    settings = orbit_settings(
        "vortex_metropolis",
        system,
        beta,
        proposal=proposal,
        step_size=proposal_scale if given else DEFAULT_PROPOSAL_SCALE,
        step_size_source="given" if given else _SOURCE_DEFAULT,
        target_acceptance_rate=target,
    )
    options = {"beta": beta, "proposal": proposal, "target_acceptance_rate": target}
    at = _Stepper(system, proposal)
    # dual averaging of the proposal scale at ``target``, up to MAX_PROPOSAL_SCALE
    tunable = Tunable(
        "dual_averaging", given, _choose, target, MAX_PROPOSAL_SCALE, adapted=("proposal_scale",)
    )
    scale = settings["step_size"]
    return at(
        scale,
        beta,
        settings=settings,
        check_positions=functools.partial(_check_positions, system),
        adaptation=tunable,
        structure=Structure(at, {"proposal_scale": scale, "beta": beta}),
        recipe=Recipe(_build, (system,), options, {"proposal_scale": proposal_scale}),
    )


def _check_positions(system, positions, *, step_size_checks=True):
    del step_size_checks  # any proposal scale is exact
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 1 + len(system.event_shape):
        system.check_position(positions, "initial_positions")
    for chain, position in enumerate(positions):
        system.check_position(position, f"initial_positions[{chain}]")
        energy = float(system.hamiltonian(jnp.asarray(position)))
        if not math.isfinite(energy):
            raise ValueError(f"initial_positions[{chain}]: h is not finite there")


def _choose(positions, rng_key=None):
    del positions, rng_key
    return DEFAULT_PROPOSAL_SCALE, _SOURCE_DEFAULT


@dataclass(frozen=True)
class _Stepper:
    """What decides the compiled step (the :class:`Structure`'s ``build``, which the warm-up
    steps too): called with the ``proposal_scale`` and ``beta`` (floats, or traced), the
    sampler with ``hooks``."""

    system: PointVortexSystem
    proposal: str

    def __call__(self, proposal_scale, beta, **hooks) -> Sampler:
        kernel = build_kernel(self.system, self.proposal)

        def step_fn(rng_key, state):
            return kernel(step_key(rng_key), state, beta, proposal_scale)

        return Sampler(plain_init_fn(init, self.system), step_fn, **hooks)


vortex_metropolis = sampling_api(
    as_top_level_api, init, build_kernel, "vortex_metropolis", __name__
)
