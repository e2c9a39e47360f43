"""The SU(2) deconfinement transition from the Polyakov loop, and the anisotropic Wilson action.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/deconfinement.py              # every part (35–60 min on 2 cores)
    .venv/bin/python benchmarks/deconfinement.py --part nt4   # one part, merged into the JSON
    .venv/bin/python benchmarks/deconfinement.py --quick      # smoke (benchmarks/results/quick/)

Writes ``deconfinement.json`` and ``deconfinement.png``. Its parts (:data:`PARTS`): ``nt2``
(``N_t = 2``, ``N_s = 4, 6``), ``nt4`` (``N_t = 4``, ``N_s = 6, 8``) and ``anisotropic``; each
records its own machine, date and load, and ``--part`` (repeatable) reruns only those, keeping
the others from the existing JSON.

1. The 4-D SU(2) Wilson action on ``N_s³ × N_t`` lattices (``wilson_gauge("SU2", (N_s, N_s,
   N_s, N_t))``, time the last axis) at ``N_t = 2`` and ``4``, for each ``N_s`` a scan of β
   (at ``N_t = 4`` denser near the published ``β_c``): one lattice per β, all β of a scan
   drawn together (``jax.vmap`` of the heat bath's kernel, ``liesample.wilson_heat_bath.
   build_kernel(system, 1, overrelaxation)``, β an argument: one compiled program per volume;
   one over-relaxation sweep per step, as more were seen to compile slowly over many batched
   lattices), independent chains from hot starts, a thermalisation, then the volume-averaged
   Polyakov loop ``P`` and the plaquette at every step. Per β:
   ``⟨|P|⟩`` with its blocking error (``tau_int`` shown), ``χ_P = N_s³(⟨|P|²⟩ − ⟨|P|⟩²)`` and
   the Binder cumulant ``U = 1 − ⟨|P|⁴⟩/(3⟨|P|²⟩²)`` with jackknife errors over blocks longer
   than the autocorrelation time (``liesample.analysis.polyakov.polyakov_summary``).
2. The transition: per volume, the peak of ``χ_P`` (the vertex of the parabola through the
   largest value and its two neighbours on the β grid), and between the two volumes the
   crossing of the Binder cumulants (linear interpolation of ``U_large − U_small`` in the
   bracket where it changes sign). The error of each is the jackknife of that location: the runs
   at different β are independent, so its variance is the sum over the runs it uses of the
   jackknife variance with that run's blocks left out one at a time (``jackknife`` of
   ``liesample.analysis.correlated_errors``, its default block length: the blocking level's).
   Compared with the published critical couplings (:data:`PUBLISHED`).
3. The anisotropic action: SU(2) on ``4³ × 2`` at β = 2, ``ξ = 1.5`` (``β_s = β/ξ``,
   ``β_t = βξ``): the spatial and temporal plaquettes from the heat bath and from HMC
   (``liesample.samplers.gauge.hmc.gauge_hmc``, step a third of its stability limit), each with
   its blocking error (``tau_int`` included), and their difference in combined standard errors.

Every error bar printed or plotted includes the autocorrelation (blocking or jackknife over
blocks). Times are wall-clock on the machine recorded, compilation excluded (counted apart).
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common, suites
from liesample.analysis.correlated_errors import blocking_error, jackknife
from liesample.analysis.polyakov import polyakov_summary
from liesample.samplers.gauge.heat_bath import GaugeState
from liesample.samplers.gauge.hmc import gauge_hmc, stability_limit
from liesample.systems import wilson_gauge

SUITE = {
    "order": 36,
    "title": "SU(2) deconfinement: the Polyakov loop across the N_t = 2 and 4 transitions; "
    "anisotropy",
}

PUBLISHED = {
    "beta_c": {2: 1.8735, 4: 2.2986},
    "source": (
        "the SU(2) critical couplings commonly quoted for N_t = 2 and 4, given here without "
        "errors: their digits are not checked against a paper's table (the papers below are "
        "checked against their abstracts only). They are often "
        "attributed to J. Fingberg, U. Heller and F. Karsch, Nucl. Phys. B 392 (1993) 493, "
        "whose own determinations are at N_t = 8 and 16 (its abstract). Determinations at "
        "N_t = 2 and 4: A. Velytsky, Int. J. Mod. Phys. C 19 (2008) 1079 (arXiv:0711.0748; "
        "N_t = 1, 2, 4, 8, from the Binder cumulant), and at N_t = 4 J. Engels, "
        "S. Mashkevich, T. Scheideler and G. Zinovjev, Phys. Lett. B (1996), "
        "doi:10.1016/0370-2693(95)01280-X (hep-lat/9509091; a χ² fit of the Polyakov loop)"
    ),
}
CHUNK = 20  # steps per compiled call
PARTS = ("nt2", "nt4", "anisotropic")  # what ``run`` measures; ``--part`` runs one and merges
CONFIG = {
    "full": {
        "nt2": {"nt": 2, "sizes": (4, 6), "seed": 0,
                "betas": (1.65, 1.7, 1.75, 1.8, 1.85, 1.9, 1.95, 2.0, 2.05),
                "chains": 2, "thermalisation": 100, "draws": {4: 1000, 6: 500},
                "overrelaxation": 1},
        "nt4": {"nt": 4, "sizes": (6, 8), "seed": 400,
                "betas": (2.2, 2.25, 2.28, 2.3, 2.32, 2.35, 2.4),
                "chains": 2, "thermalisation": 100, "draws": {6: 640, 8: 640},
                "overrelaxation": 1},
        "anisotropic": {"shape": (4, 4, 4, 2), "beta": 2.0, "xi": 1.5, "chains": 2,
                        "warmup": 100, "draws": 400, "hmc_steps": 10},
    },
    "quick": {
        "nt2": {"nt": 2, "sizes": (4, 6), "seed": 0, "betas": (1.7, 1.8, 1.9, 2.0),
                "chains": 2, "thermalisation": 20, "draws": {4: 100, 6: 60},
                "overrelaxation": 1},
        "nt4": {"nt": 4, "sizes": (4, 6), "seed": 400, "betas": (2.2, 2.3, 2.4),
                "chains": 2, "thermalisation": 20, "draws": {4: 40, 6: 40},
                "overrelaxation": 1},
        "anisotropic": {"shape": (4, 4, 4, 2), "beta": 2.0, "xi": 1.5, "chains": 2,
                        "warmup": 20, "draws": 60, "hmc_steps": 10},
    },
}  # fmt: skip


# --------------------------------------------------------------------------- the β scan


def scan_runner(system, overrelaxation: int, num_lattices: int):
    """A compiled call of ``CHUNK`` steps on ``num_lattices`` lattices, one β each (traced),
    returning the links and, per step, ``(Re P, plaquette)`` of every lattice."""
    kernel = liesample.wilson_heat_bath.build_kernel(system, 1, overrelaxation)

    def observe(links):
        return jnp.real(system.polyakov_loop(links)), system.mean_plaquette(links)

    @liesample.jit
    def run(links, key, betas):
        def body(u, k):
            keys = jax.random.split(k, num_lattices)
            state, _ = jax.vmap(kernel)(keys, GaugeState(u), betas)
            return state.position, jax.vmap(observe)(state.position)

        return jax.lax.scan(body, links, jax.random.split(key, CHUNK))

    return run


def scan_volume(ns: int, nt: int, betas, chains: int, thermalisation: int, draws: int,
                overrelaxation: int, seed: int, log) -> dict:  # fmt: skip
    """The series ``P`` and plaquette of every β (``(chains, draws)`` each) on ``N_s³ × N_t``."""
    system = wilson_gauge("SU2", (ns, ns, ns, nt))
    betas_array = jnp.asarray(betas, jnp.float64)
    run = scan_runner(system, overrelaxation, len(betas))
    loops = np.zeros((len(betas), chains, draws))
    plaquettes = np.zeros_like(loops)
    keys = jax.random.split(jax.random.key(seed), chains)
    start = time.perf_counter()
    starts = jax.vmap(system.hot_start)(jax.random.split(keys[0], len(betas)))
    jax.block_until_ready(run(starts, keys[0], betas_array))
    compile_seconds = time.perf_counter() - start
    seconds = 0.0
    for c in range(chains):
        start = time.perf_counter()
        links = jax.vmap(system.hot_start)(jax.random.split(keys[c], len(betas)))
        chunk_keys = jax.random.split(
            jax.random.fold_in(keys[c], 1), 1 + -(-thermalisation // CHUNK) + -(-draws // CHUNK)
        )
        n_therm = -(-thermalisation // CHUNK)
        for k in chunk_keys[:n_therm]:
            links, _ = run(links, k, betas_array)
        recorded = []
        for k in chunk_keys[n_therm : n_therm + -(-draws // CHUNK)]:
            links, values = run(links, k, betas_array)
            recorded.append(jax.device_get(values))
        jax.block_until_ready(links)
        seconds += time.perf_counter() - start
        p = np.concatenate([r[0] for r in recorded])[:draws]  # (draws, β)
        q = np.concatenate([r[1] for r in recorded])[:draws]
        loops[:, c], plaquettes[:, c] = p.T, q.T
    steps = chains * len(betas) * (n_therm + -(-draws // CHUNK)) * CHUNK
    log(f"  N_s = {ns}: {steps} lattice steps in {seconds:.0f} s (+ {compile_seconds:.0f} s "
        "compile)")  # fmt: skip
    return {
        "system": system,
        "loops": loops,
        "plaquettes": plaquettes,
        "seconds": seconds,
        "compile_seconds": compile_seconds,
        "lattice_steps": steps,
        "steps_per_lattice": (n_therm + -(-draws // CHUNK)) * CHUNK,
    }


def beta_rows(betas, loops, plaquettes, volume) -> list[dict]:
    """Per β: ``⟨|P|⟩``, ``χ_P``, ``U`` and the plaquette, each with its error (τ included)."""
    rows = []
    for beta, p, q in zip(betas, loops, plaquettes, strict=True):
        summary = polyakov_summary(p, volume)
        plaquette = blocking_error(q, warn=False)
        rows.append({
            "beta": float(beta),
            "abs_p": summary.modulus.mean, "abs_p_error": summary.modulus.error,
            "tau_int_abs_p": summary.modulus.tau_int,
            "chi": summary.susceptibility.estimate, "chi_error": summary.susceptibility.error,
            "binder": summary.binder.estimate, "binder_error": summary.binder.error,
            "block_size": summary.binder.block_size,
            "plaquette": plaquette.mean, "plaquette_error": plaquette.error,
            "tau_int_plaquette": plaquette.tau_int,
        })  # fmt: skip
    return rows


# --------------------------------------------------------------------------- the transition


def _chi(volume):
    return lambda a, a2: volume * (a2 - a**2)


def _binder(a2, a4):
    return 1.0 - a4 / (3.0 * a2**2)


def _vertex(x, y) -> float:
    """The maximum of the parabola through three points."""
    c2, c1, _ = np.polyfit(x, y, 2)
    return float(-c1 / (2.0 * c2)) if c2 < 0 else math.nan


def _located(location, datasets, moments, fixed):
    """``location(values)`` and its jackknife error: the runs are independent, so the variance
    is the sum over the runs in ``datasets`` of the jackknife variance from that run alone.

    ``moments(i)`` gives the per-draw series whose means fix run ``i``'s value, ``fixed`` the
    values of every run from all draws, ``value(i, *means)`` (the last of ``datasets[i]``)
    one run's value from its means."""
    estimate = location(dict(fixed))
    variance = 0.0
    for key, value in datasets:

        def perturbed(*means, key=key, value=value):
            values = dict(fixed)
            values[key] = value(*means)
            return location(values)

        variance += jackknife(perturbed, *moments(key)).error ** 2
    return estimate, math.sqrt(variance)


