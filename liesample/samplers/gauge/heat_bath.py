"""Heat bath with over-relaxation for the Wilson gauge action, checkerboarded over links.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). The links of one
direction ``μ`` at sites of one parity share no plaquette, so they are redrawn together from
their exact conditional law ``∝ exp((β/N) Re tr(U A))`` (``A`` the sum of staples,
:meth:`liesample.systems.wilson_gauge.WilsonGauge.staples`):

- U(1): a von Mises draw about ``−arg A`` with ``κ = β|A|``;
- SU(2): ``U ← s U`` with ``s`` drawn exactly from ``∝ exp(α ½ tr(s V))``, ``k V`` the
  quaternion part of ``U A`` and ``α = βk`` (Creutz / Kennedy–Pendleton);
- SU(N): the same in each of the ``N(N−1)/2`` SU(2) subgroups in turn (Cabibbo & Marinari 1982),
  ``α = 2βk/N``.

Over-relaxation reflects each link about the maximum of its conditional law and keeps the
action: ``θ ↦ −2 arg A − θ`` for U(1), ``s = V†²`` in each SU(2) subgroup. One step is
``heat_bath_sweeps`` heat-bath sweeps then ``overrelaxation`` over-relaxation sweeps; each
sweep visits ``2d`` classes (direction × parity). Each class move keeps ``exp(−S)`` exactly, so
there is no step size and no discretisation bias.

``β < 0`` (a normalisable law: the groups are compact) is drawn exactly too: the conditional law
of a U(1) link is then the von Mises law with ``κ = |β||A|`` about ``π − arg A``, and in each
SU(2) subgroup ``W ∝ exp(α ½ tr W)`` with ``α < 0`` is ``−W′``, ``W′ ∝ exp(|α| ½ tr W′)`` (``−I``
is central and keeps the Haar measure), so ``a₀`` is drawn at ``|α|`` and negated.
Over-relaxation keeps the action whatever the sign.

An anisotropic system (``wilson_gauge(..., anisotropy=ξ)``) weights each plane of a staple by
its own ``w_P`` (``1/ξ`` spatial, ``ξ`` temporal) in ``A``, so the conditional law above, and
each draw and reflection, is that of the anisotropic action with the one scalar ``β``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.validation import finite_float
from liesample.samplers.contract import (
    BasicInfo,
    DrawNames,
    Sampler,
    Structure,
    sampling_api,
    step_key,
)
from liesample.samplers.gauge._local import (
    quaternion_part,
    su2_from_a0,
    su2_heat_bath_a0,
    von_mises,
)
from liesample.systems.wilson_gauge import WilsonGauge

__all__ = ["GaugeState", "as_top_level_api", "build_kernel", "init", "wilson_heat_bath"]


class GaugeState(NamedTuple):
    """The links (``position``)."""

    position: jax.Array


def check_system(system) -> WilsonGauge:
    if not isinstance(system, WilsonGauge):
        raise TypeError(
            f"system must be a liesample.systems.wilson_gauge(...) system, got "
            f"{type(system).__name__}"
        )
    return system


def check_checkerboard(system: WilsonGauge) -> None:
    """Links of one direction and parity must share no plaquette: even extents on a torus."""
    odd = [s for s in system.shape if s % 2]
    if system.boundary == "periodic" and odd:
        raise ValueError(
            f"the heat bath's checkerboard needs even lattice extents on a torus, got shape "
            f"{system.shape}; use even extents, boundary='open', or liesample.geometric_hmc"
        )


def init(position, system: WilsonGauge, rng_key=None) -> GaugeState:
    """Initial state (the links are checked against the group)."""
    del rng_key
    system.space.check(position, "position")
    return GaugeState(jnp.asarray(position))


def _parity(system: WilsonGauge) -> np.ndarray:
    return np.indices(system.shape).sum(0) % 2


def _left_multiply(s, idx, u):
    """``E(s) u``, with ``E(s)`` the ``N × N`` identity holding ``s ∈ SU(2)`` (…, 2, 2) in
    rows/columns ``idx = (i, j)``: only rows ``i`` and ``j`` of ``u`` change."""
    return u.at[..., idx, :].set(s @ u[..., idx, :])


def _update_u1(system, key, theta, staple, beta, heat):
    centre = -jnp.angle(staple)
    if heat:
        mode = centre + jnp.where(beta < 0, jnp.pi, 0.0)  # the conditional law's maximum
        phi = von_mises(key, jnp.abs(beta) * jnp.abs(staple))
        return jnp.mod(mode + phi + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    return jnp.mod(2.0 * centre - theta + jnp.pi, 2.0 * jnp.pi) - jnp.pi


def _update_sun(system, key, u, staple, beta, heat):
    subgroups = np.array([(i, j) for i in range(system.n) for j in range(i + 1, system.n)])

    def one(u, inputs):
        idx, key = inputs
        r = (u @ staple)[..., idx[:, None], idx[None, :]]
        k, v = quaternion_part(r)
        v_dag = jnp.conj(jnp.swapaxes(v, -1, -2))
        if heat:
            k1, k2 = jax.random.split(key)
            a0 = su2_heat_bath_a0(k1, 2.0 * jnp.abs(beta) * k / system.n)
            a0 = jnp.where(beta < 0, -a0, a0)  # W = −W′ at α < 0 (module notes)
            s = su2_from_a0(k2, a0, u.dtype) @ v_dag
        else:
            s = v_dag @ v_dag
        return _left_multiply(s, idx, u), None

    keys = jax.random.split(key, len(subgroups))
    return jax.lax.scan(one, u, (jnp.asarray(subgroups), keys))[0]


def sweep(system: WilsonGauge, rng_key, links, beta, heat: bool):
    """One sweep over the ``2d`` classes (direction × parity): heat bath or over-relaxation.

    The classes are the iterations of one ``lax.scan`` (direction-major, class ``2μ + p``
    drawing ``split(rng_key, 2d)[2μ + p]``), so the update is compiled once whatever ``d``;
    only the staples, whose shifts depend on ``μ``, are a ``lax.switch`` over directions."""
    parity = jnp.asarray(_parity(system))
    update = _update_u1 if system.abelian else _update_sun
    keys = jax.random.split(rng_key, 2 * system.dim)
    staples = [functools.partial(_staples, system, mu) for mu in range(system.dim)]

    def one_class(links, inputs):
        index, key = inputs
        mu, p = index // 2, index % 2
        staple = jax.lax.switch(mu, staples, links)
        old = links[mu]
        new = update(system, key, old, staple, beta, heat)
        mask = parity == p
        mask = mask if system.abelian else mask[..., None, None]
        return links.at[mu].set(jnp.where(mask, new, old)), None

    return jax.lax.scan(one_class, links, (jnp.arange(2 * system.dim), keys))[0]


def _staples(system: WilsonGauge, mu: int, links):
    return system.staples(links, mu)


def build_kernel(system: WilsonGauge, heat_bath_sweeps: int = 1, overrelaxation: int = 1):
    """``kernel(rng_key, state, beta) -> (state, BasicInfo)``; the sweep counts are structural,
    ``beta`` may be traced."""
    check_system(system)
    check_checkerboard(system)

    def kernel(rng_key, state: GaugeState, beta):
        links = state.position
        if heat_bath_sweeps:
            keys = jax.random.split(rng_key, heat_bath_sweeps)
            heat = lambda links, key: (sweep(system, key, links, beta, heat=True), None)
            links = jax.lax.scan(heat, links, keys)[0]
        if overrelaxation:
            relax = lambda _, links: sweep(system, rng_key, links, beta, heat=False)
            links = jax.lax.fori_loop(0, overrelaxation, relax, links)
        energy = beta * system.action(links)
        divergent = ~(jnp.all(jnp.isfinite(links)) & jnp.isfinite(energy))
        links = jnp.where(divergent, state.position, links)
        energy = jnp.where(divergent, beta * system.action(state.position), energy)
        rate = jnp.where(divergent, 0.0, 1.0).astype(energy.dtype)
        return GaugeState(links), BasicInfo(divergent, rate, energy)

    return kernel


def _count(name, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name} must be a non-negative int (sweeps per step), got {value!r}")
    return int(value)


def as_top_level_api(
    system: WilsonGauge, *, beta: float, heat_bath_sweeps: int = 1, overrelaxation: int = 1
) -> Sampler:
    """Heat bath with over-relaxation for :func:`liesample.systems.wilson_gauge`.

    Parameters
    ----------
    system : WilsonGauge
        From :func:`liesample.systems.wilson_gauge` (even extents on a torus).
    beta : float
        The coupling ``β`` of ``S = β Σ_P w_P (1 − Re tr U_P / N)``: any finite real
        (``β < 0`` is normalisable on the compact links and drawn exactly, module notes); the
        plane weights ``w_P`` are the system's (``1/ξ`` spatial, ``ξ`` temporal with an
        ``anisotropy`` ``ξ``, else 1).
    heat_bath_sweeps : int
        Heat-bath sweeps per step (``>= 0``; with 0 the chain keeps the action and samples the
        Gibbs law only from exact starts).
    overrelaxation : int
        Over-relaxation sweeps per step (``>= 0``).

    Returns
    -------
    Sampler
        ``init(links) -> GaugeState`` and ``step(rng_key, state) -> (state, BasicInfo)``
        (``energy`` is ``β S``); jit- and vmap-able, usable with :func:`liesample.sample`.

    Examples
    --------
    >>> system = liesample.systems.wilson_gauge("U1", (4, 4))
    >>> sampler = liesample.wilson_heat_bath(system, beta=1.0)
    >>> state = sampler.init(system.cold_start())
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((2, 4, 4), False)
    """
    check_system(system)
    check_checkerboard(system)
    beta = finite_float("beta", beta)
    heat_bath_sweeps = _count("heat_bath_sweeps", heat_bath_sweeps)
    overrelaxation = _count("overrelaxation", overrelaxation)
    if heat_bath_sweeps + overrelaxation == 0:
        raise ValueError("heat_bath_sweeps + overrelaxation must be >= 1 (a step must move)")
    at = _Stepper(system, heat_bath_sweeps, overrelaxation)

    def check_positions(positions, **_):
        for c in range(np.shape(positions)[0]):
            system.space.check(positions[c], f"initial_positions[{c}]")

    settings = {
        "sampler": "wilson_heat_bath",
        "system": repr(system),
        "beta": beta,
        "heat_bath_sweeps": heat_bath_sweeps,
        "overrelaxation": overrelaxation,
    }
    names = DrawNames(system.space.draw_name, system.space.draw_dims())
    return at(
        beta,
        settings=settings,
        check_positions=check_positions,
        draw_names=names,
        structure=Structure(at, {"beta": beta}),
    )


@dataclass(frozen=True)
class _Stepper:
    """What decides the compiled step (the :class:`Structure`'s ``build``): the system (a value:
    equal lattices are one structure) and the sweep counts; called with ``beta`` (a float, or
    traced), the sampler with ``hooks``."""

    system: WilsonGauge
    heat_bath_sweeps: int
    overrelaxation: int

    def __call__(self, beta, **hooks) -> Sampler:
        kernel = build_kernel(self.system, self.heat_bath_sweeps, self.overrelaxation)

        def step_fn(rng_key, state):
            return kernel(step_key(rng_key), state, beta)

        return Sampler(functools.partial(_init_on, self.system), step_fn, **hooks)


def _init_on(system: WilsonGauge, position, rng_key=None) -> GaugeState:
    """``init(position, system)``: the links' own check (shape, dtype, on the group), which
    takes the complex SU(N) links that an orbit start's real-coordinate check refuses."""
    return init(position, system, rng_key)


wilson_heat_bath = sampling_api(as_top_level_api, init, build_kernel, "wilson_heat_bath", __name__)
