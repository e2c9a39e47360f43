"""Zeitlin's su(N) Euler model: cost per step against N, the deterministic scene against a
NumPy isospectral midpoint, and the sampler's ESS per second of ``h``.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/zeitlin.py            # a few minutes on 2 cores
    .venv/bin/python benchmarks/zeitlin.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``zeitlin.json``, ``zeitlin.png``, ``zeitlin_adjusted.json`` and ``zeitlin_noise.json``.
Parts:

1. **Cost per step** against ``N`` (one chain, compilation excluded, best of repeats) of
   ``lie_poisson_langevin(zeitlin_euler(N, noise_degree=2), beta=1, sigma=1)`` with the default
   ``splitting`` integrator (one Hamiltonian piece and 8 noise directions, 2 coadjoint moves
   each), and of the deterministic Euler scene (``sigma=0, theta=0``) with ``rkmk_heun`` and
   with the implicit ``isospectral_midpoint``. Every coadjoint move is an ``expm`` of an
   ``N × N`` complex matrix and two products: O(N³).
2. **Peer**: the same isospectral midpoint written in NumPy (complex BLAS matrix products, the
   inverse Laplacian by one sparse LU of the block-tridiagonal Laplacian, factored once;
   ``quflow`` is not on PyPI, so the peer is this project's own NumPy version), same step,
   tolerance and start.
3. **ESS/s of h** at ``N = 32, 64``: 4 chains (``L = 2``, ``β = 1``, ``σ = 1``, ``dt = 0.1``)
   from one start, ESS (bulk, ArviZ) of ``h`` after a warm-up, over the wall time of the timed
   run.
4. **The adjusted sampler** at ``N = 32, 64, 128`` (``zeitlin_adjusted.json``): seconds per
   chain-step now and as before the skew-Hermitian exponential (the same declaration on the
   plain ``Unitary`` algebra, full spectrum per step), in the same process, with one BLAS
   thread and with the default threads (each in its own subprocess); the floor (the
   exponential, its two conjugation products and the two products of ``[W, ∇h]``, batched over
   the same chains); ESS/s of ``h`` and of the ``ℓ = 1`` energy.
5. **Noise degree and smoothness** (``zeitlin_noise.json``): ESS per step of each degree's
   energy and steps to stationarity from points spread over the orbit, at ``β = ±N²/8``.

Parts 4 and 5 alone: ``run_adjusted(out_dir, quick, log)`` and ``run_noise(...)``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

# LAPACK's worker threads spin while waiting: on a shared, loaded 2-core machine that made
# expm/solve/eigh of 32×32 complex matrices 30–100× slower (measured). One thread each, set
# before NumPy or JAX loads LAPACK (when this suite runs alone).
# A worker of this suite started with LIESAMPLE_ZEITLIN_BENCH_WORKER=default keeps the default
# threads (to measure what a user gets).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    if os.environ.get("LIESAMPLE_ZEITLIN_BENCH_WORKER") != "default":
        os.environ.setdefault(_name, "1")

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import arviz
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from matplotlib.figure import Figure

import liesample
from benchmarks import common, suites
from liesample.dynamics.system import LiePoissonSystem
from liesample.geometry.algebras import Unitary
from liesample.samplers.orbit.adjusted_lie_poisson import build_kernel
from liesample.samplers.orbit.adjusted_lie_poisson import init as adjusted_init
from liesample.systems.zeitlin import isospectral_midpoint, random_vorticity, zeitlin_euler

_WORKER_FLAG = "LIESAMPLE_ZEITLIN_BENCH_WORKER"
SUITE = {"order": 70, "title": "Zeitlin su(N) Euler on the sphere"}

ENSTROPHY_PER_MODE = 1.0  # ‖W‖² = N: the vorticity's amplitude does not grow with N
EULER_STEP = 0.01
ESS_STEP = 0.1
MIDPOINT_TOLERANCE = 1e-14
MIDPOINT_MAX_ITERATIONS = 100


def _start(size):
    return random_vorticity(size, seed=0, enstrophy=0.5 * ENSTROPHY_PER_MODE * size)


def _cost_per_step(system, algorithm, start, repeats):
    """Seconds per step (best of two timed calls) and the spectrum drift after them."""
    state = algorithm.init(jnp.asarray(start))
    keys = jax.random.split(jax.random.key(0), repeats)

    def run(state, keys):
        return jax.lax.scan(lambda s, k: (algorithm.step(k, s)[0], None), state, keys)[0]

    compiled = liesample.jit(run).lower(state, keys).compile()
    best = math.inf
    for _ in range(2):
        out, seconds = common.timed(compiled, state, keys)
        best = min(best, seconds)
    drift = float(system.casimir_error(out.position, state.reference_casimirs))
    return best / repeats, drift


# ----------------------------------------------------------------------- NumPy peer


class NumpyIsospectralMidpoint:
    """Zeitlin's ``Ẇ = [P, W]``, ``P = Δ_N⁻¹W``, by the isospectral midpoint in NumPy/SciPy.

    ``W̃ ← W_n + h/2 [P̃, W̃] + h²/4 P̃W̃P̃`` to relative ``1e-14``, then
    ``W_{n+1} = W̃ + h/2 [P̃, W̃] − h²/4 P̃W̃P̃`` (Modin–Viviani). ``Δ_N⁻¹``: the ``2N − 1``
    tridiagonal blocks (the bands of :class:`QuantisedHarmonics`) as one sparse matrix, LU-factored
    once (``scipy.sparse.linalg.splu``), so each solve is O(N²) in compiled code.
    """

    def __init__(self, harmonics):
        self.size = n = harmonics.size
        lo, d, up = (np.asarray(b) for b in harmonics._solve_bands)
        matrix = scipy.sparse.diags(
            [lo.ravel()[1:], d.ravel(), up.ravel()[:-1]], [-1, 0, 1], format="csc"
        )
        self.lu = scipy.sparse.linalg.splu(matrix)
        index = np.arange(n)
        k, m = index[None, :], index[:, None]
        valid = index[None, :] < n - index[:, None]
        self.valid = valid
        self.rows_up = np.where(valid, k, 0)
        self.cols_up = np.where(valid, k + m, 0)
        self.below = valid.copy()
        self.below[0] = False  # the main diagonal comes from the upper copy

    def _solve(self, rhs):
        """Solve every diagonal's system; ``rhs`` complex of shape ``(2, N, N)``."""
        flat = rhs.reshape(2, -1)
        columns = np.concatenate([flat.real.T, flat.imag.T], axis=1)  # (N², 4)
        y = self.lu.solve(columns)
        return (y[:, :2] + 1j * y[:, 2:]).T.reshape(rhs.shape)

    def inverse_laplacian(self, w):
        """``Δ_N⁻¹W`` for a complex trace-free skew-Hermitian ``W``."""
        n = self.size
        upper = np.where(self.valid, w[self.rows_up, self.cols_up], 0)
        lower = np.where(self.valid, w[self.cols_up, self.rows_up], 0)
        main = upper[0] - upper[0].mean()
        main[n - 1] = 0.0
        upper[0] = main
        lower[0] = main
        y = self._solve(np.stack([upper, lower]))
        y[:, 0] -= y[0, 0].mean()
        p = np.zeros_like(w)
        p[self.rows_up[self.valid], self.cols_up[self.valid]] = y[0][self.valid]
        p[self.cols_up[self.below], self.rows_up[self.below]] = y[1][self.below]
        return -p

    def step(self, w0, h):
        w = w0
        scale = np.linalg.norm(w0)
        for _ in range(MIDPOINT_MAX_ITERATIONS):
            p = self.inverse_laplacian(w)
            new = w0 + 0.5 * h * (p @ w - w @ p) + 0.25 * h * h * p @ w @ p
            done = np.linalg.norm(new - w) <= MIDPOINT_TOLERANCE * scale
            w = new
            if done:
                break
        p = self.inverse_laplacian(w)
        return w + 0.5 * h * (p @ w - w @ p) - 0.25 * h * h * p @ w @ p


