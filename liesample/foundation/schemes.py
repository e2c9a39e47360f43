"""The one registry type of integration schemes: the named schemes of one phase space.

Each phase space declares its schemes once, as a :class:`Schemes` (a read-only mapping from a
scheme's name to what its integrator reads: an
:class:`liesample.integrators.orbit.Integrator` on a coadjoint orbit, a coefficient list of
one-effect flows on ``T*G`` (:mod:`liesample.geometry.cotangent`), a name of the symplectic
diffusions and charged particles), with a description of each; :meth:`Schemes.lookup` is the
one way a name is resolved, with the one message for an unknown name. The registries:

- ``liesample.integrators.orbit.INTEGRATORS`` (the orbit samplers' ``integrator=``);
- ``liesample.geometry.cotangent.SCHEMES`` (the ``T*G`` samplers' ``integrator=``);
- ``liesample.dynamics.symplectic.SCHEMES`` (``symplectic_path``'s ``scheme=``);
- ``liesample.systems.charged_particle.INTEGRATORS`` (``charged_particle_dynamics``);
- ``liesample.samplers.cotangent.magnetic_hmc.BLACKJAX_SCHEMES`` (BlackJAX's integrators
  that magnetic HMC takes, by object).

``liesample.samplers.schemes.all_schemes`` lists them together.

Examples
--------
>>> from liesample.foundation.schemes import Schemes
>>> schemes = Schemes("a line", {"euler": 1, "heun": 2}, {"euler": "first order"})
>>> schemes.lookup("heun"), sorted(schemes), schemes.describe()["euler"]
(2, ['euler', 'heun'], 'first order')
>>> schemes.lookup("rk4")
Traceback (most recent call last):
...
ValueError: integrator must be one of ['euler', 'heun'] (the schemes on a line), got 'rk4'
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from types import MappingProxyType
from typing import Any

__all__ = ["Schemes"]


class Schemes(Mapping[Any, Any]):
    """The named schemes on one phase space ``space``: ``name -> definition`` (read-only), a
    description per name (``descriptions``; default: none), and the keyword ``parameter`` that
    selects one (named in the error of :meth:`lookup`)."""

    def __init__(
        self,
        space: str,
        schemes: Mapping[Any, Any],
        descriptions: Mapping[Any, str] | None = None,
        parameter: str = "integrator",
    ):
        unknown = sorted(map(str, set(descriptions or {}) - set(schemes)))
        if unknown:
            raise ValueError(f"descriptions of unknown schemes {unknown}")
        self.space, self.parameter = space, parameter
        self._schemes = MappingProxyType(dict(schemes))
        self._descriptions = MappingProxyType(dict(descriptions or {}))

    def __getitem__(self, name):
        return self._schemes[name]

    def __iter__(self) -> Iterator:
        return iter(self._schemes)

    def __len__(self) -> int:
        return len(self._schemes)

    def __repr__(self) -> str:
        return f"Schemes({self.space!r}, {sorted(map(str, self))})"

    def lookup(self, name, parameter: str | None = None):
        """The definition of the scheme ``name``; a ``ValueError`` naming ``parameter``
        (default: the registry's), the allowed names and this phase space otherwise."""
        try:
            return self._schemes[name]
        except (KeyError, TypeError):  # TypeError: an unhashable value
            allowed = sorted(map(str, self))
            raise ValueError(
                f"{parameter or self.parameter} must be one of {allowed} (the schemes on "
                f"{self.space}), got {name!r}"
            ) from None

    def describe(self) -> dict:
        """``name -> description`` (empty text where none was given)."""
        return {name: self._descriptions.get(name, "") for name in self}
