"""Compile once per structure: what a sweep over ``β`` costs against one point.

A user's sweep builds a new sampler at every ``β`` and calls ``liesample.sample`` on it. A
sampler that declares a structure (``Sampler.structure``) is compiled at the first point only:
the later points reuse its programs with the new values traced. Each configuration runs in a
fresh interpreter (so the first point pays for compilation, as in a user's script): the wall
time of one point, then of a sweep of ``num_points`` values of ``β``, with the same draws and
warm-up per point; the ratio is the sweep over one point.

Run alone: ``python -m benchmarks.sweep [--quick]`` (from the repository root).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SUITE = {"order": 6, "title": "Compile once per structure: a β sweep"}

ROOT = Path(__file__).resolve().parents[1]
# sampler -> the model it sweeps: the rigid body, or a periodic Heisenberg chain of 32 spins
CASES = {
    "lie_poisson_langevin": "rigid body",
    "adjusted_lie_poisson": "rigid body",
    "heisenberg_heat_bath": "spin chain",
}


def _model(name: str):
    """``(system, starts of 4 chains)`` of a model of :data:`CASES`."""
    import numpy as np

    import liesample

    if name == "spin chain":
        system = liesample.systems.heisenberg((32,), coupling=1.0, periodic=True)
        return system, np.tile(system.default_position, (4, 1, 1))
    system = liesample.systems.rigid_body((1.0, 2.0, 4.0))
    return system, np.tile(np.array([0.9, 1.2, 0.0]), (4, 1))


def _measure(sampler_name: str, num_points: int, quick: bool) -> dict:
    """Wall seconds of each point of a sweep (called in a fresh interpreter)."""
    import time
    import warnings

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import liesample

    system, starts = _model(CASES[sampler_name])
    draws, warmup = (200, 100) if quick else (2000, 500)
    build = getattr(liesample, sampler_name)
    seconds = []
    for beta in np.linspace(0.5, 5.0, num_points):
        begin = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # short runs: the convergence checks speak
            liesample.sample(
                build(system, beta=float(beta)), jax.random.key(0), starts, draws,
                num_warmup=warmup, progress_bar=False,
            )  # fmt: skip
        seconds.append(time.perf_counter() - begin)
    return {"sampler": sampler_name, "model": CASES[sampler_name], "num_points": num_points,
            "seconds": seconds,
            "draws": draws, "num_warmup": warmup, "chains": len(starts)}  # fmt: skip


def _in_fresh_interpreter(sampler_name: str, num_points: int, quick: bool) -> dict:
    argv = [sys.executable, __file__, "--worker", sampler_name, str(num_points)]
    output = subprocess.run(
        argv + (["--quick"] if quick else []), check=True, capture_output=True, text=True,
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
    ).stdout  # fmt: skip
    return json.loads(output.strip().splitlines()[-1])


def run(out_dir: Path, quick: bool, log) -> None:
    from benchmarks import common

    rows = []
    for name in CASES:
        log(f"sweep: {name}, one point and ten points, each in a fresh interpreter")
        one = _in_fresh_interpreter(name, 1, quick)
        ten = _in_fresh_interpreter(name, 10, quick)
        rows.append({"sampler": name, "one_point": one, "ten_points": ten})
    common.write_json(
        out_dir / "sweep.json", {"machine": common.machine_info(), "quick": quick, "rows": rows}
    )


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "sweep.json"
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    machine = data["machine"]
    lines = [
        f"## {SUITE['title']}",
        "",
        "A sweep over β builds a new sampler at every point and calls `liesample.sample` on it "
        "(4 chains, the sampler's own warm-up); a sampler that declares a structure "
        "is compiled at the first point only. Wall seconds, each configuration in a fresh "
        "interpreter (`benchmarks/sweep.py`).",
        "",
        f"Machine: {machine['cpu_model']}, {machine['usable_cpus']} CPUs, jax {machine['jax']}"
        f"{' (quick mode)' if data.get('quick') else ''}.",
        "",
        "| sampler | model | draws × chains | one point (s) | ten points (s) | first point of "
        "ten (s) | each later point (s, mean) | ten over one |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in data["rows"]:
        one, ten = row["one_point"], row["ten_points"]
        total = sum(ten["seconds"])
        later = ten["seconds"][1:]
        lines.append(
            f"| `{row['sampler']}` | {ten.get('model', 'rigid body')} | {ten['draws']} × "
            f"{ten['chains']} | {one['seconds'][0]:.2f} "
            f"| {total:.2f} | {ten['seconds'][0]:.2f} | {sum(later) / len(later):.3f} "
            f"| {total / one['seconds'][0]:.2f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(_measure(sys.argv[2], int(sys.argv[3]), "--quick" in sys.argv)))
    else:
        from benchmarks import suites

        raise SystemExit(suites.standalone(__file__))
