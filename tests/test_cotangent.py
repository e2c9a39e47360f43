"""The cotangent-bundle core: one-effect steps on T*G, their composition, the kinetic–magnetic
flow on the Euclidean coordinates of a product space, and its bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from liesample import spaces as S
from liesample.geometry.cotangent import (
    BAOAB,
    LEAPFROG,
    PhasePoint,
    compose,
    cotangent_bundle,
    drift,
    kick,
    make_metric,
    ornstein_uhlenbeck,
)

# A circle, a sphere and two Euclidean blocks (3 coordinates, raveled in leaf order: "a", "z").
SPACE = {"a": S.Euclidean((2,)), "r": S.U1(()), "s": S.Sphere(2), "z": S.Euclidean(())}
FIELD = np.array([[0.0, 1.5, -0.4], [-1.5, 0.0, 0.7], [0.4, -0.7, 0.0]])
DENSE = np.array([[0.6, 0.2], [0.2, 1.4]])
MASS = {"a": DENSE, "r": 0.8, "s": 1.3, "z": 0.5}


def logdensity(x):
    return (
        -0.5 * jnp.sum(x["a"] ** 2) * (1.0 + x["z"] ** 2)
        + 2.0 * x["s"][2] * x["a"][0]
        + jnp.cos(x["r"]) * x["z"]
    )


def start(key):
    position = S.uniform({"r": SPACE["r"], "s": SPACE["s"]}, key)
    return {**position, "a": jnp.array([0.3, -0.8]), "z": jnp.array(0.4)}


def leapfrog_path(bundle, step_size=0.1, steps=20):
    """``(g, p, s) ↦ (g', p')``: ``steps`` leapfrog steps with the field ``s G``."""
    value_and_grad = S.trivialised_value_and_grad(logdensity, SPACE)

    def run(position, momentum, sign):
        flows = {1.0: bundle.kinetic_flow(step_size, sign)}
        effects = {"B": kick(value_and_grad, step_size), "A": drift(bundle, flows)}
        step = compose(LEAPFROG, effects)
        point = PhasePoint(position, momentum, *value_and_grad(position))
        point = jax.lax.fori_loop(0, steps, lambda _, p: step(p), point)
        return point.position, point.momentum

    return jax.jit(run)


def test_magnetic_leapfrog_on_a_product_is_an_involution_with_the_field_reversed():
    """``(g, p, G) ↦ (g', −p', −G)`` twice is the identity; with the same ``G`` it is not."""
    bundle = cotangent_bundle(SPACE, MASS, FIELD)
    assert bundle.euclidean_dimension == 3
    key_x, key_p = jax.random.split(jax.random.key(0))
    x0 = start(key_x)
    p0 = bundle.sample_momentum(key_p, x0)
    path = leapfrog_path(bundle)
    x1, p1 = path(x0, p0, 1.0)
    S.check_position(SPACE, x1)
    assert float(jnp.linalg.norm(x1["a"] - x0["a"])) > 0.1  # it moved
    back, pback = path(x1, jax.tree.map(jnp.negative, p1), -1.0)
    for k in SPACE:
        np.testing.assert_allclose(S._wrap(back[k] - x0[k]) if k == "r" else back[k] - x0[k],
                                   0.0, rtol=0, atol=1e-11, err_msg=k)  # fmt: skip
        np.testing.assert_allclose(-pback[k], p0[k], rtol=0, atol=1e-11, err_msg=k)
    wrong, _ = path(x1, jax.tree.map(jnp.negative, p1), 1.0)
    assert float(jnp.linalg.norm(wrong["a"] - x0["a"])) > 1e-2


def test_kinetic_flow_conserves_kinetic_energy_and_matches_the_linear_ode():
    """The drift with a field and a dense mass: ``K`` conserved on every block; on the
    Euclidean coordinates the flow of ``q̇ = M⁻¹p, ṗ = GM⁻¹p`` (scipy's ``expm``)."""
    bundle = cotangent_bundle(SPACE, MASS, FIELD)
    x0 = start(jax.random.key(1))
    p0 = bundle.sample_momentum(jax.random.key(2), x0)
    x1, p1 = bundle.drift(bundle.kinetic_flow(0.7), x0, p0)
    assert float(bundle.kinetic_energy(p1)) == pytest.approx(float(bundle.kinetic_energy(p0)))
    minv = scipy.linalg.block_diag(DENSE, [[0.5]])
    generator = np.block([[np.zeros((3, 3)), minv], [np.zeros((3, 3)), FIELD @ minv]])
    z0 = np.concatenate([x0["a"], [x0["z"]], p0["a"], [p0["z"]]])
    z1 = scipy.linalg.expm(0.7 * generator) @ z0
    got = np.concatenate([x1["a"], [x1["z"]], p1["a"], [p1["z"]]])
    np.testing.assert_allclose(got, z1, rtol=0, atol=1e-12)


# slow: 2·10⁴ draws of the momentum law; the default suite checks this with the dense-mass
# [adjusted langevin] case of test_geometric_samplers.py::
# test_a_magnetic_field_and_a_dense_mass_on_the_euclidean_block_keep_the_exact_law
@pytest.mark.slow
def test_momentum_law_and_ou_step_keep_n0m():
    """``N(0, M)`` draws and the OU step from it have covariance ``M`` (dense block, sphere)."""
    space = {"a": S.Euclidean((2,)), "s": S.Sphere(2)}
    bundle = cotangent_bundle(space, {"a": DENSE, "s": 0.25})
    x = {"a": jnp.zeros(2), "s": jnp.array([0.0, 0.0, 1.0])}
    keys = jax.random.split(jax.random.key(3), 20000)
    draws = jax.vmap(lambda k: bundle.sample_momentum(k, x))(keys)
    moved = jax.vmap(lambda k, p: bundle.ornstein_uhlenbeck(k, x, p, 1.5, 0.3))(
        jax.random.split(jax.random.key(4), 20000), draws
    )
    for p in (draws, moved):
        cov = np.cov(np.asarray(p["a"]).T)
        mcse = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / 20000)
        assert np.all(np.abs(cov - np.linalg.inv(DENSE)) < 5 * mcse)
        s = np.asarray(p["s"])
        np.testing.assert_allclose(s[:, 2], 0.0, atol=1e-15)  # tangent at the north pole
        var = s[:, :2].var(0)
        assert np.all(np.abs(var - 4.0) < 5 * 4.0 * np.sqrt(2 / 20000))


