"""What the classical-spin samplers share: state, info, local fields and the exact moves.

The samplers (:mod:`~liesample.samplers.spins.heisenberg_heat_bath`,
:mod:`~liesample.samplers.spins.heisenberg_metropolis`,
:mod:`~liesample.samplers.spins.heisenberg_cluster`) act on a :func:`liesample.systems.heisenberg`
system, or on any O(n) lattice of :func:`liesample.systems.n_vector` (spins in ``S^{n−1}``,
``n ≥ 2``; the moves below are written for ``S²`` and hold on every sphere, except the
precession by an angle other than ``π``, which needs ``n = 3``). Spins of one colour class of
the lattice's proper colouring (:func:`liesample.systems.heisenberg.colouring`) are never
neighbours, so given the other classes each feels a fixed local field

    ``F_k = J Σ_{j~k} s_j + B``      (``h = −s_k·F_k + …`` in ``s_k``, when ``D = 0``),

and the stochastic Landau–Lifshitz–Gilbert equation of that spin alone (paper,
``eq:lie-poisson-langevin``) has two exactly solvable parts:

- its **Hamiltonian flow** ``ṡ_k = s_k × ∇_k h = F_k × s_k``, a precession about ``F_k``
  (:func:`precess`; by the angle ``π`` it is the physicists' over-relaxation): it keeps ``h``
  and the area on ``S²``, hence ``exp(−βh)``, exactly, for any angle;
- its **noise–dissipation part**, a diffusion on ``S²`` whose law at infinite time is the exact
  conditional law ``∝ exp(β s_k·F_k)``, a von Mises–Fisher law of concentration ``β|F_k|``
  (:func:`heat_bath`; on ``S^{n−1}`` the same conditional law, drawn by
  :func:`liesample.targets.n_vector.von_mises_fisher_sphere`).

Every sampler's info follows the package's one contract: ``is_divergent`` (the new state or
its energy was non-finite; the chain then kept its state), ``acceptance_rate`` (the Metropolis
acceptance; 1 for rejection-free moves) and ``energy`` (``h`` after the step).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.validation import finite_float
from liesample.geometry.algebras import so3
from liesample.samplers.contract import BasicInfo, Sampler, Structure, step_key
from liesample.samplers.orbit._starts import orbit_groups, orbit_settings, plain_init_fn
from liesample.systems.cp_model import CPModelSystem
from liesample.systems.heisenberg import (
    SpinLatticeSystem,
    colouring,
    neighbour_sum,
    neighbour_table,
)
from liesample.systems.n_vector import NVectorSystem
from liesample.targets.n_vector import von_mises_fisher_sphere
from liesample.targets.spins import von_mises_fisher

__all__ = [
    "SpinInfo",
    "SpinState",
    "SpinSystem",
    "Sublattice",
    "check_beta",
    "check_precession_angle",
    "check_spin_system",
    "check_sweeps",
    "checkerboard_step",
    "energy_change",
    "finish_step",
    "heat_bath",
    "init",
    "local_energy_change",
    "local_field",
    "precess",
    "require_isotropic",
    "spin_components",
    "spin_sampler",
    "sublattice_field",
    "sublattices",
]


SpinSystem = SpinLatticeSystem | NVectorSystem | CPModelSystem
"""What the spin samplers take: :func:`liesample.systems.heisenberg`,
:func:`liesample.systems.n_vector` or :func:`liesample.systems.cp_model` lattices."""


class SpinState(NamedTuple):
    """The spins (``position``, shape ``(*shape, n)``, unit vectors)."""

    position: jax.Array


SpinInfo = BasicInfo
"""What one step of a spin sampler did: the Info contract's fields only."""


def check_spin_system(system) -> dict:
    """``system.params`` of a :func:`heisenberg` or :func:`n_vector` system, or a
    ``TypeError``."""
    if not isinstance(system, (SpinLatticeSystem, NVectorSystem)):
        raise TypeError(
            "system must be a heisenberg(...) SpinLatticeSystem or an n_vector(...) "
            f"NVectorSystem (liesample.systems), got {type(system).__name__}"
        )
    return system.params


