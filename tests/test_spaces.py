"""Spaces (liesample.geometry.spaces): validation, Haar draws, exact flows, trivialised gradients;
and the exact references of liesample.targets.groups against independent quadrature."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import liesample
from liesample import spaces as S
from liesample.geometry.cotangent import cotangent_bundle
from liesample.targets.groups import (
    MatrixFisherLaw,
    VonMisesFisherPosterior,
    su2_plaquette_mean,
    u1_plaquette_mean,
    vmf_mean_resultant_length,
)

ALL = [
    S.Euclidean((2, 3)),
    S.U1((4,)),
    S.Sphere(2, shape=(3,)),
    S.Sphere(5),
    S.SO(3, shape=(2,)),
    S.SO(4),
    S.SU(2, shape=(2,)),
    S.SU(3),
]
COMPACT = [s for s in ALL if s.compact]


@jax.jit
def _points_and_momenta(key):
    """A point and a tangent momentum of every space in ALL (one compiled call)."""
    x, p = {}, {}
    for i, s in enumerate(ALL):
        kx, kp = jax.random.split(jax.random.fold_in(key, i))
        x[repr(s)] = s.uniform(kx) if s.compact else jax.random.normal(kx, s.position_array_shape)
        p[repr(s)] = s.project(x[repr(s)], jax.random.normal(kp, s.momentum_array_shape))
    return x, p


def test_flow_is_reversible_and_stays_on_the_manifold():
    space = {repr(s): s for s in ALL}
    x, p = _points_and_momenta(jax.random.key(0))
    S.check_position(space, x)
    m = {k: jnp.full(s.mass_array_shape, 0.7) for k, s in space.items()}

    @jax.jit
    def there_and_back(x, p):
        bundle = cotangent_bundle(space, m)
        flow = bundle.kinetic_flow(1.3)
        y, q = bundle.drift(flow, x, p)
        z, r = bundle.drift(flow, y, jax.tree.map(jnp.negative, q))
        blocks = {k: cotangent_bundle(s, m[k]) for k, s in space.items()}
        energies = [(b.kinetic_energy(p[k]), b.kinetic_energy(q[k])) for k, b in blocks.items()]
        return y, z, r, energies

    y, z, r, energies = there_and_back(x, p)
    S.check_position(space, y)
    for (k, s), (before, after) in zip(space.items(), energies):
        # The kinetic energy is conserved by its own flow; the flow is reversible.
        assert float(after) == pytest.approx(float(before), rel=1e-12), k
        back = S._wrap(z[k] - x[k]) if isinstance(s, S.U1) else z[k] - x[k]
        assert np.max(np.abs(back)) < 1e-12, k
        assert np.max(np.abs(r[k] + p[k])) < 1e-12, k


def test_log_inverts_exp_and_closed_forms_equal_expm():
    x, p = _points_and_momenta(jax.random.key(1))
    with_log = [
        s
        for s in ALL
        if not isinstance(s, (S.SO, S.SU)) or (isinstance(s, S.SO) and s.n == 3) or s.n == 2
    ]

    @jax.jit
    def errors(x, p):
        out = []
        for s in with_log:
            v = 0.4 * p[repr(s)]  # angles well below π
            out.append(jnp.max(jnp.abs(s.log(x[repr(s)], s.exp(x[repr(s)], v)) - v)))
        c = jnp.array([[0.3, -1.2, 0.5], [1e-9, 0.0, -2e-9], [2.0, 2.0, -1.0]])
        for g in (S.SO(3, shape=(3,)), S.SU(2, shape=(3,))):
            out.append(jnp.max(jnp.abs(g.exponential(c) - jax.scipy.linalg.expm(g.hat(c)))))
        # The SO(3) coordinates are the angular velocity: hat(ω) v = ω × v.
        v = jnp.array([0.1, 0.7, -0.4])
        out.append(jnp.max(jnp.abs(S.SO(3).hat(c[0]) @ v - jnp.cross(c[0], v))))
        return jnp.stack(out)

    assert np.all(np.asarray(errors(x, p)) < 1e-13)


@pytest.mark.parametrize("space", [S.SO(3), S.SO(4), S.SU(2), S.SU(3)], ids=repr)
def test_algebra_basis_is_orthonormal(space):
    b = jnp.asarray(space.basis)
    gram = 0.5 * jnp.real(jnp.einsum("aij,bij->ab", jnp.conj(b), b))
    assert np.allclose(gram, np.eye(space.copy_dimension), atol=1e-15)
    assert np.allclose(b + jnp.conj(jnp.swapaxes(b, -1, -2)), 0.0)  # anti-Hermitian
    assert np.allclose(jnp.trace(b, axis1=-2, axis2=-1), 0.0)


def test_trivialised_gradient_is_the_derivative_along_the_exponential():
    key = jax.random.key(2)
    space = {"R": S.SO(3), "U": S.SU(2), "x": S.Sphere(3), "t": S.U1((2,)), "y": S.Euclidean(())}
    A = jnp.array([[1.0, 2.0, 3.0], [0.0, 1.0, 0.0], [2.0, 0.0, 5.0]])
    B = jnp.array([[1.0, 2.0j], [0.5, -1.0j]])

    def logdensity(p):
        return (
            jnp.sum(A * p["R"])
            + jnp.real(jnp.trace(B @ p["U"])) * jnp.cos(p["t"][0])
            + jnp.sum(jnp.arange(1.0, 5.0) * p["x"]) ** 2
            + jnp.sin(p["t"][1]) * p["y"] ** 2
        )

    @jax.jit
    def compare(key):
        position = S.uniform({k: v for k, v in space.items() if k != "y"}, key)
        position["y"] = jnp.asarray(0.7)
        value, grad = S.trivialised_value_and_grad(logdensity, space)(position)
        out = [value - logdensity(position), jnp.dot(grad["x"], position["x"])]  # tangent
        for name, s in space.items():

            def derivative(direction, name=name, s=s):
                d = s.project(position[name], direction)

                def along(t):  # the curve t ↦ x exp(t d) (geodesic on the sphere)
                    return logdensity({**position, name: s.exp(position[name], t * d)})

                return jnp.sum(grad[name] * d) - jax.jvp(along, (0.0,), (1.0,))[1]

            size = int(np.prod(s.momentum_array_shape))
            basis = jnp.eye(size).reshape(-1, *s.momentum_array_shape)
            out.append(jnp.max(jnp.abs(jax.vmap(derivative)(basis))))
        return jnp.stack(out)

    assert np.all(np.abs(np.asarray(compare(key))) < 1e-12)


def test_haar_draws_have_the_haar_moments():
    """E[R] = 0 and E[R_ij²] = 1/n on SO(n); E[|tr U|²] = 1 on SU(n); E[x] = 0, E[xxᵀ] = I/d."""
    n = 5000
    space = (S.SO(3, shape=(n,)), S.SU(3, shape=(n,)), S.Sphere(4, shape=(n,)), S.U1((n,)))
    R, U, X, T = map(np.asarray, jax.jit(lambda k: S.uniform(space, k))(jax.random.key(3)))
    for values, exact in [
        (R.reshape(n, -1), 0.0),
        (R.reshape(n, -1) ** 2, 1.0 / 3.0),
        (np.abs(np.trace(U, axis1=1, axis2=2)) ** 2, 1.0),
        (X, 0.0),
        (X**2, 1.0 / 5.0),
        (np.cos(T), 0.0),
    ]:
        se = values.std(0) / np.sqrt(n)
        assert np.all(np.abs(values.mean(0) - exact) < 5 * se)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(np.linalg.det(U), 1.0)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "space, bad, match",
    [
        (S.Sphere(2), jnp.array([1.0, 1e-6, 0.0]), "off Sphere"),
        (S.Sphere(2), jnp.array([1.0, 0.0]), "shape"),
        (S.SO(3), 1.001 * jnp.eye(3), "off SO"),
        (S.SO(3), jnp.diag(jnp.array([1.0, 1.0, -1.0])), "det R = 1"),
        (S.SU(2), jnp.eye(2), "complex"),
        (S.SU(2), jnp.diag(jnp.array([1j, 1j])), "off SU"),
        (S.U1((2,)), jnp.array([0.0, jnp.nan]), "finite"),
        (S.Euclidean(()), jnp.array(1), "real floating"),
    ],
)
def test_points_off_the_space_are_refused_not_projected(space, bad, match):
    with pytest.raises((ValueError, TypeError), match=match):
        space.check(bad)


def test_constructor_and_structure_errors():
    with pytest.raises(ValueError, match="integer >= 1"):
        S.Sphere(0)
    with pytest.raises(ValueError, match="integer >= 2"):
        S.SO(1)
    with pytest.raises(TypeError, match="non-negative ints"):
        S.U1("a")
    with pytest.raises(ValueError, match="no uniform"):
        S.Euclidean(()).uniform(jax.random.key(0))
    space = {"a": S.Sphere(2), "b": S.U1(())}
    with pytest.raises(ValueError, match="structure"):
        S.check_position(space, {"a": jnp.array([0.0, 0.0, 1.0])})
    with pytest.raises(ValueError, match=r"position\['a'\] is off"):
        S.check_position(space, {"a": jnp.array([0.0, 0.0, 2.0]), "b": jnp.array(0.0)})
    with pytest.raises(ValueError, match="broadcast"):
        S.check_inverse_mass(space, {"a": jnp.ones(3), "b": 1.0})
    with pytest.raises(ValueError, match="> 0"):
        S.check_inverse_mass(space, -1.0)
    with pytest.raises(TypeError, match="Space"):
        S.dimension({"a": 3})
    assert S.dimension({"a": S.SO(3, shape=(2,)), "b": S.Sphere(5), "c": S.SU(3)}) == 6 + 5 + 8


def test_sampler_init_refuses_bad_starts():
    space = S.Sphere(2)
    sampler = liesample.geometric_hmc(lambda x: x[2], space, 0.1, 3)
    with pytest.raises(ValueError, match="off Sphere"):
        sampler.init(jnp.array([1.0, 0.1, 0.0]))
    starts = jnp.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.1]])
    with pytest.raises(ValueError, match=r"initial_positions\[2\] is off Sphere"):
        sampler.check_positions(starts)  # the runner's hook
    assert sampler.settings["sampler"] == "geometric_hmc"
    bad = liesample.geometric_hmc(lambda x: jnp.log(x[2]), space, 0.1, 3)
    with pytest.raises(ValueError, match="not finite"):
        bad.init(jnp.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="step_size"):
        liesample.geometric_hmc(lambda x: x[2], space, -0.1, 3)
    with pytest.raises(ValueError, match="num_integration_steps"):
        liesample.geometric_hmc(lambda x: x[2], space, 0.1, 0)
    with pytest.raises(ValueError, match="friction"):
        liesample.geometric_langevin(lambda x: x[2], space, 0.1, -1.0)


# --------------------------------------------------------------------------- exact references


def test_vmf_mean_resultant_length_matches_quadrature():
    def weight(t, d, kappa):  # the law of t = x·μ on S^{d-1}, unnormalised
        return (1 - t * t) ** ((d - 3) / 2) * np.exp(kappa * (t - 1))

    for d, kappa in [(3, 4.0), (6, 10.0), (3, 0.3)]:
        opts = {"args": (d, kappa), "epsabs": 0.0, "epsrel": 1e-13}
        num = integrate.quad(lambda t, *args: t * weight(t, *args), -1, 1, **opts)[0]
        num /= integrate.quad(weight, -1, 1, **opts)[0]
        assert vmf_mean_resultant_length(kappa, d) == pytest.approx(num, rel=1e-10)
    assert vmf_mean_resultant_length(4.0, 3) == pytest.approx(1 / np.tanh(4.0) - 0.25)


def test_plaquette_references_match_quadrature_over_the_class_angle():
    beta = 1.7
    u1 = integrate.quad(lambda a: np.cos(a) * np.exp(beta * np.cos(a)), 0, np.pi)[0]
    u1 /= integrate.quad(lambda a: np.exp(beta * np.cos(a)), 0, np.pi)[0]
    assert u1_plaquette_mean(beta) == pytest.approx(u1, rel=1e-10)
    w = lambda a: np.sin(a) ** 2 * np.exp(beta * np.cos(a))
    su2 = integrate.quad(lambda a: np.cos(a) * w(a), 0, np.pi)[0] / integrate.quad(w, 0, np.pi)[0]
    assert su2_plaquette_mean(beta) == pytest.approx(su2, rel=1e-10)


def test_matrix_fisher_reference():
    # F = κ e3 e3ᵀ: R e3 is vMF(e3, κ) on S², so E[R33] = A_3(κ).
    assert MatrixFisherLaw(np.diag([0.0, 0.0, 2.5])).mean()[2, 2] == pytest.approx(
        vmf_mean_resultant_length(2.5, 3), rel=1e-10
    )
    assert MatrixFisherLaw(np.zeros((3, 3))).log_normalizer() == pytest.approx(0.0, abs=1e-14)
    # Against Haar draws (importance weights), for a diagonal and a general F (with det < 0).
    n = 100000
    R = np.asarray(S.SO(3, shape=(n,)).uniform(jax.random.key(4)))
    rng = np.random.default_rng(0)
    for F in (np.diag([2.0, 1.0, -0.5]), rng.normal(size=(3, 3))):
        law = MatrixFisherLaw(F)
        w = np.exp(np.einsum("ij,nij->n", F, R))
        z, se_z = w.mean(), w.std() / np.sqrt(n)
        assert abs(np.exp(law.log_normalizer()) - z) < 5 * se_z
        ratio = (w[:, None, None] * R).mean(0) / z  # delta-method MCSE of a ratio estimator
        resid = w[:, None, None] * (R - ratio) / z
        assert np.all(np.abs(law.mean() - ratio) < 5 * resid.std(0) / np.sqrt(n) + 1e-12)
    u, s, v = MatrixFisherLaw(np.diag([2.0, 1.0, -0.5])).proper_svd()
    assert np.allclose(u @ np.diag(s) @ v.T, np.diag([2.0, 1.0, -0.5]))
    assert np.linalg.det(u) > 0 and np.linalg.det(v) > 0 and s[2] < 0


def test_vmf_posterior_reference_integrates_the_direction_out():
    data = np.array([[0.0, 0.6, 0.8], [0.0, 0.8, 0.6], [0.6, 0.0, 0.8]])
    post = VonMisesFisherPosterior(data, prior_mean=0.5, prior_sd=0.7)
    exact = post.expectations()
    # Brute force: a product rule over (η, θ, φ), μ = (sin θ cos φ, sin θ sin φ, cos θ).
    eta = np.linspace(0.5 - 7 * 0.7, 0.5 + 7 * 0.7, 161)
    theta = np.linspace(0, np.pi, 301)
    phi = np.linspace(0, 2 * np.pi, 96, endpoint=False)  # periodic: the plain sum is spectral
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    mu = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    logdensity = jax.vmap(lambda e: post.logdensity({"direction": mu, "log_kappa": e}))
    logp = np.asarray(logdensity(jnp.asarray(eta)))  # (η, θ, φ)
    w = np.exp(logp - logp.max()) * np.sin(th)

    def integral(f):
        return integrate.trapezoid(integrate.trapezoid(f.sum(-1), theta, axis=1), eta)

    z = integral(w)
    assert exact["log_kappa"] == pytest.approx(integral(w * eta[:, None, None]) / z, abs=1e-4)
    mean_mu = [integral(w * mu[..., k]) / z for k in range(3)]
    assert np.allclose(exact["direction"], mean_mu, atol=1e-4)
