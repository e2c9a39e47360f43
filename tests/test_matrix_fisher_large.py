"""The matrix Fisher normaliser ``log c(F)`` and ``E[R]`` on SO(3) from ``F = 0`` to singular
values of 1e5 (liesample.targets.groups.MatrixFisherLaw, the adaptive reference, and
liesample.interop.numpyro_distributions.MatrixFisher, the traced tanh-sinh rule), against
references computed here without the 1-D integral both use:

- closed forms: ``F = diag(κ, 0, 0)`` (``R₁₁`` is uniform on ``[−1, 1]`` under Haar):
  ``c = sinh κ/κ``, ``E[R₁₁] = coth κ − 1/κ``; ``F = ±κ I`` (the rotation angle ``θ`` has Haar
  density ``(1 − cos θ)/π``): ``c(κ I) = e^{κ}(I₀(2κ) − I₁(2κ))``,
  ``c(−κ I) = e^{−κ}(I₀(2κ) + I₁(2κ))`` (proper singular values ``(κ, κ, −κ)``);
- the Gaussian (Laplace) expansion on ``S³`` where every ``s_j + s_k`` is large: in quaternions
  ``tr(FᵀR) = λ₀ − Σ_i d_i q_i²`` with ``λ₀ = s₁ + s₂ + s₃``, ``d = 2(s₂ + s₃, s₁ + s₃, s₁ + s₂)``,
  and with ``x = (q₁, q₂, q₃)`` on the hemisphere (``dA = dx/√(1 − |x|²)``, ``|S³| = 2π²``)
  ``c = e^{λ₀} π^{−1/2} (d₁d₂d₃)^{−1/2} Σ_n binom(2n, n) 4^{−n} E|x|^{2n}``, ``x_i`` independent
  ``N(0, 1/(2 d_i))`` (an asymptotic series; three terms leave an error ``O(d^{−4})``);
- direct integration over SO(3) at moderate ``F``: ZYZ Euler angles, Haar
  ``sin β dα dβ dγ/(8π²)``, the trapezoid rule in ``α, γ`` and Gauss–Legendre in ``cos β``.

The earlier reference lost the boundary layer (width ``~1/max|s|``) of the integrand next to
``u = 1``: ``log c`` was 39 too low at ``s = (1e4, 1e4, 1e4)`` and ``−∞`` at 1e5.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

pytest.importorskip("numpyro")

from liesample.interop.numpyro_distributions import MatrixFisher
from liesample.targets.groups import MatrixFisherLaw, vmf_mean_resultant_length


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.array([1.0, 1.0, np.sign(np.linalg.det(q))])


@jax.jit
def _jax_batch(Fs):
    law = MatrixFisher(Fs)
    grad = jax.vmap(jax.grad(lambda F: MatrixFisher(F).log_normalizer()))(Fs)
    return law.log_normalizer(), law.mean, grad


BATCH = 24  # every test pads its F's to this batch: one compile for the file


def _jax_values(Fs):
    """``(log c, E[R], ∂ log c/∂F)`` of the traced MatrixFisher for a list of ``F``."""
    padded = np.zeros((BATCH, 3, 3))
    padded[: len(Fs)] = np.stack(Fs)
    return tuple(np.asarray(x)[: len(Fs)] for x in _jax_batch(jnp.asarray(padded)))


def _check(Fs, log_c, means, log_c_tol, mean_tol):
    """Both implementations against the references ``log_c`` and ``means``."""
    jax_log_c, jax_mean, jax_grad = _jax_values(Fs)
    for n, F in enumerate(Fs):
        law = MatrixFisherLaw(F)
        tol = log_c_tol(log_c[n])
        assert abs(law.log_normalizer() - log_c[n]) <= tol, (F, law.log_normalizer(), log_c[n])
        assert abs(jax_log_c[n] - log_c[n]) <= tol, (F, jax_log_c[n], log_c[n])
        if means is not None:
            np.testing.assert_allclose(law.mean(), means[n], rtol=0, atol=mean_tol)
            np.testing.assert_allclose(jax_mean[n], means[n], rtol=0, atol=mean_tol)
            np.testing.assert_allclose(jax_grad[n], means[n], rtol=0, atol=mean_tol)


KAPPAS = [0.0, 1e-6, 0.5, 30.0, 1e3, 1e4, 1e5]


def test_closed_forms_from_zero_to_1e5():
    """``F = 0`` (``log c = 0``), ``diag(κ, 0, 0)``, ``κ I`` and ``−κ I`` for κ up to 1e5."""
    Fs, log_c, means = [], [], []
    for k in KAPPAS:
        x = 2.0 * k
        i0, i1 = special.ive(0, x), special.ive(1, x)
        # log(sinh κ/κ) and its derivative coth κ − 1/κ = A₃(κ), both exact near κ = 0 too.
        log_sinhc = k - math.log(2.0 * k) + math.log1p(-math.exp(-x)) if k > 1e-3 else k * k / 6
        Fs.append(np.diag([k, 0.0, 0.0]))
        log_c.append(log_sinhc)
        means.append(np.diag([vmf_mean_resultant_length(k, 3), 0.0, 0.0]))
        # d/dκ log c(±κ I) = ±tr E[R] and E[R] = m I by symmetry (I₀' = I₁, I₁' = I₀ − I₁/x).
        if k == 0.0:
            plus = minus = (0.0, 0.0)
        else:
            plus = (3.0 * k + math.log(i0 - i1), (-1.0 + 2.0 * i1 / (x * (i0 - i1))) / 3.0)
            minus = (k + math.log(i0 + i1), -(1.0 - 2.0 * i1 / (x * (i0 + i1))) / 3.0)
        for sign, (value, m) in ((1.0, plus), (-1.0, minus)):
            Fs.append(sign * k * np.eye(3))
            log_c.append(value)
            means.append(m * np.eye(3))
    # I₀ − I₁ loses ~log10(8κ) digits to cancellation: the reference's own error.
    _check(Fs, log_c, means, lambda v: 1e-13 + 1e-14 * abs(v), mean_tol=1e-10)


def _laplace_log_c(s):
    """``log c(s)`` by the Gaussian expansion on ``S³`` (module docstring), three terms."""
    d = 2.0 * jnp.stack([s[1] + s[2], s[0] + s[2], s[0] + s[1]])
    variances = 1.0 / (2.0 * d)
    k1, p2, p3 = (jnp.sum(variances**n) for n in (1, 2, 3))
    moments = (k1, k1**2 + 2.0 * p2, k1**3 + 6.0 * k1 * p2 + 8.0 * p3)  # E|x|², E|x|⁴, E|x|⁶
    series = 1.0 + sum(c * m for c, m in zip((0.5, 0.375, 0.3125), moments))
    return jnp.sum(s) - 0.5 * math.log(math.pi) - 0.5 * jnp.sum(jnp.log(d)) + jnp.log(series)


_laplace_value_and_grad = jax.jit(jax.value_and_grad(_laplace_log_c))


LARGE = [
    (1e3, 1e3, 1e3),
    (3e3, 2e3, 1e3),
    (1e4, 1e4, 1e4),  # the earlier reference: 39 too low
    (1e4, 1e4, 0.0),
    (1e4, 5e3, -2e3),  # a reflection in F: a negative proper singular value
    (1e5, 1e5, 1e5),  # the earlier reference: −∞
    (1e5, 1e5, 0.0),
    (1e5, 3e4, -2e4),
]


def test_large_singular_values_match_the_laplace_expansion():
    """``F = U diag(s) Vᵀ`` with random ``U, V ∈ SO(3)``; ``E[R] = U diag(∂ log c/∂s) Vᵀ``."""
    rng = np.random.default_rng(7)
    Fs, log_c, means = [], [], []
    for s in LARGE:
        s = np.array(s)
        u, v = _rotation(rng), _rotation(rng)
        Fs.append(u @ np.diag(s) @ v.T)
        value, slope = _laplace_value_and_grad(jnp.asarray(s))
        log_c.append(float(value))
        means.append(u @ np.diag(np.asarray(slope)) @ v.T)
    # The SVD of F returns s to ~ε‖F‖ (log c ≈ s₁ + s₂ + s₃), the series is exact to O(d⁻⁴).
    _check(Fs, log_c, means, lambda v: 1e-12 + 2e-15 * abs(v), mean_tol=1e-11)


def _euler_angle_quadrature(F, n=48):
    """``(log c, E[R])`` by direct integration over SO(3) in ZYZ Euler angles."""
    angles = 2.0 * np.pi * np.arange(n) / n
    cos_beta, weights = np.polynomial.legendre.leggauss(n)
    sin_beta = np.sqrt(1.0 - cos_beta**2)
    zero, one = np.zeros(n), np.ones(n)
    c, s = np.cos(angles), np.sin(angles)
    rz = np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1),
                   np.stack([zero, zero, one], -1)], -2)  # fmt: skip
    ry = np.stack([np.stack([cos_beta, zero, sin_beta], -1), np.stack([zero, one, zero], -1),
                   np.stack([-sin_beta, zero, cos_beta], -1)], -2)  # fmt: skip
    R = rz[:, None, None] @ ry[None, :, None] @ rz[None, None, :]
    exponent = np.einsum("ij,abcij->abc", F, R)
    peak = exponent.max()
    w = np.exp(exponent - peak) * weights[None, :, None]
    z = w.sum()
    return peak + math.log(z / (2.0 * n * n)), np.einsum("abc,abcij->ij", w, R) / z


def test_moderate_values_match_direct_integration_over_so3():
    """Generic ``F`` (one with ``det F < 0``, one near 0) against Euler-angle quadrature."""
    rng = np.random.default_rng(3)
    Fs = [2.0 * rng.normal(size=(3, 3)), -1.5 * rng.normal(size=(3, 3)),
          np.diag([4.0, 1.0, -0.5]), 1e-3 * rng.normal(size=(3, 3))]  # fmt: skip
    references = [_euler_angle_quadrature(F) for F in Fs]
    assert np.linalg.det(Fs[2]) < 0.0
    _check(Fs, [r[0] for r in references], [r[1] for r in references],
           lambda v: 1e-13, mean_tol=1e-13)  # fmt: skip


MIXED = [
    (1e5, 1.0, 0.0),
    (1e5, 1e-3, -1e-3),
    (1e5, 1e5, -99999.0),  # s₂ + s₃ = 1: concentrated in two directions only
    (1e4, 10.0, -10.0),
    (2e5, 1e5, 3.0),
    (300.0, 299.0, -298.0),
]


def test_mixed_scales_agree_and_the_mean_is_the_gradient():
    """Where only some ``s_j + s_k`` are large: the adaptive and the tanh-sinh quadratures
    agree, and ``E[R]`` (from the other two forms of the integral) is ``∂ log c/∂s`` by
    central differences of ``log c``."""
    Fs = [np.diag(s) for s in MIXED]
    jax_log_c, jax_mean, _ = _jax_values(Fs)
    for n, s in enumerate(MIXED):
        law = MatrixFisherLaw(np.diag(s))
        value = law.log_normalizer()
        assert abs(jax_log_c[n] - value) <= 1e-15 * abs(value) + 1e-13, (s, jax_log_c[n], value)
        np.testing.assert_allclose(jax_mean[n], law.mean(), rtol=0, atol=1e-11)
        h = 1e-3
        slope = [
            (MatrixFisherLaw(np.diag(np.add(s, step))).log_normalizer()
             - MatrixFisherLaw(np.diag(np.subtract(s, step))).log_normalizer()) / (2 * h)
            for step in h * np.eye(3)
        ]  # fmt: skip
        np.testing.assert_allclose(np.diag(law.mean()), slope, rtol=0, atol=1e-6)
