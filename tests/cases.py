"""Every sampler and every sampled system, listed once (as NumPyro lists its distributions).

The generic tests (``tests/test_registry.py``: the Info contract, the batched-step guard, pytree
and array positions through ``liesample.sample``, resume) and the draws-unchanged test
(``tests/test_draws_unchanged.py``) run over these rows, so a new sampler or system is one new
row here.

Each :class:`SamplerCase` builds a small instance of one public sampler and the starts of two
chains; each :class:`SystemCase` builds a small Lie–Poisson system (sampled by
``liesample.lie_poisson_langevin``) and two starts. Factories use only the names
``liesample`` exports at the top level (``liesample.<sampler>``, ``liesample.systems``,
``liesample.spaces``, ``liesample.algebras``), which the package had before and after its
reorganisation into layers: ``tests/data/make_reference_draws.py`` imports this module against
an older tree. Changing a row's parameters changes its reference draws: regenerate them with
that script from a tree whose algorithms are trusted.

Names of ``liesample.systems`` that are not rows are in :data:`NOT_SAMPLED`, with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import liesample

NUM_CHAINS = 2


class SamplerCase(NamedTuple):
    """One public sampler: ``build()`` makes a small instance, ``starts()`` two chains' starts
    (a pytree of arrays with a leading chain axis of ``NUM_CHAINS``)."""

    name: str
    build: Callable[[], Any]
    starts: Callable[[], Any]


class SystemCase(NamedTuple):
    """One Lie–Poisson system: ``build()`` makes a small instance, ``starts()`` two starts on
    (possibly different) orbits, shape ``(NUM_CHAINS, *event_shape)``."""

    name: str
    build: Callable[[], Any]
    starts: Callable[[], np.ndarray]


def _unit_rows(array):
    return array / np.linalg.norm(array, axis=-1, keepdims=True)


def _spin_starts(shape, seed):
    rng = np.random.default_rng(seed)
    return _unit_rows(rng.normal(size=(NUM_CHAINS, *shape, 3)))


# --------------------------------------------------------------------------- targets on R^n

_FIELD_2D = np.array([[0.0, 1.0], [-1.0, 0.0]])
_FIELD_3D = np.array([[0.0, 0.5, -1.0], [-0.5, 0.0, 0.3], [1.0, -0.3, 0.0]])


def _gaussian_logdensity(q):
    return -0.5 * jnp.sum(q * q)


def _correlated_logdensity(q):
    scales = jnp.asarray([1.0, 0.5, 2.0], dtype=q.dtype)
    return -0.5 * jnp.sum((q / scales) ** 2) - 0.3 * q[0] * q[1]


# --------------------------------------------------------------------------- targets on spaces

_VMF_FIELD = np.array([1.0, -2.0, 3.0])


def _product_logdensity(p):
    """A von Mises–Fisher direction and a Gaussian log-concentration, coupled."""
    field = jnp.asarray(_VMF_FIELD, dtype=p["mu"].dtype)
    return jnp.exp(0.3 * p["log_kappa"]) * jnp.dot(field, p["mu"]) - 0.5 * p["log_kappa"] ** 2


def _product_starts():
    return {
        "mu": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
        "log_kappa": np.array([-0.5, 0.5]),
    }


def _su2_logdensity(p):
    """A Wilson-like weight on SU(2) times a Gaussian on R²."""
    return 2.0 * jnp.real(jnp.trace(p[0])) - 0.5 * jnp.sum(p[1] ** 2)


def _su2_starts():
    # [[a, b], [−b̄, ā]] with |a|² + |b|² = 1: in SU(2).
    a, b = 0.6 + 0.48j, 0.64
    rotated = np.array([[a, b], [-np.conj(b), np.conj(a)]])
    return (np.stack([np.eye(2, dtype=complex), rotated]), np.array([[0.0, 0.0], [0.5, -1.0]]))


# --------------------------------------------------------------------------- a custom system

_VMF_KAPPA = 5.0
_VMF_AXIS = np.array([0.31, 0.63, 0.71]) / np.linalg.norm([0.31, 0.63, 0.71])


def _vmf_energy(m):
    return -_VMF_KAPPA * jnp.dot(jnp.asarray(_VMF_AXIS, dtype=m.dtype), m)


def _vmf_noise(m):
    return m


def vmf_system():
    """A von Mises–Fisher law on S² (κ = 5) declared with ``systems.lie_poisson_system``."""
    return liesample.systems.lie_poisson_system(
        liesample.algebras.so3, _vmf_energy, _vmf_noise, _VMF_AXIS, name="vMF"
    )


# --------------------------------------------------------------------------- the systems

_RIGID_STARTS = np.array([[0.3, 0.4, math.sqrt(0.75)], [0.6, 0.0, -0.8]])
# The heavy-top configuration that plain jax.jit once miscompiled under vmap
# (tests/stability/test_stability.py, module notes).
_TOP_STARTS = np.array([[0.6, -1.0, 0.8, 0.3, 0.5, -0.9], [0.1, 0.2, -0.1, 0.0, 0.6, -0.8]])
_VORTEX_STARTS = np.array(
    [
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, -0.8]],
        [[0.0, 0.0, -1.0], [0.8, 0.6, 0.0], [-0.6, 0.0, 0.8], [0.0, -1.0, 0.0]],
    ]
)


def _rigid_body():
    return liesample.systems.rigid_body((1.0, 2.0, 4.0))


def _heavy_top():
    return liesample.systems.heavy_top((1.0, 1.5, 2.5), mgl=1.0, chi=(0.2, 0.0, 1.0))


def _heisenberg():
    return liesample.systems.heisenberg((4, 4), periodic=True)


def _cp_starts(shape, n, seed):
    """Two chains of random unit vectors of C^n at every site of ``shape``."""
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(2, *shape, n)) + 1j * rng.normal(size=(2, *shape, n))
    return z / np.linalg.norm(z, axis=-1, keepdims=True)


def _point_vortices():
    return liesample.systems.point_vortices((1.0, 1.0, -0.5, 2.0), max_degree=2)


def _zeitlin():
    return liesample.systems.zeitlin_euler(3)


def _zeitlin_starts():
    position = np.asarray(_zeitlin().default_position)
    return np.stack([position, 1.5 * position])


SYSTEMS = [
    SystemCase("rigid_body", _rigid_body, lambda: _RIGID_STARTS),
    SystemCase("heavy_top", _heavy_top, lambda: _TOP_STARTS),
    SystemCase("heisenberg", _heisenberg, lambda: _spin_starts((4, 4), seed=0)),
    SystemCase("point_vortices", _point_vortices, lambda: _VORTEX_STARTS),
    SystemCase("zeitlin_euler", _zeitlin, _zeitlin_starts),
    SystemCase("lie_poisson_system", vmf_system, lambda: np.stack([_VMF_AXIS, -_VMF_AXIS])),
]
"""Every system in ``liesample.systems`` that a sampler here samples."""


def system_sampler(case: SystemCase, integrator=None):
    """``liesample.lie_poisson_langevin`` on ``case``'s system at β = 2, step 0.05 (the setting
    of the batched-step guard that caught the XLA:CPU miscompile), the stability bound not
    checked: the guard and the reference runs want every system at one setting."""
    options = {} if integrator is None else {"integrator": integrator}
    return liesample.lie_poisson_langevin(
        case.build(), beta=2.0, step_size=0.05, stability="off", **options
    )


# --------------------------------------------------------------------------- the samplers

SAMPLERS = [
    SamplerCase(
        "lie_poisson_langevin",
        lambda: liesample.lie_poisson_langevin(_rigid_body(), beta=2.0, step_size=0.05),
        lambda: _RIGID_STARTS,
    ),
    SamplerCase(
        "adjusted_lie_poisson",
        lambda: liesample.adjusted_lie_poisson(_heavy_top(), beta=2.0, step_size=0.1),
        lambda: _TOP_STARTS,
    ),
    SamplerCase(
        "magnetic_hmc",
        lambda: liesample.magnetic_hmc(_gaussian_logdensity, 0.3, np.ones(2), 5, _FIELD_2D),
        lambda: np.array([[1.0, -0.5], [0.0, 2.0]]),
    ),
    SamplerCase(
        "magnetic_langevin",
        lambda: liesample.magnetic_langevin(_gaussian_logdensity, 0.1, np.ones(2), 1.0, _FIELD_2D),
        lambda: np.array([[1.0, -0.5], [0.0, 2.0]]),
    ),
    SamplerCase(
        "jittered_magnetic_hmc",
        lambda: liesample.jittered_magnetic_hmc(
            _correlated_logdensity, 0.2, np.array([1.0, 0.5, 2.0]), 6, _FIELD_3D
        ),
        lambda: np.array([[0.5, 0.0, -1.0], [-1.0, 0.3, 2.0]]),
    ),
    SamplerCase(
        "geometric_hmc",
        lambda: liesample.geometric_hmc(
            _product_logdensity,
            {"mu": liesample.spaces.Sphere(2), "log_kappa": liesample.spaces.Euclidean(())},
            0.3,
            4,
        ),
        _product_starts,
    ),
    SamplerCase(
        "geometric_langevin",
        lambda: liesample.geometric_langevin(
            _su2_logdensity,
            (liesample.spaces.SU(2), liesample.spaces.Euclidean((2,))),
            0.1,
            1.0,
        ),
        _su2_starts,
    ),
    SamplerCase(
        "vortex_metropolis",
        lambda: liesample.vortex_metropolis(_point_vortices(), beta=-1.0),
        lambda: _VORTEX_STARTS,
    ),
    SamplerCase(
        "heisenberg_cluster",
        lambda: liesample.heisenberg_cluster(_heisenberg(), beta=0.5),
        lambda: _spin_starts((4, 4), seed=4),
    ),
    SamplerCase(
        "heisenberg_heat_bath",
        lambda: liesample.heisenberg_heat_bath(_heisenberg(), beta=1.0),
        lambda: _spin_starts((4, 4), seed=1),
    ),
    SamplerCase(
        "heisenberg_metropolis",
        lambda: liesample.heisenberg_metropolis(
            liesample.systems.heisenberg((5,), field=(0.0, 0.0, 0.5), anisotropy=0.2), beta=1.5
        ),
        lambda: _spin_starts((5,), seed=2),
    ),
    SamplerCase(
        "wilson_heat_bath",
        lambda: liesample.wilson_heat_bath(liesample.systems.wilson_gauge("SU2", (4, 4)), beta=2.0),
        lambda: np.stack(
            [
                liesample.systems.wilson_gauge("SU2", (4, 4)).hot_start(jax.random.key(seed))
                for seed in (5, 6)
            ]
        ),
    ),
    SamplerCase(
        "cp_heat_bath",
        lambda: liesample.cp_heat_bath(liesample.systems.cp_model((4,), 3), beta=1.5),
        lambda: _cp_starts((4,), 3, seed=7),
    ),
    SamplerCase(
        "heisenberg_wolff",
        lambda: liesample.heisenberg_wolff(_heisenberg(), beta=0.5),
        lambda: _spin_starts((4, 4), seed=3),
    ),
]
"""Every public sampler of ``liesample``, once."""

NOT_SAMPLED = {
    "charged_particle": "simulated on T*R^n (charged_particle_path); its samplers are magnetic_*",
    "charged_particle_path": "a simulation, not a system",
    "stochastic_pendulum": "a symplectic diffusion for liesample.simulate, not sampled",
    "point_vortex_integrator": "an integrator for point_vortices, not a system",
    "isospectral_midpoint": "an integrator for zeitlin_euler, not a system",
    "wilson_gauge": "a T*G system (not Lie-Poisson): its sampler row is wilson_heat_bath",
    "WilsonGauge": "the class of wilson_gauge's systems",
    "n_vector": "O(n) spins: n = 3 is the heisenberg row, other n are not Lie-Poisson systems "
    "(the spin samplers sample them: tests/test_n_vector.py)",
    "NVectorSystem": "the class of n_vector's systems for n != 3",
    "cp_model": "CP(N-1) lattices (not Lie-Poisson in z): its sampler row is cp_heat_bath",
    "CPModelSystem": "the class of cp_model's systems",
}
"""Names in ``liesample.systems`` that are not system rows, and why."""

SAMPLER_NAMES = [case.name for case in SAMPLERS]
SYSTEM_NAMES = [case.name for case in SYSTEMS]


# --------------------------------------------------------------------------- reference runs

REFERENCE_SEED = 2026
REFERENCE_DRAWS = 20
"""Short runs (20 draws of 2 chains): round-off cannot grow into a different draw."""


def reference_runs():
    """``{label: (build sampler, starts)}`` for the draws-unchanged test: every sampler row,
    ``lie_poisson_langevin`` on every system row, and each of its integrators on the rigid
    body."""
    runs = {f"sampler/{case.name}": (case.build, case.starts) for case in SAMPLERS}
    for case in SYSTEMS:
        runs[f"system/{case.name}"] = (lambda case=case: system_sampler(case), case.starts)
    rigid = SYSTEMS[0]
    for integrator in sorted(liesample.integrators.INTEGRATORS):
        runs[f"integrator/{integrator}"] = (
            lambda integrator=integrator: system_sampler(rigid, integrator),
            rigid.starts,
        )
    return runs


def reference_draws(label, build, starts):
    """The stored arrays of one reference run: each position leaf (its pytree path appended to
    ``label``), and the ``energy`` the sampler reported, all as NumPy arrays."""
    run = liesample.sample_chains(
        build(), jax.random.key(REFERENCE_SEED), starts(), REFERENCE_DRAWS, progress_bar=False
    )
    leaves, _ = jax.tree_util.tree_flatten_with_path(run.positions)
    arrays = {
        f"{label}/position{jax.tree_util.keystr(path)}": np.asarray(leaf) for path, leaf in leaves
    }
    arrays[f"{label}/energy"] = np.asarray(run.info["energy"])
    return arrays
