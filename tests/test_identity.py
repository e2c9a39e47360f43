"""Systems equal by value (``liesample.foundation.identity``): two systems built by one factory
from equal arguments are equal and hash equal, so the programs compiled for one serve the
other; different arguments, a system declared by hand and one derived from another keep their
own identity."""

import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.foundation.identity import by_value, canonical, recipe

systems = liesample.systems


@pytest.mark.parametrize(
    "build",
    [
        lambda: systems.rigid_body((1.0, 2.0, 4.0)),
        lambda: systems.heavy_top(),
        lambda: systems.point_vortices([1.0, 1.0, -1.0, -1.0]),
        lambda: systems.point_vortices(np.array([1.0, -1.0]), max_degree=3),
        lambda: systems.heisenberg((4, 4), coupling=1.0, periodic=True),
        lambda: systems.zeitlin_euler(4),
        lambda: systems.wilson_gauge("SU2", (4, 4)),
    ],
    ids=["rigid", "heavy_top", "vortices", "vortices_at", "heisenberg", "zeitlin", "gauge"],
)
def test_equal_arguments_give_equal_systems(build):
    first, second = build(), build()
    assert first is not second
    assert first == second and hash(first) == hash(second)
    assert {first: 1}[second] == 1  # usable as a key of jax.jit's static arguments


def test_different_arguments_give_different_systems():
    assert systems.rigid_body((1.0, 2.0, 4.0)) != systems.rigid_body((1.0, 2.0, 5.0))
    assert systems.rigid_body() != systems.rigid_body(split_hamiltonian=True)
    assert systems.heisenberg((4,), coupling=1.0) != systems.heisenberg((4,), coupling=-1.0)
    assert systems.heisenberg((4,)) != systems.heisenberg((5,))
    assert systems.zeitlin_euler(4) != systems.zeitlin_euler(5)


def test_a_system_without_a_recipe_is_compared_by_identity():
    so3, start = liesample.algebras.so3, np.array([0.0, 0.0, 1.0])
    by_hand = systems.lie_poisson_system(so3, lambda mu: mu @ mu, lambda mu: mu, start)
    again = systems.lie_poisson_system(so3, lambda mu: mu @ mu, lambda mu: mu, start)
    assert by_hand == by_hand and by_hand != again  # two functions: two systems
    base = systems.rigid_body()
    derived = base.with_noise(lambda mu: mu[:2])
    assert recipe(derived) is None and derived != base and derived == derived


def test_the_same_function_object_gives_equal_systems():
    def h(mu):
        return 0.5 * mu @ mu

    def noise(mu):
        return mu

    so3, start = liesample.algebras.so3, np.array([0.0, 0.0, 1.0])
    first = systems.lie_poisson_system(so3, h, noise, start)
    assert first == systems.lie_poisson_system(so3, h, noise, start.copy())
    assert first != systems.lie_poisson_system(so3, h, noise, 2 * start)


def test_canonical_forms():
    assert canonical(np.arange(3.0)) == canonical(jnp.arange(3.0))
    assert canonical(np.arange(3.0)) != canonical(np.arange(3.0, dtype=np.float32))
    assert canonical([1.0, 2.0]) != canonical((1.0, 2.0))
    assert canonical({"a": 1.0}) == canonical({"a": 1.0})
    with pytest.raises(TypeError, match="unhashable"):
        canonical(type("Unhashable", (), {"__hash__": None})())

    @by_value
    def made(values):
        return type("Made", (), {})()

    assert recipe(made([1.0])) is not None
    assert recipe(made([{1, 2}])) is None  # an unhashable argument: no recipe, identity
