"""Directional posteriors for ``benchmarks/posteriordb.py``, each with an exact or quadrature
reference, in the layout of :class:`benchmarks.posteriordb_models.Posterior`.

Each posterior has two NumPyro models with one law of the reported quantities:

- ``model``: the manifold sites themselves (``VonMisesFisher`` with concentration 0 is the
  uniform law on a sphere, ``MatrixFisher`` with ``F = 0`` the Haar law on SO(3), ``VonMises``
  a circle site), which :class:`liesample.numpyro_mcmc.GeometricHMC` moves on the manifold;
- ``nuts_model``: what a NumPyro user writes for NUTS, each unit vector ``u = z / |z|`` with
  ``z ~ Normal(0, I)`` (a rotation: the unit quaternion ``q = z / |z|``, ``z ∈ R⁴``, mapped to
  its rotation). This is exact: ``z / |z|`` is uniform on the sphere and independent of
  ``|z|``, whose law (a chi law) the likelihood does not touch, so the posterior of ``u`` is the
  posterior of the manifold site; a unit quaternion uniform on S³ gives a Haar rotation.

The data are simulated with fixed seeds (no installed package ships directional data sets).
The posteriors and their references:

- :data:`VMF_SPHERE`: ``mu`` uniform on S¹⁹, ``kappa ~ LogNormal(2, 1)``, 50 points
  ``x_i ~ vMF(mu, kappa)``. Given ``kappa``, ``mu ~ vMF(S/|S|, kappa |S|)`` (``S = Σ x_i``) and
  the marginal of ``kappa`` is ``∝ prior(kappa) C(kappa)^N / C(kappa |S|)`` with
  ``C(k) = k^(d/2−1) / ((2π)^(d/2) I_(d/2−1)(k))``; the moments are quadratures over
  ``log kappa`` of the vMF moments ``E[mu] = A m``, ``E[mu muᵀ] = (A/k) I + (1 − d A/k) m mᵀ``,
  ``A = I_(d/2)(k) / I_(d/2−1)(k)`` (Mardia & Jupp 2000, *Directional Statistics*, Wiley, §9.3).
- :data:`AXIAL_BIMODAL`: ``mu`` uniform on S², a Watson likelihood of fixed concentration
  ``κ_W`` for 12 axes: ``log p = κ_W Σ (mu·x_i)²`` + const. The posterior is the Bingham law
  ``∝ exp(muᵀ A mu)``, ``A = κ_W Σ x_i x_iᵀ``, with two antipodal modes: mean 0 and exact second
  moments (:meth:`liesample.numpyro.Bingham.second_moment`).
- :data:`CIRCULAR_REGRESSION`: ``alpha ~ VonMises(0, 0.5)`` (a circle site), ``beta ~
  Normal(0, 1)``, ``kappa ~ LogNormal(1, 1)``, ``y_i ~ VonMises(alpha + 2 atan(beta x_i),
  kappa)`` (Fisher & Lee 1992, *Biometrics* 48, 665–677), 40 points; reported ``cos alpha``,
  ``sin alpha``, ``beta``, ``kappa``. Reference: a tensor-product quadrature (periodic
  trapezoid in ``alpha``, trapezoid in ``beta`` and ``log kappa`` over the posterior's bulk),
  its error checked by halving the grid (:func:`circular_regression_reference`).
- :data:`ROTATION_AVERAGING`: ``M`` Haar on SO(3), ``kappa ~ LogNormal(1, 1)``, 15 rotations
  ``R_i ~ MatrixFisher(kappa M)``. Given ``kappa``, ``M ~ MatrixFisher(kappa S)``
  (``S = Σ R_i``), and the marginal of ``kappa`` is ``∝ prior(kappa) c(kappa S) / c(kappa I)^N``
  (``c`` the matrix Fisher normaliser); ``E[M]`` and the moments of ``kappa`` by quadrature over
  ``log kappa``, the sds of ``M``'s entries from exact i.i.d. draws (``kappa`` by inverting the
  quadrature's distribution function, then ``M`` by
  :meth:`liesample.numpyro.MatrixFisher.sample`).

:func:`load` returns a :class:`DirectionalPosterior`; references are computed on the first
call (a few seconds) and kept for the process (:func:`functools.cache`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
from scipy import special
from scipy.stats import vonmises_fisher

from benchmarks import posteriordb_models as pdb
from liesample.numpyro import Bingham, MatrixFisher, VonMisesFisher
from liesample.targets.groups import quaternion_to_rotation

VMF_SPHERE = "vmf_sphere-s19_latent_kappa"
AXIAL_BIMODAL = "watson_axis-s2_bimodal"
CIRCULAR_REGRESSION = "circular_regression-von_mises"
ROTATION_AVERAGING = "rotation_averaging-so3_latent_kappa"
NAMES = (VMF_SPHERE, AXIAL_BIMODAL, CIRCULAR_REGRESSION, ROTATION_AVERAGING)

VMF_DIMENSION = 20  # S¹⁹ in R²⁰
VMF_NUM_DATA = 50
VMF_PRIOR = (2.0, 1.0)  # kappa ~ LogNormal(2, 1)
WATSON_CONCENTRATION = 0.5
CIRCULAR_PRIOR = (0.5, (1.0, 1.0))  # alpha ~ VonMises(0, 0.5), kappa ~ LogNormal(1, 1)
ROTATION_PRIOR = (1.0, 1.0)  # kappa ~ LogNormal(1, 1)
ROTATION_NUM_DRAWS = 100_000  # i.i.d. draws for the sds of M's entries


@dataclass
class DirectionalPosterior(pdb.Posterior):
    """A :class:`benchmarks.posteriordb_models.Posterior` with the NUTS parametrisation."""

    nuts_model: Callable | None = None


def unit(z):
    """``z / |z|`` along the last axis."""
    return z / jnp.linalg.norm(z, axis=-1, keepdims=True)


def gaussian_direction(name, dimension):
    """A unit vector as NumPyro users write it for NUTS: ``z / |z|``, ``z ~ Normal(0, I)``."""
    z = numpyro.sample(f"{name}_z", dist.Normal(0.0, 1.0).expand([dimension]).to_event(1))
    return unit(z)


# --------------------------------------------------------------------------- vMF on S¹⁹


def vmf_model(data):
    """``mu`` uniform on the sphere, ``kappa ~ LogNormal``, ``x_i ~ vMF(mu, kappa)``."""
    x = data["x"]
    mu = numpyro.sample("mu", VonMisesFisher(jnp.eye(x.shape[1], dtype=x.dtype)[0], 0.0))
    vmf_likelihood(mu, x)


def vmf_nuts_model(data):
    x = data["x"]
    mu = numpyro.deterministic("mu", gaussian_direction("mu", x.shape[1]))
    vmf_likelihood(mu, x)


def vmf_likelihood(mu, x):
    kappa = numpyro.sample("kappa", dist.LogNormal(*VMF_PRIOR))
    with numpyro.plate("data", x.shape[0]):
        numpyro.sample("x", VonMisesFisher(mu, kappa), obs=x)


def log_vmf_normaliser(kappa, d):
    """``log C_d(κ)``, the vMF density's normaliser w.r.t. area on S^(d−1)."""
    order = d / 2 - 1
    return (
        order * np.log(kappa)
        - d / 2 * np.log(2 * np.pi)
        - (np.log(special.ive(order, kappa)) + kappa)
    )


