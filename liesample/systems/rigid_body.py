"""The stochastic-dissipative rigid body on so(3)* (paper, ``sec:stoch-diss-rigid-body``).

``h = ½ μ·I⁻¹μ`` and noise ``ĥ_i = e_i·μ``; with ``θ = βσ²/2`` the engine produces (paper,
``eq:stoch-diss-rb`` with the dissipation's sign corrected)

    dμ = μ×Ω dt + θ μ×(μ×Ω) dt + σ Σ_i μ×e_i ∘ dW_i,     Ω = I⁻¹μ,

whose invariant law on ``|μ| = r`` is the restricted Gaussian ``∝ exp(−(β/2) μ·I⁻¹μ)``
(the paper's printed ``eq:stoch-diss-rb`` has the opposite, anti-dissipative sign).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.validation import principal_moments
from liesample.geometry.algebras import so3
from liesample.targets import RestrictedGaussian


def kinetic_pieces(
    inverse_inertia: npt.ArrayLike, momentum: Callable[[jax.Array], jax.Array]
) -> tuple[Callable[[jax.Array], jax.Array], ...]:
    """``½ Π·I⁻¹Π = ½|Π|²/I₁ + Σ_{i=2,3} ½ (1/I_i − 1/I₁) Π_i²`` as exactly solvable pieces.

    Each piece's gradient is constant along its own flow (``Π`` rotates about itself or about
    ``e_i``), so one coadjoint move solves it (``LiePoissonSystem.hamiltonian_pieces``); terms
    with a zero coefficient are left out. With ``I₁ = I₂`` every piece is invariant under
    rotations about ``e₃`` (the Lagrange top's symmetry). ``momentum(μ)`` selects ``Π``.
    """
    inverse_inertia = np.asarray(inverse_inertia, dtype=float)
    pieces: list[Callable[..., jax.Array]] = [
        lambda mu: 0.5 * inverse_inertia[0] * jnp.sum(momentum(mu) ** 2)
    ]
    for axis in (1, 2):
        coefficient = float(inverse_inertia[axis] - inverse_inertia[0])
        if coefficient != 0.0:
            pieces.append(lambda mu, c=coefficient, a=axis: 0.5 * c * momentum(mu)[..., a] ** 2)
    return tuple(pieces)


@by_value
def rigid_body(
    inertia: Sequence[float] = (1.0, 2.0, 4.0), split_hamiltonian: bool = False
) -> LiePoissonSystem:
    """The free rigid body with principal moments of inertia ``inertia``.

    Parameters
    ----------
    inertia : sequence of 3 floats
        Principal moments ``(I₁, I₂, I₃)``, each finite and > 0.
    split_hamiltonian : bool
        Declare ``h`` as exactly solvable pieces (:func:`kinetic_pieces`), so that the
        ``splitting`` integrator's Hamiltonian flow is a composition of exact rotations (a
        Poisson map). Default ``False``: one Heun step on ``∇h``.

    Returns
    -------
    LiePoissonSystem
        State ``μ`` of shape ``(3,)`` (body angular momentum); Casimir ``|μ|²``.

    Examples
    --------
    >>> from liesample.systems import rigid_body
    >>> system = rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> float(system.hamiltonian(jnp.array([1.0, 0.0, 0.0])))  # ½ μ·I⁻¹μ
    0.5
    >>> law = system.reference(3.0, jnp.array([1.5, 0.0, 0.0]))  # exact law on |μ| = 1.5
    >>> bool(jnp.isclose(law.second_moments().sum(), 1.5**2))
    True
    """
    moments = principal_moments(inertia)
    if not isinstance(split_hamiltonian, bool):
        raise TypeError(f"split_hamiltonian must be a bool, got {split_hamiltonian!r}")
    inverse_inertia = 1.0 / np.asarray(moments)

    def hamiltonian(mu):
        return 0.5 * jnp.sum(inverse_inertia * mu * mu)

    def reference(beta, position):
        radius = float(np.linalg.norm(np.asarray(position)))
        return RestrictedGaussian(inertia=moments, beta=float(beta), radius=radius)

    return LiePoissonSystem(
        name="rigid body",
        algebra=so3,
        hamiltonian=hamiltonian,
        default_position=np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0),
        reference=reference,
        noise_reach="orbit",  # linear noise along every axis of the algebra
        component_names=("μ₁", "μ₂", "μ₃"),
        params={"inertia": moments},
        hamiltonian_pieces=kinetic_pieces(inverse_inertia, lambda mu: mu)
        if split_hamiltonian
        else None,
    )
