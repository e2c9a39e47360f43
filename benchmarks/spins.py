"""Classical Heisenberg spins at the 3-D critical point: heat bath + over-relaxation, the
Swendsen–Wang cluster algorithm and a plain reference heat bath, side by side in one process.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/spins.py            # L = 8, 16, 32 (~20 min on 2 shared cores)
    .venv/bin/python benchmarks/spins.py --quick    # L = 8 only (benchmarks/results/quick/)

Writes ``spins.json``. On ``heisenberg((L, L, L), periodic=True)``, J = 1, no field, at
``β_c = 0.693`` (the 3-D Heisenberg critical point), three samplers:

- ``heat bath + over-relaxation``: ``liesample.heisenberg_heat_bath`` (one step: one heat-bath
  sweep, one over-relaxation sweep);
- ``swendsen-wang``: ``liesample.heisenberg_cluster`` (one step: one Swendsen–Wang update with
  Wolff's embedding, every site in one cluster or another);
- ``reference heat bath``: :func:`reference_step` below, a plain checkerboard heat bath with
  over-relaxation written here with rolls and a parity mask, independently of the library (the
  same moves, so its τ should match the library's; its cost is the yardstick).

Each sampler runs ``NUM_CHAINS`` chains from the same equilibrated starts (Swendsen–Wang steps
from random spins), a short warm-up, then one draw of ``(|m|, E/N)`` per step for as many steps
as fill the wall-time budget. The integrated autocorrelation time ``τ_int`` (Sokal's automatic
window, ``W ≥ 6 τ``, error by Madras–Sokal) is per step, from the autocorrelation averaged over
chains; ``ESS = chains · draws / (2 τ)`` and ESS/s divides by the sampling time (compilation
excluded).

The user's path, at L = 8: ``liesample.sample(liesample.recommended_sampler(system, beta=β_c),
…)`` with the default warm-up, timed with its compilation, against the reference heat bath run
for as many warm-up steps and draws, also timed with its compilation. The choice table runs the
two library samplers at L = 8 over several β, and (full mode) at L = 16 on both sides of β_c, to
show where each wins (``liesample.recommended_sampler`` follows it).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common, suites
from liesample.systems.heisenberg import heisenberg

SUITE = {"order": 30, "title": "classical spins: the 3-D Heisenberg critical point"}

BETA_C = 0.693
SIZES = (8, 16, 32)
QUICK_SIZES = (8,)
NUM_CHAINS = 4
BUDGET_SECONDS = {8: 8.0, 16: 40.0, 32: 200.0}
QUICK_BUDGET_SECONDS = 4.0
CHOICE_BETAS = (0.3, 0.5, 0.693, 1.0)
CHOICE_LARGE = {16: (0.6, 0.8)}  # full mode: the edges of the window where clusters may win
CHOICE_LARGE_BUDGET = 20.0
USER_PATH_DRAWS = 4000
QUANTITIES = ("abs_magnetisation", "energy_per_site")

SAMPLERS = {
    "heat bath + over-relaxation": lambda system, beta: liesample.heisenberg_heat_bath(
        system, beta=beta, overrelaxation=1
    ),
    "swendsen-wang": lambda system, beta: liesample.heisenberg_cluster(system, beta=beta),
}


# --------------------------------------------------------------------------- the reference


def _reference_vmf(key, mean, kappa):
    """Draws ``∝ exp(κ s·mean)`` on S² (``mean`` unit, ``κ ≥ 0``), by inverting the law of
    ``w = s·mean`` and a uniform azimuth about ``mean``."""
    k_w, k_phi = jax.random.split(key)
    u = jax.random.uniform(k_w, kappa.shape, dtype=mean.dtype)
    kappa = jnp.maximum(kappa, 1e-12)
    w = 1.0 + jnp.log(u + (1.0 - u) * jnp.exp(-2.0 * kappa)) / kappa
    w = jnp.clip(w, -1.0, 1.0)
    phi = 2.0 * jnp.pi * jax.random.uniform(k_phi, kappa.shape, dtype=mean.dtype)
    helper = jnp.where(jnp.abs(mean[..., :1]) < 0.9, jnp.array([1.0, 0, 0]), jnp.array([0, 1.0, 0]))
    e1 = helper - jnp.sum(helper * mean, -1, keepdims=True) * mean
    e1 = e1 / jnp.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = jnp.cross(mean, e1)
    sine = jnp.sqrt(1.0 - w**2)
    across = (sine * jnp.cos(phi))[..., None] * e1 + (sine * jnp.sin(phi))[..., None] * e2
    return w[..., None] * mean + across


def _field(s):
    return sum(jnp.roll(s, d, axis=a) for a in range(3) for d in (1, -1))


def reference_step(key, s, beta):
    """One heat-bath sweep and one over-relaxation sweep of the periodic cubic lattice (J = 1,
    even L), one parity at a time; every site drawn, the other parity's draws discarded."""
    size = s.shape[0]
    grid = np.indices((size, size, size)).sum(0) % 2
    for parity, k in zip((0, 1), jax.random.split(key)):
        f = _field(s)
        norm = jnp.linalg.norm(f, axis=-1)
        new = _reference_vmf(k, f / norm[..., None], beta * norm)
        s = jnp.where((grid == parity)[..., None], new, s)
    for parity in (0, 1):
        f = _field(s)
        f = f / jnp.linalg.norm(f, axis=-1, keepdims=True)
        reflected = 2.0 * jnp.sum(s * f, -1, keepdims=True) * f - s
        s = jnp.where((grid == parity)[..., None], reflected, s)
    return s


