"""O(n) spin lattices (the n-vector model): unit vectors in Rⁿ on chains and hypercubic
lattices, with the Heisenberg model as the case ``n = 3``.

The state is a stack of unit spins ``s`` of shape ``(*shape, n)`` (``n ≥ 2``: ``n = 2`` is the
XY or plane-rotator model, ``n = 3`` the classical Heisenberg model, ``n = 4`` the O(4) model of
the chiral transition), ``N = prod(shape)`` sites, and

    h(s) = −J Σ_⟨xy⟩ s_x·s_y  −  h·Σ_x s_x

over nearest-neighbour bonds (open or periodic boundaries), with Gibbs law ``∝ exp(−βh)`` on
the product of spheres ``(S^{n−1})^N``. The lattice, its neighbour sums and its colourings are
those of :mod:`liesample.systems.heisenberg` (one lattice code path for every ``n``).

For ``n = 3`` :func:`n_vector` returns :func:`~liesample.systems.heisenberg.heisenberg`'s system
itself (a :class:`~liesample.systems.heisenberg.SpinLatticeSystem` on ``(so(3)*)^N``, equal to
``heisenberg(...)`` built from the same arguments), so the Lie–Poisson orbit samplers apply to
it as well. For ``n ≠ 3`` the sphere ``S^{n−1}`` is no coadjoint orbit (``S²`` is the only
sphere that carries a symplectic form), and the system is an :class:`NVectorSystem`, sampled by
the exact spin samplers only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.identity import ValueIdentity, by_value
from liesample.foundation.validation import concrete_array
from liesample.systems.heisenberg import (
    SphereLattice,
    SpinLatticeSystem,
    check_unit_spins,
    exchange_energy,
    heisenberg,
    lattice_arguments,
    lattice_field,
    lattice_name,
)
from liesample.targets.n_vector import NVectorChainReference, check_spin_components
from liesample.targets.n_vector_ring import NVectorRingReference

__all__ = ["NVectorSystem", "UnitVectorLattice", "n_vector"]


@dataclass(frozen=True, eq=False)
class UnitVectorLattice(ValueIdentity):
    """What the exact spin samplers read of a lattice of unit vectors that is no Lie–Poisson
    system (:class:`NVectorSystem`, :class:`liesample.systems.cp_model.CPModelSystem`): its
    name, ``h``, a start, its parameters, its exact reference and the shape of a state; equal
    by value (:mod:`liesample.foundation.identity`). The subclasses document the fields and
    check a position."""

    name: str
    hamiltonian: Callable
    default_position: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)
    reference: Callable | None = None
    component_names: tuple[str, ...] = ()
    event_shape: tuple[int, ...] = None  # type: ignore[assignment]
    check_beta: None = None

    def __post_init__(self):
        if self.event_shape is None:
            object.__setattr__(self, "event_shape", tuple(np.shape(self.default_position)))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"

    @property
    def n(self) -> int:
        """Components of the vector at a site (the last axis of a state)."""
        return self.event_shape[-1]


@dataclass(frozen=True, eq=False, repr=False)  # the base class's short repr
class NVectorSystem(SphereLattice, UnitVectorLattice):
    """An O(n) spin lattice for ``n ≠ 3`` (:func:`n_vector`): what the spin samplers read.

    Attributes
    ----------
    name : str
        Human-readable name (``"O(2) chain 16"``).
    hamiltonian : callable
        ``s ↦ h(s)``, a scalar, for spins of shape ``event_shape``.
    default_position : ndarray
        Every spin along the last axis ``e_n``.
    params : dict
        ``shape``, ``n``, ``coupling``, ``periodic``, ``field`` (a tuple of ``n`` floats) and
        ``anisotropy`` (always 0: the exact samplers' shared bookkeeping).
    reference : callable
        ``(beta, position=None) ↦`` the exact law of a chain without field: the
        :class:`~liesample.targets.n_vector.NVectorChainReference` of an open chain, the
        :class:`~liesample.targets.n_vector_ring.NVectorRingReference` of a periodic one (a
        ring); else ``None``.
    component_names : tuple of str
        ``("s_1", …, "s_n")``.
    event_shape : tuple of int
        ``(*shape, n)``.
    check_beta : None
        Every finite ``β`` gives a normalisable law (the state space is compact).

    ``space`` (the product of spheres ``(S^{n−1})^N``) and ``logdensity(beta)`` (``−βh``) let
    the ``T*G`` samplers move the spins (:class:`~liesample.systems.heisenberg.SphereLattice`).

    Examples
    --------
    >>> from liesample.systems import n_vector
    >>> system = n_vector((3, 3), n=4, periodic=True)
    >>> system, system.n, system.event_shape
    (NVectorSystem('O(4) square lattice 3x3'), 4, (3, 3, 4))
    >>> system.check_position(system.default_position)  # unit spins: no error
    """

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        """Reject a state of the wrong shape, non-finite, or with a spin off the unit sphere
        (naming the first bad site)."""
        shape = tuple(np.shape(position))
        if shape != self.event_shape:
            raise ValueError(
                f"{name} must have shape {self.event_shape} for the {self.name} (one unit "
                f"{self.n}-vector per site), got {shape}"
            )
        value = concrete_array(position)
        if value is not None and not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite; it holds NaN or inf spins")
        check_unit_spins(position, name)


def n_vector(
    shape: int | Sequence[int],
    n: int,
    coupling: float = 1.0,
    periodic: bool = False,
    field: Sequence[float] | None = None,
) -> SpinLatticeSystem | NVectorSystem:
    """The O(n) model (n-vector model) on a hypercubic lattice of any dimension.

    Parameters
    ----------
    shape : tuple of positive ints
        One extent per lattice axis: ``(N,)`` for a chain of ``N`` spins, ``(L1, L2)`` for a
        square lattice, ``(L1, L2, L3)`` for a simple cubic one, and so on.
    n : int
        Components of a spin, ``≥ 2``: 2 (XY), 3 (Heisenberg), 4 (O(4)), ….
    coupling : float
        Exchange ``J`` (finite): ``J > 0`` ferromagnetic, ``J < 0`` antiferromagnetic.
    periodic : bool
        Periodic boundaries along every axis (each extent must then be ≥ 3); ``False`` (the
        default, as for :func:`~liesample.systems.heisenberg.heisenberg`): open boundaries.
    field : sequence of n floats, optional
        Uniform external field ``h`` (Zeeman term ``−h·Σ s_x``); ``None``: no field.

    Returns
    -------
    SpinLatticeSystem or NVectorSystem
        State shape ``(*shape, n)``, unit spins checked at ``init``, default position every
        spin along the last axis. For ``n = 3``: ``heisenberg(shape, coupling, periodic,
        field)`` itself (equal to it, so the two share every compiled program). For ``n ≠ 3``
        an :class:`NVectorSystem`, equal to every system built from equal arguments; its
        ``reference(beta)`` is the exact law of a chain without field, the
        :class:`~liesample.targets.n_vector.NVectorChainReference` of an open chain or the
        :class:`~liesample.targets.n_vector_ring.NVectorRingReference` of a periodic one,
        else ``None`` (``n = 3``: :func:`~liesample.systems.heisenberg.heisenberg`'s
        references, the same laws).

    Which samplers apply (every ``n``): :func:`liesample.heisenberg_heat_bath` (exact von
    Mises–Fisher heat bath on ``S^{n−1}``, with over-relaxation ``s ↦ 2(s·F̂)F̂ − s``; for
    ``n ≠ 3`` its ``precession_angle`` must be ``π``, as a rotation "about" the local field is
    defined only on ``S²``), :func:`liesample.heisenberg_metropolis`, and, for the ferromagnet
    without field, the cluster moves :func:`liesample.heisenberg_cluster` (Swendsen–Wang) and
    :func:`liesample.heisenberg_wolff` (Wolff's embedding, valid for every ``n``);
    :func:`liesample.recommended_sampler` picks one. The Lie–Poisson orbit samplers
    (:func:`liesample.lie_poisson_langevin`, :func:`liesample.adjusted_lie_poisson`) apply for
    ``n = 3`` only.

    Examples
    --------
    An open XY chain of four spins, all aligned, and its exact bond correlation:

    >>> from liesample.systems import heisenberg, n_vector
    >>> system = n_vector((4,), n=2)
    >>> system.event_shape, float(system.hamiltonian(system.default_position))  # −J per bond
    ((4, 2), -3.0)
    >>> bool(0 < system.reference(1.0).correlation(1) < 1)
    True
    >>> n_vector((4,), n=3) == heisenberg((4,))  # the Heisenberg chain
    True
    """
    n = check_spin_components(n)
    if n == 3:
        return heisenberg(shape, coupling, periodic, (0.0, 0.0, 0.0) if field is None else field)
    return _n_vector(shape, n, coupling, periodic, field)


@by_value
def _n_vector(shape, n: int, coupling, periodic, field) -> NVectorSystem:
    """The :class:`NVectorSystem` of :func:`n_vector` for ``n ≠ 3`` (arguments as there)."""
    shape, coupling, periodic = lattice_arguments(shape, coupling, periodic)
    field = np.zeros(n) if field is None else lattice_field(field, n)
    has_field = bool(np.any(field != 0.0))

    def hamiltonian(s):
        return exchange_energy(s, coupling, periodic, field)

    exact_chain = len(shape) == 1 and not has_field

    def reference(beta, position=None):
        del position  # one law for every unit-spin start
        if not exact_chain:
            return None
        law = NVectorRingReference if periodic else NVectorChainReference
        return law(length=shape[0], n=n, beta=float(beta), coupling=coupling)

    default_position = np.zeros((*shape, n))
    default_position[..., -1] = 1.0
    return NVectorSystem(
        name=f"O({n}) {lattice_name(shape)}",
        hamiltonian=hamiltonian,
        default_position=default_position,
        params={
            "shape": shape,
            "n": n,
            "coupling": coupling,
            "periodic": periodic,
            "field": tuple(float(b) for b in field),
            "anisotropy": 0.0,
        },
        reference=reference,
        component_names=tuple(f"s_{i + 1}" for i in range(n)),
    )
