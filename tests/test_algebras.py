"""so(3) and its coadjoint action (MATH.md §2), against identities and an independent rotation code.

Convention under test: ``[a, b] = a × b``, ``ad*_ξ μ = μ × ξ`` (so ``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩``),
and ``coadjoint_exp(ζ, μ)`` is the time-one flow of ``μ̇ = μ × ζ = −ζ × μ``: the rotation by angle
``|ζ|`` about ``−ζ/|ζ|``, i.e. ``scipy.spatial.transform.Rotation.from_rotvec(−ζ)``.

Tolerances: every quantity here is a product of at most three vectors of size ``≲ 10``, evaluated
in float64 with a handful of roundings, so round-off is ``≲ 10 ulp × |a||b||c|``; ``1e-13`` relative
to that scale is ample yet far below any sign or factor slip (which would be O(1) relative).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

import liesample
from liesample.geometry.algebras import so3

RNG_SEED = 20240611
REL = 1e-13  # see module docstring


def rotation_matrix(zeta):
    """The matrix of ``coadjoint_exp(ζ, ·)``, built independently: rotation by ``|ζ|`` about −ζ."""
    return Rotation.from_rotvec(-np.asarray(zeta, dtype=float)).as_matrix()


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


bracket = liesample.jit(so3.bracket)
ad_star = liesample.jit(so3.ad_star)
coadjoint_exp = liesample.jit(so3.coadjoint_exp)
casimirs = liesample.jit(so3.casimirs)


# ---------------------------------------------------------------------------------------------
# Bracket and ad*
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(3,), (5, 3)])
def test_adjointness_and_pairing(rng, shape):
    mu, xi, eta = (rng.normal(size=shape) for _ in range(3))
    lhs = float(so3.pairing(ad_star(xi, mu), eta))
    rhs = float(so3.pairing(mu, bracket(xi, eta)))
    scale = np.sum(
        np.linalg.norm(mu, axis=-1) * np.linalg.norm(xi, axis=-1) * np.linalg.norm(eta, axis=-1)
    )
    assert abs(lhs - rhs) <= REL * scale
    # Copy by copy too (the pairing sums over every axis, so check it is not cancelling).
    per_copy_lhs = np.sum(np.asarray(ad_star(xi, mu)) * eta, axis=-1)
    per_copy_rhs = np.sum(mu * np.asarray(bracket(xi, eta)), axis=-1)
    np.testing.assert_allclose(per_copy_lhs, per_copy_rhs, rtol=0, atol=REL * scale)
    # The closed forms themselves, against numpy.
    np.testing.assert_allclose(bracket(xi, eta), np.cross(xi, eta), rtol=0, atol=REL * scale)
    np.testing.assert_allclose(ad_star(xi, mu), np.cross(mu, xi), rtol=0, atol=REL * scale)


def test_pairing_is_the_sum_of_elementwise_products(rng):
    mu, xi = rng.normal(size=(2, 4, 3))
    assert float(so3.pairing(mu, xi)) == pytest.approx(float(np.sum(mu * xi)), rel=1e-14)


@pytest.mark.parametrize("shape", [(3,), (6, 3)])
def test_jacobi_and_antisymmetry(rng, shape):
    a, b, c = (rng.normal(size=shape) for _ in range(3))
    jacobi = bracket(a, bracket(b, c)) + bracket(b, bracket(c, a)) + bracket(c, bracket(a, b))
    scale = np.max(
        np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1) * np.linalg.norm(c, axis=-1)
    )
    np.testing.assert_allclose(jacobi, 0.0, atol=10 * REL * scale)
    # Not bit-exact: XLA may fuse a multiply-add differently in a×b and b×a.
    np.testing.assert_allclose(bracket(a, b), -bracket(b, a), rtol=0, atol=REL * scale)
    np.testing.assert_allclose(bracket(a, a), 0.0, atol=REL * scale)
    # The identity is not vacuous: a single double bracket is O(scale).
    assert np.max(np.abs(bracket(a, bracket(b, c)))) > 1e-3 * scale


def test_stack_operations_act_copy_by_copy(rng):
    mu, xi, zeta = rng.normal(size=(3, 7, 3))
    out_bracket = bracket(xi, zeta)
    out_ad = ad_star(xi, mu)
    out_exp = coadjoint_exp(zeta, mu)
    for k in range(7):
        np.testing.assert_allclose(out_bracket[k], bracket(xi[k], zeta[k]), rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(out_ad[k], ad_star(xi[k], mu[k]), rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(out_exp[k], coadjoint_exp(zeta[k], mu[k]), rtol=0, atol=1e-14)
        np.testing.assert_allclose(out_exp[k], rotation_matrix(zeta[k]) @ mu[k], atol=1e-13)
    assert casimirs(mu).shape == (7,)
    np.testing.assert_allclose(casimirs(mu), np.sum(mu * mu, axis=-1), rtol=1e-15)
    # One generator broadcast over a stack of states.
    out_broadcast = coadjoint_exp(zeta[0], mu)
    np.testing.assert_allclose(out_broadcast, mu @ rotation_matrix(zeta[0]).T, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# The coadjoint action Ad*_{exp ζ}
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [1e-9, 1e-4, 0.3, 2.0, np.pi, 4.0, 10.0, 50.0])
def test_coadjoint_exp_is_the_rotation_about_minus_zeta(rng, angle):
    """Independent reference: scipy's rotation by |ζ| about −ζ/|ζ| (the flow of μ̇ = μ × ζ)."""
    axis = rng.normal(size=3)
    zeta = angle * axis / np.linalg.norm(axis)
    mu = rng.normal(size=3)
    # Rodrigues in float64: a few ulp of |μ|, plus ulp(|ζ|)·|μ| from the angle itself.
    tol = 1e-14 * (1 + angle) * np.linalg.norm(mu)
    np.testing.assert_allclose(coadjoint_exp(zeta, mu), rotation_matrix(zeta) @ mu, atol=tol)
    # The sign convention is not a coin flip: the opposite rotation is far off (unless the
    # angle is a multiple of π or so tiny that both agree to round-off).
    if 1e-3 < angle % np.pi < np.pi - 1e-3:
        assert np.linalg.norm(rotation_matrix(-zeta) @ mu - coadjoint_exp(zeta, mu)) > 1e-4


