"""Magnetic HMC against BlackJAX HMC, NUTS and MALA on Euclidean targets.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/euclidean.py            # full, ~8 min on 2 cores
    .venv/bin/python benchmarks/euclidean.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``euclidean.json`` and ``euclidean.png``. Every sampler gets the same tuning effort:
``blackjax.window_adaptation`` (diagonal mass matrix, target acceptance 0.8, the same number of
warm-up steps, one chain), then ``NUM_CHAINS`` chains start from the adapted state.

- ``magnetic_hmc`` (``liesample``), the field ``default_magnetic_field(M⁻¹, angle / ε)`` built
  from the adapted mass matrix and step size, ``L = NUM_STEPS`` leapfrog steps;
- ``hmc`` (BlackJAX, the same ``L``);
- ``nuts`` (BlackJAX);
- ``mala``: ``blackjax.hmc`` with one leapfrog step, which *is* preconditioned MALA;
  ``blackjax.mala`` takes no mass matrix, so ``window_adaptation`` cannot drive it.

Per target and sampler: ESS (bulk and tail, ArviZ, the minimum over coordinates of ``x`` and of
``x²``) per gradient evaluation and per second of sampling (compilation excluded), and the
bias of the means and variances against exact moments (``z`` = error / MCSE). The logistic
regression has no exact law: its reference moments come from a long NUTS run, labelled so.

A second part sweeps the field strength, as the angle ``strength · ε`` by which the field turns
the whitened velocity per leapfrog step (ESS per gradient against the angle; ``0`` is plain HMC
through the same kernel), on every target: that is the measurement behind the tuning rule
in :func:`liesample.samplers.magnetic.default_magnetic_field`. The "tuned" magnetic row of the
main table uses the best angle of that sweep (extra tuning effort, stated as such).
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
from liesample.samplers.magnetic import default_magnetic_field
from liesample.targets import correlated_gaussian

SUITE = {"order": 40, "title": "magnetic HMC vs BlackJAX HMC, NUTS, MALA (Euclidean targets)"}

NUM_CHAINS = 4
NUM_STEPS = 10  # leapfrog steps of HMC and magnetic HMC
# The field's strength as the angle (rad) it turns the whitened velocity per leapfrog step:
# strength = ANGLE / step_size (the tuning rule of default_magnetic_field).
DEFAULT_ANGLE = 0.25
ANGLES = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0)


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


def adapt(algorithm, target, key, num_warmup, **extra):
    warmup = blackjax.window_adaptation(algorithm, target.logdensity_fn, **extra)
    (state, parameters), _ = warmup.run(key, target.start, num_steps=num_warmup)
    return state, parameters


def run_chains(sampler, state, key, num_draws):
    """``(draws (chains, draws, d), gradient evaluations, wall seconds, divergences)``."""

    def chain(key):
        def one(state, k):
            state, info = sampler.step(k, state)
            return state, (state.position, info.num_integration_steps, info.is_divergent)

        return jax.lax.scan(one, state, jax.random.split(key, num_draws))[1]

    run = liesample.jit(jax.vmap(chain))
    keys = jax.random.split(key, NUM_CHAINS)
    compiled = run.lower(keys).compile()
    (draws, steps, divergent), seconds = common.timed(compiled, keys)
    return np.asarray(draws), int(np.sum(steps)), seconds, int(np.sum(divergent))


PEERS = {
    "blackjax hmc": (blackjax.hmc, {"num_integration_steps": NUM_STEPS}),
    "blackjax nuts": (blackjax.nuts, {}),
    "mala (hmc, 1 step)": (blackjax.hmc, {"num_integration_steps": 1}),
}


def measure_peer(target, label, key, num_warmup, num_draws):
    algorithm, extra = PEERS[label]
    key_warmup, key_run = jax.random.split(key)
    state, parameters = adapt(algorithm, target, key_warmup, num_warmup, **extra)
    sampler = algorithm(target.logdensity_fn, **parameters)
    draws, gradients, seconds, divergences = run_chains(sampler, state, key_run, num_draws)
    return summarise(target, label, draws, gradients, seconds, divergences, parameters)


def summarise(target, label, draws, gradients, seconds, divergences, parameters):
    x = draws
    ess = {}
    for method in ("bulk", "tail"):
        options = {"prob": (0.05, 0.95)} if method == "tail" else {}  # Vehtari et al. 2021
        e1 = np.asarray(azs.ess(x, method=method, sample_dims=(0, 1), **options))
        e2 = np.asarray(azs.ess(x**2, method=method, sample_dims=(0, 1), **options))
        ess[method] = float(min(e1.min(), e2.min()))
    mean = x.mean(axis=(0, 1))
    ess_mean = np.asarray(azs.ess(x, method="mean", sample_dims=(0, 1)))
    flat = x.reshape(-1, x.shape[-1])
    mcse = flat.std(0) / np.sqrt(ess_mean)
    z_mean = (mean - target.mean) / mcse
    rel_var_error = (flat.var(0) - target.variance) / target.variance
    return {
        "target": target.name,
        "sampler": label,
        "step_size": float(parameters["step_size"]),
        "gradients": gradients,
        "seconds": seconds,
        "divergences": divergences,
        "ess_bulk_min": ess["bulk"],
        "ess_tail_min": ess["tail"],
        "ess_bulk_per_gradient": ess["bulk"] / gradients,
        "ess_tail_per_gradient": ess["tail"] / gradients,
        "ess_bulk_per_second": ess["bulk"] / seconds,
        "max_abs_z_mean": float(np.max(np.abs(z_mean))),
        "max_abs_rel_var_error": float(np.max(np.abs(rel_var_error))),
        "reference": "exact" if target.exact else "long NUTS run",
    }


def reference_moments(target, key, num_warmup, num_draws):
    """Means and variances of the logistic regression from a long NUTS run (no exact law)."""
    state, parameters = adapt(blackjax.nuts, target, key, num_warmup)
    sampler = blackjax.nuts(target.logdensity_fn, **parameters)
    draws, *_ = run_chains(sampler, state, jax.random.fold_in(key, 1), num_draws)
    flat = draws.reshape(-1, draws.shape[-1])
    ess = float(np.min(np.asarray(azs.ess(draws, method="bulk", sample_dims=(0, 1)))))
    return flat.mean(0), flat.var(0), ess


def magnetic(target, key, num_warmup, num_draws, log):
    """The strength sweep and the two magnetic rows of the main table.

    One window adaptation of ``liesample.magnetic_hmc`` (provisional field 0: the warm-up is
    HMC's), then the field is built from the adapted ``M⁻¹``. The sweep passes the field as a
    traced argument (one compilation for all angles). The main
    rows use the top-level API (flows precomputed) with fresh keys: the default strength, and
    the sweep's best strength re-run on new keys (so the "tuned" row is not a max of noise).
    """
    key_warmup, key_sweep, key_default, key_tuned = jax.random.split(key, 4)
    zero = np.zeros((target.dimension, target.dimension))
    state, parameters = adapt(
        liesample.magnetic_hmc,
        target,
        key_warmup,
        num_warmup,
        num_integration_steps=NUM_STEPS,
        magnetic_field=zero,
    )
    step_size, imm = parameters["step_size"], np.asarray(parameters["inverse_mass_matrix"])
    start = liesample.magnetic_hmc.init(state.position, target.logdensity_fn)

    def chain(field, key):
        # The top-level API inside jit: the flows e^{±εGM⁻¹} are computed once per call from the
        # traced field, not once per transition as the BlackJAX-style kernel must.
        sampler = liesample.magnetic_hmc(target.logdensity_fn, step_size, imm, NUM_STEPS, field)

        def one(state, k):
            state, info = sampler.step(k, state)
            return state, (state.position, info.num_integration_steps, info.is_divergent)

        return jax.lax.scan(one, start, jax.random.split(key, num_draws))[1]

    keys = jax.random.split(key_sweep, NUM_CHAINS)
    compiled = liesample.jit(jax.vmap(chain, in_axes=(None, 0))).lower(zero, keys).compile()
    rows = []
    for angle in ANGLES:
        field = default_magnetic_field(imm, angle / step_size)
        (draws, steps, divergent), seconds = common.timed(compiled, field, keys)
        row = summarise(
            target,
            f"angle {angle:g}",
            np.asarray(draws),
            int(np.sum(steps)),
            seconds,
            int(np.sum(divergent)),
            parameters,
        )
        row["angle"] = angle
        rows.append(row)
        log(
            f"  sweep angle {angle:<5g} ESS/grad bulk {row['ess_bulk_per_gradient']:.2e} "
            f"tail {row['ess_tail_per_gradient']:.2e}"
        )
    best = max(rows, key=lambda r: r["ess_bulk_per_gradient"])["angle"]
    main = []
    for label, angle, k in (
        (f"magnetic_hmc (angle {DEFAULT_ANGLE:g})", DEFAULT_ANGLE, key_default),
        (f"magnetic_hmc (tuned angle {best:g})", best, key_tuned),
    ):
        sampler = liesample.magnetic_hmc(
            target.logdensity_fn,
            step_size,
            imm,
            NUM_STEPS,
            default_magnetic_field(imm, angle / step_size),
        )
        draws, gradients, seconds, divergences = run_chains(sampler, start, k, num_draws)
        row = summarise(target, label, draws, gradients, seconds, divergences, parameters)
        row["angle"] = angle
        main.append(row)
    return rows, main


def log_row(log, row):
    log(
        f"  {row['sampler']:<34} ESS/grad bulk {row['ess_bulk_per_gradient']:.2e} tail "
        f"{row['ess_tail_per_gradient']:.2e}  ESS/s {row['ess_bulk_per_second']:8.1f}  "
        f"max|z mean| {row['max_abs_z_mean']:.1f}  max rel var err "
        f"{row['max_abs_rel_var_error']:.2f}  div {row['divergences']}"
    )


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    num_warmup = 300 if quick else 1000
    num_draws = 300 if quick else 2000
    key = jax.random.key(20240611)
    results, sweeps = [], {}
    for index, target in enumerate(targets(quick)):
        tkey = jax.random.fold_in(key, index)
        log(f"target: {target.name}")
        if not target.exact:
            mean, var, ess = reference_moments(
                target, jax.random.fold_in(tkey, 99), num_warmup, 5 * num_draws
            )
            target.mean, target.variance = mean, var
            log(f"  reference: long NUTS run, min bulk ESS {ess:.0f}")
        sweeps[target.name], rows = magnetic(
            target, jax.random.fold_in(tkey, 1), num_warmup, num_draws, log
        )
        for label in PEERS:
            rows.append(
                measure_peer(target, label, jax.random.fold_in(tkey, 2), num_warmup, num_draws)
            )
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
        "default_angle": DEFAULT_ANGLE,
        "results": results,
        "sweeps": sweeps,
        "total_seconds": time.perf_counter() - start,
    }
    path = common.write_json(out_dir / "euclidean.json", data)
    plot(data, out_dir / "euclidean.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def short(label):
    """Legend name: the magnetic rows by role (default or tuned angle), the peers by name."""
    if label.startswith("magnetic_hmc"):
        return "magnetic_hmc, tuned angle" if "tuned" in label else "magnetic_hmc, default angle"
    return label.split(" (")[0]


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["target"] for r in data["results"]))
    samplers = list(dict.fromkeys(short(r["sampler"]) for r in data["results"]))
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.8))
    width = 0.8 / len(samplers)
    for j, row_label in enumerate(samplers):
        values = []
        for name in names:
            row = next(
                r
                for r in data["results"]
                if r["target"] == name and short(r["sampler"]) == row_label
            )
            values.append(row["ess_bulk_per_gradient"])
        axes[0].bar(np.arange(len(names)) + j * width, values, width, label=row_label)
    axes[0].set_yscale("log")
    axes[0].set_xticks(np.arange(len(names)) + 0.4 - width / 2)
    axes[0].set_xticklabels([n.split(",")[0].split(" (")[0] for n in names], rotation=15)
    axes[0].set_ylabel("min bulk ESS per gradient")
    axes[0].set_title("Equal tuning (window adaptation)")
    axes[0].legend(fontsize=8)
    for name, rows in data["sweeps"].items():
        axes[1].plot(
            [r["angle"] for r in rows],
            [r["ess_bulk_per_gradient"] / max(rows[0]["ess_bulk_per_gradient"], 1e-300) for r in rows],
            "o-",
            label=name.split(",")[0],
        )  # fmt: skip
    axes[1].axhline(1.0, color="k", lw=0.8)
    axes[1].axhline(1.5, color="k", lw=0.8, ls="--")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("field: rotation angle per leapfrog step (rad)")
    axes[1].set_ylabel("ESS/grad relative to angle 0 (HMC)")
    axes[1].set_title(f"magnetic_hmc, L = {data['num_integration_steps']}")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "euclidean.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    plot_path = out_dir / "euclidean.png"
    try:
        rel = plot_path.relative_to(md_dir)
    except ValueError:
        rel = plot_path
    lines = [
        "## Magnetic HMC vs BlackJAX HMC, NUTS and MALA",
        "",
        (
            f"From `benchmarks/euclidean.py` ({data['machine']['date_utc']}, {data['mode']} mode, "
            f"{data['total_seconds']:.0f} s on {data['machine']['usable_cpus']} shared CPU cores: "
            "wall times are rough, ESS per gradient does not depend on the machine). Every "
            f"sampler: `blackjax.window_adaptation` ({data['num_warmup']} steps, diagonal mass), "
            f"then {data['num_chains']} chains x {data['num_draws']} draws; HMC and magnetic HMC "
            f"use L = {data['num_integration_steps']}; MALA is `blackjax.hmc` with one leapfrog "
            "step. ESS is the minimum over coordinates of `x` and `x²` (ArviZ bulk/tail); "
            "`|z| mean` is the largest |error of a mean| / MCSE; `var err` the largest relative "
            "error of a variance."
        ),
        "",
        (
            "| target | sampler | ε | ESS/grad bulk | ESS/grad tail | ESS/s bulk "
            "| max abs z (mean) | max var err | div. | vs HMC (ESS/grad) |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    hmc = {r["target"]: r for r in data["results"] if r["sampler"] == "blackjax hmc"}
    for r in data["results"]:
        ratio = r["ess_bulk_per_gradient"] / hmc[r["target"]]["ess_bulk_per_gradient"]
        ref = "" if r["reference"] == "exact" else " †"
        lines.append(
            f"| {r['target']}{ref} | {r['sampler']} | {r['step_size']:.3g} | "
            f"{r['ess_bulk_per_gradient']:.2e} | {r['ess_tail_per_gradient']:.2e} | "
            f"{r['ess_bulk_per_second']:.3g} | {r['max_abs_z_mean']:.1f} | "
            f"{r['max_abs_rel_var_error']:.2f} | {r['divergences']} | {ratio:.2f} |"
        )
    lines += [
        "",
        "† reference moments from a long NUTS run (no exact law), not exact.",
        "",
        (
            "Field sweep: ESS per gradient relative to angle 0 (plain HMC "
            "through the same kernel); the field is `default_magnetic_field(M⁻¹, angle / ε)`, one shared adaptation per target:"
        ),
        "",
        "| target \\ angle per step | " + " | ".join(f"{a:g}" for a in ANGLES) + " |",
        "|---|" + "---|" * len(ANGLES),
    ]
    for name, rows in data["sweeps"].items():
        base = rows[0]["ess_bulk_per_gradient"]
        lines.append(
            f"| {name} | " + " | ".join(f"{r['ess_bulk_per_gradient'] / base:.2f}" for r in rows) + " |"
        )  # fmt: skip
    verdicts = []
    for name in hmc:
        if not name.startswith("Gaussian"):
            continue
        tuned = next(r for r in data["results"] if r["target"] == name and "tuned" in r["sampler"])
        ratio = tuned["ess_bulk_per_gradient"] / hmc[name]["ess_bulk_per_gradient"]
        sweep_rows = data["sweeps"][name]
        own = tuned["ess_bulk_per_gradient"] / sweep_rows[0]["ess_bulk_per_gradient"]
        verdicts.append(
            f"{name}: tuned magnetic HMC / BlackJAX HMC = {ratio:.2f} "
            f"({'meets' if ratio >= 1.5 else 'misses'} the 1.5x target; against the same kernel "
            f"without field, angle 0 of the sweep: {own:.2f})"
        )
    lines += ["", "Target (ESS/gradient ≥ 1.5× BlackJAX HMC on the Gaussians): " + "; ".join(verdicts) + ".", ""]  # fmt: skip
    # Run-to-run noise: where the default and the tuned angle coincide, the two magnetic rows
    # are the same sampler on different keys.
    noise = []
    for name in hmc:
        rows = [r for r in data["results"] if r["target"] == name and "angle" in r]
        if len(rows) == 2 and rows[0]["angle"] == rows[1]["angle"]:
            a, b = (r["ess_bulk_per_gradient"] for r in rows)
            noise.append(f"{name}: {max(a, b) / min(a, b):.2f}x")
    if noise:
        lines += [
            (
                "Noise: the same magnetic sampler (same angle) on two sets of keys differs in "
                "ESS per gradient by " + "; ".join(noise) + ". Ratios to HMC closer to 1 than "
                "that are not resolved; on the banana and the funnel the chains visit the stiff "
                "tails rarely and their ESS is unreliable (note the divergences and variance "
                "errors: every sampler is biased on the funnel)."
            ),
            "",
        ]
    lines += [f"![magnetic HMC benchmark]({rel})", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
