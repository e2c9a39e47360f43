"""1. Throughput: chain-steps per second of the vmapped sampler, and the exact i.i.d. sampler.

Each measurement jits ``vmap`` over chains of a loop of ``n`` sampler steps that carries only
the chain state (no trajectory, no per-step info: XLA drops the unused ``energy`` and
``casimir_error``). The loop is ``jax.lax.fori_loop`` with a traced trip count: the same XLA
``While`` loop that ``lax.scan`` lowers to, without stacked outputs, so one compilation serves
every ``n``. Compilation is excluded; calibration calls warm the executable up and pick ``n``
so that one call lasts about ``target_seconds``; the reported time is the best of ``repeats``.
Step ``k`` of chain ``c`` uses the key ``fold_in(key_c, k)`` as ``liesample.runner`` does, so the
cost of drawing the noise is included (and is absent where the scene has no noise).
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np
from matplotlib.figure import Figure

from benchmarks import common

import liesample

RNG_ONLY = "RNG only (fold_in + 3 normals)"


def _loop(step):
    """``(states, keys, n) -> states`` after ``n`` steps of every chain.

    ``step(key, state) -> new_state``.
    """

    def run(states, keys, n):
        def chain(state, key):
            return jax.lax.fori_loop(0, n, lambda i, s: step(jax.random.fold_in(key, i), s), state)

        return jax.vmap(chain)(states, keys)

    return liesample.jit(run)


def _measure(run, states, keys, num_chains, cfg: common.Config):
    compile_start = time.perf_counter()
    compiled = run.lower(states, keys, 1).compile()
    compile_seconds = time.perf_counter() - compile_start

    # Calibrate (and warm up): grow n until a call lasts ≥ 50 ms, then scale to the target.
    n = max(1, 20_000 // num_chains)
    while True:
        _, seconds = common.timed(compiled, states, keys, n)
        if seconds >= 0.05 or n >= 10**8:
            break
        n *= 4
    n = max(1, round(n * cfg.throughput_target_seconds / seconds))
    final, seconds = common.timed(compiled, states, keys, n)  # warm call at the final n
    times = [seconds]
    for _ in range(cfg.throughput_repeats - 1):
        final, seconds = common.timed(compiled, states, keys, n)
        times.append(seconds)
    best = min(times)
    return final, {
        "chains": num_chains,
        "steps": n,
        "seconds_best": best,
        "seconds_all": times,
        "chain_steps_per_second": num_chains * n / best,
        "compile_seconds": compile_seconds,
    }


def _initial(num_chains, key):
    """Exact Gibbs draws on |μ| = r, one per chain, and one key per chain."""
    k_pos, k_chain = jax.random.split(key)
    positions = common.target().sample(k_pos, num_chains)
    return positions, jax.random.split(k_chain, num_chains)


def run_sampler_throughput(cfg: common.Config, log=print) -> list[dict]:
    pairs = cfg.throughput_pairs or tuple(
        (name, scene) for name in common.INTEGRATOR_NAMES for scene in common.SCENES
    )
    key = jax.random.key(cfg.seed)
    rows = []
    for num_chains in cfg.throughput_chains:
        positions, keys = _initial(num_chains, jax.random.fold_in(key, num_chains))
        for integrator, scene in pairs:
            algorithm = common.sampler(integrator, scene, cfg.throughput_step_size)
            states = jax.vmap(algorithm.init)(positions)
            run = _loop(lambda k, s, step=algorithm.step: step(k, s)[0])
            final, row = _measure(run, states, keys, num_chains, cfg)
            # How many chains ended off their orbit (|C − C₀|/C₀ > tolerance) or non-finite.
            c_final = np.sum(np.asarray(final.position) ** 2, axis=-1)
            drift = np.abs(c_final - common.RADIUS**2) / common.RADIUS**2
            off = ~np.isfinite(drift) | (drift > cfg.casimir_tolerance)
            row.update(
                integrator=integrator,
                scene=scene,
                step_size=cfg.throughput_step_size,
                off_orbit_fraction=float(np.mean(off)),
            )
            rows.append(row)
            log(
                f"  {integrator:>10} | {scene:<34} | {num_chains:>6} chains: "
                f"{row['chain_steps_per_second']:.3g} chain-steps/s "
                f"(n={row['steps']}, {row['seconds_best']:.2f} s, compile "
                f"{row['compile_seconds']:.2f} s)"
            )
        # Reference: the noise draw alone, with the same key scheme.
        run = _loop(lambda k, s: s + jax.random.normal(k, s.shape, s.dtype))
        _, row = _measure(run, positions, keys, num_chains, cfg)
        row.update(integrator=RNG_ONLY, scene="-", step_size=None, off_orbit_fraction=None)
        rows.append(row)
        log(
            f"  {RNG_ONLY:>10} | {num_chains:>6} chains: "
            f"{row['chain_steps_per_second']:.3g} draws/s"
        )
    return rows


def run_iid_throughput(cfg: common.Config, log=print) -> list[dict]:
    """Samples per second of the exact rejection sampler ``RestrictedGaussian.sample``."""
    target = common.target()
    key = jax.random.key(cfg.seed + 1)
    rows = []
    for size in cfg.iid_sizes:
        compile_start = time.perf_counter()
        common.block(target.sample(jax.random.fold_in(key, 0), size))  # compile + warm-up
        first_call = time.perf_counter() - compile_start
        times = []
        for r in range(cfg.throughput_repeats):
            _, seconds = common.timed(target.sample, jax.random.fold_in(key, r + 1), size)
            times.append(seconds)
        best = min(times)
        rows.append(
            {
                "samples": size,
                "seconds_best": best,
                "seconds_all": times,
                "samples_per_second": size / best,
                "first_call_seconds": first_call,
            }
        )
        log(f"  exact iid sampler, {size:>8} samples: {size / best:.3g} samples/s")
    return rows


def sanity_check_iid(n=200_000, seed=0) -> dict:
    """The i.i.d. sampler's E[μ_i²] against the exact values (a check that it is the limit)."""
    draws = np.asarray(common.target().sample(jax.random.key(seed), n))
    m2 = draws**2
    est = m2.mean(0)
    se = m2.std(0, ddof=1) / np.sqrt(n)
    exact = common.exact_second_moments()
    return {
        "samples": n,
        "estimate": est,
        "exact": exact,
        "se": se,
        "z": (est - exact) / se,
        "variance": m2.var(0, ddof=1),
        "radius_error": float(np.max(np.abs(np.linalg.norm(draws, axis=1) - common.RADIUS))),
    }