def test_coadjoint_exp_is_a_one_parameter_group(rng):
    mu = rng.normal(size=(4, 3))
    zeta = 1.7 * rng.normal(size=(4, 3))
    for s, t in [(0.3, 0.9), (-1.9, 0.7), (2.5, 3.1), (1.0, -1.0)]:
        composed = coadjoint_exp(s * zeta, coadjoint_exp(t * zeta, mu))
        direct = coadjoint_exp((s + t) * zeta, mu)
        # Angles up to ~30 rad: ulp(angle)·|μ| ~ 1e-14 per application.
        np.testing.assert_allclose(composed, direct, rtol=0, atol=1e-13)
    # (1, −1): the identity.
    np.testing.assert_allclose(coadjoint_exp(-zeta, coadjoint_exp(zeta, mu)), mu, atol=1e-14)


def test_coadjoint_exp_composition_matches_rotation_product(rng):
    """Non-commuting generators: composition is the product of the rotation matrices."""
    mu = rng.normal(size=3)
    z1, z2 = 1.3 * rng.normal(size=(2, 3))
    composed = np.asarray(coadjoint_exp(z1, coadjoint_exp(z2, mu)))
    expected = rotation_matrix(z1) @ rotation_matrix(z2) @ mu
    np.testing.assert_allclose(composed, expected, atol=1e-13)
    # The generators genuinely do not commute (so the check above is not trivially passed by
    # coadjoint_exp(z1 + z2) or by the other order).
    assert np.linalg.norm(composed - np.asarray(coadjoint_exp(z1 + z2, mu))) > 1e-2
    other_order = np.asarray(coadjoint_exp(z2, coadjoint_exp(z1, mu)))
    assert np.linalg.norm(composed - other_order) > 1e-2


def test_coadjoint_exp_first_order_is_ad_star(rng):
    """``(Ad*_{exp εζ} μ − μ)/ε = ad*_ζ μ + (ε/2) ζ×(ζ×μ) + O(ε²)``."""
    mu, zeta = rng.normal(size=(2, 3))
    size = np.linalg.norm(zeta) ** 2 * np.linalg.norm(mu)
    first = np.asarray(ad_star(zeta, mu))
    second = 0.5 * np.cross(zeta, np.cross(zeta, mu))
    errors = []
    for eps in [1e-2, 1e-3, 1e-4]:
        quotient = (np.asarray(coadjoint_exp(eps * zeta, mu)) - mu) / eps
        error = np.linalg.norm(quotient - first)
        errors.append(error)
        # Exact second-order coefficient is ½|ζ×(ζ×μ)| ≤ ½|ζ|²|μ|.
        assert error <= eps * size
        # The next term is ε²|ζ|³|μ|/6; round-off of the difference quotient is ~1e-16|μ|/ε.
        residual = np.linalg.norm(quotient - first - eps * second)
        assert residual <= eps**2 * np.linalg.norm(zeta) ** 3 * np.linalg.norm(mu) + 1e-14 / eps
    # First order: the error shrinks ~10× per decade of ε.
    assert 8 < errors[0] / errors[1] < 12
    assert 8 < errors[1] / errors[2] < 12


def test_coadjoint_exp_smooth_at_zero(rng):
    mu = rng.normal(size=3)
    np.testing.assert_array_equal(coadjoint_exp(np.zeros(3), mu), mu)
    stack = rng.normal(size=(3, 3))
    np.testing.assert_array_equal(coadjoint_exp(np.zeros((3, 3)), stack), stack)
    direction = rng.normal(size=3)
    for size in [1e-12, 1e-8]:
        zeta = size * direction / np.linalg.norm(direction)
        increment = np.asarray(coadjoint_exp(zeta, mu)) - mu
        assert np.all(np.isfinite(increment))
        # Increment ≈ μ×ζ (size ~ |μ|·size); subtracting μ costs ~1e-16|μ|, second order is
        # ~size²|μ| — both ≤ 1e-3 of the increment for these sizes.
        np.testing.assert_allclose(
            increment, np.cross(mu, zeta), rtol=0, atol=1e-3 * size * np.linalg.norm(mu)
        )


