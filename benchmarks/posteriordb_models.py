"""posteriordb posteriors written in NumPyro, with their data and reference summaries.

Each model is written here from the Stan program that posteriordb ships with it (the program
is kept, as ``stan_code``, in ``benchmarks/data/posteriordb/<posterior>.json`` beside the
data and a summary of the reference draws; ``README.md`` there names the source and the
licence). Parameters keep Stan's names: a Stan ``vector[K] beta`` is the site ``beta`` of shape
``(K,)`` and its coordinates are the reference keys ``beta[1]`` … ``beta[K]``. Stan's
transformed parameters that the reference draws report (``theta`` of the non-centred eight
schools, ``f`` of the GP Poisson regression) are ``numpyro.deterministic`` sites.

Stan's implicit priors are kept: a parameter with no sampling statement has a flat density on
its support (``ImproperUniform``), bounds included (``beta1`` of GARCH(1,1) is flat on
``(0, 1 - alpha1)``: ``Uniform``'s normaliser, which would change the posterior, is cancelled
by a ``factor``). A
truncated ``normal``/``cauchy`` on a ``<lower=0>`` parameter is NumPyro's half law: the same
density up to a constant.

The centred eight schools has the non-centred program's reference draws (posteriordb's
``reference_posterior_name``: the law of ``(mu, tau, theta)`` is the same). ``diamonds`` is
stored gzipped (its design is 5000 x 25). One toy is not from posteriordb: ``resonance``
(``x ~ normal(0, 0.003)`` beside O(1) parameters), with exact moments (:data:`EXACT`).

:func:`load` returns a :class:`Posterior`; :func:`flatten` turns site values into the
reference's coordinates and :meth:`Posterior.latent` turns reference coordinates back into the
values of the sample sites (inverting the transformed parameters).
"""

from __future__ import annotations

import gzip
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
from numpyro.distributions import constraints

DATA_DIR = Path(__file__).resolve().parent / "data" / "posteriordb"

POSTERIORS = (
    "eight_schools-eight_schools_noncentered",
    "arK-arK",
    "gp_pois_regr-gp_pois_regr",
    "kidiq-kidscore_momiq",
    "mesquite-logmesquite",
    "garch-garch11",
    "sblrc-blr",
    "diamonds-diamonds",
    "eight_schools-eight_schools_centered",
    "kilpisjarvi_mod-kilpisjarvi",
    "low_dim_gauss_mix-low_dim_gauss_mix",
    "hmm_example-hmm_example",
    "arma-arma11",
    "earnings-earn_height",
    "gp_pois_regr-gp_regr",
    "kidiq-kidscore_interaction",
    "earnings-logearn_interaction_z",
    "nes1972-nes",
    "bball_drive_event_0-hmm_drive_0",
    "mesquite-logmesquite_logvash",
    "sblri-blr",
)


def _flat(support, shape=()):
    """Stan's implicit prior: a flat density on ``support``."""
    return dist.ImproperUniform(support, (), shape)


# --------------------------------------------------------------------------- models


def eight_schools_noncentered(data):
    """``eight_schools_noncentered.stan``: ``theta = mu + tau * theta_trans``."""
    sigma, y = data["sigma"], data["y"]
    theta_trans = numpyro.sample("theta_trans", dist.Normal(0.0, 1.0).expand([len(y)]))
    mu = numpyro.sample("mu", dist.Normal(0.0, 5.0))
    tau = numpyro.sample("tau", dist.HalfCauchy(5.0))
    theta = numpyro.deterministic("theta", theta_trans * tau + mu)
    numpyro.sample("y", dist.Normal(theta, sigma), obs=y)


def ark(data):
    """``arK.stan``: AR(K) with ``y[t] ~ normal(alpha + sum_k beta[k] y[t-k], sigma)``."""
    lags, y = data["lags"], data["y_now"]
    alpha = numpyro.sample("alpha", dist.Normal(0.0, 10.0))
    beta = numpyro.sample("beta", dist.Normal(0.0, 10.0).expand([lags.shape[1]]))
    sigma = numpyro.sample("sigma", dist.HalfCauchy(2.5))
    numpyro.sample("y", dist.Normal(alpha + lags @ beta, sigma), obs=y)


