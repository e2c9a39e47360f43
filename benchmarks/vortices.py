"""Point vortices on the sphere: cost vs N and L, accuracy–cost, the all-modes variant, substeps.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/vortices.py            # a few minutes on 2 cores
    .venv/bin/python benchmarks/vortices.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``vortices.json``, ``vortices_throughput.png`` and ``vortices_accuracy.png``. Parts:

1. **Cost per step** of ``liesample.lie_poisson_langevin`` on ``point_vortices`` (one chain,
   σ = 1, β = 1, Hamiltonian drift on) against ``N`` (``L = 4``) and against ``L`` (``N = 10``), for
   ``splitting``, ``rkmk_heun`` and ``lie_euler`` (without substeps: a well-separated start).
2. **Accuracy–cost**: bias of ``E[x₁·x₂]`` for ``Γ = (1, 1)``, ``β = 4π`` (exact ``−1/3``) against
   the step size and the wall time, per integrator; ``E`` over the final states of independent
   chains started uniformly (i.i.d. once mixed), so the standard error is exact.
3. **All-modes variant** (``rkmk_heun``, dt = 0.01): the same pair with the paper's closed-form
   dissipation (``dissipation="all_modes"``) against the derived truncated one, for
   ``L = 2, 4, 8``: stationary ``E[x₁·x₂]`` and Kolmogorov–Smirnov distance from the exact pair law.
4. **Substeps**: for a like-signed pair with the drift on, at pair exponents 1, −0.5 and −0.9
   (near the −1 bound), the mean number of substeps per step, the fraction of steps that hit the
   cap, and the wall time against the plain integrator (``rkmk_heun``).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure
from scipy import stats

import liesample
from benchmarks import common, suites
from liesample.dynamics import PoissonLangevin
from liesample.integrators import get_integrator
from liesample.integrators.substeps import substep
from liesample.systems.point_vortices import (
    point_vortex_integrator,
    point_vortices,
    substep_rate,
)
from liesample.targets.vortices import VortexPairLaw, uniform_sphere_points

SUITE = {"order": 50, "title": "point vortices on the sphere"}

INTEGRATORS = ("splitting", "rkmk_heun", "lie_euler")


def _cost_per_step(system, integrator, repeats):
    """Seconds per step of one chain (compiled scan of ``repeats`` steps, compilation excluded)."""
    algorithm = liesample.lie_poisson_langevin(
        system, beta=1.0, sigma=1.0, step_size=1e-3, integrator=integrator, stability="off"
    )
    state = algorithm.init(system.default_position)
    keys = jax.random.split(jax.random.key(0), repeats)

    def run(state, keys):
        return jax.lax.scan(lambda s, k: (algorithm.step(k, s)[0], None), state, keys)[0]

    compiled = liesample.jit(run).lower(state, keys).compile()
    _, seconds = common.timed(compiled, state, keys)
    return seconds / repeats


def throughput(quick, log):
    sizes = (2, 10, 30, 100) if quick else (2, 10, 30, 100, 300, 1000)
    degrees = (1, 2, 4) if quick else (1, 2, 4, 8, 12)
    rows = []
    for n in sizes:
        system = point_vortices(np.ones(n), max_degree=4)
        for name in INTEGRATORS:
            repeats = max(3, min(200, int(2e5 / n**2)))
            seconds = _cost_per_step(system, name, repeats)
            rows.append({"vary": "N", "N": n, "L": 4, "integrator": name, "seconds": seconds})
            log(f"  N = {n:5d}, L = 4, {name:9s}: {seconds * 1e3:9.3f} ms/step")
    for degree in degrees:
        system = point_vortices(np.ones(10), max_degree=degree)
        for name in INTEGRATORS:
            seconds = _cost_per_step(system, name, 50)
            rows.append({"vary": "L", "N": 10, "L": degree, "integrator": name, "seconds": seconds})
            log(f"  N = 10, L = {degree:3d}, {name:9s}: {seconds * 1e3:9.3f} ms/step")
    return rows


def _final_states(algorithm, num_chains, num_steps, seed, num_vortices=2):
    starts = uniform_sphere_points(jax.random.key(seed), (num_chains, num_vortices))
    keys = jax.random.split(jax.random.key(seed + 1), num_chains)

    def chain(start, key):
        state = algorithm.init(start)
        steps = jax.random.split(key, num_steps)
        return jax.lax.scan(lambda s, k: (algorithm.step(k, s)[0], None), state, steps)[0].position

    compiled = liesample.jit(jax.vmap(chain)).lower(jnp.asarray(starts), keys).compile()
    final, seconds = common.timed(compiled, jnp.asarray(starts), keys)
    return np.asarray(final), seconds


PAIR = (1.0, 1.0)
PAIR_BETA = 4.0 * math.pi  # exponent 1, exact E[x1·x2] = −1/3
SIGMA = 1.5
HORIZON = 4.0  # time each chain runs: several relaxation times at σ = 1.5, L = 3


def accuracy_cost(quick, log):
    num_chains = 400 if quick else 1500
    step_sizes = (0.04, 0.02) if quick else (0.08, 0.04, 0.02, 0.01)
    system = point_vortices(PAIR, max_degree=3)
    law = system.reference(PAIR_BETA)
    rows = []
    for name in INTEGRATORS:
        for dt in step_sizes:
            algorithm = liesample.lie_poisson_langevin(
                system,
                beta=PAIR_BETA,
                sigma=SIGMA,
                step_size=dt,
                integrator=point_vortex_integrator(system, name),
            )
            final, seconds = _final_states(algorithm, num_chains, round(HORIZON / dt), 11)
            c = np.sum(final[:, 0] * final[:, 1], axis=-1)
            error = math.sqrt(law.variance() / num_chains)
            rows.append(
                {
                    "integrator": name,
                    "step_size": dt,
                    "estimate": float(c.mean()),
                    "bias": float(c.mean() - law.mean()),
                    "standard_error": error,
                    "seconds": seconds,
                    "chains": num_chains,
                }
            )
            log(f"  {name:9s} dt = {dt:5.3f}: bias {c.mean() - law.mean():+.4f} ± {error:.4f}")
    return rows


def all_modes_variant(quick, log):
    num_chains = 400 if quick else 2000
    degrees = (2, 4) if quick else (2, 4, 8)
    dt = 0.01  # rkmk_heun: its bias at this step (part 2) is below the noise
    rows = []
    law = VortexPairLaw.from_circulations(PAIR, PAIR_BETA)
    for degree in degrees:
        system = point_vortices(PAIR, max_degree=degree)
        for dissipation in ("truncated", "all_modes"):
            algorithm = liesample.lie_poisson_langevin(
                system,
                beta=PAIR_BETA,
                sigma=SIGMA,
                step_size=dt,
                integrator=point_vortex_integrator(system, "rkmk_heun", dissipation=dissipation),
            )
            final, seconds = _final_states(algorithm, num_chains, round(HORIZON / dt), 21)
            c = np.sum(final[:, 0] * final[:, 1], axis=-1)
            ks = stats.kstest(c, law.cdf)
            rows.append(
                {
                    "L": degree,
                    "dissipation": dissipation,
                    "estimate": float(c.mean()),
                    "exact": law.mean(),
                    "standard_error": float(c.std(ddof=1) / math.sqrt(num_chains)),
                    "ks_distance": float(ks.statistic),
                    "ks_pvalue": float(ks.pvalue),
                    "seconds": seconds,
                }
            )
            log(
                f"  L = {degree}, {dissipation:9s}: E[c] = {c.mean():+.4f} "
                f"(exact {law.mean():+.4f}), "
                f"KS {ks.statistic:.3f} (p = {ks.pvalue:.2g})"
            )
    return rows


def substep_cost(quick, log):
    """Substeps per step at increasingly attractive like-signed pairs, drift on."""
    num_chains = 16 if quick else 64
    num_steps = 100 if quick else 500
    dt, sigma = 0.02, 1.0
    rows = []
    for exponent in (1.0, -0.5, -0.9):
        beta = 4.0 * math.pi * exponent
        system = point_vortices(PAIR, max_degree=2)
        base = get_integrator("rkmk_heun")
        rate_fn = substep_rate(system)
        sigma_, theta, scene = liesample.samplers.orbit.lie_poisson_langevin.make_dynamics(
            system, beta=beta, sigma=sigma
        )
        dynamics = PoissonLangevin(system, sigma_, theta, scene)

        def chain(start, key, dynamics=dynamics, rate_fn=rate_fn, base=base):
            def one(x, k):
                dW = dynamics.brownian_increments(k, dt, x.dtype)
                x, count, completed = substep(
                    base, rate_fn, dynamics, x, dt, dW, safety=0.05, max_substeps=1000
                )
                return x, (count, completed)

            return jax.lax.scan(one, start, jax.random.split(key, num_steps))[1]

        starts = jnp.asarray(uniform_sphere_points(jax.random.key(31), (num_chains, 2)))
        keys = jax.random.split(jax.random.key(32), num_chains)
        compiled = liesample.jit(jax.vmap(chain)).lower(starts, keys).compile()
        (counts, completed), seconds = common.timed(compiled, starts, keys)
        plain = liesample.lie_poisson_langevin(
            system, beta=beta, sigma=sigma, step_size=dt, integrator="rkmk_heun", stability="off"
        )
        _, plain_seconds = _final_states(plain, num_chains, num_steps, 31)
        counts = np.asarray(counts)
        rows.append(
            {
                "exponent": exponent,
                "beta": beta,
                "mean_substeps": float(counts.mean()),
                "median_substeps": float(np.median(counts)),
                "capped_fraction": float(1.0 - np.asarray(completed).mean()),
                "seconds": seconds,
                "plain_seconds": plain_seconds,
                "steps": num_chains * num_steps,
            }
        )
        log(
            f"  exponent {exponent:+.1f}: {counts.mean():.2f} substeps/step (median "
            f"{np.median(counts):.0f}), capped {1 - np.asarray(completed).mean():.2%}, "
            f"{seconds / plain_seconds:.1f}x the plain step"
        )
    return rows


ONSAGER = np.array([1.0] * 5 + [-1.0] * 5)
"""The issue's negative-temperature case: 10 vortices, Γ = +1 ×5, −1 ×5; observable |D|²."""