def _numpy_cost(system, start, repeats):
    peer = NumpyIsospectralMidpoint(system.params["harmonics"])
    algebra = system.algebra
    w0 = np.asarray(algebra.to_matrix(jnp.asarray(start)))
    assert np.allclose(
        peer.inverse_laplacian(w0),
        algebra.to_matrix(system.params["harmonics"].inverse_laplacian(start)),
        atol=1e-10,
    )
    best = math.inf
    for _ in range(2):
        w = w0
        begin = time.perf_counter()
        for _ in range(repeats):
            w = peer.step(w, EULER_STEP)
        best = min(best, time.perf_counter() - begin)
    spectrum = lambda m: np.linalg.eigvalsh(1j * m)
    drift = np.max(np.abs(spectrum(w) - spectrum(w0))) / np.linalg.norm(w0)
    return best / repeats, float(drift), w


def cost_against_size(quick, log):
    sizes = (16, 32) if quick else (16, 32, 64, 128, 256)
    rows = []
    for size in sizes:
        system = zeitlin_euler(size, noise_degree=2)
        start = _start(size)
        repeats = max(2, min(50, int(4e6 / size**3)))
        variants = {
            "sampler, splitting": liesample.lie_poisson_langevin(
                system, beta=1.0, sigma=1.0, step_size=0.05, stability="off"
            ),
            "Euler, rkmk_heun": liesample.lie_poisson_langevin(
                system, sigma=0.0, theta=0.0, step_size=EULER_STEP, integrator="rkmk_heun"
            ),
            "Euler, isospectral midpoint": liesample.lie_poisson_langevin(
                system, sigma=0.0, theta=0.0, step_size=EULER_STEP, integrator=isospectral_midpoint
            ),
        }
        for label, algorithm in variants.items():
            seconds, drift = _cost_per_step(system, algorithm, start, repeats)
            rows.append({"N": size, "variant": label, "seconds": seconds, "casimir_drift": drift})
            log(f"  N = {size:4d}, {label:28s}: {seconds * 1e3:10.3f} ms/step, drift {drift:.1e}")
        seconds, drift, w_numpy = _numpy_cost(system, start, repeats)
        rows.append(
            {
                "N": size,
                "variant": "Euler, NumPy isospectral midpoint (own)",
                "seconds": seconds,
                "casimir_drift": drift,
            }
        )
        log(f"  N = {size:4d}, {'NumPy isospectral midpoint':28s}: {seconds * 1e3:10.3f} ms/step")
        # Same trajectory: the JAX midpoint after `repeats` steps equals the NumPy one.
        midpoint = variants["Euler, isospectral midpoint"]
        state = midpoint.init(jnp.asarray(start))
        keys = jax.random.split(jax.random.key(0), repeats)
        final = _final_state(midpoint, state, keys)
        gap = float(np.max(np.abs(np.asarray(system.algebra.to_matrix(final.position)) - w_numpy)))
        rows[-1]["gap_to_jax"] = gap
        log(f"             NumPy vs JAX midpoint after {repeats} steps: max |ΔW| = {gap:.1e}")
    return rows