def gp_pois_regr(data):
    """``gp_pois_regr.stan``: ``f = chol(K(x; alpha, rho) + 1e-10 I) f_tilde``, Poisson-log."""
    x, k = data["x"], data["k"]
    rho = numpyro.sample("rho", dist.Gamma(25.0, 4.0))
    alpha = numpyro.sample("alpha", dist.HalfNormal(2.0))
    f_tilde = numpyro.sample("f_tilde", dist.Normal(0.0, 1.0).expand([len(x)]))
    f = numpyro.deterministic("f", gp_cholesky(x, alpha, rho) @ f_tilde)
    numpyro.sample("k", dist.Poisson(jnp.exp(f)), obs=k)


def gp_cholesky(x, alpha, rho):
    """Cholesky factor of Stan's ``gp_exp_quad_cov(x, alpha, rho) + 1e-10 I``."""
    squared = (x[:, None] - x[None, :]) ** 2
    cov = alpha**2 * jnp.exp(-0.5 * squared / rho**2) + 1e-10 * jnp.eye(len(x))
    return jnp.linalg.cholesky(cov)


def kidscore_momiq(data):
    """``kidscore_momiq.stan``: flat ``beta``, ``kid_score ~ normal(b1 + b2 mom_iq, sigma)``."""
    beta = numpyro.sample("beta", _flat(constraints.real, (2,)))
    sigma = numpyro.sample("sigma", dist.HalfCauchy(2.5))
    mean = beta[0] + beta[1] * data["mom_iq"]
    numpyro.sample("kid_score", dist.Normal(mean, sigma), obs=data["kid_score"])


def logmesquite(data):
    """``logmesquite.stan`` (six predictors) and ``logmesquite_logvash.stan`` (five): log-log
    regression, flat priors."""
    beta = numpyro.sample("beta", _flat(constraints.real, (data["predictors"].shape[1] + 1,)))
    sigma = numpyro.sample("sigma", _flat(constraints.positive))
    mean = beta[0] + data["predictors"] @ beta[1:]
    numpyro.sample("log_weight", dist.Normal(mean, sigma), obs=data["log_weight"])


def garch11(data):
    """``garch11.stan``: GARCH(1,1) volatility, flat priors within Stan's bounds."""
    y, sigma1 = data["y"], data["sigma1"]
    mu = numpyro.sample("mu", _flat(constraints.real))
    alpha0 = numpyro.sample("alpha0", _flat(constraints.positive))
    alpha1 = numpyro.sample("alpha1", _flat(constraints.unit_interval))
    # Flat on (0, 1 - alpha1): Uniform's -log(1 - alpha1) is cancelled by the factor. (An
    # ImproperUniform wraps its support in ``independent``, which hides from NumPyro's
    # initialize_model that the bound depends on alpha1, and its postprocess_fn then keeps the
    # bound of the initial point.)
    beta1 = numpyro.sample("beta1", dist.Uniform(0.0, 1.0 - alpha1))
    numpyro.factor("beta1_flat", jnp.log1p(-alpha1))

    def volatility(sigma_previous, y_previous):
        sigma = jnp.sqrt(alpha0 + alpha1 * (y_previous - mu) ** 2 + beta1 * sigma_previous**2)
        return sigma, sigma

    _, rest = jax.lax.scan(volatility, jnp.asarray(sigma1, y.dtype), y[:-1])
    sigma = jnp.concatenate([jnp.asarray(sigma1, y.dtype)[None], rest])
    numpyro.sample("y", dist.Normal(mu, sigma), obs=y)


def blr(data):
    """``blr.stan``: Bayesian linear regression, ``normal(0, 10)`` priors."""
    x, y = data["X"], data["y"]
    beta = numpyro.sample("beta", dist.Normal(0.0, 10.0).expand([x.shape[1]]))
    sigma = numpyro.sample("sigma", dist.HalfNormal(10.0))
    numpyro.sample("y", dist.Normal(x @ beta, sigma), obs=y)


def diamonds(data):
    """``diamonds.stan`` (brms): 24 slopes on the centred design, Student-t intercept and
    half-Student-t ``sigma`` (Stan's ``student_t_lpdf - student_t_lccdf(0 | …)``)."""
    xc = data["Xc"]
    b = numpyro.sample("b", dist.Normal(0.0, 1.0).expand([xc.shape[1]]))
    intercept = numpyro.sample("Intercept", dist.StudentT(3.0, 8.0, 10.0))
    sigma = numpyro.sample("sigma", dist.FoldedDistribution(dist.StudentT(3.0, 0.0, 10.0)))
    numpyro.sample("Y", dist.Normal(intercept + xc @ b, sigma), obs=data["Y"])


