"""Figures for sampler output: traces, time correlations, marginals, sphere densities, cost,
spectra per degree and vorticity maps.

Every function draws on a standalone :class:`matplotlib.figure.Figure` rendered by the Agg
backend (no pyplot state, no display needed), writes a PNG and returns its path.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:  # matplotlib is imported only when a figure is drawn
    from matplotlib.figure import Figure

__all__ = [
    "plot_accuracy_cost",
    "plot_autocorrelation",
    "plot_marginals",
    "plot_spectra",
    "plot_sphere_density",
    "plot_traces",
    "plot_vorticity",
]

_DPI = 150
_SUBSCRIPTS = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")
_AXIS_LABELS = {
    "seconds": "wall time (s)",
    "wall_time": "wall time (s)",
    "abs_bias": "|bias|",
    "bias": "bias",
    "rmse": "RMSE",
    "step_size": "step size h",
    "n_steps": "number of steps",
    "grad_evals": "gradient evaluations",
    "ess_per_second": "ESS / s",
}
_MAX_LEGEND_CHAINS = 10


def _default_names(d: int) -> list[str]:
    return [f"μ{str(i + 1).translate(_SUBSCRIPTS)}" for i in range(d)]


def _component_names(names, d: int) -> list[str]:
    if names is None or len(names) != d:
        return _default_names(d)
    return [str(n) for n in names]


def _as_chains(positions) -> np.ndarray:
    """``positions`` as a float array ``(chains, draws, d)`` (a missing ``d`` axis is added)."""
    pos = np.asarray(positions, dtype=float)
    if pos.ndim == 2:
        pos = pos[..., None]
    if pos.ndim != 3 or pos.shape[0] < 1 or pos.shape[1] < 1:
        raise ValueError(
            f"positions must have shape (chains, draws, d) or (chains, draws), "
            f"got {np.shape(positions)}"
        )
    return pos


def _as_samples(samples) -> np.ndarray:
    """``samples`` as a float array ``(n, d)``, ``n ≥ 2`` (chains flattened, ``d`` added)."""
    x = np.asarray(samples, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    elif x.ndim == 3:
        x = x.reshape(-1, x.shape[-1])
    if x.ndim != 2 or x.shape[0] < 2 or x.shape[1] < 1:
        raise ValueError(f"samples must have shape (n, d) with n >= 2, got {np.shape(samples)}")
    return x


def __getattr__(name):
    """``plots.Figure`` is matplotlib's class, imported on first use (PEP 562)."""
    if name == "Figure":
        from matplotlib.figure import Figure

        return Figure
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _figure(**options) -> Figure:
    """A standalone Agg :class:`matplotlib.figure.Figure` (matplotlib imported here, lazily)."""
    from matplotlib.figure import Figure

    return Figure(**options)


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=_DPI)
    fig.clear()
    return path


