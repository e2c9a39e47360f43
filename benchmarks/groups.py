"""Lie groups and spheres side by side: liesample's geometric HMC against mici's constrained
HMC, BlackJAX NUTS on an unconstrained parametrisation, and exact i.i.d. draws, in one run.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/groups.py            # ~8 min, 2 cores
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/groups.py --quick    # ~2 min (compiling)

Targets (exact references from :mod:`liesample.targets.groups`):

- **matrix Fisher on SO(3)**, ``p(R) ∝ exp(tr(FᵀR))`` (Haar), ``F = Q diag(4, 2, 0.5) Pᵀ``
  with two fixed rotations ``Q, P``; statistics: the 9 entries of ``R`` (exact ``E[R]`` from
  the 1-D Bessel integral of ``MatrixFisherLaw.mean``);
- **vMF product on (S²)⁸**: 8 independent von Mises–Fisher directions with ``κ`` from 0.5
  to 50 and fixed mean directions ``μ_i``; statistics: the 24 coordinates (exact
  ``E[x_i] = A₃(κ_i) μ_i``).

Samplers, each given the same warm-up budget of ``warmup`` transitions per chain:

- **liesample geometric HMC** (``liesample.geometric_hmc`` tuned by
  ``liesample.window_adaptation`` on one chain: dual averaging to acceptance 0.8, one mass per
  copy of the group or sphere, integration time π/2), and the **Metropolis-adjusted geometric
  Langevin** (``liesample.geometric_langevin(adjusted=True)``, friction 1), run as vmapped
  chains compiled with ``liesample.jit``;
- **mici** (0.4) constrained HMC on the embedded manifold: ``DenseConstrainedEuclideanMetricSystem``
  with the constraint ``RᵀR = I`` in ``R⁹`` (resp. ``|x_i|² = 1`` in ``R²⁴``; the Hausdorff
  measure is Haar, resp. uniform), ``ConstrainedLeapfrogIntegrator`` (quasi-Newton projection),
  ``DynamicMultinomialHMC`` (mici's NUTS) with its own dual-averaging step-size adaptation;
  NumPy value, gradient and constraint Jacobian; chains one after the other on one core
  (mici runs in Python: it cannot vmap);
- **BlackJAX NUTS** on ``y ∈ R⁴`` with ``R = R(y/|y|)`` (unit quaternions, Haar on SO(3) is
  the uniform law on S³ modulo ±) and on ``y_i ∈ R³`` with ``x_i = y_i/|y_i|`` (Stan's
  ``unit_vector``), density ``π(x(y)) e^{−|y|²/2}`` (in polar coordinates ``y/|y|`` has
  density ``∝ π``), ``blackjax.window_adaptation`` on one chain, vmapped chains;
- **exact i.i.d.**: ``liesample.interop.numpyro_distributions.MatrixFisher.sample`` (the
  quaternion's Bingham law, angular-central-Gaussian rejection) and
  ``liesample.targets.spins.von_mises_fisher`` (closed form), the ceiling; ESS = draws.

The JAX chains start from dispersed (Haar/uniform) points, run ``burn_in`` tuned transitions
after the one-chain adaptation (both reported as warm-up time), then ``draws`` kept draws;
mici's chains start from the same points and adapt for ``warmup`` iterations each.

**Measured.** ESS = min over the statistics of the ArviZ bulk ESS (``expectation_table``);
ESS/s divides it by the wall time of the kept draws only (compilation, adaptation and burn-in
are reported separately; the compiled JAX loops and the i.i.d. sampler are timed again in
interleaved rounds and keep their fastest call, mici's chains are timed once, per
iteration); ESS per gradient divides it by the gradient evaluations of the kept draws
(leapfrog steps). ESS per CPU-second divides by this process's CPU time instead: steadier
than the wall time on a shared machine, where other processes take turns on the cores.
**Matched accuracy**: every estimate is compared with the exact ``E[·]`` in MCSE units; a
sampler counts (is a peer or a candidate in the ratios) only where ``max |z| ≤ 5`` and max
R-hat ≤ 1.05. Ratios are to the best non-i.i.d. peer (mici or NUTS).
Target (issue 13): liesample ≥ 3× the best peer in ESS/s.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import common, suites  # noqa: I001  (common switches float64 on first)

import jax
import jax.numpy as jnp
import numpy as np

import liesample
from liesample import spaces
from liesample.analysis.diagnostics import expectation_table
from liesample.interop.numpyro_distributions import MatrixFisher
from liesample.targets import groups as exact_groups
from liesample.targets.groups import quaternion_to_rotation
from liesample.targets.spins import von_mises_fisher

SUITE = {"order": 15, "title": "Lie groups and spheres: geometric HMC vs mici, NUTS, i.i.d."}
NAME = "groups"
Z_LIMIT = 5.0
RHAT_LIMIT = 1.05
SEED = 20261122

FULL = {
    "warmup": 300,
    "burn_in": 100,
    "chains": 8,
    "draws": 5000,  # long enough that the timed call is not lost in the noise of a shared CPU
    "mici_chains": 2,
    "mici_draws": 300,
    # The matrix Fisher rejection sampler proposes from Haar (acceptance ≈ 3%): fewer draws.
    "iid_draws": {"matrix_fisher": 20_000, "vmf_product": 200_000},
    "langevin": True,
    "timing_rounds": 4,  # interleaved re-timings of every compiled sampler (_retime)
}
QUICK = {
    **FULL,
    "warmup": 60,
    "burn_in": 20,
    "chains": 4,
    "draws": 200,
    "mici_chains": 1,
    "mici_draws": 50,
    "iid_draws": {"matrix_fisher": 2_000, "vmf_product": 20_000},
    "langevin": False,
    "timing_rounds": 1,
}

SAMPLERS = {
    "iid": "exact i.i.d.",
    "geometric_hmc": "liesample geometric HMC",
    "geometric_langevin": "liesample adjusted geometric Langevin",
    "mici": "mici constrained HMC (dynamic multinomial)",
    "nuts": "BlackJAX NUTS (unconstrained)",
}
COLORS = {
    "iid": "0.55",
    "geometric_hmc": "C0",
    "geometric_langevin": "C9",
    "mici": "C2",
    "nuts": "C3",
}
IID_NOTES: dict[str, str] = {}
OURS = ("geometric_hmc", "geometric_langevin")
PEERS = ("mici", "nuts")


# =========================================================================== targets


def _rotation(rotvec) -> np.ndarray:
    """Rodrigues' formula (NumPy): the rotation by ``|ω|`` about ``ω/|ω|``."""
    w = np.asarray(rotvec, float)
    angle = np.linalg.norm(w)
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) / angle
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


