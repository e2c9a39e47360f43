"""Vorticity states for Zeitlin's su(N) model: from grids, standard initial states, spectra.

A vorticity ``ω = Σ_{1≤ℓ<N} ω_ℓm Y_ℓm`` on the unit sphere (real orthonormal ``Y_ℓm`` of
:mod:`liesample.geometry.spherical_harmonics`) is the matrix ``W = Σ ω_ℓm E_ℓm`` of
:mod:`liesample.systems.zeitlin`, stored as real coordinates ``(N, N)``. The transform is an
isometry, ``‖W‖² = ∫ω² dΩ``, so the **enstrophy** ``½∫ω²`` is ``½‖W‖²`` and the **energy**
``½∫|∇ψ|² = ½ Σ ω_ℓm²/(ℓ(ℓ+1))`` is the system's Hamiltonian. The ``ℓ = 0`` part of a field
(its mean) is dropped: it is the trace, which ``su(N)`` has not (on a closed sphere the
vorticity of a flow has zero mean).

- Grids: :func:`vorticity_from_grid` (samples on a latitude–longitude grid → ``W``, by quadrature
  or least squares) and :func:`vorticity_on_grid` (back).
- Initial states: :func:`vortex_blobs` (Gaussian vortex patches at given points),
  :func:`rossby_haurwitz` (solid rotation plus one degree: a wave that turns rigidly, exactly,
  in the continuum and in the model), :func:`spectral_vorticity` (random phases with a given
  energy spectrum, energy or enstrophy).
- Spectra per degree: :func:`energy_spectrum`, :func:`enstrophy_spectrum` (JAX, any batch axes,
  usable inside a sampling loop).
- Time: :func:`physical_time_unit` converts the model's time to the time of Euler's equations on
  the unit sphere.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float
from liesample.geometry.spherical_harmonics import (
    gauss_legendre_grid,
    harmonic_analysis,
    harmonic_synthesis,
)
from liesample.systems.zeitlin import (
    _check_size,
    _compiled_from_coefficients,
    quantised_harmonics,
)

__all__ = [
    "energy_spectrum",
    "enstrophy_spectrum",
    "physical_time_unit",
    "rossby_haurwitz",
    "rossby_haurwitz_angular_velocity",
    "spectral_vorticity",
    "vortex_blobs",
    "vorticity_from_grid",
    "vorticity_on_grid",
]


def physical_time_unit(size: int) -> float:
    """``√(16π / (N(N² − 1)))``: one unit of model time is this much time of Euler's equations
    ``∂_t ω + u·∇ω = 0`` on the unit sphere, ``t_phys = physical_time_unit(N) · t_model``.

    The model's ``Ẇ = [P, W]`` with Frobenius-orthonormal harmonics changes the coefficients at
    ``physical_time_unit`` times the continuum's rate: the quantised coordinates
    ``X_k = S_k/√(s(s+1))`` obey ``[X_i, X_j] = iε_ijk X_k/√(s(s+1))`` against the unit sphere's
    ``{x_i, x_j} = ε_ijk x_k``, and a Frobenius-normalised matrix is ``√(4π/N)`` times the
    quantisation of an ``L²``-normalised function, so ``[P, W]`` is
    ``√(4π/N) · 2/√(N² − 1)`` times the quantised ``{ψ, ω}``. The tests check it on
    Rossby–Haurwitz waves, which the model turns at exactly this rate."""
    size = _check_size(size)
    return math.sqrt(16.0 * math.pi / (size * (size * size - 1.0)))


@functools.lru_cache(maxsize=8)
def _compiled_coefficients(harmonics):
    return jax.jit(harmonics.coefficients)


def _from_coefficients(size, coefficients):
    coefficients = np.array(coefficients, dtype=float)
    coefficients[..., 0] = 0.0  # ℓ = 0: the trace, absent in su(N)
    transform = _compiled_from_coefficients(quantised_harmonics(size))
    return np.asarray(transform(jnp.asarray(coefficients)))


def vorticity_from_grid(
    values: npt.ArrayLike, theta: npt.ArrayLike, size: int, weights: npt.ArrayLike | None = None
) -> np.ndarray:
    """``W`` (real coordinates, shape ``(..., N, N)``) of the vorticity sampled as
    ``values[..., t, p] = ω(θ_t, φ_p)``, ``φ_p = 2πp/num_phi``, ``num_phi ≥ 2N − 1``.

    The coefficients ``ω_ℓm``, ``ℓ ≤ N − 1``, come from
    :func:`liesample.geometry.spherical_harmonics.harmonic_analysis`: quadrature with the
    latitude ``weights`` (e.g. ``gauss_legendre_grid(N − 1)``: the ``L²`` projection), or least
    squares over the colatitudes when ``weights`` is ``None`` (any ``≥ N`` distinct colatitudes,
    e.g. :meth:`QuantisedHarmonics.grid`'s). Exact for fields of degree ``≤ N − 1``. The mean
    (``ℓ = 0``) is dropped.
    """
    size = _check_size(size)
    return _from_coefficients(size, harmonic_analysis(values, theta, size - 1, weights))


def vorticity_on_grid(x: ArrayLike, theta: npt.ArrayLike, num_phi: int) -> np.ndarray:
    """``ω(θ_t, φ_p)`` of the state ``x`` (``(..., N, N)``) on colatitudes ``theta`` and
    ``num_phi`` equispaced longitudes from 0, shape ``(..., num_theta, num_phi)``: the inverse of
    :func:`vorticity_from_grid` on trace-free states."""
    x = np.asarray(x, dtype=float)
    transform = _compiled_coefficients(quantised_harmonics(x.shape[-1]))
    return harmonic_synthesis(np.asarray(transform(jnp.asarray(x))), theta, num_phi)


def _unit_vectors(points, name):
    points = np.atleast_2d(np.asarray(points, dtype=float))
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ValueError(f"{name} must be finite 3-vectors of shape (K, 3), got {points.shape}")
    norms = np.linalg.norm(points, axis=1, keepdims=True)
    if np.any(norms == 0):
        raise ValueError(f"{name} must be nonzero vectors (points on the sphere)")
    return points / norms


def vortex_blobs(
    size: int, centres: npt.ArrayLike, strengths: npt.ArrayLike, widths: npt.ArrayLike = 0.2
) -> np.ndarray:
    """Gaussian vortex patches ``ω(u) = Σ_k Γ_k exp(−|u − c_k|² / (2 w_k²))`` (chordal distance
    on the unit sphere; ``Γ_k`` the peak vorticity of patch ``k``), projected onto ``ℓ ≤ N − 1``
    and without its mean; real coordinates ``(N, N)``.

    ``centres`` are ``K`` points, as nonzero 3-vectors (normalised here); ``strengths`` and
    ``widths`` broadcast to ``K``. The projection is a Gauss–Legendre quadrature on a grid twice
    as fine as the band limit needs, which makes the aliasing of the (not band-limited) patches
    negligible for widths ``w ≳ 2/N``.
    """
    size = _check_size(size)
    centres = _unit_vectors(centres, "centres")
    strengths = np.broadcast_to(np.asarray(strengths, dtype=float), (len(centres),))
    widths = np.broadcast_to(np.asarray(widths, dtype=float), (len(centres),))
    if not (np.all(np.isfinite(strengths)) and np.all(np.isfinite(widths)) and np.all(widths > 0)):
        raise ValueError("strengths must be finite and widths finite and > 0")
    theta, phi, weights = gauss_legendre_grid(size - 1, 2 * size, 4 * size)
    sin_theta = np.sin(theta)[:, None]
    points = np.stack(
        np.broadcast_arrays(
            sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)[:, None]
        ),
        axis=-1,
    )
    cosines = np.einsum("tpi,ki->tpk", points, centres)
    values = np.sum(strengths * np.exp((cosines - 1.0) / widths**2), axis=-1)
    return vorticity_from_grid(values, theta, size, weights)


def rossby_haurwitz(
    size: int,
    degree: int = 4,
    order: int = 4,
    amplitude: float = 1.0,
    angular_velocity: float = 1.0,
) -> np.ndarray:
    """A Rossby–Haurwitz wave: solid rotation ``ω = 2Ω cos θ`` plus ``amplitude · Y_ℓ^m``;
    real coordinates ``(N, N)``.

    On the sphere, the flow with this vorticity turns rigidly about the polar axis at
    :func:`rossby_haurwitz_angular_velocity` (Haurwitz): the solid rotation advects the wave,
    and a field of a single degree does not advect itself. The same holds exactly in Zeitlin's
    model (the quantised ``ℓ = 1`` modes generate rotations and ``Δ_N`` has the exact
    eigenvalues), at that rate times :func:`physical_time_unit` per unit of model time. ``Y_ℓ^m``
    is the real harmonic (``m < 0``: the ``sin |m|φ`` one); ``1 ≤ ℓ ≤ N − 1``.
    """
    size = _check_size(size)
    for name, value in (("degree", degree), ("order", order)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int, got {value!r}")
    if not 1 <= degree <= size - 1 or abs(order) > degree:
        raise ValueError(
            f"need 1 <= degree <= N − 1 = {size - 1} and |order| <= degree, "
            f"got degree={degree}, order={order}"
        )
    harmonics = quantised_harmonics(size)
    ell, m = harmonics.degrees, harmonics.orders
    coefficients = np.zeros(size * size)
    # 2Ω cos θ = 2Ω √(4π/3) Y_1^0
    coefficients[(ell == 1) & (m == 0)] = (
        2.0 * finite_float("angular_velocity", angular_velocity) * math.sqrt(4.0 * math.pi / 3.0)
    )
    coefficients[(ell == degree) & (m == order)] += finite_float("amplitude", amplitude)
    return _from_coefficients(size, coefficients)


def rossby_haurwitz_angular_velocity(degree: int, angular_velocity: float = 1.0) -> float:
    """``Ω (1 − 2/(ℓ(ℓ + 1)))``: the angular velocity (physical time, eastward positive) at which
    :func:`rossby_haurwitz` turns; ``ℓ = 1`` does not move relative to the rotation it is."""
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 1:
        raise ValueError(f"degree must be an int >= 1, got {degree!r}")
    omega = finite_float("angular_velocity", angular_velocity)
    return omega * (1.0 - 2.0 / (degree * (degree + 1)))


def spectral_vorticity(
    size: int,
    spectrum: Callable | np.ndarray,
    seed: int = 0,
    *,
    energy: float | None = None,
    enstrophy: float | None = None,
) -> np.ndarray:
    """A vorticity with the energy spectrum ``ε_ℓ`` exactly and random phases; real coordinates
    ``(N, N)``.

    ``spectrum`` is ``ε_ℓ`` for ``ℓ = 1 … N − 1`` (an array of ``N − 1`` values ``≥ 0``, or a
    callable of the array of degrees, e.g. ``lambda ell: ell ** -3.0``). Each degree's ``2ℓ + 1``
    coefficients point in a uniformly random direction (normalised Gaussians) with length
    ``√(2ℓ(ℓ + 1) ε_ℓ)``. ``energy`` or ``enstrophy`` (at most one), if given, rescales the
    spectrum to that total energy ``Σ ε_ℓ`` or enstrophy ``½‖W‖² = Σ ℓ(ℓ + 1) ε_ℓ``.
    """
    size = _check_size(size)
    degrees = np.arange(1, size)
    values = spectrum(degrees.astype(float)) if callable(spectrum) else spectrum
    values = np.asarray(values, dtype=float)
    if values.shape != degrees.shape or not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ValueError(
            f"spectrum must give {size - 1} finite values >= 0 (ℓ = 1 … {size - 1}), got {values!r}"
        )
    if energy is not None and enstrophy is not None:
        raise ValueError("give at most one of energy and enstrophy")
    weight = degrees * (degrees + 1.0)
    for name, target, total in (
        ("energy", energy, values.sum()),
        ("enstrophy", enstrophy, np.sum(weight * values)),
    ):
        if target is not None:
            target = finite_float(name, target)
            if target < 0 or total == 0:
                raise ValueError(f"{name} must be >= 0 and the spectrum nonzero")
            values = values * (target / total)
    harmonics = quantised_harmonics(size)
    ell = harmonics.degrees
    gaussian = np.random.default_rng(seed).standard_normal(ell.shape)
    coefficients = np.zeros(size * size)
    for degree, value in zip(degrees, values, strict=True):
        block = ell == degree
        direction = gaussian[block] / np.linalg.norm(gaussian[block])
        coefficients[block] = direction * math.sqrt(2.0 * degree * (degree + 1) * value)
    return _from_coefficients(size, coefficients)


@functools.partial(jax.jit, static_argnames="energy")
def _per_degree(x, energy):
    """``½ Σ_m ω_ℓm² w_ℓ`` for ``ℓ = 1 … N − 1``, ``w_ℓ = 1/(ℓ(ℓ+1))`` (energy) or 1."""
    harmonics = quantised_harmonics(x.shape[-1])
    ell = harmonics.degrees
    weights = 0.5 / np.maximum(ell * (ell + 1), 1) if energy else np.full(ell.shape, 0.5)
    per_mode = jnp.asarray(weights, dtype=x.dtype) * harmonics.coefficients(x) ** 2
    onehot = (ell[:, None] == np.arange(1, harmonics.size)[None, :]).astype(float)
    return per_mode @ jnp.asarray(onehot, dtype=per_mode.dtype)


def enstrophy_spectrum(x: ArrayLike) -> jax.Array:
    """Enstrophy per degree ``ζ_ℓ = ½ Σ_m ω_ℓm²``, ``ℓ = 1 … N − 1``: shape ``(..., N − 1)``
    for states ``(..., N, N)``; ``Σ ζ_ℓ = ½‖W‖²`` on trace-free states. JAX (jit/vmap)."""
    return _per_degree(jnp.asarray(x, dtype=jnp.result_type(x, float)), energy=False)


def energy_spectrum(x: ArrayLike) -> jax.Array:
    """Energy per degree ``ε_ℓ = ζ_ℓ / (ℓ(ℓ + 1))``, ``ℓ = 1 … N − 1``: shape ``(..., N − 1)``;
    ``Σ ε_ℓ`` is the Hamiltonian ``h``. JAX (jit/vmap)."""
    return _per_degree(jnp.asarray(x, dtype=jnp.result_type(x, float)), energy=True)
