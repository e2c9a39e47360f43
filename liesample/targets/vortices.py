"""Exact references for point vortices on the sphere (paper, ``sec:stoch-diss-point-vortices``).

With ``h = −Σ_{j<k} (Γ_jΓ_k/2π) log|x_j − x_k|`` the Gibbs law is

    ∝ Π_{j<k} |x_j − x_k|^{βΓ_jΓ_k/(2π)} = Π_{j<k} (|x_j − x_k|²)^{p_jk},   p_jk = βΓ_jΓ_k/(4π),

times the area measure on ``(S²)^N`` (the paper's ``eq:gibbs-point-vortex`` prints
``exp(−(β/2)h)``, a slip: the equations as written leave ``exp(−βh)`` invariant).
It depends on the positions only through the unit vectors, so it is the same on a sphere of
any radius.

- **Pair law** (:class:`VortexPairLaw`, ``N = 2``): ``c = x₁·x₂`` (unit vectors) has density
  ``∝ (2 − 2c)^p`` on ``[−1, 1]`` (``c`` is uniform under the area measure, Archimedes), so
  ``u = (1 − c)/2`` is ``Beta(p + 1, 1)``: everything is in closed form.
- **Normalisability** (:func:`beta_bounds`): the law is a probability measure iff for every
  cluster ``S`` of ``n ≥ 2`` vortices ``Σ_{j<k ∈ S} p_jk > −(n − 1)`` (the cluster collapsing
  at scale ``ε`` has volume ``ε^{2(n−1)}`` and weight ``ε^{2Σp}``). For ``β < 0`` the worst
  clusters are the ``n`` strongest vortices of one sign (:func:`beta_bounds` proves it in a
  comment), so the check is exact for any ``N``; for ``N = 2`` it is the pair condition
  ``p > −1``. For ``β > 0`` only clusters containing both signs can fail; the opposite-signed
  pairs give the bound (checked by exhaustive enumeration of clusters for ``N ≤ 12``).
- **Independent Monte Carlo reference** (:func:`gibbs_expectation`): self-normalised importance
  sampling from i.i.d. uniform points, for ``N ≥ 3`` where no closed form exists.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import jax
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float, nonzero_circulations

__all__ = [
    "VortexPairLaw",
    "beta_bounds",
    "check_vortex_beta",
    "gibbs_expectation",
    "pair_exponents",
    "uniform_sphere_points",
]

_ENUMERATE_UP_TO = 12


def pair_exponents(circulations: ArrayLike, beta: float) -> np.ndarray:
    """``p_jk = βΓ_jΓ_k/(4π)`` for every pair (symmetric matrix, zero diagonal)."""
    gamma = nonzero_circulations(circulations)
    beta = finite_float("beta", beta)
    p = beta * np.outer(gamma, gamma) / (4.0 * math.pi)
    np.fill_diagonal(p, 0.0)
    return p


def beta_bounds(circulations: ArrayLike) -> tuple[float, float]:
    """The open interval ``(β_min, β_max)`` of ``β`` for which the Gibbs law is normalisable.

    ``β < 0``: a cluster ``S`` needs ``β Σ_{j<k∈S} Γ_jΓ_k /(4π) > −(n−1)``. Split a mixed
    cluster into its positive part ``P`` (sum ``a``) and negative part ``Q`` (sum of magnitudes
    ``b``): ``2Σ_{j<k} Γ_jΓ_k = (a − b)² − Σ_S Γ²``, which is at most that of ``P`` (if
    ``a ≥ b``) or ``Q``, with fewer vortices, so the worst clusters have one sign; among those
    of size ``n`` the pair sum grows with every ``|Γ|``, so the worst is the ``n`` largest.
    ``β > 0``: same-sign clusters never fail; the opposite-signed pair with the largest
    ``|Γ_jΓ_k|`` gives ``β < 4π/|Γ_jΓ_k|``, and for ``N ≤ 12`` every cluster is enumerated.

    Examples
    --------
    Two like-signed unit vortices: any ``β > −4π``; an opposite pair: any ``β < 4π``:

    >>> import numpy as np
    >>> from liesample.targets import beta_bounds
    >>> bool(np.isclose(beta_bounds([1.0, 1.0])[0], -4 * np.pi)), beta_bounds([1.0, 1.0])[1]
    (True, inf)
    """
    gamma = nonzero_circulations(circulations)
    beta_min = -math.inf
    for sign in (1.0, -1.0):
        strengths = np.sort(np.abs(gamma[np.sign(gamma) == sign]))[::-1]
        sums, squares = np.cumsum(strengths), np.cumsum(strengths**2)
        for n in range(2, strengths.size + 1):
            pair_sum = 0.5 * (sums[n - 1] ** 2 - squares[n - 1])
            beta_min = max(beta_min, -4.0 * math.pi * (n - 1) / pair_sum)
    positive, negative = gamma[gamma > 0], -gamma[gamma < 0]
    beta_max = math.inf
    if positive.size and negative.size:
        beta_max = 4.0 * math.pi / (positive.max() * negative.max())
    if gamma.size <= _ENUMERATE_UP_TO:
        for n in range(3, gamma.size + 1):
            for cluster in itertools.combinations(range(gamma.size), n):
                g = gamma[list(cluster)]
                pair_sum = 0.5 * (g.sum() ** 2 - np.sum(g**2))
                if pair_sum < 0:
                    beta_max = min(beta_max, -4.0 * math.pi * (n - 1) / pair_sum)
    return beta_min, beta_max


def check_vortex_beta(circulations: ArrayLike, beta: float) -> None:
    """``ValueError`` naming the bound when ``exp(−βh)`` is not normalisable (see
    :func:`beta_bounds`).

    Examples
    --------
    >>> from liesample.targets import check_vortex_beta
    >>> check_vortex_beta([1.0, -1.0], beta=1.0)  # normalisable: no error
    >>> check_vortex_beta([1.0, -1.0], beta=100.0)
    Traceback (most recent call last):
    ValueError: beta = 100 makes the point-vortex Gibbs law non-normalisable: ...
    """
    beta = finite_float("beta", beta)
    beta_min, beta_max = beta_bounds(circulations)
    if not beta_min < beta < beta_max:
        raise ValueError(
            f"beta = {beta:g} makes the point-vortex Gibbs law non-normalisable: it needs "
            f"{beta_min:.6g} < beta < {beta_max:.6g} "
            f"for circulations {list(map(float, np.ravel(circulations)))} "
            "(every cluster S of n >= 2 vortices must have Σ_{j<k in S} βΓ_jΓ_k/(4π) > −(n−1); "
            "for a pair, the exponent βΓ_jΓ_k/(4π) must be > −1)"
        )


@dataclass(frozen=True)
class VortexPairLaw:
    """Exact law of ``c = x₁·x₂`` for two vortices: density ``∝ (2 − 2c)^p``, ``p = βΓ₁Γ₂/(4π)``.

    ``u = (1 − c)/2 ~ Beta(p + 1, 1)``: density ``(p + 1) u^p`` on ``[0, 1]``, CDF ``u^{p+1}``.
    Requires ``p > −1``.

    Examples
    --------
    At ``p = 0`` (``β = 0``) ``c = x₁·x₂`` is uniform on ``[−1, 1]``:

    >>> import numpy as np
    >>> from liesample.targets import VortexPairLaw
    >>> law = VortexPairLaw(exponent=0.0)
    >>> bool(np.isclose(law.mean(), 0.0)), bool(np.isclose(law.variance(), 1 / 3))
    (True, True)
    """

    exponent: float

    def __post_init__(self):
        p = finite_float("exponent", self.exponent)
        if not p > -1.0:
            raise ValueError(
                f"exponent must be > -1 for the pair law (2-2c)^p to be normalisable, got {p}"
            )

    @classmethod
    def from_circulations(cls, circulations: ArrayLike, beta: float) -> VortexPairLaw:
        gamma = nonzero_circulations(circulations)
        if gamma.shape != (2,):
            raise ValueError(f"the pair law needs exactly 2 circulations, got {gamma.size}")
        check_vortex_beta(gamma, beta)
        return cls(float(beta) * gamma[0] * gamma[1] / (4.0 * math.pi))

    def density(self, c: npt.ArrayLike) -> np.ndarray:
        """``2(p+1)(2 − 2c)^p / 4^{p+1}`` on ``[−1, 1]``."""
        c = np.asarray(c, dtype=float)
        p = self.exponent
        inside = (c >= -1.0) & (c <= 1.0)
        u = np.clip((1.0 - c) / 2.0, 0.0, 1.0)
        with np.errstate(divide="ignore"):
            value = 0.5 * (p + 1.0) * u**p
        return np.where(inside, value, 0.0)

    def cdf(self, c: npt.ArrayLike) -> np.ndarray:
        """``P(x₁·x₂ ≤ c) = 1 − ((1 − c)/2)^{p+1}``."""
        u = np.clip((1.0 - np.asarray(c, dtype=float)) / 2.0, 0.0, 1.0)
        return 1.0 - u ** (self.exponent + 1.0)

    def mean(self) -> float:
        """``E[c] = −p/(p + 2)``."""
        p = self.exponent
        return -p / (p + 2.0)

    def variance(self) -> float:
        """``Var c = 4 Var u = 4(p+1)/((p+2)²(p+3))``."""
        p = self.exponent
        return 4.0 * (p + 1.0) / ((p + 2.0) ** 2 * (p + 3.0))

    def sample(self, rng_key: jax.Array, num_samples: int) -> np.ndarray:
        """Exact i.i.d. draws of ``c``: ``u = V^{1/(p+1)}``, ``V`` uniform."""
        v = np.asarray(jax.random.uniform(rng_key, (num_samples,), dtype=float))
        return 1.0 - 2.0 * v ** (1.0 / (self.exponent + 1.0))


def uniform_sphere_points(rng_key: jax.Array, shape: tuple[int, ...]) -> np.ndarray:
    """I.i.d. uniform unit vectors, shape ``(*shape, 3)`` (normalised Gaussians), as numpy."""
    g = np.asarray(jax.random.normal(rng_key, (*shape, 3), dtype=float))
    return g / np.linalg.norm(g, axis=-1, keepdims=True)


def gibbs_expectation(
    circulations: ArrayLike,
    beta: float,
    observable: Callable[[np.ndarray], npt.ArrayLike],
    rng_key: jax.Array,
    num_samples: int = 2**20,
    chunk: int = 2**16,
) -> tuple[np.ndarray, np.ndarray, float]:
    """``E[f(x)]`` under the Gibbs law by self-normalised importance sampling from uniform points.

    An independent reference (no dynamics): weights ``Π_{j<k} (|x_j − x_k|²)^{p_jk}`` on i.i.d.
    uniform ``x ∈ (S²)^N``. ``observable`` maps positions ``(n, N, 3)`` to values ``(n, k)``
    (numpy). Returns ``(estimate, standard_error, effective_sample_size)``, arrays ``(k,)`` and
    a float; the standard error is the delta-method one of a ratio estimator. Finite variance
    needs ``Σ_{j<k∈S} 2p_jk > −(n−1)`` on every cluster (e.g. every ``p_jk > −1/2``).

    Examples
    --------
    ``E[x₁·x₂]`` of a pair at ``β = 0`` (exactly 0), with its standard error:

    >>> from liesample.targets import gibbs_expectation
    >>> cosine = lambda x: (x[:, 0] * x[:, 1]).sum(-1, keepdims=True)
    >>> estimate, error, ess = gibbs_expectation([1.0, 1.0], 0.0, cosine, jax.random.key(0),
    ...                                          num_samples=4096)
    >>> estimate.shape, bool(abs(estimate[0]) < 5 * error[0])
    ((1,), True)
    """
    gamma = nonzero_circulations(circulations)
    check_vortex_beta(gamma, beta)
    p = pair_exponents(gamma, beta)
    iu = np.triu_indices(gamma.size, 1)
    log_weights, values = [], []
    keys = jax.random.split(rng_key, -(-num_samples // chunk))
    remaining = num_samples
    for key in keys:
        n = min(chunk, remaining)
        remaining -= n
        x = uniform_sphere_points(key, (n, gamma.size))
        diff = x[:, :, None, :] - x[:, None, :, :]
        d2 = np.sum(diff * diff, axis=-1)[:, iu[0], iu[1]]
        log_weights.append(np.log(d2) @ p[iu])
        values.append(np.asarray(observable(x), dtype=float).reshape(n, -1))
    log_w = np.concatenate(log_weights)
    f = np.concatenate(values)
    w = np.exp(log_w - log_w.max())
    w = w / w.sum()
    estimate = w @ f
    standard_error = np.sqrt(np.sum(w[:, None] ** 2 * (f - estimate) ** 2, axis=0))
    return estimate, standard_error, float(1.0 / np.sum(w**2))
