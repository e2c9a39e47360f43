"""Thermodynamic quantities from fluctuations, with jackknife errors: the specific heat from
the energy, the susceptibility and the Binder cumulant from the magnetisation.

Each is a function of several means (``⟨E⟩`` and ``⟨E²⟩``, ``⟨m²⟩`` and ``⟨m⁴⟩``), whose error
the MCSE of one mean does not give; :func:`liesample.analysis.correlated_errors.jackknife`
gives it, over blocks of draws.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from liesample.analysis.correlated_errors import JackknifeResult, jackknife

__all__ = ["binder_cumulant", "specific_heat", "susceptibility"]


def _per_draw(values):
    arr = np.asarray(values, dtype=float)
    return arr[None] if arr.ndim == 1 else arr


def _magnetisation_norm(magnetisation):
    """``|m|`` per draw: the value of a scalar magnetisation ``(chains, draws)``, the norm of
    a vector one ``(chains, draws, components)``."""
    m = np.asarray(magnetisation, dtype=float)
    if m.ndim == 3:
        return np.linalg.norm(m, axis=-1)
    if m.ndim in (1, 2):
        return np.abs(_per_draw(m))
    raise ValueError(
        "magnetisation must have shape (chains, draws) or (chains, draws, components), got "
        f"shape {m.shape}"
    )


def _positive(name, value):
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def specific_heat(
    energy: npt.ArrayLike, beta: float, num_sites: int, *, block_size: int | None = None
) -> JackknifeResult:
    """Specific heat per site ``C = β² (⟨E²⟩ − ⟨E⟩²) / N`` with its jackknife error.

    Parameters
    ----------
    energy : array_like, shape (chains, draws) or (draws,)
        The total energy ``E`` (the Hamiltonian) at each draw, e.g. recorded with
        ``observables={"h": system.hamiltonian}``.
    beta : float
        Inverse temperature of the run (any sign).
    num_sites : int or float
        ``N``, the number of sites (spins, vortices) the heat capacity is divided by; ``1``
        gives the total heat capacity.
    block_size : int, optional
        As for :func:`jackknife`.

    Notes
    -----
    The energy is shifted by its overall mean first (the variance is unchanged, the
    cancellation in ``⟨E²⟩ − ⟨E⟩²`` is avoided).

    Examples
    --------
    A constant energy has no fluctuations, so no specific heat:

    >>> import numpy as np
    >>> from liesample.diagnostics import specific_heat
    >>> float(specific_heat(np.full((2, 100), -3.0), beta=1.0, num_sites=4, block_size=10).estimate)
    0.0
    """
    beta = float(beta)
    num_sites = _positive("num_sites", num_sites)
    e = _per_draw(energy)
    e = e - np.mean(e)
    return jackknife(
        lambda m1, m2: beta**2 * (m2 - m1**2) / num_sites, e, e**2, block_size=block_size
    )


def susceptibility(
    magnetisation: npt.ArrayLike,
    beta: float,
    num_sites: int,
    *,
    connected: bool = True,
    block_size: int | None = None,
) -> JackknifeResult:
    """Magnetic susceptibility per site with its jackknife error.

    ``connected=True``: ``χ = β N (⟨m²⟩ − ⟨|m|⟩²)``, the finite-lattice convention that stays
    finite through an ordered phase (the order parameter of a finite lattice without field
    is ``⟨|m|⟩``, its ``⟨m⟩`` vanishes by symmetry). ``connected=False``:
    ``χ = β N ⟨m²⟩``, the susceptibility of the symmetric (disordered) phase, equal to the
    sum of the spin correlations ``β/N Σ_kl ⟨s_k·s_l⟩``.

    Parameters
    ----------
    magnetisation : array_like, shape (chains, draws), (chains, draws, components) or (draws,)
        The magnetisation per site ``m = (1/N) Σ_k s_k`` at each draw: a scalar (Ising-like)
        or a vector (Heisenberg spins; ``m² = |m|²``).
    beta : float
    num_sites : int or float
        ``N``.
    connected : bool
    block_size : int, optional
        As for :func:`jackknife`.

    Examples
    --------
    The disconnected susceptibility ``β N ⟨m²⟩`` of fully aligned spins is ``β N``:

    >>> import numpy as np
    >>> from liesample.diagnostics import susceptibility
    >>> m = np.tile([0.0, 0.0, 1.0], (2, 100, 1))
    >>> chi = susceptibility(m, beta=1.0, num_sites=4, connected=False, block_size=10)
    >>> float(chi.estimate)
    4.0
    """
    beta = float(beta)
    num_sites = _positive("num_sites", num_sites)
    norm = _magnetisation_norm(magnetisation)
    if connected:
        return jackknife(
            lambda a, m2: beta * num_sites * (m2 - a**2), norm, norm**2, block_size=block_size
        )
    return jackknife(lambda m2: beta * num_sites * m2, norm**2, block_size=block_size)


def binder_cumulant(
    magnetisation: npt.ArrayLike, *, block_size: int | None = None
) -> JackknifeResult:
    """Binder cumulant ``U = 1 − ⟨m⁴⟩ / (3 ⟨m²⟩²)`` with its jackknife error.

    ``m² = |m|²`` for a vector magnetisation. With this (Ising) normalisation ``U → 2/3`` in
    an ordered phase and, for a Gaussian ``n``-component ``m`` (disordered phase),
    ``U → 1 − (n + 2)/(3n)``: ``0`` for a scalar, ``4/9`` for Heisenberg spins.

    Parameters
    ----------
    magnetisation : array_like
        The magnetisation per site at each draw: ``(draws, components)`` for one chain or
        ``(chains, draws, components)`` for several, ``components`` being 2, 3 or 4 (O(2),
        O(3), O(4) spins); or a scalar one, ``(draws,)`` or ``(chains, draws)`` with more than
        4 draws per chain. Any other shape is a ``ValueError`` naming these.
    block_size : int, optional
        As for :func:`jackknife`.

    Examples
    --------
    Perfectly ordered spins (``|m| = 1`` at every draw) give the ordered phase's ``U = 2/3``:

    >>> import numpy as np
    >>> from liesample.diagnostics import binder_cumulant
    >>> m = np.tile([0.0, 0.0, 1.0], (2, 100, 1))  # (chains, draws, components)
    >>> bool(np.isclose(binder_cumulant(m, block_size=10).estimate, 2 / 3))
    True
    """
    m = np.asarray(magnetisation, dtype=float)
    if m.ndim == 2 and 2 <= m.shape[1] <= 4:
        m = m[None]  # one chain of a vector magnetisation
    if m.ndim not in (1, 2, 3) or (m.ndim == 2 and m.shape[1] < 2):
        raise ValueError(
            "magnetisation must have shape (draws, components) for one chain or (chains, draws, "
            "components) for several (components 2, 3 or 4), or (draws,) / (chains, draws) for "
            f"a scalar magnetisation; got shape {m.shape}"
        )
    squared = _magnetisation_norm(m) ** 2
    return jackknife(
        lambda m2, m4: 1.0 - m4 / (3.0 * m2**2), squared, squared**2, block_size=block_size
    )