class _Reference:
    """The reference heat bath as an ``init``/``step`` pair (the state is the spin array)."""

    def __init__(self, beta):
        self.beta = beta

    def init(self, position):
        return jnp.asarray(position)

    def step(self, key, state):
        return reference_step(key, state, self.beta), None


def positions(state):
    return state if isinstance(state, jax.Array) else state.position


# --------------------------------------------------------------------------- measurement


def observables(s):
    """``(|m|, E/N)`` of one configuration (J = 1, B = 0, periodic)."""
    n = s.size // 3
    bonds = sum(jnp.sum(s * jnp.roll(s, -1, axis=a)) for a in range(s.ndim - 1))
    return jnp.stack([jnp.linalg.norm(jnp.mean(s.reshape(-1, 3), axis=0)), -bonds / n])


def make_runner(algorithm, num_draws):
    """Compiled ``run(states, key, num_warmup) -> (draws (chains, draws, 2), states)``."""

    def run(states, key, num_warmup):
        def step(states, k):
            keys = jax.random.split(k, states_leaf(states).shape[0])
            states, _ = jax.vmap(algorithm.step)(keys, states)
            return states

        key_warm, key_draw = jax.random.split(key)
        states = jax.lax.fori_loop(
            0, num_warmup, lambda i, st: step(st, jax.random.fold_in(key_warm, i)), states
        )

        def draw(states, k):
            states = step(states, k)
            return states, jax.vmap(observables)(positions(states))

        states, draws = jax.lax.scan(draw, states, jax.random.split(key_draw, num_draws))
        return jnp.swapaxes(draws, 0, 1), states

    return liesample.jit(run)


def states_leaf(states):
    return jax.tree.leaves(states)[0]


def integrated_time(x, window_factor=6.0):
    """``(τ_int, error, window)`` of ``x`` (chains, draws): autocorrelation averaged over chains,
    Sokal's window (smallest ``W`` with ``W ≥ c τ(W)``), Madras–Sokal error
    ``τ √(2(2W + 1)/n)``, ``n`` all draws."""
    x = np.asarray(x, dtype=float)
    x = x - x.mean(axis=1, keepdims=True)
    chains, n = x.shape
    spectrum = np.fft.rfft(x, 2 * n, axis=1)
    acov = np.fft.irfft(np.abs(spectrum) ** 2, axis=1)[:, :n].mean(axis=0)
    if acov[0] <= 0:
        return float("nan"), float("nan"), 0
    rho = acov / acov[0]
    taus = 0.5 + np.cumsum(rho[1:])
    window = next((w for w in range(1, n - 1) if w >= window_factor * taus[w - 1]), n - 2)
    tau = max(float(taus[window - 1]), 0.5)
    return tau, tau * float(np.sqrt(2.0 * (2 * window + 1) / (chains * n))), window


