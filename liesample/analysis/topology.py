"""The topological charge of 2-D O(3) spin configurations (Berg and Lüscher's geometric
definition) and the topological susceptibility.

A periodic ``L₁ × L₂`` configuration of unit spins (the positions of
``liesample.systems.heisenberg((L1, L2), periodic=True)``, shape ``(L1, L2, 3)``) is a map of
the torus to the sphere ``S²``. Berg and Lüscher (Nucl. Phys. B 190 (1981) 412) make it a
continuous map, and its degree the charge, by cutting each plaquette
``x, x+ê₁, x+ê₁+ê₂, x+ê₂`` along its diagonal into the two triangles
``(x, x+ê₁, x+ê₁+ê₂)`` and ``(x, x+ê₁+ê₂, x+ê₂)``, both counter-clockwise in the ``(ê₁, ê₂)``
plane, and mapping each onto the geodesic triangle of its three spins ``s₁, s₂, s₃``. The
signed area ``σ`` of that spherical triangle is given by

    exp(iσ/2) = z / |z|,   z = 1 + s₁·s₂ + s₂·s₃ + s₃·s₁ + i s₁·(s₂ × s₃),   σ ∈ (−2π, 2π),

so ``σ = 2 atan2(Im z, Re z)``, and the charge is ``Q = (1/4π) Σ σ`` over all ``2 L₁ L₂``
triangles.

Why this is the area. With a unit quaternion for each rotation, the rotation that carries a unit
vector ``u`` to ``v`` along the shorter great circle is ``q(u, v) ∝ (1 + u·v) + u × v``
(its axis ``u × v``, its angle that between ``u`` and ``v``). Composing the three edges,
``q(s₃, s₁) q(s₂, s₃) q(s₁, s₂) = 2 (Re z + Im z · s₁)``, a quaternion that fixes ``s₁``: the
rotation about ``s₁`` by ``2 arg z``. It is the holonomy of parallel transport around the
geodesic triangle, which on the unit sphere (Gauss–Bonnet, curvature 1) is the rotation by its
enclosed signed area; the quaternion fixes that angle modulo ``4π``, and the branch
``2 arg z ∈ (−2π, 2π)`` is the one that is ``0`` for a degenerate triangle (``z = 4``) and
continuous as long as ``z`` stays off the closed negative real axis. Adjacent triangles share
their edges' geodesics, so the geodesic triangles form a continuous map of the torus to ``S²``
whose areas add up to ``4π`` times its degree: ``Q`` is an integer for every configuration,
up to round-off, and ``|z|² = 2 (1 + s₁·s₂)(1 + s₂·s₃)(1 + s₃·s₁)``.

**Exceptional configurations.** The construction fails where some triangle has ``z`` on the
closed negative real axis: two of its spins antipodal (``z = 0``: the geodesic between them is
not unique), or its three spins on one great circle and not within a half circle (``z < 0``:
the triangle is a hemisphere, ``σ = ±2π`` undecided). Such configurations have measure zero.
There :func:`topological_charge` and :func:`topological_charge_density` return ``NaN`` (for
each batch entry, or plaquette, that holds such a triangle), and not a value that could be a
half-integer: a triangle counts as exceptional where ``z`` lies within ``1000 ε`` of that axis
(``ε`` the round-off of the spins' dtype). A configuration in a plane (every spin on one great
circle, e.g. an XY vortex) is exceptional as soon as one triangle winds around it.

Charge 1 is the orientation of the continuum density ``q = s·(∂₁s × ∂₂s)/4π``: a
counter-clockwise triangle whose spins turn counter-clockwise about their mean has ``σ > 0``.
The charge depends on the triangulation only on rough configurations (where the diagonal chosen
matters); it is invariant under rotations of every spin and under lattice translations, and
changes sign under a reflection of every spin (an orthogonal map of determinant −1).

As an observable of a run, ``liesample.sample(sampler, key, starts, n,
observables={"Q": topological_charge})`` records ``Q`` at every draw (one chain's position is
``(L1, L2, 3)``); :func:`topological_susceptibility` then gives ``χ_t = ⟨Q²⟩ / V`` with its
jackknife error.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.analysis.correlated_errors import JackknifeResult, jackknife
from liesample.foundation.precision import check_dtype, float64_hint, roundoff_tolerance
from liesample.foundation.validation import concrete_array

__all__ = [
    "cp_topological_charge",
    "topological_charge",
    "topological_charge_density",
    "topological_susceptibility",
]

UNIT_NORM_TOLERANCE = 1e-9
"""How far ``|s|`` may be from 1 in a float64 configuration (in float32, the round-off of its
dtype: :func:`liesample.foundation.precision.roundoff_tolerance`), as for the spin systems."""

EXCEPTIONAL_ULPS = 1000
"""A triangle is exceptional where ``z`` lies within ``EXCEPTIONAL_ULPS · ε`` of the closed
negative real axis (``ε`` the round-off unit of the spins' dtype)."""


def _check_spins(spins: ArrayLike, name: str = "spins") -> jax.Array:
    """``spins`` as a real array ``(..., L1, L2, 3)`` of unit vectors (the value checked only
    when it is concrete), or an error naming ``name``, what is allowed and how to fix it."""
    shape = np.shape(spins)
    if len(shape) < 3:
        raise ValueError(
            f"{name} must be a 2-D lattice of 3-vectors, shape (L1, L2, 3) (with any leading "
            f"batch axes: (..., L1, L2, 3)), got shape {shape}; the positions of "
            "liesample.systems.heisenberg((L1, L2), periodic=True) have that shape"
        )
    if shape[-1] != 3:
        raise ValueError(
            f"{name} must hold O(3) spins: its last axis must have length 3, got shape {shape} "
            "(the geometric charge is defined for unit 3-vectors on a 2-D lattice)"
        )
    if min(shape[-3:-1]) < 2:
        raise ValueError(
            f"{name} must have lattice extents >= 2 (axes -3 and -2 are the lattice (L1, L2)), "
            f"got shape {shape}"
        )
    dtype = jnp.result_type(spins)
    if not jnp.issubdtype(dtype, jnp.floating):
        raise TypeError(f"{name} must be a real floating array (unit 3-vectors), got {dtype}")
    value = concrete_array(spins)
    if value is not None:  # traced: a sampler keeps its spins on the sphere
        _check_unit(value, name)
    return jnp.asarray(spins)


def _check_unit(value: np.ndarray, name: str) -> None:
    dtype = check_dtype(value)
    tolerance = roundoff_tolerance(dtype, floor=UNIT_NORM_TOLERANCE)
    norms = np.linalg.norm(np.asarray(value, dtype=float), axis=-1)
    bad = ~(np.abs(norms - 1.0) <= tolerance)  # NaN is bad too
    if np.any(bad):
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{name} must hold unit vectors (|s| = 1 to {tolerance:.2g}); the spin at index "
            f"{where} has norm {float(norms[where]):.12g} ({int(np.sum(bad))} bad spin(s) in "
            "all); normalise them: spins / numpy.linalg.norm(spins, axis=-1, keepdims=True)"
            + float64_hint(dtype)
        )


