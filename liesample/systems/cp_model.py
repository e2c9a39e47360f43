"""CP(N−1) lattices: unit complex vectors ``z_x ∈ Cᴺ`` modulo a phase on chains and hypercubic
lattices.

The state is a stack ``z`` of shape ``(*shape, N)`` (complex, ``N ≥ 2``), one unit vector per
site, each standing for its ray ``[z_x] ∈ CP^{N−1}`` (``z_x`` and ``e^{iφ} z_x`` are one
point). The Hamiltonian is

    h(z) = −J Σ_⟨xy⟩ |z_x^† z_y|²

over nearest-neighbour bonds (open or periodic boundaries), with Gibbs law ``∝ exp(−βh)`` on
``(CP^{N−1})^V`` with its Fubini–Study (Haar) measure. ``h`` depends on the rays only.

**As an orbit.** ``[z] ↦ P = z z^†`` identifies ``CP^{N−1}`` with the coadjoint orbit of the
rank-1 projector in ``u(N)* ≅`` Hermitian matrices (its traceless part ``P − 1/N`` lies in
``su(N)*``), and ``|z_x^† z_y|² = tr(P_x P_y)``: the CP(N−1) model is the "spin" model on that
orbit, as the Heisenberg model is on ``S² ⊂ so(3)*``. For ``N = 2`` the Hopf map
``s = z^† σ z`` (Pauli matrices ``σ``) is the identification ``CP¹ = S²``, with
``|z^† z'|² = (1 + s·s')/2``: CP(1) of coupling ``J`` is the O(3) model of coupling ``J/2``.

The lattice, its bond and neighbour sums and its colourings are those of
:mod:`liesample.systems.heisenberg` (one lattice code path): the bond term is the bond sum of
the real coordinates of ``P`` (``tr(P_x P_y)`` is their Euclidean dot product).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.identity import by_value
from liesample.foundation.validation import concrete_array
from liesample.systems.heisenberg import (
    bond_sum,
    check_unit_spins,
    lattice_arguments,
    lattice_name,
)
from liesample.systems.n_vector import UnitVectorLattice
from liesample.targets.cp_model import CPChainReference, check_cp_components
from liesample.targets.cp_ring import CPRingReference

__all__ = ["CPModelSystem", "cp_model", "projector_coordinates"]


def projector_coordinates(z):
    """The real coordinates ``(Re P, Im P)`` of ``P = z z^†`` at every site, shape
    ``(*shape, 2N²)``: their dot product at two sites is ``tr(P_x P_y) = |z_x^† z_y|²``.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> from liesample.systems.cp_model import projector_coordinates
    >>> z = jnp.array([[1.0, 0.0], [0.6, 0.8j]])  # two unit vectors of C²
    >>> p = projector_coordinates(z)
    >>> p.shape, round(float(p[0] @ p[1]), 12)  # |z_0^† z_1|² = 0.36
    ((2, 8), 0.36)
    """
    z = jnp.asarray(z)
    p = z[..., :, None] * jnp.conj(z[..., None, :])
    flat = p.reshape(*p.shape[:-2], -1)
    return jnp.concatenate([jnp.real(flat), jnp.imag(flat)], axis=-1)


@dataclass(frozen=True, eq=False, repr=False)  # the base class's short repr
class CPModelSystem(UnitVectorLattice):
    """A CP(N−1) lattice (:func:`cp_model`): what its samplers read.

    Attributes
    ----------
    name : str
        Human-readable name (``"CP(2) chain 12"``).
    hamiltonian : callable
        ``z ↦ h(z)``, a real scalar, for ``z`` of shape ``event_shape``.
    default_position : ndarray
        Every site ``z_x = e_1`` (complex).
    params : dict
        ``shape``, ``N``, ``coupling``, ``periodic``.
    reference : callable
        ``(beta, position=None) ↦`` the exact law of a chain: the
        :class:`~liesample.targets.cp_model.CPChainReference` of an open chain, the
        :class:`~liesample.targets.cp_ring.CPRingReference` of a periodic one (a ring, for
        its energy: ``bond_mean``, ``bond_energy_mean``, ``energy_mean``,
        ``energy_variance``; its bonds are correlated, so it has no ``bond_variance``); else
        ``None``.
    component_names : tuple of str
        ``("z_1", …, "z_N")``.
    event_shape : tuple of int
        ``(*shape, N)``.
    check_beta : None
        Every finite ``β`` gives a normalisable law (the state space is compact).

    Examples
    --------
    >>> from liesample.systems import cp_model
    >>> system = cp_model((3, 3), N=3, periodic=True)
    >>> system, system.n, system.event_shape
    (CPModelSystem('CP(2) square lattice 3x3'), 3, (3, 3, 3))
    >>> system.check_position(system.default_position)  # unit vectors: no error
    """

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        """Reject a state of the wrong shape, non-numeric, non-finite, or with a ``z_x`` off the
        unit sphere of ``Cᴺ`` (naming the first bad site)."""
        shape = tuple(np.shape(position))
        if shape != self.event_shape:
            raise ValueError(
                f"{name} must have shape {self.event_shape} for the {self.name} (one unit "
                f"vector of C^{self.n} per site), got {shape}"
            )
        dtype = np.dtype(getattr(position, "dtype", None) or np.asarray(position).dtype)
        if dtype.kind not in "iufc":
            raise TypeError(
                f"{name} must be a complex (or real) numeric array of unit vectors z_x, got "
                f"dtype {dtype}; pass np.asarray(position, dtype=complex)"
            )
        value = concrete_array(position)
        if value is not None and not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite; it holds NaN or inf entries")
        if value is not None:
            check_unit_spins(np.abs(np.asarray(value)), name)  # |z_x| from the moduli


def cp_model(
    shape: int | Sequence[int], N: int, coupling: float = 1.0, periodic: bool = False
) -> CPModelSystem:
    """The CP(N−1) model on a hypercubic lattice of any dimension (module docstring).

    Parameters
    ----------
    shape : tuple of positive ints
        One extent per lattice axis: ``(L,)`` for a chain, ``(L1, L2)`` for a square lattice, …
    N : int
        Complex components of ``z``, ``≥ 2``: ``N = 2`` is CP¹ = S² (the O(3) model of coupling
        ``J/2``, through the Hopf map), ``N = 3`` is CP², and so on.
    coupling : float
        ``J`` (finite) in ``h = −J Σ_⟨xy⟩ |z_x^† z_y|²``: ``J > 0`` aligns neighbouring rays.
    periodic : bool
        Periodic boundaries along every axis (each extent then ``≥ 3``); ``False`` (the default,
        as for :func:`~liesample.systems.n_vector.n_vector`): open boundaries.

    Returns
    -------
    CPModelSystem
        State shape ``(*shape, N)``, complex, unit vectors checked at ``init``, default position
        ``z_x = e_1`` everywhere; equal to every system built from equal arguments. Its
        ``reference(beta)`` is the exact :class:`~liesample.targets.cp_model.CPChainReference`
        of an open chain, the :class:`~liesample.targets.cp_ring.CPRingReference` of a
        periodic one (its energy: the bond mean, the energy's mean and variance), else
        ``None``.

    Which samplers apply: :func:`liesample.cp_heat_bath` (exact heat bath of the local complex
    Bingham law, with over-relaxation), which :func:`liesample.recommended_sampler` returns.
    The state is ``z``, not the orbit point ``P``, so the Lie–Poisson orbit samplers do not take
    this system.

    Examples
    --------
    >>> from liesample.systems import cp_model
    >>> system = cp_model((4,), N=3)
    >>> system.event_shape, float(system.hamiltonian(system.default_position))  # −J per bond
    ((4, 3), -3.0)
    >>> bool(1 / 3 < system.reference(1.0).bond_mean() < 1)
    True
    """
    return _cp_model(shape, check_cp_components(N), coupling, periodic)


@by_value
def _cp_model(shape, n: int, coupling, periodic) -> CPModelSystem:
    """The :class:`CPModelSystem` of :func:`cp_model` (arguments as there, ``N`` checked)."""
    shape, coupling, periodic = lattice_arguments(shape, coupling, periodic)

    def hamiltonian(z):
        return -coupling * bond_sum(projector_coordinates(z), periodic)

    exact_chain = len(shape) == 1

    def reference(beta, position=None):
        del position  # one law for every start
        if not exact_chain:
            return None
        law = CPRingReference if periodic else CPChainReference
        return law(length=shape[0], n=n, beta=float(beta), coupling=coupling)

    default_position = np.zeros((*shape, n), dtype=complex)
    default_position[..., 0] = 1.0
    return CPModelSystem(
        name=f"CP({n - 1}) {lattice_name(shape)}",
        hamiltonian=hamiltonian,
        default_position=default_position,
        params={"shape": shape, "N": n, "coupling": coupling, "periodic": periodic},
        reference=reference,
        component_names=tuple(f"z_{i + 1}" for i in range(n)),
    )
