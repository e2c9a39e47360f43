import jax

# Tests run in float64 (ARCHITECTURE.md, "Habits"); float32 has its own stability tests.
jax.config.update("jax_enable_x64", True)