def spin_components(system: SpinSystem) -> int:
    """``n``: the components of one spin (3 for :func:`heisenberg`)."""
    return system.event_shape[-1]


def require_isotropic(system, sampler: str) -> None:
    """Refuse ``D ≠ 0``: the conditional law of a spin is then Fisher–Bingham, not vMF."""
    anisotropy = system.params["anisotropy"]
    if anisotropy != 0.0:
        raise ValueError(
            f"{sampler} needs an isotropic system (anisotropy = 0): with D = {anisotropy:g} a "
            "spin's conditional law exp(beta*(s.F + D s_z^2)) is not von Mises-Fisher and the "
            "precession about F does not keep h; use heisenberg_metropolis or "
            "lie_poisson_langevin for anisotropic systems"
        )


def init(position, system: SpinSystem, rng_key=None) -> SpinState:
    """Initial state (unit spins are checked; ``rng_key`` is ignored)."""
    del rng_key
    system.check_position(position)
    return SpinState(jnp.asarray(position, dtype=jnp.result_type(float)))


def spin_sampler(
    name: str, build_kernel, structural: tuple, system: SpinSystem, beta, *parameters,
    start: Callable | None = None, **settings,
):  # fmt: skip
    """The :class:`~liesample.samplers.contract.Sampler` of ``kernel(rng_key, state, beta,
    *parameters)``, ``kernel = build_kernel(system, *structural)``, on ``system`` (keyless
    :func:`init`, or ``start(system)``'s ``init_fn(position, rng_key=None)`` where given: a
    module-level function, so that equal samplers stay equal); its settings are ``name``, the
    system, ``beta``, then ``settings`` in order.
    It declares its :class:`~liesample.samplers.contract.Structure`: ``β`` and the numeric
    ``parameters`` are traced, so a sweep over them compiles once. Chains of a
    :func:`heisenberg` system are grouped by orbit (unit spins: one group); those of an
    :func:`n_vector` system sample one law."""
    at = _SpinStepper(
        build_kernel, system, tuple(structural), len(parameters), start or _real_spin_start
    )
    values = {"beta": beta} | {f"parameter_{i}": value for i, value in enumerate(parameters)}
    return at(
        **values,
        settings=orbit_settings(name, system, beta, **settings),
        law_groups=orbit_groups(system) if isinstance(system, SpinLatticeSystem) else None,
        structure=Structure(at, values),
    )


@dataclass(frozen=True)
class _SpinStepper:
    """What decides a spin sampler's compiled step: its ``build_kernel``, the system, the
    structural arguments and how many numeric parameters the kernel takes after ``beta``;
    called with ``beta`` and ``parameter_0 …`` (floats, or traced), the sampler with
    ``hooks``."""

    build_kernel: Callable
    system: SpinSystem
    structural: tuple
    num_parameters: int
    start: Callable

    def __call__(self, beta, **hooks) -> Sampler:
        parameters = [hooks.pop(f"parameter_{i}") for i in range(self.num_parameters)]
        kernel = self.build_kernel(self.system, *self.structural)

        def step_fn(rng_key, state):
            return kernel(step_key(rng_key), state, beta, *parameters)

        return Sampler(self.start(self.system), step_fn, **hooks)


def _real_spin_start(system: SpinSystem):
    """The O(n) samplers' ``init_fn``: :func:`init` on a real start."""
    return plain_init_fn(init, system)


class Sublattice(NamedTuple):
    """One colour class: its flat site indices ``(n,)`` and their neighbours ``(n, 2·dim)``
    (index ``N``, a zero spin, where an open boundary has none)."""

    sites: jax.Array
    neighbours: jax.Array


