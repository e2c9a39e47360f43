"""Time to a first draw: what one ``liesample.sample`` call costs a user, compilation included.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/first_draw.py            # benchmarks/results/first_draw.json
    .venv/bin/python benchmarks/first_draw.py --quick    # benchmarks/results/quick/
    .venv/bin/python benchmarks/first_draw.py --quick --families gauge_hmc,magnetic_hmc

For every sampler family, built as the README shows (``benchmarks/_first_draw_driver.py`` has
the builders: float64, 4 chains, a short run with the sampler's own warm-up), five scenarios,
each in fresh interpreters so that "first" means first:

1. first call: build the system and the sampler, then ``liesample.sample``;
2. repeated call: ``sample`` again on the same objects (same process as 1);
3. rebuilt call: system and sampler built again from equal arguments, then ``sample`` (same
   process as 1 and 2);
4. a sweep: each point builds its system and sampler at another value of one constant (``β``;
   for the log-density samplers a constant of the model, passed by the sampler's documented
   ``model_args=`` where it takes one, else through a new closure per point; the JSON records
   which); in quick mode fewer points, and the ten-point total is projected from them;
5. second process: a process runs call 1 with liesample's default persistent compilation cache
   on (``liesample.foundation.cache``, pointed at a fresh temporary folder by
   ``XDG_CACHE_HOME``), then a new process runs call 1 again; the second is timed.

Scenarios 1–4 run with ``LIESAMPLE_COMPILATION_CACHE=0`` (no persistent cache). Each call is
timed whole, with the number and seconds of the XLA backend compilations it caused (JAX's
``/jax/core/compile/backend_compile_duration`` event), its tracing and lowering seconds, and
the run's ``sampling_time`` attribute (compilation excluded). The targets are recorded beside
the numbers (:data:`TARGETS`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import common
from benchmarks._first_draw_driver import SWEEP_POINTS

SUITE = {"order": 7, "title": "Time to a first draw: compile once, by call"}

ROOT = Path(__file__).resolve().parents[1]
DRIVER = "benchmarks._first_draw_driver"
PROCESS_TIMEOUT = 300  # seconds one driver process may take before it is recorded as failed

# family -> (model, how the README builds it, the swept constant)
FAMILIES = {
    "lie_poisson_langevin": ("rigid body", "`lie_poisson_langevin(rigid_body(…), beta, sigma=1, "
                             "step_size=0.05)`", "β"),
    "adjusted_lie_poisson": ("rigid body", "`adjusted_lie_poisson(rigid_body(…), beta, "
                             "sigma=1)`, step tuned", "β"),
    "vortex_metropolis": ("4 point vortices", "`vortex_metropolis(point_vortices(…), beta)`", "β"),
    "zeitlin": ("Zeitlin su(N)", "`recommended_sampler(zeitlin_euler(N), beta)`",
                "b = β‖W‖²/(N²−1)"),
    "heisenberg_heat_bath": ("Heisenberg 8³", "`heisenberg_heat_bath(heisenberg((8, 8, 8)), "
                             "beta)`", "β"),
    "heisenberg_cluster": ("Heisenberg 8³", "`heisenberg_cluster(heisenberg((8, 8, 8)), beta)`",
                           "β"),
    "wilson_heat_bath": ("SU(2) 8×8", "`wilson_heat_bath(wilson_gauge(\"SU2\", (8, 8)), beta)`",
                         "β"),
    "gauge_hmc": ("SU(2) 8×8", "`gauge_hmc(wilson_gauge(\"SU2\", (8, 8)), beta, step_size=0.1, "
                  "num_integration_steps=10)`", "β"),
    "geometric_hmc": ("von Mises–Fisher on S²", "`geometric_hmc(logdensity, Sphere(2))`, "
                      "step adapted", "κ"),
    "magnetic_hmc": ("5-D Gaussian", "`magnetic_hmc(logdensity)`, ChEES-adapted", "the sd"),
}  # fmt: skip

TARGETS = {
    "repeated": "wall ≤ sampling time + 0.1 s",
    "rebuilt": "wall ≤ sampling time + 0.1 s",
    "sweep": "ten points ≤ 1.3 × one point (the sweep's first point)",
    "first": "Zeitlin su(32) ≤ 3 s; SU(2) 8×8 heat bath ≤ 2 s",
    "second_process": "wall ≤ 1.5 s + sampling time",
}
FIRST_CALL_LIMITS = {"zeitlin_su32": 3.0, "wilson_heat_bath": 2.0}
# how the driver passed the swept constant -> its words in the sweep table
PASSED_AS = {"beta=": ", `beta=`", "model_args": ", `model_args=`",
             "closure": ", a new closure per point"}  # fmt: skip
SLACK_SECONDS, SWEEP_RATIO, SECOND_PROCESS_SECONDS = 0.1, 1.3, 1.5


def family_names(quick: bool) -> list[str]:
    """The driver's family names (Zeitlin su(16) in quick mode, su(32) in full mode)."""
    zeitlin = "zeitlin_su16" if quick else "zeitlin_su32"
    return [zeitlin if name == "zeitlin" else name for name in FAMILIES]


