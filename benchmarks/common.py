"""Shared set-up for the benchmarks: the rigid-body problem, configurations, timing, machine.

Float64 is switched on here, before anything builds an array; every benchmark module imports
this one first.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import subprocess
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
from matplotlib.figure import Figure

import liesample
from liesample.dynamics import make_dynamics
from liesample.systems import rigid_body
from liesample.targets import RestrictedGaussian

BENCH_DIR = Path(__file__).resolve().parent
REPO_DIR = BENCH_DIR.parent

# The problem every benchmark samples: rigid body I = (1, 2, 4), β = 3, σ = 1, |μ| = 1.5.
INERTIA = (1.0, 2.0, 4.0)
BETA = 3.0
SIGMA = 1.0
RADIUS = 1.5

INTEGRATOR_NAMES = ("splitting", "rkmk_heun", "lie_euler", "euler_heun")

# Scenes of the throughput benchmark: label -> keyword arguments of the sampler.
SCENES = {
    "all effects": {"beta": BETA, "sigma": SIGMA},
    "Hamiltonian only": {"sigma": 0.0, "theta": 0.0},
    "noise+dissipation, no Hamiltonian": {"beta": BETA, "sigma": SIGMA, "hamiltonian": False},
}


@dataclass(frozen=True)
class Config:
    """What one invocation of ``benchmarks/run.py`` measures."""

    mode: str
    # 1. throughput
    throughput_chains: tuple[int, ...] = (1, 1_000, 100_000)
    throughput_step_size: float = 0.1
    throughput_target_seconds: float = 0.6  # length of each timed call
    throughput_repeats: int = 3  # best of
    # (integrator, scene) pairs; None = every integrator in every scene
    throughput_pairs: tuple[tuple[str, str], ...] | None = None
    # 2. accuracy–cost
    accuracy_chains: int = 4096
    accuracy_time: float = 200.0  # physical time T per chain, burn-in included
    accuracy_burn_in: float = 10.0  # discarded
    accuracy_step_sizes: tuple[float, ...] = (0.8, 0.4, 0.2, 0.1, 0.05)
    accuracy_integrators: tuple[str, ...] = INTEGRATOR_NAMES
    ess_check_chains: int = 32  # stored run per setting for the ArviZ ESS cross-check
    casimir_tolerance: float = 0.1  # relative |C − C₀|/C₀ that counts as "left the orbit"
    target_errors: tuple[float, ...] = (0.03, 0.01, 0.005, 0.003)
    # High-precision order check (more chains, longer T) for the integrators whose small-h
    # biases the sweep above cannot resolve; empty to skip.
    order_check_integrators: tuple[str, ...] = ("splitting",)
    order_check_chains: int = 16384
    order_check_time: float = 400.0
    order_check_step_sizes: tuple[float, ...] = (0.4, 0.2, 0.1)
    # 3. exact i.i.d. sampler
    iid_sizes: tuple[int, ...] = (10_000, 1_000_000)
    seed: int = 20240611
    extra: dict = field(default_factory=dict)

    def to_json(self):
        return asdict(self)


FULL = Config(mode="full")
QUICK = Config(
    mode="quick",
    throughput_target_seconds=0.1,
    throughput_pairs=tuple((name, "all effects") for name in INTEGRATOR_NAMES)
    + (("splitting", "Hamiltonian only"), ("splitting", "noise+dissipation, no Hamiltonian")),
    accuracy_chains=512,
    accuracy_time=50.0,
    accuracy_burn_in=5.0,
    accuracy_step_sizes=(0.4, 0.2, 0.1),
    ess_check_chains=16,
    target_errors=(0.03, 0.01),
    order_check_integrators=(),
    iid_sizes=(10_000, 100_000),
)


def system():
    return rigid_body(INERTIA)


def target() -> RestrictedGaussian:
    return RestrictedGaussian(inertia=INERTIA, beta=BETA, radius=RADIUS)


def exact_second_moments() -> np.ndarray:
    """Exact ``E[μ_i²]``, i = 1..3."""
    return np.diag(np.asarray(target().second_moments()))


def sampler(integrator: str, scene: str, step_size: float):
    """The public sampler, ``liesample.lie_poisson_langevin``, for one scene."""
    return liesample.lie_poisson_langevin(
        system(), step_size=step_size, integrator=integrator, **SCENES[scene]
    )


def dynamics_parameters(scene: str):
    """``(sigma, theta, Scene)`` exactly as the sampler derives them."""
    return make_dynamics(system(), **SCENES[scene])


def block(x):
    return jax.block_until_ready(x)


def timed(fn, *args, repeats: int = 1, cpu: bool = False):
    """``(result, seconds)`` of ``fn(*args)``, waited for: the benchmarks' one timer.

    ``repeats``: the best (shortest) of that many calls, the usual cost on a shared machine.
    ``cpu=True``: ``(result, seconds, CPU seconds)``, the CPU time of this process during that
    call, the steadier measure where other processes take turns on the cores (XLA:CPU may use
    several threads, so it can exceed the wall time)."""
    best = (math.inf, math.inf)
    for _ in range(repeats):
        wall, used = time.perf_counter(), time.process_time()
        out = block(fn(*args))
        best = min(best, (time.perf_counter() - wall, time.process_time() - used))
    return (out, *best) if cpu else (out, best[0])


# --------------------------------------------------------------------------- machine


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _git(*args) -> str | None:
    try:
        out = subprocess.run(
            ["git", *args], cwd=REPO_DIR, capture_output=True, text=True, timeout=10, check=True
        )
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


# The first commit whose loops compile through liesample.jit (XLA:CPU's miscompiling pass off).
_SAFE_COMPILE_COMMIT = "25f23bc"


def compiled_safely(machine: dict) -> bool:
    """Whether a suite's JSON was measured free of the jax 0.12 XLA:CPU miscompile: on jax
    before 0.12, or with the library's compile path (recorded, or implied by its commit)."""
    if not str(machine.get("jax", "")).startswith("0.12"):
        return True
    if machine.get("compile_path") == "liesample.jit":
        return True
    commit = machine.get("git_commit")
    return bool(commit) and _git("merge-base", "--is-ancestor", _SAFE_COMPILE_COMMIT, commit) == ""


