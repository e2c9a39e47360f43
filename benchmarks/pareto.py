"""Accuracy against cost beyond the rigid body: the heavy top and the spin chain.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/pareto.py            # ~5 min on 2 cores
    .venv/bin/python benchmarks/pareto.py --quick

Per system, integrator and step size: independent chains from exact Gibbs draws (heavy top:
``HeavyTopGibbs.sample``; spins: bond angles drawn from Fisher's exact law) run for a physical
time ``T`` (the first ``burn_in`` discarded); per observable ``bias = mean − exact`` with
``SE = std over chains / √chains`` (honest: the chains are independent), ``ESS = Var / SE²`` and
wall time per effective sample (compilation excluded, burn-in included). The Metropolis-adjusted
sampler (``liesample.adjusted_lie_poisson``, exact at every step) is run beside them.

The Pareto plot (one PNG per system) shows, for each setting, the error reached after spending
``t`` seconds, ``max_k √(b_k² + Var_k · (s per ESS)_k / t)`` with the bias bounded by the run,
``b = |bias| + 2 SE`` (0 for the exact adjusted sampler), against ``t``; its lower envelope is
the best setting at each budget. The left panel is the measured bias against the step size.

- **Heavy top**: I = (1, 1.5, 2.5), χ = (0.2, 0, 1), mgl = 1, β = 2, orbit |Γ| = 1, Π·Γ = 0.5
  (the configuration of ``tests/test_heavy_top.py``); observables ``Γ·χ`` and ``Π_i²``, exact
  from ``HeavyTopGibbs`` quadrature.
- **Spin chain**: open Heisenberg chain of 16 spins, J = 1, β = 2, B = 0; observables the mean
  ``s_k·s_{k+n}`` over k for n = 1, 2, exact ``u^n`` with ``u = coth βJ − 1/(βJ)`` (Fisher).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax
import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common, suites
from liesample import accuracy
from liesample.systems import heavy_top, heisenberg
from liesample.targets import heisenberg_chain_correlation

SUITE = {"order": 20, "title": "accuracy against cost: heavy top and spin chain (Pareto)"}
NAME = "pareto"
INTEGRATORS = ("splitting", "rkmk_heun", "lie_euler")

HT_INERTIA, HT_CHI, HT_BETA = (1.0, 1.5, 2.5), (0.2, 0.0, 1.0), 2.0
HT_MU0 = np.array([0.5, 0.0, 0.0, 1.0, 0.0, 0.0])
CHAIN_LENGTH, CHAIN_BETA = 16, 2.0

FULL = {
    "heavy_top": {
        "chains": 1024,
        "time": 100.0,
        "burn_in": 5.0,
        "step_sizes": (0.4, 0.2, 0.1, 0.05),
        "adjusted_step_sizes": (0.4, 0.8),
        "adjusted_steps": 500,
    },
    "spin_chain": {
        "chains": 256,
        "time": 60.0,
        "burn_in": 5.0,
        "step_sizes": (0.2, 0.1, 0.05),
        "adjusted_step_sizes": (0.05, 0.1),
        "adjusted_steps": 800,
    },
}
QUICK = {
    "heavy_top": {**FULL["heavy_top"], "chains": 128, "time": 30.0, "step_sizes": (0.4, 0.1)},
    "spin_chain": {
        **FULL["spin_chain"],
        "chains": 64,
        "time": 20.0,
        "step_sizes": (0.2, 0.1),
        "adjusted_step_sizes": (0.1,),
        "adjusted_steps": 200,
    },
}


def _heavy_top_problem():
    system = heavy_top(HT_INERTIA, mgl=1.0, chi=HT_CHI)
    reference = system.reference(HT_BETA, HT_MU0)
    exact = np.r_[reference.mean_gamma_chi(), reference.pi_second_moments()]
    chi = jnp.asarray(HT_CHI)

    def observables(mu):
        return jnp.concatenate([jnp.dot(mu[3:], chi)[None], mu[:3] ** 2])

    def starts(key, n):
        return np.asarray(reference.sample(key, n))

    return system, HT_BETA, observables, exact, ("Γ·χ", "Π₁²", "Π₂²", "Π₃²"), starts


def _chain_starts(key, n, length, beta):
    """Exact Gibbs draws of the open chain: i.i.d. bond angles ``c ∝ e^{βc}`` and uniform
    azimuths, each spin placed relative to its left neighbour (Fisher's construction)."""
    rng = np.random.default_rng(int(jax.random.randint(key, (), 0, 2**31 - 1)))
    spins = np.empty((n, length, 3))
    x = rng.normal(size=(n, 3))
    spins[:, 0] = x / np.linalg.norm(x, axis=1, keepdims=True)
    for k in range(1, length):
        u = rng.uniform(size=n)
        c = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * beta)) / beta  # inverse CDF of e^{βc}
        previous = spins[:, k - 1]
        helper = np.where(np.abs(previous[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        a = np.cross(previous, helper)
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b = np.cross(previous, a)
        phi = rng.uniform(0, 2 * np.pi, size=(n, 1))
        s = np.sqrt(1 - c * c)[:, None]
        spins[:, k] = c[:, None] * previous + s * (np.cos(phi) * a + np.sin(phi) * b)
    return spins


def _spin_chain_problem():
    system = heisenberg((CHAIN_LENGTH,))
    exact = heisenberg_chain_correlation(np.array([1, 2]), CHAIN_BETA)

    def observables(s):
        return jnp.stack(
            [jnp.mean(jnp.sum(s[:-1] * s[1:], -1)), jnp.mean(jnp.sum(s[:-2] * s[2:], -1))]
        )

    def starts(key, n):
        return _chain_starts(key, n, CHAIN_LENGTH, CHAIN_BETA)

    return system, CHAIN_BETA, observables, exact, ("s_k·s_{k+1}", "s_k·s_{k+2}"), starts


PROBLEMS = {"heavy_top": _heavy_top_problem, "spin_chain": _spin_chain_problem}
TITLES = {
    "heavy_top": "heavy top (I = (1, 1.5, 2.5), χ = (0.2, 0, 1), β = 2)",
    "spin_chain": f"open Heisenberg chain, N = {CHAIN_LENGTH}, βJ = {CHAIN_BETA}",
}


def _row(label, integrator, h, estimate, se, variance, wall, exact, **extra):
    bias = np.asarray(estimate) - exact
    with np.errstate(divide="ignore", invalid="ignore"):
        ess = variance / np.asarray(se) ** 2
    finite = bool(np.all(np.isfinite(bias)) and np.all(np.isfinite(se)))
    worst = int(np.argmax(np.abs(bias))) if finite else 0
    return {
        "label": label,
        "integrator": integrator,
        "step_size": h,
        "estimate": estimate,
        "exact": exact,
        "bias": bias,
        "se": se,
        "z": bias / np.asarray(se) if finite else [math.nan] * len(exact),
        "variance": variance,
        "ess": ess,
        "wall_seconds": wall,
        "seconds_per_ess": float(wall / np.min(ess)) if finite else math.nan,
        "worst": worst,
        "max_abs_bias": float(abs(bias[worst])) if finite else math.nan,
        "max_abs_bias_se": float(se[worst]) if finite else math.nan,
        "finite": finite,
        **extra,
    }


def run_system(name, cfg, log):
    system, beta, observables, exact, labels, make_starts = PROBLEMS[name]()
    starts = make_starts(jax.random.key(50), cfg["chains"])
    rows = []
    for integrator in INTEGRATORS:
        for h in cfg["step_sizes"]:
            compile_start = time.perf_counter()
            result = accuracy.coupled_ergodic_averages(
                system,
                beta,
                observables,
                step_size=h,
                levels=1,
                integrator=integrator,
                initial_positions=starts,
                rng_key=jax.random.key(51),
                total_time=cfg["time"],
                burn_in=cfg["burn_in"],
            )
            variance = result.chain_square_means[:, 0].mean(0) - result.estimate[0] ** 2
            row = _row(
                f"{integrator} h={h}",
                integrator,
                h,
                result.estimate[0],
                result.mcse[0],
                variance,
                result.wall_time,
                exact,
                nonfinite_steps=int(result.nonfinite_steps.sum()),
                seconds_with_compilation=time.perf_counter() - compile_start,
            )
            rows.append(row)
            log(
                f"  {name} {row['label']:>18}: bias {np.round(row['bias'], 4)} ± "
                f"{np.round(row['se'], 4)}, {row['seconds_per_ess'] * 1e6:.3g} µs/ESS"
            )
    for dt in cfg["adjusted_step_sizes"]:
        sampler = liesample.adjusted_lie_poisson(system, beta=beta, sigma=1.0, step_size=dt)
        result = accuracy.ergodic_averages(
            sampler,
            jax.random.key(52),
            starts,
            observables,
            num_steps=cfg["adjusted_steps"],
            num_warmup=10,
            info_fields=("acceptance_rate", "is_divergent"),
        )
        variance = result.chain_square_means.mean(0) - result.estimate**2
        row = _row(
            f"adjusted dt={dt}",
            "adjusted",
            dt,
            result.estimate,
            result.mcse,
            variance,
            result.wall_time,
            exact,
            acceptance_rate=float(np.mean(result.info_means["acceptance_rate"])),
        )
        rows.append(row)
        log(
            f"  {name} {row['label']:>18}: bias {np.round(row['bias'], 4)} ± "
            f"{np.round(row['se'], 4)}, {row['seconds_per_ess'] * 1e6:.3g} µs/ESS, acceptance "
            f"{row['acceptance_rate']:.2f}"
        )
    return {"observables": labels, "exact": exact, "config": cfg, "rows": rows}


def _error_after(row, seconds):
    """Worst observable's √(b² + Var·(s per ESS)/t) after ``t`` seconds, with the bias bounded
    conservatively by ``b = |bias| + 2 SE`` (0 for the exact adjusted sampler)."""
    variance = np.asarray(row["variance"], float)
    per_ess = row["wall_seconds"] / np.asarray(row["ess"], float)
    if row["integrator"] == "adjusted":
        bias = np.zeros_like(variance)
    else:
        bias = np.abs(np.asarray(row["bias"], float)) + 2 * np.asarray(row["se"], float)
    seconds = np.asarray(seconds, float)[..., None]
    return np.max(np.sqrt(bias**2 + variance * per_ess / seconds), axis=-1)


def _plot(name, data, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"splitting": "tab:blue", "rkmk_heun": "tab:orange", "lie_euler": "tab:green"}
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6))
    rows = [r for r in data["rows"] if r["finite"]]
    for integrator, colour in colours.items():
        pts = sorted(
            (r for r in rows if r["integrator"] == integrator), key=lambda r: r["step_size"]
        )
        if not pts:
            continue
        left.errorbar(
            [r["step_size"] for r in pts],
            [r["max_abs_bias"] for r in pts],
            yerr=[2 * r["max_abs_bias_se"] for r in pts],
            marker="o",
            color=colour,
            capsize=3,
            label=integrator,
        )
    adjusted = [r for r in rows if r["integrator"] == "adjusted"]
    for r in adjusted:
        left.errorbar(
            [r["step_size"]],
            [max(r["max_abs_bias"], 1e-5)],
            yerr=[
                [min(2 * r["max_abs_bias_se"], max(r["max_abs_bias"], 1e-5) * 0.99)],
                [2 * r["max_abs_bias_se"]],
            ],
            marker="s",
            color="k",
            capsize=3,
            linestyle="none",
            label="adjusted (exact)" if r is adjusted[0] else None,
        )
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("step size h")
    left.set_ylabel("max over observables |bias| (bars: ±2 SE)")
    left.set_title("bias against step size")
    left.legend(fontsize=8)

    budget = np.logspace(-2, 3, 60)
    envelope = np.full_like(budget, np.inf)
    for r in rows:
        error = _error_after(r, budget)
        envelope = np.minimum(envelope, error)
        colour = colours.get(r["integrator"], "k")
        style = "--" if r["integrator"] == "adjusted" else "-"
        right.plot(budget, error, style, color=colour, alpha=0.55, lw=1)
        right.annotate(r["label"].split(" ")[-1], (budget[-1], error[-1]), fontsize=6, color=colour)
    right.plot(budget, envelope, color="k", lw=2.5, alpha=0.35, label="Pareto front")
    right.set_xscale("log")
    right.set_yscale("log")
    right.set_xlabel("seconds spent (this machine, vmapped chains)")
    right.set_ylabel("error reached √(bias² + Var/ESS)")
    right.set_title("error reached against seconds spent (dashed: adjusted)")
    right.legend(fontsize=8)
    fig.suptitle(TITLES[name])
    fig.tight_layout()
    path = out_dir / f"pareto_{name}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run(out_dir: Path, quick: bool, log=print) -> None:
    cfg = QUICK if quick else FULL
    start = time.perf_counter()
    systems = {}
    for name in PROBLEMS:
        log(f"  {name}")
        systems[name] = run_system(name, cfg[name], log)
        _plot(name, systems[name], out_dir)
    path = common.write_json(
        out_dir / f"{NAME}.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "systems": systems,
            "total_seconds": time.perf_counter() - start,
        },
    )
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _best_at(rows, seconds):
    best = min(rows, key=lambda r: _error_after(r, seconds))
    return best, float(_error_after(best, seconds))


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / f"{NAME}.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    machine = data["machine"]
    lines = [
        "## Accuracy against cost: heavy top and spin chain",
        "",
        (
            f"From `benchmarks/pareto.py` ({machine['date_utc']}, {data['total_seconds']:.0f} s, "
            f"{data['mode']} mode, {machine['usable_cpus']} CPUs {machine['cpu_model']}; shared "
            "machine, wall times ±20%). Independent chains from exact Gibbs draws; bias ± SE "
            "(SE from the spread of the chains), ESS = Var/SE², seconds per ESS of the worst "
            'observable (compilation excluded). σ = 1. "adjusted" is the Metropolis-adjusted '
            "sampler (exact; its |z| checks that)."
        ),
        "",
    ]
    for name, system in data["systems"].items():
        cfg = system["config"]
        obs = system["observables"]
        exact = ", ".join(f"{o} = {v:.5f}" for o, v in zip(obs, system["exact"], strict=True))
        rel = common.relative_link(out_dir / f"pareto_{name}.png", md_dir)
        lines += [
            f"### {TITLES[name]}",
            "",
            (
                f"{cfg['chains']} chains × T = {cfg['time']} (burn-in {cfg['burn_in']}); exact: "
                f"{exact}."
            ),
            "",
            (
                f"| setting | bias ({', '.join(obs)}) ± SE (×10⁻³) | max \\|z\\| | min ESS "
                "| wall (s) | s per ESS |"
            ),
            "|---|---|---|---|---|---|",
        ]
        for r in system["rows"]:
            if not r["finite"]:
                lines.append(f"| {r['label']} | non-finite | – | – | {r['wall_seconds']:.2f} | – |")
                continue
            bias = ", ".join(
                f"{1e3 * b:+.2f}±{1e3 * s:.2f}" for b, s in zip(r["bias"], r["se"], strict=True)
            )
            extra = f" (acceptance {r['acceptance_rate']:.2f})" if "acceptance_rate" in r else ""
            lines.append(
                f"| {r['label']}{extra} | {bias} | {np.max(np.abs(r['z'])):.1f} | "
                f"{np.min(r['ess']):.3g} | {r['wall_seconds']:.2f} | "
                f"{1e6 * r['seconds_per_ess']:.3g} µs |"
            )
        rows = [r for r in system["rows"] if r["finite"]]
        budgets = (0.1, 1.0, 10.0, 100.0)
        best = [_best_at(rows, t) for t in budgets]
        lines += [
            "",
            "Best setting per budget (lowest worst-observable √(b² + Var/ESS) with b = |bias| + "
            "2 SE, extrapolated from the measured bias and cost): "
            + "; ".join(
                f"{t:g} s → {b['label']} ({e:.2g})" for t, (b, e) in zip(budgets, best, strict=True)
            )
            + ".",
            "",
            f"![Pareto {name}]({rel})",
            "",
        ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