def chi_peak(betas, loops, volume):
    """The vertex of ``χ_P`` through its largest grid value and neighbours, with its error
    (``nan`` when the largest value is at an end of the grid)."""
    m = [np.abs(p) for p in loops]
    chi = [_chi(volume)(x.mean(), (x**2).mean()) for x in m]
    k = int(np.argmax(chi))
    if k in (0, len(betas) - 1):
        return math.nan, math.nan
    idx = (k - 1, k, k + 1)
    x = np.asarray([betas[i] for i in idx])
    fixed = {i: chi[i] for i in idx}
    datasets = [(i, _chi(volume)) for i in idx]
    return _located(
        lambda v: _vertex(x, [v[i] for i in idx]), datasets, lambda i: (m[i], m[i] ** 2), fixed
    )


def binder_crossing(betas, small_loops, large_loops):
    """Where ``U_large − U_small`` changes sign from below to above (the bracket nearest the
    middle of the grid when there are several), by linear interpolation, with its error."""
    m2 = {("s", i): np.abs(p) ** 2 for i, p in enumerate(small_loops)}
    m2 |= {("l", i): np.abs(p) ** 2 for i, p in enumerate(large_loops)}
    u = {key: _binder(x.mean(), (x**2).mean()) for key, x in m2.items()}
    d = [u["l", i] - u["s", i] for i in range(len(betas))]
    brackets = [j for j in range(len(betas) - 1) if d[j] < 0 <= d[j + 1]]
    if not brackets:
        return math.nan, math.nan
    j = min(brackets, key=lambda j: abs(j + 0.5 - (len(betas) - 1) / 2))
    keys = [("s", j), ("l", j), ("s", j + 1), ("l", j + 1)]

    def crossing(v):
        lo, hi = v["l", j] - v["s", j], v["l", j + 1] - v["s", j + 1]
        return betas[j] + (betas[j + 1] - betas[j]) * (-lo) / (hi - lo)

    fixed = {key: u[key] for key in keys}
    return _located(
        crossing, [(key, _binder) for key in keys], lambda k: (m2[k], m2[k] ** 2), fixed
    )


