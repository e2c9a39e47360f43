"""Shared pieces of the magnetic samplers on T*Rⁿ (paper, ``sec:brownian-particle``).

The chain state is ``z = (q, p)`` with the Poisson tensor ``J = [[0, I], [−I, G]]``, ``G`` a
constant antisymmetric matrix (the *magnetic field*), and ``h = −log π(q) + ½ pᵀM⁻¹p``.
:mod:`liesample.samplers.cotangent.magnetic_hmc` and
:mod:`liesample.samplers.cotangent.magnetic_langevin` are the geometric samplers on
``spaces.Euclidean((d,))`` (the raveled position) with that field: the exact kinetic–magnetic
flow, the momentum law ``N(0, M)`` (:class:`Metric`, diagonal or dense ``M⁻¹``) and its exact
Ornstein–Uhlenbeck step are those of :mod:`liesample.geometry.cotangent` (re-exported here as
:func:`magnetic_flow`, :func:`make_metric`). This module holds what the two fronts share:
parameter validation, pytree raveling, start checks, and :func:`default_magnetic_field`, the
default field and its tuning rule. The fronts import the geometric implementation; nothing
there imports them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jax.typing import ArrayLike

from liesample.foundation.compile import evaluate
from liesample.foundation.identity import Program, run_program
from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry.cotangent import (
    KineticMagneticFlow,
    Metric,
    check_magnetic_field,
    kinetic_magnetic_flow,
    make_metric,
)
from liesample.geometry.spaces import Euclidean, check_inverse_mass_matrix
from liesample.samplers.contract import first_bad_chain
from liesample.samplers.cotangent._core import (
    check_logdensity_value,
    check_positive_step_size,
    make_move,
    with_model_arguments,
)

__all__ = [
    "MagneticFlow",
    "Metric",
    "check_euclidean_starts",
    "check_inverse_mass_matrix",
    "check_magnetic_field",
    "check_parameters",
    "check_starts",
    "default_magnetic_field",
    "euclidean_move",
    "initial_values",
    "magnetic_flow",
    "make_metric",
]

MagneticFlow = KineticMagneticFlow
magnetic_flow = kinetic_magnetic_flow
"""``magnetic_flow(G, metric, ε)``: the exact flow of ``q̇ = M⁻¹p, ṗ = G M⁻¹p`` over ``ε``
(:func:`liesample.geometry.cotangent.kinetic_magnetic_flow`)."""


def check_parameters(step_size, inverse_mass_matrix, magnetic_field, dimension=None) -> int:
    """Check ``ε``, ``M⁻¹`` and ``G`` of a sampler on ``dimension`` raveled coordinates (by
    default as many as ``M⁻¹`` has); that dimension."""
    check_positive_step_size(step_size)
    check_inverse_mass_matrix(inverse_mass_matrix, dimension)
    if dimension is None:
        dimension = np.shape(inverse_mass_matrix)[0]
    check_magnetic_field(magnetic_field, dimension)
    return dimension


def euclidean_move(
    step_size, inverse_mass_matrix, magnetic_field, scheme, dtype=None, precompute=True
):
    """The geometric samplers' :class:`~liesample.samplers.cotangent._core.Move` on
    ``Euclidean((d,))`` with ``M⁻¹``, ``G`` and a checked ``scheme`` (its gradient is set per
    move by :func:`liesample.samplers.cotangent._core.ravelled`)."""
    d = np.shape(inverse_mass_matrix)[0]
    return make_move(
        None, Euclidean((d,)), step_size, inverse_mass_matrix, magnetic_field, scheme, dtype,
        precompute,
    )  # fmt: skip


# --------------------------------------------------------------------------- pytrees


def ravel(tree):
    return ravel_pytree(tree)[0]


def initial_values(position, logdensity_fn):
    """``(log π, ∇log π, zero flat momentum)`` at ``position``, shared by both samplers' ``init``.

    Raises a ``ValueError`` when ``log π`` or its gradient is not finite (checked when concrete:
    under ``jit``/``vmap`` the kernels' non-finite guard takes over).
    """
    check_logdensity_value(logdensity_fn, position)
    logdensity, grad = jax.value_and_grad(logdensity_fn)(position)
    flat_grad = ravel(grad)
    values = concrete_array(jnp.append(flat_grad, logdensity))
    if values is not None and not np.all(np.isfinite(values)):
        raise ValueError(
            "logdensity_fn or its gradient is not finite at the initial position; start the "
            "chain where log π is finite"
        )
    return logdensity, grad, jnp.zeros_like(ravel(position), dtype=flat_grad.dtype)


def check_starts(logdensity_fn, dimension=None, model=((), None)):
    """The runner's ``check_positions`` hook of a sampler on ``dimension`` raveled coordinates
    (:func:`check_euclidean_starts`); ``model``: the log density's ``(model_args,
    model_kwargs)``."""

    def check_positions(positions, **_):
        check_euclidean_starts(positions, logdensity_fn, dimension, model)

    return check_positions


def _finite_program(logdensity_fn):
    """``(positions, model) ↦`` whether ``log π`` and its gradient are finite at each start
    (a :class:`liesample.foundation.identity.Program`: one compilation per log density)."""

    def finite_at(positions, model):
        density = with_model_arguments(logdensity_fn, *model)

        def finite(position):
            logdensity, grad = jax.value_and_grad(density)(position)
            return jnp.isfinite(logdensity) & jnp.all(jnp.isfinite(ravel(grad)))

        return jax.vmap(finite)(positions)

    return finite_at


def check_euclidean_starts(positions, logdensity_fn, dimension=None, model=((), None)):
    """Check every start (a pytree whose leaves have a leading chain axis) in one vectorised
    call: ``log π`` (``logdensity_fn`` at the model's arguments ``model``) and its gradient
    finite, ``dimension`` coordinates; the error names the first bad chain."""

    first = jax.tree.map(lambda leaf: leaf[0], positions)
    size = ravel(first).shape[0]
    if dimension is not None and size != dimension:
        raise ValueError(
            f"initial_positions[0] has {size} coordinates but inverse_mass_matrix and "
            f"magnetic_field are for {dimension}"
        )
    args, kwargs = model
    program = Program(_finite_program, logdensity_fn)
    ok = np.asarray(evaluate(run_program, program, positions, (tuple(args), dict(kwargs or {}))))
    chain = first_bad_chain(ok)
    if chain is not None:
        raise ValueError(
            f"initial_positions[{chain}]: logdensity_fn or its gradient is not finite there; "
            "start the chain where log π is finite"
        )


# --------------------------------------------------------------------------- default field


def default_magnetic_field(
    inverse_mass_matrix: ArrayLike, strength: float, covariance: ArrayLike | None = None
) -> np.ndarray:
    """The default field ``G = strength · M^{1/2} J̃ M^{1/2}`` and its tuning rule.

    **Orientation.** In the coordinates whitened by the mass matrix (``x = M^{1/2} q``, where the
    adapted ``M⁻¹`` approximates the target's covariance, so the target is near ``N(0, I)``) the
    field is ``strength · J̃`` with ``J̃ = Σ_k (u_k v_kᵀ − v_k u_kᵀ)``, a sum of unit rotations in
    planes spanned by orthonormal pairs ``(u_k, v_k)``. The canonical change of variables
    ``q = M^{-1/2}x, p = M^{1/2}y`` turns ``ṗ = GM⁻¹p`` into ``ẏ = M^{-1/2}GM^{-1/2} y``, hence
    ``G = M^{1/2} (strength·J̃) M^{1/2}``.

    - Without ``covariance``: the pairs are the whitened coordinate axes ``(1, 2), (3, 4), …``.
    - With a ``covariance`` estimate (e.g. of warm-up draws): the principal directions of the
      whitened covariance ``M^{1/2} Σ M^{1/2}``, sorted by variance, paired largest with
      smallest, second largest with second smallest, … — each plane couples a slow direction
      (what the mass matrix missed) with a fast one. With odd ``d`` the median direction is
      left out.

    **Strength (the tuning rule).** ``strength`` is the rotation rate of the whitened velocity
    (rad per unit time); ``strength = 0`` gives plain HMC / underdamped Langevin. What matters
    for a leapfrog trajectory is the angle turned per step, ``strength · step_size``: after
    window adaptation the step size is set by the fastest direction, so a field with a fixed
    angle per step scales with the target's stiffest frequency. Rule: take
    ``strength = angle / step_size`` with ``angle = 0.25`` rad as the default, then compare
    ESS per gradient over a few angles ``{0, 0.25, 0.5, 1}`` on a short run and keep the best.
    A field helps most on strongly correlated targets the mass matrix cannot whiten; a strong
    field slows the slowest modes (the product of the two frequencies of a coupled pair is
    fixed, their spread grows). ``angle = 0`` (plain HMC) is always a safe fallback.

    Parameters
    ----------
    inverse_mass_matrix : array, (d,) or (d, d)
        E.g. the one returned by ``blackjax.window_adaptation``.
    strength : float
        Field strength in the whitened frame (≥ 0).
    covariance : array (d, d), optional
        A covariance estimate of the target; orients the field along its principal directions.

    Returns
    -------
    numpy.ndarray, (d, d)
        An antisymmetric field (exactly: it is built as ``A − Aᵀ``).

    Examples
    --------
    Unit mass in four dimensions: rotations in the planes ``(1, 2)`` and ``(3, 4)``:

    >>> liesample.default_magnetic_field(jnp.ones(4), strength=1.0)
    array([[ 0.,  1.,  0.,  0.],
           [-1.,  0.,  0.,  0.],
           [ 0.,  0.,  0.,  1.],
           [ 0.,  0., -1.,  0.]])
    """
    check_inverse_mass_matrix(inverse_mass_matrix)  # before the cast: complex is refused
    imm = np.asarray(inverse_mass_matrix, dtype=float)
    strength = finite_float("strength", strength, nonnegative=True)
    d = imm.shape[0]
    if imm.ndim == 1:
        mass_sqrt = np.diag(1.0 / np.sqrt(imm))
    else:
        lam, u = np.linalg.eigh(imm)
        mass_sqrt = (u / np.sqrt(lam)) @ u.T
    if covariance is None:
        basis = np.eye(d)
    else:
        covariance = np.asarray(covariance, dtype=float)
        if covariance.shape != (d, d) or not np.all(np.isfinite(covariance)):
            raise ValueError(
                f"covariance must be a finite ({d}, {d}) matrix, got shape {covariance.shape}"
            )
        whitened = mass_sqrt @ covariance @ mass_sqrt
        lam, u = np.linalg.eigh(0.5 * (whitened + whitened.T))
        order = np.argsort(lam)[::-1]  # largest variance first
        u = u[:, order]
        # interleave: largest, smallest, 2nd largest, 2nd smallest, ...
        idx = []
        lo, hi = 0, d - 1
        while hi - lo >= 1:
            idx += [lo, hi]
            lo, hi = lo + 1, hi - 1
        basis = u[:, idx]
    rotation = np.zeros((d, d))
    for k in range(0, basis.shape[1] - 1, 2):
        a, b = basis[:, k], basis[:, k + 1]
        rotation += np.outer(a, b)
    rotation = rotation - rotation.T
    field = strength * mass_sqrt @ rotation @ mass_sqrt
    return 0.5 * (field - field.T)
