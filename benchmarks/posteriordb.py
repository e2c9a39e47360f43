"""Real posteriors from posteriordb (and a resonance toy): ``MCMC(GeometricHMC(model))`` with its
defaults against ``MCMC(NUTS(model))``, side by side, and in the full run BlackJAX NUTS and
``magnetic_hmc`` beside them.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python -m benchmarks.posteriordb            # full
    .venv/bin/python -m benchmarks.posteriordb --quick    # smoke run (benchmarks/results/quick/)

Writes ``posteriordb.json`` and ``posteriordb.png``. The posteriors, their NumPyro models and
the reference summaries (from posteriordb's Stan reference draws; exact moments for the toy) are
in ``benchmarks/posteriordb_models.py`` and ``benchmarks/data/posteriordb/``.

Every sampler starts its ``NUM_CHAINS`` chains from the same points (uniform in ``(-2, 2)`` in
NumPyro's unconstrained coordinates, as ``init_to_uniform``), warms up for ``num_warmup``
transitions per chain and then draws ``num_draws`` per chain:

- ``numpyro nuts``: ``numpyro.infer.MCMC(NUTS(model))``, NumPyro's defaults (windowed
  adaptation, diagonal mass, target acceptance 0.8);
- ``liesample GeometricHMC``: ``numpyro.infer.MCMC(liesample.numpyro_mcmc.GeometricHMC(model))``
  with the kernel's defaults (every site Euclidean here, in NumPyro's unconstrained
  coordinates);
- full run only: ``blackjax nuts`` (``blackjax.window_adaptation(blackjax.nuts, …)`` on every
  chain, vmapped, on the flattened unconstrained log density) and ``magnetic_hmc``
  (``liesample.magnetic_window_adaptation`` on the chains together, then
  ``liesample.jittered_magnetic_hmc``; one row per angle in ``ANGLES``).

The two ``MCMC`` rows run with ``chain_method=CHAIN_METHOD`` (``"sequential"``: what
``MCMC``'s default ``"parallel"`` falls back to on one device), interleaved in one process:
both warm-ups, then both sampling phases, the order alternating from one posterior to the
next, so that the load of a shared machine falls on both. Their seconds are the sampling
phase's wall time less the compilation JAX reports in that phase (``jax.monitoring``'s compile
events).

Per posterior and sampler: the minimum over the reference's parameters (constrained, as Stan
reports them) of ArviZ's bulk and tail ESS, per gradient evaluation of the sampling phase
(``num_steps``) and per second of it; the largest rank-normalised split R-hat; every posterior
sd against the reference (a ratio off 1 by more than ``SD_TOLERANCE`` is warned about and
flagged, beside ArviZ's MCSE of the sd); and each mean's error,
``z = (mean − reference mean) / √(MCSE² + reference MCSE²)``.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import arviz_stats as azs
import blackjax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer import MCMC, NUTS
from numpyro.infer.util import initialize_model

import liesample
from benchmarks import common, suites
from benchmarks import posteriordb_models as pdb
from liesample.numpyro_mcmc import GeometricHMC

SUITE = {"order": 45, "title": "posteriordb: MCMC(GeometricHMC) vs MCMC(NUTS), and magnetic HMC"}

NUM_CHAINS = 4
CHAIN_METHOD = "sequential"
ANGLES = (0.0, 0.25)  # magnetic_hmc's field angle: 0 (the default) and 0.25
Z_LIMIT = 4.0  # a mean further than this many MCSEs from the reference is flagged
SD_TOLERANCE = 0.10  # a posterior sd off the reference by more than this fraction is warned
RHAT_LIMIT = 1.01  # a larger R-hat is named in the verdict
GOAL = 1.0  # ESS per gradient against NumPyro NUTS, where NUTS is healthy
PAIR = ("numpyro nuts", "liesample GeometricHMC")  # the interleaved MCMC rows
NUTS_LABELS = ("numpyro nuts", "blackjax nuts")
# The toy is cheap and its trap needs the full warm-up's mass windows: full length in either mode.
FULL_LENGTH_IN_QUICK = (pdb.RESONANCE,)
QUICK_POSTERIORS = (
    pdb.RESONANCE,
    "diamonds-diamonds",
    "eight_schools-eight_schools_noncentered",
)
NOTES = (
    "Left out: `wells_data-wells_dist` and `radon_mn-radon_pooled` have no reference draws in "
    "posteriordb; `garch-garch11` and `sblrc-blr` stand in for them. The centred eight schools "
    "is scored against the non-centred program's reference draws (posteriordb's "
    "`reference_posterior_name`: the same law of `mu`, `tau`, `theta`). The resonance toy's "
    "reference is exact. GARCH(1,1)'s `beta1` is bounded by `1 − alpha1`, a bound that "
    "depends on another parameter: `GeometricHMC` builds each Euclidean site's bijection from "
    "the support the model gives at every evaluation, as NumPyro's potential does "
    "(`tests/test_numpyro_dependent_support.py`). An sd ratio is flagged at "
    "|ratio − 1| > 10 % whatever its MCSE: with few draws a healthy run can be flagged by "
    "chance, and the MCSE column says how likely that is."
)


# --------------------------------------------------------------------------- set-up


class Setup:
    """A posterior's flattened unconstrained log density, starts and constraining map."""

    def __init__(self, posterior, key):
        self.posterior = posterior
        self.kwargs = posterior.model_kwargs()
        init, potential_fn, postprocess_fn, _ = initialize_model(
            key, posterior.model, model_kwargs=self.kwargs
        )
        flat, self.unravel = ravel_pytree(init.z)
        self.dimension = flat.shape[0]
        self.potential_fn, self.postprocess_fn = potential_fn, postprocess_fn
        starts = jax.random.uniform(
            jax.random.fold_in(key, 1), (NUM_CHAINS, self.dimension), flat.dtype, -2.0, 2.0
        )
        self.starts = starts
        self.start_params = jax.vmap(self.unravel)(starts)

    def logdensity(self, x):
        return -self.potential_fn(self.unravel(x))

    def constrained(self, flat_draws):
        """Reference coordinates ``(chains, draws, K)`` of flat unconstrained draws."""
        fn = liesample.jit(jax.vmap(jax.vmap(lambda x: self.postprocess_fn(self.unravel(x)))))
        return pdb.flatten(fn(flat_draws), self.posterior.keys, batch_ndim=2)


