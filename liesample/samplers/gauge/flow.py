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
"""

from __future__ import annotations

import jax
import numpy as np

from liesample.geometry import spaces
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["flow_scale", "wilson_flow"]

T0_REFERENCE = 0.3  # t₀² E(t₀) = 0.3 (Lüscher 2010)


def _velocity(system: WilsonGauge):
    grad = spaces.trivialised_value_and_grad(lambda u: -system.action(u), system.space)
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

    Returns ``(flowed links, values)``: ``values[k]`` is ``observable(links)`` after step
    ``k + 1`` (``observable`` defaults to ``system.energy_density``)."""
    if not isinstance(system, WilsonGauge):
        raise TypeError(f"system must be a wilson_gauge(...) system, got {type(system).__name__}")
    if int(num_steps) != num_steps or num_steps < 1:
        raise ValueError(f"num_steps must be an integer >= 1, got {num_steps!r}")
    observable = observable or system.energy_density
    velocity = _velocity(system)
    eps = flow_time / num_steps

    def body(u, _):
        u = _step(system, velocity, u, eps)
        return u, observable(u)

    return jax.lax.scan(body, links, None, length=int(num_steps))


def flow_scale(times, energies, reference: float = T0_REFERENCE) -> float:
    """``t₀``: where ``t² E(t)`` first reaches ``reference`` (linear interpolation; ``nan`` if
    the flow stops short of it). ``energies`` may be a mean over configurations."""
    times, energies = np.asarray(times), np.asarray(energies)
    y = times**2 * energies
    above = np.flatnonzero(y >= reference)
    if above.size == 0 or above[0] == 0:
        return float("nan")
    k = above[0]
    return float(np.interp(reference, y[k - 1 : k + 1], times[k - 1 : k + 1]))