def _triangle_areas(s1: jax.Array, s2: jax.Array, s3: jax.Array) -> jax.Array:
    """The signed area ``σ = 2 arg z`` of each geodesic triangle ``(s₁, s₂, s₃)`` (last axis the
    vector), ``NaN`` where the triangle is exceptional (module docstring)."""
    dot = lambda a, b: jnp.sum(a * b, axis=-1)
    real = 1.0 + dot(s1, s2) + dot(s2, s3) + dot(s3, s1)
    imag = dot(s1, jnp.cross(s2, s3))
    tolerance = EXCEPTIONAL_ULPS * jnp.finfo(real.dtype).eps
    exceptional = (real <= tolerance) & (jnp.abs(imag) <= tolerance)
    return jnp.where(exceptional, jnp.nan, 2.0 * jnp.arctan2(imag, real))


def topological_charge_density(spins: ArrayLike) -> jax.Array:
    """The charge of each plaquette, ``q(x) = (σ₁(x) + σ₂(x)) / 4π``, shape ``(..., L1, L2)``.

    ``spins`` is a periodic configuration ``(..., L1, L2, 3)`` of unit vectors (any leading
    axes are a batch); plaquette ``x`` has the corners ``x, x+ê₁, x+ê₁+ê₂, x+ê₂`` (indices
    modulo ``L``) and the two triangles of :mod:`liesample.analysis.topology`. Each value lies in
    ``(−1, 1)`` and they add up to the integer :func:`topological_charge`; ``NaN`` on a
    plaquette with an exceptional triangle. Pure JAX (jit, vmap, grad-free): the unit-vector
    check runs on concrete input only.

    Examples
    --------
    >>> from liesample.analysis.topology import topological_charge_density
    >>> cold = liesample.systems.heisenberg((4, 4), periodic=True).default_position
    >>> topological_charge_density(cold).shape, float(topological_charge_density(cold).sum())
    ((4, 4), 0.0)
    """
    s = _check_spins(spins)
    right = jnp.roll(s, -1, axis=-3)  # s(x + ê₁)
    up = jnp.roll(s, -1, axis=-2)  # s(x + ê₂)
    diagonal = jnp.roll(right, -1, axis=-2)  # s(x + ê₁ + ê₂)
    areas = _triangle_areas(s, right, diagonal) + _triangle_areas(s, diagonal, up)
    return areas / (4.0 * math.pi)