def compiled(fn, *args):
    """``fn`` compiled for ``args`` (with liesample's safe compiler options), and the seconds
    the compilation took."""
    start = time.perf_counter()
    executable = liesample.jit(fn).lower(*args).compile()
    return executable, time.perf_counter() - start


# --------------------------------------------------------------------------- samplers


class CompileClock:
    """Seconds of compilation that JAX reports (tracing, lowering, XLA) while it is active."""

    EVENTS = (
        "/jax/core/compile/jaxpr_trace_duration",
        "/jax/core/compile/jaxpr_to_mlir_module_duration",
        "/jax/core/compile/backend_compile_duration",
    )

    def __init__(self):
        self.seconds = 0.0

    def _listen(self, event, duration, **_):
        if event in self.EVENTS:
            self.seconds += duration

    def __enter__(self):
        jax.monitoring.register_event_duration_secs_listener(self._listen)
        return self

    def __exit__(self, *exc):
        jax.monitoring.unregister_event_duration_listener(self._listen)


class MCMCRun:
    """One kernel through ``numpyro.infer.MCMC``: :meth:`warmup` and :meth:`sample` are
    called apart, so that two kernels' phases interleave."""

    def __init__(self, kernel, setup, key, num_warmup, num_draws):
        self.setup, self.keys = setup, jax.random.split(key)
        self.mcmc = MCMC(
            kernel,
            num_warmup=num_warmup,
            num_samples=num_draws,
            num_chains=NUM_CHAINS,
            chain_method=CHAIN_METHOD,
            progress_bar=False,
        )
        self.out = {}

    def _phase(self, key, **options):
        """Run one phase; its seconds less compilation, the compilation, and the warnings the
        kernel raised (kept in ``out["sampler_warnings"]``)."""
        with CompileClock() as clock, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            start = time.perf_counter()
            getattr(self.mcmc, options.pop("method"))(
                key, extra_fields=("num_steps",), **options, **self.setup.kwargs
            )
            jax.block_until_ready(self.mcmc.last_state)
            wall = time.perf_counter() - start
        seen = self.out.setdefault("sampler_warnings", [])
        seen += [m for m in dict.fromkeys(str(w.message) for w in caught) if m not in seen]
        return wall - clock.seconds, clock.seconds

    def warmup(self):
        seconds, compile_seconds = self._phase(
            self.keys[0],
            method="warmup",
            collect_warmup=True,
            init_params=self.setup.start_params,
        )
        self.out.update(
            warmup_seconds=seconds,
            compile_seconds=compile_seconds,
            warmup_gradients=int(np.sum(self.mcmc.get_extra_fields()["num_steps"])),
        )

    def sample(self):
        seconds, compile_seconds = self._phase(self.keys[1], method="run")
        fields = self.mcmc.get_extra_fields(group_by_chain=True)
        values = self.mcmc.get_samples(group_by_chain=True)
        steps = final_step_sizes(self.mcmc.last_state)
        self.out.update(
            draws=pdb.flatten(values, self.setup.posterior.keys, batch_ndim=2),
            gradients=int(np.sum(fields["num_steps"])),
            seconds=seconds,
            compile_seconds=self.out["compile_seconds"] + compile_seconds,
            divergences=int(np.sum(fields["diverging"])),
            step_size=float(np.median(steps)),
            step_sizes=steps.tolist(),
        )


