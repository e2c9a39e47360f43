"""Integrators declare what they guarantee on the object, and the library reads it there."""

import dataclasses

import numpy as np
import pytest

import liesample
from liesample.integrators import DEFAULT_INTEGRATOR, INTEGRATORS, Integrator, get_integrator
from liesample.integrators.stability import STABILITY_LIMITS, check_step_size, stability_number
from liesample.integrators.substeps import adaptive_substepping

RIGID = liesample.systems.rigid_body((1.0, 2.0, 4.0))
START = np.array([1.5, 0.0, 0.0])


def test_built_in_declarations():
    declared = {
        name: (i.weak_order, i.linear_noise_only, i.preserves_orbit, i.stability_limit, i.form)
        for name, i in INTEGRATORS.items()
    }
    assert declared == {
        "splitting": (2, False, True, 2.0, "stratonovich"),
        "rkmk_heun": (1, False, True, 2.0, "stratonovich"),
        "lie_euler": (1, True, True, 2.0, "stratonovich"),
        "euler_heun": (1, False, False, None, "stratonovich"),
    }
    assert DEFAULT_INTEGRATOR == "splitting"
    assert STABILITY_LIMITS == {name: i.stability_limit for name, i in INTEGRATORS.items()}


def test_the_step_size_check_reads_the_integrators_limit():
    """The same step is accepted under the declared limit 2 and refused under a stricter one;
    an integrator that claims no limit is not checked."""
    kappa = stability_number(RIGID, 0.05, 1.5, START)
    assert 0.1 < kappa < 2.0
    splitting = get_integrator("splitting")
    assert check_step_size(RIGID, splitting, 0.05, 1.5, START, "raise") == pytest.approx(kappa)
    strict = dataclasses.replace(splitting, name="strict", stability_limit=kappa / 2)
    with pytest.raises(ValueError, match="'strict' integrator"):
        check_step_size(RIGID, strict, 0.05, 1.5, START, "raise")
    assert check_step_size(RIGID, "euler_heun", 100.0, 1.5, START, "raise") is None


def test_wrappers_inherit_the_declarations():
    for name, base in INTEGRATORS.items():
        wrapped = adaptive_substepping(base, lambda dynamics, mu: 0.0)
        assert wrapped.name == f"{name}+substeps"
        for field in ("weak_order", "linear_noise_only", "preserves_orbit", "stability_limit"):
            assert getattr(wrapped, field) == getattr(base, field)


@pytest.mark.parametrize(
    ("changes", "error", "match"),
    [
        ({"form": "ito-ish"}, ValueError, "form must be one of"),
        ({"weak_order": 1.5}, TypeError, "weak_order must be an int"),
        ({"stability_limit": 0.0}, ValueError, "stability_limit must be > 0"),
    ],
)
def test_bad_declarations_are_refused(changes, error, match):
    with pytest.raises(error, match=match):
        dataclasses.replace(get_integrator("rkmk_heun"), **changes)


def test_get_integrator_names_the_choices():
    with pytest.raises(ValueError, match="integrator must be one of"):
        get_integrator("leapfrog")
    custom = Integrator("mine", 1, True, INTEGRATORS["lie_euler"].step, "a copy")
    assert get_integrator(custom) is custom and custom.stability_limit is None
