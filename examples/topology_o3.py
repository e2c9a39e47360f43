"""Topological freezing in the 2-D O(3) model: the geometric charge ``Q`` per sampler and β.

On a periodic ``L × L`` lattice (J = 1, no field) every configuration has an integer
topological charge (Berg and Lüscher's geometric definition,
:func:`liesample.analysis.topology.topological_charge`). As ``β`` grows the correlation length
grows exponentially (asymptotic freedom) and a change of ``Q`` needs a coordinated change of
more and more spins: the charge changes ever more rarely, and once the correlation length
passes the lattice size the chains stay in the sector ``Q = 0`` (frozen), ``χ_t`` falls to 0.
At the smaller ``β`` the lattice charge is dominated by small dislocations (objects of one or
two lattice spacings) that appear and vanish within a step, so ``τ_int(Q)`` stays near 1 until
the charge freezes: what slows down is how often ``Q`` changes at all.

For each ``β`` the run records ``Q`` as an observable of :func:`liesample.sample` with two
samplers: the recommended one (:func:`liesample.recommended_sampler`: heat bath with one
over-relaxation sweep per step) and the plain heat bath (no over-relaxation). It prints the
topological susceptibility ``χ_t = ⟨Q²⟩/V`` with its jackknife error over blocks of at least
``10 τ_int(Q)`` draws (so the error includes the autocorrelation), ``τ_int(Q)`` from the
bulk ESS (:func:`liesample.analysis.convergence.rank_diagnostics`, ``τ = draws / ESS``) and the
number of changes of ``Q`` per chain (a frozen chain has none, and then no ``τ`` can be
estimated: it prints ``frozen``). ``--plot FILE`` saves the history of ``Q`` at each ``β`` and
``χ_t`` against ``β`` as a PNG; ``--quick`` is a tiny run that only shows the output.

    .venv/bin/python examples/topology_o3.py [--size 16] [--betas 1.0,1.5,2.0,2.5]
        [--chains 2] [--draws 2000] [--plot topology_o3.png] [--quick]
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import liesample
from liesample.analysis.convergence import rank_diagnostics
from liesample.analysis.topology import topological_charge, topological_susceptibility
from liesample.systems.heisenberg import heisenberg

SAMPLERS = ("recommended", "heat bath")
BLOCKS_PER_TAU = 10  # jackknife blocks at least this many τ_int(Q) long
QUICK = {"size": 6, "betas": "1.0,2.0", "chains": 2, "draws": 64}


def build(system, name, beta):
    """The sampler called ``name`` for ``system`` at ``beta``."""
    if name == "recommended":
        return liesample.recommended_sampler(system, beta=beta)
    return liesample.heisenberg_heat_bath(system, beta=beta, overrelaxation=0)


def charge_history(system, name, beta, num_chains, num_draws, seed):
    """``Q`` per chain and draw, ``(chains, draws)``, from hot starts after a warm-up as long
    as the run."""
    rng = np.random.default_rng(seed)
    starts = rng.normal(size=(num_chains, *system.event_shape))
    starts /= np.linalg.norm(starts, axis=-1, keepdims=True)
    with warnings.catch_warnings():  # short runs: the convergence checks speak of few draws
        warnings.simplefilter("ignore", UserWarning)
        tree = liesample.sample(
            build(system, name, beta),
            jax.random.key(seed),
            starts,
            num_draws,
            observables={"Q": topological_charge},
            keep_positions=False,
            progress_bar=False,
        )
    return np.asarray(tree.posterior["Q"].values)


def summarise(q, volume):
    """``χ_t`` and its error, ``τ_int(Q)`` and the changes of ``Q`` per chain."""
    q = np.rint(q)  # integers up to round-off
    ess = float(rank_diagnostics(q[None])[1][0])
    changes = np.count_nonzero(np.diff(q, axis=1), axis=1)
    frozen = bool(np.all(changes == 0))
    tau = float("nan") if frozen else q.size / ess
    # blocks of at least BLOCKS_PER_TAU τ_int(Q) draws, so the jackknife error includes the
    # autocorrelation; at most half a chain (two blocks per chain)
    block = q.shape[1] // 16 if frozen else math.ceil(BLOCKS_PER_TAU * tau)
    block = max(1, min(max(block, q.shape[1] // 16), q.shape[1] // 2))
    chi = topological_susceptibility(q, volume, block_size=block)
    short = not frozen and block < BLOCKS_PER_TAU * tau  # the error is then uncertain
    return {
        "chi": chi.estimate,
        "chi_error": chi.error,
        "tau": tau,
        "changes": changes,
        "block_size": block,
        "blocks_too_short": short,
    }


def plot(path, betas, results, histories, size):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for beta in betas:  # chain 0 of the recommended sampler at each beta
        left.plot(histories["recommended", beta][0], drawstyle="steps-post", label=f"β = {beta}")
    for name in SAMPLERS:
        kept = [b for b in betas if results[name, b]["chi"] > 0]  # a frozen Q = 0 has no log
        chi = [results[name, b]["chi"] for b in kept]
        error = [results[name, b]["chi_error"] for b in kept]
        right.errorbar(kept, chi, yerr=error, marker="o", capsize=3, label=name)
    left.set_xlabel("draw")
    left.set_ylabel("Q (chain 0, recommended sampler)")
    left.set_title(f"history of Q, L = {size}")
    right.set_yscale("log")
    right.set_xlabel("β J")
    right.set_ylabel("χ_t = ⟨Q²⟩ / V")
    right.set_title("topological susceptibility (χ_t = 0 not shown)")
    for ax in (left, right):
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=16)
    parser.add_argument("--betas", default="1.0,1.5,2.0,2.5")
    parser.add_argument("--chains", type=int, default=2)
    parser.add_argument("--draws", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", type=Path, default=None)
    parser.add_argument("--quick", action="store_true", help="a tiny run that shows the output")
    args = parser.parse_args(argv)
    if args.quick:
        for key, value in QUICK.items():
            setattr(args, key, value)
    betas = [float(b) for b in args.betas.split(",")]
    if args.size < 3:
        parser.error("--size must be >= 3 (a periodic lattice)")

    system = heisenberg((args.size, args.size), periodic=True)
    volume = args.size**2
    results, histories = {}, {}
    print(f"2-D O(3), periodic {args.size}x{args.size}, {args.chains} chains x {args.draws} draws")
    print("errors: jackknife over blocks of >= 10 tau_int(Q) draws (autocorrelation included)")
    for name in SAMPLERS:
        for beta in betas:
            q = charge_history(system, name, beta, args.chains, args.draws, args.seed)
            results[name, beta] = out = summarise(q, volume)
            histories[name, beta] = np.rint(q)
            tau = "frozen" if np.isnan(out["tau"]) else f"{out['tau']:.1f}"
            flag = " (blocks < 10 tau_int: error uncertain)" if out["blocks_too_short"] else ""
            print(
                f"{name:>11}  beta = {beta:.3g}: chi_t = {out['chi']:.4g} +- "
                f"{out['chi_error']:.2g}{flag}, tau_int(Q) = {tau}, changes of Q per chain = "
                f"{out['changes'].tolist()}"
            )
    if args.plot is not None:
        plot(args.plot, betas, results, histories, args.size)
        print(f"figure: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
