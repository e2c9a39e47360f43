"""Scale-out: throughput of ``liesample.sample_chains`` against the number of chains and devices.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/scaling.py            # ~4 min on 2 cores
    .venv/bin/python benchmarks/scaling.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``scaling.json`` and ``scaling.png``. The rigid body of the other suites
(I = (1, 2, 4), β = 3, σ = 1, |μ| = 1.5, dt = 0.05, the default ``splitting`` integrator) is run
with the public runner, ``liesample.sample_chains`` (vmapped chains, chunked ``lax.scan``,
draws copied to the host after each chunk; compilation excluded from the wall time), for
1 … 10⁶ chains, on the default device and — in a subprocess started with
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` — split over two forced host devices with
``devices=2`` (:mod:`liesample.run.sharding`). Throughput is chain-steps per second. The device
kind is recorded; on a GPU machine the same file runs unchanged (the 2-device row then uses two
GPUs if there are two, else it is skipped).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import liesample
from benchmarks import common, suites

SUITE = {"order": 60, "title": "scale-out: throughput against chains and devices"}

CHAINS_FULL = (1, 10, 100, 1_000, 10_000, 100_000, 1_000_000)
CHAINS_QUICK = (1, 100, 10_000)
STEP_SIZE = 0.05
TARGET_CHAIN_STEPS = 4_000_000  # per measurement, so that each takes about a second or more


def num_steps_for(chains: int) -> int:
    """Steps per chain: about ``TARGET_CHAIN_STEPS`` chain-steps, between 8 and 4000."""
    return int(min(4000, max(8, TARGET_CHAIN_STEPS // chains)))


def measure(chains_list, devices=None, repeats=2):
    """Rows ``{chains, steps, seconds, chain_steps_per_second}`` for each number of chains."""
    system = liesample.systems.rigid_body(common.INERTIA)
    algorithm = liesample.lie_poisson_langevin(
        system, beta=common.BETA, sigma=common.SIGMA, step_size=STEP_SIZE
    )
    start = np.array([0.6, 0.8, 0.0]) * common.RADIUS
    rows = []
    for chains in chains_list:
        steps = num_steps_for(chains)
        starts = np.tile(start, (chains, 1))
        best = np.inf
        for repeat in range(repeats):
            result = liesample.sample_chains(
                algorithm,
                jax.random.key(repeat),
                starts,
                2,
                thinning=steps // 2,
                chunk_draws=1,
                progress_bar=False,
                devices=devices,
            )
            best = min(best, result.wall_time)
        total = chains * 2 * (steps // 2)
        rows.append(
            {
                "chains": chains,
                "steps": 2 * (steps // 2),
                "seconds": best,
                "chain_steps_per_second": total / best,
            }
        )
        print(f"  {chains:>8} chains  {total / best:12.4g} chain-steps/s", flush=True)
    return rows


_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
import jax
jax.config.update("jax_enable_x64", True)
from benchmarks import scaling
print("ROWS" + json.dumps({{"devices": [str(d) for d in jax.devices()],
    "rows": scaling.measure({chains!r}, devices=2)}}))
"""


def measure_two_devices(chains_list):
    """The same measurement over two forced host devices, in a subprocess (the flag must be
    set before JAX starts). ``None`` if fewer than two devices can be had."""
    env = dict(os.environ)
    if jax.default_backend() == "cpu":
        env["XLA_FLAGS"] = (
            env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
        ).strip()
    elif len(jax.devices()) < 2:
        return None
    code = _CHILD.format(root=str(common.REPO_DIR), chains=tuple(c for c in chains_list if c >= 2))
    completed = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False
    )
    for line in completed.stdout.splitlines():
        if line.startswith("ROWS"):
            return json.loads(line[4:])
    raise RuntimeError(f"two-device run failed:\n{completed.stdout}\n{completed.stderr}")


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    one = data["one_device"]
    ax.loglog(
        [r["chains"] for r in one],
        [r["chain_steps_per_second"] for r in one],
        "o-",
        label=f"1 device ({data['machine']['backend']})",
    )
    if data.get("two_devices"):
        two = data["two_devices"]["rows"]
        ax.loglog(
            [r["chains"] for r in two],
            [r["chain_steps_per_second"] for r in two],
            "s--",
            label="2 devices (forced host devices, sharded)",
        )
    ax.set_xlabel("chains")
    ax.set_ylabel("chain-steps per second")
    ax.set_title("liesample.sample_chains throughput (rigid body, splitting)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    chains = CHAINS_QUICK if quick else CHAINS_FULL
    log(f"1. one device ({jax.default_backend()}): chains {chains}")
    one = measure(chains, repeats=1 if quick else 2)
    log("2. two devices, chains sharded (subprocess)")
    two = measure_two_devices(chains)
    data = {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": "quick" if quick else "full",
        "step_size": STEP_SIZE,
        "one_device": one,
        "two_devices": two,
        "total_seconds": time.perf_counter() - start,
    }
    path = common.write_json(out_dir / "scaling.json", data)
    plot(data, out_dir / "scaling.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``scaling.json``, if it exists."""
    path = out_dir / "scaling.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    machine = data["machine"]
    one = {r["chains"]: r for r in data["one_device"]}
    two = {r["chains"]: r for r in (data["two_devices"] or {}).get("rows", [])}
    plot_link = os.path.relpath(out_dir / "scaling.png", md_dir)
    lines = [
        "## Scale-out: throughput against chains and devices",
        "",
        (
            f"From `benchmarks/scaling.py` ({machine['date_utc']}, {data['total_seconds']:.0f} s, "
            f"backend `{machine['backend']}`, {machine['usable_cpus']} usable CPU cores, "
            f"{machine['cpu_model']}; the machine was shared, so the numbers are rough). Rigid "
            f"body, `splitting`, dt = {data['step_size']}, through `liesample.sample_chains` "
            "(compilation excluded, draws copied to the host). Two devices: the same run with "
            "`devices=2` in a process with two forced host devices."
        ),
        "",
        "| chains | steps per chain | chain-steps/s, 1 device | chain-steps/s, 2 devices | 2 / 1 |",
        "|---|---|---|---|---|",
    ]
    for chains, row in one.items():
        other = two.get(chains)
        lines.append(
            f"| {chains:,} | {row['steps']} | {row['chain_steps_per_second']:.3g} | "
            + (
                f"{other['chain_steps_per_second']:.3g} | "
                f"{other['chain_steps_per_second'] / row['chain_steps_per_second']:.2f} |"
                if other
                else "— | — |"
            )
        )
    best = max(one.values(), key=lambda r: r["chain_steps_per_second"])
    ratios = [
        two[c]["chain_steps_per_second"] / one[c]["chain_steps_per_second"] for c in two if c in one
    ]
    ratio_range = f"{min(ratios):.2f}–{max(ratios):.2f}" if ratios else "not measured"
    lines += [
        "",
        f"![throughput]({plot_link})",
        "",
        (
            f"Throughput grows with the number of chains until the device is saturated (best "
            f"{best['chain_steps_per_second']:.3g} chain-steps/s at {best['chains']:,} chains): "
            "one chain is dominated by the per-step overhead of the scan. On a CPU, two forced "
            "host devices share the same cores that XLA already uses for one device, so "
            f"sharding cannot add throughput there: the 2 / 1 ratios scatter around 1 "
            f"({ratio_range}), which is the load of other jobs on this shared machine, not a "
            "gain or loss of sharding; it is the mechanism that spreads chains over "
            "several GPUs or hosts (`jax.distributed`). No GPU was available for this run."
            if machine["backend"] == "cpu"
            else f"Measured on {machine['devices']}."
        ),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
