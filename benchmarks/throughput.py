"""1. Throughput: chain-steps per second of the vmapped sampler, and the exact i.i.d. sampler.

Each measurement jits ``vmap`` over chains of a loop of ``n`` sampler steps that carries only
the chain state (no trajectory, no per-step info: XLA drops the unused ``energy`` and
``casimir_error``). The loop is ``jax.lax.fori_loop`` with a traced trip count: the same XLA
``While`` loop that ``lax.scan`` lowers to, without stacked outputs, so one compilation serves
every ``n``. Compilation is excluded; calibration calls warm the executable up and pick ``n``
so that one call lasts about ``target_seconds``; the reported time is the best of ``repeats``.
Step ``k`` of chain ``c`` uses the key ``fold_in(key_c, k)`` as ``liesample.runner`` does, so the
cost of drawing the noise is included (and is absent where the scene has no noise).
"""

from __future__ import annotations

import time

import jax
import numpy as np

from benchmarks import common

import liesample

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


__all__ = ["RNG_ONLY", "run_iid_throughput", "run_sampler_throughput", "sanity_check_iid"]