def log_kappa_grid(log_density, centre, half_width=12.0, points=40001):
    """A grid over ``log κ`` covering the bulk of ``log_density`` (values below the maximum
    by more than 45 dropped, the rest refined), and its normalised weights."""
    grid = np.linspace(centre - half_width, centre + half_width, points)
    logp = log_density(grid)
    keep = grid[logp > logp.max() - 45.0]
    grid = np.linspace(keep.min(), keep.max(), points)
    logp = log_density(grid)
    w = np.exp(logp - logp.max())
    w[[0, -1]] *= 0.5  # trapezoid
    return grid, w / w.sum()


def vmf_data():
    d = VMF_DIMENSION
    direction = np.ones(d) / np.sqrt(d)
    x = vonmises_fisher(direction, 10.0).rvs(VMF_NUM_DATA, random_state=np.random.default_rng(7))
    return {"x": x}


def vmf_kappa_law(x):
    """``(log κ grid, weights, m = S/|S|, |S|)`` of the exact posterior."""
    n, d = x.shape
    s = x.sum(0)
    r = np.linalg.norm(s)
    loc, scale = VMF_PRIOR

    def log_density(eta):  # w.r.t. d eta, eta = log kappa
        kappa = np.exp(eta)
        prior = -0.5 * ((eta - loc) / scale) ** 2
        return prior + n * log_vmf_normaliser(kappa, d) - log_vmf_normaliser(kappa * r, d)

    grid, w = log_kappa_grid(log_density, loc)
    return grid, w, s / r, r