def _dipole_squared(x):
    dipole = jnp.einsum("k,...ki->...i", jnp.asarray(ONSAGER, x.dtype), x)
    return jnp.sum(dipole * dipole, axis=-1)


def _baseline_sweep(beta, scale):
    """The physicist's single-vortex Metropolis, as a user writes it in JAX: each sweep visits
    the vortices in order, proposes ``(x + ε g)/|x + ε g|`` with a fixed ``ε`` and recomputes the
    vortex's pair energies."""
    gamma = jnp.asarray(ONSAGER)

    def sweep(x, key):
        keys = jax.random.split(key, ONSAGER.size)

        def one(k, x):
            kg, ku = jax.random.split(keys[k])
            y = x[k] + scale * jax.random.normal(kg, (3,))
            y = y / jnp.linalg.norm(y)
            others = jnp.arange(ONSAGER.size) != k
            old = jnp.log(jnp.sum((x - x[k]) ** 2, -1))
            new = jnp.log(jnp.sum((x - y) ** 2, -1))
            dh = -gamma[k] * jnp.sum(jnp.where(others, gamma * (new - old), 0.0)) / (4 * math.pi)
            accept = jnp.log(jax.random.uniform(ku)) < -beta * dh
            return x.at[k].set(jnp.where(accept, y, x[k]))

        return jax.lax.fori_loop(0, ONSAGER.size, one, x)

    return sweep