def final_step_sizes(state):
    """Each chain's adapted step size (NumPyro's ``adapt_state.step_size``)."""
    adapt = getattr(state, "adapt_state", None)
    step = getattr(adapt, "step_size", None)
    if step is None:
        step = getattr(state, "step_size", np.nan)
    return np.atleast_1d(np.asarray(step, float)).reshape(-1)


def run_pair(setup, key, num_warmup, num_draws, first, log):
    """NumPyro NUTS and GeometricHMC through ``MCMC``, interleaved: both warm-ups, then both
    sampling phases, ``PAIR[first]`` first each time. ``label -> result`` (or the error)."""
    kernels = {
        "numpyro nuts": lambda: NUTS(setup.posterior.model),
        "liesample GeometricHMC": lambda: GeometricHMC(setup.posterior.model),
    }
    order = PAIR if first == 0 else PAIR[::-1]
    runs, failed = {}, {}
    for j, label in enumerate(PAIR):
        key_j = jax.random.fold_in(key, j)
        runs[label] = MCMCRun(kernels[label](), setup, key_j, num_warmup, num_draws)
    for phase in ("warmup", "sample"):
        for label in order:
            if label in failed:
                continue
            start = time.perf_counter()
            try:
                getattr(runs[label], phase)()
            except Exception as error:
                failed[label] = error
            log(f"  {label}: {phase} {time.perf_counter() - start:.0f} s (compilation included)")
    return {label: failed.get(label, runs[label].out) for label in PAIR}


def run_flat_chains(sampler_for, params, states, setup, key, num_draws):
    """``num_draws`` transitions of ``sampler_for(params)`` from each chain's state; ``params``
    and ``states`` have a leading chain axis."""

    def chain(params, state, key):
        sampler = sampler_for(params)

        def one(state, k):
            state, info = sampler.step(k, state)
            return state, (state.position, info.num_integration_steps, info.is_divergent)

        return jax.lax.scan(one, state, jax.random.split(key, num_draws))[1]

    keys = jax.random.split(key, NUM_CHAINS)
    executable, compile_seconds = compiled(jax.vmap(chain), params, states, keys)
    (positions, steps, divergent), seconds = common.timed(executable, params, states, keys)
    return positions, int(np.sum(steps)), int(np.sum(divergent)), seconds, compile_seconds


def run_blackjax_nuts(setup, key, num_warmup, num_draws):
    key_warmup, key_draw = jax.random.split(key)
    warmup = blackjax.window_adaptation(blackjax.nuts, setup.logdensity)

    def adapt(key, start):
        (state, params), info = warmup.run(key, start, num_steps=num_warmup)
        return state, params, info.info.num_integration_steps

    keys = jax.random.split(key_warmup, NUM_CHAINS)
    executable, warm_compile = compiled(jax.vmap(adapt), keys, setup.starts)
    (states, params, warm_steps), warm_seconds = common.timed(executable, keys, setup.starts)
    positions, gradients, divergences, seconds, draw_compile = run_flat_chains(
        lambda p: blackjax.nuts(setup.logdensity, **p), params, states, setup, key_draw, num_draws
    )
    return {
        "draws": setup.constrained(positions),
        "gradients": gradients,
        "warmup_gradients": int(np.sum(warm_steps)),
        "seconds": seconds,
        "warmup_seconds": warm_seconds,
        "compile_seconds": warm_compile + draw_compile,
        "divergences": divergences,
        "step_size": float(np.median(np.asarray(params["step_size"]))),
    }


