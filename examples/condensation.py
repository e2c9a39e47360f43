"""Negative-temperature condensation in Zeitlin's su(N) model of Euler on the sphere.

At fixed Casimirs (the vorticity's distribution of values, hence its enstrophy) the Gibbs law
``∝ exp(−βh)`` on the isospectral orbit pushes the energy ``h`` to small scales at ``β > 0`` and,
at negative temperature ``β < 0``, condenses it into the largest scale ``ℓ = 1`` (Onsager; the
energy–enstrophy picture of Kraichnan). This example samples that law on one orbit at a range of
``β`` of both signs with the Metropolis-adjusted sampler (exact at any step:
``liesample.adjusted_lie_poisson``, which ``liesample.recommended_sampler`` picks for this model)
and shows the energy moving into ``ℓ = 1`` as ``β`` decreases.

``β`` is given as the dimensionless ``b = β‖W‖²/(N² − 1)``, the scaling under which the law has a
large-``N`` limit (``docs/zeitlin.md``, "How β must scale with N"). The orbit is that of a random
vorticity with an ``ℓ⁻³`` energy spectrum and ``‖W‖² = 1``; the chains start at points spread
uniformly over the orbit (exact draws of the ``β = 0`` law), so the ``β = 0`` row is checked
against the exact uniform-orbit spectrum
(``liesample.targets.zeitlin.uniform_orbit_energy_spectrum``). The noise acts on every degree
(``noise_degree = N − 1``; the Gibbs law does not depend on it, the mixing does). The ``ℓ = 1``
share of the energy rises steeply near ``b ≈ −2``, where the chains also mix slowly (the
energy–enstrophy estimate of the scale, ``docs/zeitlin.md``); the default ``b`` values avoid
that point.

The whole sweep is compiled once: the adjusted kernel takes ``β`` and the step as traced
arguments, so the warm-up (dual averaging of one step per ``β``, shared by that ``β``'s chains,
to the sampler's target acceptance rate; ``liesample.tuning.protocol.step_size_adaptation``)
and the sampling are each one ``vmap`` over ``β`` and the chains, instead of one
``liesample.sample`` call per ``β`` (each compiles its own warm-up and sampling loops). Dual
averaging starts from ``dt = 1``. At ``β = 0`` every move is accepted, so there is no
acceptance signal to tune on: that row keeps the step tuned at the smallest ``|β|``, and needs
no warm-up (its starts are already exact draws).

Prints a table (``b``, ``β``, ``E[h] ± MCSE``, the ``ℓ = 1`` share of the energy
``E[ε₁]/E[h] ± MCSE``, R-hat, acceptance, step) and writes into ``--output`` (default
``condensation-output/``):

- ``condensation_spectra.png``: the mean energy spectrum ``E[ε_ℓ]`` at every ``β`` (±2 MCSE
  bands; dashed: the exact ``β = 0`` spectrum);
- ``condensation_fraction.png``: the ``ℓ = 1`` share of the energy against ``b``;
- ``condensation_vorticity.png``: vorticity snapshots (last draws of three chains) at the most
  negative and the most positive ``β``;
- ``condensation_summary.json``: the table's numbers and the mean spectra with their MCSE.

    .venv/bin/python examples/condensation.py [--size N] [--chains C] [--draws D]
        [--b=-4,-3,-1,0,1,2] [--noise-degree L] [--output DIR]

The default (``N = 8``, 4 chains, 400 draws after as many warm-up steps, six values of ``b``)
runs in seconds; ``--size 12 --chains 8 --draws 2000`` is a bigger run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)

import arviz_stats as azs
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

import liesample
from liesample.analysis.plots import plot_spectra, plot_vorticity
from liesample.systems import zeitlin_euler
from liesample.systems.zeitlin_states import (
    energy_spectrum,
    spectral_vorticity,
    vorticity_on_grid,
)
from liesample.targets.zeitlin import UnitaryOrbitLaw, uniform_orbit_energy_spectrum
from liesample.tuning.protocol import run_adaptation, step_size_adaptation

DEFAULT_B = "-4,-3,-1,0,1,2"
SPECTRAL_SLOPE = -3.0  # energy spectrum ε_ℓ ∝ ℓ^slope of the orbit's representative
SIGMA = 1.0  # only σ²·dt matters for the adjusted move
INITIAL_STEP = 1.0  # where dual averaging starts (it moves the step by factors quickly)


def parse_b(text: str) -> np.ndarray:
    values = np.array(sorted({float(x) for x in text.split(",") if x.strip()}))
    if values.size < 2 or not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"need at least two finite values of b, got {text!r}")
    return values


def tune_and_warm_up(sampler, betas, starts, keys, num_warmup):
    """Dual averaging of one step per ``β`` (its chains share it), all ``β`` in one compiled
    ``vmap``, from the sampler's step; returns the warmed-up states and the tuned steps."""
    tunable = sampler.adaptation
    adaptation = step_size_adaptation(tunable.target_acceptance_rate)
    initial = {"step_size": jnp.asarray(sampler.settings["step_size"])}

    def one_beta(beta, chain_keys, chain_starts):
        states = jax.vmap(sampler.init)(chain_starts)
        sampler_at = lambda step_size: tunable.at(step_size, sigma=SIGMA, beta=beta)
        states, tuned, _ = run_adaptation(
            adaptation, sampler_at, chain_keys, states, initial, num_warmup
        )
        return states, tuned["step_size"]

    run = liesample.jit(jax.vmap(one_beta))
    return run(jnp.asarray(betas), keys, jnp.asarray(starts))


