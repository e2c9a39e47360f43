"""Lattice gauge theory: 4-D SU(3) at β = 6.0 and 2-D U(1) topology (docs/gauge.md).

Rows:

1. 4-D SU(3) on ``L⁴`` (default 8⁴) at β = 6.0 from a hot start: the mean plaquette of every
   sampler against the published large-volume value 0.593683(3) (Boyd et al., Nucl. Phys. B469
   (1996) 419, Table 1, β = 6.0), ESS/s of the plaquette (ArviZ bulk ESS of the per-update
   series after thermalisation), link updates per second, for
   - ``heat bath + OR``: ``liesample.wilson_heat_bath`` (1 heat-bath + 4 over-relaxation sweeps);
   - ``HMC``: ``gauge_hmc`` (``liesample.geometric_hmc``, exact group exponentials), 25 steps
     of 0.02 (trajectory length 0.5);
   - ``SMD``: the same with ``momentum_persistence`` ``α = e^{−γε}``, ``γ = 1``, one leapfrog
     step of 0.03 per update;
   - ``plain HMC``: a leapfrog written here (matrix momenta, staple force, ``expm`` drift), the
     baseline a user would write in JAX.
2. 2-D U(1) on 16×16 at several β: the integrated autocorrelation time of the geometric charge
   ``Q`` for the heat bath + OR (topological freezing grows it with β).

Run: ``python -m benchmarks.gauge [--quick] [--size L] [--thermalisation N]``; results go to
``benchmarks/results/gauge.json`` and a Markdown table on stdout.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common
from liesample.samplers.gauge.hmc import gauge_hmc
from liesample.systems import wilson_gauge

jax.config.update("jax_enable_x64", True)

PUBLISHED_PLAQUETTE = 0.593683  # SU(3), β = 6.0, large volume (Boyd et al. 1996)
RESULTS = Path(__file__).resolve().parent / "results" / "gauge.json"


CHUNK = 10  # updates per compiled call: one compile per sampler, whatever the run length


def make_run(step, observable):
    """A jitted scan of ``CHUNK`` steps recording ``observable`` and the acceptance."""

    @jax.jit
    def run(state, keys):
        def body(s, k):
            s, info = step(k, s)
            return s, (observable(s.position), info.acceptance_rate)

        return jax.lax.scan(body, state, keys)

    return run


def _chain(run, state, key, num_updates):
    """``num_updates`` (rounded up to chunks) steps; the first chunk compiles and is not timed."""
    chunks = jax.random.split(key, -(-num_updates // CHUNK) + 1)
    jax.block_until_ready(run(state, jax.random.split(chunks[0], CHUNK)))  # compile
    values, rates = [], []
    start = time.perf_counter()
    for key in chunks[1:]:
        state, (v, r) = jax.block_until_ready(run(state, jax.random.split(key, CHUNK)))
        values.append(np.asarray(v))
        rates.append(np.asarray(r))
    seconds = time.perf_counter() - start
    return state, np.concatenate(values), float(np.mean(np.concatenate(rates))), seconds


# --------------------------------------------------------------------------- plain HMC (baseline)


def _traceless_antihermitian(m):
    a = 0.5 * (m - jnp.conj(jnp.swapaxes(m, -1, -2)))
    n = m.shape[-1]
    return a - jnp.trace(a, axis1=-2, axis2=-1)[..., None, None] * jnp.eye(n) / n


def plain_hmc(system, beta, step_size, num_steps):
    """A textbook leapfrog HMC for SU(N) (momenta ``Π`` anti-Hermitian traceless, kinetic
    ``−¼ tr Π²``, force ``−(2β/N) TA(A U)`` from the staples, drift ``U ← U expm(εΠ)``)."""
    n = system.n

    def force(links):
        forces = [
            -(2.0 * beta / n) * _traceless_antihermitian(system.staples(links, mu) @ links[mu])
            for mu in range(system.dim)
        ]
        return jnp.stack(forces)

    def kinetic(p):
        return -0.25 * jnp.sum(jnp.real(jnp.einsum("...ij,...ji->...", p, p)))

    def step(key, state):
        c = jax.random.normal(key, system.space.momentum_array_shape, jnp.float64)
        p0 = system.space.hat(c)  # unit-variance components in the basis iλ_a
        def leapfrog(k, up):
            u, p = up
            u = u @ jax.scipy.linalg.expm(step_size * p)
            return u, p + jnp.where(k < num_steps - 1, 1.0, 0.5) * step_size * force(u)

        start = (state.position, p0 + 0.5 * step_size * force(state.position))
        u, p = jax.lax.fori_loop(0, num_steps, leapfrog, start)
        energy = lambda u, p: kinetic(p) + beta * system.action(u)
        delta = energy(u, p) - energy(state.position, p0)
        accept = jax.random.uniform(jax.random.fold_in(key, 1)) < jnp.exp(-delta)  # NaN: reject
        new = jnp.where(accept, u, state.position)
        return state._replace(position=new), PlainInfo(jnp.minimum(1.0, jnp.exp(-delta)))

    return step


class PlainInfo(NamedTuple):
    acceptance_rate: jax.Array


# --------------------------------------------------------------------------- rows


def su3_rows(size, counts, thermalisation, seed=0):
    """The 4-D SU(3) rows at β = 6.0 (one chain each, from one thermalised configuration)."""
    system, beta = wilson_gauge("SU3", (size,) * 4), 6.0
    links = system.hot_start(jax.random.key(seed))
    heat_bath = liesample.wilson_heat_bath(system, beta=beta, overrelaxation=4)
    runs = {"heat bath + OR (1 + 4 sweeps)": make_run(heat_bath.step, system.mean_plaquette)}
    first = runs["heat bath + OR (1 + 4 sweeps)"]
    state, _, _, _ = _chain(first, heat_bath.init(links), jax.random.key(seed + 1), thermalisation)
    links = state.position
    # Steps for 8⁴: the energy error of a trajectory grows as V·ε⁴ (ε = 0.05 was accepted ~1%
    # of the time on 8⁴), and SMD's rejections reverse the momentum, so it needs a high rate too.
    eps, steps, eps_smd = 0.02, 25, 0.03
    samplers = {
        "heat bath + OR (1 + 4 sweeps)": (heat_bath, 5, counts["heat_bath"]),
        f"HMC (geometric_hmc, ε = {eps}, L = {steps})": (
            gauge_hmc(system, beta=beta, step_size=eps, num_integration_steps=steps), steps,
            counts["hmc"]),
        f"SMD (geometric_hmc, α = e^(-ε), ε = {eps_smd}, L = 1)": (
            gauge_hmc(system, beta=beta, step_size=eps_smd, num_integration_steps=1,
                      momentum_persistence=math.exp(-eps_smd)), 1, counts["smd"]),
        f"plain HMC (this file, expm, ε = {eps}, L = {steps})": (
            SimpleNamespace(init=heat_bath.init, step=plain_hmc(system, beta, eps, steps)), steps,
            counts["hmc"]),
    }  # fmt: skip
    rows = []
    num_links = system.dim * size**4
    for name, (sampler, sweeps, updates) in samplers.items():
        run = runs.get(name) or make_run(sampler.step, system.mean_plaquette)
        _, values, rate, seconds = _chain(run, sampler.init(links), jax.random.key(seed + 2),
                                          updates)  # fmt: skip
        rows.append(_row(name, values, rate, seconds, updates * sweeps * num_links))
        print(rows[-1], flush=True)
    return rows


def _row(name, values, rate, seconds, link_updates):
    # a chain that (almost) never moves has no meaningful ESS: report nan, not ArviZ's n
    ess = float(az.ess(values[None, :])) if rate > 0.05 else math.nan
    se = float(np.std(values, ddof=1) / math.sqrt(max(ess, 1.0)))
    return {
        "sampler": name,
        "plaquette": float(np.mean(values)),
        "mcse": se,
        "acceptance": rate,
        "ess": ess,
        "seconds": seconds,
        "ess_per_s": ess / seconds,
        "link_updates_per_s": link_updates / seconds,
    }


def u1_autocorrelation(betas, size, num_updates, seed=0):
    """Integrated autocorrelation time of ``Q`` (heat bath + OR) for each β on ``size²``."""
    rows = []
    for beta in betas:
        system = wilson_gauge("U1", (size, size))
        sampler = liesample.wilson_heat_bath(system, beta=beta, overrelaxation=1)
        run = make_run(sampler.step, system.topological_charge)
        state = sampler.init(system.hot_start(jax.random.key(seed)))
        state, _, _, _ = _chain(run, state, jax.random.key(seed + 1), num_updates // 5)
        _, q, _, seconds = _chain(run, state, jax.random.key(seed + 2), num_updates)
        ess = float(az.ess(q[None, :]))
        rows.append({"beta": beta, "tau_int_Q": len(q) / (2.0 * ess), "q2": float(np.mean(q**2)),
                     "seconds": seconds})  # fmt: skip
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4⁴ and few updates (a smoke run)")
    parser.add_argument("--size", type=int, default=8)
    parser.add_argument("--thermalisation", type=int, default=20, help="heat-bath updates")
    args = parser.parse_args(argv)
    if args.quick:
        size, therm, counts = 4, 5, {"heat_bath": 10, "hmc": 5, "smd": 20}
    else:
        counts = {"heat_bath": 40, "hmc": 20, "smd": 200}
        size, therm = args.size, args.thermalisation
    betas = (1.0, 3.0) if args.quick else (1.0, 2.0, 4.0, 6.0)
    u1 = u1_autocorrelation(betas, 8 if args.quick else 16, 200 if args.quick else 2000)
    print(u1, flush=True)
    su3 = su3_rows(size, counts, therm)
    print(f"4-D SU(3) {size}⁴, β = 6.0 (published large-volume plaquette {PUBLISHED_PLAQUETTE})")
    print("| sampler | plaquette ± MCSE | acceptance | ESS | ESS/s | link updates/s |")
    print("|---|---|---|---|---|---|")
    for r in su3:
        print(f"| {r['sampler']} | {r['plaquette']:.5f} ± {r['mcse']:.5f} | {r['acceptance']:.2f} "
              f"| {r['ess']:.0f} | {r['ess_per_s']:.3g} "
              f"| {r['link_updates_per_s']:.3g} |")  # fmt: skip
    print("\n2-D U(1): integrated autocorrelation time of Q (heat bath + OR)")
    print("| β | τ_int(Q) | ⟨Q²⟩ |")
    print("|---|---|---|")
    for r in u1:
        print(f"| {r['beta']} | {r['tau_int_Q']:.3g} | {r['q2']:.3g} |")
    if not args.quick:
        common.write_json(RESULTS, {"machine": common.machine_info(), "size": size,
                                    "su3": su3, "u1": u1})  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