def eight_schools_centered(data):
    """``eight_schools_centered.stan``: ``theta ~ normal(mu, tau)``, the funnel. The law of
    ``(mu, tau, theta)`` is the non-centred program's: posteriordb gives its draws as the
    reference."""
    sigma, y = data["sigma"], data["y"]
    tau = numpyro.sample("tau", dist.HalfCauchy(5.0))
    mu = numpyro.sample("mu", dist.Normal(0.0, 5.0))
    theta = numpyro.sample("theta", dist.Normal(mu, tau).expand([len(y)]))
    numpyro.sample("y", dist.Normal(theta, sigma), obs=y)


def kilpisjarvi(data):
    """``kilpisjarvi.stan``: a linear trend in the year (not centred), so ``alpha`` and
    ``beta`` are correlated near −1 with sds ~4000 apart; flat ``sigma``."""
    alpha = numpyro.sample("alpha", dist.Normal(data["pmualpha"], data["psalpha"]))
    beta = numpyro.sample("beta", dist.Normal(data["pmubeta"], data["psbeta"]))
    sigma = numpyro.sample("sigma", _flat(constraints.positive))
    numpyro.sample("y", dist.Normal(alpha + beta * data["x"], sigma), obs=data["y"])


def low_dim_gauss_mix(data):
    """``low_dim_gauss_mix.stan``: two normals, ordered means, ``log_mix(theta, …)``."""
    mu = numpyro.sample("mu", _flat(constraints.ordered_vector, (2,)))
    numpyro.factor("mu_prior", jnp.sum(dist.Normal(0.0, 2.0).log_prob(mu)))
    sigma = numpyro.sample("sigma", dist.HalfNormal(2.0).expand([2]))
    theta = numpyro.sample("theta", dist.Beta(5.0, 5.0))
    mixing = dist.Categorical(probs=jnp.stack([theta, 1.0 - theta]))
    numpyro.sample("y", dist.MixtureSameFamily(mixing, dist.Normal(mu, sigma)), obs=data["y"])


def hmm_example(data):
    """``hmm_example.stan``: two-state Gaussian HMM, forward algorithm. ``theta1``, ``theta2``
    are flat on the simplex (a Dirichlet(1, 1)); the program's priors name ``mu[1]`` and
    ``mu[2]``, so it has two states."""
    y = data["y"]
    theta1 = numpyro.sample("theta1", dist.Dirichlet(jnp.ones(2)))
    theta2 = numpyro.sample("theta2", dist.Dirichlet(jnp.ones(2)))
    mu = numpyro.sample("mu", _flat(constraints.positive_ordered_vector, (2,)))
    prior = dist.Normal(jnp.array([3.0, 10.0]), 1.0).log_prob(mu)
    numpyro.factor("mu_prior", jnp.sum(prior))
    log_transition = jnp.log(jnp.stack([theta1, theta2]))  # [from j, to k]
    emission = dist.Normal(mu, 1.0).log_prob(y[:, None])  # (N, K)

    def forward(gamma, emitted):
        gamma = jax.nn.logsumexp(gamma[:, None] + log_transition, axis=0) + emitted
        return gamma, None

    gamma, _ = jax.lax.scan(forward, emission[0], emission[1:])
    numpyro.factor("y", jax.nn.logsumexp(gamma))


def arma11(data):
    """``arma11.stan``: ARMA(1, 1), ``err[t] = y[t] - mu - phi y[t-1] - theta err[t-1]``."""
    y = data["y"]
    mu = numpyro.sample("mu", dist.Normal(0.0, 10.0))
    phi = numpyro.sample("phi", dist.Normal(0.0, 2.0))
    theta = numpyro.sample("theta", dist.Normal(0.0, 2.0))
    sigma = numpyro.sample("sigma", dist.HalfCauchy(2.5))
    first = y[0] - (mu + phi * mu)  # err[0] taken as 0

    def error(previous, pair):
        y_previous, y_now = pair
        err = y_now - (mu + phi * y_previous + theta * previous)
        return err, err

    _, rest = jax.lax.scan(error, first, (y[:-1], y[1:]))
    err = jnp.concatenate([first[None], rest])
    numpyro.sample("err", dist.Normal(0.0, sigma), obs=err)


