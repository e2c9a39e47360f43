"""One compile path for every loop liesample runs: ``liesample.jit``.

XLA:CPU's ``small-while-loop-hoisting`` pass miscompiles some small while loops once they are
vmapped: ``jit(vmap(lax.scan(step)))`` then gives each chain different numbers from the same
chain run alone (not round-off: up to 2e-2 after two heavy-top steps on jaxlib 0.12, and the
same pass does it on 0.11 once its size threshold is raised). ``tests/test_compile.py`` holds a
pure-JAX reproducer. Disabling that one pass removes the miscompile on every supported version;
it only affects the CPU backend and costs little (``benchmarks/RESULTS.md``, "Compile path").

Every loop the library compiles goes through :func:`jit`. A user who writes their own
``jax.jit(jax.vmap(...))`` around ``algorithm.step`` gets the same protection with
``liesample.jit`` in place of ``jax.jit``, or with
``jax.jit(f, compiler_options=liesample.safe_compiler_options())``.
"""

from __future__ import annotations

import functools

import jax

__all__ = ["SAFE_COMPILER_OPTIONS", "jit", "safe_compiler_options"]

SAFE_COMPILER_OPTIONS = {"xla_disable_hlo_passes": "small-while-loop-hoisting"}


def safe_compiler_options(compiler_options: dict | None = None) -> dict:
    """``compiler_options`` for ``jax.jit`` with the miscompiling XLA:CPU pass disabled.

    Options given here are kept; a user's own ``xla_disable_hlo_passes`` list is extended.
    """
    options = dict(compiler_options or {})
    disabled = [p for p in str(options.get("xla_disable_hlo_passes", "")).split(",") if p]
    for name in SAFE_COMPILER_OPTIONS["xla_disable_hlo_passes"].split(","):
        if name not in disabled:
            disabled.append(name)
    options["xla_disable_hlo_passes"] = ",".join(disabled)
    return options


def jit(fun=None, /, **jit_kwargs):
    """``jax.jit`` with :func:`safe_compiler_options`; usable as ``@jit`` or ``@jit(...)``.

    Takes every keyword of ``jax.jit`` (``static_argnums``, ``donate_argnums``, …). The
    protection applies to the outermost compiled function: a ``jax.jit`` nested inside is
    inlined into it, so wrapping the outer ``vmap`` of a loop is what counts.
    """
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    jit_kwargs["compiler_options"] = safe_compiler_options(jit_kwargs.get("compiler_options"))
    return jax.jit(fun, **jit_kwargs)
