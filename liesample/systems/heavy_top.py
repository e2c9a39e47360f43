"""The stochastic-dissipative heavy top on se(3)* = so(3)* ⋉ R³ (paper, ``app:semidirect``).

State ``μ = (Π, Γ)`` (body angular momentum, body-frame direction of gravity), Lie–Poisson with
``ad*_{(ξ,v)}(Π, Γ) = (Π×ξ + Γ×v, Γ×ξ)`` (paper, ``app:semidirect``), so ``X_h`` gives

    Π̇ = Π×∇_Π h + Γ×∇_Γ h,    Γ̇ = Γ×∇_Π h,    h = ½ Π·I⁻¹Π + mgl Γ·χ.

The Casimirs ``|Γ|² = r²`` and ``Π·Γ = c`` fix the orbit (``T*S²``). The default noise is the
six unit-strength Hamiltonians ``ĥ_i = ⟨Π, e_i⟩`` (fields ``(Π×e_i, Γ×e_i)``, rotations) and
``ĥ_{3+j} = ⟨Γ, e_j⟩`` (fields ``(Γ×e_j, 0)``), which together span the orbit's tangent space;
the dissipation is derived from them (paper, ``eq:poisson-langevin-eq``), so ``exp(−βh)`` on
the orbit is invariant (the paper's ``app:semidirect-noise-dissipation`` prints
``exp(−(β/2)h)``, a slip).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.identity import by_value
from liesample.foundation.validation import finite_float, nonzero_vector3, principal_moments
from liesample.geometry.algebras import se3
from liesample.systems.rigid_body import kinetic_pieces
from liesample.targets import HeavyTopGibbs


@by_value
def heavy_top(
    inertia: Sequence[float] = (1.0, 2.0, 4.0),
    mgl: float = 1.0,
    chi: Sequence[float] = (0.0, 0.0, 1.0),
    gravity: bool = True,
    split_hamiltonian: bool = False,
) -> LiePoissonSystem:
    """The heavy top (a rigid body with a fixed point in gravity).

    Parameters
    ----------
    inertia : sequence of 3 floats
        Principal moments ``(I₁, I₂, I₃)`` about the fixed point, each finite and > 0.
    mgl : float
        Mass × gravity × distance from the fixed point to the centre of mass; finite, any sign.
    chi : sequence of 3 floats
        Body-frame direction (and scale) of the centre of mass; finite and nonzero.
    gravity : bool
        Structural: with ``False`` the term ``mgl Γ·χ`` is not in ``h`` at all, and ``Π`` then
        follows the free rigid body exactly (``Γ`` is carried along).
    split_hamiltonian : bool
        Declare ``h`` as exactly solvable pieces: the kinetic pieces of
        :func:`liesample.systems.rigid_body.kinetic_pieces` and ``mgl Γ·χ`` (a translation). The
        ``splitting`` integrator then composes exact flows; for the Lagrange top
        (``I₁ = I₂``, ``χ ∥ e₃``) each piece is invariant under body rotations about ``e₃``, so
        ``Π₃`` is kept to round-off along any path whose noise shares the symmetry (stochastic
        Noether, paper ``prop:stoch-noether``). Default ``False``: one Heun step on ``∇h``.

    Returns
    -------
    LiePoissonSystem
        State ``(Π₁, Π₂, Π₃, Γ₁, Γ₂, Γ₃)``, shape ``(6,)``; Casimirs ``(|Γ|², Π·Γ)``. Positions
        with ``Γ = 0`` are rejected (degenerate orbit); ``Π·Γ`` may be any real.
        ``reference(beta, position)`` is :class:`liesample.targets.HeavyTopGibbs` on the orbit
        through ``position`` (``β > 0``).

    Examples
    --------
    >>> from liesample.systems import heavy_top
    >>> system = heavy_top(inertia=(1.0, 2.0, 4.0), mgl=1.0)
    >>> system.event_shape, system.algebra.casimirs(system.default_position).tolist()  # (|Γ|², Π·Γ)
    ((6,), [1.0, 0.0])
    >>> type(system.reference(1.0, system.default_position)).__name__
    'HeavyTopGibbs'
    """
    moments = principal_moments(inertia)
    mgl = finite_float("mgl", mgl)
    chi_vector = nonzero_vector3("chi", chi)
    for flag, value in (("gravity", gravity), ("split_hamiltonian", split_hamiltonian)):
        if not isinstance(value, bool):
            raise TypeError(f"{flag} must be a bool, got {value!r}")
    inverse_inertia = 1.0 / np.asarray(moments)
    gravity_vector = mgl * chi_vector

    if gravity:

        def hamiltonian(mu):
            pi, gamma = mu[..., :3], mu[..., 3:]
            return 0.5 * jnp.sum(inverse_inertia * pi * pi) + jnp.sum(gravity_vector * gamma)

    else:

        def hamiltonian(mu):
            pi = mu[..., :3]
            return 0.5 * jnp.sum(inverse_inertia * pi * pi)

    pieces = None
    if split_hamiltonian:
        pieces = kinetic_pieces(inverse_inertia, lambda mu: mu[..., :3])
        if gravity:
            pieces += (lambda mu: jnp.sum(gravity_vector * mu[..., 3:]),)

    def casimir_scale(mu):
        # |Π·Γ| ≤ ½|μ|² and |Γ|² ≤ |μ|²: the size of the round-off in either Casimir.
        return jnp.full(mu.shape[:-1] + (2,), jnp.sum(mu * mu, axis=-1)[..., None])

    def check_beta(beta):
        if not beta > 0:
            raise ValueError(
                f"beta must be > 0 for the heavy top, got {beta}: its orbits (T*S²) are not "
                "compact and the kinetic energy is unbounded, so exp(−βh) is not normalisable "
                "at β <= 0"
            )

    def reference(beta, position):
        position = np.asarray(position, dtype=float)
        pi, gamma = position[:3], position[3:]
        return HeavyTopGibbs(
            inertia=moments,
            mgl=mgl if gravity else 0.0,
            chi=chi_vector,
            beta=beta,
            radius=float(np.linalg.norm(gamma)),
            c=float(pi @ gamma),
        )

    default_gamma = -chi_vector / np.linalg.norm(chi_vector)  # hanging down, at rest
    return LiePoissonSystem(
        name="heavy top",
        algebra=se3,
        hamiltonian=hamiltonian,
        default_position=np.concatenate([np.zeros(3), default_gamma]),
        reference=reference,
        noise_reach="orbit",  # linear noise along every axis of the algebra
        check_beta=check_beta,
        component_names=("Π₁", "Π₂", "Π₃", "Γ₁", "Γ₂", "Γ₃"),
        params={"inertia": moments, "mgl": mgl, "chi": tuple(chi_vector), "gravity": gravity},
        positive_casimirs=(0,),
        casimir_scale=casimir_scale,
        hamiltonian_pieces=pieces,
    )