def _kind(family: str) -> str:
    """The :data:`FAMILIES` key of a driver family name."""
    return "zeitlin" if family.startswith("zeitlin") else family


# --------------------------------------------------------------------------- measuring


def _environment(cache_home: str | None) -> dict:
    """The driver's environment: no persistent cache, or liesample's default one under
    ``cache_home`` (no user-configured cache either way)."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR",)}
    env["PYTHONPATH"] = str(ROOT)
    if cache_home is None:
        env["LIESAMPLE_COMPILATION_CACHE"] = "0"
    else:
        env.pop("LIESAMPLE_COMPILATION_CACHE", None)
        env["XDG_CACHE_HOME"] = cache_home
    return env


def _driver(family: str, scenario: str, quick: bool, cache_home: str | None = None) -> dict:
    """One fresh interpreter running ``scenario``; its JSON, or ``{"error": …}``."""
    argv = [sys.executable, "-m", DRIVER, family, scenario] + (["--quick"] if quick else [])
    begin = time.perf_counter()
    try:
        out = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT,
                             env=_environment(cache_home), timeout=PROCESS_TIMEOUT)  # fmt: skip
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {PROCESS_TIMEOUT} s"}
    seconds = time.perf_counter() - begin
    if out.returncode != 0:
        return {"error": _exception_line(out.stderr)}
    return json.loads(out.stdout.strip().splitlines()[-1]) | {"process_seconds": seconds}


def _exception_line(stderr: str) -> str:
    """The exception a failed driver raised: the last line of its traceback that names one."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    named = [line for line in lines if re.match(r"^[\w.]+(Error|Exception|Interrupt)\b", line)]
    return (named or lines or ["failed without a message"])[-1]


def _cache_entries(cache_home: str) -> int:
    """Files in liesample's cache folder under ``cache_home``."""
    folder = Path(cache_home) / "liesample" / "jax"
    return sum(1 for _ in folder.glob("*-cache")) if folder.is_dir() else 0


def measure_family(family: str, quick: bool, log) -> dict:
    """Every scenario of one family (four fresh interpreters)."""
    log(f"first_draw: {family}: first, repeated and rebuilt calls")
    row = {"calls": _driver(family, "calls", quick)}
    log(f"first_draw: {family}: a sweep")
    row["sweep"] = _driver(family, "sweep", quick)
    log(f"first_draw: {family}: a second process with the compilation cache on")
    with tempfile.TemporaryDirectory(prefix="liesample-first-draw-") as cache_home:
        row["cache_first"] = _driver(family, "first", quick, cache_home)
        row["cache_entries"] = _cache_entries(cache_home)
        row["cache_second"] = _driver(family, "first", quick, cache_home)
    return row


def run(out_dir: Path, quick: bool, log=print, families=None) -> None:
    """Measure every family (or those named in ``families``), write ``first_draw.json`` and
    ``first_draw.png``."""
    start = time.perf_counter()
    mode = "quick" if quick else "full"
    data = {"description": __doc__, "machine": common.machine_info(), "mode": mode,
            "sweep_points": SWEEP_POINTS[mode], "targets": TARGETS,
            "families": {}}  # fmt: skip
    for family in family_names(quick):
        if families is None or family in families or _kind(family) in families:
            data["families"][family] = measure_family(family, quick, log)
    data["total_seconds"] = time.perf_counter() - start
    data["load_average_1min_after"] = round(os.getloadavg()[0], 2)
    log(f"wrote {common.write_json(out_dir / 'first_draw.json', data)}")
    log(f"wrote {plot(data, out_dir / 'first_draw.png')}")


# --------------------------------------------------------------------------- the verdicts


def _call(row: dict, scenario: str) -> dict | None:
    """The measured call of ``scenario`` in a family's row (``None`` where it failed)."""
    if scenario == "second_process":
        return row["cache_second"].get("calls", {}).get("first")
    return row["calls"].get("calls", {}).get(scenario)


