"""Samplers that know they are outside their validity say so by name (no compilation here)."""

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
