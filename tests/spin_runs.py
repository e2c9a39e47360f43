"""Per-chain time averages of a spin sampler, the shared run of the spin tests."""

import jax
import jax.numpy as jnp
import numpy as np

import liesample


def per_chain_averages(algorithm, starts, num_warmup, num_steps, seed, observe):
    """Time average of ``observe(spins)`` (a vector) per chain, after ``num_warmup`` steps;
    chain ``c`` uses ``split(key(seed), chains)[c]`` and step ``s`` ``fold_in(key_c, s)``."""

    def chain(key, position):
        def body(carry, step):
            state, total = carry
            state, _ = algorithm.step(jax.random.fold_in(key, step), state)
            return (state, total + observe(state.position)), None

        state = algorithm.init(position)
        zero = jnp.zeros_like(observe(state.position))
        (state, _), _ = jax.lax.scan(body, (state, zero), jnp.arange(num_warmup))
        (_, total), _ = jax.lax.scan(body, (state, zero), num_warmup + jnp.arange(num_steps))
        return total / num_steps

    keys = jax.random.split(jax.random.key(seed), starts.shape[0])
    return np.asarray(liesample.jit(jax.vmap(chain))(keys, jnp.asarray(starts)))