def plot_traces(
    positions: npt.ArrayLike,
    path: str | os.PathLike,
    *,
    names: Sequence[str] | None = ("μ₁", "μ₂", "μ₃"),
    max_draws: int = 2000,
    title: str | None = None,
) -> Path:
    """Trace plot: one panel per component, one line per chain.

    Parameters
    ----------
    positions : array_like, shape (chains, draws, d) or (chains, draws)
        Sampled states.
    path : str or Path
        Output PNG.
    names : sequence of str, default ("μ₁", "μ₂", "μ₃")
        Component labels; replaced by μ₁..μ_d when the length does not match ``d``.
    max_draws : int, default 2000
        Only the first ``max_draws`` draws of each chain are drawn.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    pos = _as_chains(positions)
    if int(max_draws) < 1:
        raise ValueError(f"max_draws must be >= 1, got {max_draws}")
    n_chains, n_draws, d = pos.shape
    shown = min(n_draws, int(max_draws))
    labels = _component_names(names, d)

    fig = _figure(figsize=(10, 1.2 + 1.9 * d), layout="constrained")
    axes = np.atleast_1d(fig.subplots(d, 1, sharex=True, squeeze=False)[:, 0])
    alpha = 0.9 if n_chains <= 4 else max(0.25, 3.0 / n_chains)
    draws = np.arange(shown)
    for i, ax in enumerate(axes):
        for c in range(n_chains):
            ax.plot(draws, pos[c, :shown, i], lw=0.7, alpha=alpha, label=f"chain {c}")
        ax.set_ylabel(labels[i], rotation=0, labelpad=12, fontsize="large")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("draw")
    axes[-1].set_xlim(0, max(shown - 1, 1))
    suffix = f" (first {shown} of {n_draws} draws)" if shown < n_draws else ""
    fig.suptitle((title or f"Traces, {n_chains} chain{'s' * (n_chains != 1)}") + suffix)
    if n_chains <= _MAX_LEGEND_CHAINS:  # below the panels, so no trace is hidden
        handles, labels_ = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels_, loc="outside lower center", ncols=n_chains, fontsize="small")
    return _save(fig, path)


def plot_autocorrelation(
    lag_times: npt.ArrayLike,
    empirical: npt.ArrayLike | tuple[npt.ArrayLike, npt.ArrayLike],
    path: str | os.PathLike,
    *,
    exact: npt.ArrayLike | None = None,
    ylabel: str = "E[μ(t)·μ(0)]",
    title: str | None = None,
) -> Path:
    """Empirical time correlation against lag, with the exact curve if known.

    Parameters
    ----------
    lag_times : array_like, shape (k,)
        Lag times t (in the dynamics' time units).
    empirical : array_like, shape (k,), or tuple (estimate, se)
        Estimated correlation; with standard errors a ±2·SE band is drawn.
    path : str or Path
        Output PNG.
    exact : array_like, shape (k,), or callable, optional
        Exact correlation at ``lag_times``, or a function evaluated on a fine grid.
    ylabel : str, default "E[μ(t)·μ(0)]"
        Y-axis label (also used in the legend).
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    t = np.asarray(lag_times, dtype=float)
    if t.ndim != 1 or t.size < 1:
        raise ValueError(f"lag_times must be a non-empty 1-D array, got shape {t.shape}")
    se = None
    if isinstance(empirical, tuple):
        if len(empirical) != 2:
            raise ValueError("empirical must be an array or a tuple (estimate, se)")
        est, se = (np.asarray(a, dtype=float) for a in empirical)
    else:
        est = np.asarray(empirical, dtype=float)
    if est.shape != t.shape or (se is not None and se.shape != t.shape):
        raise ValueError(
            f"empirical must match lag_times, shape {t.shape}: got {est.shape}"
            + ("" if se is None else f" and se {se.shape}")
        )

    fig = _figure(figsize=(7.5, 4.5), layout="constrained")
    ax = fig.subplots()
    ax.axhline(0.0, color="0.6", lw=0.8)
    if se is not None:
        ax.fill_between(t, est - 2 * se, est + 2 * se, color="C0", alpha=0.25, lw=0, label="±2 SE")
    ax.plot(t, est, "o-", color="C0", ms=3.5, lw=1.0, label="sampler estimate")
    if exact is not None:
        if callable(exact):
            fine = np.linspace(t.min(), t.max(), 400)
            ax.plot(
                fine, np.asarray(exact(fine), dtype=float), "-", color="C3", lw=1.8, label="exact"
            )
        else:
            ex = np.asarray(exact, dtype=float)
            if ex.shape != t.shape:
                raise ValueError(f"exact must match lag_times, shape {t.shape}: got {ex.shape}")
            ax.plot(t, ex, "-", color="C3", lw=1.8, label="exact")
    ax.set_xlabel("lag time t")
    ax.set_ylabel(ylabel)
    ax.set_title(title or f"Time correlation {ylabel}")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path)