class MatrixFisherTarget:
    name = "matrix_fisher"
    title = "matrix Fisher on SO(3), F = Q diag(4, 2, 0.5) Pᵀ"
    statistics = tuple(f"R{i + 1}{j + 1}" for i in range(3) for j in range(3))

    def __init__(self):
        self.F = (
            _rotation([0.3, -0.5, 0.8]) @ np.diag([4.0, 2.0, 0.5]) @ _rotation([-0.7, 0.2, 0.4]).T
        )
        self.reference = exact_groups.MatrixFisherLaw(self.F)
        self.exact = self.reference.mean().ravel()
        self.space = spaces.SO(3)
        self._F = jnp.asarray(self.F)
        self._flat = self.F.ravel()
        self._law = MatrixFisher(self.F)  # its normaliser once, outside the timed calls

    # liesample: positions are rotation matrices
    def logdensity(self, R):
        return jnp.sum(self._F * R)

    def observe(self, R):
        return jnp.ravel(R)

    def starts(self, key, n):
        return spaces.SO(3, shape=(n,)).uniform(key)

    # NUTS: y ∈ R⁴, R = R(y/|y|), a standard normal radius
    def nuts_logdensity(self, y):
        norm2 = jnp.sum(y * y)
        return self.logdensity(quaternion_to_rotation(y / jnp.sqrt(norm2))) - 0.5 * norm2

    def nuts_observe(self, y):
        return jnp.ravel(quaternion_to_rotation(y / jnp.linalg.norm(y)))

    def nuts_starts(self, key, n):
        return jax.random.normal(key, (n, 4))

    # mici: q = R.ravel() ∈ R⁹ on {RᵀR = I}; NumPy
    _upper = np.triu_indices(3)

    def mici_neg_log_dens(self, q):
        return -self._flat @ q

    def mici_grad(self, q):
        return -self._flat, -self._flat @ q

    def mici_constr(self, q):
        R = q.reshape(3, 3)
        return (R.T @ R - np.eye(3))[self._upper]

    def mici_jacob(self, q):
        R = q.reshape(3, 3)
        jac = np.zeros((6, 3, 3))
        for row, (i, j) in enumerate(zip(*self._upper, strict=True)):
            jac[row, :, i] += R[:, j]  # ∂(RᵀR)_ij/∂R_ai = R_aj
            jac[row, :, j] += R[:, i]
        return jac.reshape(6, 9), self.mici_constr(q)

    def mici_position(self, R):
        return np.asarray(R, float).ravel()

    # exact draws
    def iid(self, key, n):
        return self._law.sample(key, (n,)).reshape(n, 9)

    def describe(self):
        return {"F": self.F, "singular_values": (4.0, 2.0, 0.5), "exact_mean": self.exact}