def _compiled_dipole_chains(sweep, starts, num_sweeps, key):
    """A compiled run of vmapped chains recording ``|D|²`` after every sweep (states:
    positions, or states with a ``position``), and its arguments."""

    def chain(start, key):
        def one(x, k):
            x = sweep(x, k)
            return x, _dipole_squared(getattr(x, "position", x))

        return jax.lax.scan(one, start, jax.random.split(key, num_sweeps))[1]

    keys = jax.random.split(key, jax.tree.leaves(starts)[0].shape[0])
    return liesample.jit(jax.vmap(chain)).lower(starts, keys).compile(), (starts, keys)


def _interleaved_timings(compiled, repeats=3):
    """``{name: (values, best seconds)}``: the compiled runs timed in turn, ``repeats`` rounds
    (the machine is shared; the best of the rounds is each run's cost)."""
    out = {}
    for _ in range(repeats):
        for name, (fn, args) in compiled.items():
            values, seconds = common.timed(fn, *args)
            best = min(seconds, out[name][1]) if name in out else seconds
            out[name] = (np.asarray(values), best)
    return out


def _ess(values):
    import arviz as az

    return float(az.ess(np.asarray(values), method="bulk"))


def exact_sampler(quick, log):
    """ESS/s of |D|² for ``liesample.vortex_metropolis`` against the user's single-vortex
    Metropolis, same chains, sweeps and machine, at β = −4 and −2; also the whole
    ``liesample.sample`` call (warm-up, compile and runner included)."""
    num_chains = 16 if quick else 64
    num_sweeps = 1000 if quick else 20_000
    burn = num_sweeps // 10
    rows = []
    system = point_vortices(ONSAGER)
    for beta in (-4.0, -2.0):
        starts = jnp.asarray(uniform_sphere_points(jax.random.key(80), (num_chains, ONSAGER.size)))
        start = time.perf_counter()
        run = liesample.sample_chains(
            liesample.vortex_metropolis(system, beta=beta),
            jax.random.key(81),
            np.asarray(starts),
            num_sweeps,
            num_warmup=500,
            progress_bar=False,
        )
        sample_seconds = time.perf_counter() - start
        tuned = run.settings["step_size"]
        algorithm = liesample.vortex_metropolis(system, beta=beta, proposal_scale=tuned)

        def ours_sweep(state, key, algorithm=algorithm):
            return algorithm.step(key, state)[0]

        entries = {
            "vortex_metropolis": (ours_sweep, tuned, jax.vmap(algorithm.init)(starts)),
            "baseline_metropolis": (_baseline_sweep(beta, 0.5), 0.5, starts),
        }
        compiled = {
            name: _compiled_dipole_chains(sweep, first, num_sweeps, jax.random.key(82))
            for name, (sweep, _, first) in entries.items()
        }
        timings = _interleaved_timings(compiled)
        for name, (_, scale, _) in entries.items():
            values, seconds = timings[name]
            kept = values[:, burn:]
            ess = _ess(kept)
            chain_means = kept.mean(axis=1)
            row = {
                "beta": beta,
                "sampler": name,
                "proposal_scale": scale,
                "chains": num_chains,
                "sweeps": num_sweeps,
                "mean_dipole_squared": float(kept.mean()),
                "mcse": float(kept.std() / math.sqrt(ess)),
                "chain_mean_spread": float(chain_means.std(ddof=1) / math.sqrt(num_chains)),
                "ess": ess,
                "seconds": seconds,
                "ess_per_second": ess / seconds * (num_sweeps / (num_sweeps - burn)),
            }
            rows.append(row)
            log(
                f"  beta {beta:+g} {name:20s} eps {scale:.3g}: "
                f"E|D|² {row['mean_dipole_squared']:.2f} ± {row['mcse']:.2f}, ESS {ess:.0f}, "
                f"{seconds:.2f} s, ESS/s "
                f"{row['ess_per_second']:.0f}"
            )
        rows.append(
            {
                "beta": beta,
                "sampler": "liesample.sample(vortex_metropolis)",
                "proposal_scale": tuned,
                "acceptance": float(np.mean(run.info["acceptance_rate"])),
                "chains": num_chains,
                "sweeps": num_sweeps,
                "mean_dipole_squared": float(
                    np.asarray(_dipole_squared(jnp.asarray(run.positions))).mean()
                ),
                "seconds_with_warmup_and_compile": sample_seconds,
            }
        )
        log(f"  beta {beta:+g} liesample.sample: {sample_seconds:.1f} s (tuned eps {tuned:.3g})")
    return rows


