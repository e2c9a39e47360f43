"""The worker of ``benchmarks/first_draw.py``: one family, one scenario, in this interpreter.

Run by the suite as ``python -m benchmarks._first_draw_driver FAMILY SCENARIO [--quick]`` in a
fresh process (the suite sets the environment: no persistent compilation cache, or a fresh
temporary one); prints one JSON line, the last of its output.

Scenarios:

- ``calls``: the first call (build the system and the sampler, ``liesample.sample``), then a
  repeated call on the same objects, then a call on a system and sampler rebuilt from equal
  arguments;
- ``sweep``: :data:`SWEEP_POINTS` calls (10; 4 in quick mode), each building its system and
  sampler at another value of the family's swept constant;
- ``first``: the first call alone (the second-process scenario runs it twice, each in its own
  process, with the cache on).

Each call is timed whole (``time.perf_counter``), with the XLA backend compilations it caused
(count and seconds, from JAX's monitoring events), the seconds spent tracing and lowering, the
programs loaded from the persistent cache instead, and the tree's ``sampling_time`` attribute
(compilation excluded).

Each family is built as the README shows a new user: the constructors of ``liesample`` and
``liesample.systems``, the sampler's own warm-up and adaptation where it has one.
"""

from __future__ import annotations

import inspect
import json
import sys
import time

_START = time.perf_counter()

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import liesample
from liesample import systems
from liesample.spaces import Sphere

IMPORT_SECONDS = time.perf_counter() - _START

NUM_CHAINS = 4
RUN_LENGTH = {"full": (50, 50), "quick": (20, 20)}  # (warm-up, draws)
SWEEP_POINTS = {"full": 10, "quick": 4}

# JAX's monitoring events: the XLA compile (a persistent-cache load is reported by the same
# event, after a cache-hit event), tracing and lowering.
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
LOWER_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
CACHE_HIT_EVENT = "/jax/compilation_cache/cache_hits"


def covered_seconds(spans) -> float:
    """The length of the union of ``(start, end)`` intervals (nested spans counted once)."""
    total, reach = 0.0, -float("inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


class Events:
    """Counts and sums JAX's compile events while registered (:func:`measure`): ``compiles``
    are XLA compilations, ``cache_loads`` programs read from the persistent cache instead;
    ``trace_lower_seconds`` is the time spent tracing or lowering and not compiling (a jit
    traced inside another's trace reports its own span, and a trace may compile the eager
    operations it runs, so the spans are united, not summed)."""

    def __init__(self):
        self.compiles, self.compile_seconds = 0, 0.0
        self.cache_loads, self.cache_load_seconds = 0, 0.0
        self.spans, self.compile_spans = [], []
        self.hit = False  # a cache hit was announced: the next compile event is its load

    def duration(self, event, seconds, **kwargs):
        if event == COMPILE_EVENT and self.hit:
            self.cache_loads += 1
            self.cache_load_seconds += seconds
            self.hit = False
        elif event == COMPILE_EVENT:
            self.compiles += 1
            self.compile_seconds += seconds

    def span(self, event, start, end, **kwargs):
        if event in (TRACE_EVENT, LOWER_EVENT):
            self.spans.append((start, end))
        elif event == COMPILE_EVENT:
            self.compile_spans.append((start, end))

    def event(self, event, **kwargs):
        if event == CACHE_HIT_EVENT:
            self.hit = True

    def as_json(self) -> dict:
        return {"compiles": self.compiles, "compile_seconds": self.compile_seconds,
                "cache_loads": self.cache_loads, "cache_load_seconds": self.cache_load_seconds,
                "trace_lower_seconds": covered_seconds(self.spans + self.compile_spans)
                - covered_seconds(self.compile_spans)}  # fmt: skip


def measure(call) -> dict:
    """``call()`` timed whole, with the JAX events it caused; ``call`` returns the DataTree."""
    import warnings

    events = Events()
    jax.monitoring.register_event_duration_secs_listener(events.duration)
    jax.monitoring.register_event_time_span_listener(events.span)
    jax.monitoring.register_event_listener(events.event)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # short runs: the convergence checks speak
            begin = time.perf_counter()
            tree = call()
            wall = time.perf_counter() - begin
    finally:
        jax.monitoring.unregister_event_duration_listener(events.duration)
        jax.monitoring.unregister_event_time_span_listener(events.span)
        jax.monitoring.unregister_event_listener(events.event)
    sampling = tree.attrs.get("sampling_time")
    return {"wall_seconds": wall, **events.as_json(),
            "sampling_seconds": None if sampling is None else float(sampling)}  # fmt: skip


# --------------------------------------------------------------------------- the families
#
# Each builder takes the swept constant and returns ``(sampler, starts)``, building the system
# too, as a user's ``def run(beta): system = ...; sampler = ...`` does.


def _rigid_body_starts():
    return jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0], [0.0, 0.0, 1.5], [0.0, -1.5, 0.0]])