def run_magnetic(setup, key, num_warmup, num_draws, angle):
    key_warmup, key_draw = jax.random.split(key)
    warmup = liesample.magnetic_window_adaptation(setup.logdensity, angle=angle)
    start = time.perf_counter()
    (states, params), info = warmup.run(key_warmup, setup.starts, num_steps=num_warmup)
    jax.block_until_ready(states)
    warm_seconds = time.perf_counter() - start  # compilation included
    shared = dict(params)
    chain_params = {"dummy": jnp.zeros(NUM_CHAINS)}  # one set of parameters for all chains
    positions, gradients, divergences, seconds, draw_compile = run_flat_chains(
        lambda _: liesample.jittered_magnetic_hmc(setup.logdensity, **shared),
        chain_params,
        states,
        setup,
        key_draw,
        num_draws,
    )
    return {
        "draws": setup.constrained(positions),
        "gradients": gradients,
        "warmup_gradients": int(np.sum(info.info.num_integration_steps)),
        "seconds": seconds,
        "warmup_seconds": warm_seconds,
        "compile_seconds": draw_compile,
        "divergences": divergences,
        "step_size": float(params["step_size"]),
        "num_integration_steps": int(params["num_integration_steps"]),
        "trajectory_length": float(info.trajectory_length[-1]),
    }


def extra_samplers():
    """The full run's other rows: ``label -> run(setup, key, num_warmup, num_draws)``."""
    out = {"blackjax nuts": run_blackjax_nuts}
    for angle in ANGLES:
        out[magnetic_label(angle)] = lambda s, k, w, n, a=angle: run_magnetic(s, k, w, n, a)
    return out


def magnetic_label(angle):
    return f"magnetic_hmc (angle {angle:g}{', default' if angle == 0 else ''})"


# --------------------------------------------------------------------------- summaries


def summarise(posterior, label, run):
    x = run.pop("draws")  # (chains, draws, K)
    ess_bulk = np.asarray(azs.ess(x, method="bulk", sample_dims=(0, 1)))
    ess_tail = np.asarray(azs.ess(x, method="tail", sample_dims=(0, 1), prob=(0.05, 0.95)))
    ess_mean = np.asarray(azs.ess(x, method="mean", sample_dims=(0, 1)))
    mcse_sd = np.asarray(azs.mcse(x, method="sd", sample_dims=(0, 1)))
    rhat = np.asarray(azs.rhat(x, sample_dims=(0, 1)))
    flat = x.reshape(-1, x.shape[-1])
    mean, sd = flat.mean(0), flat.std(0, ddof=1)
    mcse = sd / np.sqrt(np.maximum(ess_mean, 1.0))
    z = (mean - posterior.mean) / np.sqrt(mcse**2 + posterior.mcse_mean**2)
    sd_ratio = sd / posterior.sd
    chain_sd_ratio = x.std(axis=1, ddof=1) / posterior.sd  # (chains, K)
    centred = x - x.mean(axis=1, keepdims=True)
    lag1 = np.mean(
        np.sum(centred[:, 1:] * centred[:, :-1], axis=1) / np.sum(centred**2, axis=1), axis=0
    )  # each parameter's lag-1 autocorrelation, averaged over chains
    off = np.abs(sd_ratio - 1.0) > SD_TOLERANCE
    worst, worst_sd = int(np.argmax(np.abs(z))), int(np.argmax(np.abs(sd_ratio - 1.0)))
    gradients = max(run["gradients"], 1)
    keys = posterior.keys
    return {
        "posterior": posterior.name,
        "sampler": label,
        **run,
        "ess_bulk_min": float(ess_bulk.min()),
        "ess_tail_min": float(ess_tail.min()),
        "ess_bulk_per_gradient": float(ess_bulk.min()) / gradients,
        "ess_tail_per_gradient": float(ess_tail.min()) / gradients,
        "ess_bulk_per_second": float(ess_bulk.min()) / max(run["seconds"], 1e-9),
        "gradients_per_draw": run["gradients"] / (x.shape[0] * x.shape[1]),
        "rhat_max": float(np.nanmax(rhat)),
        "rhat_worst_parameter": keys[int(np.nanargmax(rhat))],
        "max_abs_mean_error_sd": float(np.max(np.abs((mean - posterior.mean) / posterior.sd))),
        "max_abs_z_mean": float(np.abs(z[worst])),
        "worst_parameter": keys[worst],
        "means_within_z_limit": bool(np.all(np.abs(z) <= Z_LIMIT)),
        "worst_sd_ratio": float(sd_ratio[worst_sd]),
        "worst_sd_parameter": keys[worst_sd],
        "worst_sd_ratio_mcse": float(mcse_sd[worst_sd] / posterior.sd[worst_sd]),
        "worst_sd_chain_ratios": chain_sd_ratio[:, worst_sd].tolist(),
        "lag1_min": float(lag1.min()),
        "lag1_min_parameter": keys[int(np.argmin(lag1))],
        "sd_off": {k: float(r) for k, r, o in zip(keys, sd_ratio, off) if o},
        "sd_ratio": dict(zip(keys, sd_ratio.tolist())),
        "sd_ratio_mcse": dict(zip(keys, (mcse_sd / posterior.sd).tolist())),
        "z_mean": dict(zip(keys, z.tolist())),
        "rhat": dict(zip(keys, rhat.tolist())),
        "ess_bulk": dict(zip(keys, ess_bulk.tolist())),
    }