def vmf_reference(x):
    """Exact means and sds of ``mu[1..d]`` and ``kappa``."""
    grid, w, m, r = vmf_kappa_law(x)
    d = x.shape[1]
    k = np.exp(grid) * r
    a = special.ive(d / 2, k) / special.ive(d / 2 - 1, k)
    mean_mu = (w @ a) * m
    second = w @ (a / k) + m**2 * (w @ (1 - d * a / k))
    kappa = np.exp(grid)
    mean_k = w @ kappa
    sd_k = np.sqrt(w @ kappa**2 - mean_k**2)
    return np.append(mean_mu, mean_k), np.append(np.sqrt(second - mean_mu**2), sd_k)


def vmf_exact_draws(x, n, seed):
    """``n`` i.i.d. posterior draws ``(n, d + 1)``: ``kappa`` by the quadrature's inverse
    distribution function, then ``mu ~ vMF(m, kappa |S|)`` (for validating the reference)."""
    grid, w, m, r = vmf_kappa_law(x)
    rng = np.random.default_rng(seed)
    kappa = np.exp(np.interp(rng.uniform(size=n), np.cumsum(w), grid))
    mu = np.stack([vonmises_fisher(m, k * r).rvs(1, random_state=rng)[0] for k in kappa])
    return np.column_stack([mu, kappa])


# --------------------------------------------------------------------------- Watson axes on S²


def watson_model(data):
    mu = numpyro.sample("mu", VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 0.0))
    watson_likelihood(mu, data["x"])


def watson_nuts_model(data):
    mu = numpyro.deterministic("mu", gaussian_direction("mu", 3))
    watson_likelihood(mu, data["x"])


def watson_likelihood(mu, x):
    """Watson's ``κ_W (mu·x_i)²`` summed (its normaliser does not depend on ``mu``)."""
    numpyro.factor("x", WATSON_CONCENTRATION * jnp.sum((x @ mu) ** 2))


def watson_data():
    rng = np.random.default_rng(11)
    axis = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    x = vonmises_fisher(axis, 20.0).rvs(12, random_state=rng)
    return {"x": x * rng.choice([-1.0, 1.0], size=(12, 1))}  # axes: either sign


def watson_bingham(x):
    """The posterior as a :class:`liesample.numpyro.Bingham` law."""
    a, v = np.linalg.eigh(WATSON_CONCENTRATION * x.T @ x)
    if np.linalg.det(v) < 0:
        v[:, 0] = -v[:, 0]
    return Bingham(jnp.asarray(-a), jnp.asarray(v))


def watson_reference(x):
    second = np.asarray(watson_bingham(x).second_moment())
    return np.zeros(3), np.sqrt(np.diag(second))


# --------------------------------------------------------------------------- circular regression


def circular_model(data):
    alpha = numpyro.sample("alpha", dist.VonMises(0.0, CIRCULAR_PRIOR[0]))
    circular_likelihood(alpha, data)


def circular_nuts_model(data):
    u = gaussian_direction("alpha", 2)
    alpha = jnp.arctan2(u[1], u[0])
    numpyro.factor("alpha_prior", dist.VonMises(0.0, CIRCULAR_PRIOR[0]).log_prob(alpha))
    circular_likelihood(alpha, data)


def circular_likelihood(alpha, data):
    numpyro.deterministic("cos_alpha", jnp.cos(alpha))
    numpyro.deterministic("sin_alpha", jnp.sin(alpha))
    beta = numpyro.sample("beta", dist.Normal(0.0, 1.0))
    kappa = numpyro.sample("kappa", dist.LogNormal(*CIRCULAR_PRIOR[1]))
    mean = alpha + 2.0 * jnp.arctan(beta * data["x"])
    numpyro.sample("y", dist.VonMises(mean, kappa), obs=data["y"])


