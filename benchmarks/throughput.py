"""1. Throughput: chain-steps per second of the vmapped sampler, and the exact i.i.d. sampler.

Each measurement jits ``vmap`` over chains of a loop of ``n`` sampler steps that carries only
the chain state (no trajectory, no per-step info: XLA drops the unused ``energy`` and
``casimir_error``). The loop is ``jax.lax.fori_loop`` with a traced trip count: the same XLA
``While`` loop that ``lax.scan`` lowers to, without stacked outputs, so one compilation serves
every ``n``. Compilation is excluded; calibration calls warm the executable up and pick ``n``
so that one call lasts about ``target_seconds``; the reported time is the best of ``repeats``.
Step ``k`` of chain ``c`` uses the key ``fold_in(key_c, k)`` (``sampler.step`` with per-step keys,
as BlackJAX's drivers call it), so the cost of drawing the noise is included (and is absent where
the scene has no noise); ``liesample.sample`` draws the orbit samplers' noise in blocks, which
the hand-fused comparison below measures.

**Library against a hand-fused step** (:func:`run_fused_comparison`; alone:
``benchmarks/throughput.py --fused [--quick]``, writes ``results/throughput_fused.json``). The
Metropolis-adjusted orbit step of the rigid body and of the heavy top, in one run: the library
(``liesample.adjusted_lie_poisson`` driven by ``liesample.integrators.chain_loop.run_steps``)
with its noise drawn per step (``fold_in`` + draw) and in blocks, and a hand-written loop of the
same scheme (closed-form gradients, brackets and coadjoint moves in plain ``jnp``, the same noise
blocks). The fused loop is checked to give the library's chain (same noise, max difference
recorded); the ratio fused ÷ library is the cost of the library's abstractions.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

import liesample
from benchmarks import common
from liesample.integrators.chain_loop import run_steps
from liesample.systems import heavy_top

RNG_ONLY = "RNG only (fold_in + 3 normals)"


def _loop(step):
    """``(states, keys, n) -> states`` after ``n`` steps of every chain.

    ``step(key, state) -> new_state``.
    """

    def run(states, keys, n):
        def chain(state, key):
            return jax.lax.fori_loop(0, n, lambda i, s: step(jax.random.fold_in(key, i), s), state)

        return jax.vmap(chain)(states, keys)

    return liesample.jit(run)


def _measure(run, states, keys, num_chains, cfg: common.Config):
    compile_start = time.perf_counter()
    compiled = run.lower(states, keys, 1).compile()
    compile_seconds = time.perf_counter() - compile_start

    # Calibrate (and warm up): grow n until a call lasts ≥ 50 ms, then scale to the target.
    n = max(1, 20_000 // num_chains)
    while True:
        _, seconds = common.timed(compiled, states, keys, n)
        if seconds >= 0.05 or n >= 10**8:
            break
        n *= 4
    n = max(1, round(n * cfg.throughput_target_seconds / seconds))
    final, seconds = common.timed(compiled, states, keys, n)  # warm call at the final n
    times = [seconds]
    for _ in range(cfg.throughput_repeats - 1):
        final, seconds = common.timed(compiled, states, keys, n)
        times.append(seconds)
    best = min(times)
    return final, {
        "chains": num_chains,
        "steps": n,
        "seconds_best": best,
        "seconds_all": times,
        "chain_steps_per_second": num_chains * n / best,
        "compile_seconds": compile_seconds,
    }


def _initial(num_chains, key):
    """Exact Gibbs draws on |μ| = r, one per chain, and one key per chain."""
    k_pos, k_chain = jax.random.split(key)
    positions = common.target().sample(k_pos, num_chains)
    return positions, jax.random.split(k_chain, num_chains)


def run_sampler_throughput(cfg: common.Config, log=print) -> list[dict]:
    pairs = cfg.throughput_pairs or tuple(
        (name, scene) for name in common.INTEGRATOR_NAMES for scene in common.SCENES
    )
    key = jax.random.key(cfg.seed)
    rows = []
    for num_chains in cfg.throughput_chains:
        positions, keys = _initial(num_chains, jax.random.fold_in(key, num_chains))
        for integrator, scene in pairs:
            algorithm = common.sampler(integrator, scene, cfg.throughput_step_size)
            states = jax.vmap(algorithm.init)(positions)
            run = _loop(lambda k, s, step=algorithm.step: step(k, s)[0])
            final, row = _measure(run, states, keys, num_chains, cfg)
            # How many chains ended off their orbit (|C − C₀|/C₀ > tolerance) or non-finite.
            c_final = np.sum(np.asarray(final.position) ** 2, axis=-1)
            drift = np.abs(c_final - common.RADIUS**2) / common.RADIUS**2
            off = ~np.isfinite(drift) | (drift > cfg.casimir_tolerance)
            row.update(
                integrator=integrator,
                scene=scene,
                step_size=cfg.throughput_step_size,
                off_orbit_fraction=float(np.mean(off)),
            )
            rows.append(row)
            log(
                f"  {integrator:>10} | {scene:<34} | {num_chains:>6} chains: "
                f"{row['chain_steps_per_second']:.3g} chain-steps/s "
                f"(n={row['steps']}, {row['seconds_best']:.2f} s, compile "
                f"{row['compile_seconds']:.2f} s)"
            )
        # Reference: the noise draw alone, with the same key scheme.
        run = _loop(lambda k, s: s + jax.random.normal(k, s.shape, s.dtype))
        _, row = _measure(run, positions, keys, num_chains, cfg)
        row.update(integrator=RNG_ONLY, scene="-", step_size=None, off_orbit_fraction=None)
        rows.append(row)
        log(
            f"  {RNG_ONLY:>10} | {num_chains:>6} chains: "
            f"{row['chain_steps_per_second']:.3g} draws/s"
        )
    return rows


def run_iid_throughput(cfg: common.Config, log=print) -> list[dict]:
    """Samples per second of the exact rejection sampler ``RestrictedGaussian.sample``."""
    target = common.target()
    key = jax.random.key(cfg.seed + 1)
    rows = []
    for size in cfg.iid_sizes:
        compile_start = time.perf_counter()
        common.block(target.sample(jax.random.fold_in(key, 0), size))  # compile + warm-up
        first_call = time.perf_counter() - compile_start
        times = []
        for r in range(cfg.throughput_repeats):
            _, seconds = common.timed(target.sample, jax.random.fold_in(key, r + 1), size)
            times.append(seconds)
        best = min(times)
        rows.append(
            {
                "samples": size,
                "seconds_best": best,
                "seconds_all": times,
                "samples_per_second": size / best,
                "first_call_seconds": first_call,
            }
        )
        log(f"  exact iid sampler, {size:>8} samples: {size / best:.3g} samples/s")
    return rows


def sanity_check_iid(n=200_000, seed=0) -> dict:
    """The i.i.d. sampler's E[μ_i²] against the exact values (a check that it is the limit)."""
    draws = np.asarray(common.target().sample(jax.random.key(seed), n))
    m2 = draws**2
    est = m2.mean(0)
    se = m2.std(0, ddof=1) / np.sqrt(n)
    exact = common.exact_second_moments()
    return {
        "samples": n,
        "estimate": est,
        "exact": exact,
        "se": se,
        "z": (est - exact) / se,
        "variance": m2.var(0, ddof=1),
        "radius_error": float(np.max(np.abs(np.linalg.norm(draws, axis=1) - common.RADIUS))),
    }