def _substep_dropping_time(base, rate_fn, dynamics, mu, dt, dW, safety, max_substeps):
    """The substep rule before this benchmark's fix: a capped step *drops* the rest of its
    time (kept here to measure what that did)."""
    dt = jnp.asarray(dt, dtype=mu.dtype)

    def cond(carry):
        return (carry[0] > 0) & (carry[1] < max_substeps)

    def body(carry):
        remaining, count, x = carry
        rate = rate_fn(dynamics, x)
        limit = jnp.where(rate > 0, safety / jnp.where(rate > 0, rate, 1.0), remaining)
        h = jnp.minimum(remaining, limit)
        x = base(dynamics, x, h, dW * (h / dt))
        return jnp.where(h >= remaining, 0.0, remaining - h), count + 1, x

    return jax.lax.while_loop(cond, body, (dt, jnp.int32(0), mu))[2]


def negative_temperature_bias(quick, log):
    """The unadjusted sampler on a like-signed pair at β = −6 (exponent −0.48: it clusters):
    time averages of ``c = x₁·x₂`` and of ``c > 0.999`` over chains of length 200 (the first
    fifth dropped; standard errors from the spread of the chain means) against the exact pair
    law, for: the Hamiltonian drift off (no substeps needed) as dt shrinks; the drift on without
    substeps; substeps whose last capped substep takes the rest of the step (now), at caps 3 and
    50; and the old rule, whose capped step dropped its remaining time (cap 3)."""
    num_chains = 8 if quick else 32
    horizon = 20.0 if quick else 200.0
    beta = -6.0
    system = point_vortices([1.0, 1.0])
    law = system.reference(beta)
    exact_mean, exact_tail = law.mean(), float(1.0 - law.cdf(0.999))
    starts = jnp.asarray(uniform_sphere_points(jax.random.key(90), (num_chains, 2)))
    keys = jax.random.split(jax.random.key(91), num_chains)
    sigma_, theta, _ = liesample.samplers.orbit.lie_poisson_langevin.make_dynamics(
        system, beta=beta, sigma=1.0
    )
    rate_fn = substep_rate(system)
    configurations = [("drift off", False, "none", dt, 0) for dt in (0.2, 0.1, 0.05)] + [
        ("drift on, no substeps", True, "none", 0.05, 0),
        ("drift on, substeps, clock kept", True, "kept", 0.05, 3),
        ("drift on, substeps, clock kept", True, "kept", 0.05, 50),
        ("drift on, substeps, old rule: time dropped", True, "dropped", 0.05, 3),
    ]
    base = get_integrator("splitting")
    rows = []
    for label, hamiltonian, rule, dt, cap in configurations:
        dynamics = PoissonLangevin(system, sigma_, theta, liesample.Scene(hamiltonian=hamiltonian))
        num_steps = round(horizon / dt)

        def advance(x, dW, dynamics=dynamics, dt=dt, rule=rule, cap=cap):
            if rule == "none":
                return base(dynamics, x, dt, dW)
            if rule == "kept":
                return substep(base, rate_fn, dynamics, x, dt, dW, safety=0.05, max_substeps=cap)[0]
            return _substep_dropping_time(base, rate_fn, dynamics, x, dt, dW, 0.05, cap)

        def chain(x, key, dynamics=dynamics, dt=dt, advance=advance, num_steps=num_steps):
            def one(x, k):
                x = advance(x, dynamics.brownian_increments(k, dt, x.dtype))
                return x, jnp.sum(x[0] * x[1])

            return jax.lax.scan(one, x, jax.random.split(key, num_steps))[1]

        compiled = liesample.jit(jax.vmap(chain)).lower(starts, keys).compile()
        c, seconds = common.timed(compiled, starts, keys)
        c = np.asarray(c)[:, num_steps // 5 :]
        means, tails = c.mean(axis=1), (c > 0.999).mean(axis=1)
        row = {
            "configuration": label,
            "dt": dt,
            "max_substeps": cap,
            "mean": float(means.mean()),
            "standard_error": float(means.std(ddof=1) / math.sqrt(num_chains)),
            "exact_mean": exact_mean,
            "tail": float(tails.mean()),
            "tail_standard_error": float(tails.std(ddof=1) / math.sqrt(num_chains)),
            "exact_tail": exact_tail,
            "seconds": seconds,
            "chains": num_chains,
            "time": horizon,
        }
        rows.append(row)
        log(
            f"  {label:42s} dt {dt:<5g} cap {cap:<3d} E[c] {row['mean']:+.4f} ± "
            f"{row['standard_error']:.4f} (exact {exact_mean:+.4f}); P(c>0.999) {row['tail']:.4f}"
            f" ± {row['tail_standard_error']:.4f} (exact {exact_tail:.4f}); {seconds:.1f} s"
        )
    return rows


def batched_substeps(quick, log):
    """Seconds of 200 collision-safe steps (10 vortices, β = −2, dt = 0.01) for 1, 2 and 8
    vmapped chains: under ``vmap`` each step costs the slowest chain's substeps."""
    system = point_vortices(ONSAGER)
    rows = []
    for cap in (1000, 100):
        algorithm = liesample.lie_poisson_langevin(
            system,
            beta=-2.0,
            step_size=0.01,
            stability="off",
            integrator=point_vortex_integrator(system, max_substeps=cap),
        )
        for num_chains in (1, 2, 8):
            starts = jnp.asarray(
                uniform_sphere_points(jax.random.key(100), (num_chains, ONSAGER.size))
            )

            def chain(start, key, algorithm=algorithm):
                def one(state, k):
                    return algorithm.step(k, state)[0], None

                return jax.lax.scan(one, algorithm.init(start), jax.random.split(key, 200))[0]

            keys = jax.random.split(jax.random.key(101), num_chains)
            compiled = liesample.jit(jax.vmap(chain)).lower(starts, keys).compile()
            _, seconds = common.timed(compiled, starts, keys)
            rows.append({"max_substeps": cap, "chains": num_chains, "seconds": seconds})
            log(f"  cap {cap}: {num_chains} chains, 200 steps: {seconds:.2f} s")
    return rows


def run_exact(out_dir: Path, quick: bool, log) -> dict:
    """The exact sampler, the β < 0 bias of the unadjusted one, batched substeps:
    ``vortices_exact.json``."""
    data = {"machine": common.machine_info(), "quick": quick}
    log("vortices: exact single-vortex Metropolis against the user's Metropolis")
    data["exact_sampler"] = exact_sampler(quick, log)
    log("vortices: the unadjusted sampler at beta < 0")
    data["negative_temperature"] = negative_temperature_bias(quick, log)
    log("vortices: batched substeps")
    data["batched_substeps"] = batched_substeps(quick, log)
    common.write_json(out_dir / "vortices_exact.json", data)
    return data


def _plots(data, out_dir):
    fig = Figure(figsize=(11, 4.2))
    for index, vary in enumerate(("N", "L")):
        ax = fig.add_subplot(1, 2, index + 1)
        for name in INTEGRATORS:
            rows = [r for r in data["throughput"] if r["vary"] == vary and r["integrator"] == name]
            ax.loglog([r[vary] for r in rows], [r["seconds"] * 1e3 for r in rows], "o-", label=name)
        if vary == "N":
            n = np.array([30.0, 1000.0])
            ax.loglog(n, 1e-3 * n**2, "k:", label="∝ N²")
        ax.set_xlabel(vary if vary == "N" else "max degree L")
        ax.set_ylabel("ms per step")
        ax.set_title(f"cost per step vs {vary}" + (" (L = 4)" if vary == "N" else " (N = 10)"))
        ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / "vortices_throughput.png", dpi=120)

    fig = Figure(figsize=(11, 4.2))
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for name in INTEGRATORS:
        rows = [r for r in data["accuracy_cost"] if r["integrator"] == name]
        dts = [r["step_size"] for r in rows]
        bias = [abs(r["bias"]) for r in rows]
        ax1.loglog(dts, bias, "o-", label=name)
        ax2.loglog([r["seconds"] for r in rows], bias, "o-", label=name)
    noise = data["accuracy_cost"][0]["standard_error"]
    for ax in (ax1, ax2):
        ax.axhline(2 * noise, color="0.6", linestyle=":", label="2 × standard error")
        ax.set_ylabel("|bias of E[x₁·x₂]|")
        ax.legend()
    ax1.set_xlabel("step size")
    ax2.set_xlabel("wall time (s)")
    ax1.set_title("pair law, Γ = (1, 1), β = 4π")
    fig.tight_layout()
    fig.savefig(out_dir / "vortices_accuracy.png", dpi=120)


