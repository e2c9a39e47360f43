"""The public API tried family by family as a careless new user would (liesample issue 43).

Each row of ``ROWS`` is one call with one bad argument — constructors, samplers, spins, tuning,
numerics (NaN/inf/huge, bool/complex/string/int dtypes, 0-d vs 1-d, lists, numpy scalars) and
NumPyro — and the clear error it must raise: the exception type and a ``match=`` regex that
names the parameter. ``ACCEPTED`` holds the near misses that must work (numpy scalars, lists,
ints where floats are meant). Every call is refused (or built) before any XLA compilation of a
chain: at most a shape evaluation (``jax.eval_shape``) or a start check runs.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import pytest

import liesample
import liesample.numpyro as lnp
from liesample import accuracy, algebras, spaces, systems
from liesample.geometry.algebras import StructureConstants
from liesample.numpyro_mcmc import GeometricHMC

NAN, INF = math.nan, math.inf
KEY = jax.random.key(0)
RIGID = systems.rigid_body()
CHAIN = systems.heisenberg((4,))
PAIR = systems.point_vortices([1.0, 1.0])
E2 = spaces.Euclidean((2,))
FIELD = np.array([[0.0, 1.0], [-1.0, 0.0]])
STARTS = np.tile(RIGID.default_position, (2, 1))
UP = np.tile([0.0, 0.0, 1.0], (4, 1))


def _logdensity(q):
    return -0.5 * jnp.sum(q * q)


def _norm2(mu):
    return jnp.sum(mu * mu)


def _identity(mu):
    return mu


def _model():
    numpyro.sample("x", dist.Normal(0.0, 1.0))


def _langevin(**kwargs):
    return liesample.lie_poisson_langevin(RIGID, **{"beta": 1.0, "step_size": 0.1, **kwargs})


def _lps(hamiltonian=_norm2, position=(0.0, 0.0, 1.0), **options):
    return systems.lie_poisson_system(algebras.so3, hamiltonian, _identity, position, **options)


def _ghmc(**kwargs):
    return liesample.geometric_hmc(_logdensity, E2, 0.1, 3, **kwargs)


def _mhmc(**kwargs):
    arguments = {"inverse_mass_matrix": np.ones(2), "magnetic_field": FIELD, **kwargs}
    return liesample.magnetic_hmc(_logdensity, 0.1, num_integration_steps=3, **arguments)


def _window(**kwargs):
    return liesample.window_adaptation(liesample.geometric_hmc, _logdensity, E2, **kwargs)


def _choose(**kwargs):
    arguments = {
        "system": RIGID, "beta": 1.0, "tolerance": 0.01, "observables": _identity,
        "initial_positions": STARTS, "rng_key": KEY, **kwargs,
    }  # fmt: skip
    return accuracy.choose_step_size(**arguments)


ROWS = [
    # ---- constructors: systems.rigid_body, heavy_top
    ("rigid_body inertia scalar", lambda: systems.rigid_body(1.0), ValueError, "inertia.*3"),
    ("rigid_body inertia None", lambda: systems.rigid_body(None), ValueError, "inertia"),
    ("rigid_body inertia dict", lambda: systems.rigid_body({"a": 1}), ValueError, "inertia"),
    ("rigid_body inertia 2-D", lambda: systems.rigid_body(np.ones((3, 3))), ValueError, "inertia"),
    (
        "rigid_body inertia complex",
        lambda: systems.rigid_body((1j, 2, 3)),
        TypeError,
        r"inertia\[0\].*real",
    ),
    (
        "rigid_body inertia bool",
        lambda: systems.rigid_body((True,) * 3),
        TypeError,
        r"inertia\[0\].*real",
    ),
    (
        "rigid_body inertia string",
        lambda: systems.rigid_body(("1", "2", "3")),
        TypeError,
        r"inertia\[0\].*real",
    ),
    (
        "rigid_body split_hamiltonian",
        lambda: systems.rigid_body(split_hamiltonian="yes"),
        TypeError,
        "split_hamiltonian.*bool",
    ),
    ("heavy_top mgl array", lambda: systems.heavy_top(mgl=np.ones(2)), TypeError, "mgl.*scalar"),
    ("heavy_top mgl complex", lambda: systems.heavy_top(mgl=1j), TypeError, "mgl.*scalar"),
    ("heavy_top mgl string", lambda: systems.heavy_top(mgl="1"), TypeError, "mgl.*scalar"),
    (
        "heavy_top chi complex",
        lambda: systems.heavy_top(chi=(0, 0, 1j)),
        ValueError,
        "chi.*finite reals",
    ),
    (
        "heavy_top chi bool",
        lambda: systems.heavy_top(chi=(False, False, True)),
        ValueError,
        "chi.*finite reals",
    ),
    ("heavy_top chi string", lambda: systems.heavy_top(chi="z"), ValueError, "chi"),
    (
        "heavy_top chi scalar",
        lambda: systems.heavy_top(chi=np.float64(1.0)),
        ValueError,
        "chi.*3-vector",
    ),
    (
        "heavy_top gravity numpy bool",
        lambda: systems.heavy_top(gravity=np.False_),
        TypeError,
        "gravity.*bool",
    ),
    # ---- constructors: systems.point_vortices, zeitlin_euler, charged_particle, pendulum
    ("point_vortices scalar", lambda: systems.point_vortices(1.0), ValueError, "circulations.*1-D"),
    (
        "point_vortices complex",
        lambda: systems.point_vortices([1j, 1.0]),
        TypeError,
        "circulations",
    ),
    (
        "point_vortices bool",
        lambda: systems.point_vortices([True, True]),
        TypeError,
        "circulations",
    ),
    ("point_vortices string", lambda: systems.point_vortices("ab"), TypeError, "circulations"),
    (
        "point_vortices inf",
        lambda: systems.point_vortices([1.0, INF]),
        ValueError,
        "circulations must be finite",
    ),
    (
        "point_vortices max_degree float",
        lambda: systems.point_vortices([1.0, 1.0], 2.5),
        TypeError,
        "max_degree",
    ),
    (
        "point_vortices radius nan",
        lambda: systems.point_vortices([1.0, 1.0], radius=NAN),
        ValueError,
        "radius.*finite",
    ),
    (
        "point_vortices radius array",
        lambda: systems.point_vortices([1.0, 1.0], radius=np.ones(2)),
        TypeError,
        "radius.*scalar",
    ),
    (
        "zeitlin_euler size float",
        lambda: systems.zeitlin_euler(3.0),
        ValueError,
        "N must be an int",
    ),
    (
        "zeitlin_euler size string",
        lambda: systems.zeitlin_euler("3"),
        ValueError,
        "N must be an int",
    ),
    (
        "zeitlin_euler size bool",
        lambda: systems.zeitlin_euler(True),
        ValueError,
        "N must be an int",
    ),
    (
        "zeitlin_euler noise_degree float",
        lambda: systems.zeitlin_euler(3, noise_degree=1.5),
        TypeError,
        "noise_degree must be an int",
    ),
    (
        "zeitlin_euler noise_smoothness negative",
        lambda: systems.zeitlin_euler(3, noise_smoothness=-1),
        ValueError,
        "noise_smoothness",
    ),
    (
        "zeitlin_euler position shape",
        lambda: systems.zeitlin_euler(3, position=np.zeros((2, 2))),
        ValueError,
        r"position must have shape \(3, 3\)",
    ),
    (
        "zeitlin_euler position string",
        lambda: systems.zeitlin_euler(3, position="x"),
        TypeError,
        r"position must be a real \(3, 3\) array",
    ),
    (
        "zeitlin_euler position complex",
        lambda: systems.zeitlin_euler(3, position=1j * np.ones((3, 3))),
        TypeError,
        "position must be a real",
    ),
    (
        "zeitlin_euler position bool",
        lambda: systems.zeitlin_euler(3, position=np.eye(3, dtype=bool)),
        TypeError,
        "position must be a real",
    ),
    (
        "charged_particle field complex",
        lambda: systems.charged_particle(_norm2, magnetic_field=1j * FIELD),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "charged_particle field bool",
        lambda: systems.charged_particle(_norm2, magnetic_field=np.zeros((2, 2), bool)),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "charged_particle field vector complex",
        lambda: systems.charged_particle(_norm2, magnetic_field=np.array([0, 0, 1j])),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "charged_particle field non-square",
        lambda: systems.charged_particle(_norm2, magnetic_field=np.zeros((2, 3))),
        ValueError,
        "magnetic_field must be a square",
    ),
    (
        "charged_particle potential complex",
        lambda: systems.charged_particle(lambda q: 1j * jnp.sum(q), magnetic_field=FIELD),
        TypeError,
        "potential_fn must return a real floating scalar",
    ),
    (
        "charged_particle potential vector",
        lambda: systems.charged_particle(_identity, magnetic_field=FIELD),
        ValueError,
        "potential_fn must map",
    ),
    (
        "charged_particle potential not callable",
        lambda: systems.charged_particle(3.0, magnetic_field=FIELD),
        TypeError,
        "potential_fn",
    ),
    (
        "charged_particle mass array",
        lambda: systems.charged_particle(_norm2, magnetic_field=FIELD, mass=np.ones(2)),
        TypeError,
        "mass.*scalar",
    ),
    (
        "charged_particle dimension zero",
        lambda: systems.charged_particle(_norm2, vector_potential=_identity, dimension=0),
        ValueError,
        "dimension must be >= 1",
    ),
    (
        "stochastic_pendulum noise nan",
        lambda: systems.stochastic_pendulum(noise_position=NAN),
        ValueError,
        "noise_position must be finite",
    ),
    (
        "stochastic_pendulum noise string",
        lambda: systems.stochastic_pendulum(noise_momentum="a"),
        TypeError,
        "noise_momentum",
    ),
    (
        "stochastic_pendulum flag",
        lambda: systems.stochastic_pendulum(quadratic_momentum_noise=1),
        TypeError,
        "quadratic_momentum_noise.*bool",
    ),
    # ---- constructors: systems.lie_poisson_system
    (
        "lie_poisson_system hamiltonian complex",
        lambda: _lps(lambda mu: 1j * _norm2(mu)),
        TypeError,
        "hamiltonian must return a real floating scalar",
    ),
    (
        "lie_poisson_system hamiltonian int",
        lambda: _lps(lambda mu: 1),
        TypeError,
        "hamiltonian must return a real floating scalar",
    ),
    (
        "lie_poisson_system noise not callable",
        lambda: systems.lie_poisson_system(algebras.so3, _norm2, 3, np.ones(3)),
        TypeError,
        "noise_hamiltonians must be a callable",
    ),
    (
        "lie_poisson_system noise 2-D",
        lambda: systems.lie_poisson_system(
            algebras.so3, _norm2, lambda m: jnp.outer(m, m), np.ones(3)
        ),
        ValueError,
        "noise_hamiltonians must return a 1-D",
    ),
    (
        "lie_poisson_system position inf",
        lambda: _lps(position=(0.0, INF, 1.0)),
        ValueError,
        "position must be finite",
    ),
    ("lie_poisson_system unknown option", lambda: _lps(foo=1), TypeError, "foo"),
    # ---- constructors: liesample.spaces
    ("Euclidean shape float", lambda: spaces.Euclidean((2.5,)), TypeError, "Euclidean shape"),
    ("Euclidean shape bool", lambda: spaces.Euclidean((True,)), TypeError, "Euclidean shape"),
    ("Euclidean shape negative", lambda: spaces.Euclidean((-1,)), ValueError, "Euclidean shape"),
    ("Euclidean shape string", lambda: spaces.Euclidean("ab"), TypeError, "Euclidean shape"),
    ("U1 shape float", lambda: spaces.U1((1.5,)), TypeError, "U1 shape"),
    ("Sphere shape float", lambda: spaces.Sphere(2, (2.5,)), TypeError, "Sphere shape"),
    ("SO shape negative", lambda: spaces.SO(3, (-1,)), ValueError, "SO shape"),
    ("Sphere n zero", lambda: spaces.Sphere(0), ValueError, "Sphere dimension n"),
    ("Sphere n float", lambda: spaces.Sphere(2.0), ValueError, "Sphere dimension n"),
    ("Sphere n bool", lambda: spaces.Sphere(True), ValueError, "Sphere dimension n"),
    ("SO n one", lambda: spaces.SO(1), ValueError, r"SO\(n\): n must be an integer >= 2"),
    ("SU n None", lambda: spaces.SU(None), ValueError, r"SU\(n\): n must be an integer >= 2"),
    (
        "Sphere check nan",
        lambda: spaces.Sphere(2).check(np.array([NAN, 0, 1.0])),
        ValueError,
        "position must be finite",
    ),
    (
        "Sphere check complex",
        lambda: spaces.Sphere(2).check(np.array([0, 0, 1j])),
        TypeError,
        "position must be a real floating array",
    ),
    (
        "Sphere check list off the sphere",
        lambda: spaces.Sphere(2).check([0.0, 0.0, 2.0]),
        ValueError,
        "position is off Sphere",
    ),
    (
        "SO check int",
        lambda: spaces.SO(3).check(np.eye(3, dtype=int)),
        TypeError,
        "position must be a real floating array",
    ),
    (
        "SU check real",
        lambda: spaces.SU(2).check(np.eye(2)),
        TypeError,
        "position must be a complex array",
    ),
    (
        "check_position structure",
        lambda: spaces.check_position({"a": E2}, {"b": np.zeros(2)}),
        ValueError,
        "position must have the structure",
    ),
    (
        "uniform int key",
        lambda: spaces.uniform(spaces.Sphere(2), 0),
        TypeError,
        r"rng_key.*jax\.random\.key\(0\)",
    ),
    (
        "check_inverse_mass string",
        lambda: spaces.check_inverse_mass(E2, "big"),
        TypeError,
        "inverse mass.*must be real",
    ),
    (
        "check_inverse_mass complex",
        lambda: spaces.check_inverse_mass(E2, np.array([1j, 1.0])),
        TypeError,
        "inverse mass.*must be real",
    ),
    # ---- constructors: liesample.algebras
    (
        "StructureConstants complex",
        lambda: StructureConstants(1j * np.zeros((2, 2, 2))),
        ValueError,
        "structure constants must be a real array",
    ),
    (
        "StructureConstants bool",
        lambda: StructureConstants(np.zeros((2, 2, 2), bool)),
        ValueError,
        "structure constants must be a real array",
    ),
    (
        "StructureConstants 4-D",
        lambda: StructureConstants(np.zeros((2, 2, 2, 2))),
        ValueError,
        r"structure constants must have shape \(n, n, n\)",
    ),
    (
        "StructureConstants casimirs list",
        lambda: StructureConstants(np.zeros((1, 1, 1)), [1]),
        TypeError,
        "casimirs must be a callable",
    ),
    (
        "so3 casimirs of a 2-vector",
        lambda: algebras.so3.casimirs(np.ones(2)),
        ValueError,
        r"mu must be an so\(3\).*shape \(\.\.\., 3\); got shape \(2,\)",
    ),
    (
        "so3 coadjoint_exp 4-vector",
        lambda: algebras.so3.coadjoint_exp(np.ones(4), np.ones(3)),
        ValueError,
        r"zeta must be an so\(3\)",
    ),
    (
        "so3 bracket 2-vector",
        lambda: algebras.so3.bracket(np.ones(3), np.ones(2)),
        ValueError,
        r"b must be an so\(3\)",
    ),
    # ---- samplers: lie_poisson_langevin, adjusted_lie_poisson
    ("langevin sigma string", lambda: _langevin(sigma="1"), TypeError, "sigma.*scalar"),
    (
        "langevin step_size string",
        lambda: _langevin(step_size="0.1"),
        TypeError,
        "step_size.*scalar",
    ),
    (
        "langevin step_size complex",
        lambda: _langevin(step_size=0.1 + 0j),
        TypeError,
        "step_size.*scalar",
    ),
    ("langevin step_size bool", lambda: _langevin(step_size=True), TypeError, "step_size.*scalar"),
    (
        "langevin step_size 1-D",
        lambda: _langevin(step_size=np.array([0.1])),
        TypeError,
        "step_size.*scalar",
    ),
    ("langevin beta list", lambda: _langevin(beta=[1.0]), TypeError, "beta.*scalar"),
    ("langevin beta numpy bool", lambda: _langevin(beta=np.True_), TypeError, "beta.*scalar"),
    ("langevin sigma -inf", lambda: _langevin(sigma=-INF), ValueError, "sigma must be finite"),
    (
        "langevin sigma overflowing theta",
        lambda: _langevin(sigma=1e300),
        ValueError,
        r"theta = beta\*sigma\*\*2/2 \(reduce sigma\) must be finite",
    ),
    (
        "langevin theta nan",
        lambda: _langevin(beta=None, sigma=0.0, theta=NAN),
        ValueError,
        "theta must be finite",
    ),
    (
        "langevin integrator None",
        lambda: _langevin(integrator=None),
        ValueError,
        "integrator must be one of",
    ),
    (
        "langevin stability None",
        lambda: _langevin(stability=None),
        ValueError,
        "stability must be one of",
    ),
    (
        "langevin bias_tolerance string",
        lambda: _langevin(step_size=None, bias_tolerance="a"),
        TypeError,
        "bias_tolerance",
    ),
    (
        "langevin noise_block_size float",
        lambda: _langevin(noise_block_size=2.5),
        ValueError,
        "noise_block_size must be an integer",
    ),
    (
        "langevin system None",
        lambda: liesample.lie_poisson_langevin(None, beta=1.0),
        TypeError,
        "system must be a LiePoissonSystem",
    ),
    (
        "langevin init complex",
        lambda: _langevin().init(np.array([0, 0, 1j])),
        TypeError,
        "position must be a real array",
    ),
    (
        "langevin init bool",
        lambda: _langevin().init(np.array([True, False, True])),
        TypeError,
        "position must be a real array",
    ),
    (
        "langevin init string",
        lambda: _langevin().init("x"),
        TypeError,
        "position must be a real array",
    ),
    (
        "langevin init dict",
        lambda: _langevin().init({"a": 1}),
        TypeError,
        "position must be a real array",
    ),
    (
        "langevin init ragged",
        lambda: _langevin().init([[1.0], [1.0, 2.0]]),
        TypeError,
        "position must be a real array",
    ),
    (
        "langevin init 0-d",
        lambda: _langevin().init(1.0),
        ValueError,
        r"position must have shape \(3,\)",
    ),
    (
        "langevin init batch",
        lambda: _langevin().init(np.ones((2, 3))),
        ValueError,
        r"position must have shape \(3,\)",
    ),
    (
        "langevin init empty",
        lambda: _langevin().init(np.zeros(0)),
        ValueError,
        r"position must have shape \(3,\)",
    ),
    (
        "sample initial_positions complex",
        lambda: liesample.sample_chains(_langevin(), KEY, 1j * STARTS, 2, progress_bar=False),
        TypeError,
        "position must be a real array",
    ),
    (
        "adjusted beta None",
        lambda: liesample.adjusted_lie_poisson(RIGID, beta=None),
        TypeError,
        "beta.*scalar",
    ),
    (
        "adjusted sigma zero",
        lambda: liesample.adjusted_lie_poisson(RIGID, beta=1.0, sigma=0.0),
        ValueError,
        "sigma must be > 0",
    ),
    (
        "adjusted target string",
        lambda: liesample.adjusted_lie_poisson(RIGID, beta=1.0, target_acceptance_rate="high"),
        TypeError,
        "target_acceptance_rate",
    ),
    (
        "adjusted init complex",
        lambda: liesample.adjusted_lie_poisson(RIGID, beta=1.0, step_size=0.1).init(
            np.array([0, 0, 1j])
        ),
        TypeError,
        "position must be a real array",
    ),
    # ---- samplers: geometric_hmc, geometric_langevin
    (
        "geometric_hmc logdensity_fn not callable",
        lambda: liesample.geometric_hmc(3.0, E2, 0.1, 3),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "geometric_langevin logdensity_fn None",
        lambda: liesample.geometric_langevin(None, E2, 0.1, 1.0),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "geometric_hmc step_size string",
        lambda: liesample.geometric_hmc(_logdensity, E2, "0.1", 3),
        TypeError,
        "step_size must be a real scalar",
    ),
    (
        "geometric_hmc step_size complex",
        lambda: liesample.geometric_hmc(_logdensity, E2, 0.1j, 3),
        TypeError,
        "step_size must be a real scalar",
    ),
    (
        "geometric_hmc step_size bool",
        lambda: liesample.geometric_hmc(_logdensity, E2, True, 3),
        TypeError,
        "step_size must be a real scalar",
    ),
    (
        "geometric_hmc step_size inf",
        lambda: liesample.geometric_hmc(_logdensity, E2, INF, 3),
        ValueError,
        "step_size must be finite",
    ),
    (
        "geometric_hmc step_size array",
        lambda: liesample.geometric_hmc(_logdensity, E2, np.full(2, 0.1), 3),
        ValueError,
        "step_size must be a scalar",
    ),
    (
        "geometric_hmc steps float",
        lambda: liesample.geometric_hmc(_logdensity, E2, 0.1, 2.5),
        ValueError,
        "num_integration_steps must be an integer",
    ),
    (
        "geometric_hmc steps string",
        lambda: liesample.geometric_hmc(_logdensity, E2, 0.1, "3"),
        ValueError,
        "num_integration_steps must be an integer",
    ),
    (
        "geometric_hmc steps without step_size",
        lambda: liesample.geometric_hmc(_logdensity, E2, 0.1, None),
        ValueError,
        "num_integration_steps is unset",
    ),
    (
        "geometric_hmc inverse mass bool",
        lambda: _ghmc(inverse_mass_matrix=np.ones(2, bool)),
        TypeError,
        "inverse mass.*must be real",
    ),
    (
        "geometric_hmc inverse mass complex",
        lambda: _ghmc(inverse_mass_matrix=np.array([1j, 1.0])),
        TypeError,
        "inverse mass.*must be real",
    ),
    (
        "geometric_hmc inverse mass inf",
        lambda: _ghmc(inverse_mass_matrix=np.array([INF, 1.0])),
        ValueError,
        "inverse mass.*finite and > 0",
    ),
    (
        "geometric_hmc inverse mass shape",
        lambda: _ghmc(inverse_mass_matrix=np.ones(3)),
        ValueError,
        r"inverse mass.*must broadcast to shape \(2,\)",
    ),
    (
        "geometric_hmc dense mass not symmetric",
        lambda: _ghmc(inverse_mass_matrix=np.array([[1.0, 0.5], [0.0, 1.0]])),
        ValueError,
        "inverse mass.*symmetric",
    ),
    (
        "geometric_hmc field complex",
        lambda: _ghmc(magnetic_field=1j * FIELD),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "geometric_hmc field bool",
        lambda: _ghmc(magnetic_field=np.zeros((2, 2), bool)),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "geometric_hmc field on a sphere",
        lambda: liesample.geometric_hmc(
            _logdensity, spaces.Sphere(2), 0.1, 3, magnetic_field=FIELD
        ),
        ValueError,
        "magnetic_field acts on the Euclidean coordinates",
    ),
    (
        "geometric_hmc divergence_threshold nan",
        lambda: _ghmc(divergence_threshold=NAN),
        ValueError,
        "divergence_threshold",
    ),
    (
        "geometric_hmc persistence negative",
        lambda: _ghmc(momentum_persistence=-0.1),
        ValueError,
        "momentum_persistence",
    ),
    (
        "geometric_hmc persistent string",
        lambda: _ghmc(persistent="yes"),
        TypeError,
        "persistent must be a bool",
    ),
    (
        "geometric_hmc jitter string",
        lambda: _ghmc(jitter="yes"),
        TypeError,
        "jitter must be a bool",
    ),
    (
        "geometric_hmc space class",
        lambda: liesample.geometric_hmc(_logdensity, spaces.Euclidean, 0.1, 3),
        TypeError,
        "space must be a Space",
    ),
    (
        "geometric_hmc init list",
        lambda: _ghmc().init([0.0, 0.0]),
        ValueError,
        "position must have the structure",
    ),
    (
        "geometric_hmc init int",
        lambda: _ghmc().init(np.zeros(2, int)),
        TypeError,
        "position must be a real floating array",
    ),
    (
        "geometric_hmc logdensity vector",
        lambda: liesample.geometric_hmc(_identity, E2, 0.1, 3).init(np.ones(2)),
        TypeError,
        r"logdensity_fn must return one real floating scalar.*shape \(2,\)",
    ),
    (
        "geometric_hmc logdensity complex",
        lambda: liesample.geometric_hmc(lambda q: 1j * jnp.sum(q), E2, 0.1, 3).init(np.ones(2)),
        TypeError,
        "logdensity_fn must return one real floating scalar.*complex",
    ),
    (
        "geometric_hmc logdensity int",
        lambda: liesample.geometric_hmc(lambda q: 0, E2, 0.1, 3).init(np.ones(2)),
        TypeError,
        "logdensity_fn must return one real floating scalar.*int",
    ),
    (
        "geometric_hmc logdensity tuple",
        lambda: liesample.geometric_hmc(lambda q: (jnp.sum(q), 1.0), E2, 0.1, 3).init(np.ones(2)),
        TypeError,
        "logdensity_fn must return one real floating scalar",
    ),
    (
        "geometric_langevin friction string",
        lambda: liesample.geometric_langevin(_logdensity, E2, 0.1, "1"),
        TypeError,
        "friction.*scalar",
    ),
    (
        "geometric_langevin friction array",
        lambda: liesample.geometric_langevin(_logdensity, E2, 0.1, np.ones(2)),
        ValueError,
        "friction must be a scalar",
    ),
    (
        "geometric_langevin adjusted string",
        lambda: liesample.geometric_langevin(_logdensity, E2, 0.1, 1.0, adjusted="yes"),
        TypeError,
        "adjusted must be a bool",
    ),
    # ---- samplers: magnetic_hmc, magnetic_langevin, jittered_magnetic_hmc, default field
    (
        "magnetic_hmc logdensity_fn string",
        lambda: liesample.magnetic_hmc("logdensity"),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "magnetic_hmc logdensity_fn with parameters",
        lambda: liesample.magnetic_hmc("ld", 0.1, np.ones(2), 3, FIELD),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "magnetic_langevin logdensity_fn None",
        lambda: liesample.magnetic_langevin(None, 0.1, np.ones(2), 1.0, FIELD),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "jittered_magnetic_hmc logdensity_fn int",
        lambda: liesample.jittered_magnetic_hmc(1, 0.1, np.ones(2), 3, FIELD),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "magnetic_hmc partial parameters",
        lambda: liesample.magnetic_hmc(_logdensity, 0.1),
        ValueError,
        "together, or none of them",
    ),
    (
        "magnetic_hmc inverse mass bool",
        lambda: _mhmc(inverse_mass_matrix=np.ones(2, bool)),
        TypeError,
        "inverse_mass_matrix must be a real array",
    ),
    (
        "magnetic_hmc inverse mass 0-d",
        lambda: _mhmc(inverse_mass_matrix=np.float64(1.0)),
        ValueError,
        "inverse_mass_matrix must be a 1-D or 2-D",
    ),
    (
        "magnetic_hmc field bool",
        lambda: _mhmc(magnetic_field=np.zeros((2, 2), bool)),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "magnetic_hmc field complex",
        lambda: _mhmc(magnetic_field=1j * FIELD),
        TypeError,
        "magnetic_field must be a real array",
    ),
    (
        "magnetic_hmc field nan",
        lambda: _mhmc(magnetic_field=np.array([[0, NAN], [NAN, 0]])),
        ValueError,
        "magnetic_field must be finite",
    ),
    (
        "magnetic_hmc field 1-D",
        lambda: _mhmc(magnetic_field=np.ones(2)),
        ValueError,
        "magnetic_field must be a 2-D",
    ),
    (
        "magnetic_hmc persistence nan",
        lambda: _mhmc(momentum_persistence=NAN),
        ValueError,
        "momentum_persistence",
    ),
    ("magnetic_hmc integrator", lambda: _mhmc(integrator="x"), ValueError, "integrator must be"),
    (
        "magnetic_langevin friction string",
        lambda: liesample.magnetic_langevin(_logdensity, 0.1, np.ones(2), "a", FIELD),
        TypeError,
        "friction.*scalar",
    ),
    (
        "magnetic_langevin inverse mass shape",
        lambda: liesample.magnetic_langevin(_logdensity, 0.1, np.ones(3), 1.0, FIELD),
        ValueError,
        r"magnetic_field must have shape \(3, 3\)",
    ),
    (
        "magnetic_langevin field None",
        lambda: liesample.magnetic_langevin(_logdensity, 0.1, np.ones(2), 1.0, None),
        ValueError,
        "magnetic_field must be a 2-D",
    ),
    (
        "jittered_magnetic_hmc steps string",
        lambda: liesample.jittered_magnetic_hmc(_logdensity, 0.1, np.ones(2), "3", FIELD),
        ValueError,
        "num_integration_steps must be an integer",
    ),
    (
        "default_magnetic_field strength string",
        lambda: liesample.default_magnetic_field(np.ones(2), "a"),
        TypeError,
        "strength must be a real scalar",
    ),
    (
        "default_magnetic_field strength array",
        lambda: liesample.default_magnetic_field(np.ones(2), np.ones(2)),
        TypeError,
        "strength must be a real scalar",
    ),
    (
        "default_magnetic_field strength nan",
        lambda: liesample.default_magnetic_field(np.ones(2), NAN),
        ValueError,
        "strength must be finite",
    ),
    (
        "default_magnetic_field strength negative",
        lambda: liesample.default_magnetic_field(np.ones(2), -1.0),
        ValueError,
        "strength must be >= 0",
    ),
    (
        "default_magnetic_field mass complex",
        lambda: liesample.default_magnetic_field(1j * np.ones(2), 1.0),
        TypeError,
        "inverse_mass_matrix must be a real array",
    ),
    (
        "default_magnetic_field covariance shape",
        lambda: liesample.default_magnetic_field(np.ones(2), 1.0, np.eye(3)),
        ValueError,
        r"covariance must be a finite \(2, 2\)",
    ),
    # ---- samplers: vortex_metropolis, recommended_sampler
    (
        "vortex_metropolis beta string",
        lambda: liesample.vortex_metropolis(PAIR, beta="a"),
        TypeError,
        "beta.*scalar",
    ),
    (
        "vortex_metropolis proposal_scale array",
        lambda: liesample.vortex_metropolis(PAIR, beta=1.0, proposal_scale=np.ones(2)),
        TypeError,
        "proposal_scale.*scalar",
    ),
    (
        "vortex_metropolis init complex",
        lambda: liesample.vortex_metropolis(PAIR, beta=1.0).init(1j * np.ones((2, 3))),
        TypeError,
        "position must be a real array",
    ),
    (
        "vortex_metropolis init shape",
        lambda: liesample.vortex_metropolis(PAIR, beta=1.0).init(np.ones(3)),
        ValueError,
        r"position must have shape \(2, 3\)",
    ),
    (
        "recommended_sampler system string",
        lambda: liesample.recommended_sampler("rigid", beta=1.0),
        TypeError,
        "system must be a LiePoissonSystem",
    ),
    (
        "recommended_sampler charged particle",
        lambda: liesample.recommended_sampler(
            systems.charged_particle(_norm2, magnetic_field=FIELD), beta=1.0
        ),
        TypeError,
        "system must be a LiePoissonSystem",
    ),
    (
        "recommended_sampler beta None",
        lambda: liesample.recommended_sampler(RIGID, beta=None),
        TypeError,
        "beta.*scalar",
    ),
    (
        "recommended_sampler step_size negative",
        lambda: liesample.recommended_sampler(RIGID, beta=1.0, step_size=-1.0),
        ValueError,
        "step_size must be > 0",
    ),
    (
        "recommended_sampler unknown option",
        lambda: liesample.recommended_sampler(RIGID, beta=1.0, foo=1),
        TypeError,
        "foo",
    ),
    # ---- spins: systems.heisenberg and the spin samplers
    ("heisenberg shape int", lambda: systems.heisenberg(4), TypeError, "shape must be a tuple"),
    ("heisenberg shape float", lambda: systems.heisenberg((4.0,)), TypeError, "shape entries"),
    ("heisenberg shape negative", lambda: systems.heisenberg((-4,)), ValueError, "shape entries"),
    ("heisenberg shape bool", lambda: systems.heisenberg((True,)), TypeError, "shape entries"),
    (
        "heisenberg shape array",
        lambda: systems.heisenberg(np.array([4, 4])),
        TypeError,
        "shape must be a tuple",
    ),
    ("heisenberg shape nested", lambda: systems.heisenberg(((4,),)), TypeError, "shape entries"),
    (
        "heisenberg coupling complex",
        lambda: systems.heisenberg((4,), coupling=1j),
        TypeError,
        "coupling.*scalar",
    ),
    (
        "heisenberg coupling array",
        lambda: systems.heisenberg((4,), coupling=np.ones(3)),
        TypeError,
        "coupling.*scalar",
    ),
    (
        "heisenberg coupling -inf",
        lambda: systems.heisenberg((4,), coupling=-INF),
        ValueError,
        "coupling must be finite",
    ),
    (
        "heisenberg field 2-D",
        lambda: systems.heisenberg((4,), field=np.zeros((4, 3))),
        ValueError,
        "field must be a sequence of 3",
    ),
    (
        "heisenberg field complex",
        lambda: systems.heisenberg((4,), field=(0, 0, 1j)),
        TypeError,
        r"field\[2\].*scalar",
    ),
    (
        "heisenberg field bool",
        lambda: systems.heisenberg((4,), field=(False, False, True)),
        TypeError,
        r"field\[0\].*scalar",
    ),
    (
        "heisenberg anisotropy bool",
        lambda: systems.heisenberg((4,), anisotropy=True),
        TypeError,
        "anisotropy.*scalar",
    ),
    (
        "heisenberg anisotropy nan",
        lambda: systems.heisenberg((4,), anisotropy=NAN),
        ValueError,
        "anisotropy must be finite",
    ),
    (
        "heisenberg periodic small extent",
        lambda: systems.heisenberg((4, 2), periodic=True),
        ValueError,
        "periodic.*>= 3",
    ),
    (
        "heisenberg_metropolis beta string",
        lambda: liesample.heisenberg_metropolis(CHAIN, beta="1"),
        TypeError,
        "beta.*scalar",
    ),
    (
        "heisenberg_metropolis proposal None",
        lambda: liesample.heisenberg_metropolis(CHAIN, beta=1.0, proposal=None),
        ValueError,
        "proposal must be one of",
    ),
    (
        "heisenberg_metropolis init bool",
        lambda: liesample.heisenberg_metropolis(CHAIN, beta=1.0).init(UP.astype(bool)),
        TypeError,
        "position must be a real array",
    ),
    (
        "heisenberg_metropolis init complex",
        lambda: liesample.heisenberg_metropolis(CHAIN, beta=1.0).init(1j * UP),
        TypeError,
        "position must be a real array",
    ),
    (
        "heisenberg_metropolis init flat",
        lambda: liesample.heisenberg_metropolis(CHAIN, beta=1.0).init(np.ones(12)),
        ValueError,
        r"position must have shape \(4, 3\)",
    ),
    (
        "heisenberg_heat_bath overrelaxation float",
        lambda: liesample.heisenberg_heat_bath(CHAIN, beta=1.0, overrelaxation=1.5),
        TypeError,
        "overrelaxation must be a non-negative int",
    ),
    (
        "heisenberg_heat_bath sweeps string",
        lambda: liesample.heisenberg_heat_bath(CHAIN, beta=1.0, heat_bath_sweeps="1"),
        TypeError,
        "heat_bath_sweeps",
    ),
    (
        "heisenberg_heat_bath no move",
        lambda: liesample.heisenberg_heat_bath(
            CHAIN, beta=1.0, overrelaxation=0, heat_bath_sweeps=0
        ),
        ValueError,
        "heat_bath_sweeps \\+ overrelaxation must be >= 1",
    ),
    (
        "heisenberg_heat_bath precession nan",
        lambda: liesample.heisenberg_heat_bath(CHAIN, beta=1.0, precession_angle=NAN),
        ValueError,
        "precession_angle must be finite",
    ),
    (
        "heisenberg_heat_bath system",
        lambda: liesample.heisenberg_heat_bath(RIGID, beta=1.0),
        TypeError,
        "system must be a heisenberg",
    ),
    (
        "heisenberg_heat_bath init off the sphere",
        lambda: liesample.heisenberg_heat_bath(CHAIN, beta=1.0).init(np.ones((4, 3))),
        ValueError,
        "position must hold unit spins",
    ),
    (
        "heisenberg_wolff anisotropy",
        lambda: liesample.heisenberg_wolff(systems.heisenberg((4,), anisotropy=0.5), beta=1.0),
        ValueError,
        "anisotropy = 0.5",
    ),
    (
        "heisenberg_wolff coupling zero",
        lambda: liesample.heisenberg_wolff(systems.heisenberg((4,), coupling=0.0), beta=1.0),
        ValueError,
        "coupling J = 0",
    ),
    (
        "heisenberg_wolff system string",
        lambda: liesample.heisenberg_wolff("chain", beta=1.0),
        TypeError,
        "system must be a heisenberg",
    ),
    (
        "heisenberg_cluster beta negative",
        lambda: liesample.heisenberg_cluster(CHAIN, beta=-1.0),
        ValueError,
        "beta must be >= 0",
    ),
    (
        "heisenberg_cluster clusters None",
        lambda: liesample.heisenberg_cluster(CHAIN, beta=1.0, clusters=None),
        ValueError,
        "clusters must be one of",
    ),
    (
        "heisenberg_cluster init nan",
        lambda: liesample.heisenberg_cluster(CHAIN, beta=1.0).init(np.full((4, 3), NAN)),
        ValueError,
        "position must be finite",
    ),
    # ---- tuning: window_adaptation, magnetic_window_adaptation, accuracy.choose_step_size
    (
        "window_adaptation logdensity_fn None",
        lambda: liesample.window_adaptation(liesample.geometric_hmc, None, E2),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "window_adaptation adapt_mass string",
        lambda: _window(adapt_mass="no"),
        TypeError,
        "adapt_mass must be a bool",
    ),
    (
        "window_adaptation progress_bar string",
        lambda: _window(progress_bar="no"),
        TypeError,
        "progress_bar must be a bool",
    ),
    (
        "window_adaptation initial_step_size string",
        lambda: _window(initial_step_size="0.1"),
        TypeError,
        "initial_step_size.*scalar",
    ),
    (
        "window_adaptation target_acceptance_rate",
        lambda: _window(target_acceptance_rate=1.5),
        ValueError,
        r"target_acceptance_rate must be in \(0, 1\)",
    ),
    (
        "window_adaptation integration_time nan",
        lambda: _window(integration_time=NAN),
        ValueError,
        "integration_time must be finite",
    ),
    (
        "window_adaptation unknown parameter",
        lambda: _window(foo=1),
        TypeError,
        r"unknown parameters for geometric_hmc: \['foo'\]",
    ),
    (
        "window_adaptation step_size",
        lambda: _window(step_size=0.1),
        TypeError,
        "give initial_step_size",
    ),
    (
        "window_adaptation algorithm string",
        lambda: liesample.window_adaptation("hmc", _logdensity, E2),
        TypeError,
        "declares no window adaptation",
    ),
    (
        "window_adaptation space string",
        lambda: liesample.window_adaptation(liesample.geometric_hmc, _logdensity, "R2"),
        TypeError,
        "space must be a Space",
    ),
    (
        "window_adaptation run num_steps",
        lambda: _window().run(KEY, np.zeros(2), num_steps=10.5),
        ValueError,
        "num_steps must be an integer >= 20",
    ),
    (
        "window_adaptation run int key",
        lambda: _window().run(0, np.zeros(2), num_steps=20),
        TypeError,
        r"rng_key.*jax\.random\.key\(0\)",
    ),
    (
        "window_adaptation run start nan",
        lambda: _window().run(KEY, np.array([NAN, 0.0]), num_steps=20),
        ValueError,
        "initial_position must be finite",
    ),
    (
        "window_adaptation run batch nan",
        lambda: _window().run(KEY, np.array([[0.0, 0.0], [NAN, 0.0]]), num_steps=20),
        ValueError,
        r"initial_positions\[1\] must be finite",
    ),
    (
        "window_adaptation run start int",
        lambda: _window().run(KEY, np.zeros(2, int), num_steps=20),
        TypeError,
        "position must be a real floating array",
    ),
    (
        "magnetic_window_adaptation logdensity_fn None",
        lambda: liesample.magnetic_window_adaptation(None),
        TypeError,
        "logdensity_fn must be a callable",
    ),
    (
        "magnetic_window_adaptation algorithm string",
        lambda: liesample.magnetic_window_adaptation(_logdensity, algorithm="hmc"),
        TypeError,
        "algorithm must be liesample.magnetic_hmc",
    ),
    (
        "magnetic_window_adaptation progress_bar string",
        lambda: liesample.magnetic_window_adaptation(_logdensity, progress_bar="no"),
        TypeError,
        "progress_bar must be a bool",
    ),
    (
        "magnetic_window_adaptation angle string",
        lambda: liesample.magnetic_window_adaptation(_logdensity, angle="a"),
        TypeError,
        "angle.*scalar",
    ),
    (
        "magnetic_window_adaptation learning_rate zero",
        lambda: liesample.magnetic_window_adaptation(_logdensity, learning_rate=0.0),
        ValueError,
        "learning_rate must be > 0",
    ),
    (
        "magnetic_window_adaptation max steps float",
        lambda: liesample.magnetic_window_adaptation(_logdensity, max_num_integration_steps=2.5),
        ValueError,
        "max_num_integration_steps must be an integer",
    ),
    (
        "magnetic_window_adaptation run int key",
        lambda: liesample.magnetic_window_adaptation(_logdensity).run(0, np.zeros((2, 2)), 20),
        TypeError,
        r"rng_key.*jax\.random\.key\(0\)",
    ),
    (
        "magnetic_window_adaptation run one chain",
        lambda: liesample.magnetic_window_adaptation(_logdensity).run(KEY, np.zeros((1, 2)), 20),
        ValueError,
        ">= 2 chains",
    ),
    (
        "magnetic_window_adaptation run int starts",
        lambda: liesample.magnetic_window_adaptation(_logdensity).run(
            KEY, np.zeros((2, 2), int), 20
        ),
        TypeError,
        "initial_positions must be real floating point",
    ),
    (
        "choose_step_size system string",
        lambda: _choose(system="rigid"),
        TypeError,
        "system must be a LiePoissonSystem",
    ),
    (
        "choose_step_size observables not callable",
        lambda: _choose(observables=3),
        TypeError,
        "observables must be a callable",
    ),
    (
        "choose_step_size max_refinements negative",
        lambda: _choose(max_refinements=-1),
        ValueError,
        "max_refinements must be an integer >= 0",
    ),
    (
        "choose_step_size max_refinements float",
        lambda: _choose(max_refinements=1.5),
        ValueError,
        "max_refinements must be an integer >= 0",
    ),
    (
        "choose_step_size pilot_time nan",
        lambda: _choose(pilot_time=NAN),
        ValueError,
        "pilot_time must be finite",
    ),
    (
        "choose_step_size burn_in negative",
        lambda: _choose(burn_in=-1.0),
        ValueError,
        "burn_in must be >= 0",
    ),
    (
        "choose_step_size sigmas empty",
        lambda: _choose(sigmas=()),
        ValueError,
        "sigmas must be a non-empty",
    ),
    (
        "choose_step_size sigmas negative",
        lambda: _choose(sigmas=(-1.0,)),
        ValueError,
        r"sigmas\[0\] must be > 0",
    ),
    (
        "choose_step_size positions 1-D",
        lambda: _choose(initial_positions=RIGID.default_position),
        ValueError,
        "initial_positions must have shape",
    ),
    (
        "choose_step_size positions complex",
        lambda: _choose(initial_positions=STARTS + 0j),
        TypeError,
        "initial_positions must be real floating point, got dtype complex",
    ),
    (
        "ergodic_averages positions complex",
        lambda: accuracy.ergodic_averages(_langevin(), KEY, STARTS + 0j, _identity, num_steps=2),
        TypeError,
        "initial_positions must be real floating point, got dtype complex",
    ),
    (
        "coupled_ergodic_averages observables",
        lambda: accuracy.coupled_ergodic_averages(
            RIGID, 1.0, 3, step_size=0.1, initial_positions=STARTS, rng_key=KEY, total_time=1.0
        ),
        TypeError,
        "observables must be a callable",
    ),
    # ---- numpyro: liesample.numpyro distributions, GeometricHMC keywords
    (
        "VonMisesFisher mean_direction not unit",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 2.0]), 1.0),
        ValueError,
        "mean_direction must be a unit vector",
    ),
    (
        "VonMisesFisher mean_direction scalar",
        lambda: lnp.VonMisesFisher(1.0, 1.0),
        ValueError,
        "mean_direction must be a unit vector of length d >= 2",
    ),
    (
        "VonMisesFisher concentration negative",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0]), -1.0),
        ValueError,
        "concentration must be >= 0",
    ),
    (
        "VonMisesFisher concentration nan",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0]), NAN),
        ValueError,
        "concentration must be finite",
    ),
    (
        "VonMisesFisher concentration string",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0]), "a"),
        TypeError,
        "concentration must be .* real numbers",
    ),
    (
        "VonMisesFisher concentration complex",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0]), 1j),
        TypeError,
        "concentration must be .* real numbers.*complex",
    ),
    (
        "VonMisesFisher mean_direction complex",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0 + 0j]), 1.0),
        TypeError,
        "mean_direction must be a unit vector of real numbers",
    ),
    (
        "VonMisesFisher batch shapes",
        lambda: lnp.VonMisesFisher(np.tile([0.0, 0.0, 1.0], (2, 1)), np.ones(3)),
        ValueError,
        r"batch shapes do not broadcast: mean_direction \(2,\), concentration \(3,\)",
    ),
    (
        "VonMisesFisher sample int key",
        lambda: lnp.VonMisesFisher(np.array([0.0, 0.0, 1.0]), 1.0).sample(0),
        TypeError,
        r"key must be a JAX random key.*jax\.random\.key\(0\)",
    ),
    (
        "Bingham concentration shape",
        lambda: lnp.Bingham(np.ones(2)),
        ValueError,
        r"concentration must have shape \(\.\.\., 3\)",
    ),
    (
        "Bingham concentration nan",
        lambda: lnp.Bingham(np.array([NAN, 0.0, 1.0])),
        ValueError,
        "concentration must be finite",
    ),
    (
        "Bingham orientation shape",
        lambda: lnp.Bingham(np.ones(3), np.eye(2)),
        ValueError,
        "orientation must be a rotation matrix of shape",
    ),
    (
        "Bingham concentration complex",
        lambda: lnp.Bingham(np.array([0.0, 1.0, 2j])),
        TypeError,
        "concentration must be .* real numbers.*complex",
    ),
    (
        "Bingham concentration string",
        lambda: lnp.Bingham("abc"),
        TypeError,
        "concentration must be .* real numbers",
    ),
    (
        "Bingham orientation complex",
        lambda: lnp.Bingham(np.ones(3), np.eye(3) + 0j),
        TypeError,
        "orientation must be .* real numbers",
    ),
    (
        "MatrixFisher F shape",
        lambda: lnp.MatrixFisher(np.ones(3)),
        ValueError,
        "F must be a finite 3x3 matrix",
    ),
    (
        "MatrixFisher F nan",
        lambda: lnp.MatrixFisher(np.full((3, 3), NAN)),
        ValueError,
        "F must be finite",
    ),
    (
        "MatrixFisher F complex",
        lambda: lnp.MatrixFisher(np.eye(3) + 0j),
        TypeError,
        "F must be a 3x3 matrix .* real numbers.*complex",
    ),
    (
        "MatrixFisher F ragged list",
        lambda: lnp.MatrixFisher([[1.0, 2.0], [3.0]]),
        TypeError,
        "F must be a 3x3 matrix .* real numbers",
    ),
    (
        "MatrixFisher sample int key",
        lambda: lnp.MatrixFisher(np.eye(3)).sample(0),
        TypeError,
        r"key must be a JAX random key",
    ),
    (
        "GeometricHMC adapt_step_size string",
        lambda: GeometricHMC(_model, adapt_step_size="no"),
        TypeError,
        "adapt_step_size must be a bool",
    ),
    (
        "GeometricHMC adapt_mass_matrix string",
        lambda: GeometricHMC(_model, adapt_mass_matrix="no"),
        TypeError,
        "adapt_mass_matrix must be a bool",
    ),
    (
        "GeometricHMC find_heuristic_step_size string",
        lambda: GeometricHMC(_model, find_heuristic_step_size="no"),
        TypeError,
        "find_heuristic_step_size must be a bool",
    ),
    (
        "GeometricHMC jitter string",
        lambda: GeometricHMC(_model, jitter="no"),
        TypeError,
        "jitter must be a bool",
    ),
    (
        "GeometricHMC divergence_threshold string",
        lambda: GeometricHMC(_model, divergence_threshold="a"),
        TypeError,
        "divergence_threshold must be a real scalar",
    ),
    (
        "GeometricHMC divergence_threshold nan",
        lambda: GeometricHMC(_model, divergence_threshold=NAN),
        ValueError,
        "divergence_threshold must be finite",
    ),
    (
        "GeometricHMC inverse_mass_matrix negative",
        lambda: GeometricHMC(_model, inverse_mass_matrix=-1.0),
        ValueError,
        "inverse_mass_matrix must be > 0",
    ),
    (
        "GeometricHMC inverse_mass_matrix string",
        lambda: GeometricHMC(_model, inverse_mass_matrix="diag"),
        TypeError,
        "inverse_mass_matrix must be a real scalar",
    ),
    (
        "GeometricHMC step_size inf",
        lambda: GeometricHMC(_model, step_size=INF),
        ValueError,
        "step_size must be finite",
    ),
    (
        "GeometricHMC step_size string",
        lambda: GeometricHMC(_model, step_size="a"),
        TypeError,
        "step_size must be a real scalar",
    ),
    (
        "GeometricHMC model not callable",
        lambda: GeometricHMC(3),
        TypeError,
        "model must be a NumPyro model",
    ),
    (
        "GeometricHMC model and potential_fn",
        lambda: GeometricHMC(_model, potential_fn=_logdensity),
        ValueError,
        "give model or potential_fn, not both",
    ),
    (
        "GeometricHMC num_integration_steps float",
        lambda: GeometricHMC(_model, num_integration_steps=2.5),
        ValueError,
        "num_integration_steps.*integer",
    ),
    (
        "GeometricHMC num_steps and num_integration_steps",
        lambda: GeometricHMC(_model, num_steps=3, num_integration_steps=3),
        ValueError,
        "num_steps is NumPyro's name",
    ),
    (
        "GeometricHMC trajectory_length nan",
        lambda: GeometricHMC(_model, trajectory_length=NAN),
        ValueError,
        "integration_time must be finite",
    ),
    (
        "GeometricHMC dense_mass int",
        lambda: GeometricHMC(_model, dense_mass=1),
        TypeError,
        "dense_mass must be 'auto', a bool",
    ),
    (
        "GeometricHMC target_accept_prob one",
        lambda: GeometricHMC(_model, target_accept_prob=1.0),
        ValueError,
        r"target_accept_prob must be in \(0, 1\)",
    ),
    (
        "GeometricHMC kinetic_fn",
        lambda: GeometricHMC(_model, kinetic_fn=_identity),
        ValueError,
        "kinetic_fn is not supported",
    ),
    (
        "GeometricHMC init_strategy string",
        lambda: GeometricHMC(_model, init_strategy="median"),
        TypeError,
        "init_strategy must be a NumPyro initialisation strategy",
    ),
]

# Near misses that must work: numpy scalars and ints where floats are meant, lists for arrays.
ACCEPTED = [
    ("rigid_body inertia ints", lambda: systems.rigid_body([1, 2, 3])),
    ("rigid_body inertia jax array", lambda: systems.rigid_body(jnp.array([1.0, 2.0, 3.0]))),
    ("heisenberg shape numpy int", lambda: systems.heisenberg((np.int64(4),))),
    ("heisenberg shape list", lambda: systems.heisenberg([3, 3])),
    ("heisenberg field ints", lambda: systems.heisenberg((4,), field=(0, 0, 1))),
    ("heisenberg periodic numpy bool", lambda: systems.heisenberg((4,), periodic=np.True_)),
    ("heisenberg coupling float32", lambda: systems.heisenberg((4,), coupling=np.float32(1.0))),
    ("point_vortices integer circulations", lambda: systems.point_vortices([1, 2])),
    ("lie_poisson_system position list", lambda: _lps(position=[0.0, 0.0, 1.0])),
    ("Euclidean shape int", lambda: spaces.Euclidean(3)),
    ("U1 shape list", lambda: spaces.U1([2, 2])),
    ("SO n numpy int", lambda: spaces.SO(np.int64(3))),
    ("Sphere check list", lambda: spaces.Sphere(2).check([0.0, 0.0, 1.0])),
    ("langevin beta float32", lambda: _langevin(beta=np.float32(1.0))),
    ("langevin beta 0-d jax array", lambda: _langevin(beta=jnp.array(1.0))),
    ("langevin beta numpy int", lambda: _langevin(beta=np.int64(2))),
    ("langevin step_size int", lambda: _langevin(step_size=1)),
    (
        "geometric_hmc step_size 0-d jax array",
        lambda: liesample.geometric_hmc(_logdensity, E2, jnp.array(0.1), 3),
    ),
    ("geometric_hmc inverse mass list", lambda: _ghmc(inverse_mass_matrix=[1.0, 1.0])),
    ("geometric_hmc inverse mass scalar", lambda: _ghmc(inverse_mass_matrix=1.0)),
    ("GeometricHMC step_size float32", lambda: GeometricHMC(_model, step_size=np.float32(0.1))),
    ("VonMisesFisher mean_direction ints", lambda: lnp.VonMisesFisher([0, 0, 1], 2)),
    (
        "GeometricHMC inverse mass dict",
        lambda: GeometricHMC(_model, inverse_mass_matrix={"x": 1.0}),
    ),
]


@pytest.mark.parametrize(
    ("call", "error", "match"), [pytest.param(*row[1:], id=row[0]) for row in ROWS]
)
def test_bad_input_is_refused_naming_the_parameter(call, error, match):
    with pytest.raises(error, match=match):
        call()


@pytest.mark.parametrize("call", [pytest.param(row[1], id=row[0]) for row in ACCEPTED])
def test_near_misses_are_accepted(call):
    call()  # builds (or checks) without raising


def test_the_table_covers_every_family():
    """At least 150 bad inputs across the families the issue names, each id unique."""
    ids = [row[0] for row in ROWS] + [row[0] for row in ACCEPTED]
    assert len(ids) == len(set(ids))
    assert len(ids) >= 150