# --------------------------------------------------------------------------- hand-fused step

FUSED_NAME = "throughput_fused"
FUSED_FULL = {"chains": (1, 1000), "block_size": 32, "target_seconds": 0.6, "repeats": 5}
FUSED_QUICK = {"chains": (1000,), "block_size": 32, "target_seconds": 0.15, "repeats": 3}
HEAVY_TOP = {"inertia": (1.0, 1.5, 2.0), "mgl": 1.0, "chi": (0.0, 0.0, 1.0)}
FUSED_SETTINGS = {  # (β, step) of the adjusted sampler per system: acceptance ≈ 0.5–0.7
    "rigid body": (common.BETA, 1.0),
    "heavy top": (1.0, 0.3),
}


def _cross(a, b):
    return jnp.stack(
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    )


def _rotate(axis, x):
    """``Ad*_{exp a} x`` on so(3)*: ``x − (sin θ/θ) a×x + ((1−cos θ)/θ²) a×(a×x)``, θ = |a|."""
    theta = jnp.sqrt(jnp.sum(axis * axis))
    a_x = _cross(axis, x)
    return x - jnp.sin(theta) / theta * a_x + (1 - jnp.cos(theta)) / theta**2 * _cross(axis, a_x)


def _fused_rigid_body(inertia):
    """``(energy_and_brackets(μ), move(c, μ))`` for the rigid body, by hand: ∇h = μ/I,
    ``{h, ĥ_i} = −(μ × ∇h)_i``, the move is the rotation of :func:`_rotate`."""
    inverse = 1.0 / np.asarray(inertia)

    def energy_and_brackets(mu):
        omega = inverse * mu
        return 0.5 * jnp.sum(omega * mu), -_cross(mu, omega)

    return energy_and_brackets, _rotate


