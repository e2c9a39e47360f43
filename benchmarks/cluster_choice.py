"""O(n) lattices with n ≠ 3: heat bath + over-relaxation against Swendsen–Wang, side by side,
to set ``liesample.recommended_sampler``'s choice for the XY (O(2)) and O(4) models.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    nice .venv/bin/python benchmarks/cluster_choice.py          # ~15 min on 2 shared cores
    nice .venv/bin/python benchmarks/cluster_choice.py --quick  # smoke run (results/quick/)

Writes ``cluster_choice.json`` and ``cluster_choice.png``. On periodic lattices
(:func:`liesample.systems.n_vector`, J = 1, no field) at the points of :data:`CASES` (3-D XY
and O(4) near their critical points and one β on each side, 2-D XY below and above its BKT
point, 2-D O(4) at one β), two samplers run in one process, from the same random starts and
key:

- ``heat bath + OR``: ``heisenberg_heat_bath(system, beta=β, overrelaxation=1)`` (one step:
  one heat-bath sweep and one over-relaxation sweep);
- ``swendsen-wang``: ``heisenberg_cluster(system, beta=β)`` (one step: one Swendsen–Wang update
  with Wolff's embedding, every site in one cluster or another).

Each run is one ``liesample.sample`` call: :data:`NUM_CHAINS` chains, the case's number of
draws (one per step) after a warm-up of :data:`WARMUP_FRACTION` of them, recording ``|m|`` (the
norm of the mean spin) and the energy per site. Bulk ESS and R-hat come from
:func:`liesample.analysis.diagnostics.expectation_table` (ArviZ); ``τ_int = chains × draws /
ESS`` in steps; ESS/s divides by the run's ``sampling_time`` (compilation excluded, warm-up
included). Per point the result is the ratio ``swendsen-wang / heat bath + OR`` of ESS/s for
each quantity, and the winner: the sampler whose slower quantity (the smaller ESS/s of the two)
is faster. Wolff's single cluster (``heisenberg_wolff``) is left out: its step finds every
cluster of the bond configuration, as a Swendsen–Wang step does, and reflects one of them.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import liesample
from benchmarks import common, suites
from benchmarks.spins_beyond_o3 import _fmt, observables
from liesample.analysis.diagnostics import expectation_table
from liesample.systems import n_vector

SUITE = {
    "order": 34,
    "title": "O(n) lattices, n ≠ 3: heat bath + over-relaxation vs Swendsen–Wang",
}

NUM_CHAINS = 4
WARMUP_FRACTION = 0.25
SEED = 11

# (model, n, dimension, lattice side, beta, draws per chain). 3-D XY β_c ≈ 0.4542 and 3-D O(4)
# β_c ≈ 0.9359 (benchmarks/critical_points.py), each with one β on either side; the 2-D XY
# model on both sides of its BKT point (β ≈ 1.12); 2-D O(4) (no transition) at three β.
CASES = (
    *(("XY", 2, 3, 8, beta, 3000) for beta in (0.40, 0.4542, 0.51)),
    *(("XY", 2, 3, 16, beta, 1500) for beta in (0.40, 0.4542, 0.51)),
    ("XY", 2, 3, 24, 0.4542, 1000),
    *(("O(4)", 4, 3, 8, beta, 3000) for beta in (0.85, 0.9359, 1.02)),
    *(("O(4)", 4, 3, 16, beta, 1500) for beta in (0.85, 0.9359, 1.02)),
    ("O(4)", 4, 3, 24, 0.9359, 1000),
    *(
        ("XY", 2, 2, side, beta, draws)
        for side, draws in ((16, 4000), (32, 2000), (64, 1000))
        for beta in (0.7, 0.9, 1.2, 1.5)
    ),
    *(
        ("O(4)", 4, 2, side, beta, draws)
        for side, draws in ((16, 4000), (32, 2000), (64, 1000))
        for beta in (1.2, 1.8, 2.4)
    ),
)
QUICK_CASES = (
    ("XY", 2, 3, 4, 0.4542, 200),
    ("O(4)", 4, 2, 8, 1.8, 200),
)
SAMPLERS = ("heat bath + OR", "swendsen-wang")
QUANTITIES = ("abs_m", "energy_per_site")


def build_sampler(label, system, beta):
    if label == "swendsen-wang":
        return liesample.heisenberg_cluster(system, beta=beta)
    return liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=1)


def random_starts(system, seed):
    """Hot starts: ``NUM_CHAINS`` independent uniform unit vectors per site."""
    x = np.random.default_rng(seed).normal(size=(NUM_CHAINS, *system.event_shape))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def measure(case, label, log):
    """The rows of one run: one per quantity."""
    model, n, dimension, side, beta, num_draws = case
    system = n_vector((side,) * dimension, n, periodic=True)
    num_warmup = round(WARMUP_FRACTION * num_draws)
    with warnings.catch_warnings():  # a slow chain's convergence warning is in the rows' R-hat
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(
            build_sampler(label, system, beta),
            jax.random.key(SEED),
            random_starts(system, SEED),
            num_draws,
            num_warmup=num_warmup,
            observables=observables(model, system),  # |m| and the energy per site
            keep_positions=False,
            progress_bar=False,
        )
    seconds = float(tree.attrs["sampling_time"])
    draws = {q: np.asarray(tree.posterior[q].values, dtype=float) for q in QUANTITIES}
    table = expectation_table(draws, wall_time=seconds)
    rows = []
    for quantity, row in table.iterrows():
        tau = NUM_CHAINS * num_draws / row["ess_bulk"]
        rows.append(
            {
                "model": model,
                "n": n,
                "dimension": dimension,
                "side": side,
                "sites": side**dimension,
                "beta": beta,
                "sampler": label,
                "quantity": quantity,
                "estimate": row["estimate"],
                "mcse": row["mcse"],
                "ess_bulk": row["ess_bulk"],
                "r_hat": row["r_hat"],
                "tau_int": tau,
                "ess_per_second": row["ess_per_second"],
                "wall_seconds": seconds,
                "draws_per_chain": num_draws,
                "warmup_steps": num_warmup,
                "ms_per_step": 1e3 * seconds / (num_warmup + num_draws),
            }
        )
        log(
            f"    {label:<15} {quantity:<16} {row['estimate']:9.4f} ± {row['mcse']:.4f}  "
            f"ESS {row['ess_bulk']:7.0f}  R̂ {row['r_hat']:.3f}  τ {tau:7.1f}  "
            f"{seconds:6.1f} s  ESS/s {row['ess_per_second']:8.1f}"
        )
    return rows


def _point(r):
    return (r["model"], r["dimension"], r["side"], r["beta"])


def verdicts(rows):
    """Per point: the ESS/s ratio swendsen-wang / heat bath + OR of each quantity, their τ_int,
    and the winner by the slower quantity of each sampler."""
    out = []
    for point in dict.fromkeys(_point(r) for r in rows):
        mine = [r for r in rows if _point(r) == point]
        by = {(r["sampler"], r["quantity"]): r for r in mine}
        entry = {
            "model": point[0],
            "n": mine[0]["n"],
            "dimension": point[1],
            "side": point[2],
            "sites": mine[0]["sites"],
            "beta": point[3],
            "max_r_hat": max(r["r_hat"] for r in mine),
            "min_ess": min(r["ess_bulk"] for r in mine),
        }
        for q in QUANTITIES:
            hb, sw = by[("heat bath + OR", q)], by[("swendsen-wang", q)]
            entry[f"ratio_{q}"] = sw["ess_per_second"] / hb["ess_per_second"]
            entry[f"tau_heat_bath_{q}"] = hb["tau_int"]
            entry[f"tau_cluster_{q}"] = sw["tau_int"]
        slowest = {s: min(by[(s, q)]["ess_per_second"] for q in QUANTITIES) for s in SAMPLERS}
        entry["ratio_slowest"] = slowest["swendsen-wang"] / slowest["heat bath + OR"]
        entry["winner"] = "swendsen-wang" if entry["ratio_slowest"] > 1.0 else "heat bath + OR"
        entry["step_cost_ratio"] = (
            by[("swendsen-wang", QUANTITIES[0])]["ms_per_step"]
            / by[("heat bath + OR", QUANTITIES[0])]["ms_per_step"]
        )
        out.append(entry)
    return out


def plot(points, path):
    """ESS/s ratio swendsen-wang / heat bath + OR per point, for |m| and the energy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = points[::-1]
    labels = [f"{p['model']} {p['dimension']}-D L={p['side']} β={p['beta']}" for p in shown]
    y = np.arange(len(shown))
    fig, ax = plt.subplots(figsize=(8, 1.5 + 0.3 * len(shown)))
    ax.barh(y + 0.2, [p["ratio_abs_m"] for p in shown], 0.4, label="|m|")
    ax.barh(y - 0.2, [p["ratio_energy_per_site"] for p in shown], 0.4, label="energy")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("ESS/s ratio, swendsen-wang / heat bath + OR (> 1: the cluster wins)")
    ax.set_yticks(y, labels, fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle("O(n) on periodic lattices, J = 1")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    rows = []
    for case in QUICK_CASES if quick else CASES:
        model, _, dimension, side, beta, num_draws = case
        log(f"  {model} {dimension}-D L = {side}, beta = {beta}, {NUM_CHAINS} x {num_draws} draws")
        for label in SAMPLERS:
            rows += measure(case, label, log)
    points = verdicts(rows)
    plot(points, out_dir / "cluster_choice.png")
    path = common.write_json(
        out_dir / "cluster_choice.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "chains": NUM_CHAINS,
            "warmup_fraction": WARMUP_FRACTION,
            "ess": rows,
            "points": points,
            "total_seconds": time.perf_counter() - start,
        },
    )
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _point_lines(points):
    lines = []
    for p in points:
        flag = " ⚠" if p["max_r_hat"] >= 1.01 or p["min_ess"] < 100 else ""
        lines.append(
            f"| {p['model']} | {p['dimension']} | {p['side']} | {p['beta']} | "
            f"{_fmt(p['tau_heat_bath_abs_m'])} / {_fmt(p['tau_cluster_abs_m'])} | "
            f"{_fmt(p['tau_heat_bath_energy_per_site'])} / "
            f"{_fmt(p['tau_cluster_energy_per_site'])} | "
            f"{p['ratio_abs_m']:.2g}× | {p['ratio_energy_per_site']:.2g}× | "
            f"{p['step_cost_ratio']:.2g}× | **{p['winner']}**{flag} |"
        )
    return lines


