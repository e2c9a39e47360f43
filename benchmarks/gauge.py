"""Lattice gauge theory: 4-D SU(3) at β = 6.0 and 2-D U(1) topology (docs/gauge.md).

A suite of ``benchmarks/run.py`` (``benchmarks/suites.py``); alone::

    python -m benchmarks.gauge            # 8⁴ (benchmarks/results/gauge.json)
    python -m benchmarks.gauge --quick    # 4⁴, few updates (benchmarks/results/quick/)

Options ``--size L`` and ``--thermalisation N`` change the SU(3) lattice. Writes ``gauge.json``;
its section of ``RESULTS.md`` is built from that file alone (:func:`report`).

1. 4-D SU(3) on ``L⁴`` at β = 6.0 from a hot start, thermalised by the heat bath, then one chain
   per sampler from that configuration: the mean plaquette against the published large-volume
   value 0.593683(3) (Boyd et al., Nucl. Phys. B469 (1996) 419, Table 1, β = 6.0), ESS/s of the
   plaquette (ArviZ bulk ESS of the per-update series), link updates per second, for
   - ``heat bath + OR``: ``liesample.wilson_heat_bath`` (1 heat-bath + 4 over-relaxation sweeps);
   - ``HMC``: ``gauge_hmc`` (``liesample.geometric_hmc``, exact group exponentials);
   - ``SMD``: the same with ``momentum_persistence`` ``α = e^{−γε}``, ``γ = 1``, one leapfrog
     step per update;
   - ``plain HMC``: a leapfrog written here (matrix momenta, staple force, ``expm`` drift), the
     baseline a user would write in JAX.
2. 2-D U(1) on ``n × n`` at several β: the integrated autocorrelation time of the geometric
   charge ``Q`` for the heat bath + OR (topological freezing grows it with β), and ``⟨Q²⟩``
   against the exact torus law (``liesample.targets.gauge.u1_torus_charge_law``).

Every error bar printed (the plaquette's, the flowed ``t² E``'s, ``⟨Q²⟩``'s) is an MCSE
``σ / √ESS`` with ArviZ's bulk ESS of the correlated series (:func:`_statistics`), so it includes
the autocorrelation: ``ESS = n / (2 τ_int)``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np

import liesample
from benchmarks import common
from liesample.samplers.gauge.flow import flow_scale, wilson_flow
from liesample.samplers.gauge.hmc import gauge_hmc
from liesample.systems import wilson_gauge
from liesample.targets import gauge as exact

jax.config.update("jax_enable_x64", True)

SUITE = {"order": 35, "title": "lattice gauge theory: 4-D SU(3) at β = 6.0 and 2-D U(1) topology"}

BETA = 6.0
PUBLISHED = {  # SU(3), β = 6.0, large volume
    "plaquette": 0.593683,
    "error": 0.000003,
    "source": "Boyd et al., Nucl. Phys. B469 (1996) 419, Table 1",
}
# Steps for 8⁴: the energy error of a trajectory grows as V·ε⁴ (ε = 0.05 was accepted ~1% of the
# time on 8⁴), and SMD's rejections reverse the momentum, so it needs a high rate too.
HMC_STEP, HMC_STEPS, SMD_STEP = 0.02, 25, 0.03
FULL = {"size": 8, "thermalisation": 20, "counts": {"heat_bath": 40, "hmc": 20, "smd": 200},
        "u1_betas": (1.0, 2.0, 4.0, 6.0), "u1_size": 16, "u1_updates": 2000}  # fmt: skip
QUICK = {"size": 4, "thermalisation": 5, "counts": {"heat_bath": 10, "hmc": 5, "smd": 20},
         "u1_betas": (1.0, 3.0), "u1_size": 8, "u1_updates": 200}  # fmt: skip
U1_MAX_CHARGE = 30  # the exact law's charges: |Q| ≤ 30 holds all of ⟨Q²⟩ on 16² at β ≥ 1
ACCEPTANCE_FLOOR = 0.05  # below it a chain hardly moves: no ESS is reported


CHUNK = 10  # updates per compiled call: one compile per sampler, whatever the run length


def make_run(step, observable):
    """A jitted scan of ``CHUNK`` steps recording ``observable`` and the acceptance."""

    @jax.jit
    def run(state, keys):
        def body(s, k):
            s, info = step(k, s)
            return s, (observable(s.position), info.acceptance_rate)

        return jax.lax.scan(body, state, keys)

    return run


def _chain(run, state, key, num_updates, max_seconds=math.inf, kept=None):
    """``num_updates`` (rounded up to chunks) steps, fewer if ``max_seconds`` of timed chunks
    pass first; the first chunk compiles and is not timed. ``kept``: a list that receives the
    links at the end of every chunk (host copies, outside the timing)."""
    chunks = jax.random.split(key, -(-num_updates // CHUNK) + 1)
    jax.block_until_ready(run(state, jax.random.split(chunks[0], CHUNK)))  # compile
    values, rates = [], []
    seconds = 0.0
    for key in chunks[1:]:
        start = time.perf_counter()
        state, (v, r) = jax.block_until_ready(run(state, jax.random.split(key, CHUNK)))
        seconds += time.perf_counter() - start
        values.append(np.asarray(v))
        rates.append(np.asarray(r))
        if kept is not None:
            kept.append(np.asarray(state.position))
        if seconds > max_seconds:
            break
    return state, np.concatenate(values), float(np.mean(np.concatenate(rates))), seconds


# --------------------------------------------------------------------------- Wilson flow

FLOW = {"time": 3.5, "steps": 70, "at": 2.0, "kept": 40}
"""Flowed energy density: each kept configuration (at most ``kept`` chunk ends a chain, evenly
spaced) flowed to ``time`` in ``steps`` RK3 steps (``liesample.samplers.gauge.flow``); the ESS
row is ``t² E(t)`` at ``t = at``, ``t₀`` where the mean ``t² E(t)`` over every sampler's
configurations reaches 0.3."""


def flowed_energies(system, configurations, flow=FLOW):
    """``(t, E)``: the flow times and ``E(t)`` of each configuration, shape ``(n, steps)``."""
    along = jax.jit(lambda links: wilson_flow(system, links, flow["time"], flow["steps"])[1])
    times = flow["time"] * np.arange(1, flow["steps"] + 1) / flow["steps"]
    return times, np.stack([np.asarray(along(jnp.asarray(u))) for u in configurations])


def _flowed_statistics(times, energies, rate, seconds, flow=FLOW):
    """The ESS row of ``t² E(t)`` at ``t = flow["at"]`` over one chain's kept configurations
    (:func:`_statistics` of that series)."""
    k = int(np.argmin(np.abs(times - flow["at"])))
    series = times[k] ** 2 * energies[:, k]
    row = _statistics(series, rate, seconds)
    return {"flow_time": float(times[k]), "flowed_t2e": row["plaquette"],
            "flowed_mcse": row["mcse"], "flowed_configurations": int(series.size),
            "flowed_ess": row["ess"], "flowed_ess_per_s": row["ess_per_s"]}  # fmt: skip


# --------------------------------------------------------------------------- plain HMC (baseline)


def _traceless_antihermitian(m):
    a = 0.5 * (m - jnp.conj(jnp.swapaxes(m, -1, -2)))
    n = m.shape[-1]
    return a - jnp.trace(a, axis1=-2, axis2=-1)[..., None, None] * jnp.eye(n) / n


def plain_hmc(system, beta, step_size, num_steps):
    """A textbook leapfrog HMC for SU(N) (momenta ``Π`` anti-Hermitian traceless, kinetic
    ``−¼ tr Π²``, force ``−(2β/N) TA(A U)`` from the staples, drift ``U ← U expm(εΠ)``)."""
    n = system.n

    def force(links):
        forces = [
            -(2.0 * beta / n) * _traceless_antihermitian(system.staples(links, mu) @ links[mu])
            for mu in range(system.dim)
        ]
        return jnp.stack(forces)

    def kinetic(p):
        return -0.25 * jnp.sum(jnp.real(jnp.einsum("...ij,...ji->...", p, p)))

    def step(key, state):
        c = jax.random.normal(key, system.space.momentum_array_shape, jnp.float64)
        p0 = system.space.hat(c)  # unit-variance components in the basis iλ_a

        def leapfrog(k, up):
            u, p = up
            u = u @ jax.scipy.linalg.expm(step_size * p)
            return u, p + jnp.where(k < num_steps - 1, 1.0, 0.5) * step_size * force(u)

        start = (state.position, p0 + 0.5 * step_size * force(state.position))
        u, p = jax.lax.fori_loop(0, num_steps, leapfrog, start)
        energy = lambda u, p: kinetic(p) + beta * system.action(u)
        delta = energy(u, p) - energy(state.position, p0)
        accept = jax.random.uniform(jax.random.fold_in(key, 1)) < jnp.exp(-delta)  # NaN: reject
        new = jnp.where(accept, u, state.position)
        return state._replace(position=new), PlainInfo(jnp.minimum(1.0, jnp.exp(-delta)))

    return step


class PlainInfo(NamedTuple):
    acceptance_rate: jax.Array


# --------------------------------------------------------------------------- rows


def _thermalised(size, thermalisation, seed):
    """The heat bath on ``L⁴`` and a configuration it thermalised from a hot start."""
    system = wilson_gauge("SU3", (size,) * 4)
    heat_bath = liesample.wilson_heat_bath(system, beta=BETA, overrelaxation=4)
    run = make_run(heat_bath.step, system.mean_plaquette)
    start = heat_bath.init(system.hot_start(jax.random.key(seed)))
    state, _, _, _ = _chain(run, start, jax.random.key(seed + 1), thermalisation)
    return state.position, heat_bath, run


def su3_rows(size, counts, thermalisation, log, seed=0, max_seconds=math.inf, tile=1, flow=None):
    """The 4-D SU(3) rows at β = 6.0 (one chain each, from one thermalised configuration) and
    that configuration's plaquette; each chain stops early once ``max_seconds`` are timed.

    ``tile > 1``: the configuration is thermalised on ``(L/tile)⁴`` and repeated ``tile`` times
    along each axis (a configuration of the larger torus with the same plaquettes, which the
    untimed first chunk of every chain then moves on), and there is no heat-bath row.

    ``flow`` (like :data:`FLOW`): every row also gets the ESS of the flowed energy density, and
    the function returns a third item, the flow's ``t₀`` over all rows' configurations (``nan``
    if the flow stops short of it) and that mean curve."""
    links, heat_bath, heat_bath_run = _thermalised(size // tile, thermalisation, seed)
    system = wilson_gauge("SU3", (size,) * 4)
    if tile > 1:
        links = jnp.tile(links, (1, tile, tile, tile, tile, 1, 1))
        heat_bath = liesample.wilson_heat_bath(system, beta=BETA, overrelaxation=4)  # its init
    # the energy error of a trajectory grows as V·ε⁴: above 8⁴ the steps shrink as 8/L (the
    # acceptance of 8⁴), HMC keeping its trajectory length
    scale = min(1.0, 8 / size)
    hmc_step, hmc_steps, smd_step = HMC_STEP * scale, round(HMC_STEPS / scale), SMD_STEP * scale
    smd = gauge_hmc(system, beta=BETA, step_size=smd_step, num_integration_steps=1,
                    momentum_persistence=math.exp(-smd_step))  # fmt: skip
    plain = SimpleNamespace(init=heat_bath.init, step=plain_hmc(system, BETA, hmc_step, hmc_steps))
    # sampler -> (algorithm, compiled run or None, step size, steps per update, sweeps per update,
    # updates)
    samplers = {} if tile > 1 else {
        "heat bath + OR": (heat_bath, heat_bath_run, None, None, 5, counts["heat_bath"]),
    }  # fmt: skip
    samplers |= {
        "HMC": (gauge_hmc(system, beta=BETA, step_size=hmc_step, num_integration_steps=hmc_steps),
                None, hmc_step, hmc_steps, hmc_steps, counts["hmc"]),
        "SMD": (smd, None, smd_step, 1, 1, counts["smd"]),
        "plain HMC": (plain, None, hmc_step, hmc_steps, hmc_steps, counts["hmc"]),
    }  # fmt: skip
    rows, curves = [], []
    num_links = system.dim * size**4
    for name, (sampler, run, step_size, steps, sweeps, updates) in samplers.items():
        run = run or make_run(sampler.step, system.mean_plaquette)
        kept = None if flow is None else []
        _, values, rate, seconds = _chain(run, sampler.init(links), jax.random.key(seed + 2),
                                          updates, max_seconds, kept)  # fmt: skip
        row = {"sampler": name, "step_size": step_size, "steps": steps,
               "updates": int(values.size), **_statistics(values, rate, seconds),
               "link_updates_per_s": values.size * sweeps * num_links / seconds}  # fmt: skip
        if flow is not None:
            thin = max(1, math.ceil(len(kept) / flow["kept"]))
            times, energies = flowed_energies(system, kept[thin - 1 :: thin], flow)
            row |= _flowed_statistics(times, energies, rate, seconds, flow)
            row["updates_between_flowed"] = CHUNK * thin
            curves.append(energies)
            log(f"  {name}: t²E({row['flow_time']:g}) {row['flowed_t2e']:.4f} ± "
                f"{row['flowed_mcse']:.4f}, ESS {row['flowed_ess']:.1f}")  # fmt: skip
        rows.append(row)
        log(f"  {name}: plaquette {row['plaquette']:.5f} ± {row['mcse']:.5f}, acceptance "
            f"{rate:.2f}, ESS {row['ess']:.1f}, {seconds:.0f} s")  # fmt: skip
    start_plaquette = float(system.mean_plaquette(links))
    if flow is None:
        return rows, start_plaquette
    mean = np.concatenate(curves).mean(axis=0)
    scale = {"t0": flow_scale(times, mean), "times": times.tolist(), "mean_energy": mean.tolist()}
    return rows, start_plaquette, scale


def _statistics(values, rate, seconds):
    """Mean, MCSE (ArviZ bulk ESS), acceptance, ESS, ESS/s of one chain's series."""
    # a chain that (almost) never moves has no meaningful ESS: report nan, not ArviZ's n
    ess = float(az.ess(values[None, :])) if rate > ACCEPTANCE_FLOOR else math.nan
    se = float(np.std(values, ddof=1) / math.sqrt(ess)) if ess > 0 else math.nan
    return {"plaquette": float(np.mean(values)), "mcse": se, "acceptance": rate, "ess": ess,
            "seconds": seconds, "ess_per_s": ess / seconds}  # fmt: skip