def plot_marginals(
    samples: npt.ArrayLike,
    path: str | os.PathLike,
    *,
    exact_densities: Sequence[Callable | None] | None = None,
    names: Sequence[str] | None = ("μ₁", "μ₂", "μ₃"),
    bins: int = 60,
    title: str | None = None,
) -> Path:
    """Histogram of each component's marginal, with exact densities overlaid.

    Parameters
    ----------
    samples : array_like, shape (n, d); (chains, draws, d) is flattened
        Samples.
    path : str or Path
        Output PNG.
    exact_densities : sequence of callable or None, optional
        ``f(grid) -> density`` for each component (``None`` to skip one).
    names : sequence of str, default ("μ₁", "μ₂", "μ₃")
        Component labels; replaced by μ₁..μ_d when the length does not match ``d``.
    bins : int, default 60
        Histogram bins per component.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    x = _as_samples(samples)
    n, d = x.shape
    if exact_densities is not None and len(exact_densities) != d:
        raise ValueError(
            f"exact_densities must have one entry (callable or None) per component: "
            f"got {len(exact_densities)} for d = {d}"
        )
    if int(bins) < 1:
        raise ValueError(f"bins must be >= 1, got {bins}")
    labels = _component_names(names, d)
    finite = np.isfinite(x).all(axis=1)

    ncols = min(d, 3)
    nrows = math.ceil(d / ncols)
    fig = _figure(figsize=(4.2 * ncols, 3.4 * nrows + 0.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False).ravel())
    for i in range(d):
        ax = axes[i]
        xi = x[finite, i]
        ax.hist(xi, bins=int(bins), density=True, color="C0", alpha=0.55, label="samples")
        f = None if exact_densities is None else exact_densities[i]
        if f is not None and xi.size:
            lo, hi = float(xi.min()), float(xi.max())
            pad = 0.02 * (hi - lo or 1.0)
            grid = np.linspace(lo - pad, hi + pad, 400)
            ax.plot(grid, np.asarray(f(grid), dtype=float), color="C3", lw=1.8, label="exact")
        ax.set_xlabel(labels[i])
        ax.set_ylabel(f"density p({labels[i]})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    for ax in axes[d:]:
        ax.set_visible(False)
    dropped = n - int(finite.sum())
    note = f"; {dropped} non-finite dropped" if dropped else ""
    fig.suptitle((title or "Marginal densities") + f" (n = {int(finite.sum())}{note})")
    return _save(fig, path)


def _sphere_grid(n_points: int, bins: int | Sequence[int] | None) -> tuple[int, int]:
    if bins is not None:
        n_lon, n_z = (
            (int(cast(int, bins)), max(1, int(cast(int, bins)) // 2))
            if np.isscalar(bins)
            else map(int, bins)
        )
    else:
        # about 20 points per bin on average, longitude bins twice the height bins
        n_z = int(np.clip(round(math.sqrt(n_points / 40)), 6, 60))
        n_lon = 2 * n_z
    if n_lon < 1 or n_z < 1:
        raise ValueError(f"bins must be positive, got {bins}")
    return n_lon, n_z


def plot_sphere_density(
    unit_vectors: npt.ArrayLike,
    path: str | os.PathLike,
    *,
    logdensity_fn: Callable | None = None,
    title: str | None = None,
    bins: int | tuple[int, int] | None = None,
) -> Path:
    """Density of points on the sphere in an equal-area (Lambert cylindrical) projection.

    Points are mapped to longitude φ = atan2(y, x) and z = cos θ; equal rectangles in (φ, z)
    have equal area on the sphere, so the histogram estimates the density per steradian
    (integrating to 1 over 4π sr). Vectors are projected to the unit sphere first.

    Parameters
    ----------
    unit_vectors : array_like, shape (..., 3)
        Sampled points (any radius; leading axes are flattened).
    path : str or Path
        Output PNG.
    logdensity_fn : callable, optional
        Maps ``(..., 3)`` unit vectors to an (unnormalised) log density. When given, the
        exact density, normalised on the same grid, is drawn beside the histogram with the
        same colour scale.
    title : str, optional
        Figure title.
    bins : int or (int, int), optional
        Longitude bins (and z bins); default chooses about 20 points per bin.

    Returns
    -------
    pathlib.Path
    """
    v = np.asarray(unit_vectors, dtype=float)
    if v.ndim < 1 or v.shape[-1] != 3:
        raise ValueError(f"unit_vectors must have shape (..., 3), got {v.shape}")
    v = v.reshape(-1, 3)
    norms = np.linalg.norm(v, axis=1)
    ok = np.isfinite(norms) & (norms > 0)
    if not ok.any():
        raise ValueError("unit_vectors contains no finite non-zero vectors")
    v = v[ok] / norms[ok, None]
    lon = np.arctan2(v[:, 1], v[:, 0])
    z = np.clip(v[:, 2], -1.0, 1.0)

    n_lon, n_z = _sphere_grid(len(v), bins)
    lon_edges = np.linspace(-np.pi, np.pi, n_lon + 1)
    z_edges = np.linspace(-1.0, 1.0, n_z + 1)
    cell = (lon_edges[1] - lon_edges[0]) * (z_edges[1] - z_edges[0])  # steradians
    counts, _, _ = np.histogram2d(z, lon, bins=(z_edges, lon_edges))
    empirical = counts / (len(v) * cell)

    exact = None
    if logdensity_fn is not None:
        lon_c = 0.5 * (lon_edges[1:] + lon_edges[:-1])
        z_c = 0.5 * (z_edges[1:] + z_edges[:-1])
        zz, ll = np.meshgrid(z_c, lon_c, indexing="ij")
        rho = np.sqrt(1.0 - zz**2)
        grid = np.stack([rho * np.cos(ll), rho * np.sin(ll), zz], axis=-1)
        logp = np.asarray(logdensity_fn(grid), dtype=float)
        if logp.shape != grid.shape[:-1]:
            raise ValueError(
                f"logdensity_fn must map (..., 3) to (...), got {logp.shape} for {grid.shape}"
            )
        p = np.exp(logp - np.max(logp))
        exact = p / (p.sum() * cell)

    vmax = max(float(empirical.max()), float(exact.max()) if exact is not None else 0.0)
    panels = [("sampled", empirical)] + ([("exact", exact)] if exact is not None else [])
    fig = _figure(figsize=(6.0 * len(panels) + 0.6, 3.9), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(panels), squeeze=False)[0])
    for ax, (label, dens) in zip(axes, panels, strict=True):
        mesh = ax.pcolormesh(lon_edges, z_edges, dens, cmap="viridis", vmin=0.0, vmax=vmax)
        fig.colorbar(mesh, ax=ax, label="density (sr⁻¹)")
        ax.set_title(f"{label} ({len(v)} points)" if label == "sampled" else label)
        ax.set_xlabel("longitude φ (rad)")
        ax.set_ylabel("cos θ = z")
        ax.set_xticks([-np.pi, -np.pi / 2, 0, np.pi / 2, np.pi], ["−π", "−π/2", "0", "π/2", "π"])
        ax.set_xlim(-np.pi, np.pi)
        ax.set_ylim(-1, 1)
    fig.suptitle(title or "Density on the sphere (equal-area projection)")
    return _save(fig, path)


def plot_accuracy_cost(
    rows: Sequence[Mapping],
    path: str | os.PathLike,
    *,
    x: str = "seconds",
    y: str = "abs_bias",
    label: str = "integrator",
    title: str | None = None,
) -> Path:
    """Log–log error against cost, one line per ``label`` value.

    Parameters
    ----------
    rows : sequence of mapping
        Benchmark records, each with keys ``x``, ``y`` and ``label``.
    path : str or Path
        Output PNG.
    x, y : str, default "seconds", "abs_bias"
        Keys for cost and error.
    label : str, default "integrator"
        Key that groups rows into lines.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path

    Notes
    -----
    Points with non-positive or non-finite ``x`` or ``y`` cannot be shown on log axes; they
    are left out and counted in a note on the figure.
    """
    rows = list(rows)
    if not rows:
        raise ValueError("rows must contain at least one record")
    for i, row in enumerate(rows):
        missing = [k for k in (x, y, label) if k not in row]
        if missing:
            raise ValueError(f"rows[{i}] is missing keys {missing}")

    groups: dict[str, list[tuple[float, float]]] = {}
    dropped = 0
    for row in rows:
        xv, yv = float(row[x]), float(row[y])
        if not (math.isfinite(xv) and math.isfinite(yv) and xv > 0 and yv > 0):
            dropped += 1
            continue
        groups.setdefault(str(row[label]), []).append((xv, yv))

    fig = _figure(figsize=(7.0, 5.0), layout="constrained")
    ax = fig.subplots()
    markers = "osD^vP*X"
    for k, (name, pts) in enumerate(sorted(groups.items())):
        pts.sort()
        xs, ys = zip(*pts, strict=True)
        ax.plot(xs, ys, marker=markers[k % len(markers)], lw=1.3, ms=6, label=name)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(_AXIS_LABELS.get(x, x))
    ax.set_ylabel(_AXIS_LABELS.get(y, y))
    ax.grid(which="both", alpha=0.3)
    if groups:
        ax.legend(title=label)
    if dropped:
        ax.text(
            0.01,
            0.01,
            f"{dropped} point(s) ≤ 0 or non-finite not shown",
            transform=ax.transAxes,
            fontsize="small",
            color="0.4",
        )
    ax.set_title(title or f"{_AXIS_LABELS.get(y, y)} vs {_AXIS_LABELS.get(x, x)}")
    return _save(fig, path)


_SPECTRUM_LABELS = {"energy": "energy ε_ℓ", "enstrophy": "enstrophy ζ_ℓ"}


def _spectrum_rows(values, name, size=None):
    rows = np.atleast_2d(np.asarray(values, dtype=float))
    if rows.ndim != 2 or rows.shape[1] < 1 or (size is not None and rows.shape[1] != size):
        expected = "(degrees,) or (lines, degrees)" if size is None else f"(..., {size})"
        raise ValueError(f"{name} must have shape {expected}, got {np.shape(values)}")
    return rows


def plot_spectra(
    spectra: npt.ArrayLike,
    path: str | os.PathLike,
    *,
    kind: str = "energy",
    labels: Sequence[str] | None = None,
    errors: npt.ArrayLike | None = None,
    exact: npt.ArrayLike | None = None,
    title: str | None = None,
) -> Path:
    """Spectra per degree ``ℓ = 1, 2, …`` on log–log axes, one line per row.

    Parameters
    ----------
    spectra : array_like, shape (L,) or (lines, L)
        Values for ``ℓ = 1 … L``: e.g. mean energy spectra
        (:func:`liesample.systems.zeitlin_states.energy_spectrum` averaged over draws), one row
        per inverse temperature.
    path : str or Path
        Output PNG.
    kind : {"energy", "enstrophy"}
        Y-axis label.
    labels : sequence of str, optional
        One legend entry per line.
    errors : array_like, same shape as ``spectra``, optional
        Standard errors; a ±2·SE band is drawn.
    exact : array_like, shape (L,) or (lines, L), optional
        Exact spectra, drawn dashed in the colour of the matching line (one row for all).
    title : str, optional

    Returns
    -------
    pathlib.Path
    """
    if kind not in _SPECTRUM_LABELS:
        raise ValueError(f"kind must be one of {sorted(_SPECTRUM_LABELS)}, got {kind!r}")
    rows = _spectrum_rows(spectra, "spectra")
    lines, size = rows.shape
    if labels is not None and len(labels) != lines:
        raise ValueError(f"labels must have one entry per line ({lines}), got {len(labels)}")
    band = None if errors is None else _spectrum_rows(errors, "errors", size)
    reference = None if exact is None else _spectrum_rows(exact, "exact", size)
    if band is not None and band.shape[0] != lines:
        raise ValueError(f"errors must have {lines} rows, got {band.shape[0]}")
    degrees = np.arange(1, size + 1)
    fig = _figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.subplots()
    for i, row in enumerate(rows):
        colour = f"C{i % 10}"
        positive = row > 0
        label = None if labels is None else str(labels[i])
        ax.plot(degrees[positive], row[positive], "o-", color=colour, ms=3, label=label)
        if band is not None:
            low = np.maximum(row - 2 * band[i], row * 1e-3)
            ax.fill_between(degrees, low, row + 2 * band[i], color=colour, alpha=0.2, lw=0)
        if reference is not None:
            target = reference[i if reference.shape[0] == lines else 0]
            ax.plot(degrees[target > 0], target[target > 0], "--", color=colour, lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("degree ℓ")
    ax.set_ylabel(_SPECTRUM_LABELS[kind])
    ax.grid(alpha=0.3, which="both")
    if labels is not None:
        ax.legend(fontsize="small")
    note = " (dashed: exact)" if exact is not None else ""
    fig.suptitle(title or f"{kind.capitalize()} spectrum{note}")
    return _save(fig, path)


def plot_vorticity(
    values: npt.ArrayLike,
    theta: npt.ArrayLike,
    phi: npt.ArrayLike,
    path: str | os.PathLike,
    *,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> Path:
    """Vorticity maps ``ω(θ, φ)`` (latitude–longitude), one panel per field, one colour scale
    symmetric about 0.

    ``values`` has shape ``(num_theta, num_phi)`` or ``(panels, num_theta, num_phi)`` on
    colatitudes ``theta`` and longitudes ``phi`` (e.g. from
    :func:`liesample.systems.zeitlin_states.vorticity_on_grid` or
    :meth:`liesample.systems.zeitlin.QuantisedHarmonics.grid`). Returns the PNG's path.
    """
    fields = np.asarray(values, dtype=float)
    if fields.ndim == 2:
        fields = fields[None]
    theta, phi = np.asarray(theta, dtype=float), np.asarray(phi, dtype=float)
    if fields.ndim != 3 or fields.shape[1:] != (theta.size, phi.size):
        raise ValueError(
            f"values must have shape (panels, {theta.size}, {phi.size}), got {np.shape(values)}"
        )
    if labels is not None and len(labels) != len(fields):
        raise ValueError(f"labels must have one entry per panel ({len(fields)})")
    scale = float(np.max(np.abs(fields))) or 1.0
    panels = len(fields)
    ncols = min(panels, 3)
    nrows = math.ceil(panels / ncols)
    fig = _figure(figsize=(4.6 * ncols, 2.6 * nrows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False).ravel())
    latitude, longitude = 90.0 - np.degrees(theta), np.degrees(phi)
    image = None
    for i, field in enumerate(fields):
        image = axes[i].pcolormesh(
            longitude, latitude, field, cmap="RdBu_r", vmin=-scale, vmax=scale, shading="nearest"
        )
        axes[i].set_xlabel("longitude (°)")
        axes[i].set_ylabel("latitude (°)")
        if labels is not None:
            axes[i].set_title(str(labels[i]), fontsize="small")
    for ax in axes[panels:]:
        ax.set_visible(False)
    fig.colorbar(cast(Any, image), ax=axes[:panels].tolist(), label="ω")  # panels >= 1
    fig.suptitle(title or "Vorticity")
    return _save(fig, path)