class VonMisesFisherProductTarget:
    name = "vmf_product"
    title = "8 independent vMF directions on S², κ = 0.5 … 50"
    kappas = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 35.0, 50.0)

    def __init__(self):
        k = len(self.kappas)
        raw = np.random.default_rng(7).normal(size=(k, 3))
        self.mu = raw / np.linalg.norm(raw, axis=1, keepdims=True)
        self.kappa = np.asarray(self.kappas)
        lengths = np.array([exact_groups.vmf_mean_resultant_length(c, 3) for c in self.kappas])
        self.exact = (lengths[:, None] * self.mu).ravel()
        self.space = spaces.Sphere(2, shape=(k,))
        self.statistics = tuple(f"x{i + 1}{'xyz'[j]}" for i in range(k) for j in range(3))
        self._natural = jnp.asarray(self.kappa[:, None] * self.mu)
        self._flat = (self.kappa[:, None] * self.mu).ravel()

    def logdensity(self, x):
        return jnp.sum(self._natural * x)

    def observe(self, x):
        return jnp.ravel(x)

    def starts(self, key, n):
        return spaces.Sphere(2, shape=(n, len(self.kappas))).uniform(key)

    def nuts_logdensity(self, y):
        norm2 = jnp.sum(y * y, -1, keepdims=True)
        return self.logdensity(y / jnp.sqrt(norm2)) - 0.5 * jnp.sum(norm2)

    def nuts_observe(self, y):
        return jnp.ravel(y / jnp.linalg.norm(y, axis=-1, keepdims=True))

    def nuts_starts(self, key, n):
        return jax.random.normal(key, (n, len(self.kappas), 3))

    def mici_neg_log_dens(self, q):
        return -self._flat @ q

    def mici_grad(self, q):
        return -self._flat, -self._flat @ q

    def mici_constr(self, q):
        x = q.reshape(-1, 3)
        return np.sum(x * x, 1) - 1.0

    def mici_jacob(self, q):
        x = q.reshape(-1, 3)
        k = x.shape[0]
        jac = np.zeros((k, k, 3))
        jac[np.arange(k), np.arange(k)] = 2.0 * x
        return jac.reshape(k, 3 * k), self.mici_constr(q)

    def mici_position(self, x):
        return np.asarray(x, float).ravel()

    def iid(self, key, n):
        k = len(self.kappas)
        mean = jnp.broadcast_to(jnp.asarray(self.mu), (n, k, 3))
        kappa = jnp.broadcast_to(jnp.asarray(self.kappa), (n, k))
        return von_mises_fisher(key, mean, kappa).reshape(n, 3 * k)

    def describe(self):
        return {"kappas": self.kappas, "mean_directions": self.mu, "exact_mean": self.exact}


def targets():
    return [MatrixFisherTarget(), VonMisesFisherProductTarget()]


# =========================================================================== measurement