def circular_data():
    rng = np.random.default_rng(5)
    x = rng.standard_normal(40)
    y = 1.0 + 2.0 * np.arctan(0.8 * x) + rng.vonmises(0.0, 5.0, 40)
    return {"x": x, "y": np.angle(np.exp(1j * y))}


def circular_log_density(alpha, beta, eta, data):
    """The posterior's log density in ``(alpha, beta, eta = log kappa)`` (w.r.t. dα dβ dη)."""
    alpha, beta, eta = jnp.asarray(alpha), jnp.asarray(beta), jnp.asarray(eta)
    kappa = jnp.exp(eta)
    mean = alpha[..., None] + 2.0 * jnp.arctan(beta[..., None] * data["x"])
    loglik = jnp.sum(kappa[..., None] * jnp.cos(data["y"] - mean), -1) - len(data["x"]) * (
        jnp.log(jax.scipy.special.i0e(kappa)) + kappa
    )
    prior = CIRCULAR_PRIOR[0] * jnp.cos(alpha) - 0.5 * beta**2
    loc, scale = CIRCULAR_PRIOR[1]
    return loglik + prior - 0.5 * ((eta - loc) / scale) ** 2  # log-normal in eta: Gaussian


def circular_reference(data, points=(128, 121, 121), bounds=((-0.5, 2.0), (0.0, 3.2))):
    """Means and sds of ``(cos alpha, sin alpha, beta, kappa)`` by a tensor-product quadrature
    on ``points`` nodes, ``beta`` and ``eta`` within ``bounds``."""
    alpha = jnp.linspace(-np.pi, np.pi, points[0], endpoint=False)
    beta = jnp.linspace(*bounds[0], points[1])
    eta = jnp.linspace(*bounds[1], points[2])
    data = {k: jnp.asarray(v) for k, v in data.items()}
    a, b, e = jnp.meshgrid(alpha, beta, eta, indexing="ij")
    logp = jax.jit(jax.vmap(lambda a, b, e: circular_log_density(a, b, e, data)))(a, b, e)
    trapezoid = jnp.ones(points[1:]).at[[0, -1], :].mul(0.5).at[:, [0, -1]].mul(0.5)
    w = jnp.exp(logp - logp.max()) * trapezoid
    w = np.asarray(w / w.sum())
    values = np.stack([np.cos(a), np.sin(a), b, np.exp(e)])
    mean = np.einsum("kijl,ijl->k", values, w)
    var = np.einsum("kijl,ijl->k", (values - mean[:, None, None, None]) ** 2, w)
    return mean, np.sqrt(var)


# --------------------------------------------------------------------------- rotation averaging


def rotation_model(data):
    rotation = numpyro.sample("M", MatrixFisher(jnp.zeros((3, 3))))
    rotation_likelihood(rotation, data["R"])


def rotation_nuts_model(data):
    q = gaussian_direction("M", 4)
    rotation = numpyro.deterministic("M", quaternion_to_rotation(q))
    rotation_likelihood(rotation, data["R"])


def rotation_likelihood(rotation, rotations):
    kappa = numpyro.sample("kappa", dist.LogNormal(*ROTATION_PRIOR))
    with numpyro.plate("data", rotations.shape[0]):
        numpyro.sample("R", MatrixFisher(kappa * rotation), obs=rotations)


def rotation_data():
    truth = np.asarray(quaternion_to_rotation(jnp.array([0.8, 0.2, -0.4, 0.4]) / 1.0))
    law = MatrixFisher(jnp.asarray(5.0 * truth))
    return {"R": np.asarray(law.sample(jax.random.key(3), (15,)))}


def rotation_kappa_law(rotations):
    """``(log κ grid, weights, S)``: the marginal of ``log kappa``."""
    n = rotations.shape[0]
    s = rotations.sum(0)
    loc, scale = ROTATION_PRIOR
    log_c = jax.jit(jax.vmap(lambda f: MatrixFisher(f).log_normalizer()))

    def log_density(eta):
        kappa = np.exp(eta)[:, None, None]
        eye = np.broadcast_to(np.eye(3), kappa.shape[:1] + (3, 3))
        values = np.asarray(log_c(kappa * s)) - n * np.asarray(log_c(kappa * eye))
        return values - 0.5 * ((eta - loc) / scale) ** 2

    grid, w = log_kappa_grid(log_density, loc, half_width=8.0, points=4001)
    return grid, w, s