def sweep_totals(row: dict) -> dict | None:
    """The sweep's first point, its later points' mean, and the ten-point total (measured with
    ten points, projected as first + 9 × mean of the later points with fewer)."""
    points = row["sweep"].get("calls", {}).get("points")
    if not points:
        return None
    walls = [p["wall_seconds"] for p in points]
    later = walls[1:]
    mean_later = sum(later) / len(later) if later else 0.0
    ten = sum(walls) if len(walls) == 10 else walls[0] + 9 * mean_later
    return {"points": len(walls), "first": walls[0], "later_mean": mean_later, "ten": ten,
            "ratio": ten / walls[0], "projected": len(walls) != 10,
            "compiles": sum(p["compiles"] for p in points),
            "compile_seconds": sum(p["compile_seconds"] for p in points),
            "later_compiles": sum(p["compiles"] for p in points[1:])}  # fmt: skip


def verdict(family: str, row: dict, scenario: str) -> tuple[str, bool | None]:
    """``(the target as a number, met)`` for one family and scenario; ``met`` is ``None``
    where the scenario has no target for that family or its measurement failed."""
    if scenario == "sweep":
        totals = sweep_totals(row)
        if totals is None:
            return "≤ 1.3 × one point", None
        limit = SWEEP_RATIO * totals["first"]
        return f"≤ {limit:.2f} s", totals["ten"] <= limit
    call = _call(row, scenario)
    if scenario == "first":
        limit = FIRST_CALL_LIMITS.get(family)
        if limit is None or call is None:
            return "–", None
        return f"≤ {limit:g} s", call["wall_seconds"] <= limit
    if call is None:
        return "–", None
    slack = SECOND_PROCESS_SECONDS if scenario == "second_process" else SLACK_SECONDS
    limit = (call["sampling_seconds"] or 0.0) + slack
    return f"≤ {limit:.2f} s", call["wall_seconds"] <= limit


# --------------------------------------------------------------------------- the plot


def _segments(row: dict, scenario: str) -> tuple[float, float, float, float]:
    """``(XLA compile, tracing + lowering, sampling, the rest)`` seconds of one bar."""
    if scenario == "sweep":
        calls = row["sweep"].get("calls", {}).get("points") or []
    else:
        call = _call(row, scenario)
        calls = [] if call is None else [call]
    wall = sum(c["wall_seconds"] for c in calls)
    compile_ = sum(c["compile_seconds"] for c in calls)
    trace = sum(c["trace_lower_seconds"] for c in calls)
    sampling = sum(c["sampling_seconds"] or 0.0 for c in calls)
    return compile_, trace, sampling, max(0.0, wall - compile_ - trace - sampling)


PANELS = (("first", "1. first call"), ("repeated", "2. repeated call"),
          ("rebuilt", "3. rebuilt call"), ("sweep", "4. sweep (all points)"),
          ("second_process", "5. second process"))  # fmt: skip


def plot(data: dict, path: Path) -> Path:
    """Stacked horizontal bars per family, one panel per scenario: XLA compilation, tracing
    and lowering, sampling, and the rest of the call's wall time (linear axes: stacked parts
    keep their proportions; each panel has its own scale)."""
    from matplotlib.figure import Figure

    names = list(data["families"])
    fig = Figure(figsize=(15, 0.45 * len(names) + 2.0))
    for index, (scenario, title) in enumerate(PANELS):
        ax = fig.add_subplot(1, len(PANELS), index + 1)
        segments = [_segments(data["families"][n], scenario) for n in names]
        left = [0.0] * len(names)
        for part, (label, colour) in enumerate(
            (("XLA compile", "C3"), ("trace + lower", "C1"), ("sampling", "C2"), ("rest", "C0"))
        ):
            widths = [s[part] for s in segments]
            ax.barh(range(len(names)), widths, left=left, color=colour, label=label)
            left = [a + b for a, b in zip(left, widths, strict=True)]
        ax.set_yticks(range(len(names)), names if index == 0 else [""] * len(names))
        ax.invert_yaxis()
        ax.set_title(title)
        ax.set_xlabel("seconds")
    handles, labels = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize="small")
    fig.suptitle(f"time to a first draw ({data['mode']} mode)")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return common.save_figure(fig, path)


# --------------------------------------------------------------------------- the report


def _s(x) -> str:
    return common.format_or_dash(x, 3)


def _mark(met: bool | None) -> str:
    return {True: "met", False: "**missed**", None: "–"}[met]


def _failed(part: dict) -> str | None:
    """The error of a failed driver process, for a table cell."""
    return f"failed: `{part['error'][:120]}`" if "error" in part else None


