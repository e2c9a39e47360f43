"""Published critical points of O(n) lattices, measured on small periodic lattices: the 3-D XY
and O(4) critical couplings from Binder-cumulant crossings, and the 2-D XY helicity modulus
against the Kosterlitz–Thouless line ``Υ = 2T/π``.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/critical_points.py          # several minutes on 2 shared cores
    .venv/bin/python benchmarks/critical_points.py --quick  # smoke run (results/quick/)

Writes ``critical_points.json`` and ``critical_points.png``. Every run is one
``liesample.sample`` call on ``systems.n_vector(shape, n, periodic=True)`` (J = 1, no field)
with :data:`NUM_CHAINS` chains from random spins, one draw per step after a warm-up of
:data:`WARMUP` steps, recording the mean spin ``m`` per draw (and, in 2-D, the helicity sums
of :func:`liesample.analysis.helicity.xy_helicity_sums`). The samplers: ``recommended``
(``liesample.recommended_sampler(system, beta=β)``: the heat bath with one over-relaxation
sweep per step, or Swendsen–Wang where its measured table picks it; the rows record which) and,
for the 3-D XY model, ``plain heat bath``
(``heisenberg_heat_bath(system, beta=β, overrelaxation=0)``) beside it.

- **3-D XY and O(4).** At three couplings around the published ``β_c`` on two lattice sizes,
  the Binder cumulant ``U = 1 − ⟨m⁴⟩/(3⟨m²⟩²)``; per lattice a straight line through its three
  points (least squares in ``β``), and ``β_cross`` where the two lines meet. Its error is the
  jackknife over the chains: leaving out chain ``c`` of every run at once (the chains are
  independent, so the error includes their autocorrelation whatever its length). The points'
  own errors are :func:`liesample.analysis.fluctuations.binder_cumulant`'s jackknife over
  blocks of the automatic blocking level. Finite-size corrections shift ``β_cross`` from
  ``β_c`` by an amount that shrinks with the lattice; on lattices this small it may be
  comparable to the statistical error.
- **2-D XY.** The helicity modulus ``Υ_L(T)`` (:func:`liesample.analysis.helicity.
  helicity_modulus`, jackknife over blocks) at a few temperatures on three lattice sizes, and
  ``T*(L)``, where ``Υ_L`` crosses ``2T/π`` (linear interpolation between the two bracketing
  temperatures; jackknife over the chains). ``T*(L)`` lies above ``T_BKT`` and approaches it
  only as ``1/(ln L)²``: on these lattices it shows the drift, not ``T_BKT``.

Published values (:data:`PUBLISHED`, with what of each citation is checked): the 3-D XY
``β_c = 0.45416`` as commonly quoted from Campostrini, Hasenbusch, Pelissetto and Vicari
(Phys. Rev. B 74 (2006) 144506) and Hasenbusch (Phys. Rev. B 100 (2019) 224517), digits not
checked against their tables, beside the cluster Monte Carlo value ``K_c = 0.45420(2)`` of
Gottlob and Hasenbusch (Physica A 201 (1993) 593; the value checked against its abstract); the
3-D O(4) ``K_c = 0.935856(2)`` of Deng (Phys. Rev. E 73 (2006) 056116), beside
``β_c = 0.9360(1)`` of Kanaya and Kaya (Phys. Rev. D 51 (1995) 2404); the 2-D XY
``T_BKT = 0.8929`` of Hasenbusch (J. Phys. A 38 (2005) 5869; not checked), beside
``T_KT = 0.8933(6)`` of Tomita and Okabe (Phys. Rev. B 65 (2002) 184405; the value checked
against its abstract); the jump ``Υ(T_BKT) = 2T_BKT/π`` of Nelson and Kosterlitz (Phys. Rev.
Lett. 39 (1977) 1201).
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
from liesample.analysis.fluctuations import binder_cumulant
from liesample.analysis.helicity import helicity_modulus, xy_helicity_sums
from liesample.systems import n_vector

SUITE = {
    "order": 33,
    "title": "published critical points: 3-D XY and O(4) Binder crossings, 2-D XY helicity modulus",
}

NUM_CHAINS = 8
WARMUP = 300
SEED = 11

PUBLISHED = {
    "3-D XY": {
        "value": 0.45416,
        "error": 1e-5,
        "quantity": "β_c",
        "source": (
            "as commonly quoted from Campostrini, Hasenbusch, Pelissetto & Vicari, Phys. Rev. "
            "B 74 (2006) 144506 (cond-mat/0605083, whose abstract gives the exponents only) and "
            "Hasenbusch, Phys. Rev. B 100 (2019) 224517 (arXiv:1910.05916, whose abstract "
            "announces critical temperatures; 0.45416474(10) is the digit string attributed to "
            "it); not checked here against either paper's tables"
        ),
        "also": (
            "K_c = 0.45420(2), Gottlob & Hasenbusch, Physica A 201 (1993) 593 (the value as the "
            "paper's abstract gives it; the journal reference not checked here)"
        ),
    },
    "3-D O(4)": {
        "value": 0.935856,
        "error": 2e-6,
        "quantity": "β_c",
        "source": "Deng, Phys. Rev. E 73 (2006) 056116",
        "also": "β_c = 0.9360(1), Kanaya & Kaya, Phys. Rev. D 51 (1995) 2404",
    },
    "2-D XY": {
        "value": 0.8929,
        "error": 1e-4,
        "quantity": "T_BKT",
        "source": (
            "Hasenbusch, J. Phys. A 38 (2005) 5869, as commonly quoted (the value not checked "
            "here against the paper)"
        ),
        "also": (
            "T_KT = 0.8933(6), Tomita & Okabe, Phys. Rev. B 65 (2002) 184405 (cond-mat/0202161; "
            "the value as its abstract gives it)"
        ),
    },
}

# model -> (n, lattice sides, couplings β, draws per chain)
CROSSINGS = {
    "3-D XY": (2, (6, 8), (0.440, 0.452, 0.464), 1500),
    "3-D O(4)": (4, (6, 8), (0.915, 0.935, 0.955), 1500),
}
QUICK_CROSSINGS = {
    "3-D XY": (2, (4, 6), (0.43, 0.45, 0.47), 200),
    "3-D O(4)": (4, (4, 6), (0.90, 0.93, 0.96), 200),
}
PLAIN_FOR = ("3-D XY",)
# 2-D XY: lattice sides, temperatures, draws per chain
HELICITY = ((8, 16, 32), (0.85, 0.90, 0.95, 1.00, 1.05), 1000)
QUICK_HELICITY = ((8, 16), (0.85, 0.95, 1.05), 200)


def build_sampler(label, system, beta):
    if label == "recommended":
        return liesample.recommended_sampler(system, beta=beta)
    return liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=0)


def random_starts(system, seed):
    x = np.random.default_rng(seed).normal(size=(NUM_CHAINS, *system.event_shape))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def run_point(system, beta, label, num_draws, helicity=False):
    """One ``liesample.sample`` run: per-draw observables (numpy), seconds and the sampler."""
    n = system.event_shape[-1]
    observables = {"m": lambda s: jnp.mean(s.reshape(-1, n), axis=0)}
    if helicity:
        observables["helicity"] = xy_helicity_sums
    algorithm = build_sampler(label, system, beta)
    with warnings.catch_warnings():  # slow mixing shows in the errors and R-hat of the rows
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(
            algorithm,
            jax.random.key(SEED),
            random_starts(system, SEED),
            num_draws,
            num_warmup=WARMUP,
            observables=observables,
            keep_positions=False,
            progress_bar=False,
        )
    draws = {q: np.asarray(tree.posterior[q].values, dtype=float) for q in observables}
    return draws, float(tree.attrs["sampling_time"]), str(tree.attrs.get("sampler"))


def _binder_from_chains(m):
    """``U`` from the pooled moments of ``m`` (chains, draws, n)."""
    m2 = np.sum(m**2, axis=-1)
    return 1.0 - np.mean(m2**2) / (3.0 * np.mean(m2) ** 2)


def line_crossing(betas, u_small, u_large):
    """``β`` where the least-squares lines through ``(β, U_small)`` and ``(β, U_large)`` meet."""
    b = np.asarray(betas) - np.mean(betas)
    slope_small, slope_large = np.polyfit(b, u_small, 1)[0], np.polyfit(b, u_large, 1)[0]
    gap = np.mean(u_small) - np.mean(u_large)
    return float(np.mean(betas) + gap / (slope_large - slope_small))


def jackknife_over_chains(estimate, series_by_run):
    """``(estimate(all), error)``: ``estimate(dict run -> (chains, ...) array)`` recomputed with
    chain ``c`` left out of every run at once."""
    full = estimate(series_by_run)
    chains = next(iter(series_by_run.values())).shape[0]
    values = np.array(
        [
            estimate({k: np.delete(v, c, axis=0) for k, v in series_by_run.items()})
            for c in range(chains)
        ]
    )
    error = np.sqrt((chains - 1) / chains * np.sum((values - values.mean()) ** 2))
    return full, float(error)


def measure_crossing(model, n, sides, betas, num_draws, label, log):
    """The points ``U(L, β)`` and the crossing row of one model and sampler."""
    points, m_by_run, seconds, sampler_name = [], {}, 0.0, ""
    for side in sides:
        system = n_vector((side,) * 3, n, periodic=True)
        for beta in betas:
            draws, secs, sampler_name = run_point(system, beta, label, num_draws)
            seconds += secs
            m_by_run[(side, beta)] = draws["m"]
            u = binder_cumulant(draws["m"])
            points.append({"model": model, "sampler": label, "L": side, "beta": beta,
                           "U": u.estimate, "U_error": u.error, "seconds": secs})  # fmt: skip
            log(f"    {label:<16} L={side:<3} β={beta:.4f}  U = {u.estimate:.4f} ± {u.error:.4f}")

    def crossing(runs):
        u = [[_binder_from_chains(runs[(side, b)]) for b in betas] for side in sides]
        return line_crossing(betas, u[0], u[-1])

    beta_cross, error = jackknife_over_chains(crossing, m_by_run)
    published = PUBLISHED[model]
    z = (beta_cross - published["value"]) / np.hypot(error, published["error"])
    row = {
        "model": model, "sampler": label, "sampler_name": sampler_name,
        "lattices": f"{sides[0]}³ × {sides[-1]}³", "measured": beta_cross, "error": error,
        "published": published["value"], "published_error": published["error"],
        "z": float(z), "chain_steps": NUM_CHAINS * (WARMUP + num_draws) * len(sides) * len(betas),
        "seconds": seconds, "chains": NUM_CHAINS, "draws_per_chain": num_draws,
    }  # fmt: skip
    log(f"  {model} {label}: β_cross = {beta_cross:.5f} ± {error:.5f}  ({z:+.1f} σ from "
        f"{published['value']})")  # fmt: skip
    return points, row


def helicity_crossing(temperatures, sums_by_run, side):
    """``T*``, where ``Υ_L(T) − 2T/π`` changes sign (linear interpolation), or ``nan``."""
    gaps = []
    for t in temperatures:
        sums = sums_by_run[(side, t)]
        cos_mean = sums[..., 0].mean(axis=-1).mean()
        sin_square = (sums[..., 1] ** 2).mean(axis=-1).mean()
        gaps.append((cos_mean - sin_square / t) / side**2 - 2.0 * t / np.pi)
    for i in range(len(gaps) - 1):
        if gaps[i] > 0 >= gaps[i + 1]:
            t0, t1 = temperatures[i], temperatures[i + 1]
            return t0 + (t1 - t0) * gaps[i] / (gaps[i] - gaps[i + 1])
    return float("nan")


def measure_helicity(sides, temperatures, num_draws, log):
    """The points ``Υ(L, T)`` and one ``T*(L)`` row per lattice (recommended sampler)."""
    points, rows, sums_by_run = [], [], {}
    for side in sides:
        system = n_vector((side, side), 2, periodic=True)
        seconds = 0.0
        for t in temperatures:
            draws, secs, sampler_name = run_point(system, 1.0 / t, "recommended", num_draws, True)
            seconds += secs
            sums_by_run[(side, t)] = draws["helicity"]
            y = helicity_modulus(draws["helicity"], beta=1.0 / t, num_sites=side**2)
            points.append({"L": side, "T": t, "upsilon": y.estimate, "upsilon_error": y.error,
                           "seconds": secs})  # fmt: skip
            log(f"    L={side:<3} T={t:.3f}  Υ = {y.estimate:.4f} ± {y.error:.4f}  "
                f"(2T/π = {2 * t / np.pi:.4f})")  # fmt: skip
        runs = {k: v for k, v in sums_by_run.items() if k[0] == side}
        t_star, error = jackknife_over_chains(
            lambda r, side=side: helicity_crossing(temperatures, r, side), runs
        )
        published = PUBLISHED["2-D XY"]
        rows.append({
            "model": "2-D XY", "sampler": "recommended", "sampler_name": sampler_name,
            "lattices": f"{side}²", "measured": t_star, "error": error,
            "published": published["value"], "published_error": published["error"],
            "z": float((t_star - published["value"]) / np.hypot(error, published["error"])),
            "chain_steps": NUM_CHAINS * (WARMUP + num_draws) * len(temperatures),
            "seconds": seconds, "chains": NUM_CHAINS, "draws_per_chain": num_draws,
        })  # fmt: skip
        log(f"  2-D XY L={side}: T* = {t_star:.4f} ± {error:.4f} (finite-size; T_BKT "
            f"{published['value']})")  # fmt: skip
    return points, rows


def plot(results, path):
    """``U(β)`` of the 3-D models per lattice, and ``Υ(T)`` of the 2-D XY model per lattice
    with the line ``2T/π``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for ax, model in zip(axes[:2], CROSSINGS):
        for label, marker in (("recommended", "o"), ("plain heat bath", "s")):
            pts = [p for p in results["binder_points"]
                   if p["model"] == model and p["sampler"] == label]  # fmt: skip
            for side in sorted({p["L"] for p in pts}):
                sel = [p for p in pts if p["L"] == side]
                ax.errorbar([p["beta"] for p in sel], [p["U"] for p in sel],
                            [p["U_error"] for p in sel], marker=marker, capsize=3,
                            ls="-" if label == "recommended" else ":",
                            label=f"L = {side} ({label})")  # fmt: skip
        ax.axvline(PUBLISHED[model]["value"], color="k", lw=0.8, label="published β_c")
        ax.set_xlabel("β")
        ax.set_ylabel("Binder cumulant U")
        ax.set_title(f"{model}: U(β) on L³")
        ax.legend(fontsize=7)
    ax = axes[2]
    pts = results["helicity_points"]
    for side in sorted({p["L"] for p in pts}):
        sel = [p for p in pts if p["L"] == side]
        ax.errorbar([p["T"] for p in sel], [p["upsilon"] for p in sel],
                    [p["upsilon_error"] for p in sel], marker="o", capsize=3,
                    label=f"L = {side}")  # fmt: skip
    t = np.linspace(min(p["T"] for p in pts), max(p["T"] for p in pts), 50)
    ax.plot(t, 2 * t / np.pi, "k--", lw=1, label="2T/π")
    ax.axvline(PUBLISHED["2-D XY"]["value"], color="k", lw=0.8, label="T_BKT")
    ax.set_xlabel("T")
    ax.set_ylabel("helicity modulus Υ")
    ax.set_title("2-D XY: Υ(T) on L² (finite-size crossing drifts to T_BKT)")
    ax.legend(fontsize=7)
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    binder_points, rows = [], []
    for model, (n, sides, betas, num_draws) in (QUICK_CROSSINGS if quick else CROSSINGS).items():
        log(f"  {model}: L = {sides}, β = {betas}, {NUM_CHAINS} x {num_draws} draws")
        for label in ("recommended", "plain heat bath") if model in PLAIN_FOR else ("recommended",):
            points, row = measure_crossing(model, n, sides, betas, num_draws, label, log)
            binder_points += points
            rows.append(row)
    sides, temperatures, num_draws = QUICK_HELICITY if quick else HELICITY
    log(f"  2-D XY: L = {sides}, T = {temperatures}, {NUM_CHAINS} x {num_draws} draws")
    helicity_points, helicity_rows = measure_helicity(sides, temperatures, num_draws, log)
    results = {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": "quick" if quick else "full",
        "chains": NUM_CHAINS,
        "warmup_steps": WARMUP,
        "published": PUBLISHED,
        "rows": rows + helicity_rows,
        "binder_points": binder_points,
        "helicity_points": helicity_points,
        "total_seconds": time.perf_counter() - start,
    }
    plot(results, out_dir / "critical_points.png")
    path = common.write_json(out_dir / "critical_points.json", results)
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _row_line(r):
    def fmt(x, e):
        return "—" if not np.isfinite(x) else f"{x:.4f} ± {e:.4f}"

    z = "—" if not np.isfinite(r["z"]) else f"{r['z']:+.1f}"
    quantity = "T*(L), finite-size" if r["model"].startswith("2-D") else "β_cross"
    return (
        f"| {r['model']} | {r['lattices']} | {r['sampler']} | {quantity} | "
        f"{fmt(r['measured'], r['error'])} | "
        f"{r['published']:g} | {z} | {r['chain_steps']:,} | {r['seconds']:.0f} |"
    )


