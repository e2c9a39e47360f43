"""Property-based tests (hypothesis) of the algebra identities and of orbit preservation.

For so(3), se(3), sl(2, R), se(2) and the structure-constant se(3), on random elements:
antisymmetry and the Jacobi identity of the bracket, adjointness of ``ad*``
(``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩``, MATH.md §2), ``coadjoint_exp`` as a one-parameter group
(``Ad*_{exp sζ} Ad*_{exp tζ} = Ad*_{exp (s+t)ζ}``, ``Ad*_{exp 0} = id``) whose derivative at 0 is
``ad*_ζ``, and invariance of the Casimirs under it; and that one step of the sampler keeps a
random state on its coadjoint orbit for every orbit-preserving integrator. Example counts are
modest and derandomized (reproducible, no example database needed).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import liesample
from liesample import algebras
from liesample.samplers.orbit import lie_poisson_langevin as lpl
from liesample.systems.heisenberg import SpinLatticeSystem

PROFILE = settings(
    max_examples=30,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

ALGEBRAS = {
    "so3": (algebras.so3, 3),
    "se3": (algebras.se3, 6),
    "sl2": (algebras.sl2, 3),
    "se2": (algebras.se2, 3),
    "se3 constants": (algebras.se3_structure_constants, 6),
}


def vectors(dimension, bound=2.0):
    return arrays(np.float64, (dimension,), elements=st.floats(-bound, bound, width=64))


def _triples(dimension, bound=2.0):
    return st.tuples(
        vectors(dimension, bound), vectors(dimension, bound), vectors(dimension, bound)
    )


def _scale(*xs):
    return 1.0 + sum(float(np.max(np.abs(x))) for x in xs) ** 3


@pytest.mark.parametrize("name", list(ALGEBRAS))
def test_bracket_antisymmetry_jacobi_and_adjointness(name):
    algebra, dimension = ALGEBRAS[name]
    bracket = liesample.jit(algebra.bracket)
    ad_star = liesample.jit(algebra.ad_star)

    @PROFILE
    @given(_triples(dimension), vectors(dimension))
    def check(triple, mu):
        xi, eta, zeta = (jnp.asarray(x) for x in triple)
        tol = 1e-12 * _scale(xi, eta, zeta, mu)
        np.testing.assert_allclose(bracket(xi, eta), -bracket(eta, xi), atol=tol, rtol=0)
        jacobi = (
            bracket(xi, bracket(eta, zeta))
            + bracket(eta, bracket(zeta, xi))
            + bracket(zeta, bracket(xi, eta))
        )
        np.testing.assert_allclose(jacobi, 0.0, atol=tol)
        left = jnp.sum(ad_star(xi, mu) * eta)
        right = jnp.sum(mu * bracket(xi, eta))
        np.testing.assert_allclose(left, right, atol=tol, rtol=0)

    check()


@pytest.mark.parametrize("name", list(ALGEBRAS))
def test_coadjoint_exp_is_a_one_parameter_group_preserving_casimirs(name):
    algebra, dimension = ALGEBRAS[name]
    move = liesample.jit(algebra.coadjoint_exp)
    ad_star = liesample.jit(algebra.ad_star)
    casimirs = liesample.jit(algebra.casimirs)

    @PROFILE
    @given(
        vectors(dimension, 1.0),
        vectors(dimension, 2.0),
        st.floats(-1.0, 1.0),
        st.floats(-1.0, 1.0),
    )
    def check(zeta, mu, s, t):
        zeta, mu = jnp.asarray(zeta), jnp.asarray(mu)
        size = 1.0 + float(jnp.max(jnp.abs(mu)))
        composed = move(s * zeta, move(t * zeta, mu))
        direct = move((s + t) * zeta, mu)
        # Round-off relative to the largest entry involved (non-compact orbits stretch μ).
        tol = 1e-12 * (size + float(jnp.max(jnp.abs(direct))))
        np.testing.assert_allclose(move(0.0 * zeta, mu), mu, atol=1e-14 * size, rtol=0)
        np.testing.assert_allclose(composed, direct, atol=tol, rtol=0)
        # Casimirs are invariant (relative to the size of the state squared).
        moved = move(zeta, mu)
        c0, c1 = casimirs(mu), casimirs(moved)
        scale = size + float(jnp.max(jnp.abs(moved)))
        np.testing.assert_allclose(c1, c0, atol=1e-12 * scale**2, rtol=0)
        # d/dε Ad*_{exp εζ} μ at 0 is ad*_ζ μ (central difference, error O(ε²)).
        eps = 1e-5
        derivative = (move(eps * zeta, mu) - move(-eps * zeta, mu)) / (2 * eps)
        np.testing.assert_allclose(derivative, ad_star(zeta, mu), atol=1e-8 * size**2, rtol=0)

    check()


SYSTEMS = {
    "rigid body": liesample.systems.rigid_body((1.0, 2.0, 4.0)),
    "heavy top": liesample.systems.heavy_top(mgl=2.0),
    "spin chain": liesample.systems.heisenberg((3,), field=(0.0, 0.0, 0.5)),
}


def _random_position(system, raw):
    """A valid state from raw normals: spins normalised to unit length, others as they are."""
    position = raw.reshape(system.event_shape)
    if isinstance(system, SpinLatticeSystem):
        position = position / np.linalg.norm(position, axis=-1, keepdims=True)
    return position


def _orbit_cases():
    """Every system with the splitting and every integrator on the rigid body by default."""
    for name in SYSTEMS:
        for integrator in ("splitting", "rkmk_heun", "lie_euler"):
            quick = integrator == "splitting" or name == "rigid body"
            # slow: another integrator on another system; the default suite checks this with
            # test_properties.py::test_one_step_stays_on_the_orbit[rigid body-<integrator>]
            marks = () if quick else pytest.mark.slow
            yield pytest.param(name, integrator, id=f"{name}-{integrator}", marks=marks)


@pytest.mark.parametrize(("name", "integrator"), list(_orbit_cases()))
def test_one_step_stays_on_the_orbit(name, integrator):
    system = SYSTEMS[name]
    size = int(np.prod(system.event_shape))
    kernel = liesample.jit(lpl.build_kernel(system, integrator))

    @settings(PROFILE, max_examples=15)
    @given(
        arrays(np.float64, (size,), elements=st.floats(0.2, 2.0) | st.floats(-2.0, -0.2)),
        st.floats(1e-3, 0.3),
        st.floats(0.1, 10.0),
        st.floats(0.1, 3.0),
        st.integers(0, 2**31 - 1),
    )
    def check(raw, step_size, beta, sigma, seed):
        position = _random_position(system, raw)
        state = lpl.init(position, system)
        theta = 0.5 * beta * sigma**2
        new, info = kernel(jax.random.key(seed), state, step_size, sigma, theta)
        assert not bool(info.is_divergent)
        assert np.all(np.isfinite(np.asarray(new.position)))
        assert float(info.casimir_error) < 1e-12
        np.testing.assert_allclose(
            system.casimirs(new.position),
            state.reference_casimirs,
            rtol=1e-12,
            atol=1e-12 * float(np.sum(position**2)),
        )

    check()