# --------------------------------------------------------------------------- plots and tables


def plot_throughput(rows, iid_rows, path: Path) -> Path:
    chains = sorted({r["chains"] for r in rows})
    integrators = [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in rows)]
    scenes = [s for s in common.SCENES if any(r["scene"] == s for r in rows)]
    lookup = {(r["integrator"], r["scene"], r["chains"]): r for r in rows}
    fig = Figure(figsize=(4.6 * len(chains), 5.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(chains), sharey=True))
    width = 0.8 / max(len(scenes), 1)
    hatches = ["", "//", ".."]
    for ax, n in zip(axes, chains, strict=True):
        for k, scene in enumerate(scenes):
            xs, ys = [], []
            for i, name in enumerate(integrators):
                r = lookup.get((name, scene, n))
                if r is not None:
                    xs.append(i + (k - (len(scenes) - 1) / 2) * width)
                    ys.append(r["chain_steps_per_second"])
            ax.bar(
                xs,
                ys,
                width,
                label=scene,
                color=f"C{k}",
                hatch=hatches[k % 3],
                edgecolor="k",
                lw=0.4,
            )
        rng = lookup.get((RNG_ONLY, "-", n))
        if rng is not None:
            ax.axhline(
                rng["chain_steps_per_second"],
                color="0.3",
                ls="--",
                lw=1.2,
                label="RNG only (fold_in + 3 normals)",
            )
        if iid_rows:
            best = max(r["samples_per_second"] for r in iid_rows)
            ax.axhline(best, color="C3", ls=":", lw=1.6, label="exact iid sampler (samples/s)")
        ax.set_xticks(range(len(integrators)), integrators, rotation=20)
        ax.set_yscale("log")
        ax.set_title(common.chains_label(n) + " (vmapped)")
        ax.grid(axis="y", which="both", alpha=0.3)
    axes[0].set_ylabel("chain-steps per second (best of 3)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize="small")
    fig.suptitle("Throughput of the rigid-body sampler (float64, CPU)")
    return common.save_figure(fig, path)


def _throughput_tables(rows, iid_rows):
    chains = sorted({r["chains"] for r in rows})
    lookup = {(r["integrator"], r["scene"], r["chains"]): r for r in rows}
    head = "| integrator | scene | " + " | ".join(common.chains_label(n) for n in chains) + " |"
    lines = [head, "|" + "---|" * (2 + len(chains))]
    for name in common.INTEGRATOR_NAMES:
        for scene in common.SCENES:
            cells = [lookup.get((name, scene, n)) for n in chains]
            if all(c is None for c in cells):
                continue
            vals = []
            for c in cells:
                if c is None:
                    vals.append("–")
                    continue
                v = common.format_rate(c["chain_steps_per_second"])
                if c.get("off_orbit_fraction"):
                    v += f" ({c['off_orbit_fraction']:.0%} off orbit)"
                vals.append(v)
            lines.append(f"| {name} | {scene} | " + " | ".join(vals) + " |")
    vals = [
        common.format_rate(lookup[(RNG_ONLY, "-", n)]["chain_steps_per_second"])
        if (RNG_ONLY, "-", n) in lookup
        else "–"
        for n in chains
    ]
    lines.append(f"| *reference* | {RNG_ONLY}, draws/s | " + " | ".join(vals) + " |")
    table = "\n".join(lines)

    ratio_lines = [
        "| integrator | "
        + " | ".join(f"H-only ÷ all, {common.chains_label(n)}" for n in chains)
        + " | "
        + " | ".join(f"no-H ÷ all, {common.chains_label(n)}" for n in chains)
        + " |",
        "|" + "---|" * (1 + 2 * len(chains)),
    ]
    for name in common.INTEGRATOR_NAMES:
        base = [lookup.get((name, "all effects", n)) for n in chains]
        if any(b is None for b in base):
            continue
        cells = []
        for scene in ("Hamiltonian only", "noise+dissipation, no Hamiltonian"):
            for b, n in zip(base, chains, strict=True):
                r = lookup.get((name, scene, n))
                cells.append(
                    "–"
                    if r is None
                    else f"{r['chain_steps_per_second'] / b['chain_steps_per_second']:.2f}×"
                )
        if any(c != "–" for c in cells):
            ratio_lines.append(f"| {name} | " + " | ".join(cells) + " |")
    ratios = "\n".join(ratio_lines) if len(ratio_lines) > 2 else "_(not measured in this mode)_"

    iid_lines = ["| draws per call | samples/s (best of 3) | time per call |", "|---|---|---|"]
    for r in iid_rows:
        iid_lines.append(
            f"| {r['samples']:,} | {common.format_rate(r['samples_per_second'])} | {common.format_seconds(r['seconds_best'])} |"
        )
    return table, ratios, "\n".join(iid_lines)


# --------------------------------------------------------------------------- report sections


def report_section(results: common.CoreResults) -> str:
    """Section 1 of ``RESULTS.md`` (throughput of the vmapped sampler), with its plot."""
    cfg = results.config
    plot = plot_throughput(
        results.throughput_rows, results.iid["rows"], results.out_dir / "throughput.png"
    )
    results.written.append(plot)
    tp_table, ratio_table, _ = _throughput_tables(results.throughput_rows, results.iid["rows"])
    return f"""## 1. Throughput

Chain-steps per second of `liesample.lie_poisson_langevin(system, …, step_size=
{cfg["throughput_step_size"]:g})`, `jax.jit(jax.vmap(chain))` where each chain is a
`jax.lax.fori_loop` of `n` calls to `algorithm.step` carrying only the state (the same XLA
While loop `lax.scan` lowers to, without stacked outputs; a traced trip count lets one
compilation serve every `n`). Step `k` of chain `c` uses `fold_in(key_c, k)` as
`liesample.runner` does. Chains start from exact Gibbs draws. Compilation is excluded; calls
are warmed up, `n` is chosen so that one call lasts ≈ {cfg["throughput_target_seconds"]:g} s,
and the time is the best of {cfg["throughput_repeats"]}. Per-step `info` is not kept, so XLA
drops the energy and Casimir diagnostics (the non-finite guard stays: it decides the state).

Scenes: **all effects** (β = 3, σ = 1); **Hamiltonian only** (`sigma=0, theta=0`: noise and
dissipation are not traced at all and no random numbers are drawn); **noise+dissipation, no
Hamiltonian** (`hamiltonian=False`). "off orbit" marks chains whose final |μ|² is more than
10% from r² (or non-finite).

{tp_table}

Speed-up relative to all effects (> 1 = faster):

{ratio_table}

![throughput]({results.link(plot)})
"""


def iid_report_section(results: common.CoreResults) -> str:
    """Section 3 of ``RESULTS.md``: the exact i.i.d. sampler (the physical limit)."""
    _, _, iid_table = _throughput_tables(results.throughput_rows, results.iid["rows"])
    return f"""## 3. Exact iid sampler (the physical limit)

`RestrictedGaussian.sample(key, n)` (rejection from an angular central Gaussian envelope), jitted,
warmed up, best of {results.config["throughput_repeats"]}:

{iid_table}
"""


__all__ = [
    "RNG_ONLY",
    "iid_report_section",
    "plot_throughput",
    "report_section",
    "run_iid_throughput",
    "run_sampler_throughput",
    "sanity_check_iid",
]
