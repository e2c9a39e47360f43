"""``liesample demo``: sample the stochastic rigid body and compare with its exact Gibbs law."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import jax

DEMO_DESCRIPTION = """\
Sample the stochastic-dissipative rigid body on the sphere |μ| = radius with the
Lie–Poisson–Langevin sampler, and compare the chains with the exact Gibbs law exp(−βh),
h = ½ Σ μ_i²/I_i: ergodic averages with MCSE z-scores, ESS, R-hat, Casimir drift and the
isotropic autocorrelation against r²·exp(−σ²t). Writes plots and the draws (NetCDF).

Precision: the demo runs in float64 (it sets jax_enable_x64 itself). In your own code, call
jax.config.update("jax_enable_x64", True) before creating arrays: Casimirs are kept to
round-off, and in float32 that round-off (about 1e-7 per step) accumulates over long runs.
"""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="liesample", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    demo = commands.add_parser(
        "demo",
        help="sample the stochastic-dissipative rigid body on S² and report accuracy vs exact",
        description=DEMO_DESCRIPTION,
        formatter_class=_HelpFormatter,
    )
    demo.add_argument(
        "--output",
        type=Path,
        default=Path("liesample-demo-output"),
        help="folder for the plots (PNG) and draws.nc (created if missing; an earlier draws.nc "
        "there is replaced)",
    )
    demo.add_argument(
        "--inertia",
        type=float,
        nargs=3,
        default=(1.0, 2.0, 4.0),
        metavar=("I1", "I2", "I3"),
        help="principal moments of inertia, each > 0",
    )
    demo.add_argument("--beta", type=float, default=3.0, help="inverse temperature β")
    demo.add_argument("--sigma", type=float, default=1.0, help="noise strength σ ≥ 0")
    demo.add_argument("--radius", type=float, default=1.5, help="orbit |μ| = radius > 0")
    demo.add_argument(
        "--step-size",
        type=float,
        default=0.05,
        help="time step dt > 0; refused beyond the stability bound κ = dt·θ·max|h''| ≤ 2, "
        "θ = βσ²/2",
    )
    demo.add_argument(
        "--integrator",
        default="splitting",
        help="one of splitting (second order), rkmk_heun, lie_euler, euler_heun "
        "(liesample.integrators)",
    )
    demo.add_argument("--chains", type=int, default=16, help="number of independent chains ≥ 1")
    demo.add_argument(
        "--time", type=float, default=2000.0, help="physical time per chain (after warm-up)"
    )
    demo.add_argument("--seed", type=int, default=0, help="seed of the random keys")
    demo.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows every option's default and keeps the description's line breaks."""


def _parse(argv: list[str]) -> argparse.Namespace:
    return _parser().parse_args(argv)


def _random_points_on_sphere(key: jax.Array, num: int, radius: float) -> jax.Array:
    import jax

    x = jax.random.normal(key, (num, 3))
    return radius * x / np.linalg.norm(x, axis=-1, keepdims=True)


def demo(args: argparse.Namespace) -> int:
    """Run ``liesample demo`` with the parsed ``args``: sample, report, plot. Returns the exit
    status (1 if every draw diverged)."""
    import jax

    jax.config.update("jax_enable_x64", True)  # Casimirs to round-off need float64

    from liesample import systems

    if args.chains < 1:
        raise ValueError(f"--chains must be >= 1, got {args.chains}")
    if not args.time > 0:
        raise ValueError(f"--time must be > 0, got {args.time}")
    netcdf = _draws_file(args.output)
    system = systems.rigid_body(args.inertia)
    reference = system.reference
    assert reference is not None  # the rigid body declares its exact law
    target = reference(args.beta, [args.radius, 0.0, 0.0])
    key_start, key_run, key_iso = jax.random.split(jax.random.key(args.seed), 3)
    starts = _random_points_on_sphere(key_start, args.chains, args.radius)  # both runs
    tree = _sample_gibbs_law(args, system, starts, key_run, netcdf)
    if not _report_averages(args, system, target, tree):
        print(
            f"liesample demo: error: every draw of the {args.integrator!r} run diverged "
            "(non-finite states); reduce --step-size or choose another --integrator",
            file=sys.stderr,
        )
        return 1
    autocorrelation = _isotropic_autocorrelation(args, starts, key_iso)
    paths = _plots(args, system, target, tree.posterior["mu"].values, autocorrelation)
    print(f"\nWrote {netcdf} and plots:")
    for path in paths:
        print(f"  {path}")
    return 0