def _final_state(algorithm, state, keys):
    """The state after one step of ``algorithm`` per key, compiled."""

    def steps(state, keys):
        return jax.lax.scan(lambda s, k: (algorithm.step(k, s)[0], None), state, keys)[0]

    return liesample.jit(steps)(state, keys)


def _energy_chains(algorithm, num_steps):
    """``(states, keys) -> (states, h at each step)``: ``num_steps`` steps of every chain,
    vectorised and compiled."""

    def chain(state, key):
        def body(state, k):
            state, info = algorithm.step(k, state)
            return state, info.energy

        return jax.lax.scan(body, state, jax.random.split(key, num_steps))

    return liesample.jit(jax.vmap(chain))


def ess_per_second(quick, log):
    plan = ((16, 200, 400),) if quick else ((32, 500, 2000), (64, 200, 1000))
    num_chains = 4
    rows = []
    for size, warmup, num_steps in plan:
        system = zeitlin_euler(size, noise_degree=2)
        start = _start(size)
        algorithm = liesample.lie_poisson_langevin(system, beta=1.0, sigma=1.0, step_size=ESS_STEP)

        starts = jax.vmap(algorithm.init)(jnp.repeat(jnp.asarray(start)[None], num_chains, 0))
        keys = jax.random.split(jax.random.key(1), num_chains)
        states, _ = _energy_chains(algorithm, warmup)(starts, keys)
        run = _energy_chains(algorithm, num_steps)
        compiled = run.lower(states, keys).compile()
        timed_keys = jax.random.split(keys[0], num_chains)
        (_, energies), seconds = common.timed(compiled, states, timed_keys)
        energies = np.asarray(energies)
        ess = float(arviz.ess(energies))
        rows.append(
            {
                "N": size,
                "chains": num_chains,
                "steps": num_steps,
                "seconds": seconds,
                "ess": ess,
                "ess_per_second": ess / seconds,
                "mean_h": float(energies.mean()),
            }
        )
        log(f"  N = {size}: ESS(h) = {ess:.0f} in {seconds:.1f} s -> {ess / seconds:.2f} /s")
    return rows


# ------------------------------------------------------------- adjusted sampler: cost and ESS

ADJUSTED_PLAN = ((32, 8, 400, 2000), (64, 8, 200, 1000), (128, 4, 100, 400))  # N, chains, warm, run
ADJUSTED_QUICK_PLAN = ((16, 4, 100, 200),)
ADJUSTED_BETA = 8.0
TARGET_ACCEPTANCE = 0.574


def _today_system(system):
    """The step as it was before the structured exponential: the same declaration on the plain
    :class:`Unitary` algebra (Padé ``expm`` with an LU solve) and without the system's cheap
    per-step invariant (so every step evaluates the full spectrum for ``casimir_error``)."""
    fields = {f.name: getattr(system, f.name) for f in dataclasses.fields(LiePoissonSystem)}
    fields["algebra"] = Unitary(system.params["N"])
    return LiePoissonSystem(**fields)


def _chain_runner(system, num_chains):
    """``run(states, key, step_size, num_steps) -> (states, (h, ε₁, accepted))``, compiled
    once per number of steps; ``ε₁`` is the ℓ = 1 energy (three O(N²) projections)."""
    kernel = build_kernel(system)
    ell_one = jnp.asarray(system.params["harmonics"].basis(1, 1))  # E_1m, m = −1, 0, 1

    def run(states, key, step_size, num_steps):
        def body(states, k):
            keys = jax.random.split(k, num_chains)
            states, info = jax.vmap(kernel, in_axes=(0, 0, None, None, None))(
                keys, states, step_size, 1.0, ADJUSTED_BETA
            )
            coefficients = jnp.einsum("kij,cij->ck", ell_one, states.position)
            energy_one = 0.25 * jnp.sum(coefficients**2, axis=-1)  # ½ Σ ω²/(ℓ(ℓ+1)), ℓ = 1
            return states, (info.energy, energy_one, info.is_accepted)

        return jax.lax.scan(body, states, jax.random.split(key, num_steps))

    return liesample.jit(run, static_argnums=3)


