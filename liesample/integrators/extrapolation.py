"""Richardson–Romberg extrapolation of ergodic averages to step size 0.

Under a bias ``A(h) − A(0) ≈ C h^p``, the averages at ``h`` and ``h/2`` combine to
``(2^p A(h/2) − A(h)) / (2^p − 1)``, which cancels the leading term:
:func:`richardson_romberg` does this with its MCSE (paired when both runs share their Brownian
paths), and :func:`richardson_romberg_run` runs both levels, coupled
(:func:`liesample.integrators.chain_averages.coupled_ergodic_averages`), and extrapolates.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.validation import finite_float
from liesample.integrators.chain_averages import coupled_ergodic_averages
from liesample.integrators.orbit import DEFAULT_INTEGRATOR, Integrator, get_integrator

__all__ = ["RichardsonRomberg", "richardson_romberg", "richardson_romberg_run"]


@dataclass(frozen=True)
class RichardsonRomberg:
    """``(2^p A(h/2) − A(h)) / (2^p − 1)`` per observable, with its MCSE and the inputs.

    Examples
    --------
    A bias ``C h²``: averages 1 at ``h`` and 0.75 at ``h/2`` extrapolate to ``2/3`` at ``h = 0``:

    >>> import numpy as np
    >>> from liesample.accuracy import richardson_romberg
    >>> result = richardson_romberg(np.array([[1.0], [1.0]]), np.array([[0.75], [0.75]]), order=2)
    >>> bool(np.allclose(result.estimate, 2 / 3)), result.order
    (True, 2.0)
    """

    estimate: np.ndarray
    mcse: np.ndarray
    order: float
    coarse: np.ndarray
    fine: np.ndarray
    coarse_mcse: np.ndarray
    fine_mcse: np.ndarray
    paired: bool
    wall_time: float = math.nan


def richardson_romberg(
    coarse: ArrayLike, fine: ArrayLike, order: float, *, paired: bool = False
) -> RichardsonRomberg:
    """Richardson–Romberg extrapolation of ergodic averages across step sizes ``h`` and ``h/2``.

    Parameters
    ----------
    coarse, fine : array (chains, k) or (chains,)
        Per-chain time averages at ``h`` and at ``h/2`` from independent chains.
    order : float
        The order ``p`` of the leading bias term (the integrator's ``weak_order``, or a
        measured slope); the combination cancels ``C h^p``.
    paired : bool
        ``True`` when chain ``c`` of both inputs was driven by the same Brownian path
        (:func:`coupled_ergodic_averages`): the MCSE then comes from the spread of the per-chain
        combinations (which includes the coupling's correlation). ``False``: the two runs are
        independent and their variances add.

    Examples
    --------
    A bias ``C h²``: averages 1 at ``h`` and 0.75 at ``h/2`` extrapolate to ``(4·0.75 − 1)/3``:

    >>> import numpy as np
    >>> from liesample.accuracy import richardson_romberg
    >>> result = richardson_romberg(np.array([[1.0], [1.0]]), np.array([[0.75], [0.75]]), order=2)
    >>> bool(np.allclose(result.estimate, 2 / 3))
    True
    """
    order = finite_float("order", order, positive=True)
    coarse = np.asarray(coarse, dtype=float)
    fine = np.asarray(fine, dtype=float)
    if coarse.ndim == 1:
        coarse, fine = coarse[:, None], fine[:, None] if fine.ndim == 1 else fine
    if coarse.ndim != 2 or fine.ndim != 2 or coarse.shape[1] != fine.shape[1]:
        raise ValueError(
            f"coarse and fine must be per-chain averages of shape (chains, k) with the same k, "
            f"got {coarse.shape} and {fine.shape}"
        )
    if min(coarse.shape[0], fine.shape[0]) < 2:
        raise ValueError("coarse and fine need at least 2 chains each (for the MCSE)")
    if paired and coarse.shape != fine.shape:
        raise ValueError(f"paired runs need the same shape, got {coarse.shape} and {fine.shape}")
    weight = 2.0**order
    se_coarse = coarse.std(0, ddof=1) / math.sqrt(coarse.shape[0])
    se_fine = fine.std(0, ddof=1) / math.sqrt(fine.shape[0])
    if paired:
        combined = (weight * fine - coarse) / (weight - 1.0)
        estimate = combined.mean(0)
        mcse = combined.std(0, ddof=1) / math.sqrt(combined.shape[0])
    else:
        estimate = (weight * fine.mean(0) - coarse.mean(0)) / (weight - 1.0)
        mcse = np.hypot(weight * se_fine, se_coarse) / (weight - 1.0)
    return RichardsonRomberg(
        estimate, mcse, order, coarse.mean(0), fine.mean(0), se_coarse, se_fine, paired
    )


def richardson_romberg_run(
    system: LiePoissonSystem,
    beta: float,
    observables: Callable[[jax.Array], jax.Array],
    *,
    integrator: str | Integrator = DEFAULT_INTEGRATOR,
    order: float | None = None,
    **run_options: Any,
) -> RichardsonRomberg:
    """Run coupled chains at ``step_size`` and ``step_size/2`` and extrapolate.

    ``order`` defaults to the integrator's declared weak order. ``run_options`` (``step_size``,
    ``initial_positions``, ``rng_key``, ``total_time``, and optionally ``burn_in``, ``sigma``)
    are those of :func:`coupled_ergodic_averages`.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> result = liesample.accuracy.richardson_romberg_run(
    ...     system, 3.0, lambda mu: mu**2, step_size=0.1, rng_key=jax.random.key(0),
    ...     initial_positions=jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]]), total_time=2.0)
    >>> result.estimate.shape, result.order  # the splitting scheme's weak order
    ((3,), 2.0)
    """
    integrator = get_integrator(integrator)
    averages = coupled_ergodic_averages(
        system, beta, observables, levels=2, integrator=integrator, **run_options
    )
    result = richardson_romberg(
        averages.chain_means[:, 0],
        averages.chain_means[:, 1],
        integrator.weak_order if order is None else order,
        paired=True,
    )
    return RichardsonRomberg(**{**result.__dict__, "wall_time": averages.wall_time})
