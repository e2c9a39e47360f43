"""The gauge heat bath's written-out Threefry (liesample.samplers.gauge._local) draws exactly
the bits of JAX's own ``threefry2x32``: every split, fold-in and draw of raw bits from a
converted key agrees bit for bit, inside and outside ``jit``; the floats made from those bits
agree to round-off (XLA may fuse the arithmetic after the hash differently: one ulp of a
gamma draw under ``jit`` was seen)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from liesample.samplers.gauge._local import unrolled_threefry


def _draws(key):
    a, b = jax.random.split(key)
    c = jax.random.split(jax.random.fold_in(b, 7), (3, 2))
    return {
        "split": jax.random.key_data(c),
        "bits32": jax.random.bits(a, (5, 3), jnp.uint32),
        "bits64": jax.random.bits(b, (4,), jnp.uint64),
        "uniform": jax.random.uniform(c[1, 0], (6,)),
        "normal": jax.random.normal(c[2, 1], (2, 3)),
        "gamma": jax.random.gamma(a, 2.5, (3,)),
    }


@pytest.mark.parametrize("seed", [0, 1, 2**31 + 5])
@pytest.mark.parametrize("jitted", [False, True])
def test_converted_keys_draw_jax_threefry_bits(seed, jitted):
    key = jax.random.key(seed)
    draws = jax.jit(_draws) if jitted else _draws
    expected = draws(key)
    actual = draws(unrolled_threefry(key))
    for name in ("split", "bits32", "bits64"):
        np.testing.assert_array_equal(np.asarray(actual[name]), np.asarray(expected[name]), name)
    for name in ("uniform", "normal", "gamma"):
        np.testing.assert_allclose(actual[name], expected[name], rtol=1e-14, err_msg=name)


def test_keys_of_another_implementation_are_left_as_they_are():
    key = jax.random.key(0, impl="rbg")
    assert unrolled_threefry(key) is key
