"""Zeitlin's su(N) Euler model: cost per step against N, the deterministic scene against a
NumPy isospectral midpoint, and the sampler's ESS per second of ``h``.

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    .venv/bin/python benchmarks/zeitlin.py            # a few minutes on 2 cores
    .venv/bin/python benchmarks/zeitlin.py --quick    # smoke run (benchmarks/results/quick/)

Writes ``zeitlin.json`` and ``zeitlin.png``. Parts:

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
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

# LAPACK's worker threads spin while waiting: on a shared, loaded 2-core machine that made
# expm/solve/eigh of 32×32 complex matrices 30–100× slower (measured). One thread each, set
# before NumPy or JAX loads LAPACK (when this suite runs alone).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
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
from liesample.systems.zeitlin import isospectral_midpoint, random_vorticity, zeitlin_euler

SUITE = {"order": 60, "title": "Zeitlin su(N) Euler on the sphere"}

ENSTROPHY_PER_MODE = 1.0  # ‖W‖² = N: the vorticity's amplitude does not grow with N
EULER_STEP = 0.01
ESS_STEP = 0.1
MIDPOINT_TOLERANCE = 1e-14
MIDPOINT_MAX_ITERATIONS = 100


def _start(size):
    return random_vorticity(size, seed=0, enstrophy=ENSTROPHY_PER_MODE * size)


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
        final = liesample.jit(
            lambda s, keys: jax.lax.scan(lambda s, k: (midpoint.step(k, s)[0], None), s, keys)[0]
        )(state, keys)
        gap = float(np.max(np.abs(np.asarray(system.algebra.to_matrix(final.position)) - w_numpy)))
        rows[-1]["gap_to_jax"] = gap
        log(f"             NumPy vs JAX midpoint after {repeats} steps: max |ΔW| = {gap:.1e}")
    return rows


def ess_per_second(quick, log):
    plan = ((16, 200, 400),) if quick else ((32, 500, 2000), (64, 200, 1000))
    num_chains = 4
    rows = []
    for size, warmup, num_steps in plan:
        system = zeitlin_euler(size, noise_degree=2)
        start = _start(size)
        algorithm = liesample.lie_poisson_langevin(system, beta=1.0, sigma=1.0, step_size=ESS_STEP)

        def chain(state, key, n):
            def body(state, k):
                state, info = algorithm.step(k, state)
                return state, info.energy

            return jax.lax.scan(body, state, jax.random.split(key, n))

        starts = jax.vmap(algorithm.init)(jnp.repeat(jnp.asarray(start)[None], num_chains, 0))
        keys = jax.random.split(jax.random.key(1), num_chains)
        warm = liesample.jit(jax.vmap(lambda s, k: chain(s, k, warmup)))
        states, _ = warm(starts, keys)
        run = liesample.jit(jax.vmap(lambda s, k: chain(s, k, num_steps)))
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


def report_section(results, plot_link: str | None = "zeitlin.png") -> str:
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
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    path = out_dir / "zeitlin.json"
    if not path.exists():
        return ""
    link = Path(os.path.relpath(out_dir / "zeitlin.png", md_dir)).as_posix()
    return report_section(common.read_json(path), link)


if __name__ == "__main__":
    sys.exit(suites.standalone(__file__))
