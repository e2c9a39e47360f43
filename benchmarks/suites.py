"""Benchmark suites beyond the rigid-body core, discovered by convention.

A suite is a module ``benchmarks/<name>.py`` that defines

- ``SUITE = {"order": int, "title": str}`` — its place in ``RESULTS.md``;
- ``run(out_dir: Path, quick: bool, log) -> None`` — measures and writes ``<name>.json`` (and
  any plots) into ``out_dir``;
- ``report(out_dir: Path, md_dir: Path) -> str`` — the Markdown section (starting with a
  ``## `` heading) rebuilt from that JSON alone, with plot links relative to ``md_dir``; ``""``
  when its JSON is missing.

``benchmarks/run.py`` runs every suite after the core sections and ``benchmarks/report.py``
appends their sections, so a new system adds a benchmark without touching either file. The
rigid-body core follows the same rule: ``benchmarks/throughput.py`` and
``benchmarks/accuracy_report.py`` write their own sections (``report_section(results)``, from
``common.CoreResults``), and ``report.py`` only assembles.

A module without ``SUITE`` is not a suite: the core (``throughput``, ``accuracy``) and the
helpers of a module (``accuracy_plots``, ``accuracy_report``) define none, and the runner's
own modules (``NOT_SUITES``) are not even imported.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent

# The runner and its shared set-up: never suites, so ``discover`` does not import them.
NOT_SUITES = frozenset({"run", "report", "suites", "common"})


def discover() -> list:
    """The suite modules, sorted by ``SUITE["order"]``."""
    modules = []
    for path in sorted(BENCH_DIR.glob("*.py")):
        if path.stem.startswith("_") or path.stem in NOT_SUITES:
            continue
        module = importlib.import_module(f"benchmarks.{path.stem}")
        if hasattr(module, "SUITE"):
            modules.append(module)
    return sorted(modules, key=lambda m: m.SUITE["order"])


def suite_name(module) -> str:
    return module.__name__.rsplit(".", 1)[-1]


def run_all(out_dir: Path, quick: bool, log, only=None) -> dict[str, float]:
    """Run the suites (or those named in ``only``); return seconds per suite."""
    seconds = {}
    for module in discover():
        name = suite_name(module)
        if only is not None and name not in only:
            continue
        log(f"suite {name}: {module.SUITE['title']}")
        start = time.perf_counter()
        module.run(out_dir, quick, log)
        seconds[name] = time.perf_counter() - start
    return seconds


def report_sections(out_dir: Path, md_dir: Path) -> list[str]:
    """Each suite's Markdown section, in order (suites without results are skipped)."""
    return [s for s in (m.report(out_dir, md_dir) for m in discover()) if s]


def standalone(module_file: str, argv=None) -> int:
    """``python benchmarks/<name>.py [--quick]``: run one suite and rebuild its section."""
    import argparse

    name = Path(module_file).stem
    parser = argparse.ArgumentParser(description=f"benchmark suite {name}")
    parser.add_argument("--quick", action="store_true", help="short smoke run")
    args = parser.parse_args(argv)
    out_dir = BENCH_DIR / "results" / ("quick" if args.quick else "")
    out_dir.mkdir(parents=True, exist_ok=True)
    module = importlib.import_module(f"benchmarks.{name}")
    start = time.perf_counter()
    module.run(out_dir, args.quick, lambda message: print(message, flush=True))
    print(module.report(out_dir, out_dir))
    print(f"suite {name} took {time.perf_counter() - start:.0f} s")
    return 0