def lie_poisson_langevin(beta):
    system = systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    sampler = liesample.lie_poisson_langevin(system, beta=beta, sigma=1.0, step_size=0.05)
    return sampler, _rigid_body_starts()


def adjusted_lie_poisson(beta):
    system = systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    return liesample.adjusted_lie_poisson(system, beta=beta, sigma=1.0), _rigid_body_starts()


def vortex_metropolis(beta):
    system = systems.point_vortices((1.0, 1.0, -1.0, 2.0), max_degree=3)
    sampler = liesample.vortex_metropolis(system, beta=beta)
    return sampler, np.tile(system.default_position, (NUM_CHAINS, 1, 1))


def zeitlin(size):
    """``recommended_sampler`` on su(N) (``adjusted_lie_poisson``), ``b = β‖W‖²/(N²−1)``."""

    def build(b):
        system = systems.zeitlin_euler(size)
        squared_norm = float(np.sum(np.asarray(system.default_position) ** 2))
        beta = b * (size * size - 1) / squared_norm  # docs/zeitlin.md: β ∝ N²/‖W‖²
        sampler = liesample.recommended_sampler(system, beta=beta)
        return sampler, np.tile(system.default_position, (NUM_CHAINS, 1, 1))

    return build


def _cubic_spins():
    system = systems.heisenberg((8, 8, 8), coupling=1.0, periodic=True)
    return system, np.tile(system.default_position, (NUM_CHAINS, 1, 1, 1, 1))


def heisenberg_heat_bath(beta):
    system, starts = _cubic_spins()
    return liesample.heisenberg_heat_bath(system, beta=beta), starts


def heisenberg_cluster(beta):
    system, starts = _cubic_spins()
    return liesample.heisenberg_cluster(system, beta=beta), starts


def _su2_lattice():
    system = systems.wilson_gauge("SU2", (8, 8))
    keys = jax.random.split(jax.random.key(1), NUM_CHAINS)
    return system, jnp.stack([system.hot_start(k) for k in keys])


def wilson_heat_bath(beta):
    system, starts = _su2_lattice()
    return liesample.wilson_heat_bath(system, beta=beta), starts


def gauge_hmc(beta):
    from liesample.samplers.gauge.hmc import gauge_hmc as build

    system, starts = _su2_lattice()
    return build(system, beta=beta, step_size=0.1, num_integration_steps=10), starts


def vmf_logdensity(x, kappa):
    """A von Mises–Fisher log density on S², concentration ``kappa``."""
    return kappa * (jnp.array([0.0, 0.6, 0.8]) @ x)


def gaussian_logdensity(x, scale):
    """A 5-D isotropic Gaussian log density of sd ``scale``."""
    return -0.5 * jnp.sum((x / scale) ** 2)


def model_channel(build) -> str:
    """How a log-density sampler gets the model's constant: ``"model_args"`` where ``build``
    takes that argument (the library's documented channel), else ``"closure"``."""
    return "model_args" if "model_args" in inspect.signature(build).parameters else "closure"


def _with_constant(build, logdensity, value, *args):
    """``build(logdensity at value, *args)``, the constant passed by :func:`model_channel`."""
    if model_channel(build) == "model_args":
        return build(logdensity, *args, model_args=(value,))
    return build(lambda x: logdensity(x, value), *args)  # a new closure at every value