def _call_rows(data: dict, scenario: str) -> list[str]:
    """The table of scenario ``first``, ``repeated`` or ``rebuilt``."""
    first = scenario == "first"
    lines = [
        "| family | model | wall (s) | XLA compiles | XLA compile (s) | trace + lower (s) | "
        "sampling (s) |" + (" import (s) |" if first else "") + " target | |",
        "|---|---|---:|---:|---:|---:|---:|" + ("---:|" if first else "") + "---|---|",
    ]
    for family, row in data["families"].items():
        model = FAMILIES[_kind(family)][0]
        model = f"{model} ({family[len('zeitlin_') :]})" if _kind(family) == "zeitlin" else model
        failed, call = _failed(row["calls"]), _call(row, scenario)
        if failed or call is None:
            lines.append(f"| `{family}` | {model} | {failed or '–'} |")
            continue
        target, met = verdict(family, row, scenario)
        imported = f" {_s(row['calls']['import_seconds'])} |" if first else ""
        lines.append(
            f"| `{family}` | {model} | {_s(call['wall_seconds'])} | {call['compiles']} | "
            f"{_s(call['compile_seconds'])} | "
            f"{_s(call['trace_lower_seconds'])} | "
            f"{_s(call['sampling_seconds'])} |{imported} {target} | {_mark(met)} |"
        )
    return lines