def machine_info() -> dict:
    import jaxlib

    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    status = _git("status", "--porcelain", "--untracked-files=no")
    return {
        "cpu_model": _cpu_model(),
        "logical_cpus": os.cpu_count(),
        "usable_cpus": usable,
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "compile_path": "liesample.jit",
        "numpy": np.__version__,
        "python": platform.python_version(),
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "x64": bool(jax.config.jax_enable_x64),
        "platform": platform.platform(),
        "date_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "git_commit": _git("rev-parse", "--short", "HEAD"),
        "git_dirty": None if status is None else bool(status),
        # Other processes slow every timing; ratios within one run are affected alike.
        "load_average_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
    }


# --------------------------------------------------------------------------- JSON


def _jsonable(value):
    """Numbers and containers as JSON; non-finite floats as the strings "nan"/"inf"/"-inf"."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return v
    return value


def _from_json(value):
    if isinstance(value, dict):
        return {k: _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    if value in ("nan", "inf", "-inf"):
        return float(value)
    return value


def write_json(path: Path, data) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_jsonable(data), indent=1, allow_nan=False) + "\n")
    return path


def read_json(path: Path):
    return _from_json(json.loads(path.read_text()))


# --------------------------------------------------------------------------- report sections
#
# Each suite writes its own Markdown section from its JSON; ``benchmarks/report.py`` only
# assembles them. These are the shared formatting helpers and the core sections' inputs.

DPI = 130
COLORS = {"splitting": "C0", "rkmk_heun": "C1", "lie_euler": "C2", "euler_heun": "C3"}
MARKERS = {"splitting": "o", "rkmk_heun": "s", "lie_euler": "D", "euler_heun": "^"}
SUP = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def chains_label(n: int) -> str:
    if n == 1:
        return "1 chain"
    e = math.log10(n)
    if abs(e - round(e)) < 1e-9 and n >= 100:
        return f"10{str(round(e)).translate(SUP)} chains"
    return f"{n} chains"


def format_rate(x) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if x >= scale:
            return f"{x / scale:.3g} {unit}"
    return f"{x:.3g}"


def format_g(x, digits=3) -> str:
    if x is None:
        return "–"
    x = float(x)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "−inf"
    return f"{x:.{digits}g}".replace("-", "−")


def format_or_dash(x, digits=3) -> str:
    """``x`` to ``digits`` significant figures; ``–`` for a missing or non-finite value."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}g}"


def format_signed(x, se, decimals=4) -> str:
    return f"{x:+.{decimals}f} ± {se:.{decimals}f}".replace("-", "−")


def format_seconds(x) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    if x < 1e-3:
        return f"{x * 1e6:.3g} µs"
    if x < 1:
        return f"{x * 1e3:.3g} ms"
    if x < 120:
        return f"{x:.3g} s"
    if x < 7200:
        return f"{x / 60:.3g} min"
    return f"{x / 3600:.3g} h"


def relative_link(path: Path, md_dir: Path) -> Path:
    """``path`` relative to the report's folder when it lies below it, else as given."""
    return path.relative_to(md_dir) if path.is_relative_to(md_dir) else path


def save_figure(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    fig.clear()
    return path


@dataclass
class CoreResults:
    """The rigid-body core's JSON (``meta``, ``throughput``, ``iid``, ``accuracy``,
    ``order_check``) and where the report goes; sections append the files they write to
    ``written``, and may cache derived numbers in ``derived``."""

    out_dir: Path
    md_dir: Path
    meta: dict
    throughput_rows: list
    iid: dict
    accuracy_rows: list
    order_rows: list
    written: list = field(default_factory=list)
    derived: dict = field(default_factory=dict)

    @classmethod
    def load(cls, out_dir: Path, md_dir: Path) -> CoreResults:
        order_path = out_dir / "order_check.json"
        return cls(
            out_dir=out_dir,
            md_dir=md_dir,
            meta=read_json(out_dir / "meta.json"),
            throughput_rows=read_json(out_dir / "throughput.json")["rows"],
            iid=read_json(out_dir / "iid.json"),
            accuracy_rows=read_json(out_dir / "accuracy.json")["rows"],
            order_rows=read_json(order_path)["rows"] if order_path.exists() else [],
        )

    @property
    def config(self) -> dict:
        return self.meta["config"]

    def link(self, path: Path) -> str:
        """``path`` relative to the report's folder."""
        return os.path.relpath(path, self.md_dir)