def warn_sd(row):
    """Warn when a posterior sd is off the reference by more than SD_TOLERANCE."""
    if not row["sd_off"]:
        return
    named = ", ".join(
        f"{k} {r:.2f}× (MCSE {row['sd_ratio_mcse'][k]:.2f})" for k, r in row["sd_off"].items()
    )
    message = (
        f"posteriordb {row['posterior']} / {row['sampler']}: posterior sd off the reference by "
        f"more than {SD_TOLERANCE:.0%}: {named}"
    )
    warnings.warn(message, stacklevel=2)


def healthy(row):
    """No divergence, R-hat at most RHAT_LIMIT, every mean within Z_LIMIT MCSE and every sd
    within SD_TOLERANCE of the reference."""
    return (
        row["divergences"] == 0
        and row["rhat_max"] <= RHAT_LIMIT
        and row["means_within_z_limit"]
        and not row["sd_off"]
    )


def add_ratios(rows):
    """ESS per gradient and per second against each NUTS row of the posterior."""
    nuts = {r["sampler"]: r for r in rows if r["sampler"] in NUTS_LABELS}
    for row in rows:
        for label, ref in nuts.items():
            key = label.split()[0]
            row[f"vs_{key}_nuts_ess_per_gradient"] = ratio(
                row["ess_bulk_per_gradient"], ref["ess_bulk_per_gradient"]
            )
            row[f"vs_{key}_nuts_ess_per_second"] = ratio(
                row["ess_bulk_per_second"], ref["ess_bulk_per_second"]
            )
        row["numpyro_nuts_healthy"] = "numpyro nuts" in nuts and healthy(nuts["numpyro nuts"])


def ratio(a, b):
    return a / b if b > 0 else float("inf")


def log_row(log, row):
    log(
        f"  {row['sampler']:<36} ESS/grad {row['ess_bulk_per_gradient']:.2e} "
        f"(x{row.get('vs_numpyro_nuts_ess_per_gradient', float('nan')):.2f} NumPyro NUTS)  "
        f"ESS/s {row['ess_bulk_per_second']:8.1f}  R-hat {row['rhat_max']:.3f}  "
        f"sd {row['worst_sd_ratio']:.2f}x ({row['worst_sd_parameter']})  "
        f"lag1 {row['lag1_min']:.2f} ({row['lag1_min_parameter']})  "
        f"max|z| {row['max_abs_z_mean']:.1f} ({row['worst_parameter']})  "
        f"div {row['divergences']}  eps {step_sizes(row)}  {row['seconds']:.1f} s"
    )


