"""liesample.interop.numpyro_distributions: the Bingham distribution (exact normaliser and draws),
vMF at κ = 0, and every parameter traced (jit, a latent concentration in a model)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import i0e
from scipy.stats import gamma, vonmises_fisher

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.distributions import constraints
from numpyro.handlers import seed, trace
from numpyro.infer.util import log_density

from liesample.geometry.spaces import SO, Sphere
from liesample.interop.numpyro_distributions import (
    Bingham,
    MatrixFisher,
    VonMisesFisher,
)
from liesample.targets.groups import MatrixFisherLaw
from liesample.targets.orbits import bingham_second_moments

LAM = np.array([0.5, 3.0, -1.0])
ORIENTATION = np.asarray(SO(3).uniform(jax.random.key(4)))


def test_bingham_log_prob_is_normalised_and_rotates_with_its_axes():
    law = Bingham(LAM, ORIENTATION)
    assert law.support is constraints.sphere is VonMisesFisher.support
    x = np.asarray(Sphere(2, shape=(40000,)).uniform(jax.random.key(0)))
    density = 4.0 * np.pi * np.exp(np.asarray(law.log_prob(x)))  # E_uniform[p / (1/4π)] = 1
    assert abs(density.mean() - 1.0) < 5.0 * density.std() / np.sqrt(len(density))
    # In the frame of its axes it is the axis-aligned law.
    aligned = Bingham(LAM)
    assert np.allclose(law.log_prob(x[:5] @ ORIENTATION.T), aligned.log_prob(x[:5]), atol=1e-12)
    second = np.asarray(law.second_moment())
    exact = ORIENTATION @ np.diag(np.asarray(bingham_second_moments(LAM))) @ ORIENTATION.T
    assert np.allclose(second, exact, atol=1e-12) and np.trace(second) == pytest.approx(1.0)


def test_bingham_draws_have_the_exact_second_moments():
    law = Bingham(np.stack([LAM, np.zeros(3)]), ORIENTATION)  # batch of 2: the second uniform
    # One compiled program: drawn eagerly, the sampler's loop costs a compile per operation.
    x = np.asarray(jax.jit(lambda key: law.sample(key, (4000,)))(jax.random.key(1)))
    assert x.shape == (4000, 2, 3) and np.allclose(np.linalg.norm(x, axis=-1), 1.0)
    exact = np.asarray(law.second_moment())
    assert np.allclose(exact[1], np.eye(3) / 3.0, atol=1e-12)
    for b in range(2):
        outer = x[:, b, :, None] * x[:, b, None, :]
        se = outer.std(0) / np.sqrt(len(x))
        assert np.all(np.abs(outer.mean(0) - exact[b]) < 5.0 * se), b


def test_bingham_bad_parameters_are_refused():
    with pytest.raises(ValueError, match=r"concentration must have shape \(\.\.\., 3\)"):
        Bingham(np.zeros(4))
    with pytest.raises(ValueError, match=r"orientation must be a rotation matrix of shape"):
        Bingham(LAM, np.eye(2))


def test_vmf_at_zero_concentration_is_the_uniform_law():
    mu = jnp.array([0.0, 0.0, 1.0])
    x = jnp.array([[0.6, 0.8, 0.0], [0.0, 0.0, -1.0]])
    assert np.allclose(VonMisesFisher(mu, 0.0).log_prob(x), -np.log(4.0 * np.pi), rtol=1e-14)
    grad = jax.jit(jax.grad(lambda k: VonMisesFisher(mu, k).log_prob(x[1])))(0.0)
    assert np.isfinite(grad)
    d6 = jnp.zeros(6).at[0].set(1.0)  # |S⁵| = π³
    assert float(VonMisesFisher(d6, 0.0).log_prob(d6)) == pytest.approx(-3 * np.log(np.pi))
    sample = jax.jit(lambda key: VonMisesFisher(mu, 0.0).sample(key, (4000,)))  # one compile
    draws = np.asarray(sample(jax.random.key(2)))
    assert np.all(np.abs(draws.mean(0)) < 5.0 / np.sqrt(3.0 * len(draws)))


# ------------------------------------------------------------------ traced parameters


ROTATIONS = np.asarray(SO(3, shape=(5,)).uniform(jax.random.key(5)))


def _proper_F(singular_values, rng_seed=0):
    q, p = np.linalg.qr(np.random.default_rng(rng_seed).standard_normal((2, 3, 3)))[0]
    q, p = q * np.sign(np.linalg.det(q)), p * np.sign(np.linalg.det(p))
    return q @ np.diag(singular_values) @ p.T


def test_parameters_may_be_traced_under_jit_and_match_the_references():
    """MatrixFisher's JAX normaliser (SVD + tanh-sinh rule) against SciPy's quadrature; its
    gradient in F is E[R], also for the repeated singular values of F = κI; Bingham and vMF under
    jit equal their eager values."""
    log_prob = jax.jit(lambda F: MatrixFisher(F).log_prob(ROTATIONS))
    grad = jax.jit(jax.grad(lambda F: MatrixFisher(F).log_normalizer()))
    for F in (_proper_F([30.0, 20.0, -5.0]), _proper_F([2.0, 1.0, -0.5], 1), 3.0 * np.eye(3),
              np.zeros((3, 3))):  # fmt: skip
        reference = MatrixFisherLaw(F)
        expected = np.sum(F * ROTATIONS, axis=(1, 2)) - reference.log_normalizer()
        assert np.allclose(log_prob(F), expected, rtol=1e-12, atol=1e-12)
        assert np.allclose(grad(F), reference.mean(), atol=1e-12)
        assert np.allclose(MatrixFisher(F).mean, reference.mean(), atol=1e-12)
    x = np.asarray(Sphere(2, shape=(5,)).uniform(jax.random.key(6)))
    bingham = jax.jit(lambda lam, frame: Bingham(lam, frame).log_prob(x))
    assert np.allclose(bingham(LAM, ORIENTATION), Bingham(LAM, ORIENTATION).log_prob(x), rtol=1e-13)
    vmf = jax.jit(lambda mu, kappa: VonMisesFisher(mu, kappa).log_prob(x))
    mu = np.array([0.0, 0.6, 0.8])
    assert np.allclose(vmf(mu, 3.0), vonmises_fisher(mu, 3.0).logpdf(x), rtol=1e-13)


def _matrix_fisher_laplace(s):
    """log c(F) − Σ s as s → ∞ (Laplace at the mode): −log 8π² + (3/2) log 2π −
    ½ Σ_{i<j} log(s_i + s_j), with an O(1/s) error."""
    pairs = [s[0] + s[1], s[0] + s[2], s[1] + s[2]]
    return 1.5 * np.log(2 * np.pi) - np.log(8 * np.pi**2) - 0.5 * sum(np.log(p) for p in pairs)


def test_vmf_log_prob_is_right_for_any_concentration():
    """Against SciPy where it is exact, and against the closed forms at κ = 1e100…1e300, where
    log C ≈ −κ and κ μ·x ≈ κ once cancelled to 0 (issue 43): on S², C = κ/(4π sinh κ); on S⁴,
    I_{3/2}(κ) e^{−κ} = (1 − 1/κ)/√(2πκ) up to e^{−2κ}."""
    for d in (3, 5):
        mu = np.eye(d)[-1]
        x = np.stack([mu, np.eye(d)[0], np.full(d, 1 / np.sqrt(d))])
        for kappa in (0.5, 30.0, 700.0):
            expected = vonmises_fisher(mu, kappa).logpdf(x)
            assert np.allclose(VonMisesFisher(mu, kappa).log_prob(x), expected, rtol=1e-12), d
        for kappa in (1e100, 1e200, 1e300):
            law = VonMisesFisher(mu, kappa)
            if d == 3:
                at_mode = np.log(kappa) - np.log(2 * np.pi)
            else:
                at_mode = 2 * np.log(kappa) - 2.5 * np.log(2 * np.pi) + 0.5 * np.log(2 * np.pi)
            assert float(law.log_prob(mu)) == pytest.approx(at_mode, rel=1e-14), (d, kappa)
            assert float(law.log_prob(x[1])) == pytest.approx(at_mode - kappa, rel=1e-14)
            assert float(law.log_normalizer()) == pytest.approx(at_mode - kappa, rel=1e-14)


def test_matrix_fisher_log_prob_is_right_for_large_F():
    """log c against SciPy's quadrature of its 1-D integral at moderate F, and the Laplace limit
    where its O(1/s) error is round-off: log_prob at the mode was 0.0 at F = 1e100 I (issue 43)."""
    s = np.array([3.0, 2.0, -1.0])
    for scale in (1.0, 1e3):
        t = s * scale

        def reduced(w, t=t):  # c e^{−Σs}, w = 1 − u, every factor <= 1
            return (i0e(0.5 * (t[0] - t[1]) * w) * i0e(0.5 * (t[0] + t[1]) * (2 - w))
                    * np.exp(-(t[1] + t[2]) * w))  # fmt: skip

        expected = t.sum() + np.log(0.5 * quad(reduced, 0, 2, epsabs=0, epsrel=1e-13, limit=200)[0])
        F = _proper_F(t)
        assert float(MatrixFisher(F).log_normalizer()) == pytest.approx(expected, rel=1e-13)
    for scale in (1e15, 1e100, 1e300):
        F = np.diag(s * scale)  # the mode is I: tr(FᵀI) and Σ s agree to the last bit
        expected = -_matrix_fisher_laplace(s * scale)
        assert float(MatrixFisher(F).log_prob(np.eye(3))) == pytest.approx(expected, abs=1e-12)
    kappa = 1e100  # F = κ I: c ≈ e^{3κ} / (8 √π κ^{3/2})
    expected = np.log(8 * np.sqrt(np.pi)) + 1.5 * np.log(kappa)
    assert float(MatrixFisher(kappa * np.eye(3)).log_prob(np.eye(3))) == pytest.approx(expected)


def test_a_latent_concentration_inside_a_model():
    """``MatrixFisher(κ I)`` and ``MatrixFisher(0)`` with ``κ`` a latent site, and a vMF whose
    parameters are computed in the model: NumPyro's joint log-density under jit is the exact one;
    prior draws under jit are rotations."""

    def model():
        kappa = numpyro.sample("kappa", dist.Gamma(2.0, 0.5))
        R = numpyro.sample("R", MatrixFisher(kappa * jnp.eye(3)))
        numpyro.sample("Q", MatrixFisher(jnp.zeros((3, 3))))
        numpyro.sample("x", VonMisesFisher(R[:, 2], 1.0 + kappa), obs=jnp.array([0.0, 0.6, 0.8]))

    params = {"kappa": 2.5, "R": ROTATIONS[0], "Q": ROTATIONS[1]}
    joint = jax.jit(lambda p: log_density(model, (), {}, p)[0])(params)
    mu, kappa = ROTATIONS[0][:, 2], 2.5
    expected = (
        gamma.logpdf(kappa, 2.0, scale=2.0)
        + kappa * np.trace(ROTATIONS[0]) - MatrixFisherLaw(kappa * np.eye(3)).log_normalizer()
        + vonmises_fisher(mu, 1.0 + kappa).logpdf(np.array([0.0, 0.6, 0.8]))
    )  # fmt: skip
    assert float(joint) == pytest.approx(expected, rel=1e-12)
    draw = jax.jit(lambda key: trace(seed(model, key)).get_trace()["R"]["value"])
    R = np.asarray(draw(jax.random.key(0)))
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.slow  # traced parameters under jit run by default
def test_matrix_fisher_draws_for_a_traced_or_batched_F_are_exact():
    F = _proper_F([3.0, 1.0, -0.5], 2)
    draws = jax.jit(lambda F, key: MatrixFisher(F).sample(key, (4000,)))(F, jax.random.key(3))
    R = np.asarray(draws)
    assert np.allclose(np.swapaxes(R, 1, 2) @ R, np.eye(3), atol=1e-12)
    exact = MatrixFisherLaw(F).mean()
    assert np.all(np.abs(R.mean(0) - exact) < 5 * R.std(0) / np.sqrt(len(R)) + 1e-12)
    batch = MatrixFisher(np.stack([F, np.zeros((3, 3))]))
    assert batch.batch_shape == (2,) and batch.log_normalizer().shape == (2,)
    assert batch.sample(jax.random.key(4), (7,)).shape == (7, 2, 3, 3)


def test_concrete_parameters_are_still_checked():
    with pytest.raises(ValueError, match="F must be finite"):
        MatrixFisher(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match=r"F must be a finite 3x3 matrix"):
        MatrixFisher(np.eye(2))
    with pytest.raises(ValueError, match="concentration must be >= 0"):
        VonMisesFisher(np.array([0.0, 0.0, 1.0]), -1.0)
    with pytest.raises(ValueError, match="mean_direction must be a unit vector"):
        VonMisesFisher(np.array([0.0, 0.0, 2.0]), 1.0)
    with pytest.raises(ValueError, match="concentration must be finite"):
        Bingham(np.array([0.0, np.inf, 1.0]))
    with pytest.raises(ValueError, match="orientation must be a rotation matrix"):
        Bingham(LAM, 2.0 * np.eye(3))


# --- validate_args and infer_shapes (NumPyro's conventions) ---------------------------------------

LAWS = {
    "vmf": lambda **kw: VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 2.0, **kw),
    "vmf_s4": lambda **kw: VonMisesFisher(jnp.eye(5)[0], 1.5, **kw),
    "bingham": lambda **kw: Bingham(LAM, ORIENTATION, **kw),
    "matrix_fisher": lambda **kw: MatrixFisher(jnp.diag(jnp.array([2.0, 1.0, -0.5])), **kw),
}
OFF_SUPPORT = {
    "vmf": jnp.ones(3),
    "vmf_s4": jnp.ones(5),
    "bingham": jnp.ones(3),
    "matrix_fisher": 2.0 * jnp.eye(3),
}


@pytest.mark.parametrize("name", LAWS)
def test_validate_args_warns_off_the_support_as_projected_normal_does(name, recwarn):
    value = OFF_SUPPORT[name]
    formula = LAWS[name](validate_args=False).log_prob(value)
    assert not [w for w in recwarn if "Out-of-support" in str(w.message)]
    with pytest.warns(UserWarning, match="Out-of-support values"):
        checked = LAWS[name](validate_args=True).log_prob(value)
    assert checked == formula  # a warning, not a changed density (round-off must not be -inf)
    with pytest.warns(UserWarning, match="Out-of-support values"):  # NumPyro's own, the same
        dist.ProjectedNormal(jnp.ones(3), validate_args=True).log_prob(jnp.ones(3))


@pytest.mark.parametrize("name", LAWS)
def test_validate_args_accepts_the_laws_own_draws(name, recwarn):
    law = LAWS[name](validate_args=True)
    draws = jax.jit(lambda key: law.sample(key, (5,)))(jax.random.key(3))  # one compile
    assert np.all(np.isfinite(law.log_prob(draws)))
    assert not [w for w in recwarn if "Out-of-support" in str(w.message)]


@pytest.mark.parametrize("name", LAWS)
def test_validate_args_refuses_a_value_of_the_wrong_event_shape(name):
    law = LAWS[name](validate_args=True)
    with pytest.raises(ValueError, match=r"value must have the event shape"):
        law.log_prob(jnp.ones(4))


@pytest.mark.parametrize(
    "cls, shapes",
    [
        (VonMisesFisher, {"mean_direction": (4,), "concentration": ()}),
        (VonMisesFisher, {"mean_direction": (2, 1, 3), "concentration": (5,)}),
        (Bingham, {"concentration": (3,)}),
        (Bingham, {"concentration": (2, 3), "orientation": (4, 1, 3, 3)}),
        (MatrixFisher, {"F": (3, 3)}),
        (MatrixFisher, {"F": (6, 2, 3, 3)}),
    ],
)
def test_infer_shapes_agrees_with_the_constructed_law(cls, shapes):
    arguments = {
        "mean_direction": lambda shape: jnp.broadcast_to(jnp.eye(shape[-1])[0], shape),
        "concentration": lambda shape: jnp.ones(shape),
        "orientation": lambda shape: jnp.broadcast_to(jnp.eye(3), shape),
        "F": lambda shape: jnp.ones(shape),
    }
    law = cls(**{name: arguments[name](shape) for name, shape in shapes.items()})
    assert cls.infer_shapes(**shapes) == (law.batch_shape, law.event_shape)
    assert cls.infer_shapes(*shapes.values()) == (law.batch_shape, law.event_shape)