def _draws_file(out: Path) -> Path:
    """The demo's ``draws.nc`` in the folder ``out``, created if missing; an earlier demo's
    draws there are removed."""
    if out.exists() and not out.is_dir():
        raise ValueError(
            f"--output {str(out)!r} is a file; give a folder for the plots and draws.nc (it is "
            "created if missing)"
        )
    out.mkdir(parents=True, exist_ok=True)
    netcdf = out / "draws.nc"
    netcdf.unlink(missing_ok=True)
    return netcdf


def _sampler(args: argparse.Namespace, system):
    """The demo's Lie–Poisson–Langevin sampler of ``system``."""
    from liesample import lie_poisson_langevin

    return lie_poisson_langevin(
        system,
        beta=args.beta,
        sigma=args.sigma,
        step_size=args.step_size,
        integrator=args.integrator,
    )


def _sample_gibbs_law(args: argparse.Namespace, system, starts, key, netcdf: Path):
    """The chains of ``system`` from ``starts``, a draw every ~half time unit after a warm-up of
    20 time units (many relaxation times), written to ``netcdf`` as they run."""
    from liesample.run.runner import sample

    thinning = max(1, round(0.5 / args.step_size))
    num_draws = max(10, round(args.time / (args.step_size * thinning)))
    print(
        f"liesample demo: rigid body I={tuple(args.inertia)}, β={args.beta}, σ={args.sigma}, "
        f"|μ|={args.radius}; integrator {args.integrator}, dt={args.step_size}; "
        f"{args.chains} chains × {num_draws} draws (thinning {thinning})"
    )
    return sample(
        _sampler(args, system),
        key,
        starts,
        num_draws,
        num_warmup=round(20.0 / args.step_size),
        thinning=thinning,
        progress_bar=not args.no_progress,
        output=netcdf,  # written chunk by chunk; liesample.load_chains reads it
        coords={"component": list(system.component_names)},
        attrs={
            "system": system.name,
            "inertia": list(args.inertia),
            "beta": args.beta,
            "sigma": args.sigma,
            "step_size": args.step_size,
            "integrator": args.integrator,
        },
    )


def _report_averages(args: argparse.Namespace, system, target, tree) -> bool:
    """Print the ergodic averages against the exact Gibbs law, the Casimir drift and the
    non-finite steps; ``False`` if every draw diverged."""
    from liesample.analysis.diagnostics import (
        casimir_drift,
        count_nonfinite,
        expectation_table,
        format_table,
    )

    wall_time = tree.attrs["sampling_time"]
    mu = tree.posterior["mu"].values
    stats = tree.sample_stats
    exact_moments = np.asarray(target.second_moments())
    draws = {f"E[{n}²]": mu[..., i] ** 2 for i, n in enumerate(system.component_names)}
    draws["E[μ₁μ₂]"] = mu[..., 0] * mu[..., 1]
    exact = {f"E[{n}²]": exact_moments[i, i] for i, n in enumerate(system.component_names)}
    exact["E[μ₁μ₂]"] = 0.0
    if len(set(args.inertia)) > 1:  # an isotropic body's h is constant on the orbit
        draws["E[h]"], exact["E[h]"] = stats["hamiltonian"].values, float(target.mean_energy())
    table = expectation_table(draws, exact, wall_time=wall_time)
    print(f"\nErgodic averages vs the exact Gibbs law ({wall_time:.2f} s of sampling):")
    print(format_table(table))
    drift = casimir_drift({"casimir_error": stats["casimir_error"].values})
    nonfinite = count_nonfinite({"nonfinite": stats["diverging"].values})
    print(f"\nCasimir |μ|² relative drift: max {drift['max']:.2e}; non-finite steps: {nonfinite}")
    return nonfinite < stats["diverging"].size and bool(np.all(np.isfinite(mu)))


