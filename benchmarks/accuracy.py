"""2. Accuracy against cost: bias of E[μ_i²] per integrator and step size, and wall time per
effective sample.

For each integrator one executable is compiled with the step size and the step counts traced
(the sampler's ``build_kernel`` takes a traced ``step_size``; the scene and integrator are
structural), so every step size reuses it. ``chains`` independent chains start from exact
Gibbs draws and run for a physical time ``T`` (``round(T/h)`` steps); the first ``burn_in``
time units are discarded. Nothing is stored: the scan carry accumulates per chain the sums of
``μ_i²`` and ``μ_i⁴`` over the kept steps, the number of non-finite (rejected) steps, the
largest Casimir drift and the first step at which the drift exceeded the tolerance.

Statistics, per component ``f = μ_i²``:

* ``estimate`` = mean over chains of the per-chain time averages ``m_c``;
  ``bias = estimate − exact``; ``se = std_c(m_c)/√chains`` (the chains are independent, so
  this is an honest standard error, autocorrelation included). ``resolved`` iff
  ``|bias| ≥ 2 se``.
* ``variance`` = pooled ``mean(f²) − estimate²`` (the stationary variance of ``f``);
  ``ess = variance / se²`` (effective samples of the whole run: batch means with one batch
  per chain); ``tau_int = chains · T_kept / ess`` (integrated autocorrelation time, in time
  units).
* ``seconds_per_ess = wall / ess`` with ``wall`` the wall time of the whole run (burn-in
  included, compilation excluded).

Cross-check: a stored run of ``ess_check_chains`` chains per setting (every step kept) gives
ArviZ's rank-normalised ``ess_bulk`` of ``μ₃²`` via ``liesample.analysis.diagnostics.expectation_table``,
converted to ``tau_int`` for comparison.
"""

from __future__ import annotations

import itertools
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

import liesample
from benchmarks import common
from benchmarks.throughput import RNG_ONLY
from liesample.analysis.diagnostics import expectation_table
from liesample.integrators import DEFAULT_INTEGRATOR, get_integrator
from liesample.samplers.orbit.lie_poisson_langevin import build_kernel, init

SCENE = "all effects"


def _kernel(integrator):
    sigma, theta, scene = common.dynamics_parameters(SCENE)
    kernel = build_kernel(common.system(), integrator, scene)
    return lambda key, state, h: kernel(key, state, h, sigma, theta)


def _accumulating_run(integrator, tolerance):
    step = _kernel(integrator)

    def run(states, keys, h, n_burn, n_total):
        def chain(state, key):
            def body(i, carry):
                state, s2, s4, nonfinite, drift_max, first_off = carry
                state, info = step(jax.random.fold_in(key, i), state, h)
                m2 = state.position**2
                kept = i >= n_burn
                s2 = jnp.where(kept, s2 + m2, s2)
                s4 = jnp.where(kept, s4 + m2 * m2, s4)
                off = (info.casimir_error > tolerance) | info.is_divergent
                first_off = jnp.where((first_off < 0) & off, i, first_off)
                return (
                    state,
                    s2,
                    s4,
                    nonfinite + info.is_divergent.astype(jnp.int64),
                    jnp.maximum(drift_max, info.casimir_error),
                    first_off,
                )

            zeros = jnp.zeros(3, state.position.dtype)
            carry = (state, zeros, zeros, jnp.int64(0), jnp.zeros((), zeros.dtype), jnp.int64(-1))
            state, s2, s4, nonfinite, drift_max, first_off = jax.lax.fori_loop(
                0, n_total, body, carry
            )
            c = jnp.sum(state.position**2)
            final_drift = jnp.abs(c - state.reference_casimirs) / state.reference_casimirs
            return s2, s4, nonfinite, drift_max, first_off, final_drift

        return jax.vmap(chain)(states, keys)

    return liesample.jit(run)


def _stored_run(integrator, n_keep_max):
    """Positions at every kept step, in a buffer of static length ``n_keep_max``."""
    step = _kernel(integrator)

    def run(states, keys, h, n_burn, n_keep):
        def chain(state, key):
            state = jax.lax.fori_loop(
                0, n_burn, lambda i, s: step(jax.random.fold_in(key, i), s, h)[0], state
            )
            buffer = jnp.full((n_keep_max, 3), jnp.nan, state.position.dtype)

            def body(j, carry):
                state, buffer, nonfinite = carry
                state, info = step(jax.random.fold_in(key, n_burn + j), state, h)
                return state, buffer.at[j].set(state.position), nonfinite | info.is_divergent

            _, buffer, nonfinite = jax.lax.fori_loop(
                0, n_keep, body, (state, buffer, jnp.zeros((), bool))
            )
            return buffer, nonfinite

        return jax.vmap(chain)(states, keys)

    return liesample.jit(run)


def _steps(cfg, h):
    n_total = round(cfg.accuracy_time / h)
    n_burn = round(cfg.accuracy_burn_in / h)
    return n_burn, n_total


def _statistics(exact, s2, s4, n_keep, kept_time, wall):
    chains = s2.shape[0]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        m = s2 / n_keep
        estimate = m.mean(0)
        se = m.std(0, ddof=1) / math.sqrt(chains)
        variance = (s4 / n_keep).mean(0) - estimate**2
        ess = variance / se**2
        tau = chains * kept_time / ess
        bias = estimate - exact
        resolved = np.abs(bias) >= 2 * se
        seconds_per_ess = wall / ess
    finite = bool(np.all(np.isfinite(bias)) and np.all(np.isfinite(se)))
    return {
        "estimate": estimate,
        "exact": exact,
        "bias": bias,
        "se": se,
        "resolved": resolved,
        "max_abs_bias": float(np.max(np.abs(bias))) if finite else math.nan,
        "max_abs_bias_component": int(np.argmax(np.abs(bias))) + 1 if finite else None,
        "max_abs_bias_resolved": bool(resolved[np.argmax(np.abs(bias))]) if finite else False,
        "variance": variance,
        "ess": ess,
        "tau_int": tau,
        "seconds_per_ess": seconds_per_ess,
        "finite": finite,
    }


