"""The recommended sampler per system is the exact one where one exists, and it runs by the
default path (no step size given)."""

from pathlib import Path

import jax
import numpy as np
import pytest

import liesample
from liesample import systems
from liesample.samplers import recommended


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


def _side(window, extra=0):
    """The side of the smallest cubic lattice of ``window``'s dimension with at least
    ``window.min_sites`` sites, plus ``extra``."""
    side = round(window.min_sites ** (1 / window.dimension))
    assert side**window.dimension == window.min_sites
    return side + extra


WINDOWS = recommended.N_VECTOR_CLUSTER_WINDOWS


@pytest.mark.parametrize("window", WINDOWS, ids=lambda w: f"O({w.n}) {w.dimension}-D")
def test_n_vector_cluster_inside_each_measured_window(window):
    middle = 0.5 * (window.beta_low + window.beta_high)
    for side in (_side(window), _side(window, 8)):
        system = systems.n_vector((side,) * window.dimension, window.n, periodic=True)
        for beta in (window.beta_low, middle, window.beta_high):
            assert recommended.spin_sampler_name(system, beta) == "heisenberg_cluster"
    # βJ is what counts: a coupling of 2 halves the β of the window
    doubled = systems.n_vector(
        (_side(window),) * window.dimension, window.n, coupling=2.0, periodic=True
    )
    assert recommended.spin_sampler_name(doubled, middle / 2) == "heisenberg_cluster"
    sampler = liesample.recommended_sampler(doubled, beta=middle / 2)
    assert sampler.settings["sampler"] == "heisenberg_cluster"


@pytest.mark.parametrize("window", WINDOWS, ids=lambda w: f"O({w.n}) {w.dimension}-D")
def test_n_vector_heat_bath_outside_each_measured_window(window):
    shape = (_side(window),) * window.dimension
    middle = 0.5 * (window.beta_low + window.beta_high)
    periodic = systems.n_vector(shape, window.n, periodic=True)
    outside = [
        (periodic, 0.99 * window.beta_low),  # hotter than measured
        (periodic, 1.01 * window.beta_high),  # colder than measured
        (
            systems.n_vector((_side(window, -1),) * window.dimension, window.n, periodic=True),
            middle,
        ),  # smaller lattice than measured
        (systems.n_vector(shape, window.n), middle),  # open boundaries
        (systems.n_vector(shape, window.n, coupling=-1.0, periodic=True), -middle),
        (
            systems.n_vector(
                shape, window.n, periodic=True, field=(0.1,) + (0.0,) * (window.n - 1)
            ),
            middle,
        ),  # a field
    ]
    for system, beta in outside:
        assert recommended.spin_sampler_name(system, beta) == "heisenberg_heat_bath"
    sampler = liesample.recommended_sampler(periodic, beta=1.01 * window.beta_high)
    assert sampler.settings["sampler"] == "heisenberg_heat_bath"
    assert sampler.settings["overrelaxation"] == 1


@pytest.mark.parametrize(
    ("shape", "n"),
    [((16, 16, 16), 5), ((16, 16, 16, 16), 2), ((256,), 2), ((64, 64), 6)],
    ids=["O(5) 3-D", "XY 4-D", "XY chain", "O(6) 2-D"],
)
def test_n_vector_heat_bath_where_nothing_was_measured(shape, n):
    system = systems.n_vector(shape, n, periodic=True)
    for beta in (0.3, 0.5, 1.0, 2.0):
        assert recommended.spin_sampler_name(system, beta) == "heisenberg_heat_bath"


def test_the_docs_say_what_is_measured():
    root = Path(__file__).resolve().parent.parent
    guide = (root / "docs" / "spins.md").read_text()
    docstring = recommended.__doc__ + recommended.spin_sampler_name.__doc__
    assert "cluster_choice" in guide and "cluster_choice" in docstring
    assert "N_VECTOR_CLUSTER_WINDOWS" in docstring
    for window in WINDOWS:
        assert f"{window.beta_low:g}" in guide and f"{window.beta_high:g}" in guide
