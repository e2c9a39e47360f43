"""``binder_cumulant`` reads one chain ``(draws, components)`` or many ``(chains, draws,
components)`` of a vector magnetisation, and refuses other shapes clearly."""

import numpy as np
import pytest

from liesample.analysis.diagnostics import binder_cumulant


def test_one_chain_and_many_chains_of_a_vector_magnetisation():
    rng = np.random.default_rng(0)
    m = rng.standard_normal((4, 2000, 3))  # Gaussian 3-component m: U = 4/9
    many = binder_cumulant(m)
    assert abs(many.estimate - 4.0 / 9.0) < 4 * many.error, many
    one = binder_cumulant(m[0])
    same = binder_cumulant(m[:1])
    assert one.estimate == pytest.approx(same.estimate, rel=1e-14)
    assert one.error == pytest.approx(same.error, rel=1e-14)
    assert abs(one.estimate - 4.0 / 9.0) < 4 * one.error, one
    xy = binder_cumulant(rng.standard_normal((3000, 2)))  # n = 2: U = 1 - 4/6
    assert abs(xy.estimate - 1.0 / 3.0) < 4 * xy.error, xy


@pytest.mark.parametrize("shape", [(2, 3, 100, 3), (100, 1), ()])
def test_other_shapes_are_refused_naming_the_accepted_ones(shape):
    with pytest.raises(ValueError, match=r"\(draws, components\) for one chain"):
        binder_cumulant(np.ones(shape))