def _row(target, key, kind, observations, wall, gradients, cpu=math.nan, **extra):
    """Summary row from observations ``(chains, draws, statistics)``."""
    observations = np.asarray(observations, float)
    if kind == "iid":
        n = observations.shape[1]
        estimate = observations[0].mean(0)
        mcse = observations[0].std(0, ddof=1) / math.sqrt(n)
        ess = np.full(estimate.shape, float(n))
        r_hat = np.full(estimate.shape, math.nan)
    else:
        table = expectation_table(
            {s: observations[..., i] for i, s in enumerate(target.statistics)},
            exact=dict(zip(target.statistics, target.exact, strict=True)),
        )
        estimate = table["estimate"].to_numpy()
        mcse = table["mcse"].to_numpy()
        ess = table["ess_bulk"].to_numpy()
        r_hat = table["r_hat"].to_numpy()
    z = (estimate - target.exact) / mcse
    finite = bool(np.all(np.isfinite(z)) and np.all(np.isfinite(ess)))
    min_ess = float(np.min(ess)) if finite else math.nan
    max_abs_z = float(np.max(np.abs(z))) if finite else math.nan
    max_r_hat = float(np.nanmax(r_hat)) if np.any(np.isfinite(r_hat)) else math.nan
    matched = finite and max_abs_z <= Z_LIMIT and not (max_r_hat > RHAT_LIMIT)
    return {
        "sampler": key,
        "label": SAMPLERS[key],
        "chains": int(observations.shape[0]),
        "draws": int(observations.shape[1]),
        "estimate": estimate,
        "z": z,
        "max_abs_z": max_abs_z,
        "max_r_hat": max_r_hat,
        "ess": ess,
        "min_ess": min_ess,
        "wall_seconds": wall,
        "cpu_seconds": cpu,
        "gradients": gradients,
        "ess_per_second": min_ess / wall if finite else math.nan,
        "ess_per_cpu_second": min_ess / cpu if finite else math.nan,
        "ess_per_gradient": min_ess / gradients if finite and gradients else math.nan,
        "matched": matched,
        **extra,
    }


def run_iid(target, cfg, log):
    n = cfg["iid_draws"][target.name]
    fn = liesample.jit(lambda key: target.iid(key, n))
    _, first, _ = common.timed(fn, jax.random.key(SEED), cpu=True)  # compilation included
    draws, seconds, cpu = common.timed(fn, jax.random.key(SEED + 1), cpu=True)
    row = _row(
        target,
        "iid",
        "iid",
        np.asarray(draws)[None],
        seconds,
        0,
        cpu=cpu,
        settings=f"{n:,} draws per call",
        compile_seconds=max(first - seconds, 0.0),
        warmup_seconds=0.0,
    )
    row.update(
        _timer=lambda: common.timed(fn, jax.random.key(SEED + 1), cpu=True)[1:],
        _times=[(seconds, cpu)],
    )
    row.update(_share=1.0, _adaptation=0.0)
    log(f"    i.i.d.: {row['ess_per_second']:.3g} ESS/s, max|z| {row['max_abs_z']:.2f}")
    return row


def _retime(rows, rounds):
    """Time every compiled sampler again in ``rounds`` interleaved rounds (the load of a shared
    machine drifts over minutes; interleaving exposes all samplers to the same drift) and keep
    each one's fastest call and least CPU time (the median wall time is kept too)."""
    timed = [r for r in rows if "_timer" in r]
    for _ in range(rounds):
        for r in timed:
            r["_times"].append(r["_timer"]())
    for r in timed:
        walls, cpus = np.array(r["_times"]).T
        share = r["_share"]
        r["timed_calls"] = len(walls)
        r["wall_seconds"] = walls.min() * share
        r["wall_seconds_median"] = float(np.median(walls)) * share
        r["cpu_seconds"] = cpus.min() * share
        r["warmup_seconds"] = r["_adaptation"] + walls.min() * (1.0 - share)
        r["ess_per_second"] = r["min_ess"] / r["wall_seconds"]
        r["ess_per_cpu_second"] = r["min_ess"] / r["cpu_seconds"]
        for key in ("_timer", "_times", "_share", "_adaptation"):
            del r[key]


