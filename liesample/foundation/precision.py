"""Round-off tolerances scaled to the dtype a value is held and run in, and the way to float64.

JAX computes in float32 unless ``jax_enable_x64`` is on. A check of a start (unit spins, points
on a sphere, a trace-free vorticity) allows the round-off of that dtype, relative to the size
of what it checks: :data:`ROUNDOFF_ULPS` units of round-off ``ε`` per term, or the check's own
float64 floor, whichever is larger: float64 checks keep their floors, and a start
normalised in float32 passes in float32. A start refused in float32 is told how to run in
float64 (:func:`float64_hint`). The post-run Casimir check (:mod:`liesample.run.checks`) uses
the same rule for the drift of the chains' orbits.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import DTypeLike

__all__ = ["ROUNDOFF_ULPS", "X64_SWITCH", "check_dtype", "float64_hint", "roundoff_tolerance"]

ROUNDOFF_ULPS = 1000
"""How many units of round-off ``ε`` of its dtype (per term summed) a checked quantity may be
off, relative to its size."""

X64_SWITCH = 'jax.config.update("jax_enable_x64", True)'
"""The call that makes JAX compute in float64 (at start-up, before any array is made)."""


def check_dtype(value: object = None) -> np.dtype:
    """The floating dtype whose round-off a check of ``value`` allows: the coarser of ``value``'s
    own floating dtype (if it has one) and the float dtype JAX computes in (float32 unless
    ``jax_enable_x64``). A float64 NumPy start run with x64 off is run, and checked, in float32;
    a float32 start holds only float32's precision even when the run is in float64."""
    computed = np.dtype(jax.dtypes.canonicalize_dtype(float))
    own = getattr(value, "dtype", None)
    if own is not None and jnp.issubdtype(own, jnp.floating):
        if jnp.finfo(own).eps > jnp.finfo(computed).eps:
            return np.dtype(own)
    return computed


def roundoff_tolerance(dtype: DTypeLike, *, floor: float = 0.0, terms: int = 1) -> float:
    """``max(floor, ROUNDOFF_ULPS · terms · ε)``, ``ε`` the round-off unit of ``dtype``: the
    relative error a check allows for a quantity built from ``terms`` rounded terms."""
    return max(float(floor), ROUNDOFF_ULPS * max(int(terms), 1) * float(jnp.finfo(dtype).eps))


def float64_hint(dtype: DTypeLike) -> str:
    """``""`` for a float64 check; otherwise a sentence (with a leading space) saying that the
    check allowed the round-off of ``dtype`` and how to check and run in float64."""
    dtype = np.dtype(dtype)
    if jnp.finfo(dtype).eps <= jnp.finfo(np.float64).eps:
        return ""
    if jax.config.jax_enable_x64:
        return (
            f" The start is held in {dtype.name} and was checked to {dtype.name} round-off; to "
            "check and run it in float64, pass it as a float64 array built in float64."
        )
    return (
        f" JAX is computing in {dtype.name} (jax_enable_x64 is off), and the check allowed "
        f"{dtype.name} round-off; to run in float64, call {X64_SWITCH} at start-up, before "
        "any array is made."
    )
