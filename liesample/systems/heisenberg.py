"""Classical Heisenberg spin lattices: the stochastic Landau–Lifshitz–Gilbert equation.

The state is a stack of unit spins ``s`` of shape ``(*shape, 3)`` on the product
``(so(3)*)^N`` (``so3`` acts copy by copy), ``N = prod(shape)``: ``shape = (N,)`` is a chain,
``shape = (L₁, L₂)`` a square lattice, ``(L₁, L₂, L₃)`` a simple cubic one, and so on in any
dimension (the hypercubic lattice ``Z^d``, each site with ``2d`` neighbours). The Hamiltonian
(classical Heisenberg model) is

    h(s) = −J Σ_⟨jk⟩ s_j·s_k  −  B·Σ_k s_k  −  D Σ_k (s_k·e_z)²

over nearest-neighbour bonds, with open or periodic boundaries (easy axis ``e_z`` for
``D > 0``), and the unit-strength noise Hamiltonians are the ``3N`` spin components
``ĥ_{k,i} = e_i·s_k`` (returned flat, index ``3k + i`` with ``k`` the C-order site index). With
``θ = βσ²/2`` the engine then produces, per spin,

    ds_k = s_k×∇_k h dt + θ s_k×(s_k×∇_k h) dt + σ Σ_i s_k×e_i ∘ dW_{k,i},

the stochastic Landau–Lifshitz–Gilbert equation, whose invariant law on the orbit
``|s_k| = 1`` is the classical Heisenberg Gibbs law ``∝ exp(−βh)``.

The splitting integrator moves commuting groups of noise directions at once
(``LiePoissonSystem.noise_groups``): one spin axis on one colour class of a proper
colouring of the lattice (:func:`noise_groups`), 6 groups per step on a bipartite lattice
instead of ``3N`` single directions.

Each spin must be a unit vector: the system's ``check_position`` (which the sampler's
``init`` calls) adds that check to the base class's shape/finiteness checks; the default
position has every spin along ``e_z``.

The lattice code here (shapes, bond and neighbour sums, neighbour tables, colourings) serves
every O(n) lattice: :func:`liesample.systems.n_vector` builds its ``n ≠ 3`` systems from it, and
for ``n = 3`` returns :func:`heisenberg` itself (the model without anisotropy).
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.precision import check_dtype, float64_hint, roundoff_tolerance
from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry.algebras import so3
from liesample.geometry.flat_and_round import Sphere
from liesample.targets.spins import HeisenbergChainReference, HeisenbergRingReference

__all__ = [
    "SphereLattice",
    "SpinLatticeSystem",
    "bond_sum",
    "check_unit_spins",
    "colouring",
    "exchange_energy",
    "heisenberg",
    "lattice_arguments",
    "lattice_field",
    "lattice_name",
    "lattice_shape",
    "neighbour_sum",
    "neighbour_table",
    "noise_groups",
]

UNIT_NORM_TOLERANCE = 1e-9
"""How far ``|s_k|`` may be from 1 in a float64 initial state (in float32, the round-off of the
start's dtype: :func:`liesample.foundation.precision.roundoff_tolerance`)."""


class SphereLattice:
    """What a lattice of unit spins offers the ``T*G`` samplers (``geometric_hmc``,
    ``geometric_langevin``): the product of spheres its states live on and ``log π = −βh``.

    A mixin of :class:`SpinLatticeSystem` and :class:`liesample.systems.n_vector.NVectorSystem`;
    it reads ``hamiltonian`` and ``default_position`` (``(*shape, n)``) of the system.
    """

    hamiltonian: Any
    default_position: Any

    @property
    def space(self) -> Sphere:
        """``(S^{n−1})^N``: one sphere per site, the lattice's shape as the space's batch shape."""
        *shape, n = np.shape(self.default_position)
        return Sphere(n - 1, shape=tuple(shape))

    def logdensity(self, beta: float) -> Callable[[jax.Array], jax.Array]:
        """``s ↦ −β h(s)``: the ``log π`` (uniform measure on the spheres) of a ``T*G`` sampler
        on :attr:`space`; ``β`` any finite real (the spheres are compact)."""
        beta = finite_float("beta", beta)
        hamiltonian = self.hamiltonian
        return lambda spins: -beta * hamiltonian(spins)


class SpinLatticeSystem(SphereLattice, LiePoissonSystem):
    """A :class:`LiePoissonSystem` whose states are stacks of *unit* spins.

    ``check_position`` differs from the base class: after its checks (shape, finite,
    non-degenerate orbit) every spin must satisfy ``| |s_k| − 1 | ≤ 1e-9`` (in float32, 1000 units
    of float32 round-off); a ``ValueError`` names the first offending site. ``space`` and
    ``logdensity(beta)`` give the ``T*G`` samplers the product of spheres (:class:`SphereLattice`).
    """

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        super().check_position(position, name)
        check_unit_spins(position, name)


def check_unit_spins(position: ArrayLike, name: str = "position") -> None:
    """Raise ``ValueError`` unless every spin (last axis) of a concrete ``position`` is a unit
    vector to ``UNIT_NORM_TOLERANCE`` (float32: its round-off), naming the first bad site; a
    traced ``position`` passes (value checks happen outside ``jit``)."""
    value = concrete_array(position)
    if value is None:  # traced: value checks happen outside jit
        return
    dtype = check_dtype(value)
    tolerance = roundoff_tolerance(dtype, floor=UNIT_NORM_TOLERANCE)
    norms = np.linalg.norm(np.asarray(value, dtype=float), axis=-1)
    bad = np.abs(norms - 1.0) > tolerance
    if np.any(bad):
        site = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{name} must hold unit spins (|s_k| = 1 to {tolerance:.2g}); the spin at "
            f"site {site} has norm {float(norms[site]):.12g} "
            f"({int(np.sum(bad))} bad spin(s) in all)." + float64_hint(dtype)
        )