def random_starts(shape, seed):
    x = np.random.default_rng(seed).normal(size=(NUM_CHAINS, *shape, 3))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def equilibrated_starts(system, beta, seed, steps=200):
    """``NUM_CHAINS`` configurations after ``steps`` Swendsen–Wang steps from random spins."""
    algorithm = liesample.heisenberg_cluster(system, beta=beta)
    states = jax.vmap(algorithm.init)(jnp.asarray(random_starts(system.event_shape[:-1], seed)))
    _, states = make_runner(algorithm, 1)(states, jax.random.key(seed), steps)
    return np.asarray(states.position)


def measure(label, algorithm, starts, budget, seed, log, extra):
    """Pilot for the cost per step, then a run that fills ``budget`` seconds; one row per
    quantity."""
    states = jax.vmap(algorithm.init)(jnp.asarray(starts))
    pilot_steps = 20
    pilot = make_runner(algorithm, pilot_steps)
    (_, states), _ = common.timed(pilot, states, jax.random.key(seed), 0)  # compiles
    (_, states), seconds = common.timed(pilot, states, jax.random.key(seed + 1), 0)
    per_step = seconds / pilot_steps
    num_draws = int(np.clip(0.9 * budget / per_step, 200, 50_000))
    num_warmup = max(20, num_draws // 10)
    run = make_runner(algorithm, num_draws).lower(states, jax.random.key(0), 0).compile()
    (draws, _), seconds = common.timed(run, states, jax.random.key(seed + 2), num_warmup)
    draws = np.asarray(draws)
    rows = []
    for i, quantity in enumerate(QUANTITIES):
        tau, tau_error, window = integrated_time(draws[..., i])
        ess = NUM_CHAINS * num_draws / (2.0 * tau)
        rows.append(
            {
                **extra,
                "sampler": label,
                "quantity": quantity,
                "mean": float(draws[..., i].mean()),
                "tau_int": tau,
                "tau_int_error": tau_error,
                "window": window,
                "ess": ess,
                "wall_seconds": seconds,
                "ms_per_step": 1e3 * seconds / ((num_warmup + num_draws) * NUM_CHAINS),
                "ess_per_second": ess / seconds,
                "draws_per_chain": num_draws,
                "warmup_steps": num_warmup,
                "chains": NUM_CHAINS,
            }
        )
        log(
            f"    {label:<28} {quantity:<18} {draws[..., i].mean():8.4f}  τ {tau:7.2f} ± "
            f"{tau_error:5.2f}  ESS {ess:7.0f}  {seconds:6.1f} s  ESS/s {ess / seconds:8.1f}"
        )
    return rows


def user_path(log):
    """The recommended sampler through ``liesample.sample`` (default warm-up, compilation
    included) against the reference heat bath run as long, also compiled in the timing."""
    size, draws = 8, USER_PATH_DRAWS
    system = heisenberg((size,) * 3, periodic=True)
    starts = random_starts((size,) * 3, 7)
    functions = {"abs_m": lambda s: observables(s)[0], "e": lambda s: observables(s)[1]}
    start = time.perf_counter()
    algorithm = liesample.recommended_sampler(system, beta=BETA_C)
    tree = liesample.sample(
        algorithm,
        jax.random.key(8),
        starts,
        draws,
        observables=functions,
        keep_positions=False,
        progress=False,
    )
    seconds = time.perf_counter() - start
    values = {q: np.asarray(tree.posterior[name]) for q, name in zip(QUANTITIES, functions)}
    rows = []
    reference = _Reference(BETA_C)
    start = time.perf_counter()
    ref_draws, _ = make_runner(reference, draws)(jnp.asarray(starts), jax.random.key(9), draws)
    ref_draws = np.asarray(ref_draws)
    ref_seconds = time.perf_counter() - start
    for i, quantity in enumerate(QUANTITIES):
        tau, tau_error, _ = integrated_time(values[quantity])
        ref_tau, ref_tau_error, _ = integrated_time(ref_draws[..., i])
        ess, ref_ess = NUM_CHAINS * draws / (2 * tau), NUM_CHAINS * draws / (2 * ref_tau)
        rows.append(
            {
                "lattice": f"{size}^3",
                "quantity": quantity,
                "sampler": algorithm.settings["sampler"],
                "seconds": seconds,
                "tau_int": tau,
                "tau_int_error": tau_error,
                "ess_per_second": ess / seconds,
                "reference_seconds": ref_seconds,
                "reference_tau_int": ref_tau,
                "reference_tau_int_error": ref_tau_error,
                "reference_ess_per_second": ref_ess / ref_seconds,
                "ratio": (ess / seconds) / (ref_ess / ref_seconds),
            }
        )
        log(
            f"  user path {quantity:<18} {algorithm.settings['sampler']}: {seconds:5.1f} s, τ "
            f"{tau:.2f}; reference {ref_seconds:5.1f} s, τ {ref_tau:.2f}; ratio "
            f"{rows[-1]['ratio']:.2f}"
        )
    return rows


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    user = user_path(log)  # first: nothing compiled for it yet
    rows = []
    for size in QUICK_SIZES if quick else SIZES:
        budget = QUICK_BUDGET_SECONDS if quick else BUDGET_SECONDS[size]
        system = heisenberg((size,) * 3, periodic=True)
        starts = equilibrated_starts(system, BETA_C, size)
        log(f"  {size}^3 at beta = {BETA_C}")
        extra = {"size": size, "beta": BETA_C}
        for label, build in SAMPLERS.items():
            rows += measure(label, build(system, BETA_C), starts, budget, 1, log, extra)
        rows += measure("reference heat bath", _Reference(BETA_C), starts, budget, 1, log, extra)
    choice = []
    runs = [(8, beta, QUICK_BUDGET_SECONDS) for beta in CHOICE_BETAS]
    if not quick:
        runs += [(s, b, CHOICE_LARGE_BUDGET) for s, betas in CHOICE_LARGE.items() for b in betas]
    for size, beta, budget in runs:
        log(f"  choice: {size}^3 at beta = {beta}")
        system = heisenberg((size,) * 3, periodic=True)
        starts = equilibrated_starts(system, beta, 3)
        for label, build in SAMPLERS.items():
            choice += measure(
                label, build(system, beta), starts, budget, 2, log, {"size": size, "beta": beta}
            )
    path = common.write_json(
        out_dir / "spins.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "rows": rows,
            "user_path": user,
            "choice": choice,
            "total_seconds": time.perf_counter() - start,
        },
    )
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


