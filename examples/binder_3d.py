"""The critical point of the 3-D classical Heisenberg ferromagnet from Binder cumulants.

On periodic ``L × L × L`` lattices (J = 1, no field) the Binder cumulant
``U_L(β) = 1 − ⟨m⁴⟩/(3⟨m²⟩²)`` of the magnetisation per site tends to ``4/9`` in the disordered
phase and to ``2/3`` in the ordered one; at the critical point it is (to leading order) the
same for every ``L``, so the curves of two sizes cross at ``β_c`` (literature: ``β_c J ≈ 0.693``,
``U* ≈ 0.62``).

For each size, every ``β`` of the grid is one ``liesample.sample`` call (its warm-up, checks
and ArviZ output), compiled once for the grid (a sampler's ``β`` is a number of its program),
with the exact sampler ``liesample.recommended_sampler`` would choose for that lattice near
``β_c`` (:func:`liesample.samplers.recommended.spin_sampler_name`: heat bath
with over-relaxation, or Swendsen–Wang clusters on large lattices). ``U`` gets jackknife
errors over blocks of draws (:func:`liesample.analysis.diagnostics.binder_cumulant`); a
weighted straight line through each size's ``U(β)`` locates the crossing of consecutive sizes,
with its error propagated from the two fits. ``--plot FILE`` saves ``U(β)`` per size.

    .venv/bin/python examples/binder_3d.py [--sizes 8,16] [--betas 0.68,0.685,...]
        [--chains 4] [--draws 2000] [--warmup 500] [--plot binder.png]
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import liesample
from liesample.analysis.diagnostics import binder_cumulant
from liesample.samplers.recommended import spin_sampler_name
from liesample.systems.heisenberg import heisenberg

BETA_C = 0.693


def sampler_at(system, beta, name):
    """The sampler ``name`` (what ``liesample.recommended_sampler`` would choose near ``β_c``)
    at ``beta``: the same structure at every ``β``, so one compilation serves the grid."""
    if name == "heisenberg_cluster":
        return liesample.heisenberg_cluster(system, beta=beta)
    return liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=1)


def magnetisation(spins):
    """``m``, the magnetisation per site of one configuration (an observable of the run)."""
    return jnp.mean(spins.reshape(-1, 3), axis=0)


def magnetisations(size, betas, num_chains, num_draws, num_warmup, seed):
    """``m`` per site, shape ``(betas, chains, draws, 3)``, and the sampler's name: one
    ``liesample.sample`` per ``β`` (its checks included), the spins themselves not kept."""
    system = heisenberg((size,) * 3, periodic=True)
    name = spin_sampler_name(system, float(np.mean(betas)))
    rng = np.random.default_rng(seed)
    keys = jax.random.split(jax.random.key(seed), len(betas))
    m = []
    for key, beta in zip(keys, betas, strict=True):
        starts = rng.normal(size=(num_chains, size, size, size, 3))
        starts /= np.linalg.norm(starts, axis=-1, keepdims=True)
        tree = liesample.sample(
            sampler_at(system, beta, name), key, starts, num_draws, num_warmup=num_warmup,
            observables={"m": magnetisation}, keep_positions=False, progress_bar=False,
        )  # fmt: skip
        m.append(np.asarray(tree.posterior["m"].values))
    return np.stack(m), name


def line_fit(x, y, error):
    """Weighted least squares ``y = a + b (x − x̄)``: ``(a, b, covariance, x̄)``."""
    centre = float(np.mean(x))
    design = np.stack([np.ones_like(x), x - centre], axis=1)
    weights = 1.0 / np.asarray(error) ** 2
    covariance = np.linalg.inv(design.T @ (weights[:, None] * design))
    a, b = covariance @ design.T @ (weights * y)
    return a, b, covariance, centre


def crossing(betas, u1, e1, u2, e2):
    """``(β*, error, U*)`` where the fitted lines of two sizes cross; the error propagates the
    two independent fits' covariances (first order)."""
    betas = np.asarray(betas, dtype=float)
    a1, b1, c1, centre = line_fit(betas, u1, e1)
    a2, b2, c2, _ = line_fit(betas, u2, e2)
    t = (a1 - a2) / (b2 - b1)  # β* − centre
    # ∂t/∂(a1, b1) and ∂t/∂(a2, b2)
    g1 = np.array([1.0, t]) / (b2 - b1)
    g2 = -np.array([1.0, t]) / (b2 - b1)
    error = math.sqrt(g1 @ c1 @ g1 + g2 @ c2 @ g2)
    return centre + t, error, a1 + b1 * t


def plot(path, betas, results, crossings):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for size, (u, e) in results.items():
        ax.errorbar(betas, u, yerr=e, marker="o", capsize=3, label=f"L = {size}")
    for beta_star, error, _ in crossings:
        ax.axvspan(beta_star - error, beta_star + error, color="grey", alpha=0.2)
    ax.axvline(BETA_C, color="k", ls=":", label=f"β_c ≈ {BETA_C}")
    ax.set_xlabel("β J")
    ax.set_ylabel("Binder cumulant U")
    ax.set_title("3-D Heisenberg ferromagnet, periodic L³")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="8,16")
    parser.add_argument("--betas", default="0.68,0.685,0.69,0.695,0.7,0.705")
    parser.add_argument("--chains", type=int, default=4)
    parser.add_argument("--draws", type=int, default=2000)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", type=Path, default=None)
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    betas = [float(b) for b in args.betas.split(",")]
    if len(betas) < 2:
        parser.error("--betas needs at least two values (a line through each size's U)")

    print(
        "errors: U by the jackknife over blocks of the automatic blocking level (blocks longer "
        "than tau_int, so the autocorrelation is included); beta* by propagating them through "
        "the two weighted line fits"
    )
    results = {}
    for size in sizes:
        m, name = magnetisations(size, betas, args.chains, args.draws, args.warmup, args.seed)
        estimates = [binder_cumulant(m_beta) for m_beta in m]
        u = np.array([r.estimate for r in estimates])
        e = np.array([r.error for r in estimates])
        results[size] = (u, e)
        print(f"L = {size} ({name}, {args.chains} chains x {args.draws} draws per beta)")
        for beta, value, error in zip(betas, u, e, strict=True):
            print(f"  beta = {beta:.4f}   U = {value:.4f} +- {error:.4f}")
    crossings = []
    for small, large in itertools.pairwise(sizes):
        beta_star, error, u_star = crossing(betas, *results[small], *results[large])
        crossings.append((beta_star, error, u_star))
        print(
            f"crossing L = {small}/{large}: beta* = {beta_star:.4f} +- {error:.4f}, "
            f"U* = {u_star:.3f}"
        )
    if args.plot is not None:
        plot(args.plot, betas, results, crossings)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
