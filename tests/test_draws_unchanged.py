"""Same keys, same draws: the reorganised package reproduces the draws of the code before it.

``tests/data/reference_draws.npz`` holds short runs (2 chains × 20 draws, fixed key, float64) of
every sampler in ``tests/cases.py``, ``lie_poisson_langevin`` on every system and each of its
integrators, made by ``tests/data/make_reference_draws.py`` from the tree before the layers
(commit ``ebf7941``). Each run is reproduced here with the current code and must agree to
``1e-12`` (relative and absolute): another x86 CPU may let XLA fuse differently, and the runs
are short so that round-off cannot grow.

Recorded when the file was written (Intel Xeon, jax/jaxlib 0.12.0.1): every array was bitwise
equal at commit ``1be3165`` and in the working tree being refactored after it.

A new sampler or system row needs a reference too (``test_every_row_has_a_reference``): rerun the
script against a tree that has the row; the other rows must come out unchanged. A run the
reference tree could not build (a newer integrator) is skipped.
"""

from pathlib import Path

import cases
import numpy as np
import pytest

REFERENCE = Path(__file__).parent / "data" / "reference_draws.npz"
RUNS = cases.reference_runs()


@pytest.fixture(scope="module")
def reference():
    with np.load(REFERENCE) as stored:
        return dict(stored)


def test_every_row_has_a_reference(reference):
    labels = {name.rsplit("/position", 1)[0].removesuffix("/energy") for name in reference}
    assert {f"sampler/{name}" for name in cases.SAMPLER_NAMES} <= labels
    assert {f"system/{name}" for name in cases.SYSTEM_NAMES} <= labels


@pytest.mark.parametrize("label", sorted(RUNS))
def test_draws_are_those_of_before(label, reference):
    stored = {name: value for name, value in reference.items() if name.startswith(f"{label}/")}
    if not stored:
        pytest.skip(f"{label} is newer than the reference tree")
    build, starts = RUNS[label]
    now = cases.reference_draws(label, build, starts)
    assert now.keys() == stored.keys()
    for name, value in stored.items():
        assert now[name].dtype == value.dtype and now[name].shape == value.shape, name
        np.testing.assert_allclose(now[name], value, rtol=1e-12, atol=1e-12, err_msg=name)
