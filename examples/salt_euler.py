"""SALT-Euler on the sphere, in Zeitlin's su(N) model: Euler, relaxation, and Gibbs samples.

Writes two figures into ``--out`` (default ``salt-euler-output/``):

- ``salt_euler_scenes.png``: the vorticity on the sphere (Mollweide maps, from the quantised
  harmonics) for three scenes from one random start: pure Euler (``σ = 0``, ``θ = 0``: ``h``
  and every Casimir conserved), pure energy descent (``σ = 0``, ``θ > 0``: ``h`` decreases,
  pushing the vorticity towards small scales, until the Euler tendency has no component along
  the retained noise streams; ``docs/zeitlin.md``), and draws of the Gibbs law ``∝ exp(−βh)``
  on the orbit at ``β > 0`` (small scales) and ``β < 0`` (negative temperature: the energy
  condenses into the largest scales, ``ℓ = 1``; ``examples/condensation.py`` sweeps ``β``).
- ``salt_euler_energy.png``: ``h(t)`` of the two deterministic scenes, ``h`` along the Gibbs
  chains, and the energy spectrum ``ε_ℓ`` by degree.

The two deterministic scenes are the SALT-Euler dynamics, ``liesample.lie_poisson_langevin`` on
``systems.zeitlin_euler(N, noise_degree=L)`` with ``sigma = 0`` and the dissipation ``theta``
derived from the ``L(L+2)`` transport modes (``docs/zeitlin.md``). The Gibbs draws come from
the sampler ``liesample.recommended_sampler`` picks for this model, the Metropolis-adjusted
``liesample.adjusted_lie_poisson`` (exact at any step, so no step bias to control), run by
``liesample.sample``, whose warm-up tunes its step; it prints ``E[h]`` with its MCSE and R-hat.
Its noise acts on every degree (``noise_degree = N − 1``): the Gibbs law does not depend on
the noise, and low degrees alone mix the large scales slowly. The unadjusted
``liesample.lie_poisson_langevin`` at ``σ > 0`` is the SALT-Euler dynamics itself; as a sampler
it has a step bias and mixes far more slowly per second.

    .venv/bin/python examples/salt_euler.py [--size N] [--quick] [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

import liesample
from liesample.analysis.diagnostics import expectation_table
from liesample.systems.zeitlin import random_vorticity, zeitlin_euler
from liesample.systems.zeitlin_states import energy_spectrum

NOISE_DEGREE = 4
ENSTROPHY = 40.0  # ‖W‖² of the start (sets the time scale: turnover ~ 1/√enstrophy)
STEP_SIZE = 0.05
THETA = 50.0  # dissipation strength of the energy-descent scene
BETAS = (40.0, -40.0)  # the two temperatures of the Gibbs scene


def run_chains(algorithm, starts, num_steps, rng_key, record_every):
    """Run one chain per start; return recorded positions ``(C, T, N, N)`` and energies
    ``(C, num_steps)``."""

    def chain(start, key):
        def body(state, k):
            state, info = algorithm.step(k, state)
            return state, (state.position, info.energy)

        _, (positions, energies) = jax.lax.scan(
            body, algorithm.init(start), jax.random.split(key, num_steps)
        )
        return positions[record_every - 1 :: record_every], energies

    keys = jax.random.split(rng_key, len(starts))
    positions, energies = liesample.jit(jax.vmap(chain))(jnp.asarray(starts), keys)
    return np.asarray(positions), np.asarray(energies)


def draw_map(fig, spec, harmonics, x, title, limit):
    theta, phi, values = harmonics.grid(x, num_theta=48, num_phi=96)
    lon = np.where(phi > np.pi, phi - 2 * np.pi, phi)
    order = np.argsort(lon)
    ax = fig.add_subplot(spec, projection="mollweide")
    mesh = ax.pcolormesh(
        lon[order],
        np.pi / 2 - theta,
        np.asarray(values)[:, order],
        cmap="RdBu_r",
        vmin=-limit,
        vmax=limit,
        shading="nearest",
    )
    ax.set_xticklabels([])
    ax.set_yticklabels([])
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=9)
    return mesh


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=None, help="N (default 24; 6 with --quick)")
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    parser.add_argument("--out", type=Path, default=Path("salt-euler-output"))
    args = parser.parse_args(argv)
    size = args.size or (6 if args.quick else 24)
    steps = 40 if args.quick else 1000
    gibbs_chains = 2 if args.quick else 4
    gibbs_draws = 40 if args.quick else 1000  # after as many warm-up steps
    noise_degree = min(2 if args.quick else NOISE_DEGREE, size - 1)
    args.out.mkdir(parents=True, exist_ok=True)

    system = zeitlin_euler(size, noise_degree=noise_degree)
    harmonics = system.params["harmonics"]
    start = random_vorticity(size, seed=1, slope=1.0, enstrophy=0.5 * ENSTROPHY)
    # The Gibbs law does not depend on the noise, only the mixing does: the sampler moves every
    # degree (low degrees alone mix the large scales slowly).
    gibbs_system = zeitlin_euler(size, noise_degree=size - 1)
    record = steps // 2
    key = jax.random.key(0)

    euler = liesample.lie_poisson_langevin(system, sigma=0.0, theta=0.0, step_size=STEP_SIZE)
    euler_path, euler_energy = run_chains(euler, start[None], steps, key, record)
    descent = liesample.lie_poisson_langevin(system, sigma=0.0, theta=THETA, step_size=STEP_SIZE)
    descent_path, descent_energy = run_chains(descent, start[None], steps, key, record)
    gibbs = {}  # β -> (positions (C, D, N, N), h (C, D), energy spectra (C, D, N − 1))
    starts = np.repeat(start[None], gibbs_chains, axis=0)
    for index, beta in enumerate(BETAS):
        sampler = liesample.recommended_sampler(gibbs_system, beta=beta)
        tree = liesample.sample(
            sampler,
            jax.random.key(index + 1),
            starts,
            gibbs_draws,
            observables={"h": gibbs_system.hamiltonian, "spectrum": energy_spectrum},
        )
        posterior = tree.posterior
        (position_name,) = set(posterior.data_vars) - {"h", "spectrum"}
        h = np.asarray(posterior["h"])
        gibbs[beta] = (np.asarray(posterior[position_name]), h, np.asarray(posterior["spectrum"]))
        row = expectation_table({"h": h}).loc["h"]
        print(
            f"β = {beta:+g} ({tree.attrs['sampler']}): E[h] = {row['estimate']:.4f} ± "
            f"{row['mcse']:.4f} (MCSE), R-hat {row['r_hat']:.3f}, acceptance "
            f"{float(tree.sample_stats['acceptance_rate'].mean()):.2f}, tuned step "
            f"{tree.attrs['step_size']:.3g}"
        )
    print(
        f"h: start {float(system.hamiltonian(jnp.asarray(start))):.4f}, Euler end "
        f"{euler_energy[0, -1]:.4f}, descent end {descent_energy[0, -1]:.4f}"
    )

    # -- vorticity maps ---------------------------------------------------------------------
    limit = float(np.max(np.abs(harmonics.grid(start, 48, 96)[2])))
    fig = Figure(figsize=(12, 7.5), layout="constrained")
    grid = fig.add_gridspec(3, 3)
    times = (0, record * STEP_SIZE, steps * STEP_SIZE)
    euler_states = [start, *euler_path[0]]
    descent_states = [start, *descent_path[0]]
    for col, t in enumerate(times):
        draw_map(fig, grid[0, col], harmonics, euler_states[col], f"Euler, t = {t:g}", limit)
        draw_map(
            fig,
            grid[1, col],
            harmonics,
            descent_states[col],
            f"energy descent (θ = {THETA:g}), t = {t:g}",
            limit,
        )
    for col, beta in enumerate(BETAS):
        draw_map(
            fig, grid[2, col], harmonics, gibbs[beta][0][0, -1], f"Gibbs draw, β = {beta:+g}", limit
        )
    mesh = draw_map(
        fig,
        grid[2, 2],
        harmonics,
        gibbs[BETAS[0]][0][-1, -1],
        f"another chain, β = {BETAS[0]:+g}",
        limit,
    )
    fig.colorbar(mesh, ax=fig.axes, shrink=0.5, label="vorticity ω")
    fig.suptitle(f"Zeitlin su({size}) Euler on the sphere: one isospectral orbit, three scenes")
    fig.savefig(args.out / "salt_euler_scenes.png", dpi=110)

    # -- energy in time, and by degree -------------------------------------------------------
    fig = Figure(figsize=(15, 4), layout="constrained")
    ax_t, ax_g, ax_l = fig.subplots(1, 3)
    t = STEP_SIZE * np.arange(1, steps + 1)
    ax_t.plot(t, euler_energy[0], label="Euler (σ = θ = 0)")
    ax_t.plot(t, descent_energy[0], label=f"energy descent (θ = {THETA:g})")
    ax_t.set_xlabel("t")
    ax_t.set_ylabel("h")
    ax_t.legend(fontsize=8)
    for beta in BETAS:
        for chain, trace in enumerate(gibbs[beta][1]):
            ax_g.plot(
                trace,
                lw=0.6,
                color="C3" if beta < 0 else "C0",
                label=f"β = {beta:+g}" if chain == 0 else None,
            )
    ax_g.axhline(
        float(system.hamiltonian(jnp.asarray(start))), color="k", ls="--", lw=1, label="start"
    )
    ax_g.set_xlabel("draw (after warm-up)")
    ax_g.set_ylabel("h")
    ax_g.set_title("Gibbs chains (adjusted sampler)", fontsize=9)
    ax_g.legend(fontsize=8)
    ell = np.arange(1, size)
    spectrum = liesample.jit(harmonics.energy_spectrum)
    ax_l.semilogy(ell, spectrum(jnp.asarray(start)), "k.-", label="start")
    ax_l.semilogy(ell, spectrum(jnp.asarray(descent_path[0, -1])), ".-", label="after descent")
    for beta in BETAS:
        ax_l.semilogy(
            ell, gibbs[beta][2].mean(axis=(0, 1)), ".-", label=f"Gibbs mean, β = {beta:+g}"
        )
    ax_l.set_xlabel("degree ℓ")
    ax_l.set_ylabel("energy ε_ℓ")
    ax_l.legend(fontsize=8)
    fig.savefig(args.out / "salt_euler_energy.png", dpi=110)
    print(f"wrote {args.out / 'salt_euler_scenes.png'} and {args.out / 'salt_euler_energy.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