def _fused_heavy_top(inertia, mgl, chi):
    """The same for the heavy top on se(3)*: ∇h = (Π/I, mgl χ), brackets
    ``−ad*_{∇h} μ = −(Π×Ω + Γ×g, Γ×Ω)``, and the se(3)* coadjoint move in closed form."""
    inverse = 1.0 / np.asarray(inertia)
    g = mgl * np.asarray(chi)

    def energy_and_brackets(mu):
        pi, gamma = mu[:3], mu[3:]
        omega = inverse * pi
        energy = 0.5 * jnp.sum(omega * pi) + jnp.sum(g * gamma)
        brackets = jnp.concatenate([_cross(pi, omega) + _cross(gamma, g), _cross(gamma, omega)])
        return energy, -brackets

    def move(c, mu):
        a, v, pi, gamma = c[:3], c[3:], mu[:3], mu[3:]
        theta_sq = jnp.sum(a * a)
        theta = jnp.sqrt(theta_sq)
        a_v = _cross(a, v)
        w = v - (1 - jnp.cos(theta)) / theta_sq * a_v
        w = w + (theta - jnp.sin(theta)) / (theta * theta_sq) * _cross(a, a_v)
        gamma_new = _rotate(a, gamma)
        return jnp.concatenate([_rotate(a, pi) + _cross(gamma_new, w), gamma_new])

    return energy_and_brackets, move


def _fused_loop(energy_and_brackets, move, num_noises, beta, step_size, block_size):
    """``(positions, keys, n) -> positions``: ``n`` adjusted steps per chain, written by hand
    (sigma = 1), the noise in blocks ``normal(fold_in(key, b), (B, m + 1))`` as the library."""
    theta = 0.5 * beta
    drift, scale = theta * step_size, np.sqrt(step_size)

    def step(row, carry):
        mu, energy, brackets = carry
        normals, accept = row[:num_noises], row[num_noises]
        c = -drift * brackets + scale * normals
        proposal = move(c, mu)
        new_energy, new_brackets = energy_and_brackets(proposal)
        reverse = (-c + drift * new_brackets) / scale
        log_ratio = (
            -beta * (new_energy - energy) - 0.5 * jnp.sum(reverse**2) + 0.5 * jnp.sum(normals**2)
        )
        ok = jnp.all(jnp.isfinite(proposal)) & jnp.isfinite(log_ratio)
        accepted = ok & (jax.scipy.special.log_ndtr(accept) < log_ratio)
        return (
            jnp.where(accepted, proposal, mu),
            jnp.where(accepted, new_energy, energy),
            jnp.where(accepted, new_brackets, brackets),
        )

    def run(positions, keys, n):
        def chain(mu, key):
            def one_block(b, carry):
                noise = jax.random.normal(
                    jax.random.fold_in(key, b), (block_size, num_noises + 1), mu.dtype
                )
                high = jnp.clip(n - b * block_size, 0, block_size)
                return jax.lax.fori_loop(0, high, lambda j, c: step(noise[j], c), carry)

            carry = (mu, *energy_and_brackets(mu))
            num_blocks = (n + block_size - 1) // block_size
            return jax.lax.fori_loop(0, num_blocks, one_block, carry)[0]

        return jax.vmap(chain)(positions, keys)

    return liesample.jit(run)


