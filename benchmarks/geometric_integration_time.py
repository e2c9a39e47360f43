"""Trajectory length of geometric HMC: ESS per gradient against the integration time T.

For each target, ``liesample.window_adaptation`` tunes step size and mass with
``integration_time=T`` (``num_integration_steps = ceil(T / step_size)``), then 8 chains of
``--draws`` draws run from the adapted state; the ESS (bulk, ``arviz_stats``) of each
observable is divided by the gradient evaluations of all chains. Standalone:

    python benchmarks/geometric_integration_time.py [--quick]

The table it prints is the one quoted in ``docs/groups.md``.
"""

from __future__ import annotations

import argparse
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import arviz_stats
from scipy.stats import vonmises_fisher

import liesample
from liesample import spaces as S
from liesample.targets.groups import VonMisesFisherPosterior

NUM_CHAINS = 8


def targets():
    mu5 = jnp.array([0.5, -0.5, 0.5, 0.5, 0.0, 0.0])
    F = jnp.diag(jnp.array([4.0, 2.0, -1.0]))
    data = vonmises_fisher(np.array([0.0, 0.6, 0.8]), 5.0).rvs(
        20, random_state=np.random.default_rng(1)
    )
    posterior = VonMisesFisherPosterior(data, prior_mean=1.0, prior_sd=1.0)
    L = 4

    def lattice(p):
        h, v = p["h"], p["v"]
        dag = lambda u: jnp.conj(jnp.swapaxes(u, -1, -2))
        u = h[:, :-1] @ v[1:, :] @ dag(h[:, 1:]) @ dag(v[:-1, :])
        return 2.5 * jnp.sum(0.5 * jnp.real(jnp.trace(u, axis1=-2, axis2=-1)))

    def plaquette(p):
        h, v = p["h"], p["v"]
        dag = lambda u: jnp.conj(jnp.swapaxes(u, -1, -2))
        u = h[:, :-1] @ v[1:, :] @ dag(h[:, 1:]) @ dag(v[:-1, :])
        return 0.5 * jnp.real(jnp.trace(u, axis1=-2, axis2=-1))[0, 0][None]

    su2 = {"h": S.SU(2, shape=(L - 1, L)), "v": S.SU(2, shape=(L, L - 1))}
    return {
        "vMF on S^5, kappa=10": (
            lambda x: 10.0 * jnp.dot(mu5, x),
            S.Sphere(5),
            jnp.eye(6)[0],
            lambda x: jnp.array([jnp.dot(mu5, x), x[4]]),
        ),
        "matrix Fisher on SO(3), F=diag(4,2,-1)": (
            lambda R: jnp.sum(F * R),
            S.SO(3),
            jnp.eye(3),
            lambda R: jnp.concatenate([jnp.diagonal(R), R[0, 1:2]]),
        ),
        "vMF posterior on S^2 x R": (
            posterior.logdensity,
            {"direction": S.Sphere(2), "log_kappa": S.Euclidean(())},
            {"direction": jnp.array([1.0, 0.0, 0.0]), "log_kappa": jnp.asarray(0.0)},
            lambda p: jnp.concatenate([p["direction"], p["log_kappa"][None]]),
        ),
        "2-D SU(2) lattice 4x4, beta=2.5": (
            lattice,
            su2,
            S.uniform(su2, jax.random.key(0)),
            plaquette,
        ),
    }


def measure(logdensity, space, start, observables, integration_time, num_draws, key):
    k1, k2 = jax.random.split(key)
    warmup = liesample.window_adaptation(
        liesample.geometric_hmc, logdensity, space, integration_time=integration_time
    )
    (state, parameters), _ = warmup.run(k1, start, num_steps=500)
    sampler = liesample.geometric_hmc(logdensity, space, **parameters)

    def run(key):
        def body(state, key):
            state, info = sampler.step(key, state)
            return state, (observables(state.position), info.acceptance_rate)

        return jax.lax.scan(body, state, jax.random.split(key, num_draws))[1]

    draws, acceptance = liesample.jit(jax.vmap(run))(jax.random.split(k2, NUM_CHAINS))
    draws = np.asarray(draws)  # (chain, draw, observable)
    ess = np.array([arviz_stats.ess(draws[..., i]) for i in range(draws.shape[-1])])
    gradients = NUM_CHAINS * num_draws * parameters["num_integration_steps"]
    return parameters, float(np.mean(acceptance)), float(ess.min()) / gradients


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer draws and times")
    args = parser.parse_args(argv)
    num_draws = 300 if args.quick else 1000
    times = (
        (math.pi / 4, math.pi / 2, math.pi)
        if args.quick
        else (math.pi / 8, math.pi / 4, math.pi / 2, math.pi, 2 * math.pi)
    )
    print("| target | T | step size | L | acceptance | min ESS per 1000 gradients |")
    print("|---|---|---|---|---|---|")
    for name, (logdensity, space, start, observables) in targets().items():
        for T in times:
            t0 = time.perf_counter()
            parameters, acceptance, ess = measure(
                logdensity, space, start, observables, T, num_draws, jax.random.key(0)
            )
            print(
                f"| {name} | {T / math.pi:.3g}π | {parameters['step_size']:.3g} | "
                f"{parameters['num_integration_steps']} | {acceptance:.2f} | {1000 * ess:.1f} |"
                f"  <!-- {time.perf_counter() - t0:.0f} s -->",
                flush=True,
            )


if __name__ == "__main__":
    main()