def u1_rows(betas, size, num_updates, log, seed=0):
    """``τ_int(Q)`` and ``⟨Q²⟩`` (heat bath + OR) for each β on ``size²``, with the exact
    ``⟨Q²⟩`` of the torus law."""
    rows = []
    charges = np.arange(-U1_MAX_CHARGE, U1_MAX_CHARGE + 1)
    for beta in betas:
        system = wilson_gauge("U1", (size, size))
        sampler = liesample.wilson_heat_bath(system, beta=beta, overrelaxation=1)
        run = make_run(sampler.step, system.topological_charge)
        state = sampler.init(system.hot_start(jax.random.key(seed)))
        state, _, _, _ = _chain(run, state, jax.random.key(seed + 1), num_updates // 5)
        _, q, _, seconds = _chain(run, state, jax.random.key(seed + 2), num_updates)
        ess_q = float(az.ess(q[None, :]))
        ess_q2 = float(az.ess(q[None, :] ** 2))
        law = exact.u1_torus_charge_law(beta, size * size, U1_MAX_CHARGE)
        rows.append({
            "beta": beta, "updates": int(q.size), "tau_int_Q": q.size / (2.0 * ess_q),
            "q2": float(np.mean(q**2)),
            "q2_mcse": float(np.std(q**2, ddof=1) / math.sqrt(ess_q2)) if ess_q2 > 0 else math.nan,
            "q2_exact": float(np.sum(law * charges**2)), "seconds": seconds,
        })  # fmt: skip
        log(f"  U(1) β = {beta}: τ_int(Q) {rows[-1]['tau_int_Q']:.3g}, ⟨Q²⟩ {rows[-1]['q2']:.3g}"
            f" (exact {rows[-1]['q2_exact']:.3g})")  # fmt: skip
    return rows


def measure(settings, mode, log):
    """The suite's JSON for ``settings`` (``FULL`` or ``QUICK``, possibly with another size)."""
    start = time.perf_counter()
    log(f"  2-D U(1) {settings['u1_size']}², β = {settings['u1_betas']}")
    u1 = u1_rows(settings["u1_betas"], settings["u1_size"], settings["u1_updates"], log)
    log(f"  4-D SU(3) {settings['size']}⁴, β = {BETA}")
    su3, start_plaquette = su3_rows(
        settings["size"], settings["counts"], settings["thermalisation"], log
    )
    return {
        "description": __doc__,
        "machine": common.machine_info(),
        "mode": mode,
        "beta": BETA,
        "size": settings["size"],
        "thermalisation": settings["thermalisation"],
        "start_plaquette": start_plaquette,
        "published": PUBLISHED,
        "acceptance_floor": ACCEPTANCE_FLOOR,
        "su3": su3,
        "u1_size": settings["u1_size"],
        "u1_max_charge": U1_MAX_CHARGE,
        "u1": u1,
        "total_seconds": time.perf_counter() - start,
    }


def run(out_dir: Path, quick: bool, log=print) -> None:
    data = measure(QUICK if quick else FULL, "quick" if quick else "full", log)
    log(f"wrote {common.write_json(out_dir / 'gauge.json', data)}")


# --------------------------------------------------------------------------- report


def _label(row) -> str:
    if row["sampler"] == "heat bath + OR":
        return "heat bath + OR (`wilson_heat_bath`, 1 + 4 sweeps)"
    if row["sampler"] == "SMD":
        return f"SMD (`gauge_hmc`, α = e^(−ε), ε = {row['step_size']}, L = 1)"
    where = "`gauge_hmc` = `geometric_hmc`" if row["sampler"] == "HMC" else "this file, `expm`"
    return f"{row['sampler']} ({where}, ε = {row['step_size']}, L = {row['steps']})"


def _g(x, digits=3) -> str:
    return common.format_or_dash(x, digits)


def _su3_lines(data):
    published = data["published"]
    lines = [
        f"| sampler ({data['size']}⁴, β = {data['beta']}) | updates | plaquette ± MCSE | "
        "acceptance | ESS | ESS/s | link updates/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in data["su3"]:
        error = f" ± {r['mcse']:.5f}" if math.isfinite(r["mcse"]) else " (no ESS)"
        lines.append(
            f"| {_label(r)} | {r['updates']} | {r['plaquette']:.5f}{error} | "
            f"{r['acceptance']:.2f} | {_g(r['ess'])} | {_g(r['ess_per_s'])} | "
            f"{common.format_rate(r['link_updates_per_s'])} |"
        )
    lines += [
        "",
        f"Against the published large-volume plaquette {published['plaquette']}"
        f"({round(published['error'] * 1e6)}) ({published['source']}, β = {data['beta']}): "
        "difference, and the difference in units of √(MCSE² + published error²).",
        "",
        "| sampler | plaquette − published | in MCSE units |",
        "|---|---|---|",
    ]
    for r in data["su3"]:
        diff = r["plaquette"] - published["plaquette"]
        z = diff / math.hypot(r["mcse"], published["error"]) if math.isfinite(r["mcse"]) else None
        cell = "– (no ESS)" if z is None else f"{z:+.1f}"
        lines.append(f"| {r['sampler']} | {diff:+.5f} | {cell} |".replace("-", "−"))
    return lines


def _u1_lines(data):
    lines = [
        "| β | updates | τ_int(Q) (updates) | ⟨Q²⟩ measured ± MCSE | ⟨Q²⟩ exact (torus law) | "
        "difference in MCSE units |",
        "|---|---|---|---|---|---|",
    ]
    for r in data["u1"]:
        z = (r["q2"] - r["q2_exact"]) / r["q2_mcse"] if r["q2_mcse"] > 0 else math.nan
        lines.append(
            f"| {r['beta']} | {r['updates']} | {_g(r['tau_int_Q'])} | {r['q2']:.3f} ± "
            f"{r['q2_mcse']:.3f} | {r['q2_exact']:.3f} | {z:+.1f} |".replace("-", "−")
        )
    return lines


def report_section(data) -> str:
    """The ``RESULTS.md`` section for the contents of ``gauge.json``."""
    machine = data["machine"]
    size, u1_size = data["size"], data["u1_size"]
    precision = "float64" if machine["x64"] else "float32"
    lines = [
        "## Lattice gauge theory: 4-D SU(3) at β = 6.0 and 2-D U(1) topology",
        "",
        (
            f"From `benchmarks/gauge.py` ({machine['date_utc']}, {data['mode']} mode, "
            f"{data['total_seconds']:.0f} s, {machine['cpu_model']}, {machine['usable_cpus']} "
            f"usable CPUs, 1-min load average {machine.get('load_average_1min')}, jax "
            f"{machine['jax']}, {machine['backend']}, {precision}). The machine was "
            "shared with other jobs while this ran, so wall times (and ESS/s, link updates/s) "
            "are rough; the samplers ran one after another in one process."
        ),
        "",
        (
            f"4-D SU(3) on {size}⁴ at β = {data['beta']}: one chain per sampler, from one "
            f"configuration thermalised by {data['thermalisation']} heat-bath updates (1 "
            "heat-bath + 4 over-relaxation sweeps each) from a hot start (its plaquette "
            f"{data['start_plaquette']:.5f}). The plaquette is the "
            "mean over the updates of the lattice-mean plaquette; its MCSE is the standard "
            "deviation over √ESS, with ArviZ's bulk ESS of the per-update series, so it "
            "includes the autocorrelation (ESS = n / 2τ_int; no ESS is "
            f"given for a chain accepted at most {data['acceptance_floor']:.0%} of the time). "
            "These are short runs: with an ESS this small the MCSE is itself uncertain, by "
            "about 1/√(2 ESS) relative. ESS/s and link updates/s exclude compilation; a "
            "heat-bath or over-relaxation sweep and a leapfrog step each count as one update of "
            "every link. HMC draws a fresh momentum every trajectory; SMD (generalised HMC) "
            "makes one leapfrog step per update and keeps the momentum partially "
            "(α = e^(−ε), γ = 1), so every rejection reverses it and it wants an acceptance "
            "near one. The plain HMC is a textbook leapfrog written in the benchmark (matrix "
            "momenta, staple force, `expm` drift), the baseline a user would write in JAX; it "
            "uses the same steps as the library's HMC."
        ),
        "",
        *_su3_lines(data),
        "",
        (
            "The published value is for large volume: the finite-volume shift on "
            f"{size}⁴ and any drift left after the short thermalisation are not separated "
            "from the sampling error here."
        ),
        "",
        (
            f"2-D U(1) on {u1_size}×{u1_size}, heat bath + 1 over-relaxation sweep per update, "
            "from a hot start, a fifth of the updates of thermalisation, then the updates in "
            "the table. τ_int(Q) = n / (2 ESS) of the geometric charge series (ArviZ bulk ESS); "
            "⟨Q²⟩ exact from `liesample.targets.gauge.u1_torus_charge_law` (charges up to "
            f"±{data['u1_max_charge']}); the MCSE of ⟨Q²⟩ uses the ESS of the Q² series. "
            "Topological freezing makes τ_int(Q) grow steeply with β; where τ_int is not small "
            "against the run length the ESS, and so the MCSE, is unreliable."
        ),
        "",
        *_u1_lines(data),
        "",
    ]
    return "\n".join(lines)


def report(out_dir: Path, md_dir: Path) -> str:
    """Section from ``gauge.json``, if it exists (``suites.report_sections``)."""
    del md_dir
    path = out_dir / "gauge.json"
    if not path.exists():
        return ""
    return report_section(common.read_json(path))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4⁴ and few updates (a smoke run)")
    parser.add_argument("--size", type=int, default=None, help="SU(3) lattice extent L")
    parser.add_argument("--thermalisation", type=int, default=None, help="heat-bath updates")
    args = parser.parse_args(argv)
    settings = dict(QUICK if args.quick else FULL)
    for name in ("size", "thermalisation"):
        if getattr(args, name) is not None:
            settings[name] = getattr(args, name)
    out_dir = common.BENCH_DIR / "results" / ("quick" if args.quick else "")
    start = time.perf_counter()
    data = measure(settings, "quick" if args.quick else "full", lambda m: print(m, flush=True))
    print(f"wrote {common.write_json(out_dir / 'gauge.json', data)}")
    print(report(out_dir, out_dir))
    print(f"suite gauge took {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
