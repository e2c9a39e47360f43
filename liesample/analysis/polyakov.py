"""The Polyakov loop as the order parameter of the deconfinement transition, with errors that
include the autocorrelation of the draws.

The input is the volume-averaged Polyakov loop ``P = (1/N_s³) Σ_x tr Π_t U_t(x, t) / N`` of
each draw (:meth:`liesample.systems.wilson_gauge.WilsonGauge.polyakov_loop`, recorded as an
observable of ``liesample.sample``): real for SU(2), complex for U(1) and SU(N ≥ 3). On a finite
lattice ``⟨P⟩`` vanishes by the centre symmetry in either phase (the field tunnels between the
centre sectors), so what is read is its modulus:

- ``⟨|P|⟩``, small (``O(N_s^{−3/2})``) in the confined phase and finite in the deconfined one;
- the susceptibility ``χ_P = N_s³ (⟨|P|²⟩ − ⟨|P|⟩²)``, ``N_s³`` the spatial volume, which peaks
  at the transition (its peak grows with the volume at a second-order transition);
- the Binder cumulant ``U = 1 − ⟨|P|⁴⟩ / (3 ⟨|P|²⟩²)``, which tends to ``2/3`` in the
  deconfined phase and to its Gaussian value in the confined one (``0`` for a real ``P``, SU(2);
  ``1/3`` for a complex one), and whose curves for several volumes cross near the critical
  coupling.

The mean's error comes from :func:`liesample.analysis.correlated_errors.blocking_error` (its
``tau_int`` reported with it), those of ``χ_P`` and ``U`` (functions of several means) from
:func:`liesample.analysis.correlated_errors.jackknife` over blocks longer than the
autocorrelation time (its default block length is the blocking level's).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from liesample.analysis.correlated_errors import (
    BlockingResult,
    JackknifeResult,
    blocking_error,
    jackknife,
)

__all__ = [
    "PolyakovSummary",
    "polyakov_binder_cumulant",
    "polyakov_modulus",
    "polyakov_summary",
    "polyakov_susceptibility",
]


def _modulus(loops: npt.ArrayLike) -> np.ndarray:
    """``|P|`` per draw as ``(chains, draws)``, or an error naming ``loops``."""
    p = np.asarray(loops)
    if p.ndim not in (1, 2) or p.shape[-1] < 2:
        raise ValueError(
            "loops must hold one volume-averaged Polyakov loop per draw, shape (draws,) or "
            f"(chains, draws) with at least 2 draws, got shape {p.shape}; record "
            "system.polyakov_loop as an observable of liesample.sample"
        )
    if not np.issubdtype(p.dtype, np.number) or np.issubdtype(p.dtype, np.bool_):
        raise TypeError(f"loops must be real or complex numbers, got dtype {p.dtype}")
    if not np.all(np.isfinite(p)):
        raise ValueError("loops must be finite (a non-finite loop means a broken field)")
    modulus = np.abs(p).astype(float)
    return modulus[None] if modulus.ndim == 1 else modulus


def _volume(spatial_volume: object) -> float:
    try:
        value = float(spatial_volume)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(
            f"spatial_volume must be a finite number > 0 (N_s³, the sites of one time slice: "
            f"e.g. math.prod(system.shape[:-1])), got {spatial_volume!r}"
        )
    return value


def polyakov_modulus(loops: npt.ArrayLike) -> BlockingResult:
    """``⟨|P|⟩`` with its blocking error (``tau_int`` included: :func:`blocking_error`).

    Parameters
    ----------
    loops : array_like, shape (chains, draws) or (draws,)
        The volume-averaged Polyakov loop of each draw (real or complex).

    Returns
    -------
    BlockingResult
    """
    return blocking_error(_modulus(loops), warn=False)


def polyakov_susceptibility(
    loops: npt.ArrayLike, spatial_volume: float, *, block_size: int | None = None
) -> JackknifeResult:
    """``χ_P = N_s³ (⟨|P|²⟩ − ⟨|P|⟩²)`` with its jackknife error over blocks of draws.

    Parameters
    ----------
    loops : array_like, shape (chains, draws) or (draws,)
        The volume-averaged Polyakov loop of each draw (real or complex).
    spatial_volume : float
        ``N_s³``: the sites of one time slice (``math.prod(system.shape[:-1])``).
    block_size : int, optional
        Draws per jackknife block (default: the blocking level's, :func:`jackknife`).

    Returns
    -------
    JackknifeResult
    """
    volume = _volume(spatial_volume)
    m = _modulus(loops)
    return jackknife(lambda a, a2: volume * (a2 - a**2), m, m**2, block_size=block_size)


def polyakov_binder_cumulant(
    loops: npt.ArrayLike, *, block_size: int | None = None
) -> JackknifeResult:
    """``U = 1 − ⟨|P|⁴⟩ / (3 ⟨|P|²⟩²)`` with its jackknife error over blocks of draws
    (``2/3`` deconfined; ``0`` for a real Gaussian ``P``, ``1/3`` for a complex one: module
    notes)."""
    m2 = _modulus(loops) ** 2
    return jackknife(lambda a2, a4: 1.0 - a4 / (3.0 * a2**2), m2, m2**2, block_size=block_size)


class PolyakovSummary(NamedTuple):
    """What :func:`polyakov_summary` reads from a series of Polyakov loops.

    modulus : BlockingResult
        ``⟨|P|⟩``, its error and ``tau_int``.
    susceptibility, binder : JackknifeResult
        ``χ_P`` and the Binder cumulant ``U``, with jackknife errors.
    """

    modulus: BlockingResult
    susceptibility: JackknifeResult
    binder: JackknifeResult


def polyakov_summary(
    loops: npt.ArrayLike, spatial_volume: float, *, block_size: int | None = None
) -> PolyakovSummary:
    """``⟨|P|⟩``, ``χ_P`` and ``U`` of one run, each with an error that includes the
    autocorrelation (module notes).

    Parameters
    ----------
    loops : array_like, shape (chains, draws) or (draws,)
        The volume-averaged Polyakov loop of each draw (real or complex).
    spatial_volume : float
        ``N_s³`` (``math.prod(system.shape[:-1])``).
    block_size : int, optional
        Draws per jackknife block; default: the blocking level of ``|P|``, ``|P|²`` and
        ``|P|⁴``, the longest of them.

    Returns
    -------
    PolyakovSummary

    Examples
    --------
    A deconfined-like series, ``|P| = 0.5`` at every draw (either centre sector), has no
    fluctuation of ``|P|`` and the ordered Binder cumulant ``2/3``:

    >>> import numpy as np
    >>> from liesample.analysis.polyakov import polyakov_summary
    >>> loops = 0.5 * np.sign(np.random.default_rng(0).normal(size=(2, 64)))
    >>> summary = polyakov_summary(loops, spatial_volume=4**3, block_size=8)
    >>> float(summary.modulus.mean), float(summary.susceptibility.estimate)
    (0.5, 0.0)
    >>> bool(np.isclose(summary.binder.estimate, 2 / 3))
    True
    """
    m = _modulus(loops)
    if block_size is None:
        block_size = max(2 ** blocking_error(x, warn=False).level for x in (m, m**2, m**4))
    return PolyakovSummary(
        polyakov_modulus(m),
        polyakov_susceptibility(m, spatial_volume, block_size=block_size),
        polyakov_binder_cumulant(m, block_size=block_size),
    )