def lattice_shape(shape: int | Sequence[int]) -> tuple[int, ...]:
    """``shape`` as a non-empty tuple of positive ints (one per lattice axis), or a
    ``TypeError``/``ValueError``."""
    if not isinstance(shape, (tuple, list)):
        raise TypeError(
            f"shape must be a tuple of positive ints, one per lattice axis: (N,) for a chain, "
            f"(L1, L2) for a square lattice, (L1, L2, L3) for a cubic one; got {shape!r}"
        )
    if len(shape) == 0:
        raise ValueError(
            f"shape must have at least one entry (one per lattice axis, e.g. (8,) or (8, 8, 8)), "
            f"got {shape!r}"
        )
    out = []
    for extent in shape:
        if isinstance(extent, (bool, np.bool_)):
            raise TypeError(f"shape entries must be positive ints, got {shape!r}")
        try:
            value = operator.index(extent)
        except TypeError:
            raise TypeError(f"shape entries must be positive ints, got {shape!r}") from None
        if value < 1:
            raise ValueError(f"shape entries must be positive ints, got {shape!r}")
        out.append(value)
    return tuple(out)


def lattice_field(field, n: int = 3) -> np.ndarray:
    """``field`` as an array of ``n`` finite floats (one per spin component), or a
    ``ValueError`` naming ``field``."""
    if np.ndim(field) != 1 or len(field) != n:
        what = "(B_x, B_y, B_z)" if n == 3 else "(one per spin component)"
        raise ValueError(f"field must be a sequence of {n} finite floats {what}, got {field!r}")
    return np.array([finite_float(f"field[{i}]", b) for i, b in enumerate(field)])


def lattice_arguments(shape, coupling, periodic) -> tuple[tuple[int, ...], float, bool]:
    """``(shape, coupling, periodic)`` of a spin lattice, checked: :func:`lattice_shape`, a
    finite ``coupling`` and a bool ``periodic`` (every extent then ``≥ 3``)."""
    shape = lattice_shape(shape)
    coupling = finite_float("coupling", coupling)
    if not isinstance(periodic, (bool, np.bool_)):
        raise TypeError(f"periodic must be a bool, got {periodic!r}")
    periodic = bool(periodic)
    if periodic and min(shape) < 3:
        raise ValueError(
            f"periodic boundaries need every extent of shape to be >= 3 (a bond would join a site "
            f"to itself or be counted twice); got shape {shape}"
        )
    return shape, coupling, periodic


