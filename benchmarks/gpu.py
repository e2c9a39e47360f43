"""The accelerator run: chains per second on one device, for the two cheapest and the costliest
state of the benchmarks, with the same code as on a CPU.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``) that measures only where JAX has a
GPU: on a CPU-only machine ``run`` says so and keeps the stored ``gpu.json``. Alone::

    .venv/bin/python benchmarks/gpu.py --out benchmarks/results/gpu.json          # any device
    .venv/bin/python benchmarks/gpu.py --quick --out /tmp/gpu.json                # smoke run
    .venv/bin/python benchmarks/gpu.py --gauge 8 --out gauge8.json                # SU(3) rows
    .venv/bin/python benchmarks/gpu.py --gauge 16 --gauge-tile 2 --out gauge16.json

Two measurements, compilation excluded (each is run once to compile, then timed, best of two):

- **rigid body**: ``liesample.lie_poisson_langevin`` (the suites' rigid body, dt = 0.05) through
  ``liesample.sample_chains`` for 10² … 10⁶ chains (the rows of ``benchmarks/scaling.py``);
- **Zeitlin**: ``liesample.adjusted_lie_poisson`` on ``zeitlin_euler(N, noise_degree=2)`` at a
  given step, N = 32, 64, 128, for several numbers of chains: seconds per chain-step.

With ``--gauge L …`` it measures only the 4-D SU(3) rows of ``benchmarks/gauge.py`` on ``L⁴``
(``gauge.su3_rows``: each chain capped at ``--gauge-seconds`` timed seconds; ``--gauge-tile K``
starts from a configuration thermalised on ``(L/K)⁴`` and tiled, without the heat-bath row);
``benchmarks/results/gpu_gauge.json`` holds such runs, merged by hand with a ``runs`` list.

The device kind and the jax version are recorded with the rows; the section (``report``) quotes
them next to the CPU numbers of the scale-out and Zeitlin suites.
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
from benchmarks import common, gauge, scaling

SUITE = {"order": 65, "title": "one GPU: rigid-body throughput and the adjusted Zeitlin step"}

ZEITLIN_BETA = 1.0
ZEITLIN_STEP = 0.1
# The stored run (jax 0.11.2) predates recording the CUDA major version; it used CUDA 13.
STORED_CUDA = "13"
# SU(3) on the GPU: the updates each chain is allowed, and a cap on its timed seconds
GAUGE_COUNTS = {"heat_bath": 400, "hmc": 200, "smd": 2000}
GAUGE_THERMALISATION = 30

# Prose of the section, from the stored H200 run (the tables are rebuilt from the JSON).
RIGID_NOTE = """\
The best CPU figure of the scale-out suite on the 2-core VM is 1.82e6 chain-steps/s (1 000
chains): the H200 is about 120× that at 10⁵ chains."""

ZEITLIN_NOTE = """\
One chain is latency-bound (about 0.3 ms a step at every N). Batched, the GPU is 2.6× the CPU
at N = 64 and 10× at N = 128, but at N = 32 it is slower than the CPU, and a batched step costs
far more than its matrix work: a separate measurement in the same lease gave 0.49 ms for the
structured exponential of 64 matrices 32 × 32 and 1.2 ms for 64 of 128 × 128, against about
70 ms for one batched step at N = 32, with `noise_degree=2` and with every degree alike. Where
the rest goes on the GPU (a loop with a data-dependent trip count, host round trips in the
noise blocks, or the Metropolis bookkeeping) was not found in this lease; it is the next thing
to profile there."""


def zeitlin_rows(sizes, chains_list, num_steps: int):
    """Seconds per chain-step of the adjusted Zeitlin sampler, best of two timed runs."""
    rows = []
    for size in sizes:
        system = liesample.systems.zeitlin_euler(size, noise_degree=2)
        sampler = liesample.adjusted_lie_poisson(system, beta=ZEITLIN_BETA, step_size=ZEITLIN_STEP)
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
                    progress_bar=False,
                )
                elapsed = time.perf_counter() - start
                if repeat:
                    best = min(best, result.wall_time if np.isfinite(result.wall_time) else elapsed)
            per = best / (chains * num_steps)
            rows.append(
                {
                    "N": size,
                    "chains": chains,
                    "steps": num_steps,
                    "seconds": best,
                    "seconds_per_chain_step": per,
                    "acceptance": float(np.mean(result.info["acceptance_rate"])),
                }
            )
            print(f"  N={size:>4} chains={chains:>5}  {per:.3e} s per chain-step", flush=True)
    return rows


HEAT_BATH_PROBE = (
    "compilation of one wilson_heat_bath step (1 heat-bath + 4 over-relaxation sweeps) on L⁴, "
    "jax.jit(step).lower(...).compile(), in one process on the same device"
)


def heat_bath_compile_seconds(sizes) -> dict:
    """Seconds to compile one SU(3) heat-bath step on each ``L⁴`` (a fresh program each)."""
    seconds = {}
    for size in sizes:
        system = liesample.systems.wilson_gauge("SU3", (size,) * 4)
        sampler = liesample.wilson_heat_bath(system, beta=gauge.BETA, overrelaxation=4)
        state = sampler.init(system.cold_start())
        start = time.perf_counter()
        jax.jit(sampler.step).lower(jax.random.key(0), state).compile()
        seconds[str(size)] = round(time.perf_counter() - start, 1)
    return {"what": HEAT_BATH_PROBE, "seconds": seconds, "not_finished": {}}


def gauge_measurement(
    sizes, max_seconds: float, tile: int = 1, log=print, flow: bool = False, probe: bool = True
) -> dict:
    """4-D SU(3) at β = 6.0 on each ``L⁴`` in ``sizes``: the rows of ``benchmarks/gauge.py``
    (every chain stops once ``max_seconds`` are timed; ``tile``: see ``gauge.su3_rows``;
    ``flow``: with the flowed energy density and ``t₀``, :data:`benchmarks.gauge.FLOW`), as
    ``gpu_gauge.json``."""
    rows, start_plaquettes, scales = [], {}, {}
    extra = {}
    if probe:
        extra["heat_bath_compile_probe"] = heat_bath_compile_seconds(sorted({8, *sizes}))
        log(f"  heat-bath step compilation: {extra['heat_bath_compile_probe']['seconds']} s")
    for size in sizes:
        log(f"  SU(3) {size}⁴")
        out = gauge.su3_rows(
            size, GAUGE_COUNTS, GAUGE_THERMALISATION, log, max_seconds=max_seconds, tile=tile,
            flow=gauge.FLOW if flow else None,
        )  # fmt: skip
        start_plaquettes[size] = out[1]
        if flow:
            scales[str(size)] = out[2]
            log(f"  t0 on {size}⁴: {out[2]['t0']:.4g}")
        rows += [{"size": size, "tile": tile, **row} for row in out[0]]
    if flow:
        extra |= {"flow": gauge.FLOW, "flow_scale": scales}
    return {
        **_device_fields(),
        "machine": common.machine_info(),
        "beta": gauge.BETA,
        "thermalisation": GAUGE_THERMALISATION,
        "max_seconds": max_seconds,
        "start_plaquette": start_plaquettes,
        "published": gauge.PUBLISHED,
        "su3": rows,
        **extra,
    }


def _device_fields() -> dict:
    device = jax.devices()[0]
    return {
        "device": device.device_kind,
        "backend": jax.default_backend(),
        "jax": jax.__version__,
        "cuda": _cuda_major(),
    }


def _cuda_major():
    """The CUDA major version of the installed jax CUDA plugin, or ``None``."""
    from importlib import metadata

    for major in (13, 12, 11):
        try:
            metadata.version(f"jax-cuda{major}-plugin")
        except metadata.PackageNotFoundError:
            continue
        return str(major)
    return None


def measure(quick: bool) -> dict:
    """Both measurements on the default device, as the rows of ``gpu.json``."""
    device = jax.devices()[0]
    print(f"device: {device.device_kind} ({jax.default_backend()}), jax {jax.__version__}")
    if quick:
        rigid = scaling.measure((1, 100), repeats=1)
        zeitlin = zeitlin_rows((8,), (4,), 20)
    else:
        rigid = scaling.measure((100, 10_000, 100_000, 1_000_000))
        zeitlin = zeitlin_rows((32, 64, 128), (1, 64, 256), 40)
    return {
        **_device_fields(),
        "mode": "quick" if quick else "full",
        "zeitlin_beta": ZEITLIN_BETA,
        "zeitlin_step_size": ZEITLIN_STEP,
        "rigid_body": rigid,
        "zeitlin_adjusted": zeitlin,
    }


def run(out_dir: Path, quick: bool, log=print) -> None:
    """Measure and write ``gpu.json``, only where JAX has a GPU (else keep the stored file)."""
    if jax.default_backend() != "gpu":
        log(f"no GPU (jax backend {jax.default_backend()}): gpu.json kept, nothing measured")
        return
    path = common.write_json(out_dir / "gpu.json", measure(quick))
    log(f"wrote {path}")


def _short_e(value: float, digits: int) -> str:
    """``1.43e6`` rather than ``1.43e+06``."""
    mantissa, exponent = f"{value:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _spaced(number: int) -> str:
    """``10 000``: thousands separated by a space."""
    return f"{number:,}".replace(",", " ")


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``gpu.json`` (with the CPU column from ``zeitlin_adjusted.json``) and
    ``gpu_gauge.json`` (with the CPU column from ``gauge.json``), where they exist."""
    del md_dir
    parts = []
    if (out_dir / "gpu.json").exists():
        parts.append(section(common.read_json(out_dir / "gpu.json"), out_dir))
    if (out_dir / "gpu_gauge.json").exists():
        parts.append(gauge_section(common.read_json(out_dir / "gpu_gauge.json"), out_dir))
    return "\n".join(parts)


