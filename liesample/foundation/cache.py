"""JAX's persistent compilation cache, on by default for a process that imports liesample.

A script's second run compiles again every program its first run compiled; JAX can keep
compiled programs on disk and load them instead (its persistent compilation cache, keyed by
the program, the XLA flags and the versions, so a hit runs the executable a compilation would
have made). ``import liesample`` turns that cache on (:func:`enable_compilation_cache`) unless
the process chose otherwise:

- a cache the user configured, ``JAX_COMPILATION_CACHE_DIR`` or
  ``jax.config.update("jax_compilation_cache_dir", …)`` before the import, is used as it is;
- ``LIESAMPLE_COMPILATION_CACHE=0`` (or ``false``, ``off``, ``no``) in the environment turns
  it off: liesample then configures nothing;
- otherwise the cache is ``$XDG_CACHE_HOME/liesample/jax`` (``~/.cache/liesample/jax``).

JAX stores only programs whose compilation took at least
``jax_persistent_cache_min_compile_time_secs`` (one second by default). A call of a sampler
compiles tens of small programs (start checks, the step-size rule, the warm-up, the chunks),
most well under a second, and together they are what a second process would wait for; so in
its own folder liesample stores every program (:data:`MIN_COMPILE_TIME`), unless the
environment sets ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``. JAX decides whether a process
uses a cache at its first compilation: import liesample before computing with JAX,
as for ``jax_enable_x64``. The cache is the process's, not only liesample's programs: it is
JAX's one setting.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

SWITCH = "LIESAMPLE_COMPILATION_CACHE"
"""The environment variable that turns the default cache off (``0``, ``false``, ``off``,
``no``)."""

_OFF = {"0", "false", "off", "no"}

MIN_COMPILE_TIME = 0.0
"""The shortest compilation liesample's own cache folder stores (seconds): every program."""


def cache_directory(configured: str | None, environ: Mapping[str, str]) -> str | None:
    """The cache folder liesample would set: ``None`` where the user configured one
    (``configured``) or turned the default off (``environ[SWITCH]``); else the per-user folder.

    Examples
    --------
    >>> from liesample.foundation.cache import cache_directory
    >>> cache_directory(None, {"XDG_CACHE_HOME": "/tmp/c"})
    '/tmp/c/liesample/jax'
    >>> cache_directory("/mine", {}) is None  # the user's own cache is kept
    True
    >>> cache_directory(None, {"LIESAMPLE_COMPILATION_CACHE": "0"}) is None  # turned off
    True
    """
    if configured or environ.get(SWITCH, "").strip().lower() in _OFF:
        return None
    base = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "liesample", "jax")


def enable_compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at :func:`cache_directory`, when it gives one
    and the folder can be made; returns the folder set, or ``None`` (nothing changed).

    Examples
    --------
    >>> from liesample.foundation.cache import enable_compilation_cache
    >>> path = enable_compilation_cache()  # a second call: already configured, nothing to do
    >>> path is None
    True
    """
    import jax

    path = cache_directory(jax.config.jax_compilation_cache_dir, os.environ)
    if path is None:
        return None
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:  # a read-only home: run without a cache
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME)
    return path
