"""Samplers that know they are outside their validity say so by name."""

import math
import warnings

import pytest

import liesample
from liesample.samplers.orbit.vortex_metropolis import mixing_warning
from liesample.systems import point_vortices


def test_vortex_metropolis_warns_where_a_pair_exponent_is_below_minus_one_half():
    # like-signed pair at β = −12: exponent −0.955, normalisable (> −1) but not mixing
    pair = point_vortices([1.0, 1.0])
    with pytest.warns(UserWarning, match=r"p = beta\*Γ_jΓ_k/\(4π\) = -0.955 < -1/2") as record:
        liesample.vortex_metropolis(pair, beta=-12.0)
    message = str(record[0].message)
    assert "mix for beta >= -6.28319" in message and "system.reference(beta).sample" in message
    assert record[0].filename == __file__  # the caller's line, not the library's
    with pytest.warns(UserWarning, match="vortex_metropolis at beta = -12"):
        liesample.recommended_sampler(pair, beta=-12.0)
    # an attracting dipole at β > 0, and three vortices (no exact law to point to)
    assert "beta <= 3.14159" in mixing_warning(point_vortices([2.0, -1.0]), 5.0)
    triple = mixing_warning(point_vortices([1.0, 1.0, 1.0]), -7.0)
    assert "run far more sweeps" in triple


@pytest.mark.parametrize(
    ("circulations", "beta"),
    [([1.0, 1.0], -6.0), ([1.0, -1.0], 2 * math.pi), ([1.0, 1.0], 3.0), ([1.0] * 5, -4.0)],
)
def test_vortex_metropolis_is_silent_where_it_mixes(circulations, beta):
    # exponents −0.48, exactly −1/2 (a logarithmic divergence only), repulsive, Onsager's case
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        liesample.vortex_metropolis(point_vortices(circulations), beta=beta)


def _box(x):
    """The uniform law on the unit square: 0 inside, −∞ outside (a bounded support)."""
    import jax.numpy as jnp

    return jnp.where(jnp.all((x >= 0.0) & (x <= 1.0)), 0.0, -jnp.inf)


def test_unadjusted_langevin_on_a_bounded_support_names_the_adjusted_sampler():
    # magnetic_langevin at a step that crosses the walls: its rejected steps bias the law (its
    # mean sits near the walls, not at 0.5), and the divergence warning says why and names
    # magnetic_hmc rather than a smaller step
    import jax
    import jax.numpy as jnp

    d = 2
    sampler = liesample.magnetic_langevin(
        _box, step_size=0.3, inverse_mass_matrix=jnp.ones(d), friction=1.0,
        magnetic_field=jnp.zeros((d, d)),
    )  # fmt: skip
    starts = jnp.full((2, d), 0.5)
    with pytest.warns(RuntimeWarning, match="divergent step") as record:
        liesample.sample(sampler, jax.random.key(0), starts, 20, num_warmup=0, progress_bar=False)
    divergence = next(str(w.message) for w in record if "divergent step" in str(w.message))
    assert "unadjusted" in divergence and "liesample.magnetic_hmc" in divergence
    assert "Reduce step_size" not in divergence
    # the adjusted sampler keeps the generic advice
    assert liesample.magnetic_hmc(
        _box, step_size=0.3, inverse_mass_matrix=jnp.ones(d), num_integration_steps=1,
        magnetic_field=jnp.zeros((d, d)),
    ).divergence_advice is None  # fmt: skip
    assert (
        "unadjusted"
        in liesample.geometric_langevin(
            _box, liesample.spaces.Euclidean((d,)), step_size=0.3
        ).divergence_advice
    )


def test_the_langevin_sampler_on_a_collapsing_vortex_pair_warns_once():
    """lie_poisson_langevin at the β where vortex_metropolis warns: its steps are local too
    (measured at β = −12 it was further off than the sweeps), so it says so, at the caller's
    line, once: not again when liesample.sample's warm-up remakes it with the chosen step."""
    from liesample.samplers.contract import ValidityWarning

    pair = point_vortices([1.0, 1.0])
    with pytest.warns(ValidityWarning, match="lie_poisson_langevin at beta = -12") as record:
        liesample.lie_poisson_langevin(pair, beta=-12.0, step_size=0.05)
    assert record[0].filename == __file__ and "mix for beta >= -6.28319" in str(record[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValidityWarning)
        built = liesample.lie_poisson_langevin(pair, beta=-12.0, step_size=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert built.recipe("test", step_size=0.1).settings["step_size_source"] == "test"
        liesample.lie_poisson_langevin(pair, beta=-4.0, step_size=0.05)  # mixes: quiet
