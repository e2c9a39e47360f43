"""Classical Heisenberg spins: Poisson–Langevin (stochastic LLG) against single-spin Metropolis.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/spins.py            # ~5 min on 2 cores
    .venv/bin/python benchmarks/spins.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``spins.json``. Two parts, on ``heisenberg((L, L), periodic=True)``,
J = 1, no field:

1. **Cost per chain-step** of ``liesample.lie_poisson_langevin`` (σ = 1, dt = 0.05) for
   ``L = 8, 16, 32``, 8 vmapped chains: the default ``splitting`` with the system's commuting
   noise groups (``noise_groups``: one spin axis on one checkerboard colour, 6 pieces per step)
   and without them (the engine's default, one of the ``3N`` directions at a time, each piece
   touching the whole state: ``O(N²)`` per step), the joint-generator integrators
   (``rkmk_heun``, ``lie_euler``), and one Metropolis sweep (``N`` single-spin proposals).
2. **ESS per second** of the energy per spin and of ``|m|`` (magnetisation per spin) at
   β = 0.5 and β = 1.4 (the correlation length of the 2-D model grows fast below T ≈ 0.7 J):
   the grouped splitting at dt = 0.05 and dt = 0.1 against checkerboard Metropolis (uniform and
   small-rotation proposals). ESS (bulk) comes from ``liesample.diagnostics.expectation_table``
   (ArviZ) over 8 chains started from random spins; ESS/s divides by the sampling wall time
   (compilation excluded, warm-up included, as in ``liesample.runner``); ``ess_per_1000_steps``
   is the machine-independent ESS per thousand chain-steps (a Metropolis step is a sweep of
   ``N`` proposals). Each Langevin estimate is compared with the pooled
   Metropolis estimate (``z_vs_metropolis``), which shows the step-size bias.
"""

from __future__ import annotations

import dataclasses
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
from liesample.diagnostics import expectation_table
from liesample.samplers.lie_poisson_langevin import LiePoissonState
from liesample.systems.heisenberg import heisenberg
from liesample.systems.heisenberg_metropolis import heisenberg_metropolis

SUITE = {"order": 30, "title": "classical spins: Langevin vs single-spin Metropolis"}

BETAS = (0.5, 1.4)
SIGMA = 1.0
NUM_CHAINS = 8


# --------------------------------------------------------------------------- samplers as steps


def langevin_step(system, beta, step_size, integrator="splitting"):
    """``step(key, s) -> s'`` of the public sampler (the Casimir reference is not needed)."""
    algorithm = liesample.lie_poisson_langevin(
        system, beta=beta, sigma=SIGMA, step_size=step_size, integrator=integrator
    )
    ones = jnp.ones(system.event_shape[:-1])

    def step(key, s):
        return algorithm.step(key, LiePoissonState(s, ones))[0].position

    return step


def metropolis_step(system, beta, proposal, scale=0.5):
    algorithm = heisenberg_metropolis(system, beta=beta, proposal=proposal, proposal_scale=scale)

    def step(key, s):
        return algorithm.step(key, algorithm.init(s))[0].position

    return step


def ungrouped(system):
    """The same system without its noise groups (the engine's default splitting)."""
    return dataclasses.replace(system, noise_groups=None)


def random_starts(shape, num_chains, seed):
    x = np.random.default_rng(seed).normal(size=(num_chains, *shape, 3))
    return jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True))


# --------------------------------------------------------------------------- 1. cost


