"""One compile path for every loop liesample runs: ``liesample.jit``.

XLA:CPU's ``small-while-loop-hoisting`` pass miscompiles some small while loops once they are
vmapped: ``jit(vmap(lax.scan(step)))`` then gives each chain different numbers from the same
chain run alone, by far more than round-off (the same pass does it on jaxlib 0.11 once its size
threshold is raised). Disabling that one pass removes the miscompile on every supported version;
it only affects the CPU backend and costs little.

Every loop the library compiles goes through :func:`jit`. A user who writes their own
``jax.jit(jax.vmap(...))`` around ``algorithm.step`` gets the same protection with
``liesample.jit`` in place of ``jax.jit``, or with
``jax.jit(f, compiler_options=liesample.safe_compiler_options())``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, Protocol, cast, overload

import jax

__all__ = ["SAFE_COMPILER_OPTIONS", "Jitted", "evaluate", "jit", "safe_compiler_options"]

SAFE_COMPILER_OPTIONS = {"xla_disable_hlo_passes": "small-while-loop-hoisting"}


def safe_compiler_options(compiler_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``compiler_options`` for ``jax.jit`` with the miscompiling XLA:CPU pass disabled.

    Options given here are kept; a user's own ``xla_disable_hlo_passes`` list is extended.

    Examples
    --------
    >>> options = liesample.safe_compiler_options()
    >>> square = jax.jit(lambda x: x * x, compiler_options=options)
    >>> float(square(3.0))
    9.0
    """
    options = dict(compiler_options or {})
    disabled = [p for p in str(options.get("xla_disable_hlo_passes", "")).split(",") if p]
    for name in SAFE_COMPILER_OPTIONS["xla_disable_hlo_passes"].split(","):
        if name not in disabled:
            disabled.append(name)
    options["xla_disable_hlo_passes"] = ",".join(disabled)
    return options


# Traces under which a jitted call is still compiled on its own (eagerly, possibly batched).
_EAGER_TRACES = {"EvalTrace", "BatchTrace"}


def _inside_staged_computation() -> bool:
    """Whether a call now may be staged into an enclosing computation (``jit``, ``grad``, …).

    ``jax.jit`` refuses ``compiler_options`` on a nested jit; under an eager ``vmap`` the
    function is still compiled on its own, so the options are kept there (and only there).
    """
    try:
        from jax._src import core

        trace = core.trace_ctx.trace
        while trace is not None:
            if type(trace).__name__ not in _EAGER_TRACES:
                return True
            trace = getattr(trace, "parent_trace", None)
        return False
    except (ImportError, AttributeError):  # another jax layout: protect top-level calls only
        from jax._src import core

        return not core.trace_state_clean()


class Jitted(Protocol):
    """What :func:`jit` returns: the function, compiled on its first call, with ``jax.jit``'s
    ``lower``, ``trace`` and ``eval_shape`` (which compile with the safe options)."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any: ...

    lower: Callable[..., Any]
    trace: Callable[..., Any]
    eval_shape: Callable[..., Any]


@overload
def jit(fun: Callable[..., Any], /, **jit_kwargs: Any) -> Jitted: ...


@overload
def jit(fun: None = None, /, **jit_kwargs: Any) -> Callable[[Callable[..., Any]], Jitted]: ...


def jit(
    fun: Callable[..., Any] | None = None, /, **jit_kwargs: Any
) -> Jitted | Callable[[Callable[..., Any]], Jitted]:
    """``jax.jit`` with :func:`safe_compiler_options`; usable as ``@jit`` or ``@jit(...)``.

    Takes every keyword of ``jax.jit`` (``static_argnums``, ``donate_argnums``, …). Called at top
    level, under an eager ``vmap``, or through ``.lower(...).compile()``, it compiles with the
    pass disabled. Inside another ``jax.jit`` (or ``grad``) it is traced into the enclosing
    computation (``jax.jit`` takes compiler options only at the top), so wrap the outermost
    function in ``liesample.jit``.

    Examples
    --------
    >>> double = liesample.jit(lambda x: 2.0 * x)
    >>> double(jnp.ones(2))
    Array([2., 2.], dtype=float64)
    >>> @liesample.jit(static_argnums=1)
    ... def power(x, n):
    ...     return x**n
    >>> float(power(2.0, 3))
    8.0
    """
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    options = safe_compiler_options(jit_kwargs.pop("compiler_options", None))
    safe = jax.jit(fun, compiler_options=options, **jit_kwargs)
    nested = jax.jit(fun, **jit_kwargs)

    @functools.wraps(fun)
    def call(*args: Any, **kwargs: Any) -> Any:
        chosen = nested if _inside_staged_computation() else safe
        return chosen(*args, **kwargs)

    compiled = cast(Jitted, call)  # a plain function, given jax.jit's attributes below
    compiled.lower = safe.lower
    compiled.trace = safe.trace
    compiled.eval_shape = safe.eval_shape
    return compiled


def evaluate(fun: Callable[..., Any], /, *args: Any) -> Any:
    """``fun(*args)`` with concrete (numpy) arguments, as concrete values even while an enclosing
    computation (``jax.jit``, ``grad``) is being staged: pass numpy arrays, as ``jnp.asarray``
    outside this call would stage them too.

    There it runs under ``jax.ensure_compile_time_eval``. Called at top level it runs as it is:
    under that context a jitted ``fun`` would be traced with eager constant folding, so each of
    its constant operations would compile as a program of its own, and ``fun`` would compile
    again under a cache key of its own.
    """
    if _inside_staged_computation():
        with jax.ensure_compile_time_eval():
            return fun(*args)
    return fun(*args)