def _arviz_check(stored, nonfinite, n_keep, kept_time, exact3):
    """ArviZ ess_bulk of μ₃² from the stored run, as tau_int in time units."""
    positions = np.asarray(stored)[:, :n_keep]
    if np.any(np.asarray(nonfinite)) or not np.all(np.isfinite(positions)):
        return {"ess_bulk": math.nan, "tau_int": math.nan, "skipped": "non-finite states"}
    drift = np.abs(np.sum(positions**2, -1) - common.RADIUS**2) / common.RADIUS**2
    if np.max(drift) > 0.1:
        return {"ess_bulk": math.nan, "tau_int": math.nan, "skipped": "left the orbit"}
    f = positions[..., 2] ** 2
    table = expectation_table({"mu3_sq": f}, exact={"mu3_sq": exact3})
    ess = float(table.loc["mu3_sq", "ess_bulk"])
    return {
        "ess_bulk": ess,
        "tau_int": positions.shape[0] * kept_time / ess,
        "r_hat": float(table.loc["mu3_sq", "r_hat"]),
        "z": float(table.loc["mu3_sq", "z"]),
        "skipped": None,
    }


def run_accuracy(cfg: common.Config, log=print) -> list[dict]:
    exact = common.exact_second_moments()
    target = common.target()
    system = common.system()
    key = jax.random.key(cfg.seed + 2)
    k_pos, k_chain, k_check = jax.random.split(key, 3)
    positions = target.sample(k_pos, cfg.accuracy_chains)
    states = jax.vmap(lambda p: init(p, system))(positions)
    chain_keys = jax.random.split(k_chain, cfg.accuracy_chains)
    check_states = jax.tree.map(lambda x: x[: cfg.ess_check_chains], states)
    check_keys = jax.random.split(k_check, cfg.ess_check_chains)
    n_keep_max = max(_steps(cfg, h)[1] - _steps(cfg, h)[0] for h in cfg.accuracy_step_sizes)

    rows = []
    for integrator in cfg.accuracy_integrators:
        info = get_integrator(integrator)
        n_burn0, n_total0 = _steps(cfg, cfg.accuracy_step_sizes[0])
        start = time.perf_counter()
        run = _accumulating_run(integrator, cfg.casimir_tolerance)
        run = run.lower(states, chain_keys, 0.1, n_burn0, n_total0).compile()
        compile_seconds = time.perf_counter() - start
        start = time.perf_counter()
        stored_run = _stored_run(integrator, n_keep_max)
        stored_run = stored_run.lower(check_states, check_keys, 0.1, n_burn0, 1).compile()
        compile_seconds_check = time.perf_counter() - start

        for h in cfg.accuracy_step_sizes:
            n_burn, n_total = _steps(cfg, h)
            n_keep = n_total - n_burn
            kept_time = n_keep * h
            out, wall = common.timed(run, states, chain_keys, h, n_burn, n_total)
            s2, s4, nonfinite, drift_max, first_off, final_drift = (np.asarray(x) for x in out)
            stats = _statistics(exact, s2, s4, n_keep, kept_time, wall)
            left = first_off >= 0
            off_times = np.where(left, first_off + 1, np.nan) * h
            stored, check_nonfinite = stored_run(check_states, check_keys, h, n_burn, n_keep)
            check = _arviz_check(stored, check_nonfinite, n_keep, kept_time, exact[2])
            row = {
                "integrator": integrator,
                "declared_weak_order": info.weak_order,
                "preserves_orbit": info.preserves_orbit,
                "step_size": h,
                "chains": cfg.accuracy_chains,
                "steps_total": n_total,
                "steps_burn_in": n_burn,
                "time_total": n_total * h,
                "time_kept": kept_time,
                "wall_seconds": wall,
                "chain_steps_per_second": cfg.accuracy_chains * n_total / wall,
                "compile_seconds": compile_seconds,
                "compile_seconds_check": compile_seconds_check,
                **stats,
                "nonfinite_steps": int(nonfinite.sum()),
                "chains_with_nonfinite": int(np.count_nonzero(nonfinite)),
                "casimir_drift_max": float(np.max(drift_max)),
                "casimir_drift_final_median": float(np.median(final_drift)),
                "chains_off_orbit": int(np.count_nonzero(left)),
                "time_off_orbit_median": float(np.nanmedian(off_times)) if left.any() else None,
                "time_off_orbit_min": float(np.nanmin(off_times)) if left.any() else None,
                "arviz_check": check,
            }
            rows.append(row)
            if stats["finite"]:
                b = ", ".join(
                    f"{bi:+.4f}±{si:.4f}" for bi, si in zip(stats["bias"], stats["se"], strict=True)
                )
                log(
                    f"  {integrator:>10} h={h:<5} bias {b} | ESS(μ₃²)={stats['ess'][2]:.3g} "
                    f"τ={stats['tau_int'][2]:.2f} (ArviZ {check['tau_int']:.2f}) | "
                    f"{wall:.2f} s, {stats['seconds_per_ess'][2]:.3g} s/ESS"
                )
            else:
                log(
                    f"  {integrator:>10} h={h:<5} non-finite estimate: "
                    f"{row['chains_with_nonfinite']}/{cfg.accuracy_chains} chains hit non-finite "
                    f"states, {row['chains_off_orbit']} left the orbit (median time "
                    f"{row['time_off_orbit_median']:.3g}), {wall:.2f} s"
                )
    return rows


