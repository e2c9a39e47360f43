"""JAX's persistent compilation cache is on by default for a process that loads liesample's
modules, in a per-user folder; a cache the user configured is kept, and one switch turns it off
(liesample.foundation.cache)."""

import os
import subprocess
import sys

import jax
import pytest

from liesample.foundation.cache import SWITCH, cache_directory


def test_the_folder_is_per_user_unless_configured_or_switched_off():
    assert cache_directory(None, {"XDG_CACHE_HOME": "/c"}) == "/c/liesample/jax"
    assert cache_directory("/mine", {"XDG_CACHE_HOME": "/c"}) is None  # the user's, kept
    for off in ("0", "false", "OFF", " no "):
        assert cache_directory(None, {SWITCH: off, "XDG_CACHE_HOME": "/c"}) is None
    assert cache_directory(None, {SWITCH: "1", "XDG_CACHE_HOME": "/c"}) == "/c/liesample/jax"


def test_the_suites_own_cache_is_kept():
    """tests/conftest.py configures a session cache through the environment: loading liesample
    leaves it as it is."""
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        pytest.skip("the session's cache was not set through the environment")
    assert jax.config.jax_compilation_cache_dir == os.environ["JAX_COMPILATION_CACHE_DIR"]


_PROBE = (
    "import jax, liesample.systems; print(jax.config.jax_compilation_cache_dir); "
    "print(jax.config.jax_persistent_cache_min_compile_time_secs)"
)


@pytest.mark.parametrize(("switch", "expected"), [(None, "liesample/jax"), ("0", "None")])
def test_a_new_process_gets_the_default_cache_or_none(tmp_path, switch, expected):
    session = ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", SWITCH)
    env = {k: v for k, v in os.environ.items() if k not in session}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    if switch is not None:
        env[SWITCH] = switch
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    printed, min_time = out.stdout.split()
    if expected == "None":
        assert printed == "None"
        assert float(min_time) == 1.0  # JAX's own default, untouched
    else:
        assert printed == str(tmp_path / "liesample" / "jax") and os.path.isdir(printed)
        assert float(min_time) == 0.0  # every program of a call is kept for the next process
