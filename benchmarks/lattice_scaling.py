"""One lattice over several devices: strong and weak scaling of a heat-bath sweep, memory per site.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/lattice_scaling.py          # ~2–4 min on 2 cores
    .venv/bin/python benchmarks/lattice_scaling.py --quick  # smoke (benchmarks/results/quick/)

Writes ``lattice_scaling.json`` and ``lattice_scaling.png``. Two samplers, each one
heat-bath sweep per step (``overrelaxation=0``), one chain:

- spins: ``liesample.heisenberg_heat_bath`` on ``liesample.systems.heisenberg((L0, L1),
  periodic=True)`` at β = 0.7, from the ordered start;
- gauge: ``liesample.wilson_heat_bath`` on ``liesample.systems.wilson_gauge("SU2", (L0, L1))``
  at β = 2, from the cold start.

Each runs through ``liesample.sample_chains`` with ``lattice_sharding=n`` (lattice axis 0 split
over ``n`` devices; ``n = 1`` is the unsharded run) in a subprocess started with
``XLA_FLAGS=--xla_force_host_platform_device_count=n``, for n = 1, 2, 4, 8:

- strong scaling: one fixed lattice, sweeps per second against ``n``;
- weak scaling: lattice axis 0 grows with ``n`` (the same slab per device), sweeps per second.

Every configuration is run three times with the same arguments: the first call compiles (its
XLA compilations are counted from JAX's ``/jax/core/compile/backend_compile_duration``
event: the step's programs and the small eager operations of the set-up; none where an
earlier row already compiled the same lattice), the next two reuse ``jax.jit``'s cache (their
compilations are counted too, and should be none); the rate is the best of those two runs'
``wall_time`` (the runner's timed chunk loop, compilation excluded, kept draws copied to the
host). On a CPU the forced host devices share
the same cores, so these rows simulate the communication pattern of a split lattice (the
neighbour exchanges XLA inserts between the slabs), not a speed-up.

Memory per site is computed from the arrays' sizes (``jax.eval_shape`` of the sampler's
``init``: nothing is run or measured): the bytes of a chain's state and of one kept draw per
site, and from their sum the largest lattice one device of 16, 80 or 141 GB (10⁹ bytes) holds
for one chain. It counts the state and one chunk of one kept draw only: a chunk of ``k`` kept
draws adds ``k`` draws, and XLA's temporaries of a sweep (staples, neighbour fields, random
numbers) come on top.
"""

from __future__ import annotations

import json
import math
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

SUITE = {"order": 61, "title": "one lattice over devices: strong and weak scaling, memory"}

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
BETA = {"spins": 0.7, "gauge": 2.0}
TITLES = {
    "spins": "Heisenberg spins, `heisenberg_heat_bath`",
    "gauge": "SU(2) gauge, `wilson_heat_bath`",
}
# mode -> device counts, and per sampler: the strong-scaling lattice, the weak-scaling slab per
# device (axis 0 is multiplied by the device count), the sweeps of one timed run
CONFIG = {
    "full": {
        "devices": (1, 2, 4, 8),
        "spins": {"strong": (64, 64), "weak": (32, 32), "sweeps": 400},
        "gauge": {"strong": (16, 16), "weak": (16, 16), "sweeps": 200},
    },
    "quick": {
        "devices": (1, 2),
        "spins": {"strong": (16, 16), "weak": (8, 16), "sweeps": 20},
        "gauge": {"strong": (8, 8), "weak": (4, 8), "sweeps": 10},
    },
}
DEVICE_GB = (16, 80, 141)
# the lattices whose memory per site is reported: the benchmark's own and a physicist's
MEMORY_CASES = (("spins", 2), ("spins", 3), ("gauge", 2), ("gauge", 4))


def build(kind: str, shape):
    """``(sampler, starts)`` for one chain of ``kind`` ("spins" or "gauge") on ``shape``."""
    if kind == "spins":
        system = liesample.systems.heisenberg(tuple(shape), periodic=True)
        sampler = liesample.heisenberg_heat_bath(system, beta=BETA[kind], overrelaxation=0)
        start = np.asarray(system.default_position)
    else:
        system = liesample.systems.wilson_gauge("SU2", tuple(shape))
        sampler = liesample.wilson_heat_bath(system, beta=BETA[kind], overrelaxation=0)
        start = np.asarray(system.cold_start())
    return sampler, start[None]