def earn_height(data):
    """``earn_height.stan``: earnings (dollars) on height, flat priors: ``beta[1]`` ~ 1e4 and
    ``beta[2]`` ~ 1e2 in sd, correlated near −1."""
    beta = numpyro.sample("beta", _flat(constraints.real, (2,)))
    sigma = numpyro.sample("sigma", _flat(constraints.positive))
    mean = beta[0] + beta[1] * data["height"]
    numpyro.sample("earn", dist.Normal(mean, sigma), obs=data["earn"])


def gp_regr(data):
    """``gp_regr.stan``: a GP marginal likelihood, ``y ~ multi_normal(0, K(x; alpha, rho) +
    sigma I)`` (the program adds ``sigma``, not ``sigma²``, to the diagonal)."""
    x, y = data["x"], data["y"]
    rho = numpyro.sample("rho", dist.Gamma(25.0, 4.0))
    alpha = numpyro.sample("alpha", dist.HalfNormal(2.0))
    sigma = numpyro.sample("sigma", dist.HalfNormal(1.0))
    squared = (x[:, None] - x[None, :]) ** 2
    cov = alpha**2 * jnp.exp(-0.5 * squared / rho**2) + sigma * jnp.eye(len(x))
    numpyro.sample("y", dist.MultivariateNormal(jnp.zeros(len(x)), cov), obs=y)


def kidscore_interaction(data):
    """``kidscore_interaction.stan``: flat ``beta``, mother's IQ, high school and their product."""
    beta = numpyro.sample("beta", _flat(constraints.real, (4,)))
    sigma = numpyro.sample("sigma", dist.HalfCauchy(2.5))
    hs, iq = data["mom_hs"], data["mom_iq"]
    mean = beta[0] + beta[1] * hs + beta[2] * iq + beta[3] * hs * iq
    numpyro.sample("kid_score", dist.Normal(mean, sigma), obs=data["kid_score"])


def logearn_interaction_z(data):
    """``logearn_interaction_z.stan``: log earnings on standardised height, sex and their
    product; flat priors."""
    beta = numpyro.sample("beta", _flat(constraints.real, (4,)))
    sigma = numpyro.sample("sigma", _flat(constraints.positive))
    z, male = data["z_height"], data["male"]
    mean = beta[0] + beta[1] * z + beta[2] * male + beta[3] * z * male
    numpyro.sample("log_earn", dist.Normal(mean, sigma), obs=data["log_earn"])


def nes(data):
    """``nes.stan``: party identification on nine predictors (age as a factor), flat priors."""
    x = data["predictors"]
    beta = numpyro.sample("beta", _flat(constraints.real, (x.shape[1] + 1,)))
    sigma = numpyro.sample("sigma", _flat(constraints.positive))
    numpyro.sample("partyid7", dist.Normal(beta[0] + x @ beta[1:], sigma), obs=data["partyid7"])


def hmm_drive_0(data):
    """``hmm_drive_0.stan``: a two-state HMM of a basketball drive, exponential emissions of
    1/speed (rates ``phi``) and hoop distance (rates ``lambda``), positive-ordered rates with
    normal priors on each, Dirichlet rows of the transition matrix."""
    alpha = data["alpha"]
    theta1 = numpyro.sample("theta1", dist.Dirichlet(alpha[0]))
    theta2 = numpyro.sample("theta2", dist.Dirichlet(alpha[1]))
    phi = numpyro.sample("phi", _flat(constraints.positive_ordered_vector, (2,)))
    lam = numpyro.sample("lambda", _flat(constraints.positive_ordered_vector, (2,)))
    centres = jnp.array([0.0, 3.0])
    prior = dist.Normal(centres, 1.0).log_prob(phi) + dist.Normal(centres, 1.0).log_prob(lam)
    numpyro.factor("rates_prior", jnp.sum(prior))
    log_transition = jnp.log(jnp.stack([theta1, theta2]))  # [from j, to k]
    emission = dist.Exponential(phi).log_prob(data["u"][:, None]) + dist.Exponential(lam).log_prob(
        data["v"][:, None]
    )  # (N, K)

    def forward(gamma, emitted):
        gamma = jax.nn.logsumexp(gamma[:, None] + log_transition, axis=0) + emitted
        return gamma, None

    gamma, _ = jax.lax.scan(forward, emission[0], emission[1:])
    numpyro.factor("observations", jax.nn.logsumexp(gamma))