def _flow_lines(data: dict, short: str) -> list[str]:
    """The flowed energy density's rows (``--gauge-flow``) and the flow's ``t₀``."""
    rows = [r for r in data["su3"] if "flowed_t2e" in r]
    if not rows:
        return []
    flow = data["flow"]
    lines = [
        "",
        f"Flowed energy density (`--gauge-flow`): up to {flow['kept']} configurations a chain, "
        "evenly spaced over its timed updates, each flowed to t = "
        f"{flow['time']:g} in {flow['steps']} RK3 steps (`liesample.samplers.gauge.flow`); "
        f"t²E(t) at t = {flow['at']:g} with ArviZ's bulk ESS over the configurations, ESS/s "
        "over the chain's sampling time (the flow itself is not timed).",
        "",
        f"| L⁴ | sampler | configurations (updates apart) | t²E(t) ± MCSE | ESS | "
        f"ESS/s ({short}) |",
        "|---|---|---:|---|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['size']}⁴ | {r['sampler']} | {r['flowed_configurations']} "
            f"({r['updates_between_flowed']}) | {r['flowed_t2e']:.4f} ± {r['flowed_mcse']:.4f} | "
            f"{common.format_g(r['flowed_ess'])} | {common.format_g(r['flowed_ess_per_s'])} |"
        )
    for size, scale in data.get("flow_scale", {}).items():
        t = np.asarray(scale["times"])
        y = t**2 * np.asarray(scale["mean_energy"])
        found = (
            f"t₀ = {scale['t0']:.3g}"
            if np.isfinite(scale["t0"])
            else f"t₀ not reached: the mean t²E(t) stays below 0.3 up to t = {t[-1]:g}"
        )
        lines += [
            "",
            f"On {size}⁴, over every row's configurations: {found} (t²E = "
            f"{y[len(y) // 4]:.3f} at t = {t[len(t) // 4]:g}, {y[-1]:.3f} at t = {t[-1]:g}).",
        ]
    return lines


