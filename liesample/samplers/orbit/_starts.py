"""Checks of many starting points on coadjoint orbits in one vectorised call.

Shared by the orbit samplers' ``check_positions``
(:class:`~liesample.samplers.contract.Sampler`):
shape, finiteness, non-degenerate orbit and finite energy of every start are computed by one
compiled ``vmap``; only the first failing chain is re-checked by ``system.check_position`` so
that the error is the system's own message, prefixed by ``initial_positions[c]``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.precision import check_dtype, roundoff_tolerance
from liesample.foundation.validation import concrete_array
from liesample.samplers.contract import PositionCheck, first_bad_chain, raise_first_bad

__all__ = [
    "check_orbit_starts",
    "check_start_energy",
    "distinct_orbits",
    "orbit_init_fn",
    "orbit_settings",
    "plain_init_fn",
    "real_position",
]


def orbit_settings(name: str, system, beta, **settings) -> dict:
    """What every orbit sampler reports first in ``settings``: its name, the system and ``β``;
    then ``settings`` in order."""
    return {"sampler": name, "system": system.name, "beta": beta, **settings}


def real_position(position, name: str = "position"):
    """``position`` when it is an array of real numbers (a number or nested list becomes one
    array), else a ``TypeError`` naming ``name``: a bool, complex, string or object array is no
    point of ``g*`` (a complex one would pass as a degenerate orbit, a bool one as 0/1)."""
    if not hasattr(position, "dtype"):  # a number, or a (nested) list
        try:
            position = np.asarray(position)
        except ValueError:
            raise TypeError(f"{name} must be a real array (floats), got {position!r}") from None
    dtype = position.dtype
    if np.dtype(dtype).kind not in "iuf":  # signed, unsigned, floating
        raise TypeError(
            f"{name} must be a real array (floats), got dtype {dtype}; pass "
            "np.asarray(position, dtype=float) of real coordinates"
        )
    return position


def _init_on(init, system, position, rng_key=None):
    return init(real_position(position), system, rng_key)


def plain_init_fn(init, system):
    """``init_fn(position, rng_key=None)``: ``init(position, system, rng_key)`` with no check of
    a concrete start (the runner checks every start before it compiles)."""
    return functools.partial(_init_on, init, system)


def orbit_init_fn(init, system: LiePoissonSystem, check_orbits):
    """``init_fn(position, rng_key=None)`` of an orbit sampler: ``init(position, system,
    rng_key)``, and a concrete ``position`` passed to ``check_orbits(positions, [0])`` as the
    one chain of a batch (the sampler's own step-size and precision checks)."""

    def init_fn(position, rng_key=None):
        position = real_position(position)
        state = init(position, system, rng_key)
        value = concrete_array(position)
        if value is not None:
            check_orbits(np.asarray(value, dtype=jnp.result_type(float))[None], [0])
        return state

    return init_fn


def _start_values(system):
    """``positions ↦ (C(μ), h(μ))`` for every start, compiled once for every system equal to
    ``system`` (:mod:`liesample.foundation.identity`)."""
    return functools.partial(_casimirs_and_energies, system=system)


@functools.partial(jit, static_argnames="system")
def _casimirs_and_energies(positions, *, system):
    return jax.vmap(lambda mu: (system.casimirs(mu), system.hamiltonian(mu)))(positions)


def check_start_energy(system, position, energy) -> None:
    """``ValueError`` when the energy ``h`` of a concrete start is not finite (NaN/inf)."""
    if not np.isfinite(energy):
        raise ValueError(
            f"the energy h = {float(energy)} at this start of the {system.name} is not finite; "
            f"the chain would run on NaN. Start where h is finite (position {np.asarray(position)})"
        )


def check_orbit_starts(system: LiePoissonSystem, positions):
    """Check every start ``positions[c]`` (shape ``(chains, *event_shape)``) at once.

    Raises ``ValueError`` naming the first bad chain. Returns the Casimirs of every start,
    shape ``(chains, ...)``, for :func:`distinct_orbits`.
    """
    positions = np.asarray(real_position(positions, "initial_positions"))
    if positions.shape[1:] != tuple(system.event_shape):
        system.check_position(positions[0], "initial_positions[0]")  # the system's message
        raise ValueError(
            f"initial_positions must have shape (chains, *{tuple(system.event_shape)}), got "
            f"{positions.shape}"
        )
    flat = positions.reshape(positions.shape[0], -1)
    finite = np.all(np.isfinite(flat), axis=1)
    raise_first_bad([PositionCheck(finite, "must be finite")], positions, system.check_position)
    batched = getattr(system, "check_positions", None)
    casimirs, energies = evaluate(
        _start_values(system), np.asarray(positions, jnp.result_type(float))
    )
    casimirs, energies = np.asarray(casimirs), np.asarray(energies)
    if batched is not None:
        batched(positions, "initial_positions")
    else:
        chosen = (
            casimirs
            if system.positive_casimirs is None
            else casimirs[..., list(system.positive_casimirs)]
        )
        nondegenerate = np.all(chosen.reshape(len(positions), -1) > 0, axis=1)
        raise_first_bad(
            [PositionCheck(nondegenerate, "lies on a degenerate orbit")],
            positions,
            system.check_position,
        )
        if type(system).check_position is not LiePoissonSystem.check_position:
            # System-specific constraints (unit spins, distinct vortices): once per distinct start.
            _, first = np.unique(flat, axis=0, return_index=True)
            for chain in np.sort(first):
                system.check_position(positions[chain], f"initial_positions[{chain}]")
    chain = first_bad_chain(np.isfinite(energies))
    if chain is not None:
        try:
            check_start_energy(system, positions[chain], energies[chain])
        except ValueError as error:
            raise ValueError(f"initial_positions[{chain}]: {error}") from None
    return casimirs


def _orbits(casimirs, dtype):
    """``(first, labels)`` of :func:`numpy.unique` over the chains' Casimirs rounded to
    ``floor(−log10(1000 ε))`` decimals of ``dtype`` (12 in float64, 3 in float32): starts
    that differ by round-off lie on one orbit."""
    decimals = int(np.floor(-np.log10(roundoff_tolerance(dtype))))
    rounded = np.round(np.asarray(casimirs, dtype=float).reshape(len(casimirs), -1), decimals)
    _, first, labels = np.unique(rounded, axis=0, return_index=True, return_inverse=True)
    return first, labels.reshape(-1)


def orbit_groups(system: LiePoissonSystem):
    """The runner's ``law_groups`` hook: chains on one orbit (Casimirs equal to round-off,
    :func:`_orbits`) sample one Gibbs law."""

    def groups(positions):
        dtype = check_dtype(positions)
        positions = np.asarray(positions, jnp.result_type(float))
        casimirs = np.asarray(evaluate(_start_values(system), positions)[0])  # the starts' program
        return _orbits(casimirs, dtype)[1]

    return groups


def distinct_orbits(casimirs) -> np.ndarray:
    """Index of one start per distinct orbit (Casimirs equal to round-off, :func:`_orbits`)."""
    return np.sort(_orbits(casimirs, check_dtype(np.asarray(casimirs)))[0])