# --------------------------------------------------------------------------- report


def _row(rows, size, sampler, quantity):
    return next(
        (
            r
            for r in rows
            if r["size"] == size and r["sampler"] == sampler and r["quantity"] == quantity
        ),
        None,
    )


def _targets(results):
    lines = []
    for r in results["user_path"]:
        verdict = "meets" if r["ratio"] >= 1.0 else "misses"
        lines.append(
            f"| recommended (`{r['sampler']}`) through `liesample.sample` / reference heat bath, "
            f"{r['lattice']}, compile included | {r['quantity']} | {r['ratio']:.2f}× | ≥ 1× "
            f"({verdict}) |"
        )
    rows = results["rows"]
    largest = max(r["size"] for r in rows)
    for quantity in QUANTITIES:
        cluster = _row(rows, largest, "swendsen-wang", quantity)
        heat = _row(rows, largest, "heat bath + over-relaxation", quantity)
        ratio = cluster["ess_per_second"] / heat["ess_per_second"]
        if quantity == "abs_magnetisation":
            target = f"≥ 3× at L = 32 ({'meets' if ratio >= 3 else 'misses'})"
            if largest != 32:
                target = "≥ 3× at L = 32 (not run: quick mode)"
        else:
            target = "(no target)"
        lines.append(
            f"| swendsen-wang / heat bath + over-relaxation, {largest}^3 | {quantity} | "
            f"{ratio:.2f}× | {target} |"
        )
    return lines