def gauge_section(data: dict, out_dir: Path) -> str:
    """The SU(3) rows measured on the device, beside the CPU rows of ``gauge.json``."""
    cpu_path = out_dir / "gauge.json"
    cpu = common.read_json(cpu_path) if cpu_path.exists() else {"su3": [], "size": None}
    cpu_rate = {r["sampler"]: r["link_updates_per_s"] for r in cpu["su3"]}
    short = data["device"].removeprefix("NVIDIA ").split()[0]
    runs = data.get("runs", [{"sizes": sorted({r["size"] for r in data["su3"]}), "tile": 1}])
    lines = [
        f"### Lattice gauge theory on the {data['device']}",
        "",
        (
            f"`benchmarks/gpu.py --gauge L` (jax {data['jax']}, float64): the SU(3) rows of the "
            f"lattice-gauge suite at β = {data['beta']:g}, each chain run until its updates are "
            "done or its cap of timed seconds has passed (compilation excluded), from a "
            f"configuration thermalised by {data['thermalisation']} heat-bath updates. "
            "Above 8⁴ the steps shrink as 8/L (HMC keeps its trajectory length). The CPU "
            f"column is the lattice-gauge suite's own run on the CPU VM ({cpu['size']}⁴), "
            "another machine and another time."
        ),
        "",
    ]
    for run in runs:
        sizes = ", ".join(f"{size}⁴" for size in run["sizes"])
        how = (
            "thermalised on its own lattice"
            if run["tile"] == 1
            else f"from a configuration thermalised on the {run['tile']}-times smaller torus and "
            f"repeated {run['tile']} times along each axis; no heat-bath row"
        )
        when = run.get("date_utc", data["machine"]["date_utc"])
        lines.append(f"- {sizes} ({when}, cap {run.get('max_seconds', data['max_seconds']):g} s): "
                     f"{how}.")  # fmt: skip
    lines += [
        "",
        f"| L⁴ | sampler | ε × steps | updates | plaquette ± MCSE | acceptance | ESS | ESS/s "
        f"({short}) | link updates/s ({short}) | link updates/s (CPU VM) | {short} / CPU |",
        "|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in data["su3"]:
        on_cpu = cpu_rate.get(r["sampler"]) if r["size"] == cpu["size"] else None
        ratio = f"{r['link_updates_per_s'] / on_cpu:.0f}×" if on_cpu else "–"
        step = "–" if r["step_size"] is None else f"{r['step_size']:g} × {r['steps']}"
        lines.append(
            f"| {r['size']}⁴ | {r['sampler']} | {step} | {r['updates']} | {r['plaquette']:.5f} ± "
            f"{r['mcse']:.5f} | {r['acceptance']:.2f} | {common.format_g(r['ess'])} | "
            f"{common.format_g(r['ess_per_s'])} | {common.format_rate(r['link_updates_per_s'])} | "
            f"{common.format_rate(on_cpu)} | {ratio} |"
        )
    lines += [
        "",
        "Where the ESS is a few, the plaquette and its MCSE are not estimates to rely on; the "
        "link updates per second are.",
    ]
    lines += _flow_lines(data, short)
    probe = data.get("heat_bath_compile_probe")
    if probe:
        done = ", ".join(f"{size}⁴: {sec:g} s" for size, sec in probe["seconds"].items())
        missing = "".join(f"; {size}⁴: {why}" for size, why in probe["not_finished"].items())
        when = f" ({probe['date_utc']})" if "date_utc" in probe else ""
        lines += ["", f"Heat bath on the device{when}, {probe['what']}: {done}{missing}."]
    return "\n".join(lines + [""])


def section(data: dict, out_dir: Path) -> str:
    """The Markdown section of one ``gpu.json`` (``out_dir`` holds the CPU suite's JSON)."""
    device = data["device"]
    short = device.removeprefix("NVIDIA ")
    cuda = data.get("cuda", STORED_CUDA)
    toolkit = f" with CUDA {cuda}" if cuda else ""
    lines = [
        "## One GPU: rigid-body throughput and the adjusted Zeitlin step",
        "",
        (
            "`benchmarks/gpu.py --out benchmarks/results/gpu.json`, run once on an "
            f"**{device}** (jax"
        ),
        (
            f"{data['jax']}{toolkit}, float64), the same code as on the CPU. "
            "Compilation is excluded; each row"
        ),
        "is the best of the timed repeats.",
        "",
        "Rigid body (`lie_poisson_langevin`, dt = 0.05, the rows of the scale-out suite):",
        "",
        f"| chains | chain-steps/s ({short}) |",
        "|---:|---:|",
    ]
    for row in data["rigid_body"]:
        lines.append(f"| {_spaced(row['chains'])} | {_short_e(row['chain_steps_per_second'], 2)} |")
    zeitlin = data["zeitlin_adjusted"]
    chains_list = sorted({row["chains"] for row in zeitlin})
    cpu_path = out_dir / "zeitlin_adjusted.json"
    cpu = (
        {
            row["N"]: row["seconds_per_chain_step"]
            for row in common.read_json(cpu_path)["one_thread"]
        }
        if cpu_path.exists()
        else {}
    )
    beta = data.get("zeitlin_beta", ZEITLIN_BETA)
    step = data.get("zeitlin_step_size", ZEITLIN_STEP)
    lines += [
        "",
        RIGID_NOTE,
        "",
        (
            "Adjusted Zeitlin step (`adjusted_lie_poisson`, `zeitlin_euler(N, noise_degree=2)`, "
            f"β = {beta:g},"
        ),
        f"given step {step:g}), seconds per chain-step:",
        "",
        "| N | "
        + " | ".join(f"{c} chain" + ("s" if c > 1 else "") for c in chains_list)
        + " | CPU VM, this session's Zeitlin section |",
        "|---:|" + "---:|" * (len(chains_list) + 1),
    ]
    per = {(row["N"], row["chains"]): row["seconds_per_chain_step"] for row in zeitlin}
    for size in sorted({row["N"] for row in zeitlin}):
        cells = [_short_e(per[size, c], 1) if (size, c) in per else "–" for c in chains_list]
        cells.append(_short_e(cpu[size], 1) if size in cpu else "–")
        lines.append(f"| {size} | " + " | ".join(cells) + " |")
    lines += ["", ZEITLIN_NOTE, ""]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="JSON file to write")
    parser.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    parser.add_argument(
        "--gauge",
        type=int,
        nargs="+",
        metavar="L",
        help="only 4-D SU(3) on these L⁴ (the rows of benchmarks/gauge.py), as gpu_gauge.json",
    )
    parser.add_argument("--gauge-seconds", type=float, default=25.0, help="timed seconds a chain")
    parser.add_argument(
        "--gauge-flow", action="store_true", help="also the flowed energy density's ESS and t₀"
    )
    parser.add_argument(
        "--no-probe", action="store_true", help="skip the heat-bath compilation probe"
    )
    parser.add_argument(
        "--gauge-tile", type=int, default=1, help="thermalise on (L/K)⁴ and tile (no heat bath)"
    )
    args = parser.parse_args(argv)
    if args.gauge:
        data = gauge_measurement(
            args.gauge, args.gauge_seconds, args.gauge_tile, lambda m: print(m, flush=True),
            flow=args.gauge_flow, probe=not args.no_probe,
        )  # fmt: skip
    else:
        data = measure(args.quick)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(data, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