def run(out_dir: Path, quick: bool, log) -> None:
    start = time.perf_counter()
    # Since the splitting's pieces evaluate only their own transport mode
    # (LiePoissonSystem.single_noise_hamiltonian); older results lack this key.
    data = {"machine": common.machine_info(), "quick": quick, "splitting_evaluates_one_mode": True}
    log("vortices: cost per step vs N and L")
    data["throughput"] = throughput(quick, log)
    log("vortices: accuracy-cost of E[x1·x2]")
    data["accuracy_cost"] = accuracy_cost(quick, log)
    log("vortices: the paper's all-modes dissipation against the derived one")
    data["all_modes"] = all_modes_variant(quick, log)
    log("vortices: substepping cost")
    data["substeps"] = substep_cost(quick, log)
    data["total_seconds"] = time.perf_counter() - start
    run_exact(out_dir, quick, log)
    common.write_json(out_dir / "vortices.json", data)
    _plots(data, out_dir)


def report(out_dir: Path, md_dir: Path) -> str:
    """Markdown section from ``vortices.json``, if it exists."""
    path = out_dir / "vortices.json"
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    rel = Path(*([".."] * 0)) / out_dir.relative_to(md_dir) if out_dir != md_dir else Path(".")
    lines = [
        "## Point vortices on the sphere",
        "",
        (
            f"From `benchmarks/vortices.py` ({data['machine']['date_utc']}, "
            f"{data['total_seconds']:.0f} s{', quick mode' if data['quick'] else ''}; the machine "
            "was shared — load average 6–9 on 2 cores — so wall times are rough and the suite "
            "took far longer than its 6-minute target)."
        ),
        "",
        "**Cost per step** (one chain, σ = 1, drift on, no substeps):",
        "",
        "| N | L | " + " | ".join(INTEGRATORS) + " |",
        "|---|---|" + "---|" * len(INTEGRATORS),
    ]
    table = {}
    for r in data["throughput"]:
        table.setdefault((r["vary"], r["N"], r["L"]), {})[r["integrator"]] = r["seconds"]
    for (_, n, degree), cells in table.items():
        lines.append(
            f"| {n} | {degree} | "
            + " | ".join(f"{cells[name] * 1e3:.3g} ms" for name in INTEGRATORS)
            + " |"
        )
    by_n = {
        r["N"]: r["seconds"]
        for r in data["throughput"]
        if r["vary"] == "N" and r["integrator"] == "rkmk_heun"
    }
    if len(by_n) >= 2:
        n_small, n_large = sorted(by_n)[-2:]
        slope = math.log(by_n[n_large] / by_n[n_small]) / math.log(n_large / n_small)
        lines += [
            "",
            (
                f"Between N = {n_small} and N = {n_large} the `rkmk_heun` cost grows as "
                f"N^{slope:.2f} (pair interactions are O(N²); small N is dispatch-bound). "
                + (
                    "`splitting` moves the L(L+2) noise directions one at a time; each piece "
                    "evaluates only its own transport mode, but re-evaluates the pair gradient."
                    if data.get("splitting_evaluates_one_mode")
                    else "`splitting` moves the L(L+2) noise directions one at a time, each piece "
                    "re-evaluating the pair gradient, so it costs about L(L+2) times more per "
                    "step. (Measured before each piece evaluated only its own transport mode; "
                    "a short timing since then, one chain, N = 10, on the loaded machine, gives "
                    "splitting / rkmk_heun ≈ 5–9 for L = 4…12, down from 28 at L = 4 and 140 at "
                    "L = 12 in the same timing.)"
                )
            ),
        ]
    lines += [
        "",
        f"![cost]({rel / 'vortices_throughput.png'})",
        "",
        (
            "**Accuracy–cost** of `E[x₁·x₂]`, Γ = (1, 1), β = 4π (exact −1/3), L = 3, σ = 1.5, "
            "final states of independent chains, collision-safe integrators:"
        ),
        "",
        "| integrator | dt | bias ± s.e. | wall time |",
        "|---|---|---|---|",
    ]
    for r in data["accuracy_cost"]:
        lines.append(
            f"| {r['integrator']} | {r['step_size']:g} | {r['bias']:+.4f} ± "
            f"{r['standard_error']:.4f} | {r['seconds']:.2f} s |"
        )
    euler = [r for r in data["accuracy_cost"] if r["integrator"] == "lie_euler"]
    if euler:
        z = [r["bias"] / r["standard_error"] for r in euler]
        others = max(
            abs(r["bias"]) / r["standard_error"]
            for r in data["accuracy_cost"]
            if r["integrator"] != "lie_euler" and r["step_size"] <= 0.04
        )
        lines += [
            "",
            (
                f"`lie_euler` is biased by {min(r['bias'] for r in euler):+.3f} to "
                f"{max(r['bias'] for r in euler):+.3f} ({min(z):+.1f} to {max(z):+.1f} s.e.) at "
                "every step size, without shrinking as dt → 0: it freezes ∇ĥ_i at the start of "
                "the step, which misses the Stratonovich drift of noise Hamiltonians that are "
                "not linear (for linear noise, e.g. the rigid body, ∇ĥ_i is constant and it is "
                "consistent). `splitting` and `rkmk_heun` are within "
                f"{others:.1f} s.e. for dt ≤ 0.04 at this number of chains."
            ),
        ]
    lines += [
        "",
        f"![accuracy]({rel / 'vortices_accuracy.png'})",
        "",
        (
            "**The paper's all-modes dissipation** with truncated noise (same pair; rkmk_heun, "
            "dt = 0.01), against the derived truncated dissipation:"
        ),
        "",
        "| L | dissipation | E[x₁·x₂] ± s.e. (exact) | KS distance (p) |",
        "|---|---|---|---|",
    ]
    for r in data["all_modes"]:
        lines.append(
            f"| {r['L']} | {r['dissipation']} | {r['estimate']:+.4f} ± {r['standard_error']:.4f} "
            f"({r['exact']:+.4f}) | {r['ks_distance']:.3f} ({r['ks_pvalue']:.2g}) |"
        )
    for r in data["all_modes"]:
        z = (r["estimate"] - r["exact"]) / r["standard_error"]
        if r["dissipation"] == "truncated" and abs(z) > 4:
            lines += [
                "",
                (
                    f"At L = {r['L']} the derived (Gibbs-exact) dissipation is itself "
                    f"{r['estimate'] - r['exact']:+.3f} ({z:+.0f} s.e.) off at dt = 0.01: the "
                    "step is presumably too large for the faster high-ℓ modes (not investigated "
                    "further), so that row measures the discretisation, not the variant; compare "
                    "the variant with the derived dissipation at the same L and dt."
                ),
            ]
    lines += [
        "",
        (
            "**Substepping** (like-signed pair, drift on, rkmk_heun, dt = 0.02, safety 0.05, "
            "cap 1000):"
        ),
        "",
        "| pair exponent | substeps/step (mean, median) | steps capped | time vs plain step |",
        "|---|---|---|---|",
    ]
    for r in data["substeps"]:
        lines.append(
            f"| {r['exponent']:+.1f} | {r['mean_substeps']:.2f}, {r['median_substeps']:.0f} | "
            f"{r['capped_fraction']:.2%} | {r['seconds'] / r['plain_seconds']:.1f}× |"
        )
    lines += [
        "",
        (
            "The substep rule h = min(remaining, 0.05 · 2π d²/(|Γ_j| + |Γ_k|)) costs nothing "
            "for repelling pairs and grows as close approaches become likely. The chains start "
            "uniform and run t = 10, which does not reach the deep clustering of exponent −0.9 "
            "(Gibbs median separation ≈ 1e-5): there the expected count diverges and the cap "
            "is what bounds the cost. The time ratio is larger "
            "than the mean count because vmapped chains wait for the slowest chain's substeps. "
            "(Since this table, a capped step no longer drops its remaining time: its last "
            "substep takes it; see the exact-sampler section below.) "
            "Sampling without the Hamiltonian drift (`hamiltonian=False`, same invariant law) "
            "needs no substeps at all."
        ),
        "",
    ]
    exact = report_exact(out_dir)
    return "\n".join(lines) + ("\n" + exact if exact else "")