def geometric_hmc(kappa):
    starts = jax.vmap(Sphere(2).uniform)(jax.random.split(jax.random.key(1), NUM_CHAINS))
    return _with_constant(liesample.geometric_hmc, vmf_logdensity, kappa, Sphere(2)), starts


def magnetic_hmc(scale):
    starts = jax.random.normal(jax.random.key(1), (NUM_CHAINS, 5))
    return _with_constant(liesample.magnetic_hmc, gaussian_logdensity, scale), starts


def families(quick: bool) -> dict:
    """name -> ``(builder, the swept constant's name, its value, its sweep, how it is
    passed)``."""
    zeitlin_size = 16 if quick else 32
    points = SWEEP_POINTS["quick" if quick else "full"]
    sweep = lambda centre: tuple(float(b) for b in np.linspace(0.5, 1.5, points) * centre)
    beta = lambda build, centre: (build, "beta", centre, sweep(centre), "beta=")
    model = lambda build, sampler, name, v: (build, name, v, sweep(v), model_channel(sampler))
    return {
        "lie_poisson_langevin": beta(lie_poisson_langevin, 3.0),
        "adjusted_lie_poisson": beta(adjusted_lie_poisson, 3.0),
        "vortex_metropolis": beta(vortex_metropolis, 2.0),
        f"zeitlin_su{zeitlin_size}": (zeitlin(zeitlin_size), "b", 1.0, sweep(1.0), "beta="),
        "heisenberg_heat_bath": beta(heisenberg_heat_bath, 0.693),
        "heisenberg_cluster": beta(heisenberg_cluster, 0.693),
        "wilson_heat_bath": beta(wilson_heat_bath, 2.0),
        "gauge_hmc": beta(gauge_hmc, 2.0),
        "geometric_hmc": model(geometric_hmc, liesample.geometric_hmc, "kappa", 10.0),
        "magnetic_hmc": model(magnetic_hmc, liesample.magnetic_hmc, "scale", 1.0),
    }


# --------------------------------------------------------------------------- scenarios


def _sample(build, value, num_warmup, num_draws, built=None):
    """``liesample.sample`` on ``build(value)`` (or on ``built``, the same objects again)."""
    sampler, starts = build(value) if built is None else built
    tree = liesample.sample(
        sampler, jax.random.key(0), starts, num_draws, num_warmup=num_warmup, progress_bar=False
    )
    return tree, (sampler, starts)


def run_scenario(family: str, scenario: str, quick: bool) -> dict:
    """The measurements of ``scenario`` for ``family`` (module docstring)."""
    build, name, value, sweep, passed_as = families(quick)[family]
    num_warmup, num_draws = RUN_LENGTH["quick" if quick else "full"]
    kept = {}

    def first():
        tree, kept["objects"] = _sample(build, value, num_warmup, num_draws)
        return tree

    calls = {}
    if scenario in ("calls", "first"):
        calls["first"] = measure(first)
    if scenario == "calls":
        again = lambda: _sample(build, value, num_warmup, num_draws, kept["objects"])[0]
        calls["repeated"] = measure(again)
        calls["rebuilt"] = measure(lambda: _sample(build, value, num_warmup, num_draws)[0])
    if scenario == "sweep":
        calls["points"] = [
            measure(lambda v=v: _sample(build, v, num_warmup, num_draws)[0]) for v in sweep
        ]
    return {
        "family": family,
        "scenario": scenario,
        "swept": name,
        "value": value,
        "sweep": list(sweep),
        "passed_as": passed_as,
        "num_chains": NUM_CHAINS,
        "num_warmup": num_warmup,
        "num_draws": num_draws,
        "import_seconds": IMPORT_SECONDS,
        "cache_dir": jax.config.jax_compilation_cache_dir,
        "cache_min_compile_seconds": jax.config.jax_persistent_cache_min_compile_time_secs,
        "calls": calls,
    }


if __name__ == "__main__":
    result = run_scenario(sys.argv[1], sys.argv[2], "--quick" in sys.argv[3:])
    print(json.dumps(result))
