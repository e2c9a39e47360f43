"""The Wilson (gradient) flow: the noise-free dissipative flow of the Wilson action on the links.

Lüscher's flow (JHEP 08 (2010) 071, eq. 1.3) is ``V̇ = −g₀² ∂S_w(V) V`` with ``g₀² S_w =
Σ_{oriented P} Re tr(1 − V_P) = 2N S/β``. In the algebra coordinates of
:mod:`liesample.geometry.spaces` (basis ``iλ_a``, twice Lüscher's ``T^a``) and the bi-invariant
metric, where left and right trivialisations give one gradient flow, its velocity is

    ċ = −(N/2) ∇(S/β),      V ← V exp(ĉ),

the ``θ``-dissipation of the ``T*G`` dynamics with the noise switched off. It is
integrated by Lüscher's third-order Runge–Kutta–Munthe-Kaas scheme (his appendix C), mirrored to
the right action. The energy density ``E = 2 Σ_{μ<ν} Re tr(1 − V_μν) / V`` along the flow defines
the scale ``t₀`` by ``t₀² E(t₀) = 0.3``.

Stability. Near the identity the flow is linear, ``ċ = −d†d c`` with ``d`` the lattice curl, for
U(1) and SU(N) alike (the ``N/2`` above cancels the ``1/N`` of the SU(N) action's quadratic
form); the largest eigenvalue of ``d†d`` on a torus is ``4d`` (the staggered mode, ``d`` the
dimension), and away from the identity the action's curvature is smaller. Every explicit
three-stage scheme of third order, Lüscher's included, multiplies a mode of rate ``λ`` by
``R(−ελ)``, ``R(z) = 1 + z + z²/2 + z³/6``, and ``|R(z)| ≤ 1`` exactly on ``[−r₃, 0]``, ``r₃``
the real root of ``R(z) = −1`` (:data:`RK3_STABILITY`). A flow step ``ε = t/n`` with
``4dε ≥ r₃`` amplifies the staggered mode (a field then flows to a rough limit cycle, not to a
smooth one), so :func:`wilson_flow` refuses it and names the ``num_steps`` that fits.

Anisotropy. The flow is a smoothing with its own action: it uses the isotropic Wilson action
(every plane of weight 1) whatever the ``anisotropy`` of the system that sampled the links, the
usual convention (the flow time is then in units of the lattice spacing of every direction; on
an anisotropic lattice, whose time spacing is ``a_s/ξ``, the flowed field is smoothed over a
different physical extent in time than in space).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry import spaces
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["RK3_STABILITY", "flow_scale", "max_flow_step", "wilson_flow"]

T0_REFERENCE = 0.3  # t₀² E(t₀) = 0.3 (Lüscher 2010)

_ROOTS = np.roots([1.0 / 6.0, 0.5, 1.0, 2.0])
RK3_STABILITY = -float(np.real(_ROOTS[np.argmin(np.abs(_ROOTS.imag))]))
"""``r₃``: minus the real root of ``1 + z + z²/2 + z³/6 = −1``; the RK3 step is stable for
``z = −ελ ∈ [−r₃, 0]``."""


def max_flow_step(system: WilsonGauge) -> float:
    """The flow step ``r₃/(4d)`` at and beyond which the staggered mode grows (module notes)."""
    return RK3_STABILITY / (4 * system.dim)


def _velocity(system: WilsonGauge) -> Callable[[jax.Array], jax.Array]:
    isotropic = dataclasses.replace(system, anisotropy=1.0)  # the flow's own action (notes)

    def logdensity(links: jax.Array) -> jax.Array:
        return -isotropic.action(links)

    grad = spaces.trivialised_value_and_grad(logdensity, system.space)
    scale = 0.5 * max(system.n, 2)  # N/2 for SU(N); U(1) flows like U(1) ⊂ SU(2)
    return lambda links: scale * grad(links)[1]


def _step(system: WilsonGauge, velocity, links, eps):
    move = lambda u, c: system.space.exp(u, c)
    z0 = eps * velocity(links)
    w1 = move(links, 0.25 * z0)
    z1 = eps * velocity(w1)
    w2 = move(w1, 8.0 / 9.0 * z1 - 17.0 / 36.0 * z0)
    z2 = eps * velocity(w2)
    return move(w2, 0.75 * z2 - 8.0 / 9.0 * z1 + 17.0 / 36.0 * z0)


def wilson_flow(system: WilsonGauge, links, flow_time, num_steps: int, observable=None):
    """Flow ``links`` to time ``flow_time`` in ``num_steps`` RK3 steps.

    ``flow_time`` is a finite number ``> 0`` (concrete: it sets the step), ``num_steps`` an int
    ``>= 1`` with ``flow_time / num_steps`` below :func:`max_flow_step` (``r₃/(4d)``, module
    notes); ``links`` must be a field of ``system`` (finite, on the group, when concrete).
    Returns ``(flowed links, values)``: ``values[k]`` is ``observable(links)`` after step
    ``k + 1`` (``observable`` defaults to ``system.energy_density``). Concrete links that
    flow to non-finite values raise ``FloatingPointError``; under ``jit`` nothing can be
    inspected, and such links come back non-finite."""
    if not isinstance(system, WilsonGauge):
        raise TypeError(f"system must be a wilson_gauge(...) system, got {type(system).__name__}")
    flow_time, num_steps = _flow_arguments(system, flow_time, num_steps)
    system.space.check(links, "links")
    if observable is not None and not callable(observable):
        raise TypeError(f"observable must be a callable links -> value, got {observable!r}")
    observable = observable or system.energy_density
    velocity = _velocity(system)
    eps = flow_time / num_steps

    def body(u, _):
        u = _step(system, velocity, u, eps)
        return u, observable(u)

    flowed, values = jax.lax.scan(body, jnp.asarray(links), None, length=num_steps)
    value = concrete_array(flowed)
    if value is not None and not np.all(np.isfinite(value)):
        raise FloatingPointError(
            f"wilson_flow produced non-finite links from finite ones (flow_time = {flow_time:g} "
            f"in {num_steps} steps): check the links' dtype and that the observable and system "
            "are the ones these links belong to"
        )
    return flowed, values


def _flow_arguments(system: WilsonGauge, flow_time, num_steps) -> tuple[float, int]:
    """Checked ``(flow_time, num_steps)``: time finite and > 0, steps an int >= 1, the step
    below the RK3 stability bound (module notes)."""
    if concrete_array(flow_time) is None:
        raise TypeError(
            "flow_time must be a concrete number: it sets the flow step (and its stability "
            "check); close over it instead of passing it traced, e.g. "
            "jax.jit(lambda u: wilson_flow(system, u, 2.0, 100))"
        )
    flow_time = finite_float("flow_time", flow_time, positive=True)
    number = isinstance(num_steps, (int, float, np.integer, np.floating))
    whole = number and not isinstance(num_steps, (bool, np.bool_)) and math.isfinite(num_steps)
    if not (whole and num_steps == int(num_steps) and num_steps >= 1):
        raise ValueError(f"num_steps must be an integer >= 1, got {num_steps!r}")
    num_steps = int(num_steps)
    limit = max_flow_step(system)
    if flow_time / num_steps >= limit:
        fits = math.floor(flow_time / limit) + 1
        raise ValueError(
            f"the flow step flow_time / num_steps = {flow_time / num_steps:g} is at or past the "
            f"RK3 stability bound r3/(4d) = {limit:.4g} for a {system.dim}-dimensional lattice "
            "(the staggered mode would grow instead of being smoothed); use num_steps >= "
            f"{fits} for flow_time = {flow_time:g}, or more for accuracy"
        )
    return flow_time, num_steps


def flow_scale(times, energies, reference: float = T0_REFERENCE) -> float:
    """``t₀``: where ``t² E(t)`` first reaches ``reference`` (linear interpolation; ``nan`` if
    the flow stops short of it). ``times`` and ``energies`` are 1-D of one length (the flow
    times of :func:`wilson_flow`'s values and those values), finite, ``times`` increasing and
    ``>= 0``; ``energies`` may be a mean over configurations."""
    times = _series("times", times)
    energies = _series("energies", energies)
    if times.shape != energies.shape:
        raise ValueError(
            f"times and energies must have one length (a flow time per energy), got "
            f"{times.size} times and {energies.size} energies; for wilson_flow(system, u, T, n) "
            "the times are T * np.arange(1, n + 1) / n"
        )
    if np.any(times < 0) or np.any(np.diff(times) <= 0):
        raise ValueError("times must be >= 0 and strictly increasing (the flow times in order)")
    reference = finite_float("reference", reference, positive=True)
    y = times**2 * energies
    above = np.flatnonzero(y >= reference)
    if above.size == 0 or above[0] == 0:
        return float("nan")
    k = above[0]
    return float(np.interp(reference, y[k - 1 : k + 1], times[k - 1 : k + 1]))


def _series(name: str, values) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a 1-D array of real numbers, got {values!r}") from None
    if array.ndim != 1 or array.size < 1:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got non-finite entries")
    return array
