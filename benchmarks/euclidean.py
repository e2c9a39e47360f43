"""Adapted magnetic HMC against BlackJAX NUTS and HMC on Euclidean targets.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/euclidean.py            # full, ~10 min on 2 shared cores
    .venv/bin/python benchmarks/euclidean.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``euclidean.json`` and ``euclidean.png``. Every sampler gets the same number of warm-up
transitions per chain (``num_warmup``), then ``NUM_CHAINS`` chains draw ``num_draws`` each:

- ``magnetic_hmc`` (``liesample``): ``liesample.window_adaptation(liesample.magnetic_hmc, …)``
  (:func:`liesample.tuning.adaptation.magnetic_window_adaptation`) on the ``NUM_CHAINS``
  chains at once — step size, diagonal mass and the field
  ``default_magnetic_field(M⁻¹, angle / ε)`` adapted jointly, the trajectory length by the
  ChEES-type rule — then :func:`liesample.jittered_magnetic_hmc` from the adapted states; one
  row per angle in ``ANGLES`` (the default, and angle 0.25 or 0 beside it);
- ``blackjax nuts`` and ``blackjax hmc`` (``L = NUM_STEPS``): ``blackjax.window_adaptation``
  (diagonal mass, target acceptance 0.8) on one chain, all chains start from its state. Their
  warm-up costs ``NUM_CHAINS`` times fewer gradients than the multi-chain one (both are in the
  JSON, ``warmup_gradients``).

Per target and sampler: ESS (ArviZ bulk and tail; the minimum over coordinates of ``x`` and
``x²``, and the bulk ESS of ``log π``) per gradient evaluation of the sampling phase and per
second of sampling (compilation excluded), R-hat (largest over ``x``, and of ``log π``), and the
bias of the means and variances against exact moments (``z`` = error / MCSE). The logistic
regression has no exact law: its reference moments come from a long NUTS run, labelled so.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import arviz_stats as azs
import blackjax
import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common, suites
from liesample.targets import correlated_gaussian
from liesample.tuning import adaptation

SUITE = {"order": 40, "title": "adapted magnetic HMC vs BlackJAX NUTS and HMC (Euclidean targets)"}

NUM_CHAINS = 4
NUM_STEPS = 10  # leapfrog steps of BlackJAX HMC
# The field's strength as the angle (rad) it turns the whitened velocity per leapfrog step:
# the adaptation's default, and the other angle measured beside it.
ANGLE = adaptation.DEFAULT_ANGLE
ANGLES = tuple(sorted({ANGLE, 0.0, 0.25}))
GOALS = {"blackjax nuts": 1.0, "blackjax hmc": 1.5}  # ESS/gradient ratios (HMC: Gaussians)


# --------------------------------------------------------------------------- targets


class Target:
    """``logdensity_fn``, a start, exact (or reference) means and variances of ``x``."""

    def __init__(self, name, logdensity_fn, dimension, mean, variance, start, exact=True):
        self.name, self.logdensity_fn, self.dimension = name, logdensity_fn, dimension
        self.mean, self.variance = np.asarray(mean, float), np.asarray(variance, float)
        self.start, self.exact = jnp.asarray(start, float), exact


def gaussian_target(name, gaussian):
    d = gaussian.dimension
    return Target(
        name, gaussian.logdensity_fn, d, gaussian.mean, np.diag(gaussian.covariance), np.zeros(d)
    )


def banana():
    """``x₀ ~ N(0, 1)``, ``x₁ | x₀ ~ N(x₀², 0.3²)`` (a Rosenbrock-type ridge).

    Exact: ``E x₀ = 0``, ``Var x₀ = 1``, ``E x₁ = 1``, ``Var x₁ = Var(x₀²) + 0.09 = 2.09``."""

    def logdensity_fn(x):
        return -0.5 * x[0] ** 2 - 0.5 * ((x[1] - x[0] ** 2) / 0.3) ** 2

    return Target("banana (2-d)", logdensity_fn, 2, [0.0, 1.0], [1.0, 2.09], [0.0, 1.0])


def funnel(d=10):
    """Neal's funnel: ``v ~ N(0, 3²)``, ``x_i | v ~ N(0, e^v)``, i = 1..d−1 (centred).

    Exact: means 0, ``Var v = 9``, ``Var x_i = E e^v = e^{4.5}``."""

    def logdensity_fn(z):
        v, x = z[0], z[1:]
        return -0.5 * v**2 / 9.0 - 0.5 * (d - 1) * v - 0.5 * jnp.sum(x**2) * jnp.exp(-v)

    variance = np.full(d, np.exp(4.5))
    variance[0] = 9.0
    return Target(f"Neal's funnel ({d}-d)", logdensity_fn, d, np.zeros(d), variance, np.ones(d))


def logistic_regression():
    """Bayesian logistic regression, breast cancer (569 × 30, standardised), prior N(0, 1) on
    the 30 weights and the intercept. No exact law: moments from a long NUTS run."""
    from sklearn.datasets import load_breast_cancer

    data = load_breast_cancer()
    x = (data.data - data.data.mean(0)) / data.data.std(0)
    design = jnp.asarray(np.hstack([np.ones((x.shape[0], 1)), x]))
    y = jnp.asarray(data.target, float)

    def logdensity_fn(w):
        logits = design @ w
        return jnp.sum(y * logits - jnp.logaddexp(0.0, logits)) - 0.5 * jnp.sum(w**2)

    d = design.shape[1]
    return Target(
        "logistic regression, breast cancer (31-d)",
        logdensity_fn,
        d,
        np.zeros(d),
        np.ones(d),
        np.zeros(d),
        exact=False,
    )


def targets(quick):
    if quick:
        return [gaussian_target("Gaussian 2-d, ρ = 0.99", correlated_gaussian(2, 199.0)), banana()]
    return [
        gaussian_target(
            "Gaussian 100-d, κ = 100, rotated", correlated_gaussian(100, 100.0, seed=1)
        ),
        gaussian_target("Gaussian 2-d, ρ = 0.99", correlated_gaussian(2, 199.0)),
        banana(),
        funnel(),
        logistic_regression(),
    ]


# --------------------------------------------------------------------------- samplers


def run_chains(sampler, states, key, num_draws):
    """``(draws (chains, draws, d), log π (chains, draws), gradients, seconds, divergences)``
    from one state per chain (leading axis)."""

    def chain(state, key):
        def one(state, k):
            state, info = sampler.step(k, state)
            out = (state.position, state.logdensity, info.num_integration_steps, info.is_divergent)
            return state, out

        return jax.lax.scan(one, state, jax.random.split(key, num_draws))[1]

    run = liesample.jit(jax.vmap(chain))
    keys = jax.random.split(key, NUM_CHAINS)
    compiled = run.lower(states, keys).compile()
    (draws, logdensity, steps, divergent), seconds = common.timed(compiled, states, keys)
    return (
        np.asarray(draws),
        np.asarray(logdensity),
        int(np.sum(steps)),
        seconds,
        int(np.sum(divergent)),
    )


def replicate(state):
    return jax.tree.map(lambda leaf: jnp.broadcast_to(leaf, (NUM_CHAINS, *jnp.shape(leaf))), state)


PEERS = {
    "blackjax nuts": (blackjax.nuts, {}),
    "blackjax hmc": (blackjax.hmc, {"num_integration_steps": NUM_STEPS}),
}


def measure_peer(target, label, key, num_warmup, num_draws):
    algorithm, extra = PEERS[label]
    key_warmup, key_run = jax.random.split(key)
    warmup = blackjax.window_adaptation(algorithm, target.logdensity_fn, **extra)
    (state, parameters), info = warmup.run(key_warmup, target.start, num_steps=num_warmup)
    sampler = algorithm(target.logdensity_fn, **parameters)
    draws, logdensity, gradients, seconds, divergences = run_chains(
        sampler, replicate(state), key_run, num_draws
    )
    row = summarise(target, label, draws, logdensity, gradients, seconds, divergences)
    row["step_size"] = float(parameters["step_size"])
    row["warmup_gradients"] = int(np.sum(info.info.num_integration_steps))
    row["num_integration_steps"] = NUM_STEPS if label == "blackjax hmc" else None
    return row


def measure_magnetic(target, key, num_warmup, num_draws, angle):
    """``liesample.window_adaptation(liesample.magnetic_hmc, …)`` on ``NUM_CHAINS`` chains, then
    the jittered sampler from the adapted states."""
    key_warmup, key_run = jax.random.split(key)
    starts = target.start + 0.1 * jax.random.normal(
        jax.random.fold_in(key_warmup, 1), (NUM_CHAINS, target.dimension)
    )
    warmup = liesample.window_adaptation(liesample.magnetic_hmc, target.logdensity_fn, angle=angle)
    start = time.perf_counter()
    (states, parameters), info = warmup.run(key_warmup, starts, num_steps=num_warmup)
    warmup_seconds = time.perf_counter() - start
    sampler = liesample.jittered_magnetic_hmc(target.logdensity_fn, **parameters)
    draws, logdensity, gradients, seconds, divergences = run_chains(
        sampler, states, key_run, num_draws
    )
    label = f"magnetic_hmc (angle {angle:g}{', default' if angle == ANGLE else ''})"
    row = summarise(target, label, draws, logdensity, gradients, seconds, divergences)
    row.update(
        step_size=float(parameters["step_size"]),
        angle=angle,
        trajectory_length=float(info.trajectory_length[-1]),
        num_integration_steps=int(parameters["num_integration_steps"]),
        warmup_gradients=int(np.sum(info.info.num_integration_steps)),
        warmup_seconds=warmup_seconds,
    )
    return row


def summarise(target, label, draws, logdensity, gradients, seconds, divergences):
    x = draws
    ess = {}
    for method in ("bulk", "tail"):
        options = {"prob": (0.05, 0.95)} if method == "tail" else {}  # Vehtari et al. 2021
        e1 = np.asarray(azs.ess(x, method=method, sample_dims=(0, 1), **options))
        e2 = np.asarray(azs.ess(x**2, method=method, sample_dims=(0, 1), **options))
        ess[method] = float(min(e1.min(), e2.min()))
    ess_logdensity = float(azs.ess(logdensity, method="bulk", sample_dims=(0, 1)))
    rhat = float(np.max(np.asarray(azs.rhat(x, sample_dims=(0, 1)))))
    rhat_logdensity = float(azs.rhat(logdensity, sample_dims=(0, 1)))
    mean = x.mean(axis=(0, 1))
    ess_mean = np.asarray(azs.ess(x, method="mean", sample_dims=(0, 1)))
    flat = x.reshape(-1, x.shape[-1])
    mcse = flat.std(0) / np.sqrt(ess_mean)
    z_mean = (mean - target.mean) / mcse
    rel_var_error = (flat.var(0) - target.variance) / target.variance
    return {
        "target": target.name,
        "sampler": label,
        "gradients": gradients,
        "seconds": seconds,
        "divergences": divergences,
        "ess_bulk_min": ess["bulk"],
        "ess_tail_min": ess["tail"],
        "ess_logdensity": ess_logdensity,
        "ess_bulk_per_gradient": ess["bulk"] / gradients,
        "ess_tail_per_gradient": ess["tail"] / gradients,
        "ess_logdensity_per_gradient": ess_logdensity / gradients,
        "ess_bulk_per_second": ess["bulk"] / seconds,
        "ess_logdensity_per_second": ess_logdensity / seconds,
        "rhat_max": rhat,
        "rhat_logdensity": rhat_logdensity,
        "max_abs_z_mean": float(np.max(np.abs(z_mean))),
        "max_abs_rel_var_error": float(np.max(np.abs(rel_var_error))),
        "reference": "exact" if target.exact else "long NUTS run",
    }


def reference_moments(target, key, num_warmup, num_draws):
    """Means and variances of the logistic regression from a long NUTS run (no exact law)."""
    warmup = blackjax.window_adaptation(blackjax.nuts, target.logdensity_fn)
    (state, parameters), _ = warmup.run(key, target.start, num_steps=num_warmup)
    sampler = blackjax.nuts(target.logdensity_fn, **parameters)
    draws, *_ = run_chains(sampler, replicate(state), jax.random.fold_in(key, 1), num_draws)
    flat = draws.reshape(-1, draws.shape[-1])
    ess = float(np.min(np.asarray(azs.ess(draws, method="bulk", sample_dims=(0, 1)))))
    return flat.mean(0), flat.var(0), ess


def add_ratios(rows):
    """ESS/gradient (min bulk over x, x², and of log π) and ESS/s against NUTS and HMC."""
    for row in rows:
        for peer, key in (("blackjax nuts", "nuts"), ("blackjax hmc", "hmc")):
            ref = next(r for r in rows if r["sampler"] == peer)
            row[f"vs_{key}_ess_per_gradient"] = ref_ratio(row, ref, "ess_bulk_per_gradient")
            row[f"vs_{key}_logdensity_ess_per_gradient"] = ref_ratio(
                row, ref, "ess_logdensity_per_gradient"
            )
            row[f"vs_{key}_ess_per_second"] = ref_ratio(row, ref, "ess_bulk_per_second")


def ref_ratio(row, ref, key):
    return row[key] / ref[key] if ref[key] > 0 else float("inf")


def log_row(log, row):
    log(
        f"  {row['sampler']:<34} ESS/grad bulk {row['ess_bulk_per_gradient']:.2e} tail "
        f"{row['ess_tail_per_gradient']:.2e} log π {row['ess_logdensity_per_gradient']:.2e}  "
        f"ESS/s {row['ess_bulk_per_second']:8.1f}  R-hat {row['rhat_max']:.3f}  "
        f"max|z mean| {row['max_abs_z_mean']:.1f}  var err {row['max_abs_rel_var_error']:.2f}  "
        f"div {row['divergences']}"
    )


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    num_warmup = 300 if quick else 1000
    num_draws = 300 if quick else 2000
    key = jax.random.key(20240611)
    results = []
    for index, target in enumerate(targets(quick)):
        tkey = jax.random.fold_in(key, index)
        log(f"target: {target.name}")
        if not target.exact:
            mean, var, ess = reference_moments(
                target, jax.random.fold_in(tkey, 99), num_warmup, 5 * num_draws
            )
            target.mean, target.variance = mean, var
            log(f"  reference: long NUTS run, min bulk ESS {ess:.0f}")
        rows = [
            measure_magnetic(target, jax.random.fold_in(tkey, 1), num_warmup, num_draws, a)
            for a in ANGLES
        ]
        for label in PEERS:
            rows.append(
                measure_peer(target, label, jax.random.fold_in(tkey, 2), num_warmup, num_draws)
            )
        add_ratios(rows)
        for row in rows:
            log_row(log, row)
        results += rows
    data = {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": "quick" if quick else "full",
        "num_chains": NUM_CHAINS,
        "num_warmup": num_warmup,
        "num_draws": num_draws,
        "num_integration_steps": NUM_STEPS,
        "angle": ANGLE,
        "angles": ANGLES,
        "goals": GOALS,
        "results": results,
        "total_seconds": time.perf_counter() - start,
    }
    path = common.write_json(out_dir / "euclidean.json", data)
    plot(data, out_dir / "euclidean.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def short(label):
    """Legend name: the magnetic rows by role, the peers by name."""
    return label.replace(", default", "")


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["target"] for r in data["results"]))
    samplers = list(dict.fromkeys(short(r["sampler"]) for r in data["results"]))
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.8))
    width = 0.8 / len(samplers)
    for ax, key, title in (
        (axes[0], "ess_bulk_per_gradient", "min bulk ESS (x, x²) per gradient"),
        (axes[1], "ess_logdensity_per_gradient", "bulk ESS of log π per gradient"),
    ):
        for j, label in enumerate(samplers):
            rows = [r for r in data["results"] if short(r["sampler"]) == label]
            values = [next(r[key] for r in rows if r["target"] == n) for n in names]
            ax.bar(np.arange(len(names)) + j * width, values, width, label=label)
        ax.set_yscale("log")
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2)
        ax.set_xticklabels([n.split(",")[0].split(" (")[0] for n in names], rotation=15)
        ax.set_ylabel(title)
        ax.legend(fontsize=8)
    axes[0].set_title(f"Same warm-up length ({data['num_warmup']} transitions per chain)")
    axes[1].set_title(f"{data['num_chains']} chains x {data['num_draws']} draws")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "euclidean.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    if "goals" not in data:  # written by the older suite (field tuned after a zero-field warm-up)
        return ""
    rel = common.relative_link(out_dir / "euclidean.png", md_dir)
    lines = [
        "## Adapted magnetic HMC vs BlackJAX NUTS and HMC",
        "",
        (
            f"From `benchmarks/euclidean.py` ({data['machine']['date_utc']}, {data['mode']} mode, "
            f"{data['total_seconds']:.0f} s on {data['machine']['usable_cpus']} shared CPU cores: "
            "wall times are rough, ESS per gradient does not depend on the machine). "
            f"Every sampler warms up for {data['num_warmup']} transitions per chain, then "
            f"{data['num_chains']} chains x {data['num_draws']} draws. magnetic HMC: "
            "`liesample.window_adaptation(liesample.magnetic_hmc, ...)` on the "
            f"{data['num_chains']} chains together (step size, diagonal mass and field "
            "`default_magnetic_field(M⁻¹, angle / ε)` jointly; trajectory length by the "
            "ChEES-type rule of `magnetic_window_adaptation`), sampled with jittered lengths "
            f"(`jittered_magnetic_hmc`); the default angle is {data['angle']:g}. "
            "BlackJAX NUTS and HMC "
            f"(L = {data['num_integration_steps']}): `blackjax.window_adaptation` (diagonal mass, "
            "acceptance 0.8) on one chain, every chain starts from its state, so their warm-up "
            f"costs {data['num_chains']}x fewer gradients (column `warm-up grads`). ESS: the "
            "minimum over coordinates of `x` and `x²` (ArviZ bulk/tail) and the bulk ESS of "
            "`log π`, per gradient of the sampling phase; R-hat: the largest over `x`; "
            "`|z|`: the largest |error of a mean| / MCSE; `var err`: the largest relative "
            "error of a variance."
        ),
        "",
        (
            "| target | sampler | ε | L (max) | ESS/grad bulk | ESS/grad tail | ESS/grad log π "
            "| ESS/s bulk | R-hat | max abs z | var err | div. | warm-up grads "
            "| vs NUTS (bulk / log π) | vs HMC (bulk / log π) |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["results"]:
        ref = "" if r["reference"] == "exact" else " †"
        steps = r.get("num_integration_steps")
        lines.append(
            f"| {r['target']}{ref} | {r['sampler']} | {r['step_size']:.3g} | "
            f"{'' if steps is None else steps} | "
            f"{r['ess_bulk_per_gradient']:.2e} | {r['ess_tail_per_gradient']:.2e} | "
            f"{r['ess_logdensity_per_gradient']:.2e} | {r['ess_bulk_per_second']:.3g} | "
            f"{r['rhat_max']:.3f} | {r['max_abs_z_mean']:.1f} | "
            f"{r['max_abs_rel_var_error']:.2f} | {r['divergences']} | {r['warmup_gradients']} | "
            f"{r['vs_nuts_ess_per_gradient']:.2f} / "
            f"{r['vs_nuts_logdensity_ess_per_gradient']:.2f} | "
            f"{r['vs_hmc_ess_per_gradient']:.2f} / {r['vs_hmc_logdensity_ess_per_gradient']:.2f} |"
        )
    lines += ["", "† reference moments from a long NUTS run (no exact law), not exact.", ""]
    verdicts = []
    for r in data["results"]:
        if r.get("angle") != data["angle"]:
            continue
        nuts = r["vs_nuts_ess_per_gradient"]
        text = f"{r['target']}: {nuts:.2f}x NUTS ({'met' if nuts >= 1.0 else 'missed'})"
        if r["target"].startswith("Gaussian"):
            hmc = r["vs_hmc_ess_per_gradient"]
            text += f", {hmc:.2f}x HMC ({'met' if hmc >= 1.5 else 'missed'})"
        verdicts.append(text)
    lines += [
        (
            "Targets (min bulk ESS per gradient of the default magnetic row: ≥ 1.0× NUTS on "
            "every target, ≥ 1.5× HMC on the Gaussians): " + "; ".join(verdicts) + "."
        ),
        "",
        f"![magnetic HMC benchmark]({rel})",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
