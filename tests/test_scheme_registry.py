"""One registry type of integration schemes (liesample.foundation.schemes): every phase space
declares its named schemes as a ``Schemes``, resolves a name through ``lookup`` and refuses an
unknown one with the same message, naming the keyword, the allowed names and the phase space."""

import importlib

import pytest

import liesample
from liesample.foundation.schemes import Schemes
from liesample.samplers.schemes import all_schemes
from liesample.systems import rigid_body

charged = importlib.import_module("liesample.systems.charged_particle")


def test_every_phase_space_declares_its_schemes_as_one_type():
    registry = all_schemes()
    assert len(registry) == 5
    for space, schemes in registry.items():
        assert isinstance(schemes, Schemes), space
        assert len(schemes) >= 2, space
        for name in schemes:
            assert schemes.lookup(name) is schemes[name]
    assert set(all_schemes()["coadjoint orbit"]) == set(liesample.integrators.INTEGRATORS)
    described = all_schemes()["coadjoint orbit"].describe()
    assert all(described.values())  # every orbit integrator says what it is


def test_a_registry_is_read_only_and_its_descriptions_name_its_schemes():
    schemes = Schemes("a line", {"euler": 1})
    with pytest.raises(TypeError):
        schemes["heun"] = 2  # type: ignore[index]
    with pytest.raises(ValueError, match=r"descriptions of unknown schemes \['heun'\]"):
        Schemes("a line", {"euler": 1}, {"heun": "second order"})


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda: liesample.lie_poisson_langevin(
                rigid_body((1.0, 2.0, 4.0)), beta=1.0, step_size=0.1, integrator="rk4"
            ),
            r"integrator must be one of \['euler_heun', 'lie_euler', 'rkmk_heun', 'splitting'\] "
            r"\(the schemes on a coadjoint orbit\), got 'rk4'",
        ),
        (
            lambda: charged.charged_particle_dynamics(
                charged.charged_particle(lambda q: 0.5 * q @ q, dimension=2),
                beta=1.0,
                integrator="rk4",
            ),
            r"integrator must be one of \['baoab', 'heun'\] \(the schemes on the charged "
            r"particle's T\*Rⁿ\), got 'rk4'",
        ),
    ],
)
def test_an_unknown_scheme_is_refused_with_one_message(build, message):
    with pytest.raises(ValueError, match=message):
        build()
