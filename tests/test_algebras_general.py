"""Every Lie algebra through the same interface: so(3), se(3) in closed form and from structure
constants, and the non-compact sl(2, R) and se(2) (MATH.md §2).

Identities tested for each: ``⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩``, antisymmetry and Jacobi of the bracket,
``coadjoint_exp`` a one-parameter group whose derivative at 0 is ``ad*``, and Casimirs preserved to
round-off by repeated coadjoint moves. Tolerances: every quantity is a sum of products of at most
three O(1–10) numbers, so round-off is ~1e-15 of the product of the sizes; 1e-13 relative to that
scale leaves a wide margin yet is far below any sign or index slip (O(1) relative). Matrix
exponentials of generators of size ≲ 3 add ~1e-15·e^{‖M‖} (non-compact algebras grow).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import liesample
from liesample import algebras
from liesample.geometry.algebras import SE3, StructureConstants

REL = 1e-13
RNG_SEED = 31415


class Compiled:
    """An algebra with its operations jitted once per test worker (eager dispatch of expm and
    its many small ops is slow); everything else is delegated to the algebra."""

    def __init__(self, algebra):
        self.algebra = algebra
        for op in ("bracket", "ad_star", "coadjoint_exp", "casimirs"):
            setattr(self, op, liesample.jit(getattr(algebra, op)))
        # Jacobians of ζ ↦ Ad*_{exp ζ} μ (μ an argument), shared by the derivative tests.
        self.exp_jacfwd = liesample.jit(jax.jacfwd(algebra.coadjoint_exp))
        self.exp_jacrev = liesample.jit(jax.jacrev(algebra.coadjoint_exp))

    def __getattr__(self, name):
        return getattr(self.algebra, name)


so3, se3, se2, sl2 = (Compiled(a) for a in (algebras.so3, algebras.se3, algebras.se2, algebras.sl2))
se3_structure_constants = Compiled(algebras.se3_structure_constants)

ALGEBRAS = {
    "so3": (so3, 3),
    "se3": (se3, 6),
    "se3_constants": (se3_structure_constants, 6),
    "sl2": (sl2, 3),
    "se2": (se2, 3),
}
NAMES = list(ALGEBRAS)
NON_COMPACT = {"se3", "se3_constants", "sl2", "se2"}


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def norms(*vectors):
    return np.prod([np.linalg.norm(v) for v in vectors])


# ---------------------------------------------------------------------------------------------
# Bracket and ad*
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_adjointness(rng, name):
    algebra, n = ALGEBRAS[name]
    for _ in range(5):
        mu, xi, eta = rng.normal(size=(3, n))
        lhs = float(algebra.pairing(algebra.ad_star(xi, mu), eta))
        rhs = float(algebra.pairing(mu, algebra.bracket(xi, eta)))
        assert abs(lhs - rhs) <= REL * norms(mu, xi, eta), (lhs, rhs)
        # Not vacuous: ad*_ξ μ differs from −ad*_ξ μ (i.e. it is not identically zero).
        assert np.linalg.norm(algebra.ad_star(xi, mu)) > 1e-3 * norms(mu, xi)


@pytest.mark.parametrize("name", NAMES)
def test_jacobi_and_antisymmetry(rng, name):
    algebra, n = ALGEBRAS[name]
    bracket = algebra.bracket
    for _ in range(5):
        a, b, c = rng.normal(size=(3, n))
        jacobi = bracket(a, bracket(b, c)) + bracket(b, bracket(c, a)) + bracket(c, bracket(a, b))
        np.testing.assert_allclose(jacobi, 0.0, atol=10 * REL * norms(a, b, c))
        np.testing.assert_allclose(bracket(a, b), -bracket(b, a), rtol=0, atol=REL * norms(a, b))
        np.testing.assert_allclose(bracket(a, a), 0.0, atol=REL * norms(a, a))
        assert np.max(np.abs(bracket(a, bracket(b, c)))) > 1e-3 * norms(a, b, c)


def test_se3_closed_form_bracket_and_ad_star_match_structure_constants(rng):
    for _ in range(5):
        mu, xi, eta = rng.normal(size=(3, 6))
        np.testing.assert_allclose(
            se3.bracket(xi, eta), se3_structure_constants.bracket(xi, eta), atol=REL * 10
        )
        np.testing.assert_allclose(
            se3.ad_star(xi, mu), se3_structure_constants.ad_star(xi, mu), atol=REL * 10
        )
    # And ad* is MATH.md §2's formula, written out by hand.
    pi, gamma, a, v = rng.normal(size=(4, 3))
    expected = np.concatenate([np.cross(pi, a) + np.cross(gamma, v), np.cross(gamma, a)])
    np.testing.assert_allclose(
        se3.ad_star(np.concatenate([a, v]), np.concatenate([pi, gamma])), expected, atol=1e-14
    )


def test_sl2_coadjoint_action_by_hand():
    """``ad*_H μ = (0, 2μ_E, −2μ_F)`` from ``⟨μ, [H, E]⟩ = 2μ_E``, ``⟨μ, [H, F]⟩ = −2μ_F``: the
    flow of ``H`` is ``(μ_H, e^{2t}μ_E, e^{−2t}μ_F)``, unbounded (non-compact orbits)."""
    mu = np.array([0.7, -1.1, 0.4])
    h = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(sl2.ad_star(h, mu), [0.0, 2 * mu[1], -2 * mu[2]], atol=1e-15)
    for t in (0.3, -1.2, 2.5):
        expected = [mu[0], np.exp(2 * t) * mu[1], np.exp(-2 * t) * mu[2]]
        np.testing.assert_allclose(sl2.coadjoint_exp(t * h, mu), expected, rtol=1e-13)
    # ad*_E μ = (−2μ_E... ) written out: ⟨μ,[E,H]⟩ = −2μ_E, ⟨μ,[E,E]⟩ = 0, ⟨μ,[E,F]⟩ = μ_H.
    e = np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(sl2.ad_star(e, mu), [-2 * mu[1], 0.0, mu[0]], atol=1e-15)


def test_sl2_casimir_is_the_dual_killing_form(rng):
    """Killing form ``B_ij = tr(ad_{e_i} ad_{e_j})`` computed from the constants; the Casimir is
    ``8 μᵀB⁻¹μ`` (``B = diag-ish (8; [[0,4],[4,0]])``)."""
    c = sl2.constants
    ad = np.einsum("ilk->ikl", c)  # (ad_{e_i})_{kl} = c_{il}^k
    killing = np.einsum("ikl,jlk->ij", ad, ad)
    np.testing.assert_allclose(killing, [[8, 0, 0], [0, 0, 4], [0, 4, 0]], atol=1e-14)
    mu = rng.normal(size=(5, 3))
    expected = 8.0 * np.einsum("ni,ij,nj->n", mu, np.linalg.inv(killing), mu)
    np.testing.assert_allclose(sl2.casimirs(mu)[:, 0], expected, rtol=1e-13)


def test_default_casimirs_are_empty():
    algebra = StructureConstants(se2.constants)
    assert algebra.casimirs(jnp.ones(3)).shape == (0,)
    assert algebra.casimirs(jnp.ones((4, 3))).shape == (4, 0)
    assert se3.casimirs(jnp.ones((4, 6))).shape == (4, 2)
    assert sl2.casimirs(jnp.ones(3)).shape == (1,)
    assert se3_structure_constants.dimension == 6


# ---------------------------------------------------------------------------------------------
# The coadjoint action
# ---------------------------------------------------------------------------------------------


def generator_scale(name):
    """Generator sizes: ~1.5 for compact directions, ~0.7 where the action grows like e^{2|ζ|}."""
    return 0.7 if name == "sl2" else 1.5


@pytest.mark.parametrize("name", NAMES)
def test_coadjoint_exp_is_a_one_parameter_group(rng, name):
    algebra, n = ALGEBRAS[name]
    mu = rng.normal(size=n)
    zeta = generator_scale(name) * rng.normal(size=n)
    move = algebra.coadjoint_exp  # compiled once per algebra (Compiled), shared with the others
    for s, t in [(0.3, 0.9), (-1.9, 0.7), (1.4, 1.1), (1.0, -1.0)]:
        composed = np.asarray(move(s * zeta, move(t * zeta, mu)))
        direct = np.asarray(move((s + t) * zeta, mu))
        size = max(np.linalg.norm(direct), np.linalg.norm(move(t * zeta, mu)), np.linalg.norm(mu))
        np.testing.assert_allclose(composed, direct, rtol=0, atol=REL * 10 * size)
    np.testing.assert_allclose(move(-zeta, move(zeta, mu)), mu, atol=REL * 10 * np.exp(4))
    np.testing.assert_array_equal(move(np.zeros(n), mu), mu)


@pytest.mark.parametrize("name", NAMES)
def test_coadjoint_exp_first_order_is_ad_star(rng, name):
    """``(Ad*_{exp εζ} μ − μ)/ε = ad*_ζ μ + O(ε)``, the error shrinking ~10× per decade."""
    algebra, n = ALGEBRAS[name]
    mu, zeta = rng.normal(size=(2, n))
    first = np.asarray(algebra.ad_star(zeta, mu))
    second = 0.5 * np.asarray(algebra.ad_star(zeta, algebra.ad_star(zeta, mu)))
    errors = []
    for eps in [1e-2, 1e-3, 1e-4]:
        quotient = (np.asarray(algebra.coadjoint_exp(eps * zeta, mu)) - mu) / eps
        errors.append(np.linalg.norm(quotient - first))
        # The second-order term is ½ (ad*_ζ)² μ; the rest is O(ε²) plus round-off 1e-16/ε.
        residual = np.linalg.norm(quotient - first - eps * second)
        assert residual <= eps**2 * 10 * norms(zeta, zeta, zeta, mu) + 1e-14 / eps
    assert 8 < errors[0] / errors[1] < 12
    assert 8 < errors[1] / errors[2] < 12


@pytest.mark.parametrize("name", NAMES)
def test_coadjoint_exp_derivative_at_zero_is_ad_star(rng, name):
    algebra, n = ALGEBRAS[name]
    mu = rng.normal(size=n)
    expected = jax.jacfwd(lambda z: algebra.ad_star(z, mu))(jnp.zeros(n))
    # Reverse mode too for the closed forms (so(3), se(3)), whose small-angle branches are ours;
    # for expm-based algebras forward mode suffices (compiling expm's VJP costs seconds).
    closed_form = not isinstance(algebra.algebra, StructureConstants)
    for jac in (algebra.exp_jacfwd, algebra.exp_jacrev) if closed_form else (algebra.exp_jacfwd,):
        got = jac(jnp.zeros(n), jnp.asarray(mu))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", NAMES)
def test_casimirs_preserved_by_repeated_moves(name):
    """300 random moves (scan): each Casimir kept to 1e-12 of |μ|² (the scale of its round-off;
    the Casimirs here are quadratic and may be 0 or negative), while the state really moved and
    |μ|² itself — not a Casimir except on so(3) — did change."""
    algebra, n = ALGEBRAS[name]
    size = 0.1 if name == "sl2" else 1.0  # sl(2): hyperbolic random walk, keep |μ| moderate
    mu0 = jnp.asarray(np.random.default_rng(5).normal(size=n))

    @liesample.jit
    def run(mu, key):
        def move(mu, k):
            mu = algebra.coadjoint_exp(size * jax.random.normal(k, mu.shape), mu)
            return mu, (algebra.casimirs(mu), jnp.sum(mu * mu))

        return jax.lax.scan(move, mu, jax.random.split(key, 300))

    mu, (casimirs, sizes) = run(mu0, jax.random.key(3))
    c0 = np.asarray(algebra.casimirs(mu0))
    drift = np.abs(np.asarray(casimirs) - c0) / np.asarray(sizes)[:, None]
    assert np.all(drift < 1e-12), drift.max()
    assert np.linalg.norm(np.asarray(mu) - np.asarray(mu0)) > 0.1
    if name != "so3":
        assert np.ptp(np.asarray(sizes)) > 1e-2 * float(np.sum(mu0**2))


def test_se3_casimirs_of_either_sign_and_zero(rng):
    """Π·Γ is preserved whether it is positive, negative or zero (relative to |Π||Γ|)."""
    gamma = rng.normal(size=3)
    pi_perp = np.cross(gamma, rng.normal(size=3))
    for c in (1.3, -0.8, 0.0):
        mu = np.concatenate([pi_perp + c * gamma / np.dot(gamma, gamma), gamma])
        casimirs0 = np.asarray(se3.casimirs(mu))
        assert casimirs0[1] == pytest.approx(c, abs=1e-14)
        zeta = 2.0 * rng.normal(size=6)
        moved = np.asarray(se3.coadjoint_exp(zeta, mu))
        np.testing.assert_allclose(
            se3.casimirs(moved), casimirs0, rtol=0, atol=1e-14 * np.sum(moved**2)
        )


# ---------------------------------------------------------------------------------------------
# se(3): closed form against the matrix exponential
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "angle", [0.0, 1e-14, 1e-12, 1e-8, 1e-4, 1e-2, 0.3, 0.4999, 0.5001, 1.0, np.pi, 6.0, 20.0]
)
def test_se3_closed_form_equals_expm(rng, angle):
    """Including ξ = 0 (pure translation: Π' = Π + Γ×v), tiny ξ and both sides of the series
    switch at |ξ| = 0.5. expm loses ~ulp·‖M‖ (observed ≤ 1e-14 relative up to θ = 20), hence
    the (1+θ) factor."""
    for _ in range(3):
        direction = rng.normal(size=3)
        xi = angle * direction / np.linalg.norm(direction)
        v = 1.5 * rng.normal(size=3)
        zeta, mu = np.concatenate([xi, v]), rng.normal(size=6)
        closed = np.asarray(se3.coadjoint_exp(zeta, mu))
        matrix = np.asarray(se3_structure_constants.coadjoint_exp(zeta, mu))
        tol = 1e-13 * (1 + angle) * (1 + np.linalg.norm(v)) * np.linalg.norm(mu)
        np.testing.assert_allclose(closed, matrix, rtol=0, atol=tol)
    if angle == 0.0:
        pi, gamma = mu[:3], mu[3:]
        np.testing.assert_allclose(closed[:3], pi + np.cross(gamma, v), atol=1e-15)
        np.testing.assert_array_equal(closed[3:], gamma)


def test_se3_closed_form_is_smooth(rng):
    """Derivatives of the closed form agree with those of expm at and near ξ = 0 and at the
    series switch (a wrong branch or a NaN in the unused branch would show here)."""
    mu, base = rng.normal(size=(2, 6))
    direction = base[:3] / np.linalg.norm(base[:3])
    mu = jnp.asarray(mu)
    for angle in (0.0, 1e-9, 0.4999999, 0.5, 0.5000001, 2.0):
        zeta = jnp.concatenate([angle * direction, base[3:]])
        closed = se3.exp_jacfwd(zeta, mu)
        assert np.all(np.isfinite(closed))
        matrix = se3_structure_constants.exp_jacfwd(zeta, mu)
        np.testing.assert_allclose(closed, matrix, rtol=0, atol=1e-12)
        np.testing.assert_allclose(se3.exp_jacrev(zeta, mu), closed, rtol=0, atol=1e-13)


def test_se3_broadcasts_over_stacks(rng):
    mu, zeta = rng.normal(size=(2, 4, 6))
    stacked = np.asarray(se3.coadjoint_exp(zeta, mu))
    for k in range(4):
        np.testing.assert_allclose(stacked[k], se3.coadjoint_exp(zeta[k], mu[k]), atol=1e-14)
    assert se3.casimirs(mu).shape == (4, 2)


# ---------------------------------------------------------------------------------------------
# Products of copies: so(3) on (N, 3) is (so(3))^N
# ---------------------------------------------------------------------------------------------


def test_so3_stack_is_the_product_algebra(rng):
    """SO3 on shape (N, 3) equals the block-diagonal structure constants of (so(3))^N, built
    independently, for bracket, ad* and coadjoint_exp (no loop over blocks in SO3)."""
    num = 3
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    c = np.zeros((3 * num, 3 * num, 3 * num))
    for k in range(num):
        block = slice(3 * k, 3 * k + 3)
        c[block, block, block] = eps
    product = Compiled(StructureConstants(c, name="so(3)^3"))
    mu, xi, zeta = rng.normal(size=(3, num, 3))
    flat = lambda x: np.asarray(x).reshape(-1)
    np.testing.assert_allclose(
        flat(so3.bracket(xi, zeta)), product.bracket(flat(xi), flat(zeta)), atol=1e-14
    )
    np.testing.assert_allclose(
        flat(so3.ad_star(xi, mu)), product.ad_star(flat(xi), flat(mu)), atol=1e-14
    )
    np.testing.assert_allclose(
        flat(so3.coadjoint_exp(zeta, mu)), product.coadjoint_exp(flat(zeta), flat(mu)), atol=1e-13
    )


def test_structure_constants_broadcast_over_stacks(rng):
    mu, zeta = rng.normal(size=(2, 5, 3))
    stacked = np.asarray(sl2.coadjoint_exp(0.5 * zeta, mu))
    for k in range(5):
        np.testing.assert_allclose(
            stacked[k], sl2.coadjoint_exp(0.5 * zeta[k], mu[k]), rtol=1e-14, atol=1e-14
        )
    # One generator, many states.
    one = np.asarray(sl2.coadjoint_exp(0.5 * zeta[0], mu))
    np.testing.assert_allclose(one[2], sl2.coadjoint_exp(0.5 * zeta[0], mu[2]), atol=1e-14)


# ---------------------------------------------------------------------------------------------
# Bad structure constants
# ---------------------------------------------------------------------------------------------


def test_bad_structure_constants():
    with pytest.raises(ValueError, match="shape"):
        StructureConstants(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="shape"):
        StructureConstants(np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match="shape"):
        StructureConstants(np.zeros((0, 0, 0)))
    bad = np.array(sl2.constants)
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        StructureConstants(bad)
    # Not antisymmetric: [H, E] = 2E but [E, H] = +2E.
    bad = np.array(sl2.constants)
    bad[1, 0, 1] = 2.0
    with pytest.raises(ValueError, match="antisymmetric"):
        StructureConstants(bad)
    # A diagonal entry [e_i, e_i] ≠ 0 is also not antisymmetric.
    bad = np.zeros((2, 2, 2))
    bad[0, 0, 1] = 1.0
    with pytest.raises(ValueError, match="antisymmetric"):
        StructureConstants(bad)
    # Antisymmetric but violating Jacobi: perturb so(3)'s [e_1, e_2] = e_3 into 1.5 e_3 + 0.5 e_1.
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    StructureConstants(eps)  # fine
    bad = eps.copy()
    bad[0, 1, 0], bad[1, 0, 0] = 0.5, -0.5
    with pytest.raises(ValueError, match="Jacobi"):
        StructureConstants(bad)
    # A violation just above the threshold is caught; round-off-sized noise is not.
    tiny = eps.copy()
    tiny[0, 1, 0], tiny[1, 0, 0] = 1e-13, -1e-13
    StructureConstants(tiny)
    with pytest.raises(TypeError, match="casimirs"):
        StructureConstants(eps, casimirs="norm")


def test_se3_class_is_frozen_and_named():
    assert SE3().name == "se(3)"
    assert sl2.name == "sl(2,R)"
    with pytest.raises(AttributeError):
        algebras.sl2.constants = None
    assert not algebras.sl2.constants.flags.writeable


# ---------------------------------------------------------------------------------------------
# Property-based versions (hypothesis, derandomised)
# ---------------------------------------------------------------------------------------------

ELEMENT = st.floats(-5.0, 5.0, allow_nan=False, allow_infinity=False, allow_subnormal=False)
HYPOTHESIS = settings(max_examples=40, deadline=None, derandomize=True)


def triples(n):
    return st.tuples(*(arrays(np.float64, (n,), elements=ELEMENT) for _ in range(3)))


@pytest.mark.parametrize("name", NAMES)
def test_property_adjointness_and_jacobi(name):
    algebra, n = ALGEBRAS[name]

    @HYPOTHESIS
    @given(triples(n))
    def check(triple):
        mu, xi, eta = triple
        scale = 1.0 + norms(mu, xi, eta)
        lhs = float(algebra.pairing(algebra.ad_star(xi, mu), eta))
        rhs = float(algebra.pairing(mu, algebra.bracket(xi, eta)))
        assert abs(lhs - rhs) <= REL * scale
        b = algebra.bracket
        jacobi = b(mu, b(xi, eta)) + b(xi, b(eta, mu)) + b(eta, b(mu, xi))
        np.testing.assert_allclose(jacobi, 0.0, atol=10 * REL * scale)

    check()


@pytest.mark.parametrize("name", NAMES)
def test_property_casimirs_preserved_by_one_move(name):
    algebra, n = ALGEBRAS[name]
    shrink = 0.3 if name == "sl2" else 1.0  # |ζ| ≤ ~2.6 on sl(2): growth ≤ e^{5}

    @HYPOTHESIS
    @given(triples(n))
    def check(triple):
        zeta, mu, _ = triple
        moved = np.asarray(algebra.coadjoint_exp(shrink * zeta, mu))
        scale = 1.0 + np.sum(moved**2) + np.sum(mu**2)
        np.testing.assert_allclose(
            algebra.casimirs(moved), algebra.casimirs(mu), rtol=0, atol=1e-12 * scale
        )

    check()
