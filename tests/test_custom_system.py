"""A user-defined system needs only an algebra, h and noise: ``examples/custom_system.py``
(a pendulum on se(2)*, a non-compact orbit) samples its exact Gibbs law."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from liesample.geometry.algebras import so3
from liesample.systems import lie_poisson_system


def load_example():
    path = Path(__file__).parents[1] / "examples" / "custom_system.py"
    spec = importlib.util.spec_from_file_location("custom_system", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_example_samples_the_exact_law():
    example = load_example()
    estimate, se, radius_drift = example.run(num_chains=64, num_draws=300, progress=False)
    z = (estimate - example.exact()) / se
    assert np.all(np.abs(z) < 4.0), (estimate, example.exact(), se)
    assert radius_drift < 1e-10  # the Casimir |p| through the generic (expm) coadjoint action
    # power: the law at half the temperature is rejected
    assert abs(estimate[0] - 2 * example.exact()[0]) > 10 * se[0]


def test_system_is_inferred_from_the_functions():
    system = load_example().pendulum()
    assert system.num_noises == 3
    assert system.event_shape == (3,)
    assert system.noise_group_labels.tolist() == [0, 1, 2]


@pytest.mark.parametrize(
    ("arguments", "match"),
    [
        ((so3, lambda mu: mu, lambda mu: mu, [1.0, 0.0, 0.0]), "hamiltonian must return a scalar"),
        ((so3, lambda mu: mu @ mu, lambda mu: mu[0], [1.0, 0.0, 0.0]), "1-D array"),
        ((so3, lambda mu: mu @ mu, lambda mu: mu, [0.0, 0.0, 0.0]), "degenerate orbit"),
        ((so3, lambda mu: mu @ mu, lambda mu: mu, [[1.0, 0.0]]), "shape"),
        (("so3", lambda mu: mu @ mu, lambda mu: mu, [1.0, 0.0, 0.0]), "LieAlgebra"),
        ((so3, 3.0, lambda mu: mu, [1.0, 0.0, 0.0]), "hamiltonian must be a callable"),
        ((so3, lambda mu: mu @ mu, None, [1.0, 0.0, 0.0]), "noise_hamiltonians must be a callable"),
    ],
)
def test_bad_declarations(arguments, match):
    with pytest.raises((ValueError, TypeError), match=match):
        lie_poisson_system(*arguments)
