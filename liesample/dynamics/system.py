"""What a Lie–Poisson system declares: algebra, Hamiltonian, noise, and its exact reference.

The declaration sits below the engine (``liesample.dynamics`` reads it, integrators move it);
the concrete systems in :mod:`liesample.systems` build instances of it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.dynamics.noise_span import check_noise_reaches_orbit
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.identity import ValueIdentity
from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry.algebras import LieAlgebra

__all__ = ["NOISE_REACH", "LiePoissonSystem", "checked_beta", "coordinate_noise", "count_noises"]

NOISE_REACH = ("test", "orbit", "level_set")


def coordinate_noise(mu: jax.Array) -> jax.Array:
    """The linear noise ``ĥ_i(μ) = μ_i``, one per coordinate of the state (flattened): on a
    dual Lie algebra, the noise along every basis direction (paper, ``eq:poisson-langevin-eq``
    with ``Φ_i = e_i``)."""
    return jnp.ravel(mu)


@functools.partial(jit, static_argnames="algebra")
def _algebra_casimirs(position, *, algebra):
    return algebra.casimirs(position)


def _casimirs_function(system):
    """``system.casimirs`` as one program per algebra value (an algebra equal by its fields is
    shared by every system on it, built or rebuilt), where an eager call would compile each of
    its operations on its own; the eager method where the algebra has no hash."""
    if type(system).casimirs is not LiePoissonSystem.casimirs:
        return system.casimirs
    try:
        hash(system.algebra)
    except TypeError:
        return system.casimirs
    return functools.partial(_algebra_casimirs, algebra=system.algebra)


@dataclass(frozen=True, eq=False)
class LiePoissonSystem(ValueIdentity):
    """A system on a dual Lie algebra ``g*``, declared and never integrated by hand.

    Parameters
    ----------
    name : str
        Human-readable name.
    algebra : LieAlgebra
        Bracket, coadjoint action and Casimirs.
    hamiltonian : callable
        ``μ ↦ h(μ)``, a scalar.
    default_position : array
        A valid initial state; its shape is the shape of every state (``event_shape``).
    noise_hamiltonians : callable
        ``μ ↦ (ĥ_1(μ), …, ĥ_m(μ))``, unit-strength noise Hamiltonians; the noise is ``σ ĥ_i`` and
        the dissipation is derived from the same functions (paper,
        ``eq:poisson-langevin-eq``). Default :func:`coordinate_noise`: ``ĥ_i(μ) = μ_i``, one
        linear noise per coordinate of the state (rotations about every axis of the algebra).
    num_noises : int, optional
        ``m``; read off ``noise_hamiltonians`` at ``default_position`` when left out.
    event_shape : tuple of int, optional
        Shape of one state ``μ``; ``default_position``'s shape when left out.
    reference : callable or None
        ``(beta, position) ↦`` the exact Gibbs law on the orbit through ``position``, or ``None``.
    component_names : tuple of str
        Labels of the state's last axis, for tables and plots.
    params : dict
        The physical parameters, recorded in outputs.
    noise_groups : array of int, optional
        A group label in ``0 … G−1`` for each noise direction (shape ``(m,)``). The splitting
        integrator moves one group at a time; directions may share a group only if they
        commute and do not change each other's coefficients (e.g. the same axis on the
        non-neighbouring spins of one sublattice). Default: each direction its own group.
    positive_casimirs : tuple of int or None
        Which Casimirs (indices into the last axis of ``algebra.casimirs(μ)``) must be > 0 for
        the orbit to be non-degenerate; ``check_position`` rejects a state where one of them is
        ``≤ 0``. ``None`` (default): all of them (rigid body and spins: ``|μ_k|² > 0``). A
        Casimir that may legitimately be zero or negative (the heavy top's ``Π·Γ``) is left out:
        the heavy top declares ``(0,)``, i.e. only ``|Γ|² > 0``.
    casimir_scale : callable or None
        ``μ ↦`` a non-negative size for each Casimir (same shape as ``casimirs(μ)``), the scale
        of its round-off: :meth:`casimir_error` measures drift relative to
        ``max(|C₀|, casimir_scale(μ))`` at the current state ``μ`` (no extra state to carry).
        Needed when a Casimir may vanish (``Π·Γ = 0``), where
        ``|C − C₀|/|C₀|`` is undefined; for the quadratic Casimirs here ``|μ|²`` is the natural
        size. ``None`` (default): ``|C₀|`` alone, which must then be nonzero.
    check_beta : callable or None
        ``β ↦ None``, raising ``ValueError`` (naming the bound) where ``exp(−βh)`` is not
        normalisable on the orbit (e.g. point vortices at strongly negative ``β``). ``None``
        (default): every finite ``β`` is admissible (compact orbit, continuous ``h``).
    curvature_bound : bool
        Whether the generic step-size check of :mod:`liesample.integrators.stability` (curvature of
        ``h`` along the noise flows, sampled on the orbit) applies. ``False`` where ``h`` is
        singular on the orbit (point vortices: their integrator substeps instead).
    hamiltonian_pieces : tuple of callables or None
        Functions summing to ``h``, each exactly solved by one coadjoint move: its gradient is
        constant along its own flow, so ``Ad*_{exp(t ∇f(μ))} μ`` *is* that flow. The
        ``splitting`` integrator then advances ``X_h`` as the symmetric (Strang) composition of
        these exact flows instead of one Heun step on ``∇h``. Pieces that are each invariant
        under a symmetry keep its momentum map exactly (stochastic Noether, paper
        ``prop:stoch-noether``); see :func:`liesample.systems.heavy_top`. ``None`` (default):
        one piece, ``h``.
    single_noise_hamiltonian : callable or None
        ``(μ, i) ↦ ĥ_i(μ)``, one noise Hamiltonian (``i`` may be traced), for systems whose
        ``noise_hamiltonians`` are costly to evaluate all at once (point vortices: ``L(L+2)``
        spherical harmonics at every vortex). The ``splitting`` integrator moves one direction
        at a time and then evaluates only that direction, so a piece costs one noise function
        instead of ``m``. Only with the default grouping (``noise_groups=None``). ``None``
        (default): every piece goes through ``noise_hamiltonians``.
    noise_reach : {"test", "orbit", "level_set"}
        What the noise reaches. ``"orbit"``: every direction of every orbit, known (the
        library's systems, each with its arguments). ``"level_set"``: on purpose only the level
        set of a conserved quantity through the start (stochastic Noether, paper
        ``prop:stoch-noether``): the chain samples ``exp(−βh)`` restricted to it. ``"test"``
        (default, and after :meth:`with_noise` unless told): :meth:`check_noise` runs the rank
        test of :mod:`liesample.dynamics.noise_span` once, when a sampler is built.

    Examples
    --------
    A spherical rigid body declared by hand (:func:`liesample.systems.lie_poisson_system` is the
    usual way); the noise defaults to one linear noise per coordinate:

    >>> from liesample.algebras import so3
    >>> from liesample.systems import LiePoissonSystem
    >>> system = LiePoissonSystem(name="sphere", algebra=so3, hamiltonian=lambda mu: 0.5 * mu @ mu,
    ...                           default_position=jnp.array([0.0, 0.0, 1.0]))
    >>> system.num_noises, system.event_shape
    (3, (3,))
    """

    name: str
    algebra: LieAlgebra
    hamiltonian: Callable[[jax.Array], jax.Array]
    default_position: ArrayLike
    noise_hamiltonians: Callable[[jax.Array], jax.Array] = coordinate_noise
    component_names: tuple[str, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)
    # Left out (None), these two are derived by __post_init__, so a built system always has
    # them: typed as what a reader finds.
    num_noises: int = None  # type: ignore[assignment]
    event_shape: tuple[int, ...] = None  # type: ignore[assignment]
    reference: Callable[[float, ArrayLike | Sequence[float]], Any] | None = None
    noise_groups: ArrayLike | None = None
    positive_casimirs: tuple[int, ...] | None = None
    casimir_scale: Callable[[jax.Array], jax.Array] | None = None
    check_beta: Callable[[float], None] | None = None
    hamiltonian_pieces: tuple[Callable[[jax.Array], jax.Array], ...] | None = None
    curvature_bound: bool = True
    single_noise_hamiltonian: Callable[[jax.Array, ArrayLike], jax.Array] | None = None
    noise_reach: str = "test"

    def __post_init__(self):
        # frozen: the derived fields are set once, here
        if self.event_shape is None:
            object.__setattr__(self, "event_shape", tuple(np.shape(self.default_position)))
        if self.num_noises is None:
            num_noises = count_noises(
                self.noise_hamiltonians, self.default_position, "noise_hamiltonians"
            )
            object.__setattr__(self, "num_noises", num_noises)
        if self.single_noise_hamiltonian is not None and self.noise_groups is not None:
            raise ValueError(
                "single_noise_hamiltonian applies when each noise direction is its own group: "
                "pass noise_groups=None, or leave single_noise_hamiltonian out"
            )
        if self.noise_groups is not None:
            labels = np.asarray(self.noise_groups)
            if labels.shape != (self.num_noises,) or not np.issubdtype(labels.dtype, np.integer):
                raise ValueError(
                    f"noise_groups must be an integer array of shape ({self.num_noises},), "
                    f"one label per noise direction; got {labels.dtype} of shape {labels.shape}"
                )
            if set(np.unique(labels)) != set(range(int(labels.max()) + 1)):
                raise ValueError("noise_groups labels must be 0, 1, …, G−1 with none missing")

    def with_noise(
        self,
        noise_hamiltonians: Callable[[jax.Array], jax.Array],
        noise_groups: ArrayLike | None = None,
        *,
        noise_reach: str = "test",
    ) -> LiePoissonSystem:
        """The same system driven by other unit-strength noise Hamiltonians ``μ ↦ (ĥ_1, …, ĥ_m)``.

        The dissipation follows (it is always derived from the noise); ``m`` is read off the
        function at ``default_position``. ``noise_groups`` applies to the new directions
        (default: each direction its own group). ``noise_reach="level_set"`` declares a noise
        that keeps a conserved quantity on purpose (see the class docstring); by default the
        new noise is tested when a sampler is built.
        """
        if noise_reach not in NOISE_REACH:
            raise ValueError(f"noise_reach must be one of {NOISE_REACH}, got {noise_reach!r}")
        num_noises = count_noises(noise_hamiltonians, self.default_position, "noise_hamiltonians")
        return replace(
            self,
            noise_hamiltonians=noise_hamiltonians,
            num_noises=num_noises,
            noise_groups=noise_groups,
            single_noise_hamiltonian=None,  # it evaluated the old functions
            noise_reach=noise_reach,
        )

    def check_noise(self) -> None:
        """Raise ``ValueError`` where the noise provably cannot reach the whole orbit (the rank
        test of :func:`liesample.dynamics.noise_span.check_noise_reaches_orbit`), unless the
        system declares what its noise reaches (``noise_reach``)."""
        if self.noise_reach == "test":
            check_noise_reaches_orbit(self)

    @property
    def noise_group_labels(self) -> np.ndarray:
        """Group label of each noise direction, shape ``(m,)``."""
        if self.noise_groups is None:
            return np.arange(self.num_noises)
        return np.asarray(self.noise_groups)

    @property
    def num_noise_groups(self) -> int:
        return int(np.max(self.noise_group_labels)) + 1

    def casimirs(self, mu: ArrayLike) -> jax.Array:
        return self.algebra.casimirs(mu)

    def casimir_error(self, mu: jax.Array, reference_casimirs: jax.Array) -> jax.Array:
        """Largest relative drift ``max_k |C_k(μ) − C₀_k| / scale_k`` of the Casimirs (a scalar).

        ``scale = |C₀|``, or ``max(|C₀|, casimir_scale(μ))`` when the system declares a scale,
        which keeps the error finite on orbits where a Casimir is zero. 0 for an algebra
        without Casimirs.
        """
        scale = jnp.abs(reference_casimirs)
        if self.casimir_scale is not None:
            scale = jnp.maximum(scale, self.casimir_scale(mu))
        drift = jnp.abs(self.casimirs(mu) - reference_casimirs) / scale
        return jnp.max(drift, initial=0.0)

    def step_casimir_error(self, mu: jax.Array, reference_casimirs: jax.Array) -> jax.Array:
        """The Casimir drift a sampler reports at every step: :meth:`casimir_error`, unless a
        system overrides it with a cheaper invariant (Zeitlin's ``‖W‖²``)."""
        return self.casimir_error(mu, reference_casimirs)

    def check_position(self, position: ArrayLike, name: str = "position") -> None:
        """Reject a state of the wrong shape, non-finite, or on a degenerate orbit (one of the
        ``positive_casimirs`` is ``≤ 0``)."""
        shape = tuple(jnp.shape(position))
        if shape != self.event_shape:
            raise ValueError(
                f"{name} must have shape {self.event_shape} for the {self.name}, got {shape}"
            )
        value = concrete_array(position)
        if value is None:
            return
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite, got {value}")
        casimirs = np.asarray(evaluate(_casimirs_function(self), value))
        if self.positive_casimirs is not None:
            casimirs = casimirs[..., list(self.positive_casimirs)]
        if np.any(casimirs <= 0):
            raise ValueError(
                f"{name} lies on a degenerate orbit (a Casimir that must be > 0, e.g. |μ|², "
                f"is {np.min(casimirs):.3g}): {value}; choose a nonzero state"
            )


class DeclaresBeta(Protocol):
    """What :func:`checked_beta` reads of a system: its ``check_beta`` (``None`` or
    ``β ↦ None``, raising where ``exp(−βh)`` is not normalisable)."""

    @property
    def check_beta(self) -> Callable[[float], None] | None: ...


def checked_beta(system: DeclaresBeta, beta: object) -> float:
    """``β`` as a float: finite, and admissible for ``system`` (its ``check_beta``, ``None`` or
    ``β ↦ None`` raising where ``exp(−βh)`` is not normalisable), or a ``ValueError`` that says
    why not. ``system`` is a :class:`LiePoissonSystem` or any declaration with ``check_beta``."""
    beta = finite_float("beta", beta)
    if system.check_beta is not None:
        system.check_beta(beta)
    return beta


def count_noises(noise_hamiltonians, position, name: str) -> int:
    if not callable(noise_hamiltonians):
        raise TypeError(
            f"{name} must be a callable μ ↦ (ĥ_1(μ), …, ĥ_m(μ)), got {noise_hamiltonians!r}"
        )
    values = jax.eval_shape(noise_hamiltonians, jnp.asarray(position, dtype=float))
    if len(values.shape) != 1 or values.shape[0] < 1:
        raise ValueError(
            f"{name} must return a 1-D array (ĥ_1, …, ĥ_m) with m >= 1, got shape {values.shape}"
        )
    return int(values.shape[0])