def lattice_name(shape: Sequence[int]) -> str:
    """``"chain 8"``, ``"square lattice 4x4"``, ``"cubic lattice 4x4x4"``, ``"4-d lattice …"``."""
    geometry = {1: "chain", 2: "square lattice", 3: "cubic lattice"}.get(
        len(shape), f"{len(shape)}-d lattice"
    )
    return f"{geometry} {'x'.join(map(str, shape))}"


def exchange_energy(s, coupling: float, periodic: bool, field: np.ndarray | None):
    """``−J Σ_⟨jk⟩ s_j·s_k − B·Σ_k s_k`` of spins ``s`` (``(*shape, n)``, any ``n``); ``field``
    ``None`` (or all zero) leaves the Zeeman term out."""
    h = -coupling * bond_sum(s, periodic)
    if field is not None and bool(np.any(field != 0.0)):
        h = h - jnp.sum(s * field)
    return h


def bond_sum(s, periodic: bool):
    """``Σ_⟨jk⟩ s_j·s_k`` over nearest-neighbour bonds along every lattice axis (no loops)."""
    total = jnp.zeros((), s.dtype)
    for axis in range(s.ndim - 1):  # lattice axes only
        if periodic:
            total = total + jnp.sum(s * jnp.roll(s, -1, axis=axis))
        else:
            n = s.shape[axis]
            head = jax.lax.slice_in_dim(s, 0, n - 1, axis=axis)
            tail = jax.lax.slice_in_dim(s, 1, n, axis=axis)
            total = total + jnp.sum(head * tail)
    return total


def neighbour_sum(s: jax.Array, periodic: bool) -> jax.Array:
    """``Σ_{j ~ k} s_j`` for every site ``k`` (shape of ``s``): the exchange field over ``J``."""
    total = jnp.zeros_like(s)
    for axis in range(s.ndim - 1):
        if periodic:
            total = total + jnp.roll(s, 1, axis=axis) + jnp.roll(s, -1, axis=axis)
        else:
            pad = [(0, 0)] * s.ndim
            pad[axis] = (1, 1)
            padded = jnp.pad(s, pad)
            n = s.shape[axis]
            total = (
                total
                + jax.lax.slice_in_dim(padded, 0, n, axis=axis)
                + jax.lax.slice_in_dim(padded, 2, n + 2, axis=axis)
            )
    return total


def neighbour_table(shape: Sequence[int], periodic: bool) -> np.ndarray:
    """``(N, 2·dim)`` flat indices of each site's neighbours, ``N`` where there is none."""
    num_sites = math.prod(shape)
    index = np.arange(num_sites).reshape(shape)
    columns = []
    for axis, n in enumerate(shape):
        for shift in (1, -1):
            rolled = np.roll(index, shift, axis=axis)
            if not periodic:
                edge: list[slice | int] = [slice(None)] * len(shape)
                edge[axis] = 0 if shift == 1 else n - 1
                rolled[tuple(edge)] = num_sites
            columns.append(rolled.reshape(-1))
    return np.stack(columns, axis=1)


def colouring(shape: Sequence[int], periodic: bool) -> tuple[np.ndarray, int]:
    """A proper colouring of the lattice: ``(colours of shape `shape`, number of colours)``.

    Axis colourings ``c_a(i) = i mod 2`` (path or even cycle) or, on an odd cycle, the same with
    the last site coloured 2; their sum modulo ``k = max χ_a`` colours the Cartesian product
    properly, because neighbours differ in exactly one coordinate.
    """
    odd_cycle = periodic and any(n % 2 for n in shape)
    k = 3 if odd_cycle else 2
    total = np.zeros(shape, dtype=np.int64)
    for axis, n in enumerate(shape):
        c = np.arange(n) % 2
        if periodic and n % 2:
            c[-1] = 2
        index: list[slice | None] = [None] * len(shape)
        index[axis] = slice(None)
        total = total + c[tuple(index)]
    return total % k, k