def resonance(data):
    """The resonance toy (not from posteriordb): ``x ~ normal(0, 0.003)`` beside three
    standard normals and a ``gamma(4, 4)``. A fixed integration time near π/2 in a metric
    that over-estimates ``x``'s variance puts ``x`` near a half-period (issue 28)."""
    numpyro.sample("x", dist.Normal(0.0, data["scale"]))
    numpyro.sample("y", dist.Normal(0.0, 1.0).expand([3]))
    numpyro.sample("s", dist.Gamma(4.0, 4.0))


RESONANCE_STAN = """parameters {
  real x;
  vector[3] y;
  real<lower=0> s;
}
model {
  x ~ normal(0, 0.003);
  y ~ normal(0, 1);
  s ~ gamma(4, 4);
}
"""


# --------------------------------------------------------------------------- data


def _ark_data(raw):
    y, lags = np.asarray(raw["y"], float), int(raw["K"])
    columns = [y[lags - k : len(y) - k] for k in range(1, lags + 1)]
    return {"lags": np.stack(columns, axis=1), "y_now": y[lags:]}


def _mesquite_data(raw):
    logs = [np.log(np.asarray(raw[k], float)) for k in PREDICTORS_LOGGED]
    predictors = np.stack([*logs, np.asarray(raw["group"], float)], axis=1)
    return {"predictors": predictors, "log_weight": np.log(np.asarray(raw["weight"], float))}


PREDICTORS_LOGGED = ("diam1", "diam2", "canopy_height", "total_height", "density")


def _diamonds_data(raw):
    x = np.asarray(raw["X"], float)[:, 1:]  # the first column is the intercept's
    return {"Xc": x - x.mean(axis=0), "Y": np.asarray(raw["Y"], float)}


def _logearn_z_data(raw):
    height = np.asarray(raw["height"], float)
    z = (height - height.mean()) / height.std(ddof=1)  # Stan's sd divides by N - 1
    return {
        "z_height": z,
        "male": np.asarray(raw["male"], float),
        "log_earn": np.log(np.asarray(raw["earn"], float)),
    }


NES_PREDICTORS = ("real_ideo", "race_adj", "age30_44", "age45_64", "age65up", "educ1",
                  "gender", "income")  # fmt: skip


def _nes_data(raw):
    age = np.asarray(raw["age_discrete"], int)
    columns = {"age30_44": age == 2, "age45_64": age == 3, "age65up": age == 4}
    columns.update({k: raw[k] for k in ("real_ideo", "race_adj", "educ1", "gender", "income")})
    predictors = np.stack([np.asarray(columns[k], float) for k in NES_PREDICTORS], axis=1)
    return {"predictors": predictors, "partyid7": np.asarray(raw["partyid7"], float)}


def _mesquite_logvash_data(raw):
    d1, d2 = np.asarray(raw["diam1"], float), np.asarray(raw["diam2"], float)
    height, total = np.asarray(raw["canopy_height"], float), np.asarray(raw["total_height"], float)
    columns = [np.log(d1 * d2 * height), np.log(d1 * d2), np.log(d1 / d2), np.log(total)]
    predictors = np.stack([*columns, np.asarray(raw["group"], float)], axis=1)
    return {"predictors": predictors, "log_weight": np.log(np.asarray(raw["weight"], float))}


def _arrays(*names, integer=()):
    def prepare(raw):
        out = {k: np.asarray(raw[k], float) for k in names}
        out.update({k: np.asarray(raw[k], np.int64) for k in integer})
        return out

    return prepare


def _eight_schools_latent(values):
    return {
        "mu": values["mu"],
        "tau": values["tau"],
        "theta_trans": (values["theta"] - values["mu"][..., None]) / values["tau"][..., None],
    }


def _gp_latent(data):
    def latent(values):
        def one(alpha, rho, f):
            return jax.scipy.linalg.solve_triangular(
                gp_cholesky(data["x"], alpha, rho), f, lower=True
            )

        f_tilde = jax.vmap(one)(values["alpha"], values["rho"], values["f"])
        return {"rho": values["rho"], "alpha": values["alpha"], "f_tilde": np.asarray(f_tilde)}

    return latent


@dataclass(frozen=True)
class _Spec:
    model: Callable
    prepare: Callable
    reported: tuple  # sites whose coordinates are the reference keys
    latent: Callable | None = None  # data -> (reference site values -> sample-site values)


