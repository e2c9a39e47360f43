"""The bias of a given step from the linearised dynamics: one formula, no pilot run.

Along its stiffest noise direction the SDE linearises to an Ornstein–Uhlenbeck equation, on
which each built-in scheme's step is a linear recursion with a stationary variance of its own;
:func:`linear_sd_bias` compares that with the exact one at the stability number ``κ``
(:mod:`liesample.integrators.stability`), :func:`largest_accurate_stability_number` inverts it
for a tolerance, and :func:`warn_given_step` warns when a step given by the user is beyond it.
It indicates a step's accuracy; the pilot-based bias model of
:mod:`liesample.integrators.accuracy` measures it.
"""

from __future__ import annotations

import math
import warnings
from typing import cast

from liesample.integrators.orbit import Integrator, get_integrator

__all__ = ["largest_accurate_stability_number", "linear_sd_bias", "warn_given_step"]


# The step of each built-in scheme on the scalar Ornstein-Uhlenbeck equation
# dφ = −λφ dt + σ dW, with z = λ dt: φ' = R(z) φ + b(z) σ ΔW (Heun feeds one increment to both
# stages; every piece of ``splitting`` is Heun along one noise direction).
_LINEAR_STEPS = {
    "lie_euler": lambda z: (1.0 - z, 1.0),
    "rkmk_heun": lambda z: (1.0 - z + 0.5 * z * z, 1.0 - 0.5 * z),
    "splitting": lambda z: (1.0 - z + 0.5 * z * z, 1.0 - 0.5 * z),
}


def linear_sd_bias(integrator: str | Integrator, stability_number: float) -> float | None:
    """The relative error of the stationary sd along the stiffest noise direction, from the
    linearised dynamics at the stability number ``κ = step_size·θ·max|h''|``
    (:mod:`liesample.integrators.stability`): no pilot run, one formula.

    Along one noise direction the SDE linearises to ``dφ = −λφ dt + σ dW`` with ``λ = θ h''``
    (the stability module's derivation), whose law is ``N(0, σ²/2λ)``. A scheme's step there is
    ``φ' = R(κ) φ + b(κ) σ ΔW``, whose stationary variance is ``b² σ² dt / (1 − R²)``; the ratio
    to the exact one is ``2κ b² / (1 − R²)`` (Heun, ``splitting``'s pieces:
    ``(2 − κ)/(2 − κ + κ²/2)``, sd too small; Lie–Euler: ``2/(2 − κ)``, too large). At the
    stiffest direction this is the largest error a near-Gaussian law sees; it leaves out what
    the linear model cannot see (the Hamiltonian drift, non-commuting noise directions, a
    far-from-Gaussian law), so it indicates a given step's accuracy, it does not certify it.

    Returns ``sqrt(ratio) − 1`` (e.g. ``-0.1``: 10 % too small), ``None`` for an integrator
    without a declared linear step (``euler_heun``, user schemes) or ``κ`` outside
    ``[0, stability limit)``; ``0`` for ``κ < 1e-6`` (a flat direction: the isotropic body).

    Examples
    --------
    Lie–Euler at ``κ = 1``: the sd ratio is ``√(2/(2 − κ)) = √2``, 41 % too large:

    >>> import numpy as np
    >>> from liesample.accuracy import linear_sd_bias
    >>> bool(np.isclose(linear_sd_bias("lie_euler", 1.0), np.sqrt(2) - 1))
    True
    >>> linear_sd_bias("splitting", 0.0), linear_sd_bias("euler_heun", 1.0)  # flat; no model
    (0.0, None)
    """
    integrator = get_integrator(integrator)
    linear = _LINEAR_STEPS.get(integrator.name)
    limit = integrator.stability_limit
    kappa = float(stability_number)
    if linear is None or limit is None or not 0.0 <= kappa < limit:
        return None
    if kappa < 1e-6:  # |error| < κ/4 is below any tolerance, and 1 − R² would round to 0
        return 0.0
    r, b = linear(kappa)
    return math.sqrt(2.0 * kappa * b * b / (1.0 - r * r)) - 1.0


def largest_accurate_stability_number(
    integrator: str | Integrator, tolerance: float
) -> float | None:
    """The largest ``κ`` at which :func:`linear_sd_bias` is within ``tolerance`` (bisection; the
    error grows with ``κ``), ``None`` where the integrator has no linear model.

    Examples
    --------
    >>> from liesample.accuracy import largest_accurate_stability_number, linear_sd_bias
    >>> kappa = largest_accurate_stability_number("splitting", 0.05)
    >>> bool(0 < kappa < 2), bool(abs(linear_sd_bias("splitting", kappa)) <= 0.05 + 1e-9)
    (True, True)
    """
    integrator = get_integrator(integrator)
    if integrator.name not in _LINEAR_STEPS or integrator.stability_limit is None:
        return None
    low, high = 0.0, integrator.stability_limit
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (
            (middle, high)
            if abs(cast(float, linear_sd_bias(integrator, middle))) <= tolerance  # has a model
            else (
                low,
                middle,
            )
        )
    return low


def warn_given_step(
    integrator: str | Integrator, step_size: float, stability_number: float, tolerance: float
) -> float | None:
    """:func:`linear_sd_bias` of a given step, with a ``UserWarning`` naming a step within
    ``tolerance`` (and the other ways out) when its magnitude exceeds ``tolerance``.

    Examples
    --------
    >>> import warnings
    >>> from liesample.accuracy import warn_given_step
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     bias = warn_given_step("lie_euler", 0.1, stability_number=1.0, tolerance=0.05)
    >>> "41% too large" in str(caught[0].message)
    True
    """
    bias = linear_sd_bias(integrator, stability_number)
    if bias is None or abs(bias) <= tolerance:
        return bias
    accurate = cast(float, largest_accurate_stability_number(integrator, tolerance))  # has a model
    warnings.warn(
        f"step_size={step_size:.4g} (given) has the stability number κ = "
        f"{stability_number:.3g}: linearised along the stiffest noise direction, the "
        f"{get_integrator(integrator).name} scheme's stationary sd is "
        f"{abs(bias):.0%} too {'small' if bias < 0 else 'large'}, beyond bias_tolerance="
        f"{tolerance:g} (liesample.integrators.accuracy.linear_sd_bias; the law's own error "
        f"is often smaller, but not within the tolerance by any guarantee). Use step_size <= "
        f"{step_size * accurate / stability_number:.3g} (κ <= {accurate:.3g}), leave step_size "
        "unset for the bias model's choice, or use liesample.adjusted_lie_poisson (exact at "
        "any step)",
        UserWarning,
        stacklevel=4,
    )
    return bias
