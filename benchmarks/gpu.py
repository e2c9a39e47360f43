"""The accelerator run: chains per second on one device, for the two cheapest and the costliest
state of the benchmarks, with the same code as on a CPU.

    .venv/bin/python benchmarks/gpu.py --out benchmarks/results/gpu.json          # any device
    .venv/bin/python benchmarks/gpu.py --quick --out /tmp/gpu.json                # smoke run

Two measurements, compilation excluded (each is run once to compile, then timed, best of two):

- **rigid body**: ``liesample.lie_poisson_langevin`` (the suites' rigid body, dt = 0.05) through
  ``liesample.sample_chains`` for 10² … 10⁶ chains (the rows of ``benchmarks/scaling.py``);
- **Zeitlin**: ``liesample.adjusted_lie_poisson`` on ``zeitlin_euler(N, noise_degree=2)`` at a
  given step, N = 32, 64, 128, for several numbers of chains: seconds per chain-step.

The device kind and the jax version are recorded with the rows; ``benchmarks/RESULTS.md`` quotes
them next to the CPU numbers of the same suites.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import liesample
from benchmarks import scaling

ZEITLIN_BETA = 1.0
ZEITLIN_STEP = 0.1


def zeitlin_rows(sizes, chains_list, num_steps: int):
    """Seconds per chain-step of the adjusted Zeitlin sampler, best of two timed runs."""
    rows = []
    for size in sizes:
        system = liesample.systems.zeitlin_euler(size, noise_degree=2)
        sampler = liesample.adjusted_lie_poisson(
            system, beta=ZEITLIN_BETA, step_size=ZEITLIN_STEP
        )
        for chains in chains_list:
            starts = np.tile(system.default_position, (chains, 1, 1))
            best = np.inf
            for repeat in range(3):  # the first compiles (the runner caches the executable)
                start = time.perf_counter()
                result = liesample.sample_chains(
                    sampler,
                    jax.random.key(repeat),
                    starts,
                    2,
                    thinning=num_steps // 2,
                    chunk_draws=1,
                    progress=False,
                )
                elapsed = time.perf_counter() - start
                if repeat:
                    best = min(best, result.wall_time if np.isfinite(result.wall_time) else elapsed)
            per = best / (chains * num_steps)
            rows.append(
                {"N": size, "chains": chains, "steps": num_steps, "seconds": best,
                 "seconds_per_chain_step": per,
                 "acceptance": float(np.mean(result.info["acceptance_rate"]))}  # fmt: skip
            )
            print(f"  N={size:>4} chains={chains:>5}  {per:.3e} s per chain-step", flush=True)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="JSON file to write")
    parser.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    args = parser.parse_args(argv)
    device = jax.devices()[0]
    print(f"device: {device.device_kind} ({jax.default_backend()}), jax {jax.__version__}")
    if args.quick:
        rigid = scaling.measure((1, 100), repeats=1)
        zeitlin = zeitlin_rows((8,), (4,), 20)
    else:
        rigid = scaling.measure((100, 10_000, 100_000, 1_000_000))
        zeitlin = zeitlin_rows((32, 64, 128), (1, 64, 256), 40)
    data = {
        "device": device.device_kind,
        "backend": jax.default_backend(),
        "jax": jax.__version__,
        "rigid_body": rigid,
        "zeitlin_adjusted": zeitlin,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(data, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