def cost_table(sizes, max_seconds):
    """Milliseconds per chain-step for each sampler and lattice size (8 vmapped chains)."""
    rows = []
    for size in sizes:
        system = heisenberg((size, size), periodic=True)
        samplers = {"splitting (noise groups)": langevin_step(system, 1.0, 0.05)}
        samplers["splitting (one direction at a time)"] = langevin_step(
            ungrouped(system), 1.0, 0.05
        )
        samplers["rkmk_heun"] = langevin_step(system, 1.0, 0.05, "rkmk_heun")
        samplers["lie_euler"] = langevin_step(system, 1.0, 0.05, "lie_euler")
        samplers["metropolis sweep (uniform)"] = metropolis_step(system, 1.0, "uniform")
        starts = random_starts((size, size), NUM_CHAINS, 0)
        keys = jax.random.split(jax.random.key(0), NUM_CHAINS)
        for label, step in samplers.items():

            @liesample.jit
            def run(starts, keys, n, step=step):
                return jax.vmap(
                    lambda s, k: jax.lax.fori_loop(
                        0, n, lambda j, s: step(jax.random.fold_in(k, j), s), s
                    )
                )(starts, keys)

            compiled = run.lower(starts, keys, 1).compile()
            _, seconds = common.timed(compiled, starts, keys, 1)
            n = int(min(5000, max_seconds / max(seconds, 1e-6)))
            if n > 1:  # else one step already took the time budget: keep that measurement
                _, seconds = common.timed(compiled, starts, keys, n)
            n = max(n, 1)
            per = seconds / (n * NUM_CHAINS)
            rows.append(
                {
                    "sampler": label,
                    "lattice": f"{size}x{size}",
                    "sites": size * size,
                    "chains": NUM_CHAINS,
                    "steps_timed": n,
                    "ms_per_chain_step": 1e3 * per,
                }
            )
            print(f"  {size:>2}x{size:<2} {label:<36} {1e3 * per:10.4f} ms/chain-step", flush=True)
    return rows


# --------------------------------------------------------------------------- 2. ESS per second


def observables(s):
    """``(energy per spin, |m|)`` of one configuration (J = 1, B = 0, D = 0, periodic)."""
    n = s.size // 3
    bonds = sum(jnp.sum(s * jnp.roll(s, -1, axis=a)) for a in range(s.ndim - 1))
    return jnp.stack([-bonds / n, jnp.linalg.norm(jnp.mean(s.reshape(-1, 3), axis=0))])


def run_chains(step, starts, keys, num_draws, thinning, num_warmup):
    """Vmapped chains of ``step``: ``(observables (chains, draws, 2), wall seconds)``."""

    def chain(s, key):
        def advance(s, first, count):
            return jax.lax.fori_loop(
                0, count, lambda j, s: step(jax.random.fold_in(key, first + j), s), s
            )

        s = advance(s, 0, num_warmup)

        def draw(s, d):
            s = advance(s, num_warmup + d * thinning, thinning)
            return s, observables(s)

        return jax.lax.scan(draw, s, jnp.arange(num_draws))[1]

    compiled = liesample.jit(jax.vmap(chain)).lower(starts, keys).compile()
    draws, seconds = common.timed(compiled, starts, keys)
    return np.asarray(draws), seconds


QUANTITIES = ("energy_per_spin", "abs_magnetisation")


def ess_comparison(size, samplers, scale, seed):
    """Rows of ESS/s for each β and sampler; ``samplers[label] = (kind, arg, draws, thin, warm)``."""
    rows = []
    shape = (size, size)
    system = heisenberg(shape, periodic=True)
    for beta in BETAS:
        print(f"  {size}x{size}, beta = {beta}", flush=True)
        reference = None
        for label, (kind, arg, num_draws, thinning, num_warmup) in samplers.items():
            num_draws = max(40, int(num_draws * scale))
            num_warmup = int(num_warmup * scale)
            if kind == "langevin":
                step = langevin_step(system, beta, arg)
            else:
                step = metropolis_step(system, beta, *arg)
            starts = random_starts(shape, NUM_CHAINS, seed)
            keys = jax.random.split(jax.random.key(seed), NUM_CHAINS)
            draws, seconds = run_chains(step, starts, keys, num_draws, thinning, num_warmup)
            table = expectation_table(
                {q: draws[..., i] for i, q in enumerate(QUANTITIES)}, wall_time=seconds
            )
            if kind == "metropolis" and reference is None:
                reference = table
            for quantity, row in table.iterrows():
                z = np.nan
                if reference is not None and kind == "langevin":
                    ref = reference.loc[quantity]
                    z = (row["estimate"] - ref["estimate"]) / np.hypot(row["mcse"], ref["mcse"])
                rows.append(
                    {
                        "lattice": f"{size}x{size}",
                        "beta": beta,
                        "sampler": label,
                        "quantity": quantity,
                        "estimate": row["estimate"],
                        "mcse": row["mcse"],
                        "z_vs_metropolis": z,
                        "ess_bulk": row["ess_bulk"],
                        "r_hat": row["r_hat"],
                        "wall_seconds": seconds,
                        "chains": NUM_CHAINS,
                        "steps_per_chain": num_warmup + num_draws * thinning,
                        "warmup_steps": num_warmup,
                        "ess_per_second": row["ess_per_second"],
                        # machine-independent: ESS per 1000 chain-steps (warm-up included)
                        "ess_per_1000_steps": 1e3
                        * row["ess_bulk"]
                        / (NUM_CHAINS * (num_warmup + num_draws * thinning)),
                    }
                )
                print(
                    f"    {label:<28} {quantity:<18} {row['estimate']:8.4f} ± {row['mcse']:.4f}"
                    f"  z {z:+6.2f}  ESS {row['ess_bulk']:6.0f}  R̂ {row['r_hat']:.3f}"
                    f"  {seconds:5.1f} s  ESS/s {row['ess_per_second']:7.1f}",
                    flush=True,
                )
    return rows


