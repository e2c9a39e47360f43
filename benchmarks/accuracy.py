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
ArviZ's rank-normalised ``ess_bulk`` of ``μ₃²`` via
``liesample.analysis.diagnostics.expectation_table``, converted to ``tau_int`` for comparison.

This module measures (``run_accuracy``, ``run_order_check``) and derives the numbers the report
quotes (``analysis``: bias slopes, times to accuracy); ``benchmarks/accuracy_plots.py`` draws
the two figures and ``benchmarks/accuracy_report.py`` writes the Markdown sections.
"""

from __future__ import annotations

import itertools
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common
from liesample.analysis.diagnostics import expectation_table
from liesample.integrators import get_integrator
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


# --------------------------------------------------------------------------- statistics from JSON

FIT_H_MAX = 0.4  # the order is fitted on resolved points with h ≤ this (asymptotic range)


def measured_integrators(rows) -> list[str]:
    """The integrators that appear in ``rows``, in the order of ``common.INTEGRATOR_NAMES``."""
    return [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in rows)]


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
    names = measured_integrators(acc_rows)
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