def report_exact(out_dir: Path) -> str:
    """Markdown section from ``vortices_exact.json``, if it exists."""
    path = out_dir / "vortices_exact.json"
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    machine = data["machine"]
    lines = [
        "## Point vortices at negative temperature: exact sampler and unadjusted bias",
        "",
        (
            f"From `benchmarks/vortices.py --exact` ({machine.get('date_utc', '?')}, "
            f"{machine.get('cpu_model', '?')}, {machine.get('usable_cpus', '?')} cores usable, "
            f"{'quick' if data['quick'] else 'full'} mode; the machine was shared with other "
            "jobs, so the two samplers of each β were timed in turn, best of 3 rounds)."
        ),
        "",
        (
            "**Exact sampler.** 10 vortices (Γ = +1 ×5, −1 ×5), observable |D|², "
            "D = Σ Γ_k x_k; the same uniform starts, chains and sweeps for "
            "`liesample.vortex_metropolis` (proposal scale tuned by its warm-up) and a user's "
            "single-vortex Metropolis in JAX (fixed ε = 0.5); ESS (bulk) after a 10% burn-in; "
            "seconds of the compiled run, compile excluded:"
        ),
        "",
        "| β | sampler | ε | E\\|D\\|² ± MCSE | ESS | seconds | ESS/s | ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    rows = data["exact_sampler"]
    for beta in sorted({r["beta"] for r in rows}):
        pair = {r["sampler"]: r for r in rows if r["beta"] == beta and "ess" in r}
        baseline = pair["baseline_metropolis"]["ess_per_second"]
        for name in ("vortex_metropolis", "baseline_metropolis"):
            r = pair[name]
            lines.append(
                f"| {beta:g} | {name} | {r['proposal_scale']:.3g} | "
                f"{r['mean_dipole_squared']:.2f} ± {r['mcse']:.2f} | {r['ess']:.0f} | "
                f"{r['seconds']:.2f} | {r['ess_per_second']:.0f} | "
                f"{r['ess_per_second'] / baseline:.2f}× |"
            )
    chains, sweeps = rows[0]["chains"], rows[0]["sweeps"]
    whole = [r for r in rows if "seconds_with_warmup_and_compile" in r]
    lines += [
        "",
        (
            f"{chains} chains × {sweeps} sweeps. The whole `liesample.sample_chains` call "
            "(500 warm-up sweeps, compile, runner) took "
            + ", ".join(
                f"{r['seconds_with_warmup_and_compile']:.1f} s at β = {r['beta']:g} "
                f"(acceptance {r['acceptance']:.2f})"
                for r in whole
            )
            + ". At β = −2 the tuned scale reaches its cap (proposals uniform on the sphere) "
            "and the acceptance stays above the target: independent proposals win there."
        ),
        "",
        (
            "**Unadjusted sampler at β < 0.** A like-signed pair at β = −6 (pair exponent "
            "−0.48: it clusters), `splitting`, σ = 1; time averages over "
            f"{data['negative_temperature'][0]['chains']} chains of length "
            f"t = {data['negative_temperature'][0]['time']:g} (first fifth dropped; standard "
            "errors from the spread of the chain means, rough for the rare tail):"
        ),
        "",
        "| configuration | dt | cap | E[x₁·x₂] ± s.e. (exact) | P(x₁·x₂ > 0.999) (exact) | s |",
        "|---|---|---|---|---|---|",
    ]
    for r in data["negative_temperature"]:
        cap = r["max_substeps"] or "–"
        lines.append(
            f"| {r['configuration']} | {r['dt']:g} | {cap} | {r['mean']:+.4f} ± "
            f"{r['standard_error']:.4f} ({r['exact_mean']:+.4f}) | {r['tail']:.4f} ± "
            f"{r['tail_standard_error']:.4f} ({r['exact_tail']:.4f}) | {r['seconds']:.1f} |"
        )
    lines += [
        "",
        (
            "Two causes. (1) With substeps, the old rule dropped the rest of a capped step: the "
            "clock then runs slower where pairs are close (speed ∝ d²), and a process slowed by "
            "s(x) samples ∝ exp(−βh)/s(x), which at β < 0 is not integrable at like-signed "
            "collisions: the chains collapse (h climbs, |D|² overshoots). Fixed in "
            "`liesample/integrators/substeps.py`: the last allowed substep takes the remaining "
            "time. (2) Without substeps, or in a capped step's last substep, the Hamiltonian "
            "rotation of a close pair (rate ∝ 1/d²) is unresolved and flings the pair apart: "
            "too few close pairs (|D|² too low at β < 0), a bias that shrinks only as the "
            "fraction of pairs closer than about √dt does. The Hamiltonian drift does not change "
            "the invariant law and the noise and derived dissipation stay bounded at "
            "collisions, so `hamiltonian=False` samples the exact law as dt → 0 with no "
            "substeps (rows 'drift off')."
        ),
        "",
        "**Batched substeps** (10 vortices, β = −2, dt = 0.01, 200 collision-safe steps):",
        "",
        "| cap | chains | seconds |",
        "|---|---|---|",
    ]
    for r in data["batched_substeps"]:
        lines.append(f"| {r['max_substeps']} | {r['chains']} | {r['seconds']:.2f} |")
    lines += [
        "",
        (
            "Under `vmap` the substep loop runs until the slowest chain is done, so a batch "
            "costs its largest substep count per step, bounded by the cap."
        ),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    if "--exact" in sys.argv:  # only the exact-sampler parts (vortices_exact.json)
        quick_run = "--quick" in sys.argv
        results = Path(__file__).resolve().parent / "results" / ("quick" if quick_run else "")
        results.mkdir(parents=True, exist_ok=True)
        run_exact(results, quick_run, lambda message: print(message, flush=True))
        print(report_exact(results))
        sys.exit(0)
    sys.exit(suites.standalone(__file__))