# --------------------------------------------------------------------------- anisotropy


def anisotropic_rows(settings, seed, log) -> dict:
    """Spatial and temporal plaquettes at ``ξ ≠ 1`` from the heat bath and HMC."""
    system = wilson_gauge("SU2", tuple(settings["shape"]), anisotropy=settings["xi"])
    beta = settings["beta"]
    step = stability_limit(system, beta) / 3.0
    samplers = {
        "heat bath + OR": liesample.wilson_heat_bath(system, beta=beta),
        "HMC": gauge_hmc(system, beta=beta, step_size=step,
                         num_integration_steps=settings["hmc_steps"]),
    }  # fmt: skip
    rows = []
    for name, sampler in samplers.items():
        starts = jax.vmap(system.hot_start)(
            jax.random.split(jax.random.key(seed), settings["chains"])
        )
        observables = {"spatial": system.spatial_plaquette, "temporal": system.temporal_plaquette}
        start = time.perf_counter()
        tree = liesample.sample(
            sampler, jax.random.key(seed + 1), starts, settings["draws"],
            num_warmup=settings["warmup"], observables=observables, keep_positions=False,
            progress_bar=False,
        )  # fmt: skip
        seconds = time.perf_counter() - start
        row = {"sampler": name, "seconds_with_compile": seconds}
        for part in observables:
            result = blocking_error(np.asarray(tree.posterior[part].values), warn=False)
            row |= {part: result.mean, f"{part}_error": result.error,
                    f"{part}_tau_int": result.tau_int}  # fmt: skip
        if name == "HMC":
            row["acceptance"] = float(np.mean(tree.sample_stats["acceptance_rate"].values))
        rows.append(row)
        log(f"  ξ = {settings['xi']}: {name} spatial {row['spatial']:.4f} ± "
            f"{row['spatial_error']:.4f}, temporal {row['temporal']:.4f} ± "
            f"{row['temporal_error']:.4f}")  # fmt: skip
    heat, hmc = rows
    for part in ("spatial", "temporal"):
        sigma = math.hypot(heat[f"{part}_error"], hmc[f"{part}_error"])
        hmc[f"{part}_z"] = (hmc[part] - heat[part]) / sigma
    return {"settings": settings, "step_size": step, "rows": rows}


