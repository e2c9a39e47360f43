"""Exact references for O(n) spins (unit vectors in Rⁿ, ``n ≥ 2``), and exact von Mises–Fisher
draws on every sphere ``S^{n−1}``.

The open chain without field: with ``K = βJ`` the Gibbs law ``∝ exp(K Σ_k s_k·s_{k+1})`` on
``(S^{n−1})^N`` factorises over the bonds. Integrating out the last spin about its neighbour
leaves a constant, so the bond cosines ``c_k = s_k·s_{k+1}`` are independent, each with
density ``∝ exp(K c) (1 − c²)^{(n−3)/2}`` on ``[−1, 1]`` (the law of one coordinate of a
uniform point of ``S^{n−1}``, tilted). Its mean is

    ``u = A_n(K) = I_{n/2}(K) / I_{n/2−1}(K)``

(modified Bessel functions), and, given ``s_k``, ``E[s_{k+1} | s_k] = u s_k``, so
``E[s_x·s_{x+r}] = uʳ`` at any length and any ``x``. ``A_n`` is odd in ``K``; ``n = 3`` gives
the Langevin function ``coth K − 1/K`` (:func:`liesample.targets.spins.langevin_function`) and
``n = 2`` the XY chain's ``I₁(K)/I₀(K)``. The variance of a bond is ``A_n′(K) = 1 − u² −
(n − 1) u / K`` (the Riccati equation of the Bessel ratio).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float, int_at_least
from liesample.targets.open_chain import OpenChainLaw

__all__ = [
    "NVectorChainReference",
    "check_spin_components",
    "n_vector_bond_mean",
    "n_vector_bond_variance",
    "von_mises_fisher_sphere",
]

_SERIES_BELOW = 1e-4
"""``|K|`` below which the Bessel ratio and its derivative are taken from their Taylor series
(the ratio of two tiny ``ive`` values would lose digits, and ``0/0`` at ``K = 0``)."""


def check_spin_components(n) -> int:
    """``n`` (the number of components of a spin, the ``n`` of O(n)) as an int ``≥ 2``, or a
    ``TypeError``/``ValueError`` naming ``n``."""
    what = "spin components: 2 for XY, 3 for Heisenberg, 4 for O(4)"
    return int_at_least("n", n, what, minimum=2)


def n_vector_bond_mean(n: int, beta: float, coupling: float = 1.0) -> float:
    """``u = E[s_x·s_{x+1}] = I_{n/2}(K)/I_{n/2−1}(K)``, ``K = βJ``, of the open O(n) chain
    without field (module docstring); exponentially scaled Bessel functions keep large ``|K|``
    finite.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.targets import langevin_function, n_vector_bond_mean
    >>> bool(np.isclose(n_vector_bond_mean(3, beta=2.0), langevin_function(2.0)))  # O(3)
    True
    """
    from scipy.special import ive

    n = check_spin_components(n)
    k = finite_float("beta", beta) * finite_float("coupling", coupling)
    if abs(k) < _SERIES_BELOW:
        return k / n - k**3 / (n**2 * (n + 2))
    return math.copysign(float(ive(n / 2, abs(k)) / ive(n / 2 - 1, abs(k))), k)


def n_vector_bond_variance(n: int, beta: float, coupling: float = 1.0) -> float:
    """``Var(s_x·s_{x+1}) = 1 − u² − (n − 1) u / K`` of the open O(n) chain without field
    (``1/n`` at ``K = 0``).

    Examples
    --------
    >>> from liesample.targets import n_vector_bond_variance
    >>> n_vector_bond_variance(4, beta=0.0)  # a coordinate of a uniform point of S³
    0.25
    """
    n = check_spin_components(n)
    k = finite_float("beta", beta) * finite_float("coupling", coupling)
    if abs(k) < _SERIES_BELOW:
        return 1.0 / n - 3.0 * k**2 / (n**2 * (n + 2))
    u = n_vector_bond_mean(n, beta, coupling)
    return 1.0 - u**2 - (n - 1) * u / k


@dataclass(frozen=True)
class NVectorChainReference(OpenChainLaw):
    """Exact Gibbs law of an open chain of ``length`` O(n) spins without field (module
    docstring): the ``length − 1`` bond cosines are i.i.d. with mean ``u`` and variance
    :func:`n_vector_bond_variance`.

    Examples
    --------
    The reference of ``systems.n_vector((16,), n=2)`` (the XY chain) at ``β = 1``:

    >>> from liesample.targets import NVectorChainReference
    >>> reference = NVectorChainReference(length=16, n=2, beta=1.0, coupling=1.0)
    >>> bool(abs(reference.correlation(2) - reference.u**2) < 1e-15)
    True
    >>> bool(abs(reference.bond_energy_mean() + reference.u) < 1e-15)  # −J u per bond
    True
    """

    @staticmethod
    def check_components(n) -> int:
        """``n`` checked by :func:`check_spin_components`."""
        return check_spin_components(n)

    @property
    def u(self) -> float:
        """``E[s_x·s_{x+1}]``."""
        return n_vector_bond_mean(self.n, self.beta, self.coupling)

    def bond_mean(self) -> float:
        """``E[s_x·s_{x+1}] = u``."""
        return self.u

    def correlation(self, r: npt.ArrayLike) -> np.ndarray:
        """``E[s_x·s_{x+r}] = uʳ`` for integer ``0 ≤ r ≤ length − 1``."""
        r = np.asarray(r)
        if not np.issubdtype(r.dtype, np.integer) or np.any(r < 0) or np.any(r >= self.length):
            raise ValueError(
                f"r must be integers in [0, {self.length - 1}] (distances along the chain of "
                f"{self.length} sites), got {r!r}"
            )
        return np.float64(self.u) ** r

    def bond_variance(self) -> float:
        """``Var(s_x·s_{x+1})``."""
        return n_vector_bond_variance(self.n, self.beta, self.coupling)


PROPOSALS_PER_ROUND = 4
"""Wood proposals drawn at once per entry: a round keeps the first accepted one, and only an
entry whose four proposals are all rejected needs another round, so the rejection loop (whose
rounds every entry of a vectorised call waits for) seldom runs twice."""


def _symmetric_beta(rng_key, shape, n: int, dtype):
    """``z ~ Beta((n−1)/2, (n−1)/2)`` of shape ``shape``, as ``(1 + t)/2`` with ``t = g₁/|g|``
    the first coordinate of a uniform point of ``S^{n−1}`` (``g ~ N(0, Iₙ)``). The smaller of
    ``z`` and ``1 − z`` is ``|g_rest|²/(2|g|(|g| + |g₁|))``, free of cancellation at both ends;
    the sign of ``g₁`` picks which one ``z`` is."""
    g = jax.random.normal(rng_key, (*shape, n), dtype=dtype)
    rest = jnp.sum(g[..., 1:] ** 2, axis=-1)
    norm = jnp.sqrt(rest + g[..., 0] ** 2)
    small = rest / (2.0 * norm * (norm + jnp.abs(g[..., 0])))
    return jnp.where(g[..., 0] < 0.0, small, 1.0 - small)


def _wood_one_minus_w(rng_key, kappa, n: int):
    """``1 − w``, ``w`` the cosine to the mean of a von Mises–Fisher draw on ``S^{n−1}``
    (density ``∝ exp(κ w)(1 − w²)^{(n−3)/2}``, ``κ ≥ 0``, shape of ``kappa``): Wood's (1994)
    rejection sampler with its Beta proposal, :data:`PROPOSALS_PER_ROUND` proposals per entry
    and round, the first accepted one kept, rounds repeated until every entry has one.

    With ``m = n − 1``, ``b = m/(2κ + √(4κ² + m²))``, ``x₀ = (1 − b)/(1 + b)`` and
    ``z ~ Beta(m/2, m/2)``, the proposal ``w = (1 − (1 + b)z)/(1 − (1 − b)z)`` is accepted when
    ``κ(w − x₀) + m log((1 − x₀w)/(1 − x₀²)) ≥ log U``; everything is written in ``1 − w`` and
    ``t = 1 − x₀ = 2b/(1 + b)``, which stay accurate when ``κ`` is large and ``w`` near 1. At
    ``κ = 0`` every proposal is accepted and ``(1 + w)/2 ~ Beta(m/2, m/2)``: the uniform law.
    """
    m = n - 1.0
    b = (m / (2.0 * kappa + jnp.sqrt(4.0 * kappa**2 + m**2)))[..., None]
    t = 2.0 * b / (1.0 + b)
    x0 = 1.0 - t
    shape = (*kappa.shape, PROPOSALS_PER_ROUND)

    def body(carry):
        key, one_minus_w, done = carry
        key, key_z, key_u = jax.random.split(key, 3)
        z = _symmetric_beta(key_z, shape, n, kappa.dtype)
        candidate = 2.0 * b * z / (1.0 - (1.0 - b) * z)
        log_ratio = jnp.log1p(x0 * candidate / t) - jnp.log1p(x0)
        log_u = jnp.log(jax.random.uniform(key_u, shape, dtype=kappa.dtype))
        accept = kappa[..., None] * (t - candidate) + m * log_ratio >= log_u
        first = jnp.argmax(accept, axis=-1)
        chosen = jnp.take_along_axis(candidate, first[..., None], axis=-1)[..., 0]
        take = jnp.any(accept, axis=-1) & ~done
        return key, jnp.where(take, chosen, one_minus_w), done | take

    start = (rng_key, jnp.zeros_like(kappa), jnp.zeros(kappa.shape, bool))
    _, one_minus_w, _ = jax.lax.while_loop(lambda carry: ~jnp.all(carry[2]), body, start)
    return jnp.clip(one_minus_w, 0.0, 2.0)


def von_mises_fisher_sphere(
    rng_key: jax.Array, direction: ArrayLike, kappa: ArrayLike
) -> jax.Array:
    """Exact draws ``s ∈ S^{n−1}`` with density ``∝ exp(κ s·direction)``, one per leading index,
    for any ``n = direction.shape[-1] ≥ 2``.

    ``direction`` (..., n) are unit vectors (a zero row stands for any direction: its ``κ``
    multiplies nothing, so pass ``κ = 0`` there for the uniform law) and ``kappa`` (...) finite
    reals (``κ < 0`` draws about ``−direction``). The cosine ``w`` to the mean comes from
    :func:`_wood_one_minus_w`; the rest of the draw is uniform on the sphere ``S^{n−2}``
    orthogonal to the mean (a Gaussian vector with its mean component removed, normalised).
    On ``S²`` the closed form :func:`liesample.targets.spins.von_mises_fisher` draws the same
    law with fewer random numbers.

    Examples
    --------
    >>> import jax, jax.numpy as jnp
    >>> from liesample.targets import von_mises_fisher_sphere
    >>> mean = jnp.tile(jnp.array([0.0, 0.0, 0.0, 1.0]), (5, 1))  # on S³
    >>> s = von_mises_fisher_sphere(jax.random.key(0), mean, 10.0)
    >>> s.shape, bool(jnp.allclose(jnp.linalg.norm(s, axis=-1), 1.0))
    ((5, 4), True)
    """
    direction = jnp.asarray(direction)
    n = direction.shape[-1]
    check_spin_components(n)
    dtype = jnp.result_type(direction.dtype, float)
    direction = direction.astype(dtype)
    batch = direction.shape[:-1]
    kappa = jnp.broadcast_to(jnp.asarray(kappa, dtype=dtype), batch)
    zero = jnp.all(direction == 0.0, axis=-1, keepdims=True)
    fallback = jnp.zeros(n, dtype).at[-1].set(1.0)
    mean = jnp.where(zero, fallback, direction)
    mean = jnp.where((kappa < 0.0)[..., None], -mean, mean)
    key_w, key_v = jax.random.split(rng_key)
    one_minus_w = _wood_one_minus_w(key_w, jnp.abs(kappa), n)
    g = jax.random.normal(key_v, (*batch, n), dtype=dtype)
    g = g - jnp.sum(g * mean, axis=-1, keepdims=True) * mean
    v = g / jnp.linalg.norm(g, axis=-1, keepdims=True)
    sine = jnp.sqrt(one_minus_w * (2.0 - one_minus_w))
    return (1.0 - one_minus_w)[..., None] * mean + sine[..., None] * v
