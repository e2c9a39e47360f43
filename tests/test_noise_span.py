"""The rank test that refuses noise unable to reach the orbit (Hörmander's condition at a
generic point, liesample.dynamics.noise_span)."""

import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import systems
from liesample.dynamics.noise_span import noise_span


def test_the_librarys_linear_noises_span_their_orbits():
    for system, dimension in (
        (systems.rigid_body((1.0, 2.0, 3.0)), 2),
        (systems.heavy_top(), 4),
        (systems.heisenberg((4,)), 8),
    ):
        span = noise_span(system)
        assert span.final and span.rank == span.orbit_dimension == dimension, system.name


# The linear-noise closure runs by default on the rigid body, heavy top, spins and Zeitlin ℓ = 1.
@pytest.mark.slow
def test_zeitlin_degree_two_modes_generate_the_whole_orbit():
    """ℓ ≤ 2 modes and their brackets reach every direction of a generic su(N) orbit
    (dimension N² − N), the fact ``zeitlin_euler`` declares."""
    for size in (4, 6):
        span = noise_span(systems.zeitlin_euler(size, noise_degree=2))
        assert span.final and span.rank == span.orbit_dimension == size * size - size


def test_zeitlin_rigid_rotations_alone_cannot_reach_the_orbit():
    """The three ℓ = 1 modes (rigid rotations) close under brackets: rank 3 of N² − N."""
    system = systems.zeitlin_euler(4, noise_degree=2)
    harmonics = system.params["harmonics"]
    rotations = np.flatnonzero(np.asarray(harmonics.degrees)[1:] == 1)  # ℓ = 1 of the ℓ >= 1 modes
    rigid = system.with_noise(lambda w: system.noise_hamiltonians(w)[rotations])
    span = noise_span(rigid)
    assert span.final and span.rank == 3 < span.orbit_dimension == 12
    with pytest.raises(ValueError, match="cannot reach its orbit"):
        liesample.adjusted_lie_poisson(rigid, beta=1.0, step_size=0.1)


def test_one_axis_of_noise_on_the_rigid_body_is_refused_by_both_samplers():
    one_axis = systems.rigid_body((1.0, 2.0, 3.0)).with_noise(lambda m: m[..., :1])
    for build in (liesample.lie_poisson_langevin, liesample.adjusted_lie_poisson):
        with pytest.raises(ValueError, match="1 of the orbit's 2 directions"):
            build(one_axis, beta=1.0, step_size=0.1)
    two_axes = systems.rigid_body((1.0, 2.0, 3.0)).with_noise(lambda m: m[..., :2])
    liesample.lie_poisson_langevin(two_axes, beta=1.0, step_size=0.1)  # brackets give the third


def test_nonlinear_noise_that_only_rotates_rigidly_is_refused():
    """Point vortices moved only by rigid rotations (the ℓ = 1 transport): the fields close under
    brackets, rank 3 of 2K."""
    circulations = jnp.array([1.0, 2.0, -1.0])
    system = systems.point_vortices(circulations, max_degree=2)

    def rotations(x):
        # ĥ_i = f(m_i), m = Σ Γ_k x_k the momentum map: each field is a multiple of a rigid
        # rotation of all vortices, so the span is closed under brackets (non-linear noise)
        momentum = jnp.sum(circulations[:, None] * x, axis=0)
        return momentum + 0.3 * momentum**3

    rigid = system.with_noise(rotations)
    span = noise_span(rigid)
    assert span.rank == 3 and span.orbit_dimension == 6
    with pytest.raises(ValueError, match="cannot reach its orbit"):
        liesample.lie_poisson_langevin(rigid, beta=1.0, step_size=0.01)


def test_a_symmetric_noise_is_refused_unless_declared_to_keep_its_level_set():
    """Stochastic Noether: noise along Π₃ and Γ₃ keeps Π₃. Tested, it is refused (it cannot
    reach the orbit); declared with ``noise_reach="level_set"``, it is accepted."""
    top = systems.heavy_top(inertia=(1.0, 1.0, 2.0))

    def symmetric(mu):
        return jnp.stack([mu[2], mu[5]])

    with pytest.raises(ValueError, match="noise_reach='level_set'"):
        liesample.lie_poisson_langevin(top.with_noise(symmetric), beta=1.0, step_size=0.05)
    kept = top.with_noise(symmetric, noise_reach="level_set")
    liesample.lie_poisson_langevin(kept, beta=1.0, step_size=0.05)
    with pytest.raises(ValueError, match="noise_reach must be one of"):
        top.with_noise(symmetric, noise_reach="sometimes")
