"""Same keys, same draws: the reorganised package reproduces the draws of the code before it.

``tests/data/reference_draws.npz`` holds short runs (2 chains × 20 draws, fixed key, float64) of
every sampler in ``tests/cases.py``, ``lie_poisson_langevin`` on every system and each of its
integrators, made by ``tests/data/make_reference_draws.py`` from the tree before the layers
(commit ``ebf7941``). Each run is reproduced here with the current code and must agree to
``1e-12`` (relative and absolute): another x86 CPU may let XLA fuse differently, and the runs
are short so that round-off cannot grow.

Recorded when the file was written (Intel Xeon, jax/jaxlib 0.12.0.1): every array was bitwise
equal at commit ``1be3165`` and in the working tree being refactored after it.

XLA compiles for the host CPU's instruction set, so another jaxlib or another CPU may round one
operation differently, and one flipped Metropolis or rejection decision then changes the rest of
a chain. The suite compiles with XLA's cheap back-end setting (``tests/conftest.py``), which rounds
differently again; the draws compared here are made in a fresh process that compiles as a
user's does. The comparison is made where the references were made — the same jaxlib and
the same CPU features (``tests/data/reference_draws_host.json``) — and skipped, saying why,
elsewhere; the reorganisation was checked on that host.

A new sampler or system row needs a reference too (``test_every_row_has_a_reference``): rerun the
script against a tree that has the row; the other rows must come out unchanged. A run the
reference tree could not build (a newer integrator) is skipped.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import cases
import jaxlib
import numpy as np
import pytest

from conftest import USER_XLA_FLAGS

REFERENCE = Path(__file__).parent / "data" / "reference_draws.npz"
REFERENCE_HOST = Path(__file__).parent / "data" / "reference_draws_host.json"
RUNS = cases.reference_runs()
# The CPU features that change what XLA:CPU emits for these runs.
CODEGEN_FEATURES = ("avx", "avx2", "fma", "avx512f", "avx512dq", "avx512vl", "avx512bw")


def host() -> dict:
    """jaxlib's version and the host CPU's vector features (Linux; empty elsewhere)."""
    flags = set()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        line = next((x for x in cpuinfo.read_text().splitlines() if x.startswith("flags")), "")
        flags = set(line.split(":", 1)[-1].split())
    return {
        "jaxlib": jaxlib.__version__,
        "cpu_features": [f for f in CODEGEN_FEATURES if f in flags],
    }


@pytest.fixture(scope="module")
def same_host():
    made_on = json.loads(REFERENCE_HOST.read_text())
    if host() != made_on:
        pytest.skip(
            f"the reference draws were made with {made_on}; this host is {host()}: XLA may round "
            "differently here (module docstring)"
        )


@pytest.fixture(scope="module")
def reference():
    with np.load(REFERENCE) as stored:
        return dict(stored)


_FRESH_PROCESS = """
import sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import cases
runs = cases.reference_runs()
arrays = {}
for label in sys.argv[2:]:
    arrays.update(cases.reference_draws(label, *runs[label]))
np.savez(sys.argv[1], **arrays)
"""


def reference_labels(reference) -> set:
    """The run labels of the stored arrays (``<label>/position…`` and ``<label>/energy``)."""
    return {name.rsplit("/position", 1)[0].removesuffix("/energy") for name in reference}


@pytest.fixture(scope="module")
def draws_now(reference, tmp_path_factory, request):
    """``draws_now(label)``: the run's arrays from the current code, compiled as in a user's
    process (XLA's default flags); each kind of label (``sampler/``, ``system/``, …) is made
    in one fresh process, once, for the labels of that kind this session runs."""
    made = {}
    selected = {
        item.callspec.params["label"]
        for item in request.session.items
        if item.name.startswith("test_draws_are_those_of_before[")
    }

    def draws(label):
        if label not in made:
            kind = label.split("/")[0] + "/"
            labels = [
                name
                for name in sorted(reference_labels(reference))
                if name.startswith(kind) and name in RUNS and name in selected
            ]
            out = tmp_path_factory.mktemp("draws") / "draws.npz"
            env = {**os.environ, "XLA_FLAGS": USER_XLA_FLAGS}
            subprocess.run(
                [sys.executable, "-c", _FRESH_PROCESS, str(out), *labels],
                cwd=Path(__file__).parent, env=env, check=True,
            )  # fmt: skip
            with np.load(out) as stored:
                arrays = dict(stored)
            for name in labels:
                made[name] = {k: v for k, v in arrays.items() if k.startswith(f"{name}/")}
        return made[label]

    return draws


def test_every_row_has_a_reference(reference):
    labels = reference_labels(reference)
    assert {f"sampler/{name}" for name in cases.SAMPLER_NAMES} <= labels
    assert {f"system/{name}" for name in cases.SYSTEM_NAMES} <= labels


# One sampler of each family in the default suite (the orbit samplers, unadjusted and
# adjusted, and HMC on T*G); every other sampler, system and integrator in make test-slow.
DEFAULT_LABELS = {
    "sampler/lie_poisson_langevin",
    "sampler/adjusted_lie_poisson",
    "sampler/geometric_hmc",
}


@pytest.mark.parametrize(
    "label",
    [
        label if label in DEFAULT_LABELS else pytest.param(label, marks=pytest.mark.slow)
        for label in sorted(RUNS)
    ],
)
def test_draws_are_those_of_before(label, reference, same_host, draws_now):
    stored = {name: value for name, value in reference.items() if name.startswith(f"{label}/")}
    if not stored:
        pytest.skip(f"{label} is newer than the reference tree")
    now = draws_now(label)
    assert now.keys() == stored.keys()
    for name, value in stored.items():
        assert now[name].dtype == value.dtype and now[name].shape == value.shape, name
        np.testing.assert_allclose(now[name], value, rtol=1e-12, atol=1e-12, err_msg=name)
