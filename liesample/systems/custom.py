"""A user-defined Lie–Poisson system from an algebra, a Hamiltonian and noise Hamiltonians."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.geometry.algebras import LieAlgebra

__all__ = ["LiePoissonSystem", "lie_poisson_system"]


@by_value
def lie_poisson_system(
    algebra: LieAlgebra,
    hamiltonian: Callable[[jax.Array], jax.Array],
    noise_hamiltonians: Callable[[jax.Array], jax.Array],
    position: ArrayLike,
    *,
    name: str = "Lie–Poisson system",
    **options: Any,
) -> LiePoissonSystem:
    """A user-defined system from the three things the equation needs.

    Parameters
    ----------
    algebra : LieAlgebra
        E.g. ``liesample.geometry.algebras.so3``, ``se3`` or any ``StructureConstants``.
    hamiltonian : callable
        ``μ ↦ h(μ)``, a scalar.
    noise_hamiltonians : callable
        ``μ ↦ (ĥ_1(μ), …, ĥ_m(μ))``, unit strength; the dissipation is derived from them.
    position : array
        A valid state; fixes the state's shape and the default start.
    name : str
    **options
        Any other :class:`LiePoissonSystem` field (``reference``, ``component_names``,
        ``noise_groups``, ``positive_casimirs``, …).

    Notes
    -----
    Everything else (the dissipation, Casimir checks, every integrator and sampler) comes from
    the engine; a planar pendulum on ``se(2)*`` is built this way from ``se2``.

    Examples
    --------
    A rigid body with one noise, about the first axis (the dissipation is derived from it):

    >>> from liesample.algebras import so3
    >>> from liesample.systems import lie_poisson_system
    >>> inertia = jnp.array([1.0, 2.0, 4.0])
    >>> system = lie_poisson_system(so3, lambda mu: 0.5 * mu @ (mu / inertia),
    ...                             lambda mu: mu[:1], jnp.array([0.0, 0.0, 1.0]))
    >>> system.num_noises, system.event_shape
    (1, (3,))
    """
    if not isinstance(algebra, LieAlgebra):
        raise TypeError(
            f"algebra must be a liesample.geometry.algebras.LieAlgebra, got {algebra!r}"
        )
    if not callable(hamiltonian):
        raise TypeError(f"hamiltonian must be a callable μ ↦ h(μ), got {hamiltonian!r}")
    position = _real_position(position)
    _check_algebra_acts_on(algebra, position)
    energy = jax.eval_shape(hamiltonian, jnp.asarray(position))
    if energy.shape != ():
        raise ValueError(f"hamiltonian must return a scalar, got shape {energy.shape}")
    if energy.dtype.kind != "f":
        raise TypeError(
            f"hamiltonian must return a real floating scalar, got dtype {energy.dtype}; return "
            "the real energy h(μ) as a float"
        )
    system = LiePoissonSystem(
        name=name,
        algebra=algebra,
        hamiltonian=hamiltonian,
        noise_hamiltonians=noise_hamiltonians,
        default_position=position,
        **options,
    )
    system.check_position(position)
    return system


def _real_position(position) -> np.ndarray:
    """``position`` as a float array with at least one axis; refuses booleans, complex numbers,
    strings and ragged nests, naming what was given."""
    try:
        value = np.asarray(position)
    except ValueError as error:  # a ragged nest of sequences
        raise ValueError(f"position must be a real array, got {position!r} ({error})") from None
    if value.dtype == bool or not (
        np.issubdtype(value.dtype, np.integer) or np.issubdtype(value.dtype, np.floating)
    ):
        raise TypeError(
            f"position must be a real (integer or float) array, got dtype {value.dtype}: "
            f"{position!r}"
        )
    if value.ndim < 1:
        raise ValueError(f"position must be an array with at least one axis, got {position!r}")
    return np.array(value, dtype=float)


def _check_algebra_acts_on(algebra: LieAlgebra, position: np.ndarray) -> None:
    """The algebra's coadjoint action and Casimirs must accept an element of ``position``'s
    shape and return one of the same shape (e.g. so(3) needs a last axis of 3, se(3) of 6)."""
    try:
        moved = jax.eval_shape(lambda m: algebra.coadjoint_exp(m, m), position)
        jax.eval_shape(algebra.casimirs, position)
    except (TypeError, ValueError, IndexError) as error:
        raise ValueError(
            f"position has shape {position.shape}, which is not an element of the {algebra.name} "
            f"algebra's dual (so(3): (..., 3); se(3): (..., 6); StructureConstants: (d,)): "
            f"{error}"
        ) from None
    if moved.shape != position.shape:
        raise ValueError(
            f"position has shape {position.shape}, but the {algebra.name} algebra's coadjoint "
            f"action returns shape {moved.shape}: position must be one element of its dual"
        )