def sublattices(system: SpinSystem) -> list[Sublattice]:
    """The colour classes of the lattice's proper colouring, as gather indices (static)."""
    params = system.params
    colours, num_colours = colouring(params["shape"], params["periodic"])
    table = neighbour_table(params["shape"], params["periodic"])
    out = []
    for c in range(num_colours):
        sites = np.flatnonzero(colours.reshape(-1) == c)
        out.append(Sublattice(jnp.asarray(sites, jnp.int32), jnp.asarray(table[sites], jnp.int32)))
    return out


def sublattice_field(system: SpinSystem, flat, sublattice: Sublattice):
    """``F_k = J Σ_{j~k} s_j + B`` at the sites of ``sublattice`` (``flat``: spins ``(N, n)``)."""
    padded = jnp.concatenate([flat, jnp.zeros((1, flat.shape[-1]), flat.dtype)])
    params = system.params
    return params["coupling"] * jnp.sum(padded[sublattice.neighbours], axis=1) + jnp.asarray(
        params["field"], dtype=flat.dtype
    )


def local_field(system: SpinSystem, s):
    """``F_k = J Σ_{j~k} s_j + B`` for every site (shape of ``s``)."""
    params = system.params
    return params["coupling"] * neighbour_sum(s, params["periodic"]) + jnp.asarray(
        params["field"], dtype=s.dtype
    )


def energy_change(system: SpinSystem, old, new, field):
    """``Δh`` of moving single spins ``old → new`` in their local fields ``field`` (…, n):
    ``−(new − old)·F − D((new·e_z)² − (old·e_z)²)``; exact, as ``h`` has no self-interaction
    (every bond joins two distinct sites)."""
    delta = -jnp.sum((new - old) * field, axis=-1)
    anisotropy = system.params["anisotropy"]
    if anisotropy != 0.0:
        delta = delta - anisotropy * (new[..., 2] ** 2 - old[..., 2] ** 2)
    return delta


def local_energy_change(system: SpinSystem, s, new):
    """``Δh_k = h(s with s_k → new_k) − h(s)`` for every site ``k`` at once (lattice shape)."""
    return energy_change(system, s, new, local_field(system, s))


def _unit(field):
    """``(F/|F|, |F|)`` with ``F/|F| = 0`` where ``F = 0``."""
    norm = jnp.linalg.norm(field, axis=-1)
    safe = jnp.where(norm > 0.0, norm, 1.0)
    return jnp.where((norm > 0.0)[..., None], field / safe[..., None], 0.0), norm


def precess(system: SpinSystem, flat, sublattice: Sublattice, angle):
    """The spins of ``sublattice`` precess about their local fields by ``angle``: the exact
    Hamiltonian flow of each (``ṡ_k = F_k × s_k``, run for time ``angle/|F_k|``), which keeps
    ``h`` to round-off; spins with ``F_k = 0`` do not move. ``angle = π`` is over-relaxation,
    ``s ↦ 2(s·F̂)F̂ − s`` (computed so, without trigonometry, when ``angle`` is the float π).
    ``flat``: spins ``(N, n)``; for ``n ≠ 3`` only the reflection (``angle`` the float π) is
    defined (a rotation about one axis exists on ``S²`` only), any other angle a ``ValueError``.
    """
    check_precession_angle(system, angle)
    direction, _ = _unit(sublattice_field(system, flat, sublattice))
    s = flat[sublattice.sites]
    if isinstance(angle, float) and angle == math.pi:
        moved = 2.0 * jnp.sum(s * direction, axis=-1, keepdims=True) * direction - s
        moved = jnp.where(jnp.any(direction != 0.0, axis=-1, keepdims=True), moved, s)
    else:
        # Ad*_{exp ζ} s rotates about −ζ/|ζ| by |ζ| (so3.coadjoint_exp): ζ = −angle·F̂.
        moved = so3.coadjoint_exp(-angle * direction, s)
    return flat.at[sublattice.sites].set(moved)


