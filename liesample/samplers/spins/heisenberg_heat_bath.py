"""Heat bath plus over-relaxation for classical Heisenberg spins, from the exact limits of the
single-spin dynamics.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). One step is

1. ``heat_bath_sweeps`` sweeps, each redrawing every spin from its exact conditional law
   ``∝ exp(β s_k·F_k)`` one colour class at a time: the infinite-time limit of the
   noise–dissipation part of the stochastic Landau–Lifshitz–Gilbert equation of one spin in its
   frozen local field ``F_k`` (a von Mises–Fisher draw);
2. ``overrelaxation`` sweeps of the exact Hamiltonian flow of each spin in its frozen field, a
   precession about ``F_k`` by ``precession_angle`` (``π``: the classical over-relaxation
   ``s ↦ 2(s·F̂)F̂ − s``), which keeps ``h``.

Each colour-class move keeps ``exp(−βh)`` exactly (:mod:`liesample.samplers.spins._lattice`), so
their composition does: there is no step size and no discretisation bias. Heat bath alone is
ergodic; over-relaxation alone is microcanonical (it never changes ``h``), and the pair is the
physicists' standard sampler for O(3) models. Isotropic systems only (``anisotropy = 0``); any
coupling sign, field, boundary and finite ``β``.

The same step samples every O(n) lattice of :func:`liesample.systems.n_vector`: the heat bath
draws the von Mises–Fisher law on ``S^{n−1}`` and over-relaxation is the reflection about the
local field (for ``n ≠ 3`` the only energy-keeping precession, so ``precession_angle`` must be
``π`` there).
"""

from __future__ import annotations

import math

from liesample.foundation.validation import finite_float
from liesample.samplers.contract import Sampler, sampling_api
from liesample.samplers.spins._lattice import (
    SpinInfo,
    SpinState,
    SpinSystem,
    check_beta,
    check_precession_angle,
    check_spin_system,
    check_sweeps,
    checkerboard_step,
    heat_bath,
    init,
    precess,
    require_isotropic,
    spin_sampler,
    sublattices,
)

__all__ = ["SpinInfo", "SpinState", "as_top_level_api", "build_kernel", "init"]


def build_kernel(system: SpinSystem, heat_bath_sweeps: int = 1, overrelaxation: int = 1):
    """``kernel(rng_key, state, beta, precession_angle) -> (state, SpinInfo)``.

    The sweep counts are structural (unrolled); ``beta`` and ``precession_angle`` may be traced
    (for ``n ≠ 3`` the angle must be the float ``π``).
    """
    check_spin_system(system)
    require_isotropic(system, "heisenberg_heat_bath")
    heat_bath_sweeps = check_sweeps("heat_bath_sweeps", heat_bath_sweeps)
    overrelaxation = check_sweeps("overrelaxation", overrelaxation)
    classes = sublattices(system)

    def kernel(rng_key, state: SpinState, beta, precession_angle):
        return checkerboard_step(
            system, rng_key, state, classes, heat_bath_sweeps, overrelaxation,
            lambda key, flat, sublattice: heat_bath(system, key, flat, sublattice, beta),
            lambda flat, sublattice: precess(system, flat, sublattice, precession_angle),
        )  # fmt: skip

    return kernel


def as_top_level_api(
    system: SpinSystem,
    *,
    beta: float,
    overrelaxation: int = 1,
    heat_bath_sweeps: int = 1,
    precession_angle: float = math.pi,
) -> Sampler:
    """Heat-bath + over-relaxation sampler of ``exp(−βh)`` for an isotropic :func:`heisenberg` or
    any :func:`n_vector` lattice.

    Parameters
    ----------
    system : SpinLatticeSystem or NVectorSystem
        From :func:`liesample.systems.heisenberg` with ``anisotropy = 0`` (a ``ValueError``
        otherwise), or from :func:`liesample.systems.n_vector` (any ``n ≥ 2``).
    beta : float
        Inverse temperature (finite, any sign).
    overrelaxation : int
        Precession (over-relaxation) sweeps per step, ``≥ 0``.
    heat_bath_sweeps : int
        Heat-bath sweeps per step, ``≥ 0``; with 0 the chain is microcanonical (it keeps ``h``),
        so it samples ``exp(−βh)`` only from exact starting draws.
    precession_angle : float
        Angle of each precession about the local field (radians, finite); ``π`` is
        over-relaxation, and the only angle allowed for ``n ≠ 3``.

    Returns
    -------
    Sampler
        ``init(position) -> SpinState`` and ``step(rng_key, state) -> (state, SpinInfo)``; one
        step is the sweeps above; jit- and vmap-able, usable with :mod:`liesample.run.runner`.

    Examples
    --------
    >>> system = liesample.systems.heisenberg((4, 4), periodic=True)
    >>> sampler = liesample.heisenberg_heat_bath(system, beta=1.0)
    >>> state = sampler.init(system.default_position)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((4, 4, 3), False)
    """
    beta = check_beta(beta)
    precession_angle = finite_float("precession_angle", precession_angle)
    check_spin_system(system)
    check_precession_angle(system, precession_angle)
    heat_bath_sweeps = check_sweeps("heat_bath_sweeps", heat_bath_sweeps)
    overrelaxation = check_sweeps("overrelaxation", overrelaxation)
    if heat_bath_sweeps + overrelaxation == 0:
        raise ValueError("heat_bath_sweeps + overrelaxation must be >= 1 (a step must move)")
    return spin_sampler(
        "heisenberg_heat_bath",
        _kernel_at_angle,
        (heat_bath_sweeps, overrelaxation, precession_angle),
        system,
        beta,
        heat_bath_sweeps=heat_bath_sweeps,
        overrelaxation=overrelaxation,
        precession_angle=precession_angle,
    )


def _kernel_at_angle(system, heat_bath_sweeps, overrelaxation, precession_angle):
    """The kernel of :func:`build_kernel` with the precession angle fixed (a constant of the
    compiled step, as the draws were made; ``β`` stays traced)."""
    kernel = build_kernel(system, heat_bath_sweeps, overrelaxation)

    def at_angle(rng_key, state, beta):
        return kernel(rng_key, state, beta, precession_angle)

    return at_angle


heisenberg_heat_bath = sampling_api(
    as_top_level_api, init, build_kernel, "heisenberg_heat_bath", __name__
)