def run_order_check(cfg: common.Config, log=print) -> list[dict]:
    """The same estimator with many more samples, for the order of the bias at small h."""
    exact = common.exact_second_moments()
    system = common.system()
    chains, total, burn = cfg.order_check_chains, cfg.order_check_time, cfg.accuracy_burn_in
    key = jax.random.key(cfg.seed + 3)
    k_pos, k_chain = jax.random.split(key)
    states = jax.vmap(lambda p: init(p, system))(common.target().sample(k_pos, chains))
    chain_keys = jax.random.split(k_chain, chains)
    rows = []
    for integrator in cfg.order_check_integrators:
        run = _accumulating_run(integrator, cfg.casimir_tolerance)
        run = run.lower(states, chain_keys, 0.1, 1, 2).compile()
        for h in cfg.order_check_step_sizes:
            n_total, n_burn = round(total / h), round(burn / h)
            n_keep = n_total - n_burn
            out, wall = common.timed(run, states, chain_keys, h, n_burn, n_total)
            s2, s4, nonfinite = (np.asarray(x) for x in out[:3])
            stats = _statistics(exact, s2, s4, n_keep, n_keep * h, wall)
            rows.append(
                {
                    "integrator": integrator,
                    "declared_weak_order": get_integrator(integrator).weak_order,
                    "step_size": h,
                    "chains": chains,
                    "time_total": n_total * h,
                    "time_kept": n_keep * h,
                    "wall_seconds": wall,
                    "nonfinite_steps": int(nonfinite.sum()),
                    **stats,
                }
            )
            b = ", ".join(
                f"{bi:+.5f}±{si:.5f}" for bi, si in zip(stats["bias"], stats["se"], strict=True)
            )
            log(f"  {integrator:>10} h={h:<5} bias {b} | {wall:.1f} s")
    return rows


FIT_H_MAX = 0.4  # the order is fitted on resolved points with h ≤ this (asymptotic range)


def fit_slopes(rows, integrator, h_max=FIT_H_MAX) -> dict:
    """Log–log slope of max|bias| against h over the resolved points with ``h ≤ h_max``, and
    the local slopes between neighbouring step sizes."""
    pts = sorted(
        (r["step_size"], r["max_abs_bias"], r["max_abs_bias_resolved"])
        for r in rows
        if r["integrator"] == integrator and r["finite"]
    )
    local = []
    for (h0, b0, ok0), (h1, b1, ok1) in itertools.pairwise(pts):
        local.append(
            {
                "from": h0,
                "to": h1,
                "slope": math.log(b1 / b0) / math.log(h1 / h0),
                "both_resolved": ok0 and ok1,
            }
        )
    resolved = [(h, b) for h, b, ok in pts if ok and h <= h_max * (1 + 1e-9)]
    slope = None
    if len(resolved) >= 2:
        x = np.log([h for h, _ in resolved])
        y = np.log([b for _, b in resolved])
        slope = float(np.polyfit(x, y, 1)[0])
    return {"fit_slope": slope, "fit_points": len(resolved), "local": local}


def time_to_accuracy(rows, integrator, eps) -> dict | None:
    """Least wall time, over the measured step sizes, to reach RMSE ≤ eps on every E[μ_i²].

    For a run at step size h, ``RMSE_i² = b_i² + σ_i²/ESS_i`` with the bias bounded
    conservatively by ``b_i = |bias_i| + 2 se_i``; the needed time is
    ``max_i (wall/ESS_i) · σ_i² / (eps² − b_i²)`` = ``max_i wall · se_i² / (eps² − b_i²)``.
    """
    best = None
    for r in rows:
        if r["integrator"] != integrator or not r["finite"]:
            continue
        bound = np.abs(np.asarray(r["bias"])) + 2 * np.asarray(r["se"])
        if np.any(bound >= eps):
            continue
        seconds = float(np.max(r["wall_seconds"] * np.asarray(r["se"]) ** 2 / (eps**2 - bound**2)))
        if best is None or seconds < best["seconds"]:
            best = {"seconds": seconds, "step_size": r["step_size"]}
    return best


# --------------------------------------------------------------------------- plots and tables


def _finite_rows(rows, name):
    return sorted(
        (r for r in rows if r["integrator"] == name and r["finite"]), key=lambda r: r["step_size"]
    )


def _max_component(r):
    i = r["max_abs_bias_component"] - 1
    return abs(r["bias"][i]), r["se"][i]


def _line_with_2se_bars(ax, x, y, se, color):
    """A line through ``(x, y)`` with ±2 SE bars, kept above zero on log axes."""
    ax.plot(x, y, "-", color=color, lw=1.2)
    ax.errorbar(
        x,
        y,
        yerr=[np.minimum(2 * se, 0.9 * y), 2 * se],
        fmt="none",
        ecolor=color,
        elinewidth=0.8,
        capsize=2,
    )