def _chains(sampler, observe, keys, starts, burn_in, draws):
    """One compiled loop over vmapped chains: ``burn_in`` discarded transitions, then ``draws``
    kept ones. Timed without compilation (see :func:`_retime`); the kept draws are charged
    ``draws / (burn_in + draws)`` of the wall time, the rest is reported as warm-up."""

    def run(key, position):
        def body(state, k):
            state, info = sampler.step(k, state)
            return state, (
                observe(state.position),
                info.num_integration_steps,
                info.acceptance_rate,
                info.is_divergent,
            )

        return jax.lax.scan(body, sampler.init(position), jax.random.split(key, burn_in + draws))[1]

    begin = time.perf_counter()
    compiled = liesample.jit(jax.vmap(run)).lower(keys, starts).compile()
    compile_seconds = time.perf_counter() - begin
    out, seconds, cpu = common.timed(compiled, keys, starts, cpu=True)
    obs, steps, acceptance, divergent = (np.asarray(x)[:, burn_in:] for x in out)
    share = draws / (burn_in + draws)
    return {
        "observations": obs,
        "gradients": int(np.sum(steps)),
        "acceptance_rate": float(np.mean(acceptance)),
        "divergences": int(np.sum(divergent)),
        "wall": seconds * share,
        "cpu": cpu * share,
        "compile_seconds": compile_seconds,
        "burn_seconds": seconds * (1.0 - share),
        "timing": {
            "_timer": lambda: common.timed(compiled, keys, starts, cpu=True)[1:],
            "_times": [(seconds, cpu)],
            "_share": share,
        },
    }


def _chains_row(target, key, out, settings, adaptation_seconds, log):
    """The row of a sampler run by ``_chains`` after ``adaptation_seconds`` of adaptation."""
    row = _row(
        target,
        key,
        key,
        out["observations"],
        out["wall"],
        out["gradients"],
        cpu=out["cpu"],
        settings=settings,
        acceptance_rate=out["acceptance_rate"],
        divergences=out["divergences"],
        compile_seconds=out["compile_seconds"],
        warmup_seconds=adaptation_seconds + out["burn_seconds"],
    )
    row.update(out["timing"], _adaptation=adaptation_seconds)
    _log_row(log, row)
    return row


def run_liesample(target, cfg, log, which):
    hmc = which == "geometric_hmc"
    algorithm = liesample.geometric_hmc if hmc else liesample.geometric_langevin
    options = {} if hmc else {"adjusted": True}
    key_adapt, key_start, key_run = jax.random.split(jax.random.key(SEED + 10), 3)
    starts = target.starts(key_start, cfg["chains"])
    warmup = liesample.window_adaptation(algorithm, target.logdensity, target.space, **options)
    begin = time.perf_counter()
    (_, parameters), _ = warmup.run(key_adapt, starts[0], num_steps=cfg["warmup"])
    adaptation_seconds = time.perf_counter() - begin  # its compilation included
    sampler = algorithm(target.logdensity, target.space, **parameters)
    out = _chains(
        sampler,
        target.observe,
        jax.random.split(key_run, cfg["chains"]),
        starts,
        cfg["burn_in"],
        cfg["draws"],
    )
    mass = np.ravel(np.asarray(jax.tree.leaves(parameters["inverse_mass_matrix"])[0]))
    steps = parameters.get("num_integration_steps", 1)
    settings = (
        f"step {parameters['step_size']:.3g}, L = {steps}, M⁻¹ ∈ [{mass.min():.2g}, "
        f"{mass.max():.2g}]" + ("" if hmc else f", friction {parameters['friction']:g}")
    )
    return _chains_row(target, which, out, settings, adaptation_seconds, log)


def run_nuts(target, cfg, log):
    import blackjax

    key_adapt, key_start, key_run = jax.random.split(jax.random.key(SEED + 20), 3)
    starts = target.nuts_starts(key_start, cfg["chains"])
    warmup = blackjax.window_adaptation(blackjax.nuts, target.nuts_logdensity)
    begin = time.perf_counter()
    (_, parameters), _ = warmup.run(key_adapt, starts[0], num_steps=cfg["warmup"])
    jax.block_until_ready(parameters)
    adaptation_seconds = time.perf_counter() - begin
    nuts = blackjax.nuts(target.nuts_logdensity, **parameters)
    out = _chains(
        nuts,
        target.nuts_observe,
        jax.random.split(key_run, cfg["chains"]),
        starts,
        cfg["burn_in"],
        cfg["draws"],
    )
    draws_total = cfg["chains"] * cfg["draws"]
    settings = (
        f"step {float(parameters['step_size']):.3g}, "
        f"{out['gradients'] / draws_total:.1f} leapfrog steps per draw, diagonal mass"
    )
    return _chains_row(target, "nuts", out, settings, adaptation_seconds, log)