# Jacobians in ζ, compiled once for both derivative tests (eager, each of the small-angle
# branches' operations would compile on its own); μ is an argument.
ad_star_jacobian = liesample.jit(jax.jacfwd(so3.ad_star))
coadjoint_exp_jacobians = {
    "jacfwd": liesample.jit(jax.jacfwd(so3.coadjoint_exp)),
    "jacrev": liesample.jit(jax.jacrev(so3.coadjoint_exp)),
}


def test_coadjoint_exp_derivative_at_zero_is_ad_star(rng):
    mu = rng.normal(size=3)
    expected = ad_star_jacobian(jnp.zeros(3), mu)  # ζ ↦ μ × ζ
    for jac in coadjoint_exp_jacobians.values():
        got = jac(jnp.zeros(3), mu)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


def test_coadjoint_exp_derivative_near_zero_is_ad_star(rng):
    """Away from exactly 0 the derivative is fine (and → ad*_· μ)."""
    mu = rng.normal(size=3)
    expected = ad_star_jacobian(jnp.zeros(3), mu)
    got = coadjoint_exp_jacobians["jacfwd"](jnp.full(3, 1e-10), mu)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-8)


def test_casimirs_preserved_under_many_random_moves():
    """2000 successive moves with generators of size ~3 (many full turns): |μ_k|² kept to 1e-12.

    Each move adds a few ulp of relative error to |μ|² (a random walk, ~√2000·1e-16 ≈ 5e-15);
    1e-12 leaves room for a systematic per-move bias of 5e-16 but not for any real drift.
    """
    key = jax.random.key(7)
    mu0 = jnp.array([[0.3, -1.2, 2.0], [1e-3, 2e-3, -5e-4], [40.0, 10.0, -25.0]])

    @liesample.jit
    def run(mu, key):
        def move(mu, k):
            return so3.coadjoint_exp(3.0 * jax.random.normal(k, mu.shape), mu), None

        return jax.lax.scan(move, mu, jax.random.split(key, 2000))[0]

    mu = run(mu0, key)
    c0 = np.asarray(casimirs(mu0))
    relative = np.abs(np.asarray(casimirs(mu)) - c0) / c0
    assert np.all(relative < 1e-12), relative
    # The moves did move the state.
    assert np.all(np.linalg.norm(np.asarray(mu) - np.asarray(mu0), axis=-1) > 1e-2 * np.sqrt(c0))


# ---------------------------------------------------------------------------------------------
# Property-based versions (hypothesis, derandomised so CI is reproducible)
# ---------------------------------------------------------------------------------------------

ELEMENT = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False, allow_subnormal=False)
HYPOTHESIS = settings(max_examples=60, deadline=None, derandomize=True)


def vectors(n):
    return arrays(np.float64, (n, 3), elements=ELEMENT)


def _scale(*vs):
    return np.prod([np.linalg.norm(v, axis=-1) for v in vs], axis=0)


@HYPOTHESIS
@given(st.integers(1, 3).flatmap(lambda n: st.tuples(vectors(n), vectors(n), vectors(n))))
def test_property_adjointness(triple):
    mu, xi, eta = triple
    lhs = np.sum(np.asarray(ad_star(xi, mu)) * eta, axis=-1)
    rhs = np.sum(mu * np.asarray(bracket(xi, eta)), axis=-1)
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=REL * (1 + _scale(mu, xi, eta)).max())


@HYPOTHESIS
@given(st.integers(1, 3).flatmap(lambda n: st.tuples(vectors(n), vectors(n), vectors(n))))
def test_property_jacobi(triple):
    a, b, c = triple
    jacobi = bracket(a, bracket(b, c)) + bracket(b, bracket(c, a)) + bracket(c, bracket(a, b))
    np.testing.assert_allclose(jacobi, 0.0, atol=10 * REL * (1 + _scale(a, b, c)).max())


@HYPOTHESIS
@given(st.integers(1, 3).flatmap(lambda n: st.tuples(vectors(n), vectors(n))))
def test_property_casimir_preserved(pair):
    zeta, mu = pair
    c0 = np.sum(mu * mu, axis=-1)
    assume(np.all(c0 > 1e-12))
    moved = np.asarray(coadjoint_exp(zeta, mu))
    # |ζ| ≤ 17.4 here: ulp(angle) effects stay ~1e-15 relative; 1e-12 is generous but a
    # wrong Rodrigues coefficient would be O(1).
    np.testing.assert_allclose(np.sum(moved * moved, axis=-1), c0, rtol=1e-12)
    # And the move agrees with the independent rotation.
    for k in range(len(mu)):
        np.testing.assert_allclose(
            moved[k],
            rotation_matrix(zeta[k]) @ mu[k],
            rtol=0,
            atol=1e-13 * (1 + np.linalg.norm(zeta[k])) * np.sqrt(c0[k]),
        )
