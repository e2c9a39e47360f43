"""Lattice gauge theory with liesample: 2-D U(1) topology against the exact law, and a 4-D SU(3)
plaquette with the Wilson-flow scale ``t₀``.

1. 2-D U(1) on an ``L × L`` torus at coupling ``β``: the heat bath with over-relaxation
   (``liesample.recommended_sampler``) from hot starts; the plaquette and the topological
   susceptibility ``⟨Q²⟩/V`` against the exact torus laws (``liesample.targets.gauge``).
2. 4-D SU(3) on ``L⁴`` at ``β``: the mean plaquette, ``t₀`` from ``t² E(t) = 0.3`` along the
   Wilson flow of the last configuration, and that configuration's clover charge after the flow.

Every error printed is a blocking error over the chains' draws
(``liesample.diagnostics.blocking_error``), which includes the autocorrelation of the draws; its
``tau_int`` is printed with it.

Run: ``python examples/lattice_gauge.py [--quick]`` (``--quick``: small lattices, seconds).
"""

from __future__ import annotations

import argparse
import json

import jax
import numpy as np

import liesample
from liesample.diagnostics import blocking_error
from liesample.samplers.gauge.flow import flow_scale, wilson_flow
from liesample.systems import wilson_gauge
from liesample.targets import gauge as exact

jax.config.update("jax_enable_x64", True)


def u1_topology(size, beta, num_draws, num_chains=4, seed=0):
    """Plaquette and ``⟨Q²⟩/V`` of 2-D U(1) with blocking errors (``tau_int`` included) and
    exact values."""
    system = wilson_gauge("U1", (size, size))
    starts = jax.vmap(system.hot_start)(jax.random.split(jax.random.key(seed), num_chains))
    observables = {"plaquette": system.mean_plaquette, "Q": system.topological_charge}
    tree = liesample.sample(
        liesample.recommended_sampler(system, beta=beta), jax.random.key(seed + 1), starts,
        num_draws, observables=observables, keep_positions=False, progress_bar=False,
    )  # fmt: skip
    plaquette = blocking_error(np.asarray(tree.posterior["plaquette"].values))
    chi = blocking_error(np.asarray(tree.posterior["Q"].values) ** 2 / size**2)
    law = exact.u1_torus_charge_law(beta, size**2, 12)
    return {
        "plaquette": plaquette.mean,
        "plaquette_mcse": plaquette.error,
        "plaquette_tau_int": plaquette.tau_int,
        "plaquette_exact": exact.u1_torus_plaquette_mean(beta, size**2),
        "chi": chi.mean,
        "chi_mcse": chi.error,
        "chi_tau_int": chi.tau_int,
        "chi_exact": float(np.sum(law * np.arange(-12, 13) ** 2)) / size**2,
    }


def su3_scale(size, beta, num_draws, flow_time, seed=0):
    """Mean plaquette of 4-D SU(3) on ``size⁴`` (blocking error) and ``t₀`` from the flow of the
    last draw."""
    system = wilson_gauge("SU3", (size,) * 4)
    starts = system.hot_start(jax.random.key(seed))[None]
    sampler = liesample.recommended_sampler(system, beta=beta)
    tree = liesample.sample(
        sampler, jax.random.key(seed + 1), starts, num_draws, num_warmup=num_draws,
        observables={"plaquette": system.mean_plaquette}, progress_bar=False,
    )  # fmt: skip
    plaquette = blocking_error(np.asarray(tree.posterior["plaquette"].values))
    last = {part: tree.posterior[f"U.{part}"].values[0, -1] for part in ("real", "imag")}
    links = last["real"] + 1j * last["imag"]  # complex links are stored as two real parts
    num_steps = round(flow_time / 0.02)
    flowed, energies = jax.jit(lambda u: wilson_flow(system, u, flow_time, num_steps))(links)
    times = flow_time * np.arange(1, num_steps + 1) / num_steps
    return {
        "plaquette": plaquette.mean,
        "plaquette_mcse": plaquette.error,
        "plaquette_tau_int": plaquette.tau_int,
        "t0": flow_scale(times, np.asarray(energies)),
        "t2E_end": float(times[-1] ** 2 * energies[-1]),
        "Q_flowed": float(system.topological_charge(flowed)),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small lattices (seconds)")
    parser.add_argument("--output", help="write the numbers as JSON here")
    args = parser.parse_args(argv)
    if args.quick:
        u1 = u1_topology(4, 1.0, 100, 2)
        su3 = su3_scale(2, 6.0, 4, 0.1)
    else:
        u1 = u1_topology(16, 2.0, 2000)
        su3 = su3_scale(8, 6.0, 200, 4.0)
    print(f"2-D U(1): plaquette {u1['plaquette']:.4f} ± {u1['plaquette_mcse']:.4f} "
          f"(tau_int {u1['plaquette_tau_int']:.1f}; exact {u1['plaquette_exact']:.4f}); "
          f"chi = <Q²>/V {u1['chi']:.4f} ± {u1['chi_mcse']:.4f} (tau_int "
          f"{u1['chi_tau_int']:.1f}; exact {u1['chi_exact']:.4f})")  # fmt: skip
    print(f"4-D SU(3): plaquette {su3['plaquette']:.4f} ± {su3['plaquette_mcse']:.4f} (tau_int "
          f"{su3['plaquette_tau_int']:.1f}), t0/a² {su3['t0']:.3f}, clover charge after the "
          f"flow {su3['Q_flowed']:.3f}")  # fmt: skip
    if args.output:
        with open(args.output, "w") as f:
            json.dump({"u1": u1, "su3": su3}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
