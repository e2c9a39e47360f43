"""The step-size stability bound of the Lie–Poisson–Langevin integrators.

The stiff part of the Poisson–Langevin SDE (paper, ``eq:poisson-langevin-eq``) is the derived
dissipation. Along one noise direction ``i`` the SDE is a one-dimensional Langevin equation in the
group coordinate ``φ`` of ``exp(φ ∇ĥ_i)`` (``PoissonLangevin.group_generator``),

    dφ = −θ ∂_φ h dt + σ dW,

whose linearisation about a point of the orbit relaxes at the rate ``θ h''_i`` with the
curvature of ``h`` along the noise flow

    h''_i(μ) = d²/dφ² h(Ad*_{exp(φ ∇ĥ_i(μ))} μ) |_{φ=0}.

The **stability number** of a step is ``κ = step_size · θ · max_i |h''_i|``, the maximum taken
over the orbit. Explicit Euler (``lie_euler``) and Heun (``rkmk_heun``, each piece of
``splitting``, ``euler_heun``) applied to ``y' = −λy`` are stable iff ``λ dt ≤ 2``
(``|1 − z| ≤ 1``, resp. ``|1 − z + z²/2| ≤ 1``, ``z = λ dt``), hence the bound ``κ ≤ 2``.

- **Rigid body** (``h = ½ μ·I⁻¹μ``, ``ĥ_i = e_i·μ``, ``|μ| = r``): rotating about ``e_i``,
  ``h''_i = ρ²(1/I_k − 1/I_j) cos 2φ``, so ``max_i |h''_i| = r² (1/I_min − 1/I_max)`` and

      κ = θ · step_size · r² · (1/I_min − 1/I_max) ≤ 2,     θ = βσ²/2.

  The pure dissipative flow from near the minimum converges just below ``κ = 2`` and
  settles on a spurious 2-cycle just above it, with ``splitting``, ``rkmk_heun`` and ``lie_euler``
  alike (the Hamiltonian drift does not move the bound). The orbit is compact, so beyond the bound
  the chain stays finite but samples a wrong law. Isotropic inertia has ``h'' ≡ 0``: no bound.
- **Heavy top**: the translation noise ``ĥ_{3+j} = ⟨Γ, e_j⟩`` shifts ``Π`` by ``φ Γ×e_j``, with
  ``h'' = (Γ×e_j)·I⁻¹(Γ×e_j) ≤ r²/I_min`` on any orbit; the rotations add
  ``|mgl| r |χ|`` and kinetic terms ``∝ |Π|²``. The orbit is not compact: beyond the bound
  ``Π`` grows geometrically, overflows, and the sampler flags the step ``nonfinite``.
- **Spins**: the per-spin curvature is set by the local field, ``≲ 2|J|·z + |B| + 2|D|``
  (``z`` neighbours).

:func:`stiffness` estimates ``θ · max |h''_i|`` on the orbit generically, by autodiff at the
initial point and at 32 fixed pseudo-random points ``Ad*_{exp ζ_k} μ₀`` of its orbit (``ζ_k``
standard normal), over every noise direction (a fixed subset of 12 when there are more, e.g.
spin lattices, whose directions are alike): on compact orbits (so(3)ⁿ) this finds the maximum to a
few per cent; on the heavy top's non-compact orbit it measures the ``Π`` of those points,
``|Π| ≲ |Π₀| + 2|Γ|``, so a chain whose ``Π`` wanders much further (high temperature) may be
stiffer than estimated. ``euler_heun`` leaves the orbit, and the growing radius raises its ``κ``
over long runs.
"""

from __future__ import annotations

import functools
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.dynamics.system import LiePoissonSystem
from liesample.foundation.compile import evaluate, jit
from liesample.foundation.validation import raise_or_warn
from liesample.integrators.orbit import INTEGRATORS, Integrator

__all__ = [
    "FLOAT32_MIN_RELATIVE_SPREAD",
    "FLOAT32_MIN_STABLE_STEP",
    "STABILITY_LIMITS",
    "check_precision",
    "check_step_size",
    "largest_stable_step",
    "noise_curvatures",
    "stability_number",
    "stiffness",
    "stiffness_on_orbits",
]

STABILITY_LIMITS = {name: i.stability_limit for name, i in INTEGRATORS.items()}
"""Largest stable ``κ = step_size · θ · max_i |h''_i|`` of each built-in integrator, as it declares
(``Integrator.stability_limit``; module docstring)."""

STABILITY_MODES = ("raise", "warn", "off")
"""``"raise"`` (the samplers' default): refuse a step beyond the bound, naming the largest
allowed one; ``"warn"``: a ``UserWarning`` and run; ``"off"``: no check."""