def topological_charge(spins: ArrayLike) -> jax.Array:
    """The geometric topological charge ``Q`` of a periodic 2-D O(3) configuration.

    Parameters
    ----------
    spins : array_like, shape (..., L1, L2, 3)
        Unit spins on a periodic ``L1 × L2`` lattice (``L ≥ 2``), e.g. a position of
        ``liesample.systems.heisenberg((L1, L2), periodic=True)``; leading axes are a batch
        (chains, draws). Real floating; checked for unit length when concrete.

    Returns
    -------
    jax.Array, shape (...)
        ``Q = (1/4π) Σ σ`` over the ``2 L1 L2`` triangles (module docstring): an integer up to
        round-off for every configuration, in the spins' dtype; ``NaN`` for an exceptional
        configuration (a triangle with two antipodal spins, or a hemisphere: measure zero).
        Jit-able and vmappable; ``observables={"Q": topological_charge}`` records it at every
        draw of :func:`liesample.sample`.

    Raises
    ------
    ValueError
        ``spins`` not of shape ``(..., L1, L2, 3)``, an extent below 2, or (concrete input)
        not unit vectors.
    TypeError
        ``spins`` not real floating.

    Examples
    --------
    The aligned (cold) start has no charge; a random configuration has an integer charge:

    >>> import numpy as np
    >>> from liesample.analysis.topology import topological_charge
    >>> system = liesample.systems.heisenberg((6, 6), periodic=True)
    >>> float(topological_charge(system.default_position))
    0.0
    >>> s = np.random.default_rng(0).normal(size=(6, 6, 3))
    >>> q = float(topological_charge(s / np.linalg.norm(s, axis=-1, keepdims=True)))
    >>> abs(q - round(q)) < 1e-9
    True
    """
    return jnp.sum(topological_charge_density(spins), axis=(-2, -1))


def _check_cp_field(z: ArrayLike, name: str = "z") -> jax.Array:
    """``z`` as a complex array ``(..., L1, L2, N)`` of unit vectors (checked when concrete),
    or an error naming ``name``."""
    shape = np.shape(z)
    if len(shape) < 3 or shape[-1] < 2 or min(shape[-3:-1]) < 2:
        raise ValueError(
            f"{name} must be a 2-D lattice of unit vectors of C^N, shape (..., L1, L2, N) with "
            f"L1, L2 >= 2 and N >= 2, got shape {shape}; the positions of "
            "liesample.systems.cp_model((L1, L2), N, periodic=True) have that shape"
        )
    dtype = jnp.result_type(z)
    if not jnp.issubdtype(dtype, jnp.complexfloating):
        raise TypeError(
            f"{name} must be a complex array (unit vectors z_x of C^N), got {dtype}; pass "
            "numpy.asarray(z, dtype=complex) (O(3) spins go to topological_charge)"
        )
    value = concrete_array(z)
    if value is not None:
        _check_unit(np.abs(value), name)
    return jnp.asarray(z)


def _triangle_phases(z1: jax.Array, z2: jax.Array, z3: jax.Array) -> jax.Array:
    """``arg(z₁^†z₂ z₂^†z₃ z₃^†z₁) = arg tr(P₁P₂P₃) ∈ (−π, π]`` per triangle (last axis the
    vector), ``NaN`` where the product lies within ``EXCEPTIONAL_ULPS · ε`` of the closed
    negative real axis (a zero overlap or an undecided ``±π``)."""
    overlap = lambda a, b: jnp.sum(jnp.conj(a) * b, axis=-1)
    product = overlap(z1, z2) * overlap(z2, z3) * overlap(z3, z1)
    real, imag = jnp.real(product), jnp.imag(product)
    tolerance = EXCEPTIONAL_ULPS * jnp.finfo(real.dtype).eps
    exceptional = (real <= tolerance) & (jnp.abs(imag) <= tolerance)
    return jnp.where(exceptional, jnp.nan, jnp.arctan2(imag, real))