def rotation_reference(rotations, num_draws=ROTATION_NUM_DRAWS, seed=0):
    """Means (exact quadrature) and sds (``num_draws`` exact draws) of ``M``'s entries and
    ``kappa``."""
    grid, w, s = rotation_kappa_law(rotations)
    kappa = np.exp(grid)
    means = jax.jit(jax.vmap(lambda f: MatrixFisher(f).mean))(jnp.asarray(kappa[:, None, None] * s))
    mean_m = np.einsum("g,gij->ij", w, np.asarray(means)).reshape(-1)
    draws = rotation_exact_draws(rotations, num_draws, seed)
    mean_k = w @ kappa
    sd_k = np.sqrt(w @ kappa**2 - mean_k**2)
    sd_m = draws[:, :9].std(0, ddof=1)
    return np.append(mean_m, mean_k), np.append(sd_m, sd_k)


def rotation_exact_draws(rotations, n, seed):
    """``n`` i.i.d. posterior draws ``(n, 10)``: ``M``'s entries (row-major) and ``kappa``."""
    grid, w, s = rotation_kappa_law(rotations)
    rng = np.random.default_rng(seed)
    kappa = np.exp(np.interp(rng.uniform(size=n), np.cumsum(w), grid))
    m = MatrixFisher(jnp.asarray(kappa[:, None, None] * s)).sample(jax.random.key(seed))
    return np.column_stack([np.asarray(m).reshape(n, 9), kappa])


# --------------------------------------------------------------------------- posteriors

_MODELS = {
    VMF_SPHERE: (vmf_model, vmf_nuts_model, vmf_data, ("mu", "kappa")),
    AXIAL_BIMODAL: (watson_model, watson_nuts_model, watson_data, ("mu",)),
    CIRCULAR_REGRESSION: (
        circular_model,
        circular_nuts_model,
        circular_data,
        ("cos_alpha", "sin_alpha", "beta", "kappa"),
    ),
    ROTATION_AVERAGING: (rotation_model, rotation_nuts_model, rotation_data, ("M", "kappa")),
}


def keys_of(name, data):
    if name == VMF_SPHERE:
        return [f"mu[{i + 1}]" for i in range(data["x"].shape[1])] + ["kappa"]
    if name == AXIAL_BIMODAL:
        return ["mu[1]", "mu[2]", "mu[3]"]
    if name == CIRCULAR_REGRESSION:
        return ["cos_alpha", "sin_alpha", "beta", "kappa"]
    return [f"M[{i + 1},{j + 1}]" for i in range(3) for j in range(3)] + ["kappa"]


def reference_of(name, data):
    """``(mean, sd, method)`` of the reference."""
    if name == VMF_SPHERE:
        return (*vmf_reference(data["x"]), "exact (quadrature over log kappa)")
    if name == AXIAL_BIMODAL:
        return (*watson_reference(data["x"]), "exact (Bingham second moments)")
    if name == CIRCULAR_REGRESSION:
        return (*circular_reference(data), "quadrature (128 x 121 x 121 nodes)")
    return (
        *rotation_reference(data["R"]),
        f"exact means (quadrature); sds from {ROTATION_NUM_DRAWS} exact draws",
    )


@functools.cache
def load(name: str) -> DirectionalPosterior:
    """The directional posterior ``name`` (one of :data:`NAMES`)."""
    model, nuts_model, make_data, reported = _MODELS[name]
    data = make_data()
    mean, sd, method = reference_of(name, data)
    mcse = np.zeros_like(mean)  # exact or quadrature means
    return DirectionalPosterior(
        name=name,
        model=model,
        data=data,
        reported=reported,
        keys=keys_of(name, data),
        mean=np.asarray(mean, float),
        sd=np.asarray(sd, float),
        mcse_mean=mcse,
        reference_info={"method": method, "num_chains": 0, "num_draws": 0},
        draws_sample=np.zeros((0, len(mean))),
        stan_code="",
        nuts_model=nuts_model,
    )