def report_section(results) -> str:
    """The ``RESULTS.md`` section for the contents of ``spins.json``."""
    machine = results["machine"]
    rows = results["rows"]
    lines = [
        "## Classical spins: the 3-D Heisenberg critical point",
        "",
        (
            f"From `benchmarks/spins.py` ({machine['date_utc']}, {results['mode']} mode, "
            f"{results['total_seconds']:.0f} s, {machine['cpu_model']}, "
            f"{machine['usable_cpus']} usable CPUs, 1-min load average "
            f"{machine.get('load_average_1min')}, jax {machine['jax']}). The machine was shared "
            "with other jobs while this ran, so wall times (and ESS/s) are rough; the samplers "
            "of one lattice ran side by side in one process, so their ratios are steadier, and "
            "τ_int does not depend on the machine. Periodic L³ lattice, J = 1, no field, "
            f"β = {BETA_C}, {NUM_CHAINS} chains from equilibrated starts; τ_int in steps "
            "(Sokal window, Madras–Sokal error, which is the only error bar here: the "
            "means are printed without one); ESS/s over the sampling time, compilation "
            "excluded. A heat-bath step is one heat-bath and one over-relaxation sweep, a "
            "Swendsen–Wang step one update of every cluster."
        ),
        "",
        "Targets:",
        "",
        "| comparison | quantity | ratio of ESS/s | target |",
        "|---|---|---|---|",
        *_targets(results),
        "",
        "| L | sampler | quantity | mean | τ_int | ESS | ESS/s | ms/step/chain | draws/chain |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['size']} | {r['sampler']} | {r['quantity']} | {r['mean']:.4f} | "
            f"{r['tau_int']:.2f} ± {r['tau_int_error']:.2f} | {r['ess']:.0f} | "
            f"{r['ess_per_second']:.3g} | {r['ms_per_step']:.3g} | {r['draws_per_chain']} |"
        )
    sizes = sorted({r["size"] for r in rows})
    if len(sizes) > 1:
        lines += ["", "Growth of τ_int(|m|) with L (exponent z from the two largest L):", ""]
        lines += ["| sampler | " + " | ".join(f"L = {s}" for s in sizes) + " | z |"]
        lines += ["|---|" + "---|" * (len(sizes) + 1)]
        for sampler in dict.fromkeys(r["sampler"] for r in rows):
            taus = [_row(rows, s, sampler, "abs_magnetisation")["tau_int"] for s in sizes]
            z = np.log(taus[-1] / taus[-2]) / np.log(sizes[-1] / sizes[-2])
            lines.append(f"| {sampler} | " + " | ".join(f"{t:.2f}" for t in taus) + f" | {z:.2f} |")
    lines += [
        "",
        "Which library sampler wins (ESS/s of |m| and E; `liesample.recommended_sampler` "
        "follows this table and the rows above):",
        "",
        "| L | β | quantity | heat bath + OR ESS/s | swendsen-wang ESS/s | ratio SW/HB |",
        "|---|---|---|---|---|---|",
    ]
    choice = results["choice"]
    for size, beta in sorted({(r["size"], r["beta"]) for r in choice}):
        for quantity in QUANTITIES:
            heat, cluster = (
                next(
                    r
                    for r in choice
                    if r["size"] == size
                    and r["beta"] == beta
                    and r["sampler"] == s
                    and r["quantity"] == quantity
                )
                for s in SAMPLERS
            )
            lines.append(
                f"| {size} | {beta} | {quantity} | {heat['ess_per_second']:.3g} | "
                f"{cluster['ess_per_second']:.3g} | "
                f"{cluster['ess_per_second'] / heat['ess_per_second']:.2f} |"
            )
    lines.append("")
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``spins.json``, if it exists (``suites.report_sections``)."""
    del md_dir
    path = out_dir / "spins.json"
    if not path.exists():
        return ""
    return report_section(json.loads(path.read_text()))


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