SPECS = {
    "eight_schools-eight_schools_noncentered": _Spec(
        eight_schools_noncentered,
        _arrays("y", "sigma"),
        ("theta", "mu", "tau"),
        lambda data: _eight_schools_latent,
    ),
    "arK-arK": _Spec(ark, _ark_data, ("alpha", "beta", "sigma")),
    "gp_pois_regr-gp_pois_regr": _Spec(
        gp_pois_regr, _arrays("x", integer=("k",)), ("rho", "alpha", "f"), _gp_latent
    ),
    "kidiq-kidscore_momiq": _Spec(
        kidscore_momiq, _arrays("kid_score", "mom_iq"), ("beta", "sigma")
    ),
    "mesquite-logmesquite": _Spec(logmesquite, _mesquite_data, ("beta", "sigma")),
    "garch-garch11": _Spec(garch11, _arrays("y", "sigma1"), ("mu", "alpha0", "alpha1", "beta1")),
    "sblrc-blr": _Spec(blr, _arrays("X", "y"), ("beta", "sigma")),
    "diamonds-diamonds": _Spec(diamonds, _diamonds_data, ("b", "Intercept", "sigma")),
    "eight_schools-eight_schools_centered": _Spec(
        eight_schools_centered, _arrays("y", "sigma"), ("theta", "mu", "tau")
    ),
    "kilpisjarvi_mod-kilpisjarvi": _Spec(
        kilpisjarvi,
        _arrays("x", "y", "pmualpha", "psalpha", "pmubeta", "psbeta"),
        ("alpha", "beta", "sigma"),
    ),
    "low_dim_gauss_mix-low_dim_gauss_mix": _Spec(
        low_dim_gauss_mix, _arrays("y"), ("mu", "sigma", "theta")
    ),
    "hmm_example-hmm_example": _Spec(hmm_example, _arrays("y"), ("theta1", "theta2", "mu")),
    "arma-arma11": _Spec(arma11, _arrays("y"), ("mu", "phi", "theta", "sigma")),
    "earnings-earn_height": _Spec(earn_height, _arrays("earn", "height"), ("beta", "sigma")),
    "gp_pois_regr-gp_regr": _Spec(gp_regr, _arrays("x", "y"), ("rho", "alpha", "sigma")),
    "kidiq-kidscore_interaction": _Spec(
        kidscore_interaction, _arrays("kid_score", "mom_iq", "mom_hs"), ("beta", "sigma")
    ),
    "earnings-logearn_interaction_z": _Spec(
        logearn_interaction_z, _logearn_z_data, ("beta", "sigma")
    ),
    "nes1972-nes": _Spec(nes, _nes_data, ("beta", "sigma")),
    "bball_drive_event_0-hmm_drive_0": _Spec(
        hmm_drive_0, _arrays("u", "v", "alpha"), ("theta1", "theta2", "phi", "lambda")
    ),
    "mesquite-logmesquite_logvash": _Spec(logmesquite, _mesquite_logvash_data, ("beta", "sigma")),
    "sblri-blr": _Spec(blr, _arrays("X", "y"), ("beta", "sigma")),
}


# --------------------------------------------------------------------------- names

_KEY = re.compile(r"^(\w+?)(?:\[(\d+(?:,\d+)*)\])?$")


def parse_key(key: str) -> tuple[str, tuple[int, ...]]:
    """``"beta[2]"`` → ``("beta", (1,))`` (0-based); ``"sigma"`` → ``("sigma", ())``."""
    match = _KEY.match(key)
    if match is None:
        raise ValueError(f"not a Stan parameter key: {key!r}")
    name, index = match.groups()
    return name, tuple(int(i) - 1 for i in index.split(",")) if index else ()


def reference_keys(values: dict) -> list[str]:
    """Stan's keys for site values without a batch axis (``beta`` of shape (2,) →
    ``beta[1]``, ``beta[2]``)."""
    keys = []
    for name, value in values.items():
        shape = np.shape(value)
        if shape == ():
            keys.append(name)
            continue
        for index in np.ndindex(*shape):
            keys.append(f"{name}[{','.join(str(i + 1) for i in index)}]")
    return keys