def _sweep_rows(data: dict) -> list[str]:
    lines = [
        "| family | swept, passed as | points | first point (s) | later points, mean (s) | "
        "ten points (s) | XLA compiles after the first point | ten / one | target | |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for family, row in data["families"].items():
        swept = FAMILIES[_kind(family)][2]
        failed, totals = _failed(row["sweep"]), sweep_totals(row)
        swept += PASSED_AS.get(row["sweep"].get("passed_as"), "")
        if failed or totals is None:
            lines.append(f"| `{family}` | {swept} | {failed or '–'} |")
            continue
        target, met = verdict(family, row, "sweep")
        ten = _s(totals["ten"]) + (" (projected)" if totals["projected"] else "")
        lines.append(
            f"| `{family}` | {swept} | {totals['points']} | {_s(totals['first'])} | "
            f"{_s(totals['later_mean'])} | {ten} | {totals['later_compiles']} | "
            f"{totals['ratio']:.2f} | {target} | {_mark(met)} |"
        )
    return lines


def _second_process_rows(data: dict) -> list[str]:
    lines = [
        "| family | first process: wall (s) | programs cached | second process: wall (s) | "
        "XLA compiles | XLA compile (s) | cache loads (s) | sampling (s) | target | |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for family, row in data["families"].items():
        failed = _failed(row["cache_first"]) or _failed(row["cache_second"])
        if failed:
            lines.append(f"| `{family}` | {failed} |")
            continue
        cold, warm = row["cache_first"]["calls"]["first"], _call(row, "second_process")
        target, met = verdict(family, row, "second_process")
        lines.append(
            f"| `{family}` | {_s(cold['wall_seconds'])} | {row['cache_entries']} | "
            f"{_s(warm['wall_seconds'])} | {warm['compiles']} | {_s(warm['compile_seconds'])} | "
            f"{warm['cache_loads']} ({_s(warm['cache_load_seconds'])}) | "
            f"{_s(warm['sampling_seconds'])} | {target} | {_mark(met)} |"
        )
    return lines


def _tally(data: dict) -> tuple[int, int]:
    """``(met, with a verdict)`` over every family and scenario."""
    verdicts = [
        verdict(family, row, scenario)[1]
        for family, row in data["families"].items()
        for scenario, _ in PANELS
    ]
    return sum(v is True for v in verdicts), sum(v is not None for v in verdicts)


def _how_built(data: dict) -> list[str]:
    lines = ["| family | built as |", "|---|---|"]
    for family in data["families"]:
        lines.append(f"| `{family}` | {FAMILIES[_kind(family)][1]} |")
    return lines


MISSES = (
    "**What the misses are.** No repeated, rebuilt or swept call compiles anything (the "
    "compile columns): what is left is not compilation. A first call compiles its step's body "
    "once, into the one program that runs the warm-up (dual averaging's adaptation included) "
    "and every chunk; XLA's compile of that program for a Zeitlin or SU(2) heat-bath step, and "
    "for Zeitlin the program of its step-size rule (the orbit's curvature), take most of the "
    "call, and the import column is paid before it. A repeated Zeitlin call runs its "
    "dual-averaging warm-up before the timed sampling (the sampling column counts the chunks; "
    "a heat bath's warm-up steps run inside it), and a rebuilt one evaluates its step-size rule "
    "again (one run of a compiled program). Beyond that a call on a lattice spends its extra "
    "time in the run's convergence checks (rank-normalised R-hat and bulk/tail ESS of every "
    "lattice element, screened), which stay on by default, and a rebuilt system traces its "
    "programs again to find them in the cache (the trace column). "
    "A sweep's ratio is bounded below by the sampling each point must do: where one point's "
    "sampling is not small against its first compile (the lattices), ten points cannot cost "
    "1.3 times one. A second process still imports liesample and traces and lowers every "
    "program before the persistent cache can serve it: on a machine where the import alone "
    "takes most of the allowance (the first table's import column), that target is out of "
    "reach. The targets are seconds on two cores, so a slower machine misses more of them; the "
    "compile counts do not depend on the machine."
)
"""The explanation of the missed targets (what the measurements show, no numbers)."""


def report_section(data: dict, plot_link: str) -> str:
    """The ``RESULTS.md`` section for the contents of ``first_draw.json``."""
    machine = data["machine"]
    any_row = next(iter(data["families"].values()), {}).get("calls", {})
    met, judged = _tally(data)
    lines = [
        f"## {SUITE['title']}",
        "",
        (
            f"From `benchmarks/first_draw.py` ({machine['date_utc']}, {data['mode']} mode, "
            f"{data['total_seconds']:.0f} s, {machine['cpu_model']}, {machine['usable_cpus']} "
            f"usable CPUs, 1-min load average {machine.get('load_average_1min')} before and "
            f"{data.get('load_average_1min_after')} after, jax {machine['jax']}, "
            f"{machine['backend']}, float64). What one `liesample.sample` call costs a user, "
            "compilation included: each family built as the README shows "
            f"({any_row.get('num_chains', '–')} chains, {any_row.get('num_warmup', '–')} "
            f"warm-up steps and {any_row.get('num_draws', '–')} draws), in fresh interpreters "
            "without the persistent compilation cache (`LIESAMPLE_COMPILATION_CACHE=0`) except "
            "in scenario 5. Wall is the whole call (building the system and sampler included "
            "in scenarios 1, 3 and 4); XLA compiles count JAX's backend compilations during the "
            "call; sampling is the tree's `sampling_time` attribute (compilation excluded). "
            "Times on a shared machine are rough; the counts are not."
        ),
        "",
        f"Targets met: {met} of {judged} (a dash: no target for that family, or no measurement).",
        "",
        *_how_built(data),
        "",
        f"**1. First call** (target: {TARGETS['first']}):",
        "",
        *_call_rows(data, "first"),
        "",
        f"**2. Repeated call**, the same objects (target: {TARGETS['repeated']}):",
        "",
        *_call_rows(data, "repeated"),
        "",
        f"**3. Rebuilt call**, system and sampler built again from equal arguments (target: "
        f"{TARGETS['rebuilt']}):",
        "",
        *_call_rows(data, "rebuilt"),
        "",
        (
            f"**4. A sweep**, {data['sweep_points']} points in one fresh interpreter, each "
            "building its system and sampler (the swept range is 0.5–1.5 × the value above; "
            f"target: {TARGETS['sweep']}"
            + (
                "; with fewer than ten points the ten-point time is the first point plus nine "
                "times the later points' mean):"
                if data["sweep_points"] != 10
                else "):"
            )
        ),
        "",
        *_sweep_rows(data),
        "",
        (
            "**5. Second process**: one process runs call 1 with liesample's default "
            "compilation cache on (in a fresh temporary folder), then a new process runs it "
            f"again (target: {TARGETS['second_process']}). In its own cache folder liesample "
            "stores every program (`jax_persistent_cache_min_compile_time_secs` 0, "
            "`liesample.foundation.cache`); programs cached counts the files the first "
            "process left."
        ),
        "",
        *_second_process_rows(data),
        "",
        f"![compile against the rest, per scenario]({plot_link})",
        "",
        MISSES,
        "",
    ]
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``first_draw.json``, if it exists (``suites.report_sections``)."""
    path = out_dir / "first_draw.json"
    if not path.exists():
        return ""
    link = os.path.relpath(out_dir / "first_draw.png", md_dir)
    return report_section(common.read_json(path), link)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="su(16), shorter runs, 4-point sweep")
    parser.add_argument("--families", default=None, help="comma-separated families (default all)")
    args = parser.parse_args(argv)
    out_dir = common.BENCH_DIR / "results" / ("quick" if args.quick else "")
    out_dir.mkdir(parents=True, exist_ok=True)
    families = None if args.families is None else set(args.families.split(","))
    start = time.perf_counter()
    run(out_dir, args.quick, lambda m: print(m, flush=True), families)
    print(report(out_dir, out_dir))
    print(f"suite first_draw took {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