def plot_accuracy_cost(rows, iid_rows, iid_check, target_errors, path: Path) -> Path:
    fig = Figure(figsize=(13.0, 5.6), layout="constrained")
    ax, ax2 = fig.subplots(1, 2)
    notes, lowest = [], []
    names = [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in rows)]
    for name in names:
        pts = _finite_rows(rows, name)
        if not pts:
            notes.append(f"{name}: not shown, estimates non-finite at every step size")
            continue
        x = np.array([r["seconds_per_ess"][2] for r in pts])
        y = np.array([_max_component(r)[0] for r in pts])
        se = np.array([_max_component(r)[1] for r in pts])
        ok = np.array([r["max_abs_bias_resolved"] for r in pts])
        c, m = common.COLORS[name], common.MARKERS[name]
        _line_with_2se_bars(ax, x, y, se, c)
        ax.plot(x[ok], y[ok], m, color=c, ms=7, label=name)
        lowest.append(y.min())
        ax.plot(x[~ok], y[~ok], m, mfc="white", mec=c, ms=7)
        for xi, yi, r in zip(x, y, pts, strict=True):
            ax.annotate(
                f"h={r['step_size']:g}",
                (xi, yi),
                textcoords="offset points",
                xytext=(5, 4),
                fontsize=7,
                color=c,
            )
        # Right panel: least time to RMSE ≤ ε on every E[μ_i²], as a function of ε.
        eps_grid = np.geomspace(1e-3, 0.3, 120)
        tt = [time_to_accuracy(rows, name, e) for e in eps_grid]
        xe = [t["seconds"] if t else np.nan for t in tt]
        ax2.plot(xe, eps_grid, "-", color=c, lw=1.8, label=name)
    iid_rate = max(r["samples_per_second"] for r in iid_rows) if iid_rows else None
    if iid_rate:
        ax.axvline(
            1 / iid_rate,
            color="0.2",
            ls=":",
            lw=1.5,
            label="exact iid sampler (bias 0): s per sample",
        )
        var = max(iid_check["variance"])
        eps_grid = np.geomspace(1e-3, 0.3, 50)
        ax2.plot(
            var / eps_grid**2 / iid_rate,
            eps_grid,
            ":",
            color="0.2",
            lw=1.8,
            label="exact iid sampler",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    if lowest:
        ax.set_ylim(bottom=0.3 * min(lowest))
    ax.set_xlabel("wall time per effective sample of μ₃² (s)")
    ax.set_ylabel("max_i |bias of E[μ_i²]|   (error bars ±2 SE)")
    ax.set_title("Bias against cost per effective sample\n(hollow: |bias| < 2 SE, not resolved)")
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize="small", loc="lower left")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("wall time to reach it (s), best measured step size")
    ax2.set_ylabel("target RMSE ε on every E[μ_i²]")
    ax2.set_title(
        "Error against seconds (Pareto): least time to RMSE ≤ ε\nbias bounded by |bias| + 2 SE"
    )
    ax2.grid(which="both", alpha=0.3)
    ax2.legend(fontsize="small")
    fig.suptitle(
        f"Rigid body I={common.INERTIA}, β={common.BETA}, σ={common.SIGMA}, r={common.RADIUS}: "
        f"{rows[0]['chains']} chains × T={rows[0]['time_total']:g}"
        + ("\n" + "; ".join(notes) if notes else "")
    )
    return common.save_figure(fig, path)


def plot_bias_vs_step(rows, path: Path, order_rows=()) -> Path:
    fig = Figure(figsize=(7.5, 5.4), layout="constrained")
    ax = fig.subplots()
    names = [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in rows)]
    notes, anchors = [], []
    for name in names:
        pts = _finite_rows(rows, name)
        if not pts:
            notes.append(f"{name}: non-finite at every step size (diverged)")
            continue
        h = np.array([r["step_size"] for r in pts])
        y = np.array([_max_component(r)[0] for r in pts])
        se = np.array([_max_component(r)[1] for r in pts])
        ok = np.array([r["max_abs_bias_resolved"] for r in pts])
        c, m = common.COLORS[name], common.MARKERS[name]
        _line_with_2se_bars(ax, h, y, se, c)
        order = pts[0]["declared_weak_order"]
        ax.plot(h[ok], y[ok], m, color=c, ms=7, label=f"{name} (declared order {order})")
        ax.plot(h[~ok], y[~ok], m, mfc="white", mec=c, ms=7)
        anchors.append((h.max(), y[np.argmax(h)]))
    for name in dict.fromkeys(r["integrator"] for r in order_rows):
        pts = _finite_rows(order_rows, name)
        if not pts:
            continue
        h = np.array([r["step_size"] for r in pts])
        y = np.array([_max_component(r)[0] for r in pts])
        se = np.array([_max_component(r)[1] for r in pts])
        c = common.COLORS[name]
        ax.errorbar(
            h * 1.03,
            y,
            yerr=[np.minimum(2 * se, 0.9 * y), 2 * se],
            fmt="--",
            color=c,
            lw=1.0,
            capsize=2,
            marker="x",
            ms=7,
            label=f"{name}, high precision ({pts[0]['chains']} chains × "
            f"T={pts[0]['time_total']:g})",
        )
    if anchors:
        hs = np.geomspace(min(r["step_size"] for r in rows), max(r["step_size"] for r in rows), 20)
        top = max(a[1] for a in anchors)
        low = min(a[1] for a in anchors)
        h0 = max(a[0] for a in anchors)
        ax.plot(hs, top * (hs / h0), "k--", lw=1, label="slope 1")
        ax.plot(hs, low * (hs / h0) ** 2, "k:", lw=1.3, label="slope 2")
        floor = np.median([2 * r["se"][2] for r in rows if r["finite"]])
        ax.axhspan(1e-9, floor, color="0.85", zorder=0, label=f"≈ 2 SE ({floor:.1e}): unresolved")
        ax.set_ylim(bottom=floor / 4)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("step size h")
    ax.set_ylabel("max_i |bias of E[μ_i²]|   (error bars ±2 SE)")
    ax.set_title(
        "Bias of ergodic averages against step size\n(hollow: not resolved, |bias| < 2 SE)"
    )
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize="small", loc="lower right")
    if notes:
        ax.text(
            0.01,
            0.99,
            "\n".join(notes),
            transform=ax.transAxes,
            ha="left",
            va="top",
            fontsize=8,
            color="C3",
        )
    return common.save_figure(fig, path)


# --------------------------------------------------------------------------- markdown


def _bias_cell(r, i):
    s = common.format_signed(r["bias"][i], r["se"][i])
    return s if r["resolved"][i] else f"{s} (n.r.)"