# --------------------------------------------------------------------------- run


def lengths(name, quick):
    """``(num_warmup, num_draws)`` per chain for the posterior ``name``."""
    return (300, 300) if quick and name not in FULL_LENGTH_IN_QUICK else (1000, 1000)


def run(out_dir: Path, quick: bool, log=print, names=None) -> None:
    start = time.perf_counter()
    if names is None:
        names = QUICK_POSTERIORS if quick else pdb.NAMES
    key = jax.random.key(20261126)
    results, failures, posteriors = [], [], {}
    for index, name in enumerate(names):
        posterior = pdb.load(name)
        pkey = jax.random.fold_in(key, index)
        setup = Setup(posterior, pkey)
        num_warmup, num_draws = lengths(name, quick)
        log(f"posterior: {name} (d = {setup.dimension}, {num_warmup} + {num_draws} per chain)")
        posteriors[name] = {
            "reference": posterior.reference_info,
            "dimension": setup.dimension,
            "num_warmup": num_warmup,
            "num_draws": num_draws,
        }
        outs = run_pair(setup, jax.random.fold_in(pkey, 10), num_warmup, num_draws, index % 2, log)
        if not quick:
            for j, (label, fn) in enumerate(extra_samplers().items()):
                try:
                    outs[label] = fn(setup, jax.random.fold_in(pkey, 20 + j), num_warmup, num_draws)
                except Exception as error:
                    outs[label] = error
        rows = []
        for label, out in outs.items():
            if isinstance(out, Exception):
                failures.append({"posterior": name, "sampler": label, "error": repr(out)})
                log(f"  {label}: FAILED {out!r}")
            else:
                rows.append(summarise(posterior, label, out))
        add_ratios(rows)
        for row in rows:
            log_row(log, row)
            warn_sd(row)
        results += rows
    data = {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": "quick" if quick else "full",
        "num_chains": NUM_CHAINS,
        "chain_method": CHAIN_METHOD,
        "angles": ANGLES,
        "z_limit": Z_LIMIT,
        "sd_tolerance": SD_TOLERANCE,
        "rhat_limit": RHAT_LIMIT,
        "goal": GOAL,
        "posteriors": posteriors,
        "results": results,
        "failures": failures,
        "total_seconds": time.perf_counter() - start,
    }
    path = common.write_json(out_dir / "posteriordb.json", data)
    plot(data, out_dir / "posteriordb.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def short_name(posterior):
    return posterior.split("-", 1)[1]


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = data["results"]
    names = list(dict.fromkeys(r["posterior"] for r in rows))
    labels = list(dict.fromkeys(r["sampler"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(15, 5))
    width = 0.8 / max(len(labels), 1)
    panels = (
        (axes[0], lambda r: r["ess_bulk_per_gradient"], "min bulk ESS per gradient (sampling)"),
        (axes[1], lambda r: abs(r["worst_sd_ratio"] - 1.0), "max |sd / reference sd − 1|"),
    )
    axes[1].axhline(data["sd_tolerance"], color="k", lw=0.8, ls="--")
    for ax, value, title in panels:
        for j, label in enumerate(labels):
            values = [
                next((value(r) for r in rows if r["posterior"] == n and r["sampler"] == label), 0)
                for n in names
            ]
            ax.bar(np.arange(len(names)) + j * width, values, width, label=label)
        ax.set_yscale("log")
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2)
        ax.set_xticklabels([short_name(n) for n in names], rotation=20, ha="right")
        ax.set_title(title)
        ax.legend(fontsize=8)
    fig.suptitle(f"posteriordb, {data['num_chains']} chains, {describe_lengths(data)}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- report


def trajectory(row):
    """``L (T)`` of a magnetic row: the adapted maximum of the jittered lengths and ChEES's
    trajectory length; blank for the others."""
    if "trajectory_length" not in row:
        return ""
    return f"{row['num_integration_steps']} ({row['trajectory_length']:.2g})"


def step_sizes(row):
    """The median adapted step size, and the range over chains when they differ by > 2×."""
    steps = row.get("step_sizes") or [row["step_size"]]
    text = common.format_g(row["step_size"])
    if max(steps) > 2 * min(steps):
        text += f" ({common.format_g(min(steps))}–{common.format_g(max(steps))})"
    return text


def sd_cell(row):
    flag = f" ⚠ {len(row['sd_off'])} off" if row["sd_off"] else ""
    chains = row["worst_sd_chain_ratios"]
    return (
        f"{row['worst_sd_ratio']:.2f} ± {row['worst_sd_ratio_mcse']:.2f} "
        f"({row['worst_sd_parameter']}; chains {min(chains):.2f}–{max(chains):.2f}){flag}"
    )


def table_row(r):
    flag = "" if r["means_within_z_limit"] else " ⚠"
    return (
        f"| {short_name(r['posterior'])} | {r['sampler']} | {step_sizes(r)} | {trajectory(r)} | "
        f"{r['gradients_per_draw']:.1f} | {r['ess_bulk_per_gradient']:.2e} | "
        f"{r.get('vs_numpyro_nuts_ess_per_gradient', float('nan')):.2f} | "
        f"{common.format_g(r['ess_bulk_per_second'])} | "
        f"{r.get('vs_numpyro_nuts_ess_per_second', float('nan')):.2f} | "
        f"{r['rhat_max']:.3f} ({r['rhat_worst_parameter']}) | {sd_cell(r)} | "
        f"{r['lag1_min']:.2f} ({r['lag1_min_parameter']}) | "
        f"{r['max_abs_z_mean']:.1f} ({r['worst_parameter']}){flag} | "
        f"{r['divergences']} | {r['warmup_gradients']} |"
    )


def verdict(name, rows, data):
    """One posterior's verdict on the non-NUTS rows against NumPyro NUTS."""
    parts = []
    for label, r in rows.items():
        if label in NUTS_LABELS:
            continue
        vs = r.get("vs_numpyro_nuts_ess_per_gradient", float("nan"))
        goal = "met" if vs >= data["goal"] else "missed"
        if not r["numpyro_nuts_healthy"]:
            goal = "NUTS unhealthy"
        checks = []
        if r["sd_off"]:
            checks.append("sd " + ", ".join(f"{k} {v:.2f}×" for k, v in r["sd_off"].items()))
        if not r["means_within_z_limit"]:
            checks.append(f"mean {r['worst_parameter']} at {r['max_abs_z_mean']:.1f} MCSE")
        if r["rhat_max"] > data["rhat_limit"]:
            checks.append(f"R-hat {r['rhat_max']:.3f}")
        parts.append(f"{label} {vs:.2f}× ({goal}; {'; '.join(checks) or 'checks ok'})")
    return f"{short_name(name)}: " + ", ".join(parts)


def describe_lengths(data):
    """``"W transitions per chain and draws D"``, naming the posteriors with other lengths."""
    by_length = {}
    for name, info in data["posteriors"].items():
        by_length.setdefault((info["num_warmup"], info["num_draws"]), []).append(name)
    (common_length, _), *others = sorted(by_length.items(), key=lambda kv: -len(kv[1]))
    text = f"{common_length[0]} transitions per chain and draws {common_length[1]}"
    for (warmup, draws), names in others:
        text += f" ({', '.join(map(short_name, names))}: {warmup} and {draws})"
    return text


def findings(data):
    """Paragraphs after the table: the sds off the reference, the samplers' own warnings and
    the failed runs."""
    lines = []
    off = [r for r in data["results"] if r["sd_off"]]
    if off:
        lines.append(
            "Posterior sds off the reference by more than "
            f"{data['sd_tolerance']:.0%} (ratio ± MCSE): "
            + "; ".join(
                f"{short_name(r['posterior'])} / {r['sampler']}: "
                + ", ".join(
                    f"{k} {v:.2f} ± {r['sd_ratio_mcse'][k]:.2f}" for k, v in r["sd_off"].items()
                )
                for r in off
            )
            + "."
        )
        lines.append("")
    warned = [r for r in data["results"] if r.get("sampler_warnings")]
    lines.append(
        "Warnings the samplers raised through `MCMC`: "
        + (
            "; ".join(
                f"{short_name(r['posterior'])} / {r['sampler']}: "
                + " | ".join(m[:300] for m in r["sampler_warnings"])
                for r in warned
            )
            if warned
            else "none"
        )
        + "."
    )
    lines.append("")
    if data["failures"]:
        lines.append(
            "Failed runs: "
            + "; ".join(
                f"{f['posterior']} / {f['sampler']}: {f['error']}" for f in data["failures"]
            )
            + "."
        )
        lines.append("")
    return lines


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "posteriordb.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    if "sd_tolerance" not in data:  # written by the earlier version of this suite
        return (
            "## posteriordb: MCMC(GeometricHMC) against MCMC(NUTS) on real posteriors\n\n"
            f"`{path.name}` was written by an earlier version of `benchmarks/posteriordb.py`; "
            "rerun it (`python -m benchmarks.posteriordb`) to fill this section.\n"
        )
    rel = common.relative_link(out_dir / "posteriordb.png", md_dir)
    machine = data["machine"]
    lines = [
        "## posteriordb: MCMC(GeometricHMC) against MCMC(NUTS) on real posteriors",
        "",
        (
            f"From `benchmarks/posteriordb.py` ({machine['date_utc']}, {data['mode']} mode, "
            f"{data['total_seconds']:.0f} s on {machine['usable_cpus']} shared CPU cores "
            f"({machine.get('cpu_model', '')}), JAX {machine.get('jax', '')}, liesample "
            f"{machine.get('git_commit', '')}: wall times are rough and other jobs shared the "
            "cores; ESS per gradient does not depend on the machine). Posteriors, data and "
            "reference draws from [posteriordb](https://github.com/stan-dev/posteriordb) (BSD "
            "3-Clause; `benchmarks/data/posteriordb/`), each model written again in NumPyro "
            "(`benchmarks/posteriordb_models.py`, checked against the Stan program by "
            "`tests/test_posteriordb_models.py`); the resonance toy (x ~ normal(0, 0.003) "
            "beside O(1) parameters) has exact moments. Every sampler starts "
            f"{data['num_chains']} chains from the same uniform(−2, 2) unconstrained points, "
            f"warms up for {describe_lengths(data)}. `numpyro nuts` is `MCMC(NUTS(model))` and "
            "`liesample GeometricHMC` is `MCMC(GeometricHMC(model))`, both with their "
            f"defaults and `chain_method={data['chain_method']!r}`, interleaved (both "
            "warm-ups, then both sampling phases); BlackJAX NUTS and `magnetic_hmc` (full mode "
            "only) run after them on the flattened unconstrained log density. ε: the median "
            "adapted step size over chains (their range when it spans more than 2×); ESS: the "
            "minimum over the reference's (constrained) parameters of ArviZ's bulk ESS, per "
            "gradient and per second of the sampling phase (compilation excluded); `sd ratio`: "
            "the posterior sd over the reference's for the parameter furthest from 1, ± ArviZ's "
            f"MCSE of the sd, flagged ⚠ (and warned) when off by more than "
            f"{data['sd_tolerance']:.0%}, with the range of that ratio over single chains; "
            "`lag-1`: the most negative lag-1 autocorrelation of a parameter (averaged over "
            "chains; near −1 when a fixed integration time sits at a half-period); `|z|`: the "
            "largest |error of a mean| / √(MCSE² + reference MCSE²), flagged above "
            f"{data['z_limit']:g}."
        ),
        "",
        (
            "| posterior | sampler | ε | L (T) | grads/draw | ESS/grad | vs NumPyro NUTS "
            "| ESS/s | ESS/s vs NumPyro NUTS | R-hat | sd ratio | lag-1 | max abs z | div. "
            "| warm-up grads |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *(table_row(r) for r in data["results"]),
        "",
    ]
    verdicts = [
        verdict(name, {r["sampler"]: r for r in data["results"] if r["posterior"] == name}, data)
        for name in dict.fromkeys(r["posterior"] for r in data["results"])
    ]
    lines += [
        (
            f"Target: ≥ {data['goal']:g}× NumPyro NUTS's ESS per gradient wherever NUTS is "
            f"healthy (no divergence, R-hat ≤ {data['rhat_limit']}, every mean within "
            f"{data['z_limit']:g} MCSE and every sd within {data['sd_tolerance']:.0%}), with "
            "every sd within that tolerance. " + "; ".join(verdicts) + "."
        ),
        "",
    ]
    lines += findings(data)
    lines += [NOTES, "", f"![posteriordb benchmark]({rel})", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