class CompileCounter:
    """Counts XLA compilations while registered (``with CompileCounter() as counter``)."""

    def __init__(self):
        self.compiles = 0
        self.seconds = 0.0

    def _duration(self, event, seconds, **kwargs):
        if event == COMPILE_EVENT:
            self.compiles += 1
            self.seconds += seconds

    def __enter__(self):
        jax.monitoring.register_event_duration_secs_listener(self._duration)
        return self

    def __exit__(self, *exc):
        jax.monitoring.unregister_event_duration_listener(self._duration)
        return False


def measure_one(kind: str, shape, devices: int, sweeps: int) -> dict:
    """One configuration: a compiling call, then two timed calls from ``jax.jit``'s cache."""
    sampler, starts = build(kind, shape)

    def call(repeat):
        with CompileCounter() as counter:
            result = liesample.sample_chains(
                sampler,
                jax.random.key(repeat),
                starts,
                2,
                thinning=sweeps // 2,
                chunk_draws=1,
                progress_bar=False,
                lattice_sharding=None if devices == 1 else devices,
            )
        return result.wall_time, counter

    first_wall, first = call(0)
    timed = [call(repeat) for repeat in (1, 2)]
    best = min(wall for wall, _ in timed)
    steps = 2 * (sweeps // 2)
    sites = math.prod(shape)
    return {
        "sampler": kind,
        "devices": devices,
        "shape": list(shape),
        "sites": sites,
        "sites_per_device": sites // devices,
        "sweeps": steps,
        "seconds": best,
        "first_call_seconds": first_wall,
        "sweeps_per_second": steps / best,
        "site_updates_per_second": steps * sites / best,
        "compiles_first_call": first.compiles,
        "compile_seconds_first_call": first.seconds,
        "compiles_timed_calls": sum(c.compiles for _, c in timed),
    }


def measure_on_devices(devices: int, mode: str) -> list[dict]:
    """Every row at one device count (run in a process that has ``devices`` devices)."""
    config = CONFIG[mode]
    rows = []
    for kind in ("spins", "gauge"):
        case = config[kind]
        weak = (case["weak"][0] * devices, *case["weak"][1:])
        for scaling, shape in (("strong", case["strong"]), ("weak", weak)):
            row = {"scaling": scaling, **measure_one(kind, shape, devices, case["sweeps"])}
            rows.append(row)
            print(
                f"  {kind:>5} {scaling:>6} {devices} dev {'×'.join(map(str, shape)):>8}: "
                f"{row['sweeps_per_second']:9.4g} sweeps/s, "
                f"{row['compiles_first_call']} + {row['compiles_timed_calls']} compiles",
                file=sys.stderr,
                flush=True,
            )
    return rows


_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
from benchmarks import lattice_scaling
import jax
print("ROWS" + json.dumps({{"devices": [str(d) for d in jax.devices()],
    "rows": lattice_scaling.measure_on_devices({devices}, {mode!r})}}))
"""


def run_forced(devices: int, mode: str) -> dict:
    """:func:`measure_on_devices` in a subprocess with ``devices`` forced host devices (the flag
    must be set before JAX starts)."""
    env = dict(os.environ)
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "force_host_platform" not in f]
    env["XLA_FLAGS"] = " ".join([*flags, f"--xla_force_host_platform_device_count={devices}"])
    env["JAX_PLATFORMS"] = "cpu"
    code = _CHILD.format(root=str(common.REPO_DIR), devices=devices, mode=mode)
    completed = subprocess.run(
        [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True, check=False
    )
    for line in completed.stdout.splitlines():
        if line.startswith("ROWS"):
            return json.loads(line[4:])
    raise RuntimeError(f"the run on {devices} forced host devices failed:\n{completed.stdout}")


def memory_per_site(kind: str, dimension: int) -> dict:
    """Bytes per site of a chain's state and of one kept draw, from the arrays' sizes, and the
    largest ``L^dimension`` lattice of one chain per device of each of :data:`DEVICE_GB`."""
    shape = (4,) * dimension
    sampler, starts = build(kind, shape)
    state = jax.eval_shape(sampler.init, starts[0])
    nbytes = lambda tree: sum(
        math.prod(leaf.shape) * np.dtype(leaf.dtype).itemsize for leaf in jax.tree.leaves(tree)
    )
    sites = math.prod(shape)
    state_bytes = nbytes(state) / sites
    draw_bytes = starts[0].nbytes / sites
    per_site = state_bytes + draw_bytes
    largest = {}
    for gb in DEVICE_GB:
        max_sites = gb * 1e9 / per_site
        side = math.floor(max_sites ** (1 / dimension) + 1e-9)
        largest[str(gb)] = {"sites": int(max_sites), "side": side}
    return {
        "sampler": kind,
        "dimension": dimension,
        "dtype": str(starts.dtype),
        "state_bytes_per_site": state_bytes,
        "draw_bytes_per_site": draw_bytes,
        "bytes_per_site": per_site,
        "largest_per_device": largest,
    }


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2))
    for ax, scaling in zip(axes, ("strong", "weak"), strict=True):
        for color, kind in zip(("C0", "C1"), ("spins", "gauge"), strict=True):
            rows = [r for r in data["rows"] if r["sampler"] == kind and r["scaling"] == scaling]
            if not rows:
                continue
            counts = [r["devices"] for r in rows]
            rates = [r["sweeps_per_second"] for r in rows]
            ends = dict.fromkeys("×".join(map(str, r["shape"])) for r in (rows[0], rows[-1]))
            shapes = "→".join(ends)
            ax.loglog(counts, rates, "o-", color=color, label=f"{kind} ({shapes})", base=2)
            ideal = [rates[0] * (n if scaling == "strong" else 1) for n in counts]
            ax.loglog(counts, ideal, ":", color=color, alpha=0.6, base=2)
        ax.set_xticks(data["config"]["devices"], [str(n) for n in data["config"]["devices"]])
        ax.set_xlabel("forced host devices (lattice axis 0 split)")
        ax.set_ylabel("heat-bath sweeps per second (one chain)")
        fixed = "fixed lattice" if scaling == "strong" else "lattice grows with the devices"
        ax.set_title(f"{scaling} scaling: {fixed}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, title="dotted: ideal", title_fontsize=8)
    fig.suptitle(
        f"lattice_sharding on one {data['machine']['usable_cpus']}-core CPU: a simulation of "
        "the communication pattern, not a speed-up",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=common.DPI)
    plt.close(fig)


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    mode = "quick" if quick else "full"
    log("1. memory per site (from the arrays' sizes)")
    memory = [memory_per_site(kind, dimension) for kind, dimension in MEMORY_CASES]
    rows, device_lists = [], {}
    for n, devices in enumerate(CONFIG[mode]["devices"], start=2):
        log(f"{n}. {devices} forced host device(s), lattice axis 0 split (subprocess)")
        child = run_forced(devices, mode)
        rows += child["rows"]
        device_lists[str(devices)] = child["devices"]
    data = {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": mode,
        "beta": BETA,
        "config": CONFIG[mode],
        "device_gb": list(DEVICE_GB),
        "rows": rows,
        "child_devices": device_lists,
        "memory": memory,
        "total_seconds": time.perf_counter() - start,
    }
    path = common.write_json(out_dir / "lattice_scaling.json", data)
    plot(data, out_dir / "lattice_scaling.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _scaling_table(data) -> list[str]:
    lines = [
        "| sampler | scaling | devices | lattice | sites per device | sweeps/s | "
        "vs 1 device | efficiency | compiles (first call + timed calls) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for kind in ("spins", "gauge"):
        for scaling in ("strong", "weak"):
            rows = [r for r in data["rows"] if r["sampler"] == kind and r["scaling"] == scaling]
            base = rows[0]["sweeps_per_second"] if rows else None
            for r in rows:
                ratio = r["sweeps_per_second"] / base
                # strong: ideal ratio n; weak: ideal ratio 1
                efficiency = ratio / r["devices"] if scaling == "strong" else ratio
                lines.append(
                    f"| {kind} | {scaling} | {r['devices']} | {'×'.join(map(str, r['shape']))} "
                    f"| {r['sites_per_device']:,} | {r['sweeps_per_second']:.3g} | "
                    f"{ratio:.2f} | {efficiency:.2f} | "
                    f"{r['compiles_first_call']} + {r['compiles_timed_calls']} |"
                )
    return lines


def _memory_table(data) -> list[str]:
    gbs = data["device_gb"]
    lines = [
        "| sampler | lattice | dtype | state B/site | kept draw B/site | "
        + " | ".join(f"largest, {gb} GB" for gb in gbs)
        + " |",
        "|---|---|---|---|---|" + "---|" * len(gbs),
    ]
    for m in data["memory"]:
        cells = []
        for gb in gbs:
            largest = m["largest_per_device"][str(gb)]
            power = str(m["dimension"]).translate(common.SUP)
            cells.append(f"{largest['side']}{power} ({largest['sites']:.2e} sites)")
        lines.append(
            f"| {m['sampler']} | {m['dimension']}-d | {m['dtype']} | "
            f"{m['state_bytes_per_site']:g} | {m['draw_bytes_per_site']:g} | "
            + " | ".join(cells)
            + " |"
        )
    return lines


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``lattice_scaling.json``, if it exists."""
    path = out_dir / "lattice_scaling.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    machine = data["machine"]
    plot_link = os.path.relpath(out_dir / "lattice_scaling.png", md_dir)
    counts = ", ".join(str(n) for n in data["config"]["devices"])
    cpu = machine["backend"] == "cpu"
    lines = [
        "## One lattice over devices: strong and weak scaling, memory per site",
        "",
        (
            f"From `benchmarks/lattice_scaling.py` ({machine['date_utc']}, "
            f"{data['total_seconds']:.0f} s, {data['mode']} mode, backend `{machine['backend']}`, "
            f"{machine['usable_cpus']} usable CPU cores, {machine['cpu_model']}, load average "
            f"{machine['load_average_1min']}; the machine was shared, so the numbers are rough). "
            f"One chain, one heat-bath sweep per step (`overrelaxation=0`; spins β = "
            f"{data['beta']['spins']}, ordered start; SU(2) β = {data['beta']['gauge']}, cold "
            f"start), through `liesample.sample_chains(..., lattice_sharding=n)`, lattice axis 0 "
            f"split over n = {counts} devices (n = 1: unsharded), each n in its own process "
            "with `XLA_FLAGS=--xla_force_host_platform_device_count=n`. Rates: the best of two "
            "runs from `jax.jit`'s cache (the runner's `wall_time`, compilation excluded, kept "
            "draws copied to the host), after a first call that compiles; the compilations of "
            "both are counted. Strong: a fixed lattice, efficiency = (rate / 1-device rate) / n; "
            "weak: axis 0 grows with n, efficiency = rate / 1-device rate."
        ),
        "",
        (
            "**A simulation of the communication pattern, not a speed-up claim:** the forced "
            f"host devices are slices of the same {machine['usable_cpus']} CPU cores, so a split "
            "lattice computes no faster here; what these rows show is the cost of the neighbour "
            "exchanges XLA inserts between the slabs, on tiny lattices where it dominates."
            if cpu
            else f"Measured on {machine['devices']}."
        ),
        "",
        *_scaling_table(data),
        "",
        (
            "Compiles: XLA compilations of the first call (the step's programs and the set-up's "
            "small eager operations; 0 where an earlier row compiled the same lattice) + those "
            "of the two timed calls."
        ),
        "",
        f"![lattice scaling]({plot_link})",
        "",
        (
            "Memory per site, from the arrays' sizes (`jax.eval_shape` of the sampler's `init`, "
            "nothing measured): a chain's state and one kept draw. The largest lattice per "
            "device is one chain's L^d whose state plus one chunk of one kept draw fit in the "
            "device's memory (GB = 10⁹ bytes); it counts the state and that one chunk of kept "
            "draws only: a chunk of k kept draws adds k draws, and XLA's temporaries of a sweep "
            "(staples, neighbour fields, random numbers) come on top, so a real run fits less."
        ),
        "",
        *_memory_table(data),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