def _detail_lines(rows):
    lines = []
    for r in rows:
        flag = "" if r["r_hat"] < 1.01 else " ⚠"
        lines.append(
            f"| {r['model']} | {r['dimension']} | {r['side']} | {r['beta']} | {r['sampler']} | "
            f"{r['quantity']} | {r['estimate']:.4f} ± {r['mcse']:.4f} | {r['ess_bulk']:.0f} | "
            f"{r['r_hat']:.3f}{flag} | {_fmt(r['tau_int'])} | {_fmt(r['ess_per_second'])} | "
            f"{r['ms_per_step']:.3g} |"
        )
    return lines


def _findings(points) -> str:
    """Where the cluster won, per (model, dimension), and the step costs, from the JSON."""
    parts = []
    for key in dict.fromkeys((p["model"], p["dimension"]) for p in points):
        mine = [p for p in points if (p["model"], p["dimension"]) == key]
        won = [p for p in mine if p["winner"] == "swendsen-wang"]
        if len(won) == len(mine):
            where = f"at all {len(mine)} points"
        elif not won:
            where = f"at none of the {len(mine)} points"
        else:
            where = f"at {len(won)} of {len(mine)} points: " + ", ".join(
                f"L = {p['side']} β = {p['beta']}" for p in won
            )
        ratios = [p["ratio_slowest"] for p in mine]
        parts.append(
            f"{key[0]} {key[1]}-D, Swendsen–Wang wins {where} (slower quantity's ESS/s ratio "
            f"{min(ratios):.2g}–{max(ratios):.2g}×)"
        )
    costs = [p["step_cost_ratio"] for p in points]
    return (
        "Summary (computed from the rows above; the winner is the sampler whose slower "
        "quantity has the larger ESS/s): " + "; ".join(parts) + ". A Swendsen–Wang step costs "
        f"{min(costs):.2g}–{max(costs):.2g}× a heat-bath + over-relaxation step here, which "
        "can outweigh a longer τ_int per step. `liesample.recommended_sampler` "
        "follows this table for O(n), n ≠ 3 (`liesample/samplers/recommended.py`, "
        "`N_VECTOR_CLUSTER_WINDOWS`)."
    )


