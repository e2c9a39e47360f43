"""Exact references for CP(N−1) chains: unit vectors ``z ∈ Cᴺ`` modulo a phase, ``N ≥ 2``.

The open chain: with ``K = βJ`` the Gibbs law ``∝ exp(K Σ_x |z_x^† z_{x+1}|²)`` on
``(CP^{N−1})^L`` factorises over the bonds. Integrating out the last site about its neighbour
leaves a constant (the Haar law of ``z_{x+1}`` is invariant under the unitaries that fix
``z_x``), so the bond variables ``t_x = |z_x^† z_{x+1}|² ∈ [0, 1]`` are independent. Under the
Haar (Fubini–Study) law the squared moduli of a uniform unit vector of ``Cᴺ`` are a uniform
point of the simplex, so one of them, ``t``, has the base law Beta(1, N − 1), density
``(N − 1)(1 − t)^{N−2}``; tilted by ``e^{Kt}``, the law of a bond is

    ``p(t) ∝ (1 − t)^{N−2} e^{K t}``   on ``[0, 1]``,

with ``E[e^{Kt}]`` under the base law the confluent hypergeometric function ``₁F₁(1; N; K)``.
Its mean and variance are taken here by 1-D quadrature (``scipy.integrate.quad`` with the
algebraic end-point weight ``(1 − t)^{N−2}`` and the exponential shifted so that it never
overflows), which holds for every finite ``K`` and any ``N``. The energy per bond is
``−J E[t]``.

For ``N = 2`` (CP¹ = S²) the Hopf map ``s = z^† σ z`` gives ``|z^† z'|² = (1 + s·s')/2``, so
the CP¹ chain of coupling ``J`` is the O(3) chain of coupling ``J/2`` (plus ``−J/2`` per bond):
``E[t] = (1 + L(K/2))/2`` with ``L`` the Langevin function
(:func:`liesample.targets.spins.langevin_function`).

**The local law.** Given its neighbours, one site of a CP(N−1) lattice has the conditional law
``∝ exp(β z^† M z)`` with ``M = J Σ_y z_y z_y^†`` Hermitian: a complex Bingham law on
``CP^{N−1}``, drawn exactly by :func:`complex_bingham` (Kent, Constable and Er, Statistics and
Computing 14 (2004) 53, describe the same reduction to the simplex; the envelope below is this
module's own). In the eigenbasis ``M = U diag(λ) U^†`` the coordinates ``w = U^† z`` have
squared moduli ``t_k = |w_k|²`` uniform on the simplex under the Haar law and phases
independent and uniform, and ``z^† M z = Σ λ_k t_k``; so ``t`` has density
``∝ exp(−Σ r_k t_k)`` on the simplex, ``r_k = max_j βλ_j − βλ_k ≥ 0`` (zero at the most likely
axis), and the phases stay uniform. :func:`tilted_simplex` draws that density exactly by
rejection, from an envelope that splits the coordinates by their rates: each "fast" one
(large ``r_k``) is an exponential variate ``E_k / r_k``, the "slow" ones (small ``r_k``, and
always those with ``r_k = 0``) share the remaining mass ``1 − S_f`` uniformly (a flat Dirichlet
draw), and the proposal is accepted with probability ``(1 − S_f)^{m} exp(−Σ_slow r_k t_k)``
(``m + 1`` slow coordinates; rejected when ``S_f ≥ 1``). That is the ratio of the target to
the proposal density, at most 1, so the accepted draw has the target law for any split; the
split is chosen per entry (from the rates alone) to keep the acceptance high: all slow is the
uniform proposal (good for small rates), all fast but one the truncated-exponential one (good
for large rates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from liesample.foundation.validation import finite_float, int_at_least
from liesample.targets.open_chain import OpenChainLaw

__all__ = [
    "CPChainReference",
    "check_cp_components",
    "complex_bingham",
    "cp_bond_moments",
    "tilted_simplex",
]

PROPOSALS_PER_ROUND = 4
"""Envelope proposals drawn at once per entry: a round keeps the first accepted one, and only an
entry whose proposals are all rejected needs another round of the rejection loop."""


def check_cp_components(n) -> int:
    """``N`` (the complex components of ``z``, the ``N`` of CP(N−1)) as an int ``≥ 2``, or a
    ``TypeError``/``ValueError`` naming ``N``."""
    return int_at_least("N", n, "complex components of z: 2 for CP(1), 3 for CP(2), ...", minimum=2)


def cp_bond_moments(n: int, beta: float, coupling: float = 1.0) -> tuple[float, float]:
    """``(E[t], Var t)`` of one bond ``t = |z_x^† z_{x+1}|²`` of the open CP(N−1) chain, the law
    ``∝ (1 − t)^{N−2} e^{Kt}`` on ``[0, 1]``, ``K = βJ`` (module docstring), by quadrature.

    Examples
    --------
    >>> from liesample.targets import cp_bond_moments
    >>> mean, variance = cp_bond_moments(3, beta=0.0)  # Beta(1, 2): mean 1/3, variance 1/18
    >>> round(mean, 12), round(variance, 12)
    (0.333333333333, 0.055555555556)
    """
    from scipy import integrate

    n = check_cp_components(n)
    k = finite_float("beta", beta) * finite_float("coupling", coupling)
    shift = max(k, 0.0)  # e^{K t − shift} ≤ 1 on [0, 1]

    def moment(p: int) -> float:
        value, _ = integrate.quad(
            lambda t: t**p * math.exp(k * t - shift),
            0.0,
            1.0,
            weight="alg",
            wvar=(0.0, float(n - 2)),
            epsabs=0.0,
            epsrel=1e-13,
            limit=200,
        )
        return value

    z = moment(0)
    mean = moment(1) / z
    variance = moment(2) / z - mean**2
    return mean, max(variance, 0.0)


@dataclass(frozen=True)
class CPChainReference(OpenChainLaw):
    """Exact Gibbs law of an open chain of ``length`` CP(N−1) sites (module docstring): the
    ``length − 1`` bond variables ``t = |z_x^† z_{x+1}|²`` are i.i.d. with the mean and variance
    of :func:`cp_bond_moments`.

    Examples
    --------
    The reference of ``systems.cp_model((12,), N=3)`` (the CP(2) chain) at ``β = 2``:

    >>> from liesample.targets import CPChainReference
    >>> reference = CPChainReference(length=12, n=3, beta=2.0)
    >>> bool(1 / 3 < reference.bond_mean() < 1)  # ferromagnetic: above the Haar value 1/N
    True
    >>> bool(abs(reference.bond_energy_mean() + reference.bond_mean()) < 1e-15)  # −J E[t]
    True
    """

    @staticmethod
    def check_components(n) -> int:
        """``n`` checked by :func:`check_cp_components`."""
        return check_cp_components(n)

    def bond_mean(self) -> float:
        """``E[|z_x^† z_{x+1}|²]``."""
        return cp_bond_moments(self.n, self.beta, self.coupling)[0]

    def bond_variance(self) -> float:
        """``Var(|z_x^† z_{x+1}|²)``."""
        return cp_bond_moments(self.n, self.beta, self.coupling)[1]


def _split_scores(rates):
    """A score per split ``j = 0 … N−1`` of the sorted rates (``j + 1`` slow coordinates, the
    rest fast): a rough log acceptance of :func:`tilted_simplex`'s envelope,
    ``−max(j, 1) Σ_fast 1/r − Σ_slow r/(j + 1)`` (``−inf`` where a zero rate would be fast)."""
    ordered = jnp.sort(rates, axis=-1)
    n = rates.shape[-1]
    inverse = jnp.where(ordered > 0.0, 1.0 / jnp.where(ordered > 0.0, ordered, 1.0), jnp.inf)
    # fast_inverse[j] = Σ_{i > j} 1/r_(i); slow_sum[j] = Σ_{i ≤ j} r_(i)
    tail = jnp.cumsum(inverse[..., ::-1], axis=-1)[..., ::-1]
    fast_inverse = jnp.concatenate([tail[..., 1:], jnp.zeros_like(tail[..., :1])], axis=-1)
    slow_sum = jnp.cumsum(ordered, axis=-1)
    j = jnp.arange(n, dtype=rates.dtype)
    scores = -jnp.maximum(j, 1.0) * fast_inverse - slow_sum / (j + 1.0)
    return ordered, scores


def tilted_simplex(rng_key: jax.Array, rates: ArrayLike) -> jax.Array:
    """Exact draws ``t`` on the simplex ``{t_k ≥ 0, Σ t_k = 1}`` with density
    ``∝ exp(−Σ_k r_k t_k)`` (Lebesgue measure on the simplex), one per leading index.

    ``rates`` (..., N) are finite, ``≥ 0``, with a zero in every row (subtract the row minimum
    first: the law does not change). Rejection from the split envelope of the module docstring,
    :data:`PROPOSALS_PER_ROUND` proposals per entry and round, rounds repeated until every
    entry has an accepted one. All-zero rates give the uniform law on the simplex (every
    proposal accepted).

    Examples
    --------
    >>> import jax, jax.numpy as jnp
    >>> from liesample.targets import tilted_simplex
    >>> t = tilted_simplex(jax.random.key(0), jnp.array([[0.0, 5.0, 50.0]] * 4))
    >>> t.shape, bool(jnp.allclose(t.sum(-1), 1.0)), bool(jnp.all(t >= 0))
    ((4, 3), True, True)
    """
    rates = jnp.asarray(rates)
    rates = rates.astype(jnp.result_type(rates.dtype, float))
    dtype, n = rates.dtype, rates.shape[-1]
    ordered, scores = _split_scores(rates)
    best = jnp.argmax(scores, axis=-1)
    threshold = jnp.take_along_axis(ordered, best[..., None], axis=-1)
    fast = rates > threshold  # (..., N): ties and zero rates are slow
    slow_count = jnp.sum(~fast, axis=-1).astype(dtype)  # ≥ 1 (the zero rate)
    shape = (*rates.shape[:-1], PROPOSALS_PER_ROUND, n)
    fast_p, rates_p = fast[..., None, :], rates[..., None, :]

    def body(carry):
        key, draw, done = carry
        key, key_e, key_u = jax.random.split(key, 3)
        e = jax.random.exponential(key_e, shape, dtype=dtype)
        safe_rates = jnp.where(fast_p, rates_p, 1.0)
        fast_t = jnp.where(fast_p, e / safe_rates, 0.0)
        left = 1.0 - jnp.sum(fast_t, axis=-1, keepdims=True)  # mass of the slow coordinates
        slow_e = jnp.where(fast_p, 0.0, e)
        share = slow_e / jnp.sum(slow_e, axis=-1, keepdims=True)
        candidate = jnp.where(fast_p, fast_t, jnp.maximum(left, 0.0) * share)
        log_accept = (slow_count[..., None] - 1.0) * jnp.log(jnp.maximum(left[..., 0], 0.0))
        log_accept = log_accept - jnp.sum(jnp.where(fast_p, 0.0, rates_p * candidate), axis=-1)
        log_u = jnp.log(jax.random.uniform(key_u, shape[:-1], dtype=dtype))
        accept = (left[..., 0] > 0.0) & (log_u <= log_accept)
        first = jnp.argmax(accept, axis=-1)
        chosen = jnp.take_along_axis(candidate, first[..., None, None], axis=-2)[..., 0, :]
        take = (jnp.any(accept, axis=-1) & ~done)[..., None]
        return key, jnp.where(take, chosen, draw), done | take[..., 0]

    start = (rng_key, jnp.zeros_like(rates), jnp.zeros(rates.shape[:-1], bool))
    _, draw, _ = jax.lax.while_loop(lambda carry: ~jnp.all(carry[2]), body, start)
    return draw


def complex_bingham(rng_key: jax.Array, matrix: ArrayLike, kappa: ArrayLike = 1.0) -> jax.Array:
    """Exact draws of unit vectors ``z ∈ Cᴺ`` with density ``∝ exp(κ z^† M z)`` with respect to
    the uniform law of the unit sphere (equivalently, of their rays in ``CP^{N−1}``), one per
    leading index.

    ``matrix`` (..., N, N) are Hermitian ``M`` (complex or real symmetric), ``kappa`` (...)
    finite reals (any sign). In the eigenbasis of ``M`` the squared moduli come from
    :func:`tilted_simplex` and the phases are uniform (module docstring); ``M = 0`` or
    ``κ = 0`` gives the uniform law. The overall phase of each draw is uniform too (it is no
    part of the ray).

    Examples
    --------
    >>> import jax, jax.numpy as jnp
    >>> from liesample.targets import complex_bingham
    >>> m = jnp.diag(jnp.array([1.0, 0.0, 0.0])).astype(complex)  # favours the axis e_1
    >>> z = complex_bingham(jax.random.key(0), jnp.tile(m, (5, 1, 1)), 20.0)
    >>> z.shape, bool(jnp.allclose(jnp.linalg.norm(z, axis=-1), 1.0))
    ((5, 3), True)
    """
    matrix = jnp.asarray(matrix)
    dtype = jnp.result_type(matrix.dtype, complex)
    matrix = matrix.astype(dtype)
    values, vectors = jnp.linalg.eigh(matrix)
    exponent = jnp.asarray(kappa, dtype=values.dtype)[..., None] * values
    rates = jnp.max(exponent, axis=-1, keepdims=True) - exponent
    key_t, key_phase = jax.random.split(rng_key)
    t = tilted_simplex(key_t, rates)
    phase = jax.random.uniform(key_phase, t.shape, dtype=values.dtype, maxval=2.0 * math.pi)
    w = jnp.sqrt(t) * jnp.exp(1j * phase)
    return jnp.einsum("...ij,...j->...i", vectors, w)
