"""Spin lattices beyond the Heisenberg model: the recommended sampler against a plain heat bath
for the 2-D XY (O(2)), O(3), O(4) and CP(2) models, with the topological charge.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/spins_beyond_o3.py          # ~5 min on 2 shared cores
    .venv/bin/python benchmarks/spins_beyond_o3.py --quick  # smoke run (results/quick/)

Writes ``spins_beyond_o3.json`` and ``spins_beyond_o3.png``. On periodic 16×16 and 32×32
lattices (J = 1, no field; :func:`liesample.systems.n_vector` for O(n),
:func:`liesample.systems.cp_model` for CP(N−1)) at the β of :data:`CASES`, two samplers run side
by side in one process, from the same random starts and key:

- ``recommended``: ``liesample.recommended_sampler(system, beta=β)`` (on these lattices
  Swendsen–Wang, ``heisenberg_cluster``, where the table measured by ``cluster_choice.py``
  picks it, else the heat bath with one over-relaxation sweep per step,
  ``heisenberg_heat_bath`` or ``cp_heat_bath``; the run records which, from the tree's
  ``sampler`` attribute);
- ``plain heat bath``: ``heisenberg_heat_bath(system, beta=β, overrelaxation=0)`` or
  ``cp_heat_bath(system, beta=β, overrelaxation=0)``, one heat-bath sweep per step.

Each run is one ``liesample.sample`` call: :data:`NUM_CHAINS` chains, the case's number of
draws (one per step) after a warm-up of :data:`WARMUP_FRACTION` of them, observables recorded
with ``observables=`` (``keep_positions=False``): ``|m|`` (the norm of the mean spin) and the
energy per site for O(n); for CP(N−1) the energy per site and ``|P̄| = ‖P̄ − 1/N‖`` (the
Frobenius norm of the mean projector ``P = z z^†`` less ``1/N``, the counterpart of ``|m|``);
for O(3) and CP(N−1) the geometric topological charge ``Q``
(:func:`liesample.analysis.topology.topological_charge`, ``cp_topological_charge``) and its
susceptibility per draw, ``Q²/V`` (whose mean is ``χ_t``; its jackknife error comes from
:func:`liesample.analysis.topology.topological_susceptibility`). Bulk ESS and R-hat over the
chains come from :func:`liesample.analysis.diagnostics.expectation_table` (ArviZ);
``τ_int = chains × draws / ESS`` in steps; ESS/s divides by the run's ``sampling_time``
(compilation excluded, warm-up included). The ratio ``recommended / plain`` of ESS/s is the
row's result.
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

import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common, suites
from liesample.analysis.diagnostics import expectation_table
from liesample.analysis.topology import (
    cp_topological_charge,
    topological_charge,
    topological_susceptibility,
)
from liesample.systems import cp_model, n_vector

SUITE = {
    "order": 32,
    "title": "spin lattices beyond O(3): XY, O(4), CP(2) and the topological charge, recommended "
    "vs plain heat bath",
}

NUM_CHAINS = 4
WARMUP_FRACTION = 0.25
SEED = 7

# (model, n or N, lattice side, beta, draws per chain): the XY model at and below its BKT
# temperature (T_BKT ≈ 0.893, β ≈ 1.12), O(3) and O(4) at moderate β, CP(2) at moderate β.
CASES = (
    ("XY", 2, 16, 0.9, 4000),
    ("XY", 2, 16, 1.2, 4000),
    ("XY", 2, 32, 0.9, 2000),
    ("XY", 2, 32, 1.2, 2000),
    ("O(3)", 3, 16, 1.5, 20000),
    ("O(3)", 3, 32, 1.5, 8000),
    ("O(4)", 4, 16, 1.8, 4000),
    ("O(4)", 4, 32, 1.8, 2000),
    ("CP(2)", 3, 16, 3.0, 2000),
    ("CP(2)", 3, 16, 4.0, 2000),
    ("CP(2)", 3, 32, 3.0, 800),
)
QUICK_CASES = (
    ("XY", 2, 8, 1.2, 200),
    ("O(3)", 3, 8, 1.5, 400),
    ("O(4)", 4, 8, 1.8, 200),
    ("CP(2)", 3, 8, 3.0, 200),
)
SAMPLERS = ("recommended", "plain heat bath")
# The quantities whose ESS/s ratios head each model's rows (issue 44: |m| or Q).
HEADLINE = {
    "XY": ("abs_m",),
    "O(3)": ("abs_m", "Q", "chi_t"),
    "O(4)": ("abs_m",),
    "CP(2)": ("energy_per_site", "abs_P", "Q"),
}


def build_system(model, n, side):
    if model.startswith("CP"):
        return cp_model((side, side), n, periodic=True)
    return n_vector((side, side), n, periodic=True)


def build_sampler(label, model, system, beta):
    if label == "recommended":
        return liesample.recommended_sampler(system, beta=beta)
    if model.startswith("CP"):
        return liesample.cp_heat_bath(system, beta=beta, overrelaxation=0)
    return liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=0)


def random_starts(model, system, seed):
    """Hot starts: ``NUM_CHAINS`` independent uniform unit vectors (complex for CP) per site."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(NUM_CHAINS, *system.event_shape))
    if model.startswith("CP"):
        x = x + 1j * rng.normal(size=x.shape)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def observables(model, system):
    """The per-draw observables of ``model`` (``observables=`` of ``liesample.sample``)."""
    n = system.event_shape[-1]
    volume = int(np.prod(system.event_shape[:-1]))
    out = {"energy_per_site": lambda s: system.hamiltonian(s) / volume}
    if model.startswith("CP"):
        out["abs_P"] = lambda z: projector_order(z.reshape(-1, n))
        out["Q"] = cp_topological_charge
    else:
        out["abs_m"] = lambda s: jnp.linalg.norm(jnp.mean(s.reshape(-1, n), axis=0))
    if model == "O(3)":
        out["Q"] = topological_charge
    return out