def run_sweep(sampler, system, betas, step_sizes, positions, keys, num_draws):
    """``num_draws`` adjusted steps per chain at every ``β`` from ``positions`` (β, chains, N,
    N); records ``h``, the energy spectrum and acceptance per step, and the last positions."""
    kernel = liesample.adjusted_lie_poisson.build_kernel(system)

    def chain(beta, step_size, key, position):
        state = sampler.init(position)

        def body(state, k):
            state, info = kernel(k, state, step_size, SIGMA, beta)
            return state, (state.energy, energy_spectrum(state.position), info.acceptance_rate)

        last, record = jax.lax.scan(body, state, jax.random.split(key, num_draws))
        return last.position, record

    over_chains = jax.vmap(chain, in_axes=(None, None, 0, 0))
    return liesample.jit(jax.vmap(over_chains))(
        jnp.asarray(betas), jnp.asarray(step_sizes), keys, jnp.asarray(positions)
    )


def mcse(x):
    return float(azs.mcse(np.asarray(x), method="mean"))


def rhat(x):
    with np.errstate(invalid="ignore", divide="ignore"):
        return float(azs.rhat(np.asarray(x)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=8, help="N (default 8)")
    parser.add_argument(
        "--noise-degree",
        type=int,
        default=None,
        help="L (default N − 1: every degree, which mixes fastest)",
    )
    parser.add_argument("--chains", type=int, default=4, help="chains per β (default 4)")
    parser.add_argument(
        "--draws",
        type=int,
        default=400,
        help="draws per chain, after as many warm-up steps (default 400)",
    )
    parser.add_argument(
        "--b",
        type=parse_b,
        default=parse_b(DEFAULT_B),
        help="values of b = β‖W‖²/(N² − 1), comma-separated, written "
        f"--b=-4,-1,0,1 (default {DEFAULT_B})",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", "--out", type=Path, default=Path("condensation-output"))
    args = parser.parse_args(argv)
    size, chains, draws = args.size, args.chains, args.draws
    noise_degree = args.noise_degree or size - 1
    if size < 3 or chains < 2 or draws < 20:
        parser.error("need --size >= 3, --chains >= 2 and --draws >= 20")
    args.output.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()

    # -- one orbit, chains spread uniformly over it ------------------------------------------
    start = spectral_vorticity(
        size, lambda ell: ell**SPECTRAL_SLOPE, seed=args.seed, enstrophy=0.5
    )  # ‖W‖² = 2 · enstrophy = 1
    squared_norm = float(np.sum(start**2))
    system = zeitlin_euler(size, noise_degree=noise_degree, position=start)
    orbit = UnitaryOrbitLaw(system.hamiltonian, start, 0.0)
    rng = np.random.default_rng(args.seed)
    b = args.b
    betas = b * (size * size - 1) / squared_norm
    starts = np.stack([orbit.orbit_samples(rng, chains) for _ in b])  # (β, chains, N, N)
    warmup_key, draw_key = jax.random.split(jax.random.key(args.seed))
    warmup_keys = jax.random.split(warmup_key, (len(b), chains))
    draw_keys = jax.random.split(draw_key, (len(b), chains))

    # -- warm-up: one step per β by dual averaging (β = 0 borrows the smallest |β|'s) -------
    sampler = liesample.adjusted_lie_poisson(
        system, beta=float(betas[0]), sigma=SIGMA, step_size=INITIAL_STEP
    )
    tuned = b != 0
    warm_states, warm_steps = tune_and_warm_up(
        sampler, betas[tuned], starts[tuned], warmup_keys[tuned], draws
    )
    step_sizes = np.empty(len(b))
    step_sizes[tuned] = np.asarray(warm_steps)
    step_sizes[~tuned] = step_sizes[tuned][np.argmin(np.abs(b[tuned]))]

    # -- sampling (the β = 0 rows start at their exact draws) --------------------------------
    positions = np.array(starts)
    positions[tuned] = np.asarray(warm_states.position)
    last, (energy, spectra, acceptance) = jax.tree.map(
        np.asarray, run_sweep(sampler, system, betas, step_sizes, positions, draw_keys, draws)
    )
    # energy (β, C, D), spectra (β, C, D, N − 1)
    exact = uniform_orbit_energy_spectrum(size, squared_norm)
    seconds = time.perf_counter() - started

    rows = []
    for i in range(len(b)):
        # the ℓ = 1 share E[ε₁]/E[h], a ratio of means: its MCSE is that of the mean of the
        # linearised draws (ε₁ − r h)/E[h] (delta method)
        fraction = float(spectra[i, ..., 0].mean() / energy[i].mean())
        linearised = (spectra[i, ..., 0] - fraction * energy[i]) / energy[i].mean()
        rows.append(
            {
                "b": float(b[i]),
                "beta": float(betas[i]),
                "mean_h": float(energy[i].mean()),
                "mcse_h": mcse(energy[i]),
                "fraction_l1": fraction,
                "mcse_fraction_l1": mcse(linearised),
                "r_hat": max(rhat(energy[i]), rhat(spectra[i, ..., 0])),
                "acceptance": float(np.mean(acceptance[i])),
                "step_size": float(step_sizes[i]),
                "spectrum": spectra[i].mean(axis=(0, 1)).tolist(),
                "mcse_spectrum": [mcse(spectra[i, ..., ell]) for ell in range(size - 1)],
            }
        )
    print(
        f"Zeitlin su({size}), noise_degree {noise_degree}, one orbit (‖W‖² = "
        f"{squared_norm:.3g}), {chains} chains × {draws} draws (+{draws} warm-up) per β, "
        f"adjusted sampler, {seconds:.1f} s"
    )
    print(
        f"exact at β = 0: E[h] = {exact.sum():.5f}, ℓ = 1 share E[ε₁]/E[h] = "
        f"{exact[0] / exact.sum():.4f}"
    )
    print(
        f"{'b':>6} {'β':>9} {'E[h] ± MCSE':>20} {'ℓ=1 share ± MCSE':>20} "
        f"{'R-hat':>6} {'accept':>6} {'step':>8}"
    )
    for row in rows:
        print(
            f"{row['b']:+6.2f} {row['beta']:+9.2f} "
            f"{row['mean_h']:>10.5f} ± {row['mcse_h']:<7.5f} "
            f"{row['fraction_l1']:>10.4f} ± {row['mcse_fraction_l1']:<7.4f} "
            f"{row['r_hat']:6.3f} {row['acceptance']:6.2f} {row['step_size']:8.3g}"
        )

    # -- figures ------------------------------------------------------------------------------
    labels = [f"b = {row['b']:+g} (β = {row['beta']:+.3g})" for row in rows]
    plot_spectra(
        [row["spectrum"] for row in rows],
        args.output / "condensation_spectra.png",
        labels=labels,
        errors=[row["mcse_spectrum"] for row in rows],
        exact=exact,
        title=f"Mean energy spectrum on one su({size}) orbit (dashed: exact at β = 0)",
    )

    fig = Figure(figsize=(5.5, 4), layout="constrained")
    ax = fig.subplots()
    ax.errorbar(
        b,
        [r["fraction_l1"] for r in rows],
        yerr=[2 * r["mcse_fraction_l1"] for r in rows],
        fmt="o-",
        capsize=3,
        label="sampled (±2 MCSE)",
    )
    ax.axhline(exact[0] / exact.sum(), color="k", ls="--", lw=1, label="exact, β = 0")
    ax.set_xlabel("b = β‖W‖² / (N² − 1)")
    ax.set_ylabel("E[ε₁] / E[h]: ℓ = 1 share of the energy")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.suptitle(f"Condensation into ℓ = 1 at negative temperature, su({size})")
    fig.savefig(args.output / "condensation_fraction.png", dpi=110)

    shown = min(3, chains)
    theta = np.linspace(0.0, np.pi, 4 * size + 1)[1:-1]
    num_phi = 8 * size
    phi = 2 * np.pi * np.arange(num_phi) / num_phi
    panels, titles = [], []
    for i in (0, len(b) - 1):
        for c in range(shown):
            panels.append(vorticity_on_grid(last[i, c], theta, num_phi))
            titles.append(f"b = {b[i]:+g}, chain {c}, last draw")
    plot_vorticity(
        np.stack(panels),
        theta,
        phi,
        args.output / "condensation_vorticity.png",
        labels=titles,
        title=f"Gibbs draws on one su({size}) orbit",
    )

    summary = {
        "size": size,
        "noise_degree": noise_degree,
        "chains": chains,
        "draws": draws,
        "squared_norm": squared_norm,
        "exact_spectrum_beta0": exact.tolist(),
        "seconds": seconds,
        "rows": rows,
    }
    (args.output / "condensation_summary.json").write_text(json.dumps(summary, indent=1))
    print(
        f"wrote {', '.join(p.name for p in sorted(args.output.glob('condensation_*')))} "
        f"into {args.output}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
