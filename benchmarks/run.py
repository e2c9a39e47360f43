"""Benchmarks of liesample: the rigid-body core (throughput, accuracy against cost, exact limit)
and every suite of ``benchmarks/suites.py`` (one per system or comparison).

Usage (from the repository root)::

    .venv/bin/python benchmarks/run.py            # full run, ~5 min on 2 cores
    .venv/bin/python benchmarks/run.py --quick    # ~1 min smoke run
    .venv/bin/python benchmarks/run.py --report-only   # rebuild the report from the JSON

The full run writes ``benchmarks/results/*.json``, ``benchmarks/results/*.png`` and regenerates
``benchmarks/RESULTS.md``; ``--quick`` writes the same files under ``benchmarks/results/quick/``
(including its own ``RESULTS.md``) so that a smoke run never overwrites the real results.
"""

from __future__ import annotations

import time

_START = time.perf_counter()

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

from benchmarks import accuracy, common, report, suites, throughput


def _paths(args):
    if args.out is not None:
        out = Path(args.out).resolve()
        return out, out / "RESULTS.md"
    if args.quick:
        out = common.BENCH_DIR / "results" / "quick"
        return out, out / "RESULTS.md"
    return common.BENCH_DIR / "results", common.BENCH_DIR / "RESULTS.md"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="~1 minute smoke version")
    parser.add_argument(
        "--report-only", action="store_true", help="rebuild the plots and RESULTS.md from JSON"
    )
    parser.add_argument("--out", default=None, help="results folder (RESULTS.md goes inside)")
    parser.add_argument(
        "--suites",
        default=None,
        help="comma-separated suites to run (default: all in benchmarks/suites.py); 'none' skips",
    )
    args = parser.parse_args(argv)
    out_dir, md_path = _paths(args)
    cfg = common.QUICK if args.quick else common.FULL

    if not args.report_only:
        out_dir.mkdir(parents=True, exist_ok=True)
        meta = {"machine": common.machine_info(), "config": cfg.to_json()}
        print(
            f"liesample benchmarks ({cfg.mode}) on {meta['machine']['cpu_model']}, "
            f"{meta['machine']['usable_cpus']} CPUs, jax {meta['machine']['jax']} "
            f"({meta['machine']['backend']})",
            flush=True,
        )
        sections = {}

        print("1. Throughput of the vmapped sampler", flush=True)
        t = time.perf_counter()
        rows = throughput.run_sampler_throughput(cfg, log=_log)
        sections["throughput"] = time.perf_counter() - t
        common.write_json(out_dir / "throughput.json", {"rows": rows})

        print("3. Exact i.i.d. sampler", flush=True)
        t = time.perf_counter()
        iid = {
            "rows": throughput.run_iid_throughput(cfg, log=_log),
            "check": throughput.sanity_check_iid(),
        }
        sections["iid"] = time.perf_counter() - t
        common.write_json(out_dir / "iid.json", iid)

        print("2. Accuracy against cost", flush=True)
        t = time.perf_counter()
        rows = accuracy.run_accuracy(cfg, log=_log)
        sections["accuracy"] = time.perf_counter() - t
        common.write_json(out_dir / "accuracy.json", {"rows": rows})

        order_path = out_dir / "order_check.json"
        if cfg.order_check_integrators:
            print("2b. High-precision order check", flush=True)
            t = time.perf_counter()
            rows = accuracy.run_order_check(cfg, log=_log)
            sections["order_check"] = time.perf_counter() - t
            common.write_json(order_path, {"rows": rows})
        elif order_path.exists():
            order_path.unlink()  # a stale check from another run must not be reported

        only = None if args.suites is None else set(args.suites.split(",")) - {"none"}
        sections.update(suites.run_all(out_dir, args.quick, _log, only))

        meta["section_seconds"] = sections
        meta["runtime_seconds"] = time.perf_counter() - _START  # before the report
        common.write_json(out_dir / "meta.json", meta)

    written = report.write_report(out_dir, md_path)
    for path in written:
        shown = path.relative_to(common.REPO_DIR) if path.is_relative_to(common.REPO_DIR) else path
        print(f"wrote {shown}")
    print(f"total {time.perf_counter() - _START:.1f} s", flush=True)
    return 0


def _log(message):
    print(message, flush=True)


if __name__ == "__main__":
    sys.exit(main())
