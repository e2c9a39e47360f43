"""Template for a new system: copy this file to ``liesample/systems/<your_system>.py``.

A system only *declares* what the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``)
needs: a Lie algebra (the Poisson structure on ``g*``), a Hamiltonian ``h``, unit-strength
noise Hamiltonians ``ĥ_i`` and, where one is known, the exact Gibbs law ``∝ exp(−βh)`` on an
orbit. The dissipation, the Casimir checks, every integrator and every sampler come from the
engine; a system never writes a drift by hand.

The working example here is a magnetic moment ``μ ∈ so(3)*`` in a constant field ``b``:

    h(μ) = −b·μ,        ĥ_i(μ) = e_i·μ  (i = 1, 2, 3: rotations about the body axes).

Its orbit is the sphere ``|μ| = r`` and its Gibbs law there is the von Mises–Fisher law of
``μ/r`` with mean direction ``b/|b|`` and concentration ``κ = β r |b|``
(:class:`liesample.targets.groups.VonMisesFisherLaw`), so it can be checked exactly.

Steps for your own system:

1. Rename the constructor and fill in ``hamiltonian`` (a JAX function of ``μ``; the state may
   carry leading axes, e.g. ``(N, 3)`` for ``N`` copies of so(3)*, see
   :mod:`liesample.systems.heisenberg`). The noise defaults to ``ĥ_i = e_i·μ`` along every
   coordinate (:func:`liesample.dynamics.system.coordinate_noise`); pass
   ``noise_hamiltonians=`` for another.
2. Pick the algebra from :mod:`liesample.geometry.algebras` (``so3``, ``se3``, ``unitary(N)``
   or ``StructureConstants`` for any other).
3. Give the exact reference if there is one (from :mod:`liesample.targets`, or a new module
   there), else ``reference=None``.
4. Validate every argument with :mod:`liesample.foundation.validation` so that a bad input
   fails at construction, naming the parameter.
5. Keep the ``@by_value`` decorator (:mod:`liesample.foundation.identity`): two systems built
   from equal arguments are then equal, and every compiled program serves both (a user's
   ``def run(beta): system = moment_in_field(...)`` compiles once, not once per call).
6. Export the constructor from :mod:`liesample.systems` (its ``__init__``) if it is public.

Imports may only point down the layers: ``foundation``, ``geometry``, ``targets``,
``dynamics`` and ``integrators`` (never ``samplers`` or above).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.validation import nonzero_vector3
from liesample.geometry.algebras import so3
from liesample.targets.groups import VonMisesFisherLaw

__all__ = ["moment_in_field"]


@by_value
def moment_in_field(field: Sequence[float] = (0.0, 0.0, 1.0)) -> LiePoissonSystem:
    """A magnetic moment on so(3)* precessing in the constant field ``field``.

    Parameters
    ----------
    field : sequence of 3 floats
        The field ``b``; finite and nonzero.

    Returns
    -------
    LiePoissonSystem
        State ``μ`` of shape ``(3,)``; Casimir ``|μ|²``. ``system.reference(beta, position)`` is
        the exact law of the direction ``μ/|μ|`` on the orbit through ``position``.
    """
    b = nonzero_vector3("field", field)
    strength = float(np.linalg.norm(b))

    def hamiltonian(mu):
        return -jnp.sum(jnp.asarray(b, mu.dtype) * mu, axis=-1)

    def reference(beta, position):
        radius = float(np.linalg.norm(np.asarray(position)))
        return VonMisesFisherLaw(mean_direction=b / strength, kappa=float(beta) * radius * strength)

    return LiePoissonSystem(
        name="moment in a field",
        algebra=so3,
        hamiltonian=hamiltonian,
        default_position=np.array([1.0, 0.0, 0.0]),
        reference=reference,
        component_names=("μ₁", "μ₂", "μ₃"),
        params={"field": tuple(float(v) for v in b)},
    )
