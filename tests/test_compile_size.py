"""Small compiled programs: a first call of Zeitlin's recommended sampler and of the SU(2) heat
bath compiles a bounded number of XLA programs, the heat bath's step holds one copy of its
link update whatever the lattice's dimension, and Zeitlin's step compiles to a bounded number
of XLA kernels, its energy to no scatter (counted, not timed: the numbers do not depend on
the machine).

The bounds are this tree's counts plus a small margin: a regression guard against eager
operations in a constructor or a start check (each compiles as a program of its own) and
against bodies unrolled over directions. The persistent compilation cache (``tests/conftest.py``)
and programs earlier tests compiled can only lower a count.
"""

import contextlib
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.samplers.gauge import heat_bath
from liesample.samplers.orbit import adjusted_lie_poisson

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"

# this tree's counts (float64, a cold process): 7 to build Zeitlin su(8)'s sampler and 14 to
# sample (the 126 of an eager step-size rule and start checks would fail), 12 for the heat bath
ZEITLIN_BUILD_BOUND = 10
ZEITLIN_FIRST_CALL_BOUND = 26
HEAT_BATH_FIRST_CALL_BOUND = 14


@contextlib.contextmanager
def counted_compiles():
    """``with counted_compiles() as compiles:`` counts the XLA compilations of the block
    (``len(compiles)``)."""
    compiles = []

    def listener(event, duration, **kwargs):
        if event == COMPILE_EVENT:
            compiles.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield compiles
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def _sample(sampler, starts):
    return liesample.sample(
        sampler, jax.random.key(0), starts, 10, num_warmup=10, progress_bar=False
    )


def _zeitlin_sampler():
    system = liesample.systems.zeitlin_euler(8)
    return system, liesample.recommended_sampler(system, beta=1.0)


def test_building_zeitlins_recommended_sampler_compiles_few_programs():
    # the step-size rule and the system's checks: one program each, no eager operations
    with counted_compiles() as building:
        _zeitlin_sampler()
    assert len(building) <= ZEITLIN_BUILD_BOUND


@pytest.mark.slow  # compiles the warm-up and the chunks (seconds)
@pytest.mark.filterwarnings("ignore::UserWarning")  # 10 draws: the convergence checks speak
def test_a_first_zeitlin_call_compiles_few_programs():
    with counted_compiles() as compiles:
        system, sampler = _zeitlin_sampler()
        _sample(sampler, np.stack([np.asarray(system.default_position)] * 2))
    assert len(compiles) <= ZEITLIN_FIRST_CALL_BOUND


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_first_heat_bath_call_compiles_few_programs():
    system = liesample.systems.wilson_gauge("SU2", (4, 4))
    starts = np.broadcast_to(np.eye(2, dtype=complex), (2, system.dim, 4, 4, 2, 2))
    with counted_compiles() as compiles:
        _sample(liesample.wilson_heat_bath(system, beta=2.0), starts)
    assert len(compiles) <= HEAT_BATH_FIRST_CALL_BOUND


def _while_loops(shape):
    """The ``while`` loops in the main function of the heat bath's lowered step (traced, not
    compiled; the random bits' own loops are functions of their own, one per shape drawn)."""
    system = liesample.systems.wilson_gauge("SU2", shape)
    kernel = heat_bath.build_kernel(system, heat_bath_sweeps=1, overrelaxation=1)
    links = jnp.broadcast_to(jnp.eye(2, dtype=jnp.complex128), (len(shape), *shape, 2, 2))
    lowered = jax.jit(lambda key, links: kernel(key, heat_bath.GaugeState(links), 2.0)).lower(
        jax.random.key(0), links
    )
    main = lowered.as_text().split("func.func public @main", 1)[1].split("\n  func.func ", 1)[0]
    return len(re.findall(r"stablehlo\.while", main))


def test_the_heat_bath_step_holds_one_link_update_whatever_the_dimension():
    # the 2d direction × parity classes are one scan: a 4-D lattice's step has the loops of
    # a 2-D one, not twice as many rejection loops
    assert _while_loops((2, 2, 2, 2)) == _while_loops((4, 4))


# XLA:CPU compiles each kernel of a program (a fusion, a copy, a transpose, a dot, a gather or
# scatter, a custom call, a loop) on its own, so their number is what a program's compile time
# follows. Zeitlin su(8)'s adjusted step (2 chains, vmapped) compiled to 210 kernels before
# its energy's indexed updates became selections and its proposal was formed once (153 after,
# jaxlib 0.12.0.1). The bound sits between: about 20 % above this tree's count, room for
# another XLA's fusion choices, and below what either regression would add back.
ZEITLIN_STEP_KERNEL_BOUND = 185
_KERNEL = re.compile(r" = \S+ (?:fusion|copy|transpose|gather|scatter|custom-call|dot|while)\(")


def test_zeitlins_energy_holds_no_scatter():
    # the value and gradient of h: gathers of the diagonals and one solve, no indexed update
    # (each .at[].set is a scatter, a kernel of its own in every program that evaluates h)
    system = liesample.systems.zeitlin_euler(8)
    energy = jax.jit(jax.value_and_grad(system.hamiltonian))
    text = energy.lower(jnp.asarray(system.default_position)).as_text()
    assert "stablehlo.scatter" not in text


def test_zeitlins_step_compiles_to_few_kernels():
    system = liesample.systems.zeitlin_euler(8)  # N >= 5: the noise by harmonic transform
    kernel = adjusted_lie_poisson.build_noise_kernel(system)
    state = adjusted_lie_poisson.init(system.default_position, system)
    states = jax.tree.map(lambda leaf: jnp.stack([leaf] * 2), state)
    noise = jnp.zeros((2, system.num_noises + 1))
    step = jax.vmap(lambda n, s: kernel(n, s, 0.01, 1.0, 1.0))
    compiled = jax.jit(step).lower(noise, states).compile()
    assert len(_KERNEL.findall(compiled.as_text())) <= ZEITLIN_STEP_KERNEL_BOUND
