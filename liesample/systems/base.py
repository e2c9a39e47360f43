"""A user-defined Lie–Poisson system from an algebra, a Hamiltonian and noise Hamiltonians."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from liesample.algebras import LieAlgebra
from liesample.system_base import LiePoissonSystem, count_noises

__all__ = ["LiePoissonSystem", "lie_poisson_system"]


def lie_poisson_system(
    algebra: LieAlgebra,
    hamiltonian: Callable,
    noise_hamiltonians: Callable,
    position,
    *,
    name: str = "Lie–Poisson system",
    **options,
) -> LiePoissonSystem:
    """A user-defined system from the three things the equation needs (ARCHITECTURE: *systems*).

    Parameters
    ----------
    algebra : LieAlgebra
        E.g. ``liesample.algebras.so3``, ``se3`` or any ``StructureConstants``.
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

    Everything else (the dissipation, Casimir checks, every integrator and sampler) comes from
    the engine; ``examples/custom_system.py`` builds a planar pendulum on ``se(2)*`` this way.
    """
    if not isinstance(algebra, LieAlgebra):
        raise TypeError(f"algebra must be a liesample.algebras.LieAlgebra, got {algebra!r}")
    if not callable(hamiltonian):
        raise TypeError(f"hamiltonian must be a callable μ ↦ h(μ), got {hamiltonian!r}")
    position = np.array(position, dtype=float)
    if position.ndim < 1:
        raise ValueError(f"position must be an array with at least one axis, got {position!r}")
    energy = jax.eval_shape(hamiltonian, jnp.asarray(position))
    if energy.shape != ():
        raise ValueError(f"hamiltonian must return a scalar, got shape {energy.shape}")
    system = LiePoissonSystem(
        name=name,
        algebra=algebra,
        hamiltonian=hamiltonian,
        noise_hamiltonians=noise_hamiltonians,
        num_noises=count_noises(noise_hamiltonians, position, "noise_hamiltonians"),
        event_shape=position.shape,
        default_position=position,
        **options,
    )
    system.check_position(position)
    return system