def noise_groups(shape: Sequence[int], periodic: bool) -> np.ndarray:
    """Commuting groups of the ``3N`` noise directions, for the splitting integrator.

    Direction ``(k, i)`` (flat index ``3k + i``) gets label ``3·colour(k) + i``: one group is
    one spin axis on one colour class of :func:`colouring`. Its directions act on different,
    non-neighbouring spins, so their vector fields commute and none changes another's
    coefficient ``{h, ĥ_{k,i}}`` (which depends on ``s_k`` and its neighbours only): the group
    moves as one piece, ``3 × colours`` (6 or 9) pieces per step instead of ``3N``.
    """
    colours, _ = colouring(shape, periodic)
    return (3 * colours.reshape(-1, 1) + np.arange(3)).reshape(-1)


@by_value
def heisenberg(
    shape: int | Sequence[int],
    coupling: float = 1.0,
    periodic: bool = False,
    field: Sequence[float] = (0.0, 0.0, 0.0),
    anisotropy: float = 0.0,
) -> SpinLatticeSystem:
    """The classical Heisenberg model on a hypercubic lattice of any dimension.

    Parameters
    ----------
    shape : tuple of positive ints
        One extent per lattice axis: ``(N,)`` for a chain of ``N`` spins, ``(L1, L2)`` for a
        square lattice, ``(L1, L2, L3)`` for a simple cubic one, and so on.
    coupling : float
        Exchange ``J`` (finite): ``J > 0`` ferromagnetic, ``J < 0`` antiferromagnetic.
    periodic : bool
        Periodic boundaries along every axis (each extent must then be ≥ 3, so that every bond
        joins two distinct sites once); ``False``: open boundaries.
    field : sequence of 3 floats
        Uniform external field ``B`` (Zeeman term ``−B·Σ s_k``).
    anisotropy : float
        ``D`` in ``−D Σ (s_k·e_z)²``: easy axis ``e_z`` for ``D > 0``, easy plane for ``D < 0``.

    Returns
    -------
    SpinLatticeSystem
        A :class:`LiePoissonSystem` on ``(so(3)*)^N`` with state shape ``(*shape, 3)``, ``3N``
        noise Hamiltonians ``e_i·s_k`` (grouped by :func:`noise_groups`), unit spins checked at
        ``init`` and default position all spins along ``e_z``. ``reference(beta)`` is the exact
        :class:`HeisenbergChainReference` for an open chain with ``B = 0``, ``D = 0``,
        :class:`HeisenbergRingReference` for a periodic one, else ``None``.

    Examples
    --------
    A ferromagnetic open chain of four spins, all up, and its exact reference (Fisher):

    >>> from liesample.systems import heisenberg
    >>> system = heisenberg((4,), coupling=1.0)
    >>> system.event_shape, float(system.hamiltonian(system.default_position))  # −J per bond
    ((4, 3), -3.0)
    >>> bool(0 < system.reference(1.0).correlation(1) < 1)
    True
    """
    shape, coupling, periodic = lattice_arguments(shape, coupling, periodic)
    field = lattice_field(field)
    anisotropy = finite_float("anisotropy", anisotropy)
    has_field = bool(np.any(field != 0.0))

    def hamiltonian(s):
        h = exchange_energy(s, coupling, periodic, field)
        if anisotropy != 0.0:
            h = h - anisotropy * jnp.sum(s[..., 2] ** 2)
        return h

    exact_chain = len(shape) == 1 and not has_field and anisotropy == 0.0

    def reference(beta, position=None):
        del position  # the law does not depend on the (unit-spin) orbit
        if not exact_chain:
            return None
        law = HeisenbergRingReference if periodic else HeisenbergChainReference
        return law(length=shape[0], beta=float(beta), coupling=coupling)

    default_position = np.zeros((*shape, 3))
    default_position[..., 2] = 1.0
    return SpinLatticeSystem(
        name=f"Heisenberg {lattice_name(shape)}",
        algebra=so3,
        hamiltonian=hamiltonian,
        default_position=default_position,  # noise ĥ_{k,i} = e_i·s_k, index 3k + i
        reference=reference,
        noise_reach="orbit",  # three linear noises per spin span every sphere
        component_names=("s_x", "s_y", "s_z"),
        params={
            "shape": shape,
            "coupling": coupling,
            "periodic": periodic,
            "field": tuple(float(b) for b in field),
            "anisotropy": anisotropy,
        },
        noise_groups=noise_groups(shape, periodic),
    )