def test_ornstein_uhlenbeck_step_is_exact_also_without_friction():
    """``p ← e^{−rt}p + s ξ``: ``s² = D(1 − e^{−2rt})/2r``, and ``D t`` at ``r = 0``."""
    one = jnp.ones(3)
    rates = jnp.array([0.0, 1e-12, 2.0])
    out = ornstein_uhlenbeck(one, one, rates, 3.0, 0.5)
    expected = np.exp(-0.5 * np.array([0.0, 1e-12, 2.0])) + np.sqrt(
        [1.5, 1.5, 3.0 * (1 - np.exp(-2.0)) / 4.0]
    )
    np.testing.assert_allclose(out, expected, rtol=1e-12)
    np.testing.assert_allclose(ornstein_uhlenbeck(one, None, 2.0, 3.0, 0.5), np.exp(-1.0) * one)
    # The flat metric's OU step is this one in the eigenbasis of M⁻¹.
    metric = make_metric(jnp.array([0.5, 2.0]))
    p = metric.ornstein_uhlenbeck(jax.random.key(0), jnp.array([1.0, -1.0]), 0.7, 0.4)
    xi = jax.random.normal(jax.random.key(0), (2,))
    np.testing.assert_allclose(
        p, ornstein_uhlenbeck(jnp.array([1.0, -1.0]), xi, 0.7 * jnp.array([0.5, 2.0]), 1.4, 0.4)
    )


def test_compose_runs_the_scheme_and_skips_missing_effects():
    calls = []

    def record(name):
        return lambda point, fraction, key: calls.append((name, fraction, key is None)) or point

    compose(BAOAB, {"B": record("B"), "A": record("A"), "O": record("O")})(0, jax.random.key(0))
    assert calls == [
        ("B", 0.5, True), ("A", 0.5, True), ("O", 1.0, False), ("A", 0.5, True), ("B", 0.5, True)
    ]  # fmt: skip
    calls.clear()
    compose(BAOAB, {"O": record("O"), "B": None})(0, jax.random.key(0))
    assert calls == [("O", 1.0, False)]
    with pytest.raises(ValueError, match="'A', 'B' or 'O'"):
        compose((("C", 1.0),), {})


@pytest.mark.parametrize(
    "space, mass, field, match",
    [
        (S.Sphere(2), None, np.zeros((3, 3)), "has none"),
        (SPACE, None, np.zeros((2, 2)), r"shape \(3, 3\)"),
        (SPACE, None, np.ones((3, 3)), "antisymmetric"),
        (SPACE, None, np.zeros(3), "2-D"),
        (SPACE, {**MASS, "a": np.array([[1.0, 2.0], [2.0, 1.0]])}, None, "positive definite"),
        (SPACE, {**MASS, "a": np.array([[1.0, 0.5], [0.0, 1.0]])}, None, "symmetric"),
        (SPACE, {**MASS, "a": np.ones((3, 3))}, None, r"dense \(n, n\)"),
    ],
)
def test_bad_field_and_mass_raise_clear_errors(space, mass, field, match):
    with pytest.raises(ValueError, match=match):
        cotangent_bundle(space, mass, field)
