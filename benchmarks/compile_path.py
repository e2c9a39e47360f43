"""Compile path: the cost of ``liesample.jit`` (XLA:CPU ``small-while-loop-hoisting`` disabled).

For the rigid body, the heavy top and an 8×8 spin lattice, with 1, 8, 64 and 1024 chains, a
``vmap`` over chains of a ``fori_loop`` of sampler steps is compiled twice: with
``liesample.jit`` (the library's compile path) and with plain ``jax.jit``. Each is timed (best
of ``repeats`` calls of about ``target_seconds``, compilation excluded) and checked against the
same chains run one by one (``max |batched − single|`` after the timed steps: round-off when
the compile is correct). The measurement runs in this interpreter and, when ``.venv-oldest``
exists (``make test-oldest`` creates it, with the oldest supported jax), in that one too, so
one report holds both jax versions side by side.

Run alone: ``python benchmarks/compile_path.py [--quick]``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

SUITE = {"order": 5, "title": "Compile path: cost of the miscompile guard"}

ROOT = Path(__file__).resolve().parents[1]
OLDEST_PYTHON = ROOT / ".venv-oldest" / "bin" / "python"
CHAINS = (1, 8, 64, 1024)
SYSTEMS = ("rigid body", "heavy top", "spins 8x8")


def _runners(algorithm):
    """``run(states, keys, n) -> positions``: ``n`` steps of every chain, vectorised; and
    ``single(state, key, n)``, the same for one chain, jitted."""
    import jax

    def run(states, keys, n):
        def chain(state, key):
            return jax.lax.fori_loop(
                0, n, lambda i, s: algorithm.step(jax.random.fold_in(key, i), s)[0], state
            )

        return jax.vmap(chain)(states, keys).position

    def single(state, key, n):
        return run(jax.tree.map(lambda x: x[None], state), key[None], n)[0]

    return run, jax.jit(single)


def _chain(states, c):
    """Chain ``c`` of the batched ``states``."""
    import jax

    return jax.tree.map(lambda x: x[c], states)


def _measure_here(quick: bool) -> dict:
    """Measure every configuration in this interpreter (called in a subprocess)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import jaxlib
    import numpy as np

    import liesample

    systems = {
        "rigid body": (liesample.systems.rigid_body((1.0, 2.0, 4.0)), [0.3, 0.4, math.sqrt(0.75)]),
        "heavy top": (
            liesample.systems.heavy_top((1.0, 1.5, 2.5), mgl=1.0, chi=(0.2, 0.0, 1.0)),
            [0.6, -1.0, 0.8, 0.3, 0.5, -0.9],
        ),
        "spins 8x8": (
            liesample.systems.heisenberg((8, 8), periodic=True),
            np.tile(np.array([0.0, 0.6, 0.8]), (8, 8, 1)),
        ),
    }
    target_seconds = 0.05 if quick else 0.3
    repeats = 2 if quick else 3
    check_steps = 20
    rows = []
    for name, (system, start) in systems.items():
        algorithm = liesample.lie_poisson_langevin(
            system, beta=2.0, step_size=0.05, stability="off"
        )

        run, single = _runners(algorithm)
        start = jnp.asarray(start, dtype=jnp.float64)
        for num_chains in CHAINS:
            keys = jax.random.split(jax.random.key(0), num_chains)
            states = jax.vmap(algorithm.init)(jnp.broadcast_to(start, (num_chains, *start.shape)))
            for compile_path, compile_fn in (
                ("liesample.jit", liesample.jit),
                ("jax.jit", jax.jit),
            ):
                compiled = compile_fn(run).lower(states, keys, 1).compile()
                batched = np.asarray(compiled(states, keys, check_steps))
                alone = np.stack(
                    [
                        np.asarray(liesample.jit(single)(_chain(states, c), keys[c], check_steps))
                        for c in sorted({0, num_chains - 1})
                    ]
                )
                error = float(np.abs(batched[sorted({0, num_chains - 1})] - alone).max())
                n = max(1, 2000 // num_chains)
                while True:
                    begin = time.perf_counter()
                    jax.block_until_ready(compiled(states, keys, n))
                    seconds = time.perf_counter() - begin
                    if seconds >= 0.02:
                        break
                    n *= 4
                n = max(1, round(n * target_seconds / seconds))
                times = []
                for _ in range(repeats):
                    begin = time.perf_counter()
                    jax.block_until_ready(compiled(states, keys, n))
                    times.append(time.perf_counter() - begin)
                rows.append(
                    {
                        "system": name,
                        "chains": num_chains,
                        "compile_path": compile_path,
                        "chain_steps_per_second": num_chains * n / min(times),
                        "max_batched_minus_single": error,
                    }
                )
    return {"jax": jax.__version__, "jaxlib": jaxlib.__version__, "rows": rows}


def run(out_dir: Path, quick: bool, log) -> None:
    from benchmarks import common

    measurements = []
    pythons = [Path(sys.executable)]
    if OLDEST_PYTHON.exists():
        pythons.append(OLDEST_PYTHON)
    else:
        log("compile_path: .venv-oldest missing (run `make test-oldest` once); current jax only")
    for python in pythons:
        log(f"compile_path: measuring with {python}")
        output = subprocess.run(
            [str(python), __file__, "--worker"] + (["--quick"] if quick else []),
            check=True,
            capture_output=True,
            text=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        ).stdout
        measurements.append(json.loads(output.strip().splitlines()[-1]))
    common.write_json(
        out_dir / "compile_path.json",
        {"machine": common.machine_info(), "quick": quick, "measurements": measurements},
    )


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "compile_path.json"
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    by_version = {
        m["jax"]: {(r["system"], r["chains"], r["compile_path"]): r for r in m["rows"]}
        for m in data["measurements"]
    }
    versions = sorted(by_version, key=lambda v: tuple(int(p) for p in v.split(".")))
    oldest, newest = versions[0], versions[-1]
    lines = [
        f"## {SUITE['title']}",
        "",
        (
            "Every loop liesample compiles goes through `liesample.jit`: `jax.jit` with XLA:CPU's "
            "`small-while-loop-hoisting` pass disabled, the pass that miscompiles vmapped sampler "
            "loops (`tests/test_compile.py`). Chain-steps per second of `vmap` over chains of a "
            "`fori_loop` of `lie_poisson_langevin` steps (splitting, β = 2, dt = 0.05, compilation "
            "excluded, best of several calls), and the largest difference after 20 steps between "
            "the batched chains and the same chains compiled alone (`err`: round-off when correct)."
        ),
        "",
        (
            f"Measured with jax {', '.join(versions)}"
            f"{' (quick mode)' if data.get('quick') else ''}. "
            f"Ratio: `liesample.jit` on jax {newest} over plain `jax.jit` on jax {oldest} (the "
            "previously pinned configuration)."
        ),
        "",
    ]
    header = "| system | chains |"
    rule = "|---|---:|"
    for version in versions:
        for compile_path in ("jax.jit", "liesample.jit"):
            header += f" {compile_path} {version} (steps/s, err) |"
            rule += "---:|"
    header += " ratio |"
    rule += "---:|"
    lines += [header, rule]
    for system in SYSTEMS:
        for chains in CHAINS:
            row = f"| {system} | {chains} |"
            for version in versions:
                for compile_path in ("jax.jit", "liesample.jit"):
                    r = by_version[version].get((system, chains, compile_path))
                    row += (
                        f" {r['chain_steps_per_second']:.3g}, {r['max_batched_minus_single']:.1e} |"
                        if r
                        else " – |"
                    )
            base = by_version[oldest].get((system, chains, "jax.jit"))
            new = by_version[newest].get((system, chains, "liesample.jit"))
            ratio = (
                new["chain_steps_per_second"] / base["chain_steps_per_second"]
                if base and new
                else math.nan
            )
            lines.append(row + f" {ratio:.2f} |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    if "--worker" in sys.argv:
        print(json.dumps(_measure_here("--quick" in sys.argv)))
    else:
        from benchmarks.suites import standalone

        raise SystemExit(standalone(__file__))
