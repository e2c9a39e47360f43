"""Every integration scheme liesample has, by phase space: the registries of
:mod:`liesample.foundation.schemes` gathered in one place.

Examples
--------
>>> from liesample.samplers.schemes import all_schemes
>>> registry = all_schemes()
>>> "splitting" in registry["coadjoint orbit"], "leapfrog" in registry["T*G"]
(True, True)
"""

from __future__ import annotations

from liesample.dynamics.symplectic import SCHEMES as SYMPLECTIC
from liesample.foundation.schemes import Schemes
from liesample.geometry.cotangent import SCHEMES as COTANGENT
from liesample.integrators.orbit import INTEGRATORS as ORBIT
from liesample.samplers.cotangent.magnetic_hmc import BLACKJAX_SCHEMES
from liesample.systems.charged_particle import INTEGRATORS as CHARGED_PARTICLE

__all__ = ["all_schemes"]


def all_schemes() -> dict[str, Schemes]:
    """``phase space -> Schemes``: the orbit samplers' integrators, the ``T*G`` samplers' named
    schemes, the symplectic diffusions', the charged particle's, and the BlackJAX integrators
    that magnetic HMC takes."""
    return {
        "coadjoint orbit": ORBIT,
        "T*G": COTANGENT,
        "symplectic diffusion": SYMPLECTIC,
        "charged particle": CHARGED_PARTICLE,
        "magnetic HMC (BlackJAX integrators)": BLACKJAX_SCHEMES,
    }
