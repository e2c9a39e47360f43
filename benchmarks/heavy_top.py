"""Heavy top on se(3)*: throughput of the vmapped sampler, per integrator, scene and chain count.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/heavy_top.py            # ~2 min on 2 cores
    .venv/bin/python benchmarks/heavy_top.py --quick

The same timing loop as the rigid body's (``benchmarks/throughput.py``: ``vmap`` over chains of
a ``fori_loop`` carrying only the state, compilation excluded, best of repeats), on
``heavy_top(inertia=(1, 2, 4), mgl=1, chi=e₃)`` at β = 2, σ = 1, dt = 0.05, from exact Gibbs
draws (``HeavyTopGibbs.sample``). "split h" is ``split_hamiltonian=True``: the splitting
integrator composes the exact flows of the Hamiltonian's pieces instead of one Heun step.
After the timed calls, the largest Casimir drift over the chains is recorded.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax
import numpy as np

import liesample
from benchmarks import common, suites
from benchmarks.throughput import _loop, _measure
from liesample.systems import heavy_top

SUITE = {"order": 25, "title": "heavy top throughput"}

BETA, SIGMA, STEP_SIZE = 2.0, 1.0, 0.05
START = np.array([0.3, -0.2, 0.5, 0.0, 0.6, -0.8])
VARIANTS = {
    "splitting": ("splitting", False),
    "splitting, split h": ("splitting", True),
    "rkmk_heun": ("rkmk_heun", False),
    "lie_euler": ("lie_euler", False),
}
SCENES = {"all effects": {"beta": BETA, "sigma": SIGMA}, "Hamiltonian only": {"sigma": 0.0}}


def run(out_dir: Path, quick: bool, log=print) -> None:
    cfg = common.QUICK if quick else common.FULL
    chain_counts = (1, 1_000) if quick else (1, 1_000, 100_000)
    key = jax.random.key(cfg.seed + 25)
    rows = []
    for num_chains in chain_counts:
        k_start, k_chains = jax.random.split(jax.random.fold_in(key, num_chains))
        reference = heavy_top().reference(BETA, START)
        positions = reference.sample(k_start, num_chains)
        keys = jax.random.split(k_chains, num_chains)
        for label, (integrator, split) in VARIANTS.items():
            system = heavy_top(split_hamiltonian=split)
            for scene, kwargs in SCENES.items():
                algorithm = liesample.lie_poisson_langevin(
                    system, step_size=STEP_SIZE, integrator=integrator, **kwargs
                )
                states = jax.vmap(algorithm.init)(positions)
                loop = _loop(lambda k, s, step=algorithm.step: step(k, s)[0])
                final, row = _measure(loop, states, keys, num_chains, cfg)
                drift = jax.vmap(system.casimir_error)(final.position, states.reference_casimirs)
                row.update(
                    variant=label, scene=scene, max_casimir_error=float(np.max(np.asarray(drift)))
                )
                rows.append(row)
                log(
                    f"  {label:<20} {scene:<17} {num_chains:>7} chains: "
                    f"{row['chain_steps_per_second']:.3g} chain-steps/s, "
                    f"Casimir drift {row['max_casimir_error']:.1e}"
                )
    common.write_json(
        out_dir / "heavy_top.json",
        {
            "machine": common.machine_info(),
            "mode": cfg.mode,
            "beta": BETA,
            "sigma": SIGMA,
            "step_size": STEP_SIZE,
            "rows": rows,
        },
    )


def report(out_dir: Path, md_dir: Path) -> str:
    del md_dir
    path = out_dir / "heavy_top.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    rows = data["rows"]
    chain_counts = sorted({r["chains"] for r in rows})
    lines = [
        "## Heavy top: throughput",
        "",
        (
            f"From `benchmarks/heavy_top.py` ({data['mode']} mode, {data['machine']['date_utc']}, "
            f"{data['machine']['cpu_model']}, {data['machine']['usable_cpus']} CPUs). "
            "Chain-steps per second of `liesample.lie_poisson_langevin(heavy_top(...), "
            f"beta={data['beta']}, sigma={data['sigma']}, step_size={data['step_size']})` "
            "(I = (1, 2, 4), mgl = 1, χ = e₃), vmapped chains from exact Gibbs draws, "
            'compilation excluded, best of repeats; "split h" composes the exact flows of the '
            "Hamiltonian's pieces (`split_hamiltonian=True`). Last column: the largest relative "
            "Casimir drift after the timed calls."
        ),
        "",
        "| integrator | scene | "
        + " | ".join(f"{n:,} chains" for n in chain_counts)
        + " | Casimir drift |",
        "|---|---|" + "---|" * len(chain_counts) + "---|",
    ]
    for variant in VARIANTS:
        for scene in SCENES:
            cells = []
            drift = 0.0
            for n in chain_counts:
                match = [
                    r
                    for r in rows
                    if r["variant"] == variant and r["scene"] == scene and r["chains"] == n
                ]
                cells.append(f"{match[0]['chain_steps_per_second']:.3g}" if match else "–")
                drift = max([drift] + [r["max_casimir_error"] for r in match])
            lines.append(f"| {variant} | {scene} | " + " | ".join(cells) + f" | {drift:.1e} |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