def _accuracy_table(rows):
    lines = [
        (
            "| integrator | h | max\\|bias\\| | bias E[μ₁²] ± SE | bias E[μ₂²] ± SE | bias E[μ₃²] ± SE "
            "| ESS(μ₃²) | τ_int(μ₃²): chains / ArviZ | wall (s) | s per ESS(μ₃²) | Casimir drift |"
        ),
        "|" + "---|" * 11,
    ]
    for r in rows:
        drift = common.format_g(r["casimir_drift_max"], 2)
        if r["chains_off_orbit"]:
            drift = (
                f"{drift}; {r['chains_off_orbit']}/{r['chains']} chains > 10% "
                f"(median after t={common.format_g(r['time_off_orbit_median'])})"
            )
        if r["finite"]:
            mb = f"{r['max_abs_bias']:.4f}"
            if not r["max_abs_bias_resolved"]:
                mb += " (n.r.)"
            cells = (
                [mb]
                + [_bias_cell(r, i) for i in range(3)]
                + [
                    f"{r['ess'][2]:.3g}",
                    f"{r['tau_int'][2]:.3f} / {common.format_g(r['arviz_check']['tau_int'])}",
                    f"{r['wall_seconds']:.2f}",
                    common.format_seconds(r["seconds_per_ess"][2]),
                    drift,
                ]
            )
        else:
            nf = f"{r['chains_with_nonfinite']}/{r['chains']} chains hit NaN/inf"
            est = ", ".join(common.format_g(e) for e in r["estimate"])
            cells = [
                f"**diverged** ({nf})",
                f"estimate = ({est})",
                "–",
                "–",
                "–",
                "–",
                f"{r['wall_seconds']:.2f}",
                "–",
                drift,
            ]
        lines.append(f"| {r['integrator']} | {r['step_size']:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _slope_table(rows, slopes):
    steps = sorted({r["step_size"] for r in rows}, reverse=True)
    pairs = list(itertools.pairwise(steps))
    lines = [
        f"| integrator | declared weak order | fitted slope (resolved, h ≤ {FIT_H_MAX:g}) | "
        + " | ".join(f"local {a:g}→{b:g}" for a, b in pairs)
        + " |",
        "|" + "---|" * (3 + len(pairs)),
    ]
    for name, s in slopes.items():
        order = next(r["declared_weak_order"] for r in rows if r["integrator"] == name)
        fit = "–" if s["fit_slope"] is None else f"{s['fit_slope']:.2f} ({s['fit_points']} pts)"
        local = {(loc["to"], loc["from"]): loc for loc in s["local"]}
        cells = []
        for a, b in pairs:
            loc = local.get((a, b))
            if loc is None:
                cells.append("–")
            else:
                cells.append(common.format_g(loc["slope"], 2) + ("" if loc["both_resolved"] else " (n.r.)"))
        lines.append(f"| {name} | {order} | {fit} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _tta_table(tta, iid_tta, target_errors):
    lines = [
        "| integrator | " + " | ".join(f"ε = {e:g}" for e in target_errors) + " |",
        "|" + "---|" * (1 + len(target_errors)),
    ]
    for name, per_eps in tta.items():
        cells = []
        for e in target_errors:
            t = per_eps[str(e)]
            cells.append(
                "not certified" if t is None else f"{common.format_seconds(t['seconds'])} (h={t['step_size']:g})"
            )
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if iid_tta:
        lines.append(
            "| *exact iid sampler* | "
            + " | ".join(common.format_seconds(iid_tta[str(e)]) for e in target_errors)
            + " |"
        )
    return "\n".join(lines)


def _order_section(order_rows, order_slopes, sweep_rows):
    if not order_rows:
        return ""
    r0 = order_rows[0]
    lines = [
        (
            "**High-precision check.** With the sweep's SE (≈ "
            f"{np.median([max(r['se']) for r in sweep_rows if r['finite']]):.1e}) a second-order "
            "bias is not resolvable at h ≤ 0.1, so the integrator(s) below are rerun with "
            f"{r0['chains']} chains × "
            f"T = {r0['time_total']:g} (same estimator, burn-in included in T):"
        ),
        "",
        (
            "| integrator | h | max\\|bias\\| | bias E[μ₁²] ± SE | bias E[μ₂²] ± SE "
            "| bias E[μ₃²] ± SE | wall (s) |"
        ),
        "|---|---|---|---|---|---|---|",
    ]
    for r in order_rows:
        mb = f"{r['max_abs_bias']:.5f}" + ("" if r["max_abs_bias_resolved"] else " (n.r.)")
        cells = (
            [mb]
            + [
                f"{r['bias'][i]:+.5f} ± {r['se'][i]:.5f}".replace("-", "−")
                + ("" if r["resolved"][i] else " (n.r.)")
                for i in range(3)
            ]
            + [f"{r['wall_seconds']:.1f}"]
        )
        lines.append(f"| {r['integrator']} | {r['step_size']:g} | " + " | ".join(cells) + " |")
    lines.append("")
    for name, s in order_slopes.items():
        local = ", ".join(
            f"{loc['to']:g}→{loc['from']:g}: {loc['slope']:.2f}"
            + ("" if loc["both_resolved"] else " (n.r.)")
            for loc in sorted(s["local"], key=lambda d: -d["to"])
        )
        fit = "–" if s["fit_slope"] is None else f"{s['fit_slope']:.2f}"
        lines.append(f"{name}: local slopes {local}; fitted slope {fit}.")
    return "\n".join(lines) + "\n"


def _findings(
    tp_rows,
    iid_rows,
    iid_check,
    acc_rows,
    slopes,
    tta,
    iid_tta,
    target_errors,
    order_rows=(),
    order_slopes=None,
):
    order_slopes = order_slopes or {}
    out = []
    lookup = {(r["integrator"], r["scene"], r["chains"]): r for r in tp_rows}
    chains = sorted({r["chains"] for r in tp_rows})
    mid = chains[len(chains) // 2]
    all_rates = {
        name: lookup[(name, "all effects", mid)]["chain_steps_per_second"]
        for name in common.INTEGRATOR_NAMES
        if (name, "all effects", mid) in lookup
    }
    if all_rates:
        spreads = [max(r["seconds_all"]) / min(r["seconds_all"]) - 1 for r in tp_rows]
        out.append(
            f"**Throughput ({common.chains_label(mid)}, all effects):** "
            + ", ".join(
                f"{n} {common.format_rate(v)}" for n, v in sorted(all_rates.items(), key=lambda kv: -kv[1])
            )
            + " chain-steps/s. The four steps cost within a factor "
            + f"{max(all_rates.values()) / min(all_rates.values()):.1f} of each other; the "
            "repeats of one measurement spread by a median "
            + f"{100 * float(np.median(spreads)):.0f}% (max {100 * max(spreads):.0f}%) on this "
            "shared VM, so rankings closer than that are not meaningful."
        )
        per_chain = {
            n: lookup[(n, "all effects", 1)]["chain_steps_per_second"]
            for n in all_rates
            if (n, "all effects", 1) in lookup
        }
        big = {
            n: lookup[(n, "all effects", chains[-1])]["chain_steps_per_second"]
            for n in all_rates
            if (n, "all effects", chains[-1]) in lookup
        }
        if per_chain and big:
            out.append(
                "Vectorising over chains buys little on this 2-core CPU: with all effects, "
                + "; ".join(
                    f"{n} runs {common.format_rate(per_chain[n])} steps/s as a single chain, "
                    f"{common.format_rate(all_rates[n])} at {common.chains_label(mid)} and {common.format_rate(big[n])} at "
                    f"{common.chains_label(chains[-1])}"
                    for n in per_chain
                    if n in big
                )
                + " (chain-steps/s): batched ÷ single-chain throughput ranges from "
                + f"{min(min(all_rates[n], big[n]) / per_chain[n] for n in per_chain if n in big):.2f}"
                + " to "
                + f"{max(max(all_rates[n], big[n]) / per_chain[n] for n in per_chain if n in big):.2f}."
            )
        rng = lookup.get((RNG_ONLY, "-", mid))
        if rng:
            share = {n: v / rng["chain_steps_per_second"] for n, v in all_rates.items()}
            out.append(
                f"Drawing the noise alone (`fold_in` + 3 normals) runs at "
                f"{common.format_rate(rng['chain_steps_per_second'])} draws/s at {common.chains_label(mid)}, so it "
                "would account for roughly "
                + ", ".join(f"{100 * s:.0f}% ({n})" for n, s in share.items())
                + " of an all-effects step if the costs simply add."
            )
    h_only = [
        (
            n,
            lookup[(n, "Hamiltonian only", c)]["chain_steps_per_second"]
            / lookup[(n, "all effects", c)]["chain_steps_per_second"],
            c,
        )
        for n in common.INTEGRATOR_NAMES
        for c in chains
        if (n, "Hamiltonian only", c) in lookup and (n, "all effects", c) in lookup
    ]
    if h_only:
        per = {}
        for n, ratio, c in h_only:
            per.setdefault(n, []).append(ratio)
        out.append(
            "**Hamiltonian only** (σ = 0, θ = 0: no noise or dissipation traced, no random "
            "numbers drawn) is faster than the full step by "
            + ", ".join(f"{min(v):.1f}–{max(v):.1f}× ({n})" for n, v in per.items())
            + " over the chain counts: the deterministic step is a fraction of the cost of "
            "drawing and applying the noise."
        )
    no_h = [
        lookup[(n, "noise+dissipation, no Hamiltonian", c)]["chain_steps_per_second"]
        / lookup[(n, "all effects", c)]["chain_steps_per_second"]
        for n in common.INTEGRATOR_NAMES
        for c in chains
        if (n, "noise+dissipation, no Hamiltonian", c) in lookup and (n, "all effects", c) in lookup
    ]
    if no_h:
        out.append(
            "Dropping only the Hamiltonian drift (`hamiltonian=False`) changes the cost by a "
            f"factor {min(no_h):.2f}–{max(no_h):.2f}"
            + (": noise and dissipation are most of the step's cost." if max(no_h) < 2 else ".")
        )
    if iid_rows:
        best_iid = max(r["samples_per_second"] for r in iid_rows)
        default = [r for r in acc_rows if r["integrator"] == DEFAULT_INTEGRATOR and r["finite"]]
        if default:
            cost = [r["seconds_per_ess"][2] for r in default]
            out.append(
                f"**Physical limit:** the exact iid sampler delivers {common.format_rate(best_iid)} "
                f"independent samples/s ({common.format_seconds(1 / best_iid)} each). An effective sample "
                f"of μ₃² from the default splitting sampler costs {common.format_seconds(min(cost))} – "
                f"{common.format_seconds(max(cost))} for h = {max(r['step_size'] for r in default):g} … "
                f"{min(r['step_size'] for r in default):g}, i.e. "
                f"{min(cost) * best_iid:.1f}–{max(cost) * best_iid:.1f}× the iid cost, and it "
                "carries a bias the iid sampler does not have (τ_int ≈ "
                f"{np.median([r['tau_int'][2] for r in default]):.2f} time units, so the cost "
                "grows like 1/h). "
                f"(iid check: |z| ≤ {max(abs(z) for z in iid_check['z']):.1f} for E[μ_i²] "
                f"from {iid_check['samples']:,} draws.)"
            )
    for name, s in slopes.items():
        order = next(r["declared_weak_order"] for r in acc_rows if r["integrator"] == name)
        if s["fit_slope"] is None:
            continue
        if abs(s["fit_slope"] - order) <= 0.35:
            verdict = "consistent with the"
        elif s["fit_slope"] > order:
            verdict = "steeper (better) than the"
        else:
            verdict = "**below** the"
        local = ", ".join(
            f"{loc['slope']:.2f}" + ("" if loc["both_resolved"] else "*")
            for loc in sorted(s["local"], key=lambda d: -d["to"])
        )
        out.append(
            f"**{name}:** observed bias slope {s['fit_slope']:.2f} over {s['fit_points']} resolved "
            f"step sizes h ≤ {FIT_H_MAX:g} (local slopes from large to small h: {local}"
            + ("; * = a point not resolved" if "*" in local else "")
            + "), "
            f"{verdict} declared weak order {order}."
        )
        if name in order_slopes and order_slopes[name]["fit_slope"] is not None:
            o = order_slopes[name]
            local = ", ".join(
                f"{loc['slope']:.2f}" + ("" if loc["both_resolved"] else "*")
                for loc in sorted(o["local"], key=lambda d: -d["to"])
            )
            out[-1] += (
                f" The high-precision check ({order_rows[0]['chains']} chains × "
                f"T={order_rows[0]['time_total']:g}, SE ≈ "
                f"{np.median([max(r['se']) for r in order_rows]):.1e}) gives local slopes {local} "
                f"(fit {o['fit_slope']:.2f}): the slope steepens as h decreases, i.e. these step "
                "sizes are pre-asymptotic (and the sweep is noise-limited at small h); the "
                f"declared order {order} is approached but not reached on h ≥ "
                f"{min(r['step_size'] for r in order_rows):g}"
                if o["local"] and o["local"][0]["slope"] > o["local"][-1]["slope"] + 0.3
                else f" The high-precision check gives local slopes {local} (fit "
                f"{o['fit_slope']:.2f})"
            ) + "."
    for name in {r["integrator"] for r in acc_rows}:
        rs = [r for r in acc_rows if r["integrator"] == name]
        if any(not r["finite"] for r in rs):
            bad = [r for r in rs if not r["finite"]]
            kind = (
                "orbit-preserving"
                if get_integrator(name).preserves_orbit
                else "ambient baseline, not orbit-preserving"
            )
            out.append(
                f"**{name}** ({kind}) gives no usable estimate: "
                "at h = "
                + ", ".join(f"{r['step_size']:g}" for r in bad)
                + " the averages are non-finite; "
                + (
                    f"all {bad[0]['chains']} chains"
                    if all(r["chains_with_nonfinite"] == r["chains"] for r in bad)
                    else f"{min(r['chains_with_nonfinite'] for r in bad)}–"
                    f"{max(r['chains_with_nonfinite'] for r in bad)} of {bad[0]['chains']} chains"
                )
                + " hit NaN/inf at every h, and the median time until |μ|² is 10% off its initial value is "
                + ", ".join(f"{common.format_g(r['time_off_orbit_median'])}" for r in bad)
                + " time units respectively (of T = "
                + f"{bad[0]['time_total']:g}). Each "
                "explicit ambient step changes |μ|² at second order in the (noise-dominated) "
                "increment; once |μ| has grown, the dissipation drift θ μ×(μ×Ω), cubic in μ, "
                "presumably makes the explicit step unstable, and the state overflows (the kernel "
                "then keeps the last finite state, flagged non-finite). The orbit-preserving "
                "integrators keep |μ|² to "
                + common.format_g(
                    max(
                        (r["casimir_drift_max"] for r in acc_rows if r["preserves_orbit"]),
                        default=math.nan,
                    ),
                    2,
                )
                + " relative (largest drift over all their runs)."
            )
    for e in target_errors:
        best = [(n, t[str(e)]) for n, t in tta.items() if t[str(e)] is not None]
        if best:
            n, t = min(best, key=lambda kv: kv[1]["seconds"])
            others = (
                ", ".join(f"{m} {common.format_seconds(u['seconds'])}" for m, u in best if m != n)
                or "no other integrator reaches it on the grid"
            )
            iid = (
                (
                    f"; exact iid: {common.format_seconds(iid_tta[str(e)])}, "
                    f"{t['seconds'] / iid_tta[str(e)]:.0f}× faster than {n}"
                )
                if iid_tta
                else ""
            )
            out.append(
                f"**RMSE ≤ {e:g} on every E[μ_i²]:** fastest is {n} at h={t['step_size']:g}, "
                f"{common.format_seconds(t['seconds'])} ({others}{iid})."
            )
        else:
            out.append(
                f"**RMSE ≤ {e:g}:** no integrator is certified on the measured step sizes "
                "(|bias| + 2 SE ≥ ε everywhere; for the smallest steps this is the SE of this "
                "run, not necessarily the bias)."
            )
    return "\n".join(f"- {line}" for line in out)


# Measured by the slow test, not by this script (it takes ~11 minutes); kept in every report.
SLOW_ORDER_SECTION = """
## Order of the default integrator below h = 0.1 (slow test)

`make test-slow` runs `tests/test_sampling.py::test_splitting_bias_is_second_order`
(16384 chains × T = 1400 per step size, about 11 minutes on the machine above). It measures
the bias of E[μ₃² − μ₁²] at h = 0.1 and h = 0.05 and checks that halving h divides it by
about 4: the h = 0.05 bias is within 3 SE of b(0.1)/4 and more than 3 SE away from b(0.1)/2.
It passed on 2026-11-22 (684 s). So the splitting is second order; the slopes of 1.3–1.7
above come from a large third-order term of opposite sign at h ≥ 0.1.
"""


# --------------------------------------------------------------------------- report sections

# Measured by the slow test, not by this script (it takes ~11 minutes); kept in every report.
SLOW_ORDER_SECTION = """
## Order of the default integrator below h = 0.1 (slow test)

`make test-slow` runs `tests/test_sampling.py::test_splitting_bias_is_second_order`
(16384 chains × T = 1400 per step size, about 11 minutes on the machine above). It measures
the bias of E[μ₃² − μ₁²] at h = 0.1 and h = 0.05 and checks that halving h divides it by
about 4: the h = 0.05 bias is within 3 SE of b(0.1)/4 and more than 3 SE away from b(0.1)/2.
It passed on 2026-11-22 (684 s). So the splitting is second order; the slopes of 1.3–1.7
above come from a large third-order term of opposite sign at h ≥ 0.1.
"""


def analysis(results: common.CoreResults) -> dict:
    """Slopes, times to accuracy and the exact sampler's times, computed once per report and
    written to ``summary.json``."""
    if "accuracy" in results.derived:
        return results.derived["accuracy"]
    acc_rows, order_rows, iid = results.accuracy_rows, results.order_rows, results.iid
    target_errors = results.config["target_errors"]
    order_slopes = {
        n: fit_slopes(order_rows, n) for n in dict.fromkeys(r["integrator"] for r in order_rows)
    }
    names = [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in acc_rows)]
    slopes = {n: fit_slopes(acc_rows, n) for n in names}
    tta = {n: {str(e): time_to_accuracy(acc_rows, n, e) for e in target_errors} for n in names}
    iid_rate = max(r["samples_per_second"] for r in iid["rows"]) if iid["rows"] else None
    var = np.asarray(iid["check"]["variance"])
    iid_tta = (
        {str(e): float(np.max(var) / e**2 / iid_rate) for e in target_errors} if iid_rate else {}
    )
    derived = {
        "slopes": slopes,
        "order_check_slopes": order_slopes,
        "time_to_accuracy": tta,
        "iid_time_to_accuracy": iid_tta,
    }
    results.written.append(common.write_json(results.out_dir / "summary.json", derived))
    results.derived["accuracy"] = derived
    return derived


def report_section(results: common.CoreResults) -> str:
    """Section 2 of ``RESULTS.md`` (accuracy against cost, observed order, time to accuracy),
    with its two plots."""
    derived = analysis(results)
    cfg, acc_rows, iid = results.config, results.accuracy_rows, results.iid
    target_errors = cfg["target_errors"]
    cost_plot = plot_accuracy_cost(
        acc_rows, iid["rows"], iid["check"], target_errors, results.out_dir / "accuracy_cost.png"
    )
    bias_plot = plot_bias_vs_step(
        acc_rows, results.out_dir / "bias_vs_step.png", results.order_rows
    )
    results.written += [cost_plot, bias_plot]
    a0 = acc_rows[0]
    return f"""## 2. Accuracy against cost

{a0["chains"]} independent chains per setting, started from exact Gibbs draws, each run for a
physical time T = {a0["time_total"]:g} (round(T/h) steps); the first {cfg["accuracy_burn_in"]:g}
time units are discarded. Nothing is stored: the loop carry accumulates, per chain, Σμ_i² and
Σμ_i⁴ over kept steps, the number of non-finite (rejected) steps and the Casimir drift. Per
component f = μ_i²:

- **bias** = (mean over chains of the per-chain time averages) − exact; **SE** = std over chains
  / √chains. The chains are independent, so this SE is honest (autocorrelation included).
  "(n.r.)" = **not resolved**, |bias| < 2 SE.
- **ESS** = Var(f) / SE², with Var(f) the pooled mean(f²) − mean(f)² (batch means with one
  batch per chain); **τ_int** = chains × (kept time) / ESS, in time units. Cross-check: ArviZ
  `ess_bulk` of μ₃² (via `liesample.analysis.diagnostics.expectation_table`) from a separate stored run
  of {cfg["ess_check_chains"]} chains keeping every step, converted to τ_int the same way.
- **wall** = wall time of the whole {a0["chains"]}-chain run, burn-in included, compilation
  excluded (one executable per integrator; the step size is a traced argument).
  **s per ESS(μ₃²)** = wall / ESS(μ₃²).

{_accuracy_table(acc_rows)}

### Observed order

Log–log slope of max_i |bias| against h (least squares over the resolved points with
h ≤ {FIT_H_MAX:g}, the asymptotic range) and local slopes between neighbouring step sizes
((n.r.) = one of the two points is not resolved, so that slope is noise-dominated):

{_slope_table(acc_rows, derived["slopes"])}

{_order_section(results.order_rows, derived["order_check_slopes"], acc_rows)}
![bias vs step size]({results.link(bias_plot)})

### Time to a given accuracy

Least wall time (on this machine, {a0["chains"]} vmapped chains) for an estimator of every
E[μ_i²] with RMSE ≤ ε: for each measured h, RMSE_i² = b_i² + Var_i/ESS_i with the bias bounded
conservatively by b_i = |bias_i| + 2 SE_i, so the time needed is
max_i wall · SE_i² / (ε² − b_i²); the table keeps the best h (h must have b_i < ε for every
i; "not certified" = no measured h qualifies, which at small ε can be the SE of this run rather
than the bias). The exact iid row is max_i Var_i / ε² divided by its samples/s. These are
marginal costs at the measured per-ESS rate: they leave out compilation (≈ 1–2 s per
executable) and assume as many vmapped chains as here; the {
        100 * cfg["accuracy_burn_in"] / cfg["accuracy_time"]:.0f}% burn-in is included.

{_tta_table(derived["time_to_accuracy"], derived["iid_time_to_accuracy"], target_errors)}

![accuracy against cost]({results.link(cost_plot)})
"""


def findings_section(results: common.CoreResults) -> str:
    """The findings of the core sections 1–3, then the slow test's order check."""
    derived = analysis(results)
    findings = _findings(
        results.throughput_rows,
        results.iid["rows"],
        results.iid["check"],
        results.accuracy_rows,
        derived["slopes"],
        derived["time_to_accuracy"],
        derived["iid_time_to_accuracy"],
        results.config["target_errors"],
        results.order_rows,
        derived["order_check_slopes"],
    )
    return f"## Findings\n\n{findings}\n{SLOW_ORDER_SECTION}"
