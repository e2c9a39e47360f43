"""The two figures of section 2 (accuracy against cost), drawn from ``accuracy.json`` alone.

``plot_accuracy_cost``: bias against seconds per effective sample, and least time to a target
RMSE; ``plot_bias_vs_step``: bias against step size with reference slopes. The numbers come
from ``benchmarks/accuracy.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from benchmarks import common
from benchmarks.accuracy import measured_integrators, time_to_accuracy


def _finite_rows(rows, name):
    return sorted(
        (r for r in rows if r["integrator"] == name and r["finite"]), key=lambda r: r["step_size"]
    )


def _largest_bias(pts):
    """Per row: |bias| and SE of the component with the largest |bias|, and whether that bias
    is resolved (arrays)."""
    i = [r["max_abs_bias_component"] - 1 for r in pts]
    y = np.array([abs(r["bias"][k]) for r, k in zip(pts, i, strict=True)])
    se = np.array([r["se"][k] for r, k in zip(pts, i, strict=True)])
    return y, se, np.array([r["max_abs_bias_resolved"] for r in pts])


def _two_se(y, se):
    """±2 SE error bars, the lower one kept above zero on log axes."""
    return [np.minimum(2 * se, 0.9 * y), 2 * se]


def _line_with_2se_bars(ax, x, y, se, color):
    """A line through ``(x, y)`` with ±2 SE bars."""
    ax.plot(x, y, "-", color=color, lw=1.2)
    ax.errorbar(
        x,
        y,
        yerr=_two_se(y, se),
        fmt="none",
        ecolor=color,
        elinewidth=0.8,
        capsize=2,
    )


def plot_accuracy_cost(rows, iid_rows, iid_check, path: Path) -> Path:
    """Left: max |bias| against seconds per effective sample of μ₃², one line per integrator;
    right: least time to RMSE ≤ ε against ε; the exact sampler as the reference in both."""
    fig = Figure(figsize=(13.0, 5.6), layout="constrained")
    ax, ax2 = fig.subplots(1, 2)
    notes, lowest = [], []
    names = measured_integrators(rows)
    for name in names:
        pts = _finite_rows(rows, name)
        if not pts:
            notes.append(f"{name}: not shown, estimates non-finite at every step size")
            continue
        x = np.array([r["seconds_per_ess"][2] for r in pts])
        y, se, ok = _largest_bias(pts)
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
    """Max |bias| against step size, with the high-precision check and slopes 1 and 2."""
    fig = Figure(figsize=(7.5, 5.4), layout="constrained")
    ax = fig.subplots()
    names = measured_integrators(rows)
    notes, anchors = [], []
    for name in names:
        pts = _finite_rows(rows, name)
        if not pts:
            notes.append(f"{name}: non-finite at every step size (diverged)")
            continue
        h = np.array([r["step_size"] for r in pts])
        y, se, ok = _largest_bias(pts)
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
        y, se, _ = _largest_bias(pts)
        c = common.COLORS[name]
        ax.errorbar(
            h * 1.03,
            y,
            yerr=_two_se(y, se),
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