# --------------------------------------------------------------------------- run, plot, report


def scan_part(cfg: dict, log) -> dict:
    """One ``N_t``: the β scan of every volume, the χ_P peaks and the Binder crossing."""
    start = time.perf_counter()
    machine = common.machine_info()
    nt, betas = cfg["nt"], list(cfg["betas"])
    volumes, raw = [], {}
    for ns in cfg["sizes"]:
        log(f"N_s = {ns}, N_t = {nt}: β = {betas[0]} … {betas[-1]}")
        scan = scan_volume(ns, nt, betas, cfg["chains"], cfg["thermalisation"], cfg["draws"][ns],
                           cfg["overrelaxation"], seed=cfg["seed"] + 10 * ns, log=log)  # fmt: skip
        raw[ns] = scan["loops"]
        peak, peak_error = chi_peak(betas, scan["loops"], ns**3)
        volumes.append({
            "ns": ns, "nt": nt, "rows": beta_rows(betas, scan["loops"], scan["plaquettes"], ns**3),
            "chi_peak": peak, "chi_peak_error": peak_error,
            "seconds": scan["seconds"], "compile_seconds": scan["compile_seconds"],
            "lattice_steps": scan["lattice_steps"], "steps_per_lattice": scan["steps_per_lattice"],
            "draws": cfg["draws"][ns], "chains": cfg["chains"],
        })  # fmt: skip
        log(f"  χ_P peak at β = {peak:.4f} ± {peak_error:.4f}")
    small, large = cfg["sizes"][0], cfg["sizes"][-1]
    crossing, crossing_error = binder_crossing(betas, raw[small], raw[large])
    log(f"  Binder crossing N_s = {small}, {large}: β = {crossing:.4f} ± {crossing_error:.4f}")
    return {
        "machine": machine,
        "config": {k: v for k, v in cfg.items() if k != "draws"}
        | {"draws": {str(k): v for k, v in cfg["draws"].items()}},
        "volumes": volumes,
        "crossing": {"sizes": [small, large], "beta": crossing, "error": crossing_error},
        "seconds": time.perf_counter() - start,
    }  # fmt: skip