def run_mici(target, cfg, log):
    import mici

    chains, draws, warm = cfg["mici_chains"], cfg["mici_draws"], cfg["warmup"]
    system = mici.systems.DenseConstrainedEuclideanMetricSystem(
        target.mici_neg_log_dens,
        target.mici_constr,
        grad_neg_log_dens=target.mici_grad,
        jacob_constr=target.mici_jacob,
        dens_wrt_hausdorff=True,
    )
    integrator = mici.integrators.ConstrainedLeapfrogIntegrator(
        system, projection_solver=mici.solvers.solve_projection_onto_manifold_quasi_newton
    )
    sampler = mici.samplers.DynamicMultinomialHMC(
        system, integrator, np.random.default_rng(SEED + 30)
    )
    starts = np.asarray(target.starts(jax.random.key(SEED + 10 + 1), chains))
    inits = [target.mici_position(s) for s in starts]

    def trace(state):
        return {"q": state.pos, "clock": time.perf_counter(), "cpu": time.process_time()}

    begin, begin_cpu = time.perf_counter(), time.process_time()
    _, traces, stats = sampler.sample_chains(
        warm,
        draws,
        inits,
        trace_funcs=[trace],
        trace_warm_up=True,
        display_progress=False,
    )
    # mici runs every chain's warm-up, then every chain's kept draws: each iteration's duration
    # is the gap to the previous timestamp in the order of execution.
    clock = np.asarray(traces["clock"])  # (chains, warm + draws)
    order = np.argsort(clock, axis=None)
    durations = np.empty(clock.size)
    durations[order] = np.diff(np.concatenate([[begin], clock.ravel()[order]]))
    durations = durations.reshape(clock.shape)
    wall = float(np.sum(durations[:, warm:]))
    cpu_clock = np.asarray(traces["cpu"]).ravel()[order]
    cpu_durations = np.empty(clock.size)
    cpu_durations[order] = np.diff(np.concatenate([[begin_cpu], cpu_clock]))
    cpu = float(np.sum(cpu_durations.reshape(clock.shape)[:, warm:]))
    q = np.asarray(traces["q"])[:, warm:]
    n_step = np.asarray(stats["n_step"])[:, warm:]
    accept = np.asarray(stats["accept_stat"])[:, warm:]
    failures = (
        np.asarray(stats["convergence_error"])[:, warm:]
        | np.asarray(stats["non_reversible_step"])[:, warm:]
    )
    observations = q  # the flat ambient position: the statistics, in the same order
    step_size = np.asarray(stats["step_size"])[:, -1]
    row = _row(
        target,
        "mici",
        "mici",
        observations,
        wall,
        int(np.sum(n_step)),
        cpu=cpu,
        settings=(
            f"step {np.mean(step_size):.3g} (dual averaging per chain), "
            f"{np.mean(n_step):.1f} leapfrog steps per draw, "
            f"{np.mean(failures):.1%} projection failures"
        ),
        acceptance_rate=float(np.mean(accept)),
        divergences=int(np.sum(np.asarray(stats["diverging"])[:, warm:])),
        compile_seconds=0.0,
        warmup_seconds=float(np.sum(durations[:, :warm])),
    )
    _log_row(log, row)
    return row


def _log_row(log, row):
    log(
        f"    {row['label']}: {row['ess_per_second']:.3g} ESS/s, "
        f"{1000 * row['ess_per_gradient']:.3g} ESS/1000 grad, max|z| {row['max_abs_z']:.2f}, "
        f"R-hat {row['max_r_hat']:.3f}, wall {row['wall_seconds']:.2f} s, "
        f"compile {row['compile_seconds']:.1f} s, warm-up {row['warmup_seconds']:.1f} s"
    )


def _best(rows, keys, field):
    usable = [r for r in rows if r["sampler"] in keys and r["matched"]]
    return max(usable, key=lambda r: r[field], default=None)


def _ratios(rows):
    """Each row's ESS/s, ESS per CPU-second and ESS/gradient over the best matched non-i.i.d.
    peer's; the best matched liesample sampler over the best peer and over i.i.d. draws."""
    fields = ("ess_per_second", "ess_per_cpu_second", "ess_per_gradient")
    for field in fields:
        best = _best(rows, PEERS, field)
        for r in rows:
            r[f"{field}_over_best_peer"] = r[field] / best[field] if best else math.nan
    iid = next(r for r in rows if r["sampler"] == "iid")
    out = {}
    for field, suffix in (("ess_per_second", ""), ("ess_per_cpu_second", "_cpu")):
        peer, ours = _best(rows, PEERS, field), _best(rows, OURS, field)
        out[f"best_peer{suffix}"] = peer["sampler"] if peer else None
        out[f"best_liesample{suffix}"] = ours["sampler"] if ours else None
        out[f"best_liesample_over_best_peer{suffix}"] = (
            ours[field] / peer[field] if ours and peer else math.nan
        )
        out[f"best_liesample_over_iid{suffix}"] = ours[field] / iid[field] if ours else math.nan
    out["target_met"] = bool(out["best_liesample_over_best_peer"] >= 3.0)
    return out