def _findings(rows) -> str:
    """A summary of the rows, computed from the JSON."""
    three = [r for r in rows if r["model"].startswith("3-D") and np.isfinite(r["z"])]
    two = sorted(
        (r for r in rows if r["model"].startswith("2-D")), key=lambda r: int(r["lattices"][:-1])
    )
    parts = []
    if three:
        zs = ", ".join(f"{r['model']} {r['sampler']} {r['z']:+.1f} σ" for r in three)
        parts.append(
            f"The crossings of the two smallest lattices lie at {zs} from the published "
            "couplings: on lattices this small a shift of this size can come from the "
            "corrections to scaling (a larger lattice pair would show whether it shrinks)."
        )
    finite = [r for r in two if np.isfinite(r["measured"])]
    if len(finite) >= 2:
        drift = " → ".join(f"{r['measured']:.3f} ({r['lattices']})" for r in finite)
        parts.append(
            f"T*(L) of the 2-D XY model moves towards T_BKT as the lattice grows: {drift}, "
            f"against T_BKT = {finite[0]['published']}."
        )
    return "Summary (computed from the rows above). " + " ".join(parts) if parts else ""


def report_section(results) -> str:
    """The ``RESULTS.md`` section for the contents of ``critical_points.json``."""
    machine, published = results["machine"], results["published"]
    cited = {model: PUBLISHED.get(model, p) for model, p in published.items()}  # the citations
    sources = "; ".join(  # as the module now gives them, the values as the run used them
        f"{model}: {p['quantity']} = {p['value']:g} ({cited[model]['source']}; also "
        f"{cited[model]['also']})"
        for model, p in published.items()
    )
    lines = [
        "## Published critical points: 3-D XY and O(4) Binder crossings, 2-D XY helicity",
        "",
        (
            f"From `benchmarks/critical_points.py` ({machine['date_utc']}, {results['mode']} "
            f"mode, {results['total_seconds']:.0f} s, jax {machine['jax']}, "
            f"{machine['cpu_model']}, {machine['usable_cpus']} usable CPUs, load average "
            f"{machine['load_average_1min']} at the end; the cores were shared with other "
            f"jobs, so the seconds are rough). Periodic lattices, J = 1, no field, "
            f"{results['chains']} chains from random spins, warm-up {results['warmup_steps']} "
            "steps, one draw per step. The 3-D rows: β where the straight lines fitted to "
            "the Binder cumulant U(β) of the two lattices cross. The 2-D rows: T* where the "
            "helicity modulus Υ_L(T) crosses 2T/π, a finite-size temperature that approaches "
            "T_BKT only as 1/(ln L)², so the column 'σ from published' shows the drift, not a "
            "failure. Errors: jackknife over the chains (each chain left out of every run at "
            "once), which includes the autocorrelation however long; the points' errors in "
            "the figure are jackknife errors over blocks of the automatic blocking level "
            "(blocking_error), which include it too. σ from published: (measured − "
            "published) / the two errors in quadrature. Chain-steps: steps of every chain "
            "over all runs of the row, warm-up included; seconds: their `sampling_time` "
            "(compilation excluded)."
        ),
        "",
        "| model | lattices | sampler | quantity | measured | published | σ from published | "
        "chain-steps | seconds |",
        "|---|---|---|---|---|---|---|---|---|",
        *[_row_line(r) for r in results["rows"]],
        "",
        f"Published values: {sources}; the jump Υ(T_BKT) = 2T_BKT/π: Nelson & Kosterlitz, "
        "Phys. Rev. Lett. 39 (1977) 1201.",
        "",
        _findings(results["rows"]),
        "",
        "![Binder cumulants and the helicity modulus](results/critical_points.png)",
        "",
    ]
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``critical_points.json``, if it exists (``suites.report_sections``)."""
    del md_dir
    path = out_dir / "critical_points.json"
    if not path.exists():
        return ""
    return report_section(json.loads(path.read_text()))


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