def _isotropic_autocorrelation(args: argparse.Namespace, starts, key):
    """``(lag_times, per-chain autocovariances, exact)`` of the isotropic body, whose law is
    uniform and whose autocorrelation is ``r² exp(−σ² t)``; the largest error is printed.

    A path study from exact starts (uniform on the sphere), not a posterior estimate: the
    low-level loop, whose draws are every step and which leaves the convergence checks of
    estimates to its caller."""
    from liesample import systems
    from liesample.analysis.diagnostics import autocovariance
    from liesample.run.runner import sample_chains
    from liesample.targets import isotropic_autocorrelation

    iso_algorithm = _sampler(args, systems.rigid_body((2.0, 2.0, 2.0)))
    iso_draws = round(200.0 / args.step_size)
    iso_mu = np.asarray(
        sample_chains(iso_algorithm, key, starts, iso_draws, progress_bar=False).positions
    )
    max_lag = min(iso_draws - 1, round(3.0 / (args.sigma**2 * args.step_size)))
    per_chain = np.stack([autocovariance(chain[None], max_lag, center=False) for chain in iso_mu])
    lag_times = np.arange(max_lag + 1) * args.step_size
    exact_acf = isotropic_autocorrelation(lag_times, args.radius, args.sigma)
    acf_error = np.max(np.abs(per_chain.mean(0) - exact_acf))
    print(
        f"Isotropic body: max |E[μ(t)·μ(0)] − r²e^(−σ²t)| over t ≤ {lag_times[-1]:.1f} = "
        f"{acf_error:.3f} (r² = {args.radius**2:.2f})"
    )
    return lag_times, per_chain, exact_acf


def _plots(args: argparse.Namespace, system, target, mu, autocorrelation) -> list[Path]:
    """The demo's figures in ``args.output``: traces, the isotropic autocorrelation, the
    marginals and the density on the sphere, each against the exact law."""
    from liesample.analysis.plots import (
        plot_autocorrelation,
        plot_marginals,
        plot_sphere_density,
        plot_traces,
    )

    out = args.output
    lag_times, per_chain, exact_acf = autocorrelation
    flat = mu.reshape(-1, 3)
    return [
        plot_traces(mu[:4], out / "trace.png", names=system.component_names, max_draws=200),
        plot_autocorrelation(
            lag_times,
            (per_chain.mean(0), per_chain.std(0, ddof=1) / np.sqrt(len(per_chain))),
            out / "autocorrelation.png",
            exact=exact_acf,
            title=f"Isotropic rigid body: E[μ(t)·μ(0)] vs exact r²e^(−σ²t), σ={args.sigma}",
        ),
        plot_marginals(
            flat,
            out / "marginals.png",
            exact_densities=[
                (lambda m, i=i: np.asarray(target.marginal_density(m, i))) for i in range(3)
            ],
            names=system.component_names,
            title="Marginals of μ: sampled (histogram) vs exact Gibbs law (line)",
        ),
        plot_sphere_density(
            flat,
            out / "sphere.png",
            logdensity_fn=lambda x: (
                np.asarray(target.logdensity(args.radius * x)) + 2 * np.log(args.radius)
            ),
            title="Density of μ/|μ| on S²: sampled vs exact",
        ),
    ]


def main(argv: list[str] | None = None) -> int:
    """The ``liesample`` command: parse ``argv`` (default ``sys.argv[1:]``), run the command,
    return its exit status (2 for a bad argument, named without a traceback)."""
    args = _parse(sys.argv[1:] if argv is None else argv)
    if args.command == "demo":
        start = time.perf_counter()
        try:
            status = demo(args)
        except (ValueError, TypeError, OSError) as error:  # say what is wrong, no traceback
            print(f"liesample demo: error: {error}", file=sys.stderr)
            return 2
        print(f"Done in {time.perf_counter() - start:.1f} s.")
        return status
    return 2


if __name__ == "__main__":
    sys.exit(main())
