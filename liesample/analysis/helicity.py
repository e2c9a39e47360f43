"""The helicity modulus (spin stiffness) of the XY model on a periodic lattice.

Twisting the boundary condition of a periodic lattice of planar spins ``θ_x`` by an angle
``δ`` per bond along the direction ``e`` (``θ_x − θ_{x+e} → θ_x − θ_{x+e} + δ``) raises the
free energy by ``F(δ) − F(0) = V Υ_e δ²/2 + O(δ⁴)``; ``Υ`` measures how rigid the phase is.
With ``h = −J Σ_{⟨xy⟩} cos(θ_x − θ_y)`` and the two sums over the bonds along ``e``,

    ``C_e = Σ_x cos(θ_x − θ_{x+e})`` and ``S_e = Σ_x sin(θ_x − θ_{x+e})``,

the second derivative of ``F = −log Z / β`` at ``δ = 0`` is the standard estimator

    ``Υ_e = (J/V) (⟨C_e⟩ − βJ ⟨S_e²⟩)``

(``⟨S_e⟩ = 0`` by the symmetry ``θ → −θ``). In two dimensions the Kosterlitz–Thouless
theory predicts a jump of ``Υ`` to zero at ``T_BKT``, from ``Υ(T_BKT⁻) = 2 T_BKT/π`` (Nelson
and Kosterlitz, Phys. Rev. Lett. 39 (1977) 1201); on a finite lattice ``Υ_L(T)`` crosses the
line ``2T/π`` at a temperature that approaches ``T_BKT`` only as ``1/(ln L)²``.

:func:`xy_helicity_sums` gives ``(C_e, S_e)`` of one configuration (a jax function, usable as
an observable of ``liesample.sample``); :func:`helicity_modulus` the estimate from the draws,
averaged over the directions, with its jackknife error over blocks
(:func:`liesample.analysis.correlated_errors.jackknife`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.analysis.correlated_errors import JackknifeResult, jackknife
from liesample.foundation.validation import finite_float

__all__ = ["helicity_modulus", "xy_helicity_sums"]


def xy_helicity_sums(spins: ArrayLike) -> jnp.ndarray:
    """``(C_e, S_e)`` for every lattice direction ``e`` of one periodic XY configuration
    (module docstring), shape ``(d, 2)``.

    ``spins`` has shape ``(*shape, 2)``: unit vectors ``(cos θ_x, sin θ_x)`` on a periodic
    lattice of ``d = len(shape)`` dimensions (the state of
    ``systems.n_vector(shape, n=2, periodic=True)``). ``cos(θ_x − θ_y) = s_x·s_y`` and
    ``sin(θ_x − θ_y) = s_x² s_y¹ − s_x¹ s_y²``.

    Examples
    --------
    Spins winding once around a ring of four sites: every bond is turned by ``−π/2``:

    >>> import numpy as np
    >>> from liesample.analysis.helicity import xy_helicity_sums
    >>> theta = np.pi / 2 * np.arange(4)
    >>> np.round(np.asarray(xy_helicity_sums(np.stack([np.cos(theta), np.sin(theta)], -1))), 12)
    array([[ 0., -4.]])
    """
    s = jnp.asarray(spins)
    if s.ndim < 2 or s.shape[-1] != 2:
        raise ValueError(
            f"spins must have shape (*shape, 2) (XY unit vectors on a lattice), got {s.shape}"
        )
    rows = []
    for axis in range(s.ndim - 1):
        t = jnp.roll(s, -1, axis=axis)  # s_{x+e}
        cos_sum = jnp.sum(s[..., 0] * t[..., 0] + s[..., 1] * t[..., 1])
        sin_sum = jnp.sum(s[..., 1] * t[..., 0] - s[..., 0] * t[..., 1])
        rows.append(jnp.stack([cos_sum, sin_sum]))
    return jnp.stack(rows)


def helicity_modulus(
    sums: npt.ArrayLike,
    beta: float,
    num_sites: int,
    *,
    coupling: float = 1.0,
    block_size: int | None = None,
) -> JackknifeResult:
    """The helicity modulus ``Υ = (J/V)(⟨C⟩ − βJ⟨S²⟩)`` averaged over the lattice directions,
    with its jackknife error over blocks of draws (module docstring).

    Parameters
    ----------
    sums : array_like, shape (chains, draws, d, 2) or (draws, d, 2)
        :func:`xy_helicity_sums` at each draw (e.g. recorded with
        ``observables={"helicity": xy_helicity_sums}``).
    beta : float
        Inverse temperature of the run.
    num_sites : int
        ``V``, the number of sites of the lattice.
    coupling : float
        ``J`` of ``h = −J Σ cos(θ_x − θ_y)``.
    block_size : int, optional
        As for :func:`liesample.analysis.correlated_errors.jackknife` (default: from the
        automatic blocking level, which follows the autocorrelation).

    Returns
    -------
    JackknifeResult
        The estimate of ``Υ`` (in the units of ``J``), its error and bias.

    Examples
    --------
    Aligned spins (the ground state) are as stiff as the coupling, ``Υ = J``:

    >>> import numpy as np
    >>> from liesample.analysis.helicity import helicity_modulus
    >>> sums = np.tile([[16.0, 0.0], [16.0, 0.0]], (2, 64, 1, 1))  # 4x4, all aligned
    >>> float(helicity_modulus(sums, beta=3.0, num_sites=16, block_size=8).estimate)
    1.0
    """
    arr = np.asarray(sums, dtype=float)
    arr = arr[None] if arr.ndim == 3 else arr
    if arr.ndim != 4 or arr.shape[-1] != 2:
        raise ValueError(
            "sums must have shape (chains, draws, d, 2) or (draws, d, 2) (xy_helicity_sums at "
            f"each draw), got shape {np.shape(sums)}"
        )
    beta = finite_float("beta", beta)
    coupling = finite_float("coupling", coupling)
    volume = finite_float("num_sites", num_sites, positive=True)
    cos_mean = arr[..., 0].mean(axis=-1)  # (chains, draws): mean over directions
    sin_square = (arr[..., 1] ** 2).mean(axis=-1)
    return jackknife(
        lambda c, s2: coupling * (c - beta * coupling * s2) / volume,
        cos_mean,
        sin_square,
        block_size=block_size,
    )