def _floor_seconds(system, states, step_size, key):
    """Seconds (best of three) of the matrix work one step needs, batched over the same chains:
    the exponential of the proposal's generator and its two conjugation products
    (``coadjoint_exp``), and the two products of ``[W, ∇h]`` (the brackets ``{h, ĥ_i}``)."""
    streams = jnp.asarray(system.params["noise_streams"])
    num_chains = states.position.shape[0]
    coefficients = jnp.sqrt(step_size) * jax.random.normal(key, (num_chains, len(streams)))
    zetas = jnp.einsum("k...,ck->c...", streams, coefficients)
    algebra = system.algebra
    gradients = -system.params["harmonics"].inverse_laplacian(states.position)

    def matrix_work(zetas, positions, gradients):
        moved = algebra.coadjoint_exp(zetas, positions)
        w, g = algebra.to_matrix(positions), algebra.to_matrix(gradients)
        return moved, w @ g - g @ w

    compiled = liesample.jit(matrix_work).lower(zetas, states.position, gradients).compile()
    _, seconds = common.timed(compiled, zetas, states.position, gradients, repeats=3)
    return seconds


def _step_seconds(system, states, step_size, num_steps, repeats=3):
    """Seconds per chain-step (best of ``repeats``) of the adjusted step, states carried."""
    num_chains = states.position.shape[0]
    run = _chain_runner(system, num_chains)
    key = jax.random.key(5)
    run(states, key, step_size, num_steps)  # compile
    (_, (_, _, accepted)), seconds = common.timed(
        lambda: run(states, key, step_size, num_steps), repeats=repeats
    )
    return seconds / (num_chains * num_steps), float(jnp.mean(accepted))


def adjusted_costs(quick, log, sizes=None, with_ess=True):
    """Per N: the tuned step, seconds per chain-step now and as before (same process, so the
    same BLAS threads), the matrix-work floor, and ESS/s of h and of the ℓ = 1 energy."""
    plan = ADJUSTED_QUICK_PLAN if quick else ADJUSTED_PLAN
    rows = []
    for size, num_chains, warmup, num_steps in plan:
        if sizes is not None and size not in sizes:
            continue
        system = zeitlin_euler(size, noise_degree=2)
        kernel_states = jax.vmap(functools.partial(adjusted_init, system=system))(
            jnp.repeat(jnp.asarray(_start(size))[None], num_chains, 0)
        )
        run = _chain_runner(system, num_chains)
        key = jax.random.key(size)
        step_size = _tuned_step_on(run, kernel_states, key, 40)
        states, _ = run(kernel_states, jax.random.fold_in(key, 100), step_size, warmup)
        if not with_ess:
            num_steps = 2  # what follows needs only the warm state and a few draws
        run(states, key, step_size, num_steps)  # compile
        ((_, (h, energy_one, accepted)), seconds) = common.timed(
            run, states, jax.random.fold_in(key, 101), step_size, num_steps
        )
        h, energy_one = np.asarray(h).T, np.asarray(energy_one).T  # (chains, draws)
        ess_h, ess_one = (
            (float(arviz.ess(h)), float(arviz.ess(energy_one))) if with_ess else (math.nan,) * 2
        )
        now, _ = _step_seconds(system, states, step_size, 100)
        today_steps = max(5, min(50, int(2e5 / size**3 * 50)))
        today_system = _today_system(system)
        today_states = jax.vmap(functools.partial(adjusted_init, system=today_system))(
            states.position
        )
        today, _ = _step_seconds(today_system, today_states, step_size, today_steps, repeats=2)
        floor = _floor_seconds(system, states, step_size, jax.random.fold_in(key, 102))
        row = {
            "N": size,
            "chains": num_chains,
            "steps": num_steps,
            "step_size": step_size,
            "acceptance": float(np.mean(accepted)),
            "seconds_per_chain_step": now,
            "seconds_per_chain_step_before": today,
            "floor_per_chain_step": floor / num_chains,
            "run_seconds": seconds,
            "ess_h": ess_h,
            "ess_energy_l1": ess_one,
            "ess_per_second_h": ess_h / seconds,
            "ess_per_second_energy_l1": ess_one / seconds,
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        }
        rows.append(row)
        log(
            f"  N = {size}: dt = {step_size:.3g}, acceptance {row['acceptance']:.2f}; "
            f"{now * 1e3:.3f} ms/chain-step (before {today * 1e3:.3f}, floor "
            f"{floor / num_chains * 1e3:.3f}); ESS/s h {row['ess_per_second_h']:.2f}, "
            f"ε₁ {row['ess_per_second_energy_l1']:.2f}"
        )
    return rows


