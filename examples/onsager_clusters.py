"""Onsager's clustered vortices at negative temperature, sampled exactly.

``N`` point vortices on the sphere, half with circulation ``+1`` and half ``−1``, under the Gibbs
law ``∝ exp(−βh)`` (:mod:`liesample.targets.vortices`). At ``β > 0`` opposite signs pair up and the
dipole ``D = Σ_k Γ_k x_k`` is small; at ``β < 0`` (Onsager's negative temperatures, the high-energy
states) like-signed vortices gather into two clusters, one of each sign, and ``|D|²`` approaches
its largest value ``N²``. ``liesample.vortex_metropolis`` samples this law with no step bias:
single-vortex Metropolis sweeps, the proposal scale tuned in the warm-up.

Prints, for each ``β``: ``E|D|²`` with its Monte Carlo standard error (``sd/√ESS``, ArviZ's bulk
ESS over the chains, so the autocorrelation is included), R-hat, the mean angle from a
vortex to its nearest like-signed neighbour, and the tuned proposal scale. ``--plot FILE`` also
saves ``|D|²`` against ``β`` and one state per ``β`` (longitude–latitude map).

    .venv/bin/python examples/onsager_clusters.py [--vortices 10] [--betas 2,0,-2,-4]
        [--chains 16] [--draws 1000] [--plot onsager.png]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import arviz as az
import numpy as np

import liesample
from liesample.systems.point_vortices import point_vortices
from liesample.targets.vortices import beta_bounds, uniform_sphere_points


def dipole_squared(x, circulations):
    """``|Σ_k Γ_k x_k|²`` for positions ``(..., N, 3)``."""
    dipole = np.einsum("k,...ki->...i", circulations, x)
    return np.sum(dipole * dipole, axis=-1)


def like_signed_neighbour_angle(x, circulations):
    """Mean angle (degrees) from each vortex to its nearest vortex of the same sign."""
    cosines = np.einsum("...ki,...ji->...kj", x, x)
    same = np.sign(circulations)[:, None] == np.sign(circulations)[None, :]
    np.fill_diagonal(same, False)
    nearest = np.max(np.where(same, cosines, -1.0), axis=-1)
    return float(np.degrees(np.arccos(np.clip(nearest, -1.0, 1.0))).mean())


def sample_at(system, beta, num_chains, num_draws, seed):
    """Draws ``(chains, draws, N, 3)`` of ``vortex_metropolis`` and the tuned proposal scale."""
    starts = uniform_sphere_points(jax.random.key(seed), (num_chains, system.event_shape[0]))
    run = liesample.sample_chains(
        liesample.vortex_metropolis(system, beta=beta),
        jax.random.key(seed + 1),
        starts,
        num_draws,
        num_warmup=max(num_draws // 2, 100),
        progress_bar=False,
    )
    return np.asarray(run.positions), run.settings["step_size"]


def plot(path, rows, circulations):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4 + 3 * len(rows), 3.4), constrained_layout=True)
    axes = fig.subplots(1, 1 + len(rows))
    betas = [row["beta"] for row in rows]
    axes[0].errorbar(
        betas, [row["dipole"] for row in rows], yerr=[2 * row["mcse"] for row in rows], fmt="o-"
    )  # two MCSEs (from the ESS: autocorrelation included)
    axes[0].axhline(circulations.size**2, ls=":", c="gray")
    axes[0].set(xlabel="β", ylabel="E|D|²", title="dipole against β")
    for ax, row in zip(axes[1:], rows, strict=True):
        x = row["state"]
        longitude, latitude = np.arctan2(x[:, 1], x[:, 0]), np.arcsin(np.clip(x[:, 2], -1, 1))
        ax.scatter(longitude, latitude, c=np.sign(circulations), cmap="coolwarm", vmin=-1, vmax=1)
        ax.set(
            xlim=(-math.pi, math.pi), ylim=(-math.pi / 2, math.pi / 2), title=f"β = {row['beta']:g}"
        )
        ax.set_xticks([])
        ax.set_yticks([])
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vortices", type=int, default=10, help="even number N (default 10)")
    parser.add_argument("--betas", default="2,0,-2,-4", help="comma-separated β values")
    parser.add_argument("--chains", type=int, default=16)
    parser.add_argument("--draws", type=int, default=1000, help="sweeps kept per chain")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", type=Path, default=None, help="save a figure to this file")
    args = parser.parse_args(argv)
    if args.vortices < 2 or args.vortices % 2:
        parser.error(f"--vortices must be an even number >= 2, got {args.vortices}")
    half = args.vortices // 2
    circulations = np.array([1.0] * half + [-1.0] * half)
    system = point_vortices(circulations)
    low, high = beta_bounds(circulations)
    print(
        f"{args.vortices} vortices (Γ = ±1): the Gibbs law is normalisable for "
        f"{low:.3g} < β < {high:.3g}"
    )
    print(
        f"{'β':>6} {'E|D|²':>8} {'± MCSE':>7} {'R-hat':>6} "
        f"{'like-signed NN angle':>21} {'scale':>7}"
    )
    rows = []
    for index, beta in enumerate(float(b) for b in args.betas.split(",")):
        draws, scale = sample_at(system, beta, args.chains, args.draws, args.seed + 10 * index)
        values = dipole_squared(draws, circulations)
        ess = float(az.ess(values))
        rows.append(
            {
                "beta": beta,
                "dipole": float(values.mean()),
                "mcse": float(values.std() / math.sqrt(ess)),
                "r_hat": float(az.rhat(values)),
                "angle": like_signed_neighbour_angle(draws[:, -1], circulations),
                "scale": scale,
                "state": draws[0, -1],
            }
        )
        row = rows[-1]
        print(
            f"{beta:6g} {row['dipole']:8.2f} {row['mcse']:7.2f} {row['r_hat']:6.3f} "
            f"{row['angle']:19.1f}°  {scale:7.3g}"
        )
    print("MCSE = sd / sqrt(ESS), ArviZ's bulk ESS over the chains (autocorrelation included)")
    if args.plot is not None:
        plot(args.plot, rows, circulations)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
