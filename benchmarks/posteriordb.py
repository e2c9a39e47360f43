"""Real posteriors from posteriordb, directional posteriors and a resonance toy:
``MCMC(GeometricHMC(model))`` with its defaults against ``MCMC(NUTS(model))`` and
``MCMC(NUTS(model, dense_mass=True))``, side by side, with both chain methods and two seeds.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python -m benchmarks.posteriordb                  # full
    .venv/bin/python -m benchmarks.posteriordb --quick          # smoke run (results/quick/)
    .venv/bin/python -m benchmarks.posteriordb --names arK-arK  # some posteriors, merged in
    .venv/bin/python -m benchmarks.posteriordb --extra          # + BlackJAX NUTS, magnetic_hmc

Each posterior runs in a process of its own (one long process runs out of memory mappings for
compiled code), which merges its rows into ``posteriordb.json`` (the rows of the posteriors it
did not run are kept, so that a partial run is not lost); then ``posteriordb.png``. The posteriordb
posteriors, their NumPyro models and reference summaries (posteriordb's Stan reference draws;
exact moments for the toy) are in ``benchmarks/posteriordb_models.py`` and
``benchmarks/data/posteriordb/``; the directional ones (a sphere, an axis, a circle, a
rotation, with exact or quadrature references) in ``benchmarks/directional_models.py``.

Per posterior, seed (``SEEDS``) and chain method (``CHAIN_METHODS``), one *group* of runs:
``numpyro nuts`` (``NUTS(model)``: NumPyro's defaults, windowed adaptation, diagonal mass,
target acceptance 0.8), ``numpyro nuts dense`` (``NUTS(model, dense_mass=True)``) and
``liesample GeometricHMC`` (``liesample.numpyro_mcmc.GeometricHMC(model)``, its defaults),
each through ``numpyro.infer.MCMC`` with ``NUM_CHAINS`` chains, interleaved in one process:
the three warm-ups, then the three sampling phases, the order rotating from one group to the
next, so that the load of a shared machine falls on all. On a Euclidean posterior every run of
a group starts from the same points (uniform in ``(-2, 2)`` in NumPyro's unconstrained
coordinates, as ``init_to_uniform``; new points for each seed). On a directional posterior the
NUTS runs sample ``posterior.nuts_model`` (each unit vector a normalised Gaussian vector, as a
NumPyro user writes it) from those starts, and ``GeometricHMC`` samples ``posterior.model``
(the sphere, circle or rotation sites themselves) from its own default starts.

Seconds: each phase's wall time less the compilation JAX reports in it (``jax.monitoring``'s
compile events), and that compilation. Per run: the minimum over the reference's parameters
(constrained, as Stan reports them) of ArviZ's bulk and tail ESS, and the smaller of the two
(``ess_min``) per gradient of the sampling phase and per second of warm-up plus sampling,
compilation excluded and included; the largest rank-normalised split R-hat; the posterior sds
against the reference (off by more than ``SD_TOLERANCE`` is flagged); each mean's error
``z = (mean − reference mean) / √(MCSE² + reference MCSE²)`` (beyond ``Z_LIMIT`` is flagged);
divergences of the sampling phase; and whether a warning was raised: any warning during
``MCMC.warmup`` / ``MCMC.run`` (the kernel's own end-of-warm-up checks), or from the post-run
checks a careful user calls, ``liesample.interop.numpyro_checks.check_mcmc(mcmc)`` for
``GeometricHMC`` and the same checks (``numpyro_checks.check_draws``) on NUTS's latent sites
and fields, with the model's hierarchical scales, for NUTS. A run is *right* when every mean is
within ``Z_LIMIT`` and every sd within ``SD_TOLERANCE``; a wrong run is *warned* or *silent*.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import subprocess
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
from benchmarks import common
from benchmarks import directional_models as dm
from benchmarks import posteriordb_models as pdb
from liesample.interop.numpyro_checks import check_draws, check_mcmc
from liesample.numpyro_mcmc import GeometricHMC

SUITE = {
    "order": 45,
    "title": "posteriordb and directional posteriors: MCMC(GeometricHMC) vs MCMC(NUTS)",
}

SCHEMA = 2  # the layout of posteriordb.json's rows
NUM_CHAINS = 4
CHAIN_METHODS = ("sequential", "vectorized")
SEEDS = (0, 1)
ANGLES = (0.0, 0.25)  # magnetic_hmc's field angle (--extra): 0 (the default) and 0.25
Z_LIMIT = 4.0  # a mean further than this many MCSEs from the reference is flagged
SD_ERROR_AXIS_MAX = 10.0  # the figure's sd-error axis ends here (larger errors marked ▲)
SD_TOLERANCE = 0.10  # a posterior sd off the reference by more than this fraction is flagged
RHAT_LIMIT = 1.01  # NUTS is healthy only with R-hat at most this
GOAL = 1.0  # ESS/s (warm-up included) against the better NUTS, where NUTS is healthy
DIRECTIONAL_GOAL = 3.0  # the same on the directional posteriors
OURS = "liesample GeometricHMC"
MCMC_LABELS = ("numpyro nuts", "numpyro nuts dense", OURS)  # the interleaved MCMC rows
NUTS_LABELS = ("numpyro nuts", "numpyro nuts dense")
# The toy is cheap and its trap needs the full warm-up's mass windows: full length in either mode.
FULL_LENGTH_IN_QUICK = (pdb.RESONANCE,)
QUICK_POSTERIORS = ("eight_schools-eight_schools_noncentered", dm.VMF_SPHERE)
NAMES = (*pdb.NAMES, *dm.NAMES)
NOTES = (
    "Left out: `wells_data-wells_dist` and `radon_mn-radon_pooled` have no reference draws in "
    "posteriordb; `garch-garch11` and `sblrc-blr` stand in for them. The centred eight schools "
    "is scored against the non-centred program's reference draws (posteriordb's "
    "`reference_posterior_name`: the same law of `mu`, `tau`, `theta`). The resonance toy's "
    "reference is exact; the directional references are described in "
    "`benchmarks/directional_models.py` and checked by `tests/test_directional_models.py`. "
    "GARCH(1,1)'s `beta1` is bounded by `1 − alpha1`, a bound that depends on another "
    "parameter: `GeometricHMC` builds each Euclidean site's bijection from the support the "
    "model gives at every evaluation, as NumPyro's potential does. An sd ratio is flagged at "
    "|ratio − 1| > 10 % whatever its MCSE: with few draws a healthy run can be flagged by "
    "chance. BlackJAX NUTS and `magnetic_hmc` rows are not in the default run (their cost); "
    "`--extra` adds them, once per seed, on the flattened unconstrained log density."
)


def load(name):
    """A posteriordb, toy or directional posterior by name."""
    return dm.load(name) if name in dm.NAMES else pdb.load(name)


# --------------------------------------------------------------------------- set-up


class Setup:
    """A posterior's flattened unconstrained log density (of the NUTS model), starts and
    constraining map."""

    def __init__(self, posterior, key):
        self.posterior = posterior
        self.model = getattr(posterior, "nuts_model", None) or posterior.model
        self.directional = self.model is not posterior.model
        self.kwargs = posterior.model_kwargs()
        init, potential_fn, postprocess_fn, _ = initialize_model(
            key, self.model, model_kwargs=self.kwargs
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


class Caught:
    """The distinct warning messages raised while it is active, kept in ``messages``."""

    def __init__(self, messages):
        self.messages = messages

    def __enter__(self):
        self._context = warnings.catch_warnings(record=True)
        self._caught = self._context.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc):
        self._context.__exit__(*exc)
        for message in dict.fromkeys(str(w.message) for w in self._caught):
            if message not in self.messages:
                self.messages.append(message)


class MCMCRun:
    """One kernel through ``numpyro.infer.MCMC``: :meth:`warmup` and :meth:`sample` are
    called apart, so that the kernels' phases interleave."""

    FIELDS = ("num_steps", "accept_prob", "energy")

    def __init__(self, kernel, setup, key, num_warmup, num_draws, chain_method, init_params):
        self.setup, self.keys, self.init_params = setup, jax.random.split(key), init_params
        self.mcmc = MCMC(
            kernel,
            num_warmup=num_warmup,
            num_samples=num_draws,
            num_chains=NUM_CHAINS,
            chain_method=chain_method,
            progress_bar=False,
        )
        self.out = {"sampler_warnings": [], "check_warnings": []}

    def _phase(self, key, **options):
        """Run one phase; its seconds less compilation, and the compilation."""
        with CompileClock() as clock, Caught(self.out["sampler_warnings"]):
            start = time.perf_counter()
            getattr(self.mcmc, options.pop("method"))(
                key, extra_fields=self.FIELDS, **options, **self.setup.kwargs
            )
            jax.block_until_ready(self.mcmc.last_state)
            wall = time.perf_counter() - start
        return wall - clock.seconds, clock.seconds

    def warmup(self):
        seconds, compile_seconds = self._phase(
            self.keys[0], method="warmup", collect_warmup=True, init_params=self.init_params
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

    def check(self, scales):
        """The post-run checks (module docstring): ``check_mcmc`` for GeometricHMC, the same
        ``check_draws`` on the latent sites for another kernel."""
        with Caught(self.out["check_warnings"]):
            if isinstance(self.mcmc.sampler, GeometricHMC):
                check_mcmc(self.mcmc)
            else:
                samples = self.mcmc.get_samples(group_by_chain=True)
                latent = {k: np.asarray(samples[k]) for k in self.mcmc.last_state.z}
                extra = self.mcmc.get_extra_fields(group_by_chain=True)
                fields = {k: np.asarray(extra[k]) for k in ("diverging", "accept_prob", "energy")}
                check_draws(latent, fields, scales)
        self.out["warned"] = bool(self.out["sampler_warnings"] or self.out["check_warnings"])


def final_step_sizes(state):
    """Each chain's adapted step size (NumPyro's ``adapt_state.step_size``)."""
    adapt = getattr(state, "adapt_state", None)
    step = getattr(adapt, "step_size", None)
    if step is None:
        step = getattr(state, "step_size", np.nan)
    return np.atleast_1d(np.asarray(step, float)).reshape(-1)


def kernels(setup):
    """``label -> (kernel, init_params)`` of one group's three ``MCMC`` runs."""
    ours_init = None if setup.directional else setup.start_params
    return {
        "numpyro nuts": (NUTS(setup.model), setup.start_params),
        "numpyro nuts dense": (NUTS(setup.model, dense_mass=True), setup.start_params),
        OURS: (GeometricHMC(setup.posterior.model), ours_init),
    }


def run_group(setup, key, lengths, chain_method, rotation, log):
    """The three ``MCMC`` runs of one group, interleaved: the warm-ups, then the sampling
    phases, the order rotated by ``rotation``; then their checks. ``label -> result`` (or the
    error)."""
    order = MCMC_LABELS[rotation % 3 :] + MCMC_LABELS[: rotation % 3]
    runs, failed = {}, {}
    for j, (label, (kernel, init)) in enumerate(kernels(setup).items()):
        runs[label] = MCMCRun(
            kernel, setup, jax.random.fold_in(key, j), *lengths, chain_method, init
        )
    for phase in ("warmup", "sample"):
        for label in order:
            if label in failed:
                continue
            try:
                getattr(runs[label], phase)()
            except Exception as error:
                failed[label] = error
    scales = None
    if not setup.directional and OURS not in failed:
        scales = getattr(runs[OURS].mcmc.sampler, "hierarchical_scales", None)
    for label, run in runs.items():
        if label not in failed:
            run.check(scales)
    log(f"  {chain_method} group done: " + ", ".join(f"{k} failed" for k in failed))
    return {label: failed.get(label, runs[label].out) for label in MCMC_LABELS}


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
    """The ``--extra`` rows: ``label -> run(setup, key, num_warmup, num_draws)``."""
    out = {"blackjax nuts": run_blackjax_nuts}
    for angle in ANGLES:
        out[magnetic_label(angle)] = lambda s, k, w, n, a=angle: run_magnetic(s, k, w, n, a)
    return out


def magnetic_label(angle):
    return f"magnetic_hmc (angle {angle:g}{', default' if angle == 0 else ''})"


# --------------------------------------------------------------------------- summaries


def summarise(posterior, label, run):
    """One run's row (module docstring)."""
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
    off = np.abs(sd_ratio - 1.0) > SD_TOLERANCE
    worst, worst_sd = int(np.argmax(np.abs(z))), int(np.argmax(np.abs(sd_ratio - 1.0)))
    keys = posterior.keys
    ess_min = float(min(ess_bulk.min(), ess_tail.min()))
    seconds = run["warmup_seconds"] + run["seconds"]  # warm-up and sampling, compile excluded
    row = {
        "posterior": posterior.name,
        "sampler": label,
        **run,
        "ess_bulk_min": float(ess_bulk.min()),
        "ess_tail_min": float(ess_tail.min()),
        "ess_min": ess_min,
        "ess_per_gradient": ess_min / max(run["gradients"], 1),
        "ess_per_second": ess_min / max(seconds, 1e-9),
        "ess_per_second_with_compile": ess_min / max(seconds + run["compile_seconds"], 1e-9),
        "gradients_per_draw": run["gradients"] / (x.shape[0] * x.shape[1]),
        "rhat_max": float(np.nanmax(rhat)),
        "rhat_worst_parameter": keys[int(np.nanargmax(rhat))],
        "max_abs_z_mean": float(np.abs(z[worst])),
        "worst_parameter": keys[worst],
        "means_within_z_limit": bool(np.all(np.abs(z) <= Z_LIMIT)),
        "worst_sd_error": float(np.abs(sd_ratio[worst_sd] - 1.0)),
        "worst_sd_ratio": float(sd_ratio[worst_sd]),
        "worst_sd_parameter": keys[worst_sd],
        "worst_sd_ratio_mcse": float(mcse_sd[worst_sd] / posterior.sd[worst_sd]),
        "sd_off": {k: float(r) for k, r, o in zip(keys, sd_ratio, off) if o},
        "z_mean": dict(zip(keys, z.tolist())),
        "sd_ratio": dict(zip(keys, sd_ratio.tolist())),
    }
    row["right"] = row["means_within_z_limit"] and not row["sd_off"]
    row["verdict"] = verdict_of(row)
    return row


def verdict_of(row):
    """``right``, ``wrong, warned`` or ``wrong, silent``."""
    if row["right"]:
        return "right"
    if row.get("warned") is None:  # an --extra row: no post-run checks
        return "wrong, unchecked"
    return "wrong, warned" if row["warned"] else "wrong, silent"


def healthy(row):
    """No divergence, R-hat at most RHAT_LIMIT, right."""
    return row["divergences"] == 0 and row["rhat_max"] <= RHAT_LIMIT and row["right"]


def ratio(a, b):
    return a / b if b > 0 else float("inf")


def group_ratios(rows):
    """Per group ``(posterior, chain method, seed)``: our ESS/s (warm-up included; compile
    excluded and included) and ESS per gradient over the better healthy NUTS's, or ``None``
    when neither NUTS is healthy. ``[(posterior, method, seed, ratios or None, our row)]``."""
    groups = {}
    for r in rows:
        groups.setdefault((r["posterior"], r["chain_method"], r["seed"]), {})[r["sampler"]] = r
    out = []
    for (name, method, seed), by in groups.items():
        ours = by.get(OURS)
        if ours is None:
            continue
        either = [by[k] for k in NUTS_LABELS if k in by]
        if either:  # against the better NUTS, healthy or not (shown, not a goal)
            best_any = max(r["ess_per_second"] for r in either)
            ours["vs_better_nuts_any_per_second"] = ratio(ours["ess_per_second"], best_any)
        nuts = [r for r in either if healthy(r)]
        if not nuts:
            out.append((name, method, seed, None, ours))
            continue
        best = max(nuts, key=lambda r: r["ess_per_second"])
        best_c = max(nuts, key=lambda r: r["ess_per_second_with_compile"])
        best_g = max(nuts, key=lambda r: r["ess_per_gradient"])
        ratios = {
            "per_second": ratio(ours["ess_per_second"], best["ess_per_second"]),
            "per_second_with_compile": ratio(
                ours["ess_per_second_with_compile"], best_c["ess_per_second_with_compile"]
            ),
            "per_gradient": ratio(ours["ess_per_gradient"], best_g["ess_per_gradient"]),
            "time_per_gradient": ratio(seconds_per_gradient(ours), seconds_per_gradient(best)),
            "better_nuts": best["sampler"],
        }
        out.append((name, method, seed, ratios, ours))
    return out


def posterior_summary(data):
    """Per posterior: the medians of :func:`group_ratios` over its groups, how many groups had
    a healthy NUTS, our verdicts, the goal and whether it was met."""
    summary = {}
    for name, _, _, ratios, ours in group_ratios(data["results"]):
        s = summary.setdefault(name, {"groups": 0, "nuts_healthy": 0, "ratios": [], "ours": []})
        s["groups"] += 1
        s["ours"].append(ours["verdict"])
        s.setdefault("any", []).append(ours.get("vs_better_nuts_any_per_second", float("nan")))
        if ratios is not None:
            s["nuts_healthy"] += 1
            s["ratios"].append(ratios)
    for name, s in summary.items():
        s["directional"] = name in dm.NAMES
        s["any_median"] = float(np.median(s["any"]))
        s["goal"] = data["directional_goal"] if s["directional"] else data["goal"]
        for key in ("per_second", "per_second_with_compile", "per_gradient", "time_per_gradient"):
            values = [r[key] for r in s["ratios"]]
            s[key] = float(np.median(values)) if values else float("nan")
            s[key + "_range"] = (min(values), max(values)) if values else None
        misses = []
        if s["nuts_healthy"] and s["per_second"] < s["goal"]:
            misses.append(f"ESS/s {s['per_second']:.2f}× < {s['goal']:g}×")
        wrong = [v for v in s["ours"] if v != "right"]
        if s["nuts_healthy"] and wrong:
            misses.append(f"{len(wrong)} of {s['groups']} runs wrong")
        silent = s["ours"].count("wrong, silent")
        if silent:
            misses.append(f"{silent} wrong run(s) without a warning")
        s["misses"] = misses
    return summary


def log_row(log, row):
    log(
        f"  {row['chain_method']:<10} seed {row['seed']} {row['sampler']:<24} "
        f"ESS {row['ess_min']:7.0f} ESS/grad {row['ess_per_gradient']:.2e} "
        f"ESS/s {row['ess_per_second']:8.1f} (+compile {row['ess_per_second_with_compile']:7.1f})"
        f"  R-hat {row['rhat_max']:.3f}  sd {row['worst_sd_ratio']:.2f}x "
        f"({row['worst_sd_parameter']})  max|z| {row['max_abs_z_mean']:.1f} "
        f"({row['worst_parameter']})  div {row['divergences']}  "
        f"warned {row['warned']}  {row['verdict']}"
    )


# --------------------------------------------------------------------------- run


def lengths(name, quick, num_warmup, num_draws):
    """``(num_warmup, num_draws)`` per chain for the posterior ``name``."""
    if quick and name not in FULL_LENGTH_IN_QUICK:
        return (300, 300)
    return (num_warmup, num_draws)


def run_posterior(name, quick, extra, num_warmup, num_draws, log):
    """Every group of one posterior: ``(info, rows, failures)``."""
    start = time.perf_counter()
    posterior = load(name)
    pkey = jax.random.fold_in(jax.random.key(20261126), NAMES.index(name))
    length = lengths(name, quick, num_warmup, num_draws)
    rows, failures, dimension = [], [], None
    for s, seed in enumerate(SEEDS):
        setup = Setup(posterior, jax.random.fold_in(pkey, 1000 * seed))
        dimension = setup.dimension
        log(f"posterior: {name} (d = {dimension}), seed {seed}, {length[0]} + {length[1]}")
        outs = {}
        for m, method in enumerate(CHAIN_METHODS):
            key = jax.random.fold_in(pkey, 1000 * seed + 10 + m)
            rotation = NAMES.index(name) + 2 * s + m
            group = run_group(setup, key, length, method, rotation, log)
            outs.update({(label, method): out for label, out in group.items()})
        if extra:
            for j, (label, fn) in enumerate(extra_samplers().items()):
                try:
                    out = fn(setup, jax.random.fold_in(pkey, 1000 * seed + 20 + j), *length)
                    out.update(sampler_warnings=[], check_warnings=[], warned=None)
                except Exception as error:
                    out = error
                outs[(label, "vmap")] = out
        for (label, method), out in outs.items():
            if isinstance(out, Exception):
                failures.append(
                    {
                        "posterior": name,
                        "sampler": label,
                        "chain_method": method,
                        "seed": seed,
                        "error": repr(out),
                    }
                )
                log(f"  {method} seed {seed} {label}: FAILED {out!r}")
                continue
            row = summarise(posterior, label, {"chain_method": method, "seed": seed, **out})
            rows.append(row)
            log_row(log, row)
    info = {
        "reference": posterior.reference_info,
        "dimension": dimension,
        "num_warmup": length[0],
        "num_draws": length[1],
        "directional": name in dm.NAMES,
        "seconds": time.perf_counter() - start,
    }
    return info, rows, failures


def merge(path, names, mode, update):
    """Read ``path`` (if it holds this schema and mode), drop the rows of ``names``, apply
    ``update(data)`` and write it back, under a lock (two runs may merge into one file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    folder = os.open(path.parent, os.O_RDONLY)  # the lock: the folder (no lock file left)
    try:
        fcntl.flock(folder, fcntl.LOCK_EX)
        data = common.read_json(path) if path.exists() else {}
        if data.get("schema") != SCHEMA or data.get("mode") != mode:
            data = {"posteriors": {}, "results": [], "failures": []}
        for field in ("results", "failures"):
            data[field] = [r for r in data[field] if r["posterior"] not in names]
        data["posteriors"] = {k: v for k, v in data["posteriors"].items() if k not in names}
        update(data)
        common.write_json(path, data)
        return data
    finally:
        os.close(folder)


def run(out_dir: Path, quick: bool, log=print, names=None, extra=False,
        num_warmup=1000, num_draws=1000) -> None:  # fmt: skip
    """Every posterior of ``names`` (by default all, or ``QUICK_POSTERIORS``), each in a
    process of its own (:func:`run_in_process`): one process that builds a few hundred
    ``MCMC`` programs runs out of memory mappings for compiled code (LLVM's "Cannot allocate
    memory", then a crash)."""
    start = time.perf_counter()
    if names is None:
        names = QUICK_POSTERIORS if quick else NAMES
    options = ["--num-warmup", str(num_warmup), "--num-draws", str(num_draws)]
    options += ["--quick"] * quick + ["--extra"] * extra
    for name in names:
        command = [sys.executable, "-m", "benchmarks.posteriordb", "--one", name, *options]
        child = subprocess.Popen(
            [*command, "--out-dir", str(out_dir)],
            cwd=common.BENCH_DIR.parent,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for line in child.stdout:
            if "LLVM compilation error" not in line:
                log(line.rstrip())
        if child.wait() != 0:
            log(f"  {name}: the process failed (exit status {child.returncode})")
    path = out_dir / "posteriordb.json"
    if path.exists():
        plot(common.read_json(path), out_dir / "posteriordb.png")
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def run_in_process(out_dir: Path, quick: bool, log, name, extra, num_warmup, num_draws):
    """One posterior's groups, merged into ``out_dir/posteriordb.json``."""
    mode = "quick" if quick else "full"
    info, rows, failures = run_posterior(name, quick, extra, num_warmup, num_draws, log)

    def update(data):
        data.update(settings(mode))
        data["posteriors"][name] = info
        data["results"] += rows
        data["failures"] += failures
        data["total_seconds"] = sum(p["seconds"] for p in data["posteriors"].values())

    merge(out_dir / "posteriordb.json", [name], mode, update)


def settings(mode):
    return {
        "schema": SCHEMA,
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": mode,
        "num_chains": NUM_CHAINS,
        "chain_methods": CHAIN_METHODS,
        "seeds": SEEDS,
        "z_limit": Z_LIMIT,
        "sd_tolerance": SD_TOLERANCE,
        "rhat_limit": RHAT_LIMIT,
        "goal": GOAL,
        "directional_goal": DIRECTIONAL_GOAL,
    }


def short_name(posterior):
    """posteriordb's model name (after the data set's); a directional posterior's full name."""
    if posterior in dm.NAMES or "-" not in posterior:
        return posterior
    model = posterior.split("-", 1)[1]
    if sum(name.split("-", 1)[-1] == model for name in NAMES) > 1:  # sblrc-blr, sblri-blr
        return posterior
    return model


def seconds_per_gradient(row):
    """Seconds of warm-up and sampling (compile excluded) per gradient evaluation."""
    total = row["warmup_gradients"] + row["gradients"]
    return (row["warmup_seconds"] + row["seconds"]) / max(total, 1)


def plot(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = posterior_summary(data)
    names = list(summary)
    fig, axes = plt.subplots(1, 2, figsize=(15, 5))
    x = np.arange(len(names))
    for key, label, shift in (
        ("per_second", "ESS/s, warm-up included, compile excluded", -0.2),
        ("per_second_with_compile", "ESS/s, compile included", 0.0),
        ("per_gradient", "ESS per gradient", 0.2),
    ):
        axes[0].bar(x + shift, [summary[n][key] for n in names], 0.2, label=label)
    axes[0].axhline(1.0, color="k", lw=0.8, ls="--")
    axes[0].set_yscale("log")
    axes[0].set_title("GeometricHMC / better healthy NUTS (median over groups)")
    rows = data["results"]
    labels = list(dict.fromkeys(r["sampler"] for r in rows))
    width = 0.8 / max(len(labels), 1)
    for j, label in enumerate(labels):
        values = [
            max(
                [r["worst_sd_error"] for r in rows if r["posterior"] == n and r["sampler"] == label]
                or [0]
            )
            for n in names
        ]
        # an sd off by orders of magnitude (a stuck chain) would flatten every other bar
        clipped = [min(v, SD_ERROR_AXIS_MAX) for v in values]
        axes[1].bar(x + j * width - 0.4, clipped, width, label=label)
        for k, v in enumerate(values):
            if v > SD_ERROR_AXIS_MAX:
                axes[1].text(x[k] + j * width - 0.4, SD_ERROR_AXIS_MAX, "▲", ha="center",
                             va="bottom", fontsize=6)  # fmt: skip
    axes[1].axhline(data["sd_tolerance"], color="k", lw=0.8, ls="--")
    axes[1].set_yscale("log")
    axes[1].set_ylim(top=SD_ERROR_AXIS_MAX * 3)
    axes[1].set_title(f"max |sd / reference sd − 1| over runs (▲: above {SD_ERROR_AXIS_MAX:g})")
    for ax in axes:
        ax.set_xticks(x)
        ax.set_xticklabels([short_name(n) for n in names], rotation=35, ha="right", fontsize=7)
        ax.legend(fontsize=8)
    fig.suptitle(f"posteriordb and directional posteriors, {data['num_chains']} chains")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- report


def describe_lengths(data):
    """``"W transitions per chain and D draws"``, naming the posteriors with other lengths."""
    by_length = {}
    for name, info in data["posteriors"].items():
        by_length.setdefault((info["num_warmup"], info["num_draws"]), []).append(name)
    (common_length, _), *others = sorted(by_length.items(), key=lambda kv: -len(kv[1]))
    text = f"{common_length[0]} transitions per chain and then draws {common_length[1]}"
    for (warmup, draws), names in others:
        text += f" ({', '.join(map(short_name, names))}: {warmup} and {draws})"
    return text


def fmt_range(s, key):
    if s[key + "_range"] is None:
        return "–"
    lo, hi = s[key + "_range"]
    return f"{s[key]:.2f} ({lo:.2f}–{hi:.2f})"


def outcome(s):
    """The misses, or ``met``, or, without a healthy NUTS, that no ratio was asked for."""
    if s["misses"]:
        return "; ".join(s["misses"])
    return "met" if s["nuts_healthy"] else "no healthy NUTS (no ratio goal); no silent wrong run"


def summary_lines(data):
    summary = posterior_summary(data)
    lines = [
        "| posterior | d | groups with a healthy NUTS | GeometricHMC / better NUTS, ESS/s "
        "(warm-up incl., compile excl.): median (range) | same, compile incl. | ESS/grad "
        "| seconds per gradient (ours / that NUTS's) | ESS/s vs the better NUTS, healthy or "
        "not | our runs: right / wrong warned / wrong silent | goal | misses |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, s in summary.items():
        counts = " / ".join(
            str(s["ours"].count(v)) for v in ("right", "wrong, warned", "wrong, silent")
        )
        lines.append(
            f"| {short_name(name)} | {data['posteriors'][name]['dimension']} | "
            f"{s['nuts_healthy']} of {s['groups']} | {fmt_range(s, 'per_second')} | "
            f"{fmt_range(s, 'per_second_with_compile')} | {fmt_range(s, 'per_gradient')} | "
            f"{fmt_range(s, 'time_per_gradient')} | {s['any_median']:.2f} | {counts} | "
            f"{s['goal']:g}× | "
            f"{outcome(s)} |"
        )
    lines.append("")
    for directional in (False, True):
        part = [s for s in summary.values() if s["directional"] == directional and s["ratios"]]
        if not part:
            continue
        med = {k: float(np.median([s[k] for s in part]))
               for k in ("per_second", "per_second_with_compile", "per_gradient")}  # fmt: skip
        lines.append(
            f"Median over the {len(part)} {'directional' if directional else 'other'} "
            "posteriors with a healthy NUTS of GeometricHMC's ratio to the better NUTS: "
            f"ESS/s {med['per_second']:.2f}× (compile excluded), "
            f"{med['per_second_with_compile']:.2f}× (compile included), ESS per gradient "
            f"{med['per_gradient']:.2f}×."
        )
        lines.append("")
    missed = [f"{short_name(n)} ({'; '.join(s['misses'])})" for n, s in summary.items()
              if s["misses"]]  # fmt: skip
    lines.append(
        "Target misses (goal: where a NUTS is healthy, every run right and the median ESS/s "
        f"ratio ≥ {data['goal']:g}×, ≥ {data['directional_goal']:g}× on directional "
        "posteriors; everywhere, no wrong run without a warning): "
        + ("; ".join(missed) if missed else "none")
        + "."
    )
    lines.append("")
    return lines


WARNED = {True: "yes", False: "no", None: "–"}  # None: an --extra row, not checked


def table_row(r):
    return (
        f"| {short_name(r['posterior'])} | {r['chain_method']} | {r['seed']} | {r['sampler']} | "
        f"{r['ess_bulk_min']:.0f} / {r['ess_tail_min']:.0f} | {r['ess_per_gradient']:.2e} | "
        f"{common.format_g(r['ess_per_second'])} | "
        f"{common.format_g(r['ess_per_second_with_compile'])} | "
        f"{common.format_g(1e6 * seconds_per_gradient(r))} | "
        f"{r['worst_sd_error']:.3f} ({r['worst_sd_parameter']}) | "
        f"{r['max_abs_z_mean']:.1f} ({r['worst_parameter']}) | {r['rhat_max']:.3f} | "
        f"{r['divergences']} | {WARNED[r['warned']]} | {r['verdict']} |"
    )


def findings(data):
    """Paragraphs after the table: wrong runs' warnings and failed runs."""
    lines = []
    warned = [r for r in data["results"] if r["warned"] and not r["right"]]
    if warned:
        lines.append(
            "What warned on the wrong runs (first message, shortened): "
            + "; ".join(
                f"{short_name(r['posterior'])} / {r['chain_method']} {r['seed']} / "
                f"{r['sampler']}: "
                + (r["sampler_warnings"] + r["check_warnings"])[0][:160].replace("|", "/")
                for r in warned
            )
            + "."
        )
        lines.append("")
    right_warned = sum(1 for r in data["results"] if r["warned"] and r["right"])
    lines.append(f"Right runs that warned all the same: {right_warned} of "
                 f"{sum(r['right'] for r in data['results'])}.")  # fmt: skip
    lines.append("")
    if data["failures"]:
        lines.append(
            "Failed runs: "
            + "; ".join(
                f"{f['posterior']} / {f['chain_method']} {f['seed']} / {f['sampler']}: "
                f"{f['error'][:200]}"
                for f in data["failures"]
            )
            + "."
        )
        lines.append("")
    return lines


def intro(data, out_dir):
    machine = data["machine"]
    return (
        f"From `benchmarks/posteriordb.py` ({machine['date_utc']}, {data['mode']} mode, "
        f"{data['total_seconds']:.0f} s summed over the posteriors (several posteriors may "
        f"run side by side) on {machine['usable_cpus']} shared CPU cores "
        f"({machine.get('cpu_model', '')}), JAX {machine.get('jax', '')}, liesample "
        f"{machine.get('git_commit', '')}: wall times are rough and other jobs shared the "
        "cores, so only ratios within a group, whose runs are interleaved, mean much). "
        "Posteriors, data and reference draws from "
        "[posteriordb](https://github.com/stan-dev/posteriordb) (BSD 3-Clause; "
        "`benchmarks/data/posteriordb/`), each model written again in NumPyro "
        "(`benchmarks/posteriordb_models.py`, checked against the Stan program by "
        "`tests/test_posteriordb_models.py`); the resonance toy (x ~ normal(0, 0.003) beside "
        "O(1) parameters) has exact moments; the directional posteriors "
        f"(`benchmarks/directional_models.py`: {', '.join(dm.NAMES)}) exact or quadrature "
        f"references. Per posterior, seed ({', '.join(map(str, data['seeds']))}) and "
        f"chain method ({', '.join(data['chain_methods'])}): `MCMC(NUTS(model))`, "
        "`MCMC(NUTS(model, dense_mass=True))` and `MCMC(GeometricHMC(model))`, their defaults, "
        f"{data['num_chains']} chains, interleaved (the three warm-ups, then the three "
        "sampling phases), from the same uniform(−2, 2) unconstrained starts (on a "
        "directional posterior NUTS samples unit vectors as normalised Gaussian vectors, and "
        "GeometricHMC the sphere, circle or rotation sites from its own starts); warm-up "
        f"{describe_lengths(data)}. ESS: the minimum over the reference's (constrained) "
        "parameters of ArviZ's bulk / tail ESS; ESS/grad: the smaller of the two per gradient "
        "of the sampling phase; ESS/s: per second of warm-up and sampling, compilation "
        "(JAX's compile events) excluded, and included (`+c`; liesample's default persistent "
        "compilation cache was on, so a program compiled before, by an earlier seed or run, "
        "is loaded from it); µs/grad: seconds of warm-up and sampling per gradient; sd err: "
        "the largest |sd / reference sd − 1|; |z|: the largest |error of a mean| / "
        "√(MCSE² + reference MCSE²); "
        "div.: divergences while sampling; warned: a warning during `MCMC.warmup`/`run`, or "
        "from the post-run checks (`liesample.interop.numpyro_checks.check_mcmc(mcmc)` for "
        "GeometricHMC, the same `check_draws` on NUTS's latent sites and fields, with the "
        "model's hierarchical scales). Verdict: right when every |z| ≤ "
        f"{data['z_limit']:g} and every sd within {data['sd_tolerance']:.0%}; a NUTS run is "
        f"healthy when right, with no divergence and R-hat ≤ {data['rhat_limit']}."
    )


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "posteriordb.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    title = "## posteriordb and directional posteriors: MCMC(GeometricHMC) against MCMC(NUTS)"
    if data.get("schema") != SCHEMA:  # written by an earlier version of this suite
        return (
            f"{title}\n\n`{path.name}` was written by an earlier version of "
            "`benchmarks/posteriordb.py`; rerun it (`python -m benchmarks.posteriordb`) to fill "
            "this section.\n"
        )
    rel = common.relative_link(out_dir / "posteriordb.png", md_dir)
    lines = [title, "", intro(data, out_dir), "", *summary_lines(data)]
    lines += [
        "| posterior | chains | seed | sampler | ESS bulk / tail | ESS/grad | ESS/s | ESS/s +c "
        "| µs/grad | sd err | max abs z | R-hat | div. | warned | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *(table_row(r) for r in data["results"]),
        "",
    ]
    lines += findings(data)
    lines += [NOTES, "", f"![posteriordb benchmark]({rel})", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="benchmark suite posteriordb")
    parser.add_argument("--quick", action="store_true", help="short smoke run")
    parser.add_argument("--names", nargs="+", choices=NAMES, help="these posteriors only")
    parser.add_argument("--extra", action="store_true", help="add BlackJAX NUTS, magnetic_hmc")
    parser.add_argument("--num-warmup", type=int, default=1000)
    parser.add_argument("--num-draws", type=int, default=1000)
    parser.add_argument("--one", choices=NAMES, help=argparse.SUPPRESS)  # in this process
    parser.add_argument("--out-dir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    out_dir = args.out_dir or common.BENCH_DIR / "results" / ("quick" if args.quick else "")
    log = lambda m: print(m, flush=True)
    lengths = (args.num_warmup, args.num_draws)
    if args.one:
        run_in_process(out_dir, args.quick, log, args.one, args.extra, *lengths)
        return 0
    run(out_dir, args.quick, log, args.names, args.extra, *lengths)
    print(report(out_dir, out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