# =========================================================================== suite


def run(out_dir: Path, quick: bool, log=print) -> None:
    cfg = QUICK if quick else FULL
    start = time.perf_counter()
    load_before = os.getloadavg()[0]
    results = []
    for target in targets():
        log(f"  {target.title}")
        rows = [run_iid(target, cfg, log), run_liesample(target, cfg, log, "geometric_hmc")]
        if cfg["langevin"]:
            rows.append(run_liesample(target, cfg, log, "geometric_langevin"))
        rows += [run_mici(target, cfg, log), run_nuts(target, cfg, log)]
        _retime(rows, cfg["timing_rounds"])
        for row in rows:
            log(
                f"    retimed {row['label']}: {row['ess_per_second']:.3g} ESS/s, "
                f"{row['ess_per_cpu_second']:.3g} ESS per CPU-second"
            )
        ratios = _ratios(rows)
        log(
            f"    best liesample / best peer: {ratios['best_liesample_over_best_peer']:.3g}×, "
            f"/ i.i.d.: {ratios['best_liesample_over_iid']:.3g}×; per CPU-second "
            f"{ratios['best_liesample_over_best_peer_cpu']:.3g}× and "
            f"{ratios['best_liesample_over_iid_cpu']:.3g}×"
        )
        results.append(
            {
                "name": target.name,
                "title": target.title,
                "statistics": target.statistics,
                "problem": target.describe(),
                "rows": rows,
                "ratios": ratios,
            }
        )
    path = common.write_json(
        out_dir / f"{NAME}.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "config": cfg,
            "z_limit": Z_LIMIT,
            "r_hat_limit": RHAT_LIMIT,
            "targets": results,
            "total_seconds": time.perf_counter() - start,
            "load_average": {"start": load_before, "end": os.getloadavg()[0]},
        },
    )
    _plot(results, out_dir)
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def _plot(results, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in SAMPLERS if any(r["sampler"] == k for t in results for r in t["rows"])]
    fig, ax = plt.subplots(figsize=(8, 5))
    width = 0.8 / len(keys)
    for i, key in enumerate(keys):
        values, hatch = [], []
        for t in results:
            row = next((r for r in t["rows"] if r["sampler"] == key), None)
            v = row["ess_per_second"] if row else math.nan
            values.append(v if np.isfinite(v) else 0.0)
            hatch.append(bool(row) and not row["matched"])
        x = np.arange(len(results)) + (i - (len(keys) - 1) / 2) * width
        bars = ax.bar(x, values, width, label=SAMPLERS[key], color=COLORS[key])
        for bar, unmatched in zip(bars, hatch, strict=True):
            if unmatched:
                bar.set_hatch("//")
                bar.set_alpha(0.5)
    ax.set_xticks(np.arange(len(results)), [t["title"] for t in results], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("min ESS per second (sampling only)")
    ax.set_title("Lie groups and spheres: ESS/s at matched accuracy (hatched: not matched)")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2)
    fig.tight_layout()
    fig.savefig(out_dir / f"{NAME}.png", dpi=110)
    plt.close(fig)


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / f"{NAME}.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    machine, cfg = data["machine"], data["config"]
    load = data.get("load_average", {"start": math.nan, "end": math.nan})
    rel = common.relative_link(out_dir / f"{NAME}.png", md_dir)
    lines = [
        "## Lie groups and spheres: geometric HMC against mici, NUTS and i.i.d.",
        "",
        (
            f"From `benchmarks/groups.py` ({machine['date_utc']}, {data['total_seconds']:.0f} s, "
            f"{data['mode']} mode, {machine['usable_cpus']} CPUs {machine['cpu_model']}, jax "
            f"{machine['jax']}; shared machine, 1-minute load average {load['start']:.1f} at the "
            f"start and {load['end']:.1f} at the end). Every sampler gets "
            f"{cfg['warmup']} warm-up transitions (JAX samplers: window adaptation on one chain, "
            f"then {cfg['burn_in']} tuned transitions per chain from dispersed starts; mici: its "
            f"dual averaging per chain). Kept draws: {cfg['chains']} vmapped chains × "
            f"{cfg['draws']} for the JAX samplers, {cfg['mici_chains']} sequential chain(s) × "
            f"{cfg['mici_draws']} for mici (Python, one core). ESS = min over the statistics "
            "of the bulk ESS; ESS/s uses the wall time of the kept draws only (compilation and "
            "warm-up in their own columns; each compiled JAX loop keeps its fastest of "
            f"{cfg['timing_rounds'] + 1} calls, interleaved with the other samplers' calls); "
            "ESS per CPU-s uses this process's CPU time instead (steadier on a shared machine); "
            "gradients = leapfrog steps of the kept draws. "
            f"**Matched accuracy**: max |z| ≤ {data['z_limit']:g} against the exact mean (z = "
            f"error / MCSE) and max R-hat ≤ {data['r_hat_limit']:g}; ratios are to the best "
            "matched peer (mici or NUTS)."
        ),
        "",
    ]
    for t in data["targets"]:
        ratios = t["ratios"]
        lines += [
            f"**{t['title']}** ({len(t['statistics'])} statistics):",
            "",
            (
                "| sampler | settings | max abs z | max R-hat | min ESS | ESS/s | ESS per CPU-s | "
                "ESS per 1000 grad | sampling wall, CPU (s) | warm-up (s) | compile (s) | "
                "÷ best peer: ESS/s, per CPU-s, per grad |"
            ),
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in t["rows"]:
            flag = "" if r["matched"] else " (not matched)"
            extra = ""
            if "acceptance_rate" in r:
                extra = f", acceptance {r['acceptance_rate']:.2f}"
                if r.get("divergences"):
                    extra += f", {r['divergences']} divergent"
            lines.append(
                f"| {r['label']}{flag} | {r.get('settings', '')}{extra} | "
                f"{common.format_or_dash(r['max_abs_z'], 2)} | "
                f"{common.format_or_dash(r['max_r_hat'], 4)} | "
                f"{common.format_or_dash(r['min_ess'])} | "
                f"{common.format_or_dash(r['ess_per_second'])} | "
                f"{common.format_or_dash(r['ess_per_cpu_second'])} | "
                f"{common.format_or_dash(1000 * r['ess_per_gradient'])} | "
                f"{common.format_or_dash(r['wall_seconds'])}, "
                f"{common.format_or_dash(r['cpu_seconds'])} | "
                f"{common.format_or_dash(r['warmup_seconds'])} | "
                f"{common.format_or_dash(r['compile_seconds'], 2)} | "
                f"{common.format_or_dash(r['ess_per_second_over_best_peer'], 3)}, "
                f"{common.format_or_dash(r['ess_per_cpu_second_over_best_peer'], 3)}, "
                f"{common.format_or_dash(r['ess_per_gradient_over_best_peer'], 3)} |"
            )
        verdict = "met" if ratios["target_met"] else "missed"
        lines += [
            "",
            (
                f"Best liesample sampler ({ratios['best_liesample']}) over the best peer "
                f"({ratios['best_peer']}) in ESS/s: "
                f"{common.format_or_dash(ratios['best_liesample_over_best_peer'], 3)}× "
                f"(target ≥ 3×: **{verdict}**; per CPU-second "
                f"{common.format_or_dash(ratios['best_liesample_over_best_peer_cpu'], 3)}×); "
                f"over exact i.i.d. draws: "
                f"{common.format_or_dash(ratios['best_liesample_over_iid'], 3)}×"
                + (
                    f" (not a ceiling here: {IID_NOTES[t['name']]})."
                    if ratios["best_liesample_over_iid"] > 1 and t["name"] in IID_NOTES
                    else " (the ceiling)."
                )
                + " Per CPU-second over i.i.d.: "
                + f"{common.format_or_dash(ratios['best_liesample_over_iid_cpu'], 3)}×."
            ),
            "",
        ]
    lines += [f"![ESS per second by sampler and target]({rel})", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