def report_section(results) -> str:
    """The ``RESULTS.md`` section for the contents of ``cluster_choice.json``."""
    rows, points, machine = results["ess"], results["points"], results["machine"]
    lines = [
        "## O(n) lattices, n ≠ 3: heat bath + over-relaxation vs Swendsen–Wang",
        "",
        (
            f"From `benchmarks/cluster_choice.py` ({machine['date_utc']}, {results['mode']} "
            f"mode, {results['total_seconds']:.0f} s, jax {machine['jax']}, "
            f"{machine['cpu_model']}, {machine['usable_cpus']} usable CPUs, load average "
            f"{machine['load_average_1min']} at the end; the cores were shared with other "
            "jobs, so ESS/s is rough, while τ_int does not depend on the machine). Periodic "
            f"lattices, J = 1, no field, {results['chains']} chains from random spins, one draw "
            f"per step, warm-up {results['warmup_fraction']:.0%} of the draws; both samplers in "
            "one process from the same starts and key. `heat bath + OR` is "
            "`heisenberg_heat_bath(…, overrelaxation=1)`, `swendsen-wang` is "
            "`heisenberg_cluster(…)`. ESS is ArviZ's bulk ESS over the chains, τ_int = chains × "
            "draws / ESS in steps, ESS/s over the run's `sampling_time` (compilation excluded, "
            "warm-up included). The ratios are swendsen-wang / heat bath + OR in ESS/s "
            "(> 1: the cluster is faster); the step cost is the ratio of ms per step. The winner "
            "is the sampler whose slower quantity has the larger ESS/s. 3-D XY β_c ≈ 0.4542, "
            "3-D O(4) β_c ≈ 0.9359, 2-D XY β_BKT ≈ 1.12 (`benchmarks/critical_points.py`)."
        ),
        "",
        "| model | dim | L | β | τ_int(\\|m\\|) HB / SW | τ_int(E) HB / SW | ESS/s \\|m\\| | "
        "ESS/s E | step cost | winner |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *_point_lines(points),
        "",
        "⚠: R-hat ≥ 1.01 or an ESS below 100 in one of the runs; that point's ratio is rough.",
        "",
        "<details><summary>All rows</summary>",
        "",
        "| model | dim | L | β | sampler | quantity | estimate ± MCSE | ESS | R-hat | τ_int | "
        "ESS/s | ms/step |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *_detail_lines(rows),
        "",
        "</details>",
        "",
        _findings(points),
        "",
        "![ESS/s ratio per point](results/cluster_choice.png)",
        "",
    ]
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``cluster_choice.json``, if it exists (``suites.report_sections``)."""
    del md_dir
    path = out_dir / "cluster_choice.json"
    if not path.exists():
        return ""
    return report_section(json.loads(path.read_text()))


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