_NUM_ORBIT_POINTS = 32
_MAX_DIRECTIONS = 12
_ORBIT_SEED = 20261122


def noise_curvatures(
    system: LiePoissonSystem, mu: ArrayLike, directions: ArrayLike | None = None
) -> jax.Array:
    """``h''_i(μ)``, the second derivative of ``h`` along each noise flow, shape ``(m,)`` (or
    only for the noise directions listed in ``directions``).

    Examples
    --------
    ``h`` is constant along the rotation about ``μ``'s own axis:

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> curvatures = liesample.stability.noise_curvatures(system, jnp.array([1.5, 0.0, 0.0]))
    >>> curvatures.shape, float(curvatures[0])
    ((3,), 0.0)
    """
    mu = jnp.asarray(mu)
    # only the gradients asked for: one pullback each, never the whole (m, dim) Jacobian
    values, pullback = jax.vjp(system.noise_hamiltonians, mu)
    rows = jnp.eye(values.shape[0], dtype=values.dtype)
    rows = rows if directions is None else rows[jnp.asarray(directions)]
    directions = jax.vmap(lambda row: pullback(row)[0])(rows)

    def along(xi):
        # The orbit curve φ ↦ Ad*_{exp φξ} μ solves μ̇ = ad*_ξ μ, so at φ = 0 its velocity is
        # ad*_ξ μ and its acceleration ad*_ξ ad*_ξ μ: h'' there is h'' along the parabola
        # with that 2-jet, which needs no group exponential (nor its second derivative).
        velocity = system.algebra.ad_star(xi, mu)
        acceleration = system.algebra.ad_star(xi, velocity)

        def h_at(phi):
            return system.hamiltonian(mu + phi * velocity + (0.5 * phi * phi) * acceleration)

        def slope(phi):
            return jax.jvp(h_at, (phi,), (jnp.ones_like(phi),))[1]

        zero = jnp.zeros((), mu.dtype)
        return jax.jvp(slope, (zero,), (jnp.ones_like(zero),))[1]

    count = directions.shape[0]
    if count <= _MAX_DIRECTIONS:  # the step-size rule's directions: one batch
        return jax.vmap(along)(directions)
    # bounded memory for many directions; a batch that divides them leaves no remainder,
    # which lax.map would compile as a second copy of the body
    batch = max(b for b in range(1, 9) if count % b == 0)
    return jax.lax.map(along, directions, batch_size=batch)


def _chosen_directions(num_noises):
    """All noise directions, or a fixed subset of them for large systems (cost)."""
    if num_noises <= _MAX_DIRECTIONS:
        return None
    rng = np.random.default_rng(_ORBIT_SEED)
    return np.sort(rng.choice(num_noises, _MAX_DIRECTIONS, replace=False))


def _orbit_points(system, position):
    rng = np.random.default_rng(_ORBIT_SEED)
    zetas = rng.standard_normal((_NUM_ORBIT_POINTS, *position.shape))
    move = jax.vmap(system.algebra.coadjoint_exp, in_axes=(0, None))
    return jnp.concatenate([position[None], move(jnp.asarray(zetas, position.dtype), position)])


@functools.partial(jit, static_argnames="system")
def _worst_curvatures(positions, *, system):
    """The largest ``|h''_i|`` on the orbit through each of ``positions`` (a ``lax.map`` over
    them and over points of each orbit: bounded memory); one program for every system equal to
    ``system`` (:mod:`liesample.foundation.identity`) and every number of orbits of a padded
    size."""
    chosen = _chosen_directions(system.num_noises)

    def worst(position):
        curvatures = jax.lax.map(
            lambda m: noise_curvatures(system, m, chosen), _orbit_points(system, position)
        )
        return jnp.max(jnp.abs(curvatures))

    return jax.lax.map(worst, positions)


@functools.partial(jit, static_argnames="system")
def _casimirs(positions, *, system):
    """The Casimirs of each of ``positions``: one program per system value, where an eager call
    would compile each of its operations on its own."""
    return jax.vmap(system.casimirs)(positions)