def run(out_dir: Path, quick: bool, log=print) -> None:
    start = time.perf_counter()
    scale = 0.1 if quick else 1.0

    log("1. cost per chain-step (heisenberg((L, L), periodic=True), 8 chains)")
    cost = cost_table(sizes=(8, 16) if quick else (8, 16, 32), max_seconds=1.0)

    size = 32
    log(f"2. ESS per second on {size}x{size}")
    # Metropolis first: its pooled estimate is the reference the Langevin rows are compared to.
    # (kind, argument, draws, thinning, warm-up steps); a Metropolis step is one sweep.
    samplers = {
        "metropolis uniform": ("metropolis", ("uniform",), 600, 5, 1000),
        "metropolis rotation eps=0.5": ("metropolis", ("rotation", 0.5), 600, 5, 1000),
        "langevin splitting dt=0.1": ("langevin", 0.1, 250, 5, 500),
        "langevin splitting dt=0.05": ("langevin", 0.05, 200, 10, 1000),
    }
    ess = ess_comparison(size, samplers, scale, seed=1)

    path = common.write_json(
        out_dir / "spins.json",
        {
            "description": __doc__,
            "machine": common.machine_info(),
            "mode": "quick" if quick else "full",
            "sigma": SIGMA,
            "cost": cost,
            "ess": ess,
            "total_seconds": time.perf_counter() - start,
        },
    )
    log(f"wrote {path} in {time.perf_counter() - start:.0f} s")


def report(out_dir: Path, md_dir: Path) -> str:
    """Table from ``spins.json``, if it exists."""
    del md_dir
    path = out_dir / "spins.json"
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    lines = [
        "## Classical spins: Langevin vs single-spin Metropolis",
        "",
        (
            f"From `benchmarks/spins.py` ({data['machine']['date_utc']}, "
            f"{data['total_seconds']:.0f} s; the machine was shared, so wall times are rough — "
            "ESS per 1000 chain-steps does not depend on the machine). Periodic 32×32 Heisenberg "
            "lattice, J = 1, σ = 1, 8 chains; a Metropolis step is one checkerboard sweep."
        ),
        "",
        "| β | sampler | quantity | estimate ± MCSE | ESS/s | ESS per 1000 steps | R-hat |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in data["ess"]:
        lines.append(
            f"| {row['beta']} | {row['sampler']} | {row['quantity']} | "
            f"{row['estimate']:.4f} ± {row['mcse']:.4f} | {row['ess_per_second']:.3g} | "
            f"{row['ess_per_1000_steps']:.3g} | {row['r_hat']:.2f} |"
        )
    lines += [
        "",
        (
            "Metropolis wins here: it can decorrelate a spin in one move, while the Langevin "
            "dynamics rotates each spin diffusively by a small angle per step. R-hat > 1.01 at "
            "β = 1.4 marks runs that have not converged (critical slowing down)."
        ),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