def _cost_subprocess(threads, quick, sizes=None, with_ess=True):
    """:func:`adjusted_costs` in a fresh process with ``OPENBLAS_NUM_THREADS`` (and OMP, MKL)
    set to ``threads`` (``None``: left unset, what a user gets by default)."""
    env = dict(os.environ)
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.pop(name, None)
        if threads is not None:
            env[name] = str(threads)
    env[_WORKER_FLAG] = "default" if threads is None else "set"
    code = (
        "import json, sys; from benchmarks import zeitlin; "
        f"rows = zeitlin.adjusted_costs({quick!r}, lambda m: print(m, file=sys.stderr, "
        f"flush=True), {sizes!r}, {with_ess!r}); print(json.dumps(rows))"
    )
    root = Path(__file__).resolve().parent.parent
    done = subprocess.run(
        [sys.executable, "-c", code],
        check=False,
        env=env,
        cwd=root,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-2000:])
    print(done.stderr, end="", flush=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------- noise: degree and smoothness

NOISE_PLAN = {16: (32, 1500, (2, 4, 15), (0, 1, 2)), 32: (16, 1000, (2, 8, 31), (1, 2))}
NOISE_QUICK_PLAN = {8: (8, 300, (2, 7), (1,))}
NOISE_BETA_SCALES = (0.125, -0.125)  # β = scale · N² (energy O(1), entropy O(N²))


def _spread_over_orbit(position, num_chains, seed):
    """``U W U*`` for Haar-random unitaries ``U`` (QR of complex Gaussians, phases fixed):
    points spread uniformly over the orbit of ``position``."""
    rng = np.random.default_rng(seed)
    size = position.shape[-1]
    gaussian = rng.normal(size=(num_chains, size, size)) + 1j * rng.normal(
        size=(num_chains, size, size)
    )
    q, r = np.linalg.qr(gaussian)
    q = (
        q
        * (np.diagonal(r, axis1=-2, axis2=-1) / np.abs(np.diagonal(r, axis1=-2, axis2=-1)))[
            :, None, :
        ]
    )
    algebra = Unitary(size)
    w = np.asarray(algebra.to_matrix(jnp.asarray(position)))
    return np.asarray(algebra.from_matrix(jnp.asarray(q @ w @ np.conj(np.swapaxes(q, -1, -2)))))


def _spectrum_runner(system, beta, num_chains):
    """``run(states, key, step_size, num_steps) -> (states, (ε_ℓ per step, accepted))``."""
    kernel = build_kernel(system)
    harmonics = system.params["harmonics"]

    def run(states, key, step_size, num_steps):
        def body(states, k):
            keys = jax.random.split(k, num_chains)
            states, info = jax.vmap(kernel, in_axes=(0, 0, None, None, None))(
                keys, states, step_size, 1.0, beta
            )
            return states, (harmonics.energy_spectrum(states.position), info.is_accepted)

        return jax.lax.scan(body, states, jax.random.split(key, num_steps))

    return liesample.jit(run, static_argnums=3)


def _time_to_stationarity(means, window=50):
    """First step at which the chain mean, averaged over ``window`` steps, comes within 10 % of
    its initial distance from the stationary value (the mean over the last half), or within
    twice its scatter there; ``None`` if not in the first half of the run."""
    stationary = means[len(means) // 2 :].mean()
    gap = abs(means[0] - stationary)
    smoothed = np.convolve(means, np.ones(window) / window, mode="valid")
    # ... or within twice the scatter of the smoothed mean at stationarity, whichever is larger
    scatter = smoothed[len(smoothed) // 2 :].std()
    inside = np.nonzero(np.abs(smoothed - stationary) <= max(0.1 * gap, 2 * scatter))[0]
    return int(inside[0]) if len(inside) and inside[0] < len(smoothed) // 2 else None


def noise_mixing(quick, log):
    """ESS per step of each degree's energy and steps to stationarity from points spread over
    the orbit, against ``noise_degree`` and ``noise_smoothness``, at ``β`` of both signs."""
    plan = NOISE_QUICK_PLAN if quick else NOISE_PLAN
    rows = []
    for size, (num_chains, num_steps, degrees, smoothnesses) in plan.items():
        starts = _spread_over_orbit(_start(size), num_chains, seed=size)
        for beta in (scale * size**2 for scale in NOISE_BETA_SCALES):
            for degree in degrees:
                for smoothness in smoothnesses:
                    system = zeitlin_euler(size, noise_degree=degree, noise_smoothness=smoothness)
                    states = jax.vmap(functools.partial(adjusted_init, system=system))(
                        jnp.asarray(starts)
                    )
                    run = _spectrum_runner(system, beta, num_chains)
                    key = jax.random.key(size * 1000 + degree * 10 + smoothness)
                    step_size = _tuned_step_on(run, states, key, 40)
                    begin = time.perf_counter()
                    _, (spectra, accepted) = run(states, key, step_size, num_steps)
                    spectra = np.asarray(spectra)  # (steps, chains, N − 1)
                    seconds = time.perf_counter() - begin
                    half = spectra[num_steps // 2 :]
                    ess = np.array([float(arviz.ess(half[:, :, k].T)) for k in range(size - 1)]) / (
                        num_chains * len(half)
                    )
                    h = spectra.sum(-1).mean(1)
                    row = {
                        "N": size,
                        "beta": beta,
                        "noise_degree": degree,
                        "noise_smoothness": smoothness,
                        "num_noises": system.num_noises,
                        "chains": num_chains,
                        "steps": num_steps,
                        "step_size": step_size,
                        "acceptance": float(np.mean(accepted)),
                        "seconds": seconds,
                        "ess_per_step_by_degree": ess,
                        "steps_to_stationarity_l1": _time_to_stationarity(spectra[:, :, 0].mean(1)),
                        "steps_to_stationarity_h": _time_to_stationarity(h),
                        "stationary_l1_fraction": float(half[:, :, 0].mean() / half.sum(-1).mean()),
                    }
                    rows.append(row)
                    log(
                        f"  N = {size}, β = {beta:+g}, L = {degree}, n = {smoothness}: dt "
                        f"{step_size:.3g}, acc {row['acceptance']:.2f}, ESS/step min "
                        f"{ess.min():.2e} (ℓ=1 {ess[0]:.2e}), to stationarity ℓ=1 "
                        f"{row['steps_to_stationarity_l1']}, h {row['steps_to_stationarity_h']}; "
                        f"{seconds:.1f} s"
                    )
    return rows


def _tuned_step_on(run, states, key, num_steps):
    """:func:`_tuned_step` for a runner whose outputs end with the acceptance flags."""
    low, high = -12.0, 24.0
    for i in range(12):
        middle = 0.5 * (low + high)
        _, outputs = run(states, jax.random.fold_in(key, i), 10.0**middle, num_steps)
        if float(jnp.mean(outputs[-1])) > TARGET_ACCEPTANCE:
            low = middle
        else:
            high = middle
    return 10.0 ** (0.5 * (low + high))


def run_adjusted(out_dir: Path, quick: bool, log) -> None:
    """The adjusted sampler's cost, floor and ESS/s (one BLAS thread, and the default threads
    for the cost alone), written to ``zeitlin_adjusted.json``."""
    log("Zeitlin su(N): adjusted step, one BLAS thread (cost, floor, ESS/s)")
    one_thread = _cost_subprocess(1, quick)
    log("Zeitlin su(N): adjusted step, default BLAS threads (cost)")
    default_threads = _cost_subprocess(None, quick, with_ess=False)
    results = {
        "mode": "quick" if quick else "full",
        "machine": common.machine_info(),
        "beta": ADJUSTED_BETA,
        "one_thread": one_thread,
        "default_threads": default_threads,
    }
    common.write_json(out_dir / "zeitlin_adjusted.json", results)


def run_noise(out_dir: Path, quick: bool, log) -> None:
    """The noise-degree and smoothness measurements, written to ``zeitlin_noise.json``."""
    log("Zeitlin su(N): noise degree and smoothness")
    results = {
        "mode": "quick" if quick else "full",
        "machine": common.machine_info(),
        "rows": noise_mixing(quick, log),
    }
    common.write_json(out_dir / "zeitlin_noise.json", results)


def run(out_dir: Path, quick: bool, log) -> None:
    log("Zeitlin su(N): cost per step against N")
    cost = cost_against_size(quick, log)
    log("Zeitlin su(N): ESS/s of h")
    ess = ess_per_second(quick, log)
    results = {
        "mode": "quick" if quick else "full",
        "machine": common.machine_info(),
        "euler_step": EULER_STEP,
        "ess_step": ESS_STEP,
        "cost": cost,
        "ess": ess,
    }
    common.write_json(out_dir / "zeitlin.json", results)
    _plot(results, out_dir / "zeitlin.png")
    run_adjusted(out_dir, quick, log)
    run_noise(out_dir, quick, log)


def _plot(results, path):
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    variants = list(dict.fromkeys(r["variant"] for r in results["cost"]))
    for variant in variants:
        rows = [r for r in results["cost"] if r["variant"] == variant]
        ax.loglog([r["N"] for r in rows], [r["seconds"] for r in rows], "o-", label=variant)
    sizes = np.array(sorted({r["N"] for r in results["cost"]}), dtype=float)
    reference = [r for r in results["cost"] if r["variant"] == variants[0]][-1]
    ax.loglog(sizes, reference["seconds"] * (sizes / reference["N"]) ** 3, "k:", label="∝ N³")
    ax.set_xlabel("N")
    ax.set_ylabel("seconds per step (one chain)")
    ax.legend(fontsize=7)
    common.save_figure(fig, path)


def _slope(rows):
    """Least-squares slope of log(seconds) against log(N) over the two largest N."""
    rows = sorted(rows, key=lambda r: r["N"])[-2:]
    if len(rows) < 2:
        return float("nan")
    (n0, t0), (n1, t1) = ((r["N"], r["seconds"]) for r in rows)
    return math.log(t1 / t0) / math.log(n1 / n0)


def _adjusted_section(results) -> list[str]:
    """Markdown rows of ``zeitlin_adjusted.json``: cost, floor, speed-up and ESS/s."""
    machine = results["machine"]
    one = {r["N"]: r for r in results["one_thread"]}
    default = {r["N"]: r for r in results["default_threads"]}
    sizes = sorted(one)
    lines = [
        "### The adjusted sampler at N = 32, 64, 128",
        "",
        (
            f"`adjusted_lie_poisson(zeitlin_euler(N, noise_degree=2), beta={results['beta']:g})` "
            f"({results['mode']} mode, {machine['date_utc']}, 2-core Intel Xeon VM "
            f"(`{machine['cpu_model']}`), jax {machine['jax']}; a shared machine under a load "
            "of about 10, so absolute times are indicative; ratios are measured in the same "
            "process). Chains start from the benchmark vorticity (‖W‖² = N/2) and run after a "
            "warm-up; the step is tuned by bisection to a mean acceptance of 0.574. *Now*: "
            "the step with the skew-Hermitian exponential by matrix products "
            "(`SkewHermitianUnitary`) and the cheap per-step invariant (`step_casimir_error`). "
            "*Before*: the same declaration on the plain `Unitary` algebra (Padé `expm`, one "
            "LU solve) with the full spectrum per step, i.e. the step at git HEAD before this "
            "change. *Floor*: the exponential of the same generators with its two conjugation "
            "products plus the two products of `[W, ∇h]`, batched over the same chains. "
            "Seconds per chain-step (chains vmapped, best of repeats)."
        ),
        "",
        (
            "| N | chains | dt | acceptance | now | before (1 BLAS thread) | before (default "
            "threads) | now (default threads) | floor | now / floor | speed-up (1 thread) | "
            "speed-up (default threads) |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in sizes:
        r, d = one[n], default.get(n)
        now, before, floor = (
            r["seconds_per_chain_step"],
            r["seconds_per_chain_step_before"],
            r["floor_per_chain_step"],
        )
        d_before = d["seconds_per_chain_step_before"] if d else math.nan
        d_now = d["seconds_per_chain_step"] if d else math.nan
        lines.append(
            f"| {n} | {r['chains']} | {r['step_size']:.3g} | {r['acceptance']:.2f} | "
            f"{common.format_seconds(now)} | {common.format_seconds(before)} | "
            f"{common.format_seconds(d_before)} | {common.format_seconds(d_now)} | "
            f"{common.format_seconds(floor)} | {now / floor:.1f} | {before / now:.1f}× | "
            f"{d_before / d_now:.1f}× |"
        )
    slope = [{"N": n, "seconds": one[n]["seconds_per_chain_step"]} for n in sizes]
    floor_slope = [{"N": n, "seconds": one[n]["floor_per_chain_step"]} for n in sizes]
    lines += [
        "",
        (
            f"Cost slope d log t / d log N over the two largest N: {_slope(slope):.2f} (step), "
            f"{_slope(floor_slope):.2f} (floor); over all N by least squares: "
            f"{_fit_slope(slope):.2f} (step)."
        ),
        "",
        (
            "Reading: with the default BLAS threads (what a user gets) the old step's one LAPACK "
            "call (the LU solve inside `expm`, and the `eigvalsh` of the Casimir check) waits "
            "on spinning worker threads on this loaded machine, which made it tens of ms per "
            "chain-step; the new step makes no LAPACK call, so its cost does not depend on "
            "the threads. With one BLAS thread the gain is the exponential's and the skipped "
            "eigenvalue problem's alone. At β = 8 the law on this orbit is close to uniform, "
            "so the tuned step is very large and the exponential needs many squarings (its "
            "cost grows with log ‖Z‖ in both versions); the floor timings are as noisy as the "
            "load (a floor above the step means noise, not a faster-than-floor step)."
        ),
        "",
        "| N | chains × steps | ESS(h) | ESS(ε₁) | seconds | ESS/s of h | ESS/s of ε₁ |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in sizes:
        r = one[n]
        lines.append(
            f"| {n} | {r['chains']} × {r['steps']} | {r['ess_h']:.0f} | "
            f"{r['ess_energy_l1']:.0f} | {r['run_seconds']:.1f} | "
            f"{r['ess_per_second_h']:.2f} | {r['ess_per_second_energy_l1']:.2f} |"
        )
    lines.append("")
    return lines


def _fit_slope(rows):
    if len(rows) < 2:
        return float("nan")
    x = np.log([r["N"] for r in rows])
    y = np.log([r["seconds"] for r in rows])
    return float(np.polyfit(x, y, 1)[0])


def _noise_section(results) -> list[str]:
    """Markdown rows of ``zeitlin_noise.json``."""
    machine = results["machine"]
    lines = [
        "### Noise degree and smoothness",
        "",
        (
            f"({results['mode']} mode, {machine['date_utc']}, 2-core Intel Xeon VM, jax "
            f"{machine['jax']}.) `adjusted_lie_poisson(zeitlin_euler(N, noise_degree=L, "
            "noise_smoothness=n), beta)`, chains started at points spread uniformly over the "
            "orbit of the benchmark vorticity (Haar-random conjugations), step tuned to a mean "
            "acceptance of 0.574. ESS per step of each degree's energy ε_ℓ over the second "
            "half (bulk ESS / (chains × steps)): the smallest over ℓ, and at ℓ = 1 and "
            "ℓ = N − 1. Steps to stationarity: the first step at which the 50-step moving "
            "chain mean of ε₁ (and of h) comes within 10 % of its initial distance from the "
            "second-half mean, or within twice its scatter there (– : not in the first half). "
            "β = ±N²/8 (the energy is O(1) while the orbit's dimension grows as N², so β "
            "must grow as N² for the Gibbs law to differ from the uniform law on the orbit). "
            "ε₁ share: ε₁/h over the second half."
        ),
        "",
        (
            "Reading: at β > 0 every (L, n) mixes every degree within a few steps. At β < 0 "
            "(condensation into ℓ = 1) noise on every degree (L = N − 1) reaches stationarity "
            "first; at N = 32 the second half of the L = 2 and L = 8 runs is not yet "
            "stationary (their ε₁ share is below L = 31's), so their ESS and steps to "
            "stationarity are measured against a moving target and flatter them. The step was "
            "tuned at the spread starts, and at β < 0 the acceptance at stationarity falls "
            "well below the target (the acceptance column), so the ESS per step at β < 0 is a "
            "lower bound for a step tuned at stationarity. Hence the default noise_degree = "
            "N − 1 (every degree) with n = 1; n = 2 is slower at β < 0."
        ),
        "",
        (
            "| N | β | L | n | m | chains × steps | dt | acceptance | ESS/step min | "
            "ESS/step ℓ=1 | ESS/step ℓ=N−1 | steps to stationarity ε₁ | h | ms per step "
            "(all chains) | ε₁ share |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["rows"]:
        ess = np.asarray(r["ess_per_step_by_degree"])
        cell = lambda v: "–" if v is None else str(v)
        lines.append(
            f"| {r['N']} | {r['beta']:+g} | {r['noise_degree']} | {r['noise_smoothness']} | "
            f"{r['num_noises']} | {r['chains']} × {r['steps']} | {r['step_size']:.3g} | "
            f"{r['acceptance']:.2f} | {ess.min():.3f} | {ess[0]:.3f} | {ess[-1]:.3f} | "
            f"{cell(r['steps_to_stationarity_l1'])} | {cell(r['steps_to_stationarity_h'])} | "
            f"{r['seconds'] / r['steps'] * 1e3:.2f} | {r['stationary_l1_fraction']:.2f} |"
        )
    lines.append("")
    return lines


def report_section(
    results, plot_link: str | None = "zeitlin.png", adjusted=None, noise=None
) -> str:
    """The Markdown section of ``RESULTS.md`` from the suite's JSON (a dict)."""
    machine = results["machine"]
    sizes = sorted({r["N"] for r in results["cost"]})
    variants = list(dict.fromkeys(r["variant"] for r in results["cost"]))
    lines = [
        "## Zeitlin su(N) Euler on the sphere",
        "",
        (
            f"From `benchmarks/zeitlin.py` ({results['mode']} mode, {machine['date_utc']}, "
            f"{machine['cpu_model']}, {machine['usable_cpus']} CPUs, a shared and loaded machine: "
            "absolute times are indicative). Seconds per step of one chain, compilation excluded; "
            "`zeitlin_euler(N, noise_degree=2)` from a random vorticity with ‖W‖² = N. The sampler "
            "row is `lie_poisson_langevin(beta=1, sigma=1, step_size=0.05)` (splitting: 18 "
            f"coadjoint moves per step); the Euler rows advance `dt = {results['euler_step']}`. "
            "The NumPy isospectral midpoint is this project's own (quflow is not on PyPI). "
            "The last column is the local slope d log t / d log N over the two largest N "
            "(O(N³) expected)."
        ),
        "",
        "| variant | " + " | ".join(f"N = {n}" for n in sizes) + " | slope | spectrum drift |",
        "|---|" + "---|" * len(sizes) + "---|---|",
    ]
    for variant in variants:
        rows = {r["N"]: r for r in results["cost"] if r["variant"] == variant}
        cells = [common.format_seconds(rows[n]["seconds"]) if n in rows else "–" for n in sizes]
        drift = max(r["casimir_drift"] for r in rows.values())
        lines.append(
            f"| {variant} | "
            + " | ".join(cells)
            + f" | {_slope(list(rows.values())):.2f} | {drift:.1e} |"
        )
    gaps = [r["gap_to_jax"] for r in results["cost"] if "gap_to_jax" in r]
    if gaps:
        lines += [
            "",
            (
                f"The NumPy and JAX midpoint trajectories agree to {max(gaps):.1e} "
                "(largest entry difference after the timed steps)."
            ),
        ]
    lines += [
        "",
        (
            "ESS per second of h: `lie_poisson_langevin(zeitlin_euler(N, noise_degree=2), "
            f"beta=1, sigma=1, step_size={results.get('ess_step', 0.1)})`, 4 vmapped chains "
            "from one start after "
            "a warm-up; bulk ESS by ArviZ over the wall time of the timed run. Only the 8 modes "
            "ℓ ≤ 2 are forced, so h decorrelates slowly."
        ),
        "",
        "| N | chains × steps | ESS(h) | seconds | ESS/s | mean h |",
        "|---|---|---|---|---|---|",
    ]
    for r in results["ess"]:
        lines.append(
            f"| {r['N']} | {r['chains']} × {r['steps']} | {r['ess']:.0f} | "
            f"{r['seconds']:.1f} | {r['ess_per_second']:.2f} | {r['mean_h']:.3f} |"
        )
    if plot_link:
        lines += ["", f"![cost per step against N]({plot_link})"]
    lines.append("")
    if adjusted is not None:
        lines += _adjusted_section(adjusted)
    if noise is not None:
        lines += _noise_section(noise)
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "zeitlin.json"
    if not path.exists():
        return ""
    link = Path(os.path.relpath(out_dir / "zeitlin.png", md_dir)).as_posix()
    extra = {}
    for name in ("adjusted", "noise"):
        part = out_dir / f"zeitlin_{name}.json"
        extra[name] = common.read_json(part) if part.exists() else None
    text = report_section(common.read_json(path), link, **extra)
    exponential = out_dir / "zeitlin_exponential.json"
    if exponential.exists():  # its own script (benchmarks/zeitlin_exponential.py), a subsection
        from benchmarks import zeitlin_exponential  # it imports this module's helpers

        text += "\n" + zeitlin_exponential.section(common.read_json(exponential))
    return text


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
