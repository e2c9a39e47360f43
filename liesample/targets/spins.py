"""Exact references for classical Heisenberg spins.

The open chain without field (Fisher 1964, with an exact i.i.d. sampler), the periodic chain
by its transfer matrix, and exact von Mises–Fisher draws on ``S²`` (the conditional law of one
spin in a fixed local field, which the heat-bath samplers use).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.foundation.compile import jit
from liesample.foundation.validation import finite_float

__all__ = [
    "HeisenbergChainReference",
    "HeisenbergRingReference",
    "heisenberg_chain_correlation",
    "langevin_function",
    "sample_heisenberg_chain",
    "von_mises_fisher",
    "von_mises_fisher_cosine",
]


def langevin_function(x: npt.ArrayLike) -> np.ndarray:
    """``L(x) = coth x − 1/x`` (``x/3`` near 0, odd), stable for every finite ``x``.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import langevin_function
    >>> langevin_function(np.array([0.0, -1.0])) + langevin_function(np.array([0.0, 1.0]))  # odd
    array([0., 0.])
    """
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    series = x / 3.0 - x**3 / 45.0 + 2.0 * x**5 / 945.0
    return np.where(small, series, 1.0 / np.tanh(safe) - 1.0 / safe)


def heisenberg_chain_correlation(
    n: npt.ArrayLike, beta: float, coupling: float = 1.0
) -> np.ndarray:
    """Exact ``E[s_k·s_{k+n}] = u^n``, ``u = coth(βJ) − 1/(βJ)`` (Fisher 1964).

    For the open classical Heisenberg chain without field or anisotropy, at any length and for
    any ``k``: the bond angles are independent under the Gibbs law. ``n ≥ 0`` (array or int).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import heisenberg_chain_correlation, langevin_function
    >>> c = heisenberg_chain_correlation(np.arange(3), beta=1.0)
    >>> bool(c[0] == 1.0), bool(np.isclose(c[2], langevin_function(1.0) ** 2))
    (True, True)
    """
    n = np.asarray(n)
    if not np.issubdtype(n.dtype, np.integer) or np.any(n < 0):
        raise ValueError(f"n must be a non-negative integer (or array of them), got {n!r}")
    beta = finite_float("beta", beta)
    coupling = finite_float("coupling", coupling)
    return langevin_function(beta * coupling) ** n


@dataclass(frozen=True)
class HeisenbergChainReference:
    """Exact Gibbs law of an open chain of ``length`` spins, ``B = 0``, ``D = 0`` (Fisher 1964).

    With ``K = βJ``, the ``length − 1`` bond cosines ``c_k = s_k·s_{k+1}`` are i.i.d. with
    density ``∝ exp(K c)`` on ``[−1, 1]``: mean ``L(K)`` (Langevin function) and variance
    ``L′(K) = 1/K² − 1/sinh²K``.

    Examples
    --------
    The reference of ``systems.heisenberg((4,))`` at ``β = 1`` (``system.reference(1.0)``):

    >>> import numpy as np
    >>> from liesample.targets import HeisenbergChainReference, langevin_function
    >>> reference = HeisenbergChainReference(length=4, beta=1.0, coupling=1.0)
    >>> bool(np.isclose(reference.correlation(1), langevin_function(1.0)))
    True
    """

    length: int
    beta: float
    coupling: float

    @property
    def u(self) -> float:
        return float(langevin_function(self.beta * self.coupling))

    def correlation(self, n: npt.ArrayLike) -> np.ndarray:
        """``E[s_k·s_{k+n}] = u^n``."""
        return heisenberg_chain_correlation(n, self.beta, self.coupling)

    def bond_variance(self) -> float:
        """``Var(s_k·s_{k+1}) = 1/K² − 1/sinh²K``."""
        k = self.beta * self.coupling
        if abs(k) < 1e-3:
            return 1.0 / 3.0 - k**2 / 15.0  # the series of 1/K² − 1/sinh²K
        return 1.0 / k**2 - 1.0 / math.sinh(k) ** 2

    def energy_mean(self) -> float:
        """``E[h] = −J (length − 1) u``."""
        return -self.coupling * (self.length - 1) * self.u

    def energy_variance(self) -> float:
        """``Var(h) = J² (length − 1) Var(c)``."""
        return self.coupling**2 * (self.length - 1) * self.bond_variance()


def _ring_transfer_ratios(beta, coupling, num_terms=400):
    """``λ_l/λ_0 = i_l(K)/i_0(K)``, ``l = 0, 1, …``: the transfer-kernel eigenvalue ratios.

    ``exp(K s·s') = Σ_l λ_l Σ_m Y_lm(s) Y_lm(s')*`` with ``λ_l = 4π i_l(K)`` (modified spherical
    Bessel function), ``K = βJ``; ``ive`` keeps large ``K`` finite; the ratios fall off like
    ``K^l/(2l+1)!!`` then underflow to 0, so ``num_terms`` terms are exact in float64.
    """
    from scipy.special import ive

    k = beta * coupling
    l = np.arange(num_terms)
    if k == 0.0:
        return (l == 0).astype(float)
    ratios = ive(l + 0.5, abs(k)) / ive(0.5, abs(k))
    return ratios * np.sign(k) ** l  # i_l(−K) = (−1)^l i_l(K)


@dataclass(frozen=True)
class HeisenbergRingReference:
    """Exact Gibbs law of a periodic chain (ring) of ``length`` spins, ``B = 0``, ``D = 0``.

    Transfer matrix on ``S²``: ``Z = Σ_l (2l+1) λ_l^N`` and, since multiplying by ``s`` couples
    ``l`` only to ``l ± 1`` with total weight ``Σ_{m,m',i} |⟨l m|s_i|l+1 m'⟩|² = l + 1``,

        ``E[s_0·s_n] = Σ_l (l+1) (λ_l^{N−n} λ_{l+1}^n + λ_{l+1}^{N−n} λ_l^n) / Z``.

    For ``N → ∞`` this is ``(λ_1/λ_0)^n = uⁿ``, the open chain's law.
    """

    length: int
    beta: float
    coupling: float

    def __post_init__(self):
        if not isinstance(self.length, int) or self.length < 3:
            raise ValueError(f"length must be an int >= 3 (a ring), got {self.length!r}")
        finite_float("beta", self.beta)
        finite_float("coupling", self.coupling)

    def correlation(self, n: npt.ArrayLike) -> np.ndarray:
        """``E[s_k·s_{k+n}]`` on the ring, for integer ``0 ≤ n ≤ length``."""
        n = np.asarray(n)
        if not np.issubdtype(n.dtype, np.integer) or np.any(n < 0) or np.any(n > self.length):
            raise ValueError(f"n must be integers in [0, {self.length}], got {n!r}")
        r = _ring_transfer_ratios(self.beta, self.coupling)
        l = np.arange(r.size - 1)
        big_n = self.length
        z = np.sum((2 * np.arange(r.size) + 1) * r**big_n)
        nn = n[..., None]
        terms = (l + 1) * (
            r[:-1] ** (big_n - nn) * r[1:] ** nn + r[1:] ** (big_n - nn) * r[:-1] ** nn
        )
        return np.sum(terms, axis=-1) / z

    def energy_mean(self) -> float:
        """``E[h] = −J N E[s_0·s_1]``."""
        return float(-self.coupling * self.length * self.correlation(1))


def _orthonormal_frame(n):
    """Two unit vectors ``(e1, e2)`` completing the unit vectors ``n`` (..., 3) to a right-handed
    orthonormal frame, branch-free and continuous except on ``n_z = −1`` (Duff et al. 2017)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = jnp.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    e1 = jnp.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    e2 = jnp.stack([b, sign + y * y * a, -y], axis=-1)
    return e1, e2


def von_mises_fisher_cosine(uniform: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """``1 − w`` for ``w = cos`` of the angle to the mean of a von Mises–Fisher draw on ``S²``.

    ``w`` has density ``∝ exp(κ w)`` on ``[−1, 1]`` (``κ ≥ 0``); inverting its distribution
    function, ``w = 1 + log(u + (1 − u) e^{−2κ})/κ``. With ``v = 1 − u ∈ [0, 1)`` (``uniform``)
    the form ``1 − w = −log1p(v·expm1(−2κ))/κ`` is exact to round-off for tiny ``κ`` (it tends
    to ``2v``, the uniform law) and for huge ``κ`` (``−log(1 − v)/κ``, never ``log 0``), and
    returning ``1 − w`` keeps ``sin = √((1 − w)(1 + w))`` accurate near the mean.
    """
    positive = jnp.asarray(kappa) > 0.0
    safe = jnp.where(positive, kappa, 1.0)
    one_minus_w = -jnp.log1p(uniform * jnp.expm1(-2.0 * safe)) / safe
    return jnp.clip(jnp.where(positive, one_minus_w, 2.0 * uniform), 0.0, 2.0)


def von_mises_fisher(rng_key: jax.Array, direction: ArrayLike, kappa: ArrayLike) -> jax.Array:
    """Exact draws ``s ∈ S²`` with density ``∝ exp(κ s·direction)``, one per leading index.

    ``direction`` (..., 3) are unit vectors and ``kappa`` (...) any finite reals (``κ < 0``
    draws around ``−direction``; ``κ = 0`` is uniform, whatever ``direction`` is). The cosine to
    the mean is :func:`von_mises_fisher_cosine`, the azimuth uniform: the law of
    ``exp(κ s·n)`` factorises so in coordinates ``(w, φ)`` (Archimedes: area ``dw dφ``).
    """
    direction = jnp.asarray(direction)
    kappa = jnp.asarray(kappa, dtype=direction.dtype)
    mean = jnp.where((kappa < 0.0)[..., None], -direction, direction)
    key_w, key_phi = jax.random.split(rng_key)
    batch = mean.shape[:-1]
    one_minus_w = von_mises_fisher_cosine(
        jax.random.uniform(key_w, batch, dtype=mean.dtype), jnp.abs(kappa)
    )
    phi = 2.0 * jnp.pi * jax.random.uniform(key_phi, batch, dtype=mean.dtype)
    sine = jnp.sqrt(one_minus_w * (2.0 - one_minus_w))
    e1, e2 = _orthonormal_frame(mean)
    return (
        (1.0 - one_minus_w)[..., None] * mean
        + (sine * jnp.cos(phi))[..., None] * e1
        + (sine * jnp.sin(phi))[..., None] * e2
    )


def sample_heisenberg_chain(
    rng_key: jax.Array, num_samples: int, length: int, beta: float, coupling: float = 1.0
) -> jax.Array:
    """Exact i.i.d. configurations of the open chain (``B = 0``, ``D = 0``): ``(num, length, 3)``.

    ``s_0`` is uniform and, the bond angles being independent (Fisher 1964), each
    ``s_{k+1}`` is a von Mises–Fisher draw about ``s_k`` with ``κ = βJ``.
    """
    kappa = finite_float("beta", beta) * finite_float("coupling", coupling)
    return _chain_draws(rng_key, int(num_samples), int(length), kappa)


@functools.partial(jit, static_argnums=(1, 2))
def _chain_draws(rng_key, num_samples, length, kappa):
    keys = jax.random.split(rng_key, length)
    first = von_mises_fisher(keys[0], jnp.tile(jnp.array([0.0, 0.0, 1.0]), (num_samples, 1)), 0.0)

    def next_spin(s, key):
        new = von_mises_fisher(key, s, jnp.full(s.shape[:-1], kappa))
        return new, new

    _, rest = jax.lax.scan(next_spin, first, keys[1:])
    return jnp.concatenate([first[:, None], jnp.moveaxis(rest, 0, 1)], axis=1)
