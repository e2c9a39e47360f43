"""The helicity modulus of the XY model (``liesample.analysis.helicity``).

References, written independently of the samplers:

- the sums ``C_e``, ``S_e`` against the angle formula ``Σ cos/sin(θ_x − θ_{x+e})`` on a
  random periodic 3×5 lattice (each direction separately);
- the exact helicity modulus of the periodic XY ring of ``L`` sites: a twist ``φ = Lδ`` of the
  ring multiplies the transfer-matrix term of the harmonic ``e^{imθ}`` by ``e^{imφ}``, so
  ``Z(φ) ∝ Σ_m I_{|m|}(K)ᴸ e^{imφ}`` and ``Υ = (1/L) ∂²F/∂δ² = (L/β) Σ_m m² I_{|m|}(K)ᴸ /
  Σ_m I_{|m|}(K)ᴸ`` (``K = βJ``), which tends to ``J`` as ``K → ∞``.

The recommended sampler on a ring of 12 sites then gives ``Υ`` within ``Z_MAX`` jackknife
errors (blocks from the automatic blocking level, so the autocorrelation is included), fixed
keys, and more than ``Z_MAX`` errors from the ring at ``1.25 β``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import ive

import liesample
from liesample.analysis.helicity import helicity_modulus, xy_helicity_sums
from liesample.systems import n_vector

Z_MAX = 4.0
RING = 12
CHAINS = 4


def ring_helicity(length, beta, coupling=1.0):
    """The exact ``Υ`` of the periodic XY ring (module docstring)."""
    k = beta * coupling
    m = np.arange(1, int(2 * abs(k)) + 60)
    weights = (ive(m, k) / ive(0, k)) ** length
    return coupling * (length / k) * 2 * np.sum(m**2 * weights) / (1 + 2 * np.sum(weights))


def test_sums_are_the_angle_sums_per_direction():
    theta = np.random.default_rng(0).uniform(0, 2 * np.pi, size=(3, 5))
    spins = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    sums = np.asarray(xy_helicity_sums(jnp.asarray(spins)))
    for axis in range(2):
        diff = theta - np.roll(theta, -1, axis=axis)
        np.testing.assert_allclose(sums[axis], [np.cos(diff).sum(), np.sin(diff).sum()])


def test_ring_reference_limits():
    assert ring_helicity(8, 200.0) == pytest.approx(1.0, rel=0.03)  # the ground state's J
    assert ring_helicity(8, 200.0, coupling=0.5) == pytest.approx(0.5, rel=0.03)
    assert ring_helicity(8, 0.05) < 1e-10  # no stiffness at high temperature


def test_estimator_of_fixed_draws():
    # aligned spins give J at any beta; a uniform twist of 2π around the ring gives
    # C = L cos(2π/L), S = −L sin(2π/L) at every draw
    theta = 2 * np.pi * np.arange(RING) / RING
    sums = np.asarray(xy_helicity_sums(np.stack([np.cos(theta), np.sin(theta)], -1)))
    draws = np.tile(sums, (2, 40, 1, 1))
    result = helicity_modulus(draws, beta=0.5, num_sites=RING, coupling=2.0, block_size=4)
    c, s = RING * np.cos(2 * np.pi / RING), -RING * np.sin(2 * np.pi / RING)
    assert result.estimate == pytest.approx(2.0 * (c - 0.5 * 2.0 * s**2) / RING)
    assert result.error == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    ("make", "error", "match"),
    [
        (lambda: xy_helicity_sums(np.ones((4, 3))), ValueError, r"spins must have shape"),
        (lambda: xy_helicity_sums(np.ones(2)), ValueError, r"spins must have shape"),
        (lambda: helicity_modulus(np.ones((10, 2)), 1.0, 4), ValueError, "sums must have"),
        (lambda: helicity_modulus(np.ones((2, 10, 1, 2)), np.nan, 4), ValueError, "beta"),
        (lambda: helicity_modulus(np.ones((2, 10, 1, 2)), 1.0, 0), ValueError, "num_sites"),
    ],
)
def test_bad_arguments_are_refused(make, error, match):
    with pytest.raises(error, match=match):
        make()


def ring_sums(algorithm, num_warmup, num_steps, seed):
    """``xy_helicity_sums`` per chain and step after ``num_warmup`` steps from random starts,
    ``(chains, steps, 1, 2)``; chain ``c`` uses ``split(key(seed), chains)[c]``, step ``s``
    ``fold_in(key_c, s)``."""
    x = np.random.default_rng(seed).normal(size=(CHAINS, RING, 2))
    starts = jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True))

    def chain(key, position):
        def body(state, step):
            state, _ = algorithm.step(jax.random.fold_in(key, step), state)
            return state, xy_helicity_sums(state.position)

        steps = jnp.arange(num_warmup + num_steps)
        return jax.lax.scan(body, algorithm.init(position), steps)[1][num_warmup:]

    keys = jax.random.split(jax.random.key(seed), CHAINS)
    return np.asarray(liesample.jit(jax.vmap(chain))(keys, starts), dtype=float)


def test_recommended_sampler_gives_the_exact_ring_helicity():
    beta = 2.0
    system = n_vector((RING,), 2, periodic=True)
    sums = ring_sums(liesample.recommended_sampler(system, beta=beta), 100, 4096, 90)
    result = helicity_modulus(sums, beta=beta, num_sites=RING)
    for b, inside in ((beta, True), (1.25 * beta, False)):
        z = (result.estimate - ring_helicity(RING, b)) / result.error
        assert (abs(z) < Z_MAX) == inside, (b, result, ring_helicity(RING, b), z)
