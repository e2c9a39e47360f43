"""The recommended sampler per system is the exact one where one exists, and it runs by the
default path (no step size given)."""

import jax
import numpy as np
import pytest

import liesample
from liesample import systems


@pytest.mark.parametrize(
    ("system", "name"),
    [
        (systems.rigid_body((1.0, 2.0, 3.0)), "adjusted_lie_poisson"),
        (systems.heavy_top(), "adjusted_lie_poisson"),
        # slow: its default step's stiffness program (matrix exponentials) compiles for seconds;
        # the rule it checks (linear noise: adjusted) runs by default on the rigid body and top
        pytest.param(systems.zeitlin_euler(4), "adjusted_lie_poisson", marks=pytest.mark.slow),
        (systems.heisenberg((8,)), "heisenberg_heat_bath"),
        (systems.point_vortices([1.0, -1.0, 1.0]), "vortex_metropolis"),
    ],
    ids=lambda x: getattr(x, "name", x),
)
def test_recommended_sampler_per_system(system, name):
    sampler = liesample.recommended_sampler(system, beta=1.0)
    assert sampler.settings["sampler"] == name


def test_nonlinear_noise_gets_the_langevin_sampler():
    rigid = systems.rigid_body((1.0, 2.0, 3.0))
    cubic = rigid.with_noise(lambda m: m + 0.1 * m**3)
    sampler = liesample.recommended_sampler(cubic, beta=1.0)
    assert sampler.settings["sampler"] == "lie_poisson_langevin"


@pytest.mark.slow  # the default path is tested per sampler (test_negative_temperature, ...)
def test_recommended_sampler_runs_by_the_default_path():
    system = systems.rigid_body((1.0, 2.0, 3.0))
    target = system.reference(2.0, system.default_position)
    sampler = liesample.recommended_sampler(system, beta=2.0)
    tree = liesample.sample(sampler, jax.random.key(0), target.sample(jax.random.key(1), 4), 50,
                            progress_bar=False)  # fmt: skip
    assert np.isfinite(tree.attrs["step_size"])
    assert tree.attrs["step_size_source"].startswith("warm-up dual averaging")


def test_refuses_what_is_not_a_lie_poisson_system():
    with pytest.raises(TypeError, match="LiePoissonSystem"):
        liesample.recommended_sampler(
            systems.charged_particle(lambda q: q @ q, dimension=2), beta=1.0
        )