def projector_order(z):
    """``‖P̄ − 1/N‖`` (Frobenius), ``P̄`` the mean of ``P = z z^†`` over the sites of ``z``
    ``(V, N)``: the CP(N−1) counterpart of ``|m|`` (for ``N = 2``, ``|m|/√2`` of the Hopf
    spins)."""
    n = z.shape[-1]
    mean = jnp.einsum("vi,vj->ij", z, jnp.conj(z)) / z.shape[0]
    return jnp.linalg.norm(mean - jnp.eye(n) / n)


def measure(model, n, side, beta, num_draws, label, log):
    """The rows of one run: one per quantity."""
    system = build_system(model, n, side)
    algorithm = build_sampler(label, model, system, beta)
    num_warmup = round(WARMUP_FRACTION * num_draws)
    with warnings.catch_warnings():  # a slow chain's convergence warning is in the rows' R-hat
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(
            algorithm,
            jax.random.key(SEED),
            random_starts(model, system, SEED),
            num_draws,
            num_warmup=num_warmup,
            observables=observables(model, system),
            keep_positions=False,
            progress_bar=False,
        )
    seconds = float(tree.attrs["sampling_time"])
    draws = {q: np.asarray(tree.posterior[q].values, dtype=float) for q in tree.posterior}
    volume = side * side
    extra = {}
    if "Q" in draws:
        q = np.rint(draws["Q"])
        draws["Q"] = q
        draws["chi_t"] = q**2 / volume
        chi = topological_susceptibility(q, volume, block_size=max(1, num_draws // 16))
        extra = {
            "chi_t_jackknife": chi.estimate,
            "chi_t_jackknife_error": chi.error,
            "changes_of_Q_per_chain": np.count_nonzero(np.diff(q, axis=1), axis=1).tolist(),
        }
    table = expectation_table(draws, wall_time=seconds)
    rows = []
    for quantity, row in table.iterrows():
        tau = NUM_CHAINS * num_draws / row["ess_bulk"]
        rows.append(
            {
                "model": model,
                "n": n,
                "lattice": f"{side}x{side}",
                "beta": beta,
                "sampler": label,
                "sampler_name": str(tree.attrs.get("sampler")),
                "overrelaxation": int(algorithm.settings.get("overrelaxation", -1)),
                "quantity": quantity,
                "estimate": row["estimate"],
                "mcse": row["mcse"],
                "ess_bulk": row["ess_bulk"],
                "r_hat": row["r_hat"],
                "tau_int": tau,
                "ess_per_second": row["ess_per_second"],
                "wall_seconds": seconds,
                "chains": NUM_CHAINS,
                "draws_per_chain": num_draws,
                "warmup_steps": num_warmup,
                "ms_per_step": 1e3 * seconds / (num_warmup + num_draws),
                **(extra if quantity in ("Q", "chi_t") else {}),
            }
        )
        log(
            f"    {label:<16} {quantity:<16} {row['estimate']:9.4f} ± {row['mcse']:.4f}  "
            f"ESS {row['ess_bulk']:7.0f}  R̂ {row['r_hat']:.3f}  τ {tau:7.1f}  "
            f"{seconds:5.1f} s  ESS/s {row['ess_per_second']:8.1f}"
        )
    return rows


def ratios(rows):
    """Per (model, lattice, β, quantity): recommended / plain in ESS/s and τ_int."""
    out = []
    keys = dict.fromkeys((r["model"], r["lattice"], r["beta"], r["quantity"]) for r in rows)
    for key in keys:
        pair = {
            r["sampler"]: r
            for r in rows
            if (r["model"], r["lattice"], r["beta"], r["quantity"]) == key
        }
        rec, plain = pair["recommended"], pair["plain heat bath"]
        out.append(
            {
                "model": key[0],
                "lattice": key[1],
                "beta": key[2],
                "quantity": key[3],
                "ess_per_second_ratio": rec["ess_per_second"] / plain["ess_per_second"],
                "tau_int_recommended": rec["tau_int"],
                "tau_int_plain": plain["tau_int"],
                "max_r_hat": max(rec["r_hat"], plain["r_hat"]),
            }
        )
    return out


def plot(ratio_rows, path):
    """τ_int of both samplers and their ESS/s ratio, one horizontal bar pair per headline row."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [r for r in ratio_rows if r["quantity"] in HEADLINE[r["model"]]][::-1]
    labels = [f"{r['model']} {r['lattice']} β={r['beta']}  {r['quantity']}" for r in shown]
    y = np.arange(len(shown))
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 1.5 + 0.3 * len(shown)), sharey=True)
    left.barh(y + 0.2, [r["tau_int_plain"] for r in shown], 0.4, label="plain heat bath")
    left.barh(y - 0.2, [r["tau_int_recommended"] for r in shown], 0.4, label="recommended")
    left.set_xscale("log")
    left.set_xlabel("τ_int (steps)")
    left.legend(fontsize=8)
    bars = right.barh(y, [r["ess_per_second_ratio"] for r in shown], 0.6, color="tab:green")
    for bar, r in zip(bars, shown):
        if r["max_r_hat"] >= 1.01:
            bar.set_hatch("//")
    right.axvline(1.0, color="k", lw=0.8)
    right.set_xscale("log")
    right.set_xlabel("ESS/s ratio, recommended / plain")
    left.set_yticks(y, labels, fontsize=8)
    for ax in (left, right):
        ax.grid(axis="x", alpha=0.3)
    fig.suptitle("2-D periodic spin lattices, J = 1 (hatched: R-hat ≥ 1.01 in one of the runs)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    rows = []
    for model, n, side, beta, num_draws in QUICK_CASES if quick else CASES:
        log(f"  {model} {side}x{side}, beta = {beta}, {NUM_CHAINS} x {num_draws} draws")
        for label in SAMPLERS:
            rows += measure(model, n, side, beta, num_draws, label, log)
    ratio_rows = ratios(rows)
    plot(ratio_rows, out_dir / "spins_beyond_o3.png")
    path = common.write_json(
        out_dir / "spins_beyond_o3.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "chains": NUM_CHAINS,
            "warmup_fraction": WARMUP_FRACTION,
            "ess": rows,
            "ratios": ratio_rows,
            "total_seconds": time.perf_counter() - start,
        },
    )
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _fmt(value, digits=3):
    return "—" if value is None or not np.isfinite(value) else f"{value:.{digits}g}"


def _headline_lines(ratio_rows):
    lines = []
    for r in ratio_rows:
        if r["quantity"] not in HEADLINE[r["model"]]:
            continue
        flag = " ⚠" if r["max_r_hat"] >= 1.01 else ""
        lines.append(
            f"| {r['model']} | {r['lattice']} | {r['beta']} | {r['quantity']} | "
            f"{_fmt(r['tau_int_plain'])} | {_fmt(r['tau_int_recommended'])} | "
            f"**{r['ess_per_second_ratio']:.2g}×**{flag} |"
        )
    return lines


def _detail_lines(rows):
    lines = []
    for r in rows:
        flag = "" if r["r_hat"] < 1.01 else " ⚠"
        lines.append(
            f"| {r['model']} | {r['lattice']} | {r['beta']} | {r['sampler']} | {r['quantity']} | "
            f"{r['estimate']:.4f} ± {r['mcse']:.4f} | {r['ess_bulk']:.0f} | "
            f"{r['r_hat']:.3f}{flag} | {_fmt(r['tau_int'])} | {_fmt(r['ess_per_second'])} | "
            f"{r['ms_per_step']:.3g} |"
        )
    return lines


def _topology_lines(rows):
    lines = []
    for r in rows:
        if r["quantity"] != "Q":
            continue
        lines.append(
            f"| {r['model']} | {r['lattice']} | {r['beta']} | {r['sampler']} | "
            f"{r['chi_t_jackknife']:.3g} ± {r['chi_t_jackknife_error']:.2g} | "
            f"{_fmt(r['tau_int'])} | {min(r['changes_of_Q_per_chain'])}–"
            f"{max(r['changes_of_Q_per_chain'])} |"
        )
    return lines


def _findings(results) -> str:
    """A summary of the ratios and the step costs, computed from the JSON."""
    ratios_ = results["ratios"]

    def span(quantities, model="", key="ess_per_second_ratio"):
        values = [
            r["tau_int_plain"] / r["tau_int_recommended"] if key == "tau" else r[key]
            for r in ratios_
            if r["quantity"] in quantities and r["model"].startswith(model)
        ]
        return f"{min(values):.2g}–{max(values):.2g}×" if values else "—"

    def cost(prefix):
        rows = [r for r in results["ess"] if r["model"].startswith(prefix)]
        rec = [r["ms_per_step"] for r in rows if r["sampler"] == "recommended"]
        plain = [r["ms_per_step"] for r in rows if r["sampler"] == "plain heat bath"]
        return f"{np.mean(rec) / np.mean(plain):.2g}×" if rec and plain else "—"

    long_range = ("abs_m", "abs_P")
    return (
        "Summary (computed from the rows above). On the long-wavelength quantities, |m| of "
        f"O(n) and ‖P̄ − 1/N‖ of CP(2), the recommended sampler gains {span(long_range)} in "
        f"ESS/s over the plain heat bath (τ_int shorter by {span(long_range, key='tau')}). On "
        f"the local ones the gain is smaller, or a loss: Q and Q²/V {span(('Q', 'chi_t'))}, "
        f"the energy of CP(2) {span(('energy_per_site',), 'CP')}. A step of the recommended "
        f"sampler costs {cost('O(')} / {cost('XY')} the plain one's for O(3)+O(4) / XY and "
        f"{cost('CP')} for CP(2) (its over-relaxation needs the top eigenvector of the local "
        "matrix at every site)."
    )


def _shortest_block_in_tau(rows) -> float:
    """The shortest jackknife block of ``χ_t`` (a sixteenth of a chain) in units of
    ``τ_int(Q)``, over the rows of ``Q``."""
    ratios = [r["draws_per_chain"] // 16 / r["tau_int"] for r in rows if r["quantity"] == "Q"]
    return min(ratios) if ratios else float("nan")


def report_section(results) -> str:
    """The ``RESULTS.md`` section for the contents of ``spins_beyond_o3.json``."""
    rows, machine = results["ess"], results["machine"]
    names = sorted({f"`{r['sampler_name']}`" + (f" ({r['overrelaxation']} over-relaxation)"
                                                 if r["overrelaxation"] >= 0 else "")
                    for r in rows if r["sampler"] == "recommended"})  # fmt: skip
    lines = [
        "## Spin lattices beyond O(3): XY, O(4), CP(2) and the topological charge",
        "",
        (
            f"From `benchmarks/spins_beyond_o3.py` ({machine['date_utc']}, {results['mode']} "
            f"mode, {results['total_seconds']:.0f} s, jax {machine['jax']}, "
            f"{machine['cpu_model']}, {machine['usable_cpus']} usable CPUs, load average "
            f"{machine['load_average_1min']} at the end; the cores were shared with other "
            "jobs, so ESS/s is rough, while τ_int does not depend on the machine). Periodic 2-D "
            f"lattices, J = 1, no field, {results['chains']} chains from random spins, one draw "
            f"per step, warm-up {results['warmup_fraction']:.0%} of the draws; both samplers "
            "in one process from the same starts and key. `recommended` is "
            "`liesample.recommended_sampler(system, beta=β)`, here "
            f"{', '.join(names)} per step; `plain` is the heat bath alone "
            "(`heisenberg_heat_bath` / `cp_heat_bath` with `overrelaxation=0`). ESS is ArviZ's "
            "bulk ESS over the chains, τ_int = chains × draws / ESS in steps, ESS/s over the "
            "run's `sampling_time` (compilation excluded, warm-up included). Error bars: "
            "± MCSE is ArviZ's Monte Carlo standard error of the mean, from that ESS, so it "
            "includes the autocorrelation; χ_t's error is the jackknife over 16 blocks per "
            f"chain, each at least {_shortest_block_in_tau(rows):.0f} τ_int(Q) long here (so it "
            "includes the autocorrelation too)."
        ),
        "",
        "| model | lattice | β | quantity | τ_int plain | τ_int recommended | "
        "ESS/s recommended / plain |",
        "|---|---|---|---|---|---|---|",
        *_headline_lines(results["ratios"]),
        "",
        (
            "Quantities: `abs_m` = |m| (norm of the mean spin), `Q` = geometric topological "
            "charge (Berg–Lüscher), `chi_t` = Q²/V per draw (its mean is χ_t), "
            "`energy_per_site` = h/V, `abs_P` = ‖P̄ − 1/N‖ (Frobenius norm of the mean "
            "projector z z^† less 1/N, the CP(N−1) counterpart of |m|). ⚠: R-hat ≥ 1.01 in "
            "one of the two runs, the ratio is rough."
        ),
        "",
        "Topological susceptibility χ_t (jackknife error) and the changes of Q per chain:",
        "",
        "| model | lattice | β | sampler | χ_t | τ_int(Q) | changes of Q per chain |",
        "|---|---|---|---|---|---|---|",
        *_topology_lines(rows),
        "",
        "<details><summary>All rows</summary>",
        "",
        "| model | lattice | β | sampler | quantity | estimate ± MCSE | ESS | R-hat | τ_int | "
        "ESS/s | ms/step |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *_detail_lines(rows),
        "",
        "</details>",
        "",
        _findings(results),
        "",
        "![τ_int and ESS/s ratio](results/spins_beyond_o3.png)",
        "",
    ]
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``spins_beyond_o3.json``, if it exists (``suites.report_sections``)."""
    del md_dir
    path = out_dir / "spins_beyond_o3.json"
    if not path.exists():
        return ""
    return report_section(json.loads(path.read_text()))


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
