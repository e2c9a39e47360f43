"""A user-defined system needs only an algebra, h and noise: ``examples/custom_system.py``
(a pendulum on se(2)*, a non-compact orbit) samples its exact Gibbs law."""

import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from conftest import load_example
from liesample.dynamics.system import LiePoissonSystem, checked_beta, coordinate_noise
from liesample.geometry.algebras import so3
from liesample.systems import lie_poisson_system


# the example's law by statistics; its system inference and refusals run by default
@pytest.mark.slow
def test_example_samples_the_exact_law():
    example = load_example("custom_system")
    estimate, se, radius_drift = example.run(num_chains=64, num_draws=300, progress=False)
    z = (estimate - example.exact()) / se
    assert np.all(np.abs(z) < 4.0), (estimate, example.exact(), se)
    assert radius_drift < 1e-10  # the Casimir |p| through the generic (expm) coadjoint action
    # power: the law at half the temperature is rejected
    assert abs(estimate[0] - 2 * example.exact()[0]) > 10 * se[0]


def test_system_is_inferred_from_the_functions():
    system = load_example("custom_system").pendulum()
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


def test_declaration_reads_noise_count_and_shape_off_the_default_position():
    """Left out, the noise is ``ĥ_i = μ_i`` along every coordinate and ``m``, the event shape
    follow from ``default_position``; the library's linear-noise systems use that default."""
    system = LiePoissonSystem(
        name="free body",
        algebra=so3,
        hamiltonian=lambda mu: 0.5 * jnp.sum(mu * mu),
        default_position=np.ones((2, 3)),
    )
    assert system.noise_hamiltonians is coordinate_noise
    assert system.num_noises == 6 and system.event_shape == (2, 3)
    np.testing.assert_array_equal(coordinate_noise(jnp.arange(6.0).reshape(2, 3)), np.arange(6.0))
    assert liesample.systems.rigid_body().num_noises == 3
    assert liesample.systems.heavy_top().num_noises == 6
    assert liesample.systems.heisenberg((4,)).num_noises == 12
    with pytest.raises(ValueError, match="1-D array"):
        LiePoissonSystem(
            name="bad",
            algebra=so3,
            hamiltonian=lambda mu: 0.0,
            default_position=np.ones(3),
            noise_hamiltonians=lambda mu: mu[None],
        )


def test_checked_beta_names_what_is_wrong():
    assert checked_beta(liesample.systems.rigid_body(), -2) == -2.0
    with pytest.raises(ValueError, match="beta must be finite"):
        checked_beta(liesample.systems.rigid_body(), float("nan"))
    with pytest.raises(ValueError, match="heavy top"):
        checked_beta(liesample.systems.heavy_top(), 0.0)