def heat_bath(system: SpinSystem, rng_key, flat, sublattice: Sublattice, beta):
    """The spins of ``sublattice`` are redrawn from their exact conditional law
    ``∝ exp(β s·F_k)``: the infinite-time limit of each spin's noise–dissipation dynamics in the
    frozen field ``F_k``, a von Mises–Fisher law (on ``S²``
    :func:`liesample.targets.spins.von_mises_fisher`, on ``S^{n−1}``
    :func:`liesample.targets.n_vector.von_mises_fisher_sphere`); ``F_k = 0`` gives a uniform
    draw (about ``e_n``, so that the draw is a unit vector). ``flat``: spins ``(N, n)``."""
    direction, norm = _unit(sublattice_field(system, flat, sublattice))
    axis = jnp.zeros(flat.shape[-1], flat.dtype).at[-1].set(1.0)
    direction = jnp.where((norm > 0.0)[..., None], direction, axis)
    draw = von_mises_fisher if flat.shape[-1] == 3 else von_mises_fisher_sphere
    return flat.at[sublattice.sites].set(draw(rng_key, direction, beta * norm))


def checkerboard_step(system, rng_key, state, classes, heat_bath_sweeps, overrelaxation,
                      draw: Callable, reflect: Callable):  # fmt: skip
    """One step of a lattice's exact moves: ``heat_bath_sweeps`` sweeps of ``draw(key, flat,
    sublattice)`` over the colour classes (one key per class and sweep), then
    ``overrelaxation`` sweeps of ``reflect(flat, sublattice)``; ``(state, info)`` by
    :func:`finish_step`."""
    flat = state.position.reshape(-1, state.position.shape[-1])
    keys = jax.random.split(rng_key, max(1, heat_bath_sweeps * len(classes)))
    for sweep in range(heat_bath_sweeps):
        for c, sublattice in enumerate(classes):
            flat = draw(keys[sweep * len(classes) + c], flat, sublattice)
    for _ in range(overrelaxation):
        for sublattice in classes:
            flat = reflect(flat, sublattice)
    return finish_step(system, state.position, flat.reshape(state.position.shape), 1.0)


def finish_step(system: SpinSystem, old, new, acceptance_rate, info_class=SpinInfo, **extra):
    """``(SpinState, info)`` after a step; a non-finite state or energy keeps ``old`` (and
    reports ``acceptance_rate = 0``)."""
    energy = system.hamiltonian(new)
    divergent = ~(jnp.all(jnp.isfinite(new)) & jnp.isfinite(energy))
    position = jnp.where(divergent, old, new)
    energy = jnp.where(divergent, system.hamiltonian(old), energy)
    real_dtype = jnp.finfo(position.dtype).dtype  # a complex state's (CP(N−1)) real part
    rate = jnp.where(divergent, 0.0, jnp.asarray(acceptance_rate, dtype=real_dtype))
    return SpinState(position), info_class(divergent, rate, energy, **extra)


def check_precession_angle(system: SpinSystem, angle) -> None:
    """Refuse a precession angle other than the float ``π`` for ``n ≠ 3`` (on ``S^{n−1}`` the
    energy-keeping move of a spin in its field is the reflection about the field only)."""
    n = spin_components(system)
    if n != 3 and not (isinstance(angle, float) and angle == math.pi):
        raise ValueError(
            f"precession_angle must be math.pi for an O({n}) system (a precession about the "
            f"local field by another angle exists on S^2 only, n = 3); got {angle!r}. Leave "
            "precession_angle at its default (over-relaxation, the reflection about the field)"
        )


def check_beta(beta) -> float:
    """``β`` as a finite float (any sign: ``β < 0`` samples the negative temperature)."""
    return finite_float("beta", beta)


def check_sweeps(name: str, value) -> int:
    """A non-negative int count of sweeps, or a clear error."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be a non-negative int (sweeps per step), got {value!r}")
    if value < 0:
        raise ValueError(f"{name} must be a non-negative int (sweeps per step), got {value!r}")
    return int(value)
