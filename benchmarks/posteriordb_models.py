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

:func:`load` returns a :class:`Posterior`; :func:`flatten` turns site values into the
reference's coordinates and :meth:`Posterior.latent` turns reference coordinates back into the
values of the sample sites (inverting the transformed parameters).
"""

from __future__ import annotations

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
    """``logmesquite.stan``: log-log regression on six predictors, flat priors."""
    beta = numpyro.sample("beta", _flat(constraints.real, (7,)))
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
    """The posterior ``name`` (one of :data:`POSTERIORS`)."""
    record = json.loads((DATA_DIR / f"{name}.json").read_text())
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
