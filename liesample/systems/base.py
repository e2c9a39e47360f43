"""What a Lie–Poisson system declares: algebra, Hamiltonian, noise, and its exact reference."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from liesample._validation import concrete_array
from liesample.algebras import LieAlgebra


@dataclass(frozen=True, eq=False)
class LiePoissonSystem:
    """A system on a dual Lie algebra ``g*``, declared and never integrated by hand.

    Parameters
    ----------
    name : str
        Human-readable name.
    algebra : LieAlgebra
        Bracket, coadjoint action and Casimirs.
    hamiltonian : callable
        ``μ ↦ h(μ)``, a scalar.
    noise_hamiltonians : callable
        ``μ ↦ (ĥ_1(μ), …, ĥ_m(μ))``, unit-strength noise Hamiltonians; the noise is ``σ ĥ_i`` and
        the dissipation is derived from the same functions (MATH.md §1).
    num_noises : int
        ``m``.
    event_shape : tuple of int
        Shape of one state ``μ``.
    default_position : array
        A valid initial state.
    reference : callable or None
        ``(beta, position) ↦`` the exact Gibbs law on the orbit through ``position``, or ``None``.
    component_names : tuple of str
        Labels of the state's last axis, for tables and plots.
    params : dict
        The physical parameters, recorded in outputs.
    """

    name: str
    algebra: LieAlgebra
    hamiltonian: Callable
    noise_hamiltonians: Callable
    num_noises: int
    event_shape: tuple[int, ...]
    default_position: Any
    reference: Callable | None = None
    component_names: tuple[str, ...] = ()
    params: dict = field(default_factory=dict)

    def casimirs(self, mu):
        return self.algebra.casimirs(mu)

    def check_position(self, position, name: str = "position"):
        """Reject a state of the wrong shape, non-finite, or on a degenerate (zero) orbit."""
        shape = tuple(jnp.shape(position))
        if shape != self.event_shape:
            raise ValueError(
                f"{name} must have shape {self.event_shape} for the {self.name}, got {shape}"
            )
        value = concrete_array(position)
        if value is None:
            return
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite, got {value}")
        with jax.ensure_compile_time_eval():
            casimirs = np.asarray(self.casimirs(value))
        if np.any(casimirs <= 0):
            raise ValueError(
                f"{name} lies on a degenerate orbit (a Casimir |μ|² is zero): {value}; "
                "choose a nonzero state"
            )