def _library_loop(algorithm, blocked):
    """``(positions, keys, n) -> positions`` through ``run_steps`` (per-step keys when not
    ``blocked``)."""
    if not blocked:
        algorithm = liesample.samplers.contract.Sampler(algorithm.init, algorithm.step)

    def run(positions, keys, n):
        def chain(mu, key):
            return run_steps(algorithm, key, algorithm.init(mu), 0, n)[0].position

        return jax.vmap(chain)(positions, keys)

    return liesample.jit(run)


def _measure_interleaved(loops, positions, keys, num_chains, cfg):
    """:func:`_measure` for several loops at once: each calibrated alone, then the timed calls
    taken in turns (a load change on a shared machine hits every loop alike); best of
    ``repeats``."""
    timing = common.Config(mode="fused", throughput_target_seconds=cfg["target_seconds"])
    compiled, steps, times = {}, {}, {}
    for label, loop in loops.items():
        compiled[label] = loop.lower(positions, keys, 1).compile()
        n = max(1, 20_000 // num_chains)
        while True:
            _, seconds = common.timed(compiled[label], positions, keys, n)
            if seconds >= 0.05 or n >= 10**8:
                break
            n *= 4
        steps[label] = max(1, round(n * timing.throughput_target_seconds / seconds))
        times[label] = []
    for _ in range(cfg["repeats"]):
        for label in loops:
            _, seconds = common.timed(compiled[label], positions, keys, steps[label])
            times[label].append(seconds)
    return {
        label: {
            "chains": num_chains,
            "steps": steps[label],
            "seconds_best": min(times[label]),
            "seconds_all": times[label],
            "chain_steps_per_second": num_chains * steps[label] / min(times[label]),
        }
        for label in loops
    }


def _fused_case(name):
    if name == "rigid body":
        system = common.system()
        pieces = _fused_rigid_body(common.INERTIA)
    else:
        system = heavy_top(**HEAVY_TOP)
        pieces = _fused_heavy_top(**HEAVY_TOP)
    return system, pieces


def _starts(system, name, num_chains, key):
    if name == "rigid body":
        return common.target().sample(key, num_chains)
    base = jnp.asarray(system.default_position)
    tilt = jnp.concatenate([jnp.array([0.3, -0.2, 0.1]), jnp.zeros(3)])
    return jnp.tile(base + tilt, (num_chains, 1))


def run_fused_comparison(quick: bool = False, log=print) -> dict:
    """Chain-steps per second of the library's adjusted step (per-step keys, blocks) and of a
    hand-fused loop of the same scheme, rigid body and heavy top, measured side by side."""
    cfg = FUSED_QUICK if quick else FUSED_FULL
    rows = []
    for name, (beta, step_size) in FUSED_SETTINGS.items():
        system, (energy_and_brackets, move) = _fused_case(name)
        algorithm = liesample.adjusted_lie_poisson(
            system, beta=beta, step_size=step_size, noise_block_size=cfg["block_size"]
        )
        loops = {
            "library, per-step keys": _library_loop(algorithm, blocked=False),
            "library, noise blocks": _library_loop(algorithm, blocked=True),
            "hand-fused, noise blocks": _fused_loop(
                energy_and_brackets, move, system.num_noises, beta, step_size, cfg["block_size"]
            ),
        }
        for num_chains in cfg["chains"]:
            key = jax.random.fold_in(jax.random.key(7), num_chains)
            positions = _starts(system, name, num_chains, key)
            keys = jax.random.split(jax.random.fold_in(key, 1), num_chains)
            check = {label: np.asarray(loop(positions, keys, 200)) for label, loop in loops.items()}
            agreement = float(
                np.max(np.abs(check["hand-fused, noise blocks"] - check["library, noise blocks"]))
            )
            measured = _measure_interleaved(loops, positions, keys, num_chains, cfg)
            library = measured["library, noise blocks"]["chain_steps_per_second"]
            per_step = measured["library, per-step keys"]["chain_steps_per_second"]
            fused = measured["hand-fused, noise blocks"]["chain_steps_per_second"]
            rows.append(
                {
                    "system": name,
                    "chains": num_chains,
                    "beta": beta,
                    "step_size": step_size,
                    "block_size": cfg["block_size"],
                    "measurements": measured,
                    "fused_over_library": fused / library,
                    "blocks_over_per_step": library / per_step,
                    "max_difference_after_200_steps": agreement,
                }
            )
            log(
                f"  {name:>10}, {num_chains:>5} chains: library {per_step:.3g} (per-step keys), "
                f"{library:.3g} (blocks), hand-fused {fused:.3g} chain-steps/s; fused ÷ library "
                f"{fused / library:.2f}, blocks ÷ per-step {library / per_step:.2f}, "
                f"max |Δ| {agreement:.1e}"
            )
    return {"config": cfg, "machine": common.machine_info(), "rows": rows}


def fused_report_section(out_dir: Path) -> str:
    path = out_dir / f"{FUSED_NAME}.json"
    if not path.exists():
        return ""
    data = common.read_json(path)
    machine = data["machine"]
    lines = [
        "### The library's step against a hand-fused step",
        "",
        (
            f"`benchmarks/throughput.py --fused` ({machine['date_utc']}, {machine['usable_cpus']} "
            f"CPUs {machine['cpu_model']}, jax {machine['jax']}): the Metropolis-adjusted orbit "
            "step (`liesample.adjusted_lie_poisson`, driven by `run_steps`) against a "
            "hand-written loop of the same scheme in plain `jnp` (closed-form brackets and "
            f"coadjoint moves) with the same noise blocks of {data['config']['block_size']} "
            "steps; chain-steps per second, best of "
            f"{data['config']['repeats']}. Max |Δ| is the largest difference between the two "
            "chains after 200 steps from the same keys (same scheme, same draws)."
        ),
        "",
        (
            "| system | chains | library, per-step keys | library, noise blocks | hand-fused | "
            "blocks ÷ per-step | fused ÷ library | max abs difference |"
        ),
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        m = r["measurements"]
        lines.append(
            f"| {r['system']} (β = {r['beta']:g}, dt = {r['step_size']:g}) | {r['chains']:,} | "
            f"{common.format_rate(m['library, per-step keys']['chain_steps_per_second'])} | "
            f"{common.format_rate(m['library, noise blocks']['chain_steps_per_second'])} | "
            f"{common.format_rate(m['hand-fused, noise blocks']['chain_steps_per_second'])} | "
            f"{r['blocks_over_per_step']:.2f}× | {r['fused_over_library']:.2f}× | "
            f"{r['max_difference_after_200_steps']:.1e} |"
        )
    lines.append("")
    return "\n".join(lines)


# --------------------------------------------------------------------------- plots and tables


def plot_throughput(rows, iid_rows, path: Path) -> Path:
    chains = sorted({r["chains"] for r in rows})
    integrators = [n for n in common.INTEGRATOR_NAMES if any(r["integrator"] == n for r in rows)]
    scenes = [s for s in common.SCENES if any(r["scene"] == s for r in rows)]
    lookup = {(r["integrator"], r["scene"], r["chains"]): r for r in rows}
    fig = Figure(figsize=(4.6 * len(chains), 5.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(chains), sharey=True))
    width = 0.8 / max(len(scenes), 1)
    hatches = ["", "//", ".."]
    for ax, n in zip(axes, chains, strict=True):
        for k, scene in enumerate(scenes):
            xs, ys = [], []
            for i, name in enumerate(integrators):
                r = lookup.get((name, scene, n))
                if r is not None:
                    xs.append(i + (k - (len(scenes) - 1) / 2) * width)
                    ys.append(r["chain_steps_per_second"])
            ax.bar(
                xs,
                ys,
                width,
                label=scene,
                color=f"C{k}",
                hatch=hatches[k % 3],
                edgecolor="k",
                lw=0.4,
            )
        rng = lookup.get((RNG_ONLY, "-", n))
        if rng is not None:
            ax.axhline(
                rng["chain_steps_per_second"],
                color="0.3",
                ls="--",
                lw=1.2,
                label="RNG only (fold_in + 3 normals)",
            )
        if iid_rows:
            best = max(r["samples_per_second"] for r in iid_rows)
            ax.axhline(best, color="C3", ls=":", lw=1.6, label="exact iid sampler (samples/s)")
        ax.set_xticks(range(len(integrators)), integrators, rotation=20)
        ax.set_yscale("log")
        ax.set_title(common.chains_label(n) + " (vmapped)")
        ax.grid(axis="y", which="both", alpha=0.3)
    axes[0].set_ylabel("chain-steps per second (best of 3)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize="small")
    fig.suptitle("Throughput of the rigid-body sampler (float64, CPU)")
    return common.save_figure(fig, path)


def _throughput_tables(rows, iid_rows):
    chains = sorted({r["chains"] for r in rows})
    lookup = {(r["integrator"], r["scene"], r["chains"]): r for r in rows}
    head = "| integrator | scene | " + " | ".join(common.chains_label(n) for n in chains) + " |"
    lines = [head, "|" + "---|" * (2 + len(chains))]
    for name in common.INTEGRATOR_NAMES:
        for scene in common.SCENES:
            cells = [lookup.get((name, scene, n)) for n in chains]
            if all(c is None for c in cells):
                continue
            vals = []
            for c in cells:
                if c is None:
                    vals.append("–")
                    continue
                v = common.format_rate(c["chain_steps_per_second"])
                if c.get("off_orbit_fraction"):
                    v += f" ({c['off_orbit_fraction']:.0%} off orbit)"
                vals.append(v)
            lines.append(f"| {name} | {scene} | " + " | ".join(vals) + " |")
    vals = [
        common.format_rate(lookup[(RNG_ONLY, "-", n)]["chain_steps_per_second"])
        if (RNG_ONLY, "-", n) in lookup
        else "–"
        for n in chains
    ]
    lines.append(f"| *reference* | {RNG_ONLY}, draws/s | " + " | ".join(vals) + " |")
    table = "\n".join(lines)

    ratio_lines = [
        "| integrator | "
        + " | ".join(f"H-only ÷ all, {common.chains_label(n)}" for n in chains)
        + " | "
        + " | ".join(f"no-H ÷ all, {common.chains_label(n)}" for n in chains)
        + " |",
        "|" + "---|" * (1 + 2 * len(chains)),
    ]
    for name in common.INTEGRATOR_NAMES:
        base = [lookup.get((name, "all effects", n)) for n in chains]
        if any(b is None for b in base):
            continue
        cells = []
        for scene in ("Hamiltonian only", "noise+dissipation, no Hamiltonian"):
            for b, n in zip(base, chains, strict=True):
                r = lookup.get((name, scene, n))
                cells.append(
                    "–"
                    if r is None
                    else f"{r['chain_steps_per_second'] / b['chain_steps_per_second']:.2f}×"
                )
        if any(c != "–" for c in cells):
            ratio_lines.append(f"| {name} | " + " | ".join(cells) + " |")
    ratios = "\n".join(ratio_lines) if len(ratio_lines) > 2 else "_(not measured in this mode)_"

    iid_lines = ["| draws per call | samples/s (best of 3) | time per call |", "|---|---|---|"]
    for r in iid_rows:
        iid_lines.append(
            f"| {r['samples']:,} | {common.format_rate(r['samples_per_second'])} "
            f"| {common.format_seconds(r['seconds_best'])} |"
        )
    return table, ratios, "\n".join(iid_lines)


# --------------------------------------------------------------------------- report sections


def report_section(results: common.CoreResults) -> str:
    """Section 1 of ``RESULTS.md`` (throughput of the vmapped sampler), with its plot."""
    cfg = results.config
    plot = plot_throughput(
        results.throughput_rows, results.iid["rows"], results.out_dir / "throughput.png"
    )
    results.written.append(plot)
    tp_table, ratio_table, _ = _throughput_tables(results.throughput_rows, results.iid["rows"])
    return f"""## 1. Throughput

Chain-steps per second of `liesample.lie_poisson_langevin(system, …, step_size=
{cfg["throughput_step_size"]:g})`, `jax.jit(jax.vmap(chain))` where each chain is a
`jax.lax.fori_loop` of `n` calls to `algorithm.step` carrying only the state (the same XLA
While loop `lax.scan` lowers to, without stacked outputs; a traced trip count lets one
compilation serve every `n`). Step `k` of chain `c` uses `fold_in(key_c, k)` (per-step
keys; `liesample.sample` draws the noise in blocks, measured in the last table of this
section). Chains start from exact Gibbs draws. Compilation is excluded; calls
are warmed up, `n` is chosen so that one call lasts ≈ {cfg["throughput_target_seconds"]:g} s,
and the time is the best of {cfg["throughput_repeats"]}. Per-step `info` is not kept, so XLA
drops the energy and Casimir diagnostics (the non-finite guard stays: it decides the state).

Scenes: **all effects** (β = 3, σ = 1); **Hamiltonian only** (`sigma=0, theta=0`: noise and
dissipation are not traced at all and no random numbers are drawn); **noise+dissipation, no
Hamiltonian** (`hamiltonian=False`). "off orbit" marks chains whose final |μ|² is more than
10% from r² (or non-finite).

{tp_table}

Speed-up relative to all effects (> 1 = faster):

{ratio_table}

![throughput]({results.link(plot)})

{fused_report_section(results.out_dir)}"""


def iid_report_section(results: common.CoreResults) -> str:
    """Section 3 of ``RESULTS.md``: the exact i.i.d. sampler (the physical limit)."""
    _, _, iid_table = _throughput_tables(results.throughput_rows, results.iid["rows"])
    return f"""## 3. Exact iid sampler (the physical limit)

`RestrictedGaussian.sample(key, n)` (rejection from an angular central Gaussian envelope), jitted,
warmed up, best of {results.config["throughput_repeats"]}:

{iid_table}
"""


__all__ = [
    "RNG_ONLY",
    "fused_report_section",
    "iid_report_section",
    "plot_throughput",
    "report_section",
    "run_fused_comparison",
    "run_iid_throughput",
    "run_sampler_throughput",
    "sanity_check_iid",
]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="library step against a hand-fused step")
    parser.add_argument("--fused", action="store_true", help="run the hand-fused comparison")
    parser.add_argument("--quick", action="store_true", help="shorter timings, 1000 chains")
    args = parser.parse_args(argv)
    if not args.fused:
        parser.error("the core throughput runs from benchmarks/run.py; pass --fused here")
    out_dir = common.BENCH_DIR / "results" / ("quick" if args.quick else "")
    data = run_fused_comparison(args.quick)
    path = common.write_json(out_dir / f"{FUSED_NAME}.json", data)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