def flatten(values: dict, keys, batch_ndim: int = 0) -> np.ndarray:
    """Site values (``batch_ndim`` leading batch axes) as an array ``(*batch, len(keys))``
    in the order of the reference ``keys``."""
    columns = []
    for key in keys:
        name, index = parse_key(key)
        value = np.asarray(values[name])
        columns.append(value[(Ellipsis, *index)] if index else value)
    return np.stack(columns, axis=-1)


def unflatten(array, keys) -> dict:
    """Reference coordinates ``(..., len(keys))`` back into site arrays (1-d indices only)."""
    array = np.asarray(array)
    sites: dict = {}
    for column, key in enumerate(keys):
        name, index = parse_key(key)
        sites.setdefault(name, []).append((index, array[..., column]))
    out = {}
    for name, entries in sites.items():
        if entries[0][0] == ():
            out[name] = entries[0][1]
        else:
            entries = sorted(entries, key=lambda e: e[0])
            out[name] = np.stack([v for _, v in entries], axis=-1)
    return out


# --------------------------------------------------------------------------- posteriors


@dataclass
class Posterior:
    """One posteriordb posterior: its NumPyro model, prepared data and reference summary."""

    name: str
    model: Callable
    data: dict
    reported: tuple
    keys: list  # reference keys, in the reference's order
    mean: np.ndarray
    sd: np.ndarray
    mcse_mean: np.ndarray  # reference MCSE of each mean (sd / sqrt(bulk ESS))
    reference_info: dict
    draws_sample: np.ndarray  # (n, len(keys)): a few reference draws
    stan_code: str
    _latent: Callable | None = None

    def model_kwargs(self) -> dict:
        return {"data": {k: jnp.asarray(v) for k, v in self.data.items()}}

    def latent(self, reference_draws) -> dict:
        """Sample-site values (constrained) of reference draws ``(n, len(keys))``."""
        values = unflatten(reference_draws, self.keys)
        if self._latent is None:
            return values
        return self._latent(values)


def load(name: str) -> Posterior:
    """The posterior ``name`` (one of :data:`NAMES`)."""
    if name in EXACT:
        return EXACT[name]()
    record = read_record(name)
    spec = SPECS[name]
    data = spec.prepare(record["data"])
    ref = record["reference"]
    keys = ref["names"]
    sample = np.stack([np.asarray(record["draws_sample"][k], float) for k in keys], axis=-1)
    return Posterior(
        name=name,
        model=spec.model,
        data=data,
        reported=spec.reported,
        keys=keys,
        mean=np.asarray(ref["mean"]),
        sd=np.asarray(ref["sd"]),
        mcse_mean=np.asarray(ref["mcse_mean"]),
        reference_info={k: ref[k] for k in ("method", "num_chains", "num_draws")},
        draws_sample=sample,
        stan_code=record["stan_code"],
        _latent=None if spec.latent is None else spec.latent(data),
    )


def read_record(name: str) -> dict:
    """The stored record of a posteriordb posterior (data as posteriordb ships it, Stan
    program, reference summary); a large one is stored gzipped."""
    path = DATA_DIR / f"{name}.json"
    if path.exists():
        return json.loads(path.read_text())
    return json.loads(gzip.decompress(path.with_suffix(".json.gz").read_bytes()))


RESONANCE_SCALE = 0.003


def resonance_posterior() -> Posterior:
    """The resonance toy with its exact moments (reference MCSE 0) and 20 exact draws."""
    scale = RESONANCE_SCALE
    keys = ["x", "y[1]", "y[2]", "y[3]", "s"]
    rng = np.random.default_rng(28)
    draws = np.column_stack(
        [scale * rng.standard_normal(20), rng.standard_normal((20, 3)), rng.gamma(4.0, 0.25, 20)]
    )
    return Posterior(
        name=RESONANCE,
        model=resonance,
        data={"scale": np.asarray(scale)},
        reported=("x", "y", "s"),
        keys=keys,
        mean=np.array([0.0, 0.0, 0.0, 0.0, 1.0]),
        sd=np.array([scale, 1.0, 1.0, 1.0, 0.5]),
        mcse_mean=np.zeros(5),
        reference_info={"method": "exact", "num_chains": 0, "num_draws": 0},
        draws_sample=draws,
        stan_code=RESONANCE_STAN,
    )


RESONANCE = "resonance-normal_0.003"
EXACT = {RESONANCE: resonance_posterior}  # toy posteriors with exact references
NAMES = (*POSTERIORS, *EXACT)