def cp_topological_charge(z: ArrayLike) -> jax.Array:
    """The geometric topological charge ``Q`` of a periodic 2-D CP(N−1) configuration.

    With ``P = z z^†``, the charge is ``Q = (1/2π) Σ arg tr(P₁P₂P₃)`` over the same ``2 L1 L2``
    counter-clockwise triangles as :func:`topological_charge`, and
    ``tr(P₁P₂P₃) = z₁^†z₂ z₂^†z₃ z₃^†z₁``. Each phase ``z_x^†z_y/|z_x^†z_y|`` of a link enters
    the two triangles that share it with opposite orientations, so the phases cancel and the
    sum of the principal arguments is ``2π`` times an integer: ``Q`` is an integer by
    construction, it depends on the rays only (``z_x → e^{iφ_x} z_x`` changes no product) and
    a global ``z_x → U z_x``, ``U ∈ U(N)``, changes none. For ``N = 2`` the Hopf map
    ``s = z^† σ z`` gives ``tr(P₁P₂P₃) = (1 + s₁·s₂ + s₂·s₃ + s₃·s₁ + i s₁·(s₂ × s₃))/4``, so
    ``Q`` is the O(3) charge of :func:`topological_charge` of ``s``.

    Parameters
    ----------
    z : array_like, shape (..., L1, L2, N)
        Unit vectors of ``Cᴺ`` on a periodic ``L1 × L2`` lattice (``L ≥ 2``, ``N ≥ 2``), e.g. a
        position of ``liesample.systems.cp_model((L1, L2), N, periodic=True)``; leading axes are
        a batch. Complex; checked for unit length when concrete.

    Returns
    -------
    jax.Array, shape (...)
        ``Q``, an integer up to round-off, in the real dtype of ``z``; ``NaN`` for an
        exceptional configuration (a triangle with a zero overlap, or a product on the negative
        real axis: measure zero). Jit-able; ``observables={"Q": cp_topological_charge}``
        records it at every draw.

    Raises
    ------
    ValueError
        ``z`` not of shape ``(..., L1, L2, N)`` with the extents above, or (concrete input) not
        unit vectors.
    TypeError
        ``z`` not complex.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.analysis.topology import cp_topological_charge
    >>> system = liesample.systems.cp_model((6, 6), N=3, periodic=True)
    >>> float(cp_topological_charge(system.default_position))
    0.0
    >>> rng = np.random.default_rng(0)
    >>> z = rng.normal(size=(6, 6, 3)) + 1j * rng.normal(size=(6, 6, 3))
    >>> q = float(cp_topological_charge(z / np.linalg.norm(z, axis=-1, keepdims=True)))
    >>> abs(q - round(q)) < 1e-9
    True
    """
    z = _check_cp_field(z)
    right = jnp.roll(z, -1, axis=-3)  # z(x + ê₁)
    up = jnp.roll(z, -1, axis=-2)  # z(x + ê₂)
    diagonal = jnp.roll(right, -1, axis=-2)  # z(x + ê₁ + ê₂)
    phases = _triangle_phases(z, right, diagonal) + _triangle_phases(z, diagonal, up)
    return jnp.sum(phases, axis=(-2, -1)) / (2.0 * math.pi)


def topological_susceptibility(
    charge: npt.ArrayLike, volume: float, *, block_size: int | None = None
) -> JackknifeResult:
    """The topological susceptibility ``χ_t = ⟨Q²⟩ / V`` with its jackknife error.

    Parameters
    ----------
    charge : array_like, shape (chains, draws) or (draws,)
        ``Q`` at each draw (e.g. ``tree.posterior["Q"]`` of a run with
        ``observables={"Q": topological_charge}``); finite.
    volume : float
        ``V``, the number of sites ``L1 · L2`` (or the volume in lattice units); ``> 0``.
    block_size : int, optional
        Draws per jackknife block, as for
        :func:`liesample.analysis.correlated_errors.jackknife` (default: from the blocking
        analysis of ``Q²``). ``⟨Q⟩ = 0`` by symmetry, so ``⟨Q²⟩`` is not centred: a run
        that is frozen in one sector shows it as a ``χ_t`` far from its neighbours'.

    Returns
    -------
    JackknifeResult
        ``estimate`` is ``χ_t``, ``error`` its jackknife error, ``per_chain`` each chain's.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.analysis.topology import topological_susceptibility
    >>> q = np.tile([1.0, -1.0], (2, 64))  # |Q| = 1 at every draw
    >>> float(topological_susceptibility(q, volume=16, block_size=8).estimate)
    0.0625
    """
    volume = float(volume)
    if not (math.isfinite(volume) and volume > 0):
        raise ValueError(
            f"volume must be a finite number > 0 (the number of sites L1 * L2), got {volume!r}"
        )
    q = np.asarray(charge, dtype=float)
    if q.ndim not in (1, 2):
        raise ValueError(
            f"charge must have shape (chains, draws) or (draws,): one Q per draw, got shape "
            f"{q.shape}"
        )
    if not np.all(np.isfinite(q)):
        raise ValueError(
            "charge must be finite; a NaN marks an exceptional configuration "
            "(topological_charge), drop those draws first"
        )
    q = q[None] if q.ndim == 1 else q
    return jackknife(lambda q2: q2 / volume, q**2, block_size=block_size)