def stiffness(system: LiePoissonSystem, theta: float, position: ArrayLike) -> float:
    """``θ · max_i |h''_i|`` estimated on the orbit through ``position`` (module docstring).

    Computed once per system and orbit (the result is cached on the system by its Casimirs).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> bool(liesample.stability.stiffness(system, 1.5, jnp.array([1.5, 0.0, 0.0])) > 0)
    True
    """
    if theta == 0.0:
        return 0.0
    position = np.asarray(position, dtype=float)
    casimirs = np.asarray(evaluate(functools.partial(_casimirs, system=system), position[None]))[0]
    cache_key = (position.shape, tuple(np.round(casimirs, 12).reshape(-1)))
    cache = system.__dict__.setdefault("_stiffness_cache", {})
    if cache_key not in cache:
        worst = evaluate(functools.partial(_worst_curvatures, system=system), position[None])
        cache[cache_key] = float(np.asarray(worst)[0])
    return abs(theta) * cache[cache_key]


def stiffness_on_orbits(system: LiePoissonSystem, theta: float, positions: ArrayLike) -> np.ndarray:
    """:func:`stiffness` of the orbits through each of ``positions`` (shape ``(n, *event)``),
    the orbits not yet cached computed in one compiled call (a ``lax.map`` over them: bounded
    memory) and cached as :func:`stiffness` does.

    Examples
    --------
    The rigid body's ``h`` is quadratic: doubling ``|μ|`` quadruples the curvature:

    >>> import numpy as np
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> orbits = jnp.array([[1.5, 0.0, 0.0], [3.0, 0.0, 0.0]])
    >>> s = liesample.stability.stiffness_on_orbits(system, 1.5, orbits)
    >>> s.shape, bool(np.isclose(s[1], 4 * s[0]))
    ((2,), True)
    """
    positions = np.asarray(positions, dtype=float)
    if theta == 0.0:
        return np.zeros(len(positions))
    casimirs = np.asarray(evaluate(functools.partial(_casimirs, system=system), positions))
    keys = [(positions.shape[1:], tuple(np.round(c, 12).reshape(-1))) for c in casimirs]
    cache = system.__dict__.setdefault("_stiffness_cache", {})
    missing = sorted({i for i, key in enumerate(keys) if key not in cache})
    if missing:
        batched = functools.partial(_worst_curvatures, system=system)
        # Padded to a power of two: a few compiled shapes serve every number of orbits.
        padded = missing + [missing[-1]] * (2 ** math.ceil(math.log2(len(missing))) - len(missing))
        values = np.asarray(evaluate(batched, positions[padded]))[: len(missing)]
        for i, value in zip(missing, values, strict=True):
            cache[keys[i]] = float(value)
    return abs(theta) * np.array([cache[key] for key in keys])


def stability_number(
    system: LiePoissonSystem, step_size: float, theta: float, position: ArrayLike
) -> float:
    """``κ = step_size · |θ| · max_i |h''_i|`` on the orbit through ``position``
    (θ < 0 at β < 0).

    Examples
    --------
    ``κ`` is linear in the step size:

    >>> import numpy as np
    >>> from liesample.stability import stability_number, stiffness
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> mu = jnp.array([1.5, 0.0, 0.0])
    >>> bool(np.isclose(stability_number(system, 0.1, 1.5, mu), 0.1 * stiffness(system, 1.5, mu)))
    True
    """
    return step_size * stiffness(system, theta, position)


def check_step_size(
    system: LiePoissonSystem,
    integrator: str | Integrator,
    step_size: float,
    theta: float,
    position: ArrayLike,
    mode: str = "warn",
) -> float | None:
    """Warn (``mode="warn"``) or raise ``ValueError`` (``"raise"``) when ``κ`` exceeds the
    integrator's declared ``stability_limit`` (an :class:`~liesample.integrators.Integrator` or
    a built-in's name); ``"off"``, an unknown name or no declared limit: no check.
    Returns ``κ`` (or ``None`` when not checked).

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> mu = jnp.array([1.5, 0.0, 0.0])
    >>> kappa = liesample.stability.check_step_size(system, "splitting", 0.1, 1.5, mu)  # κ ≤ 2
    >>> liesample.stability.check_step_size(system, "splitting", 10.0, 1.5, mu, mode="raise")
    Traceback (most recent call last):
    ValueError: step_size=10 is beyond the stable bound of the 'splitting' integrator ...
    """
    if not isinstance(integrator, Integrator):
        integrator = INTEGRATORS.get(integrator)
    limit = None if integrator is None else integrator.stability_limit
    integrator_name = None if integrator is None else integrator.name
    if mode == "off" or limit is None or theta == 0.0 or not system.curvature_bound:
        return None
    kappa = stability_number(system, step_size, theta, position)
    if kappa <= limit:
        return kappa
    largest = step_size * limit / kappa
    message = (
        f"step_size={step_size:g} is beyond the stable bound of the {integrator_name!r} "
        f"integrator on this orbit of the {system.name}: "
        f"κ = step_size·θ·max_i|h''_i| = {kappa:.3g} > {limit:g} (θ = {theta:.3g}), i.e. "
        f"step_size must be <= {largest:.3g}; reduce step_size (or leave it unset: the sampler "
        "then chooses one below the bound), sigma or beta "
        "(see liesample.integrators.stability), or pass "
        "stability='warn' or 'off' to run anyway (the chain then samples a wrong law)"
    )
    raise_or_warn(message, mode == "raise", stacklevel=4)
    return kappa


