"""The periodic O(n) and CP(N−1) rings' transfer-matrix references
(``targets.NVectorRingReference``, ``targets.CPRingReference``).

References, written independently of the samplers:

- direct numerical integration over ``(S^{n−1})^L`` with the first spin fixed (rotation
  invariance): ``L = 3`` for ``n = 2, 3, 4`` (tensor Gauss–Legendre grids in the polar angles
  and the relative azimuth), ``L = 4`` for ``n = 2`` (the periodic trapezoid rule in three
  angles, which gives ``E[s_0·s_2]``, a correlation beyond the bond);
- ``L = 2``, the two sites joined twice: one bond at ``2K``, the open chain's Bessel ratio;
- a long ring is the open chain (``E[s_0·s_r] → uʳ``).

The samplers are then checked against the periodic systems' own ``reference`` (the ring's law;
``n = 3``: ``heisenberg``'s ring reference) on rings of 12 sites: the time averages
of the energy per site and of ``s_x·s_{x+6}`` (averaged over ``x``) within ``Z_MAX`` standard
errors, the errors by blocking (``blocking_error``, which includes the integrated
autocorrelation time) over 4 chains with fixed keys; and more than ``Z_MAX`` of them from the
ring at ``1.25 β`` (a sampler of the wrong temperature is caught) and from the open chain's
``u⁶`` (the periodic bond is seen).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.diagnostics import blocking_error
from liesample.systems import cp_model, n_vector
from liesample.targets import (
    CPChainReference,
    CPRingReference,
    NVectorChainReference,
    NVectorRingReference,
    cp_bond_moments,
    n_vector_bond_mean,
)
from liesample.targets.n_vector import n_vector_bond_variance

Z_MAX = 4.0
RING = 12
CHAINS = 4


def triangle_by_quadrature(n, k, points=72):
    """``(E[s_0·s_1], Var(Σ bonds))`` of the ring of three O(n) spins at ``K``: ``s_0 = e_n``,
    ``s_1`` at polar angle ``θ₁`` in a fixed plane, ``s_2`` at polar angle ``θ₂`` and azimuth
    ``ψ`` about ``s_0`` relative to ``s_1``, weight ``sin^{n−2}θ₁ sin^{n−2}θ₂ sin^{n−3}ψ``."""
    if n == 2:  # S¹: two angles on the circle, the trapezoid rule
        t = 2 * np.pi * np.arange(points) / points
        t1, t2 = np.meshgrid(t, t, indexing="ij")
        bonds = np.cos(t1) + np.cos(t2 - t1) + np.cos(t2)
        weight = np.ones_like(bonds)
    else:
        x, w = np.polynomial.legendre.leggauss(points)
        angle, w = np.pi * (x + 1) / 2, w * np.pi / 2
        t1, t2, psi = np.meshgrid(angle, angle, angle, indexing="ij")
        weight = np.einsum("i,j,k->ijk", w, w, w)
        weight *= (np.sin(t1) * np.sin(t2)) ** (n - 2) * np.sin(psi) ** (n - 3)
        s12 = np.sin(t1) * np.sin(t2) * np.cos(psi) + np.cos(t1) * np.cos(t2)
        bonds = np.cos(t1) + np.cos(t2) + s12
    density = weight * np.exp(k * (bonds - 3.0))
    z = density.sum()
    mean = np.sum(density * bonds) / z
    return mean / 3, np.sum(density * bonds**2) / z - mean**2


def xy_square_by_quadrature(k, points=48):
    """``(E[s_0·s_1], E[s_0·s_2], Var(Σ bonds))`` of the ring of four XY spins at ``K``."""
    t = 2 * np.pi * np.arange(points) / points
    t1, t2, t3 = np.meshgrid(t, t, t, indexing="ij")
    bonds = np.cos(t1) + np.cos(t2 - t1) + np.cos(t3 - t2) + np.cos(t3)
    density = np.exp(k * (bonds - 4.0))
    z = density.sum()
    mean = np.sum(density * bonds) / z
    across = np.sum(density * np.cos(t2)) / z
    return mean / 4, across, np.sum(density * bonds**2) / z - mean**2


@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("k", [-1.2, 0.4, 2.5])
def test_triangle_against_direct_integration(n, k):
    ring = NVectorRingReference(length=3, n=n, beta=k)
    mean, variance = triangle_by_quadrature(n, k)
    assert ring.bond_mean() == pytest.approx(mean, rel=1e-10, abs=1e-13)
    assert float(ring.correlation(1)) == pytest.approx(mean, rel=1e-10, abs=1e-13)
    assert ring.energy_variance() == pytest.approx(variance, rel=1e-9)


@pytest.mark.parametrize("k", [-0.8, 0.6, 3.0])
def test_xy_square_against_direct_integration(k):
    ring = NVectorRingReference(length=4, n=2, beta=k, coupling=1.0)
    mean, across, variance = xy_square_by_quadrature(k)
    assert ring.bond_mean() == pytest.approx(mean, rel=1e-10)
    np.testing.assert_allclose(ring.correlation([1, 2, 3]), [mean, across, mean], rtol=1e-10)
    assert ring.energy_variance() == pytest.approx(variance, rel=1e-9)


@pytest.mark.parametrize("n", [2, 3, 4, 7])
@pytest.mark.parametrize("k", [-2.0, 1e-7, 0.9, 30.0])
def test_two_sites_are_one_bond_at_twice_the_coupling(n, k):
    ring = NVectorRingReference(length=2, n=n, beta=k / 2, coupling=2.0)  # K = k
    assert ring.bond_mean() == pytest.approx(n_vector_bond_mean(n, 2 * k), rel=1e-12, abs=1e-15)
    assert float(ring.correlation(1)) == pytest.approx(ring.bond_mean(), rel=1e-12, abs=1e-15)
    variance = 4 * n_vector_bond_variance(n, 2 * k)  # Var(2c) of the doubled bond, times J²
    assert ring.energy_variance() == pytest.approx(4 * variance, rel=1e-9)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_a_long_ring_is_the_open_chain(n):
    chain = NVectorChainReference(length=600, n=n, beta=1.5)
    ring = NVectorRingReference(length=600, n=n, beta=1.5)
    r = np.arange(8)
    np.testing.assert_allclose(ring.correlation(r), chain.correlation(r), rtol=1e-12)
    assert ring.bond_energy_mean() == pytest.approx(chain.bond_energy_mean(), rel=1e-12)
    assert ring.energy_variance() / 600 == pytest.approx(chain.bond_variance(), rel=1e-9)
    # and a short one is more ordered than its open chain, symmetric under r -> L - r
    short = NVectorRingReference(length=10, n=n, beta=1.5)
    np.testing.assert_allclose(short.correlation(r[1:]), short.correlation(10 - r[1:]))
    assert np.all(short.correlation(r[1:]) > chain.correlation(r[1:]))


def test_zero_coupling_and_frustration():
    free = NVectorRingReference(length=5, n=3, beta=0.0)
    np.testing.assert_array_equal(free.correlation([0, 1, 4, 5]), [1.0, 0.0, 0.0, 1.0])
    assert free.bond_mean() == 0.0 and free.energy_variance() == pytest.approx(5 / 3)
    # an even antiferromagnetic ring is the ferromagnetic one with every other spin flipped
    even, flipped = NVectorRingReference(6, 2, -1.3), NVectorRingReference(6, 2, 1.3)
    r = np.arange(7)
    np.testing.assert_allclose(even.correlation(r), (-1.0) ** r * flipped.correlation(r))
    assert even.energy_variance() == pytest.approx(flipped.energy_variance(), rel=1e-12)


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (lambda: NVectorRingReference(length=1, n=2, beta=1.0), ValueError, "length"),
        (lambda: NVectorRingReference(length=4.0, n=2, beta=1.0), TypeError, "length"),
        (lambda: NVectorRingReference(length=4, n=1, beta=1.0), ValueError, "n must"),
        (lambda: NVectorRingReference(length=4, n=2, beta=math.nan), ValueError, "beta"),
        (lambda: NVectorRingReference(4, 2, 1.0).correlation(5), ValueError, "r must"),
        (lambda: NVectorRingReference(4, 2, 1.0).correlation(1.0), ValueError, "r must"),
        (lambda: NVectorRingReference(5, 2, -40.0), ValueError, "use an even length"),
    ],
)
def test_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()


# ---------------------------------------------------------------------------------------------
# Samplers on periodic rings against the exact law
# ---------------------------------------------------------------------------------------------


def ring_series(algorithm, n, num_warmup, num_steps, seed):
    """Per chain and step after ``num_warmup`` steps: the energy per site and the mean over
    ``x`` of ``s_x·s_{x+RING/2}``, ``(chains, steps, 2)``, from random starts; chain ``c`` uses
    ``split(key(seed), chains)[c]`` and step ``s`` ``fold_in(key_c, s)``."""
    x = np.random.default_rng(seed).normal(size=(CHAINS, RING, n))
    starts = jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True))

    def chain(key, position):
        def body(state, step):
            state, info = algorithm.step(jax.random.fold_in(key, step), state)
            s = state.position
            across = jnp.mean(jnp.sum(s * jnp.roll(s, RING // 2, axis=0), axis=-1))
            return state, jnp.stack([info.energy / RING, across])

        steps = jnp.arange(num_warmup + num_steps)
        return jax.lax.scan(body, algorithm.init(position), steps)[1][num_warmup:]

    keys = jax.random.split(jax.random.key(seed), CHAINS)
    return np.asarray(liesample.jit(jax.vmap(chain))(keys, starts), dtype=float)


def assert_exact_ring_law(series, system, beta):
    """Against ``system.reference``: the periodic system's own reference is the ring's law."""
    n = system.event_shape[-1]
    exact, wrong = (system.reference(b) for b in (beta, 1.25 * beta))
    for reference, inside in ((exact, True), (wrong, False)):
        target = [reference.energy_mean() / RING, float(reference.correlation(RING // 2))]
        z = []
        for i in range(2):
            result = blocking_error(series[..., i])
            z.append((result.mean - target[i]) / result.error)
        assert np.all(np.abs(z) < Z_MAX) == inside, (n, inside, target, z)
    # the open chain's u^(L/2) is not the ring's correlation: the boundary is seen
    across = blocking_error(series[..., 1])
    open_chain = NVectorChainReference(RING, n, beta).correlation(RING // 2)
    assert abs(across.mean - open_chain) > Z_MAX * across.error


@pytest.mark.parametrize(("n", "beta"), [(2, 2.0), (3, 2.5), (4, 3.0)])
def test_recommended_sampler_samples_the_exact_ring(n, beta):
    system = n_vector((RING,), n, periodic=True)
    sampler = liesample.recommended_sampler(system, beta=beta)
    series = ring_series(sampler, n, 100, 2048, 70 + n)
    assert_exact_ring_law(series, system, beta)


@pytest.mark.slow
@pytest.mark.parametrize("n", [2, 4])
def test_plain_heat_bath_samples_the_exact_ring(n):
    system = n_vector((RING,), n, periodic=True)
    sampler = liesample.heisenberg_heat_bath(system, beta=2.0, overrelaxation=0)
    series = ring_series(sampler, n, 200, 8192, 80 + n)
    assert_exact_ring_law(series, system, 2.0)


# ---------------------------------------------------------------------------------------------
# CP(N−1) rings (targets.CPRingReference)
# ---------------------------------------------------------------------------------------------


def haar_cp(rng, size, n):
    z = rng.normal(size=(size, n)) + 1j * rng.normal(size=(size, n))
    return z / np.linalg.norm(z, axis=-1, keepdims=True)


@pytest.mark.parametrize("n", [3, 4])
@pytest.mark.parametrize("k", [-1.5, 0.7, 12.0])
def test_cp_two_sites_are_one_bond_at_twice_the_coupling(n, k):
    ring = CPRingReference(length=2, n=n, beta=k)
    mean, variance = cp_bond_moments(n, 2 * k)
    assert ring.bond_mean() == pytest.approx(mean, rel=1e-12)
    assert ring.energy_variance() == pytest.approx(4 * variance, rel=1e-9)


@pytest.mark.parametrize("length", [3, 8])
@pytest.mark.parametrize("k", [-2.0, 1.0, 20.0])
def test_cp1_ring_is_the_o3_ring_at_half_the_coupling(length, k):
    """Hopf: ``t = (1 + s·s′)/2``, so ``E[t] = (1 + E[s·s′])/2`` and ``Var Σt = Var Σ s·s′ / 4``
    of the O(3) ring at ``K/2``."""
    cp, o3 = CPRingReference(length, 2, k), NVectorRingReference(length, 3, k / 2)
    assert cp.bond_mean() == pytest.approx((1 + o3.bond_mean()) / 2, rel=1e-12)
    assert cp.energy_variance() == pytest.approx(o3.energy_variance() / 4, rel=1e-10)


def test_cp_long_ring_is_the_open_chain():
    ring, chain = CPRingReference(600, 3, 2.5), CPChainReference(600, 3, 2.5)
    assert ring.bond_mean() == pytest.approx(chain.bond_mean(), rel=1e-12)
    assert ring.energy_variance() / 600 == pytest.approx(chain.bond_variance(), rel=1e-8)


def test_cp2_triangle_against_independent_haar_draws():
    """``E[t̄]`` and ``E[(Σt)²]`` of the CP(2) triangle at ``K = 2`` by importance sampling
    from 400 000 i.i.d. Haar triples (weights ``e^{K Σt}``; delta-method standard error),
    within ``Z_MAX`` standard errors: a check of the higher degrees the two-site ring and the
    long ring do not see."""
    k, num = 2.0, 400_000
    rng = np.random.default_rng(5)
    z = [haar_cp(rng, num, 3) for _ in range(3)]
    bonds = sum(np.abs(np.sum(np.conj(z[i]) * z[(i + 1) % 3], axis=-1)) ** 2 for i in range(3))
    weight = np.exp(k * (bonds - 3.0))
    ring = CPRingReference(3, 3, k)
    second = ring.energy_variance() + (3 * ring.bond_mean()) ** 2
    for values, exact in ((bonds / 3, ring.bond_mean()), (bonds**2, second)):
        estimate = np.sum(weight * values) / np.sum(weight)
        influence = weight * (values - estimate) / weight.mean()  # ratio estimator
        assert abs(estimate - exact) < Z_MAX * influence.std() / math.sqrt(num), (estimate, exact)


def test_recommended_sampler_samples_the_exact_cp_ring():
    """The energy per site of a CP(2) ring of 4 sites at ``β = 5`` (short and cold enough for
    the periodic bond to change it by many standard errors from the open chain's)."""
    beta, n, length = 5.0, 3, 4
    system = cp_model((length,), n, periodic=True)
    algorithm = liesample.recommended_sampler(system, beta=beta)
    rng = np.random.default_rng(6)
    starts = jnp.asarray(np.stack([haar_cp(rng, length, n) for _ in range(CHAINS)]))

    def chain(key, position):
        def body(state, step):
            state, info = algorithm.step(jax.random.fold_in(key, step), state)
            return state, info.energy / length

        return jax.lax.scan(body, algorithm.init(position), jnp.arange(2148))[1][100:]

    keys = jax.random.split(jax.random.key(95), CHAINS)
    series = np.asarray(liesample.jit(jax.vmap(chain))(keys, starts), dtype=float)
    result = blocking_error(series)
    for b, inside in ((beta, True), (1.25 * beta, False)):  # the system's own reference
        z = (result.mean - system.reference(b).bond_energy_mean()) / result.error
        assert (abs(z) < Z_MAX) == inside, (b, result.mean, z)
    open_chain = CPChainReference(length, n, beta).bond_energy_mean()
    assert abs(result.mean - open_chain) > Z_MAX * result.error  # the periodic bond is seen


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (lambda: CPRingReference(length=1, n=3, beta=1.0), ValueError, "length"),
        (lambda: CPRingReference(length=4, n=1, beta=1.0), ValueError, "N must"),
        (lambda: CPRingReference(length=4, n=3, beta=math.inf), ValueError, "beta"),
    ],
)
def test_cp_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()