def _legacy_parts(data: dict) -> dict:
    """The parts of a result written before the suite had parts (``N_t = 2`` and anisotropy)."""
    if "parts" in data:
        return data["parts"]
    volumes = data["volumes"]
    nt2 = {
        "machine": data["machine"],
        "config": {k: v for k, v in data["config"].items() if k != "anisotropic"} | {"seed": 0},
        "volumes": volumes,
        "crossing": data["crossing"],
        "seconds": sum(v["seconds"] + v["compile_seconds"] for v in volumes),
    }
    return {"nt2": nt2, "anisotropic": data["anisotropic"] | {"machine": data["machine"]}}


def run(out_dir: Path, quick: bool, log=print, parts=PARTS) -> None:
    """Measure ``parts`` (of :data:`PARTS`); the others are kept from an existing result."""
    start = time.perf_counter()
    mode = "quick" if quick else "full"
    cfg = CONFIG[mode]
    path = out_dir / "deconfinement.json"
    kept = {}
    if set(parts) != set(PARTS) and path.exists():
        kept = _legacy_parts(common.read_json(path))
    results = {}
    for name in PARTS:
        if name not in parts:
            if name not in kept:
                raise ValueError(f"part {name!r} is neither measured nor in {path}: run it too "
                                 f"(parts={PARTS})")  # fmt: skip
            results[name] = kept[name]
            continue
        log(f"part {name}")
        if name == "anisotropic":
            results[name] = anisotropic_rows(cfg["anisotropic"], seed=7, log=log) | {
                "machine": common.machine_info()
            }
        else:
            results[name] = scan_part(cfg[name], log)
    data = {
        "description": __doc__,
        "mode": mode,
        "published": {"beta_c": {str(k): v for k, v in PUBLISHED["beta_c"].items()},
                      "source": PUBLISHED["source"]},
        "parts": results,
        "measured_now": list(parts),
        "total_seconds": time.perf_counter() - start,
    }  # fmt: skip
    common.write_json(path, data)
    plot(data, out_dir / "deconfinement.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scans = [part for name, part in data["parts"].items() if name != "anisotropic"]
    fig, grid = plt.subplots(len(scans), 3, figsize=(13, 4 * len(scans)), squeeze=False)
    quantities = (("abs_p", "⟨|P|⟩"), ("chi", "χ_P = N_s³(⟨|P|²⟩ − ⟨|P|⟩²)"),
                  ("binder", "U = 1 − ⟨|P|⁴⟩ / 3⟨|P|²⟩²"))  # fmt: skip
    for axes, part in zip(grid, scans, strict=True):
        nt = part["config"]["nt"]
        beta_c = PUBLISHED["beta_c"].get(nt)
        for ax, (key, label) in zip(axes, quantities, strict=True):
            for color, volume in zip(("C0", "C1", "C2"), part["volumes"], strict=False):
                rows = volume["rows"]
                ax.errorbar([r["beta"] for r in rows], [r[key] for r in rows],
                            yerr=[r[f"{key}_error"] for r in rows], fmt="o-", color=color,
                            capsize=2, label=f"{volume['ns']}³ × {volume['nt']}")  # fmt: skip
                if key == "chi" and math.isfinite(volume["chi_peak"]):
                    c, e = volume["chi_peak"], volume["chi_peak_error"]
                    ax.axvspan(c - e, c + e, color=color, alpha=0.2)
            if key == "binder" and math.isfinite(part["crossing"]["beta"]):
                c, e = part["crossing"]["beta"], part["crossing"]["error"]
                ax.axvspan(c - e, c + e, color="grey", alpha=0.3, label="crossing")
            if beta_c is not None:
                ax.axvline(beta_c, color="k", ls=":", label=f"published β_c = {beta_c}")
            ax.set_xlabel("β")
            ax.set_title(f"N_t = {nt}: {label}", fontsize=10)
            ax.grid(True, alpha=0.3)
        axes[0].legend(fontsize=8)
        axes[2].legend(fontsize=8)
    fig.suptitle("4-D SU(2): heat bath + over-relaxation; error bars from blocking / jackknife "
                 "over blocks (τ_int included)", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=common.DPI)
    plt.close(fig)


def _pm(x, e, digits=4) -> str:
    """``x ± e``; ``—`` for no estimate, ``n/a`` for an error a jackknife could not give."""
    if not math.isfinite(x):
        return "—"
    return f"{x:.{digits}f} ± " + (f"{e:.{digits}f}" if math.isfinite(e) else "n/a")


def _scan_table(part) -> list[str]:
    lines = [
        "| lattice | β | ⟨\\|P\\|⟩ | τ_int(\\|P\\|) | χ_P | U | plaquette | block | blocks |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for volume in part["volumes"]:
        for r in volume["rows"]:
            blocks = volume["chains"] * (volume["draws"] // r["block_size"])
            lines.append(
                f"| {volume['ns']}³×{volume['nt']} | {r['beta']:.3f} | "
                f"{_pm(r['abs_p'], r['abs_p_error'])} | {r['tau_int_abs_p']:.1f} | "
                f"{_pm(r['chi'], r['chi_error'], 3)} | {_pm(r['binder'], r['binder_error'], 3)} | "
                f"{_pm(r['plaquette'], r['plaquette_error'])} | {r['block_size']} | {blocks} |"
            )
    return lines


def _difference(x, e, beta_c) -> tuple[str, str]:
    """``x − β_c`` and that in standard errors of ``x`` (the published value's own error is
    not used: :data:`PUBLISHED` gives none)."""
    if not math.isfinite(x):
        return "—", "—"
    z = f"{(x - beta_c) / e:+.1f}".replace("-", "−") if math.isfinite(e) else "n/a"
    return f"{x - beta_c:+.4f}".replace("-", "−"), z


def _transition_lines(part) -> list[str]:
    beta_c = PUBLISHED["beta_c"][part["config"]["nt"]]
    lines = ["| estimate | β | − published β_c | in standard errors | sweeps per β | seconds "
             "(compile) |", "|---|---|---|---|---|---|"]  # fmt: skip
    for v in part["volumes"]:
        diff, z = _difference(v["chi_peak"], v["chi_peak_error"], beta_c)
        lines.append(
            f"| χ_P peak, {v['ns']}³×{v['nt']} | {_pm(v['chi_peak'], v['chi_peak_error'])} | "
            f"{diff} | {z} | {v['chains']} × {v['steps_per_lattice']} | "
            f"{v['seconds']:.0f} ({v['compile_seconds']:.0f}) |"
        )
    c = part["crossing"]
    diff, z = _difference(c["beta"], c["error"], beta_c)
    lines.append(
        f"| Binder crossing, N_s = {c['sizes'][0]}, {c['sizes'][1]} | {_pm(c['beta'], c['error'])}"
        f" | {diff} | {z} | both scans | — |"
    )
    return lines


def _machine(part) -> str:
    m = part["machine"]
    return (f"{m['date_utc']}, backend `{m['backend']}`, {m['usable_cpus']} usable CPU cores, "
            f"{m['cpu_model']}, load average {m['load_average_1min']}")  # fmt: skip


def _part_lines(part) -> list[str]:
    cfg = part["config"]
    nt = cfg["nt"]
    return [
        f"### N_t = {nt}",
        "",
        (
            f"Measured {_machine(part)}; {part['seconds']:.0f} s. N_s = "
            f"{', '.join(str(v['ns']) for v in part['volumes'])}, β = "
            f"{', '.join(f'{b:g}' for b in cfg['betas'])}; heat bath with "
            f"{cfg['overrelaxation']} over-relaxation sweep(s) per step, {cfg['chains']} chains "
            f"from hot starts, {cfg['thermalisation']} thermalisation steps."
        ),
        "",
        *_scan_table(part),
        "",
        *_few_blocks(part),
        *_transition_lines(part),
        "",
    ]


def _few_blocks(part, minimum: int = 10) -> list[str]:
    """A line naming the rows whose jackknife has fewer than ``minimum`` blocks, if any."""
    few = [
        f"{v['ns']}³×{v['nt']} at β = {r['beta']:g} ({n})"
        for v in part["volumes"]
        for r in v["rows"]
        if (n := v["chains"] * (v["draws"] // r["block_size"])) < minimum
    ]
    if not few:
        return []
    return [
        f"Fewer than {minimum} blocks (τ_int long against the run): {', '.join(few)}; the "
        "errors of those rows, and of a location that uses them, are themselves uncertain by "
        "about 1/√(2 · blocks) relative.",
        "",
    ]


def _anisotropic_lines(data) -> list[str]:
    a = data["parts"]["anisotropic"]
    s = a["settings"]
    lines = [
        f"Measured {_machine(a)}.",
        "",
        f"SU(2) on {'×'.join(map(str, s['shape']))} at β = {s['beta']}, ξ = {s['xi']} "
        f"(β_s = {s['beta'] / s['xi']:.4g}, β_t = {s['beta'] * s['xi']:.4g}), {s['chains']} chains "
        f"× {s['draws']} draws after {s['warmup']} warm-up steps each; HMC: "
        f"{s['hmc_steps']} leapfrog steps of {a['step_size']:.4f} (a third of the stability "
        "limit). Errors: blocking over the chains (τ_int shown).",
        "",
        "| sampler | spatial plaquette | τ_int | temporal plaquette | τ_int | seconds (with "
        "compile) |",
        "|---|---|---|---|---|---|",
    ]
    for r in a["rows"]:
        extra = f" (acceptance {r['acceptance']:.2f})" if "acceptance" in r else ""
        lines.append(
            f"| {r['sampler']}{extra} | {_pm(r['spatial'], r['spatial_error'])} | "
            f"{r['spatial_tau_int']:.1f} | {_pm(r['temporal'], r['temporal_error'])} | "
            f"{r['temporal_tau_int']:.1f} | {r['seconds_with_compile']:.0f} |"
        )
    hmc = a["rows"][1]
    difference = (
        f"HMC − heat bath, in combined standard errors: spatial {hmc['spatial_z']:+.1f}, "
        f"temporal {hmc['temporal_z']:+.1f}."
    )
    lines += ["", difference.replace("-", "−")]
    return lines


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``deconfinement.json``, if it exists (one written before the suite had
    parts is read as its ``N_t = 2`` and anisotropy parts)."""
    path = out_dir / "deconfinement.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    data["parts"] = _legacy_parts(data)
    data.setdefault("mode", "full")
    plot_link = os.path.relpath(out_dir / "deconfinement.png", md_dir)
    scans = [part for name, part in data["parts"].items() if name != "anisotropic"]
    published = ", ".join(f"β_c(N_t = {nt}) = {b}" for nt, b in PUBLISHED["beta_c"].items())
    lines = [
        f"## {SUITE['title']}",
        "",
        (
            f"From `benchmarks/deconfinement.py` ({data['mode']} mode). Its parts ran at "
            "different times, each on the machine and at the load its own line records (a "
            "part is rerun alone with `--part` and merged into the JSON). 4-D SU(2) Wilson "
            "action on N_s³ × N_t, heat bath with over-relaxation, one lattice per β, all β "
            "of a volume drawn together (one compiled program), chains from hot starts. "
            "⟨|P|⟩ and the plaquette: blocking errors (τ_int shown); χ_P and the Binder "
            "cumulant U: jackknife over blocks of the blocking level ('block', in steps; "
            "'blocks' over all chains) — every error includes the autocorrelation. Where "
            "τ_int is long against the run (near β_c on the larger volume) the blocks are few "
            "and the errors themselves uncertain, by about 1/√(2 · blocks) relative."
        ),
        "",
        (
            "The transition: the vertex of the parabola through the largest χ_P and its two "
            "grid neighbours, per volume; the crossing of U between the two volumes (linear "
            "interpolation in the bracket where U_large − U_small changes sign). Their errors: "
            "the jackknife of the location over the blocks of each run it uses (the runs are "
            "independent: the variances add); 'n/a' where a leave-one-block-out sample has no "
            "maximum (its parabola opens upwards): that location is not resolved. "
            f"Published: {published}; "
            f"{PUBLISHED['source']}. 'In standard errors': (β − β_c) over the error of β. "
            "On these small volumes the χ_P peak is a pseudo-critical coupling, shifted from "
            "β_c by finite-size corrections of order N_s^(−1/ν), ν ≈ 0.63 (3-D Ising "
            "universality), and the crossing of two small volumes by corrections to scaling: "
            "a difference of several standard errors is that shift, not a sampler error; it "
            "shrinks only with larger N_s (and, at N_t = 4, larger N_s/N_t)."
        ),
        "",
        *[line for part in scans for line in _part_lines(part)],
        (
            "What accuracy costs: the statistical error of a location falls as "
            "1/√(sweeps); at the rates above, halving it costs four times the seconds of its "
            "row; the finite-size shift falls only with a larger N_s, each doubling of N_s "
            "costing eight times the seconds per sweep (and longer autocorrelations near β_c)."
        ),
        "",
        f"![SU(2) deconfinement]({plot_link})",
        "",
        "### The anisotropic Wilson action, heat bath against HMC",
        "",
        *_anisotropic_lines(data),
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python benchmarks/deconfinement.py [--quick] [--part NAME ...]``; without ``--part``
    the whole suite (``benchmarks/suites.py``'s ``standalone``), with it only those parts,
    merged into the existing ``deconfinement.json``."""
    import argparse

    parser = argparse.ArgumentParser(description="benchmark suite deconfinement")
    parser.add_argument("--quick", action="store_true", help="short smoke run")
    parser.add_argument(
        "--part",
        action="append",
        choices=PARTS,
        help="measure only this part (repeatable); the others are kept",
    )
    args = parser.parse_args(argv)
    if not args.part:
        return suites.standalone(__file__, ["--quick"] if args.quick else [])
    out_dir = common.BENCH_DIR / "results" / ("quick" if args.quick else "")
    out_dir.mkdir(parents=True, exist_ok=True)
    run(out_dir, args.quick, lambda message: print(message, flush=True), parts=args.part)
    print(report(out_dir, out_dir))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