def largest_stable_step(
    system: LiePoissonSystem, integrator: str | Integrator, theta: float, position: ArrayLike
) -> float:
    """The largest ``step_size`` with ``κ ≤`` the integrator's ``stability_limit`` on the orbit
    through ``position`` (``inf`` where there is no bound: no dissipation, flat ``h``, no declared
    limit, or a system without the curvature bound).

    Examples
    --------
    The largest step puts ``κ`` at the splitting scheme's limit, 2:

    >>> import numpy as np
    >>> from liesample.stability import largest_stable_step, stability_number
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> mu = jnp.array([1.5, 0.0, 0.0])
    >>> step = largest_stable_step(system, "splitting", 1.5, mu)
    >>> bool(np.isclose(stability_number(system, step, 1.5, mu), 2.0))
    True
    """
    if not isinstance(integrator, Integrator):
        integrator = INTEGRATORS.get(integrator)
    limit = None if integrator is None else integrator.stability_limit
    if limit is None or theta == 0.0 or not system.curvature_bound:
        return float("inf")
    stiff = stiffness(system, theta, position)
    return float("inf") if stiff == 0.0 else limit / stiff


# --------------------------------------------------------------------------- float32

FLOAT32_MIN_STABLE_STEP = 1e-3
"""float32 is not enough when the stable step ``2/(θ max|h''|)`` is below this: a unit of
physical time then takes over a thousand steps, and round-off (``ε₃₂ ≈ 1.2e-7`` per step,
growing like ``ε₃₂ √n``) reaches ``1e-4`` in the Casimirs and averages over ``10⁶`` steps."""

FLOAT32_MIN_RELATIVE_SPREAD = 1e-3
"""float32 is not enough when the target's spread along its stiffest noise direction,
``1/√(|β| max|h''|)``, is below this fraction of the state's size ``max|μ|``: each coadjoint
step then rounds by ``ε₃₂ max|μ|``, a visible fraction of the fluctuations being sampled."""


def check_precision(
    system: LiePoissonSystem,
    beta: float | None,
    theta: float,
    position: ArrayLike,
    dtype: DTypeLike,
) -> bool:
    """Warn (``UserWarning``; the same message for the same system, so Python's default warning
    filter shows it once per calling line) when a sampler runs in float32 on a problem that
    needs float64, by the two rules :data:`FLOAT32_MIN_STABLE_STEP` and
    :data:`FLOAT32_MIN_RELATIVE_SPREAD`. Returns whether float32 was judged insufficient.

    Examples
    --------
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> mu = jnp.array([1.5, 0.0, 0.0])
    >>> liesample.stability.check_precision(system, 3.0, 1.5, mu, jnp.float64)  # float64: enough
    False
    """
    if jnp.dtype(dtype) != jnp.float32 or theta == 0.0 or not system.curvature_bound:
        return False
    position = np.asarray(position, dtype=float)
    curvature = stiffness(system, theta, position) / abs(theta)  # max_i |h''_i| on the orbit
    if curvature == 0.0:
        return False
    stable_step = 2.0 / (abs(theta) * curvature)
    spread = 1.0 / np.sqrt(abs(beta) * curvature) if beta else np.inf
    size = float(np.max(np.abs(position)))
    reasons = []
    if stable_step < FLOAT32_MIN_STABLE_STEP:
        reasons.append(f"the stable step {stable_step:.3g} is below {FLOAT32_MIN_STABLE_STEP:g}")
    if spread < FLOAT32_MIN_RELATIVE_SPREAD * size:
        reasons.append(
            f"the target's spread {spread:.3g} is below {FLOAT32_MIN_RELATIVE_SPREAD:g} of the "
            f"state's size {size:.3g}"
        )
    if not reasons:
        return False
    warnings.warn(
        f"the {system.name} is sampled in float32, but {' and '.join(reasons)}: float32 "
        "round-off will show in the Casimirs and the averages. Call "
        'jax.config.update("jax_enable_x64", True) at start-up '
        "(see liesample.integrators.stability)",
        UserWarning,
        stacklevel=4,
    )
    return True
