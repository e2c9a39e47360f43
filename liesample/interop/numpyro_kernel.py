"""A NumPyro ``MCMC`` kernel that runs :func:`liesample.geometric_hmc` on a NumPyro model.

``GeometricHMC(model)`` is a ``numpyro.infer.mcmc.MCMCKernel``: ``MCMC(GeometricHMC(model),
num_warmup=…, num_samples=…, num_chains=…)`` then ``.run``, ``.print_summary()`` and
``arviz.from_numpyro`` work as with NumPyro's ``NUTS``. Each latent site is moved on the space
its support names:

- ``constraints.sphere`` (``VonMisesFisher``, ``Bingham``, NumPyro's ``ProjectedNormal``):
  :class:`liesample.geometry.spaces.Sphere`, one copy per batch element;
- :data:`liesample.interop.numpyro_distributions.rotation` (``MatrixFisher``):
  :class:`liesample.geometry.spaces.SO` ``(3)``;
- ``constraints.circular`` (NumPyro's ``VonMises``): :class:`liesample.geometry.spaces.U1` (angles);
- any other continuous support with a bijection to ``Rᵈ`` (``numpyro.distributions.biject_to``):
  ``Euclidean``, in the unconstrained coordinates NumPyro's HMC uses, with the log-Jacobian of
  the bijection added to the log-density. The bijection is built from the support as the model
  gives it at each evaluation (as NumPyro's ``potential_energy`` does), so a bound that depends
  on another site (``Uniform(0, 1 - a)``) follows that site's current value.

Discrete sites, and supports with neither a space nor a bijection, are refused when the kernel
is initialised, naming the site. The log-density is the model's joint log-density (NumPyro's
``log_density``) with respect to the area of spheres, Haar measure on SO(3) and Lebesgue
measure in the unconstrained coordinates: these differ from the samplers' reference measures by
constants only. Every shape is settled in ``init``: the sites' spaces, the starts and the
deterministic sites (evaluated abstractly on the start), so no shape error waits for the end
of the run.

**NumPyro's conventions.** The keywords of ``numpyro.infer.HMC`` mean what they mean there:
``potential_fn`` (model-free use, ``init_params`` given to ``MCMC.run``), ``init_strategy``
(``init_to_median``, ``init_to_value``, …; a value it gives a sphere or SO(3) site is taken to
the nearest point of the manifold), ``dense_mass``, ``inverse_mass_matrix``, ``step_size``,
``adapt_step_size``, ``adapt_mass_matrix``, ``target_accept_prob``,
``find_heuristic_step_size``, ``num_steps`` and ``trajectory_length``. A dense mass is possible
on ``Euclidean`` sites only: the exact drift on a sphere or a group needs one inverse mass per
copy (:mod:`liesample.samplers.cotangent.geometric_hmc`).

**Mass by default.** ``dense_mass="auto"`` (the default, where NumPyro's is ``False``) adapts
one dense inverse mass over the ``Euclidean`` sites together when they hold at most
:data:`AUTO_DENSE_MAX_DIMENSION` unconstrained coordinates and the warm-up has at least
:data:`AUTO_DENSE_WARMUP_PER_DIMENSION` iterations per coordinate (enough draws for Stan's last
slow window to estimate a covariance), and a diagonal one otherwise, or when
``inverse_mass_matrix`` is given or the mass is not adapted. Correlated, differently scaled
parameters (a regression on an uncentred covariate) are then whitened as a whole; a dense
block costs ``O(n²)`` per step, negligible beside a gradient at these sizes.

**Warm-up.** During NumPyro's ``num_warmup`` iterations the kernel adapts by the one adaptation
protocol (:mod:`liesample.tuning.protocol`) with the adaptation :func:`liesample.window_adaptation`
runs (:func:`liesample.tuning.windows.windows_adaptation`): NumPyro drives the loop, so each
iteration calls its ``current`` (the parameters of the transition) and, after the transition,
its ``update``. It reads what to adapt from ``liesample.geometric_hmc.adaptation``: Stan's
windows, dual averaging of the step size towards ``target_accept_prob``, the inverse mass from
Welford moments in algebra coordinates (for a ``dense_mass`` block the Welford covariance, shrunk
towards ``1e-3 I`` as Stan does), and a jittered integration time ``u T``
(``L = ceil(u T/ε)`` steps of the ``integrator`` scheme, ``u`` from the base-2 Halton sequence)
with ``T`` learnt by the ChEES-type rule, unless ``num_integration_steps`` or
``integration_time`` is given. Vectorized chains
(``chain_method="vectorized"``) adapt together: one step size (their pooled rate,
:func:`liesample.tuning.protocol.pooled_rate`), one mass (pooled moments) and one ``T``;
sequential chains adapt alone: at the end of each one's warm-up the kernel records its step size
and diagonal inverse mass (``chain_adaptations``) and warns when a chain's ends more than 10
times from the median of the other chains' (:func:`liesample.tuning.windows.far_adapted`).
After the warm-up the adaptation's ``final`` parameters are used
(dual averaging's average step, the rule's ``T``); nothing changes any more. ``num_warmup=0``
with anything left to adapt warns.

**State and diagnostics.** The sample field is ``z``: the manifold sites' points and the other
sites' unconstrained values (``init_params`` takes the same form); ``postprocess_fn`` maps it to
the constrained values and adds deterministic sites, so ``mcmc.get_samples()`` holds what the
model sees. ``extra_fields`` offers NumPyro's HMC names: ``diverging`` (collected by default:
``print_summary`` counts divergences), ``energy`` (``H`` of the state after the transition,
for ``arviz.plot_energy``), ``potential_energy``, ``accept_prob``, ``mean_accept_prob``,
``num_steps`` (gradient evaluations: two per ``minimal_norm`` step), ``step_size``,
``trajectory_length`` (``ε L``) and ``adapt_state`` (its ``step_size``, ``inverse_mass_matrix``,
keyed by tuples of site names, and ``trajectory_length``, the adapted ``T``).
``arviz.from_numpyro`` names some of them ``lp``, ``acceptance_rate`` and ``n_steps``.

**Checks after the run.** :func:`liesample.interop.numpyro_checks.check_mcmc` runs on a
finished ``MCMC`` the checks :func:`liesample.sample` runs: divergences, stuck chains, and the
rank-normalised split R-hat and bulk/tail ESS of every element of every latent site, as warnings
naming them; it costs nothing while the chains run. ``check_convergence=True`` runs the same
checks at the end of ``MCMC.run`` with no extra call, at the price of a host round trip per
kept draw (several times the sampling time of a cheap model): NumPyro does not tell a kernel
how many draws follow its warm-up, so ``init`` finds the calling ``MCMC`` on the call stack; the
mechanism and its limits are in :mod:`liesample.interop.numpyro_checks`.

**Chains.** ``chain_method="vectorized"`` vmaps init and transition over chains;
``"sequential"`` works as well. NumPyro compiles its loop with plain ``jax.jit``, not
:func:`liesample.jit`; the vmapped chains were checked against the same chains run alone (equal
to round-off, a slow test), as XLA:CPU's vmapped-loop miscompile
(:mod:`liesample.foundation.compile`) would show there.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple, cast

try:
    import numpyro
    from numpyro.distributions import Distribution, constraints
    from numpyro.distributions.transforms import IdentityTransform, biject_to
    from numpyro.infer.mcmc import MCMCKernel
    from numpyro.infer.util import log_density
    from numpyro.util import is_prng_key
except ImportError as error:  # an optional integration module
    raise ImportError(
        "liesample.interop.numpyro_kernel needs NumPyro: pip install numpyro (or the 'test' "
        "extras of liesample)"
    ) from error

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.compile import jit
from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry import spaces
from liesample.geometry.cotangent import cotangent_bundle
from liesample.interop.numpyro_checks import RunChecks, latent_values
from liesample.interop.numpyro_distributions import check_observed_sites, rotation
from liesample.samplers.contract import Tunable
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.tuning.protocol import Adaptation, restart_step_size, row_at, schedule
from liesample.tuning.trajectory import (
    DEFAULT_INTEGRATION_TIME,
    chain_move,
    euclidean_size,
    halton,
    jittered_steps,
    trajectory_adaptation,
)
from liesample.tuning.windows import (
    DenseBlocks,
    Windows,
    WindowState,
    far_adapted,
    inverse_mass,
    statistic,
    windows_adaptation,
)

__all__ = [
    "AUTO_DENSE_MAX_DIMENSION",
    "AUTO_DENSE_WARMUP_PER_DIMENSION",
    "AdaptState",
    "GeometricHMC",
    "GeometricHMCState",
]

AUTO_DENSE_MAX_DIMENSION = 32
"""``dense_mass="auto"``: the most unconstrained ``Euclidean`` coordinates adapted densely."""
AUTO_DENSE_WARMUP_PER_DIMENSION = 25
"""``dense_mass="auto"``: warm-up iterations needed per coordinate of a dense block."""

MAX_INIT_ATTEMPTS = 100
HEURISTIC_ACCEPT_PROB = 0.8  # NumPyro's find_reasonable_step_size aims one step at this rate
SUPPORTED = (
    "constraints.sphere (Sphere), liesample.interop.numpyro_distributions.rotation (SO(3)), "
    "constraints.circular (U1), or a continuous support with a bijection to R^d "
    "(numpyro.distributions.biject_to)"
)


class AdaptState(NamedTuple):
    """``extra_fields=("adapt_state",)`` (the names of NumPyro's ``HMCAdaptState``): what the
    warm-up adapted, as the next transition uses it: the step size, the inverse mass (keyed by
    tuples of site names: one per site, one per ``dense_mass`` group) and the integration time
    ``T`` (each transition integrates ``u T`` when jittered, ``u`` in ``(0, 1)``; ``ε L`` for a
    fixed ``L``)."""

    step_size: jax.Array
    inverse_mass_matrix: dict
    trajectory_length: jax.Array


class GeometricHMCState(NamedTuple):
    """One chain's state; ``z`` is the sample field, the others are ``extra_fields`` (module
    docstring). ``inner`` is the sampler's state, ``adaptation`` the warm-up's (the protocol's
    state; each chain carries a copy, with its own running rate)."""

    i: jax.Array
    z: dict
    potential_energy: jax.Array
    energy: jax.Array
    diverging: jax.Array
    accept_prob: jax.Array
    mean_accept_prob: jax.Array
    num_steps: jax.Array
    step_size: jax.Array
    trajectory_length: jax.Array
    adapt_state: AdaptState
    inner: object  # the liesample.geometric_hmc state
    adaptation: WindowState
    rng_key: jax.Array


def _base_constraint(constraint):
    """The constraint under any ``independent(…)`` wrappers."""
    while hasattr(constraint, "base_constraint"):
        constraint = constraint.base_constraint
    return constraint


class _Site(NamedTuple):
    space: spaces.Space
    euclidean: bool  # moved in the unconstrained coordinates of its support's bijection


def _site_space(name, site):
    """The liesample space of a latent site (``Euclidean`` when it is moved through its
    support's bijection; the bijection itself is rebuilt at every evaluation, as a support may
    depend on other sites' values)."""
    support = site["fn"].support
    base = _base_constraint(support)
    value = jnp.asarray(site["value"])
    if getattr(base, "is_discrete", False) or getattr(support, "is_discrete", False):
        raise ValueError(
            f"site {name!r} has the discrete support {support}: GeometricHMC moves continuous "
            "sites only (marginalise it out, or use numpyro's DiscreteHMCGibbs)"
        )
    if type(base) is type(constraints.sphere):
        if value.ndim < 1 or value.shape[-1] < 2:
            raise ValueError(f"site {name!r} on the sphere must have unit vectors of length >= 2")
        return _Site(spaces.Sphere(value.shape[-1] - 1, shape=value.shape[:-1]), False)
    if base is rotation:
        if value.ndim < 2 or value.shape[-2:] != (3, 3):
            raise ValueError(f"site {name!r} on SO(3) must have 3 x 3 matrices, got {value.shape}")
        return _Site(spaces.SO(3, shape=value.shape[:-2]), False)
    if type(base) is type(constraints.circular):
        return _Site(spaces.U1(shape=value.shape), False)
    try:
        transform = biject_to(support)
    except NotImplementedError:
        raise ValueError(
            f"site {name!r} has the support {support}, which GeometricHMC cannot handle; "
            f"supported: {SUPPORTED}"
        ) from None
    shape = jnp.shape(transform.inv(value))
    return _Site(spaces.Euclidean(shape), True)


def _feasible_value(site):
    """A point of a latent site's support of the right shape, or ``None`` (then it is drawn)."""
    if site["type"] != "sample" or site["is_observed"] or site["value"] is not None:
        return None
    fn = site["fn"]
    shape = fn.shape(site["kwargs"].get("sample_shape", ()))
    try:
        return fn.support.feasible_like(jnp.zeros(shape))
    except (NotImplementedError, AttributeError):
        return None


def _is_manifold(support) -> bool:
    base = _base_constraint(support)
    return (
        type(base) is type(constraints.sphere)
        or base is rotation
        or type(base) is type(constraints.circular)
    )


def _nearest_point(space, x):
    """The point of a manifold site nearest to ``x`` (what an ``init_strategy`` gave): unit
    vectors on spheres, the polar factor on SO(3); angles as they are. A point with no nearest
    one (``init_to_feasible`` gives zeros: the unconstrained origin of the manifold's identity
    view) or a non-finite one is taken to the first basis vector, or the identity on SO(3)."""
    x = jnp.asarray(x)
    if isinstance(space, spaces.Sphere):
        norm = jnp.linalg.norm(x, axis=-1, keepdims=True)
        ok = jnp.isfinite(norm) & (norm > jnp.finfo(x.dtype).tiny)
        pole = jnp.zeros_like(x).at[..., 0].set(1.0)
        return jnp.where(ok, x / jnp.where(ok, norm, 1.0), pole)
    if isinstance(space, spaces.SO):
        finite = jnp.all(jnp.isfinite(x), axis=(-2, -1), keepdims=True)
        x = jnp.where(finite, x, jnp.eye(x.shape[-1], dtype=x.dtype))
        u, _, vt = jnp.linalg.svd(x)
        sign = jnp.sign(jnp.linalg.det(u @ vt))
        u = u.at[..., :, -1].multiply(sign[..., None])
        return u @ vt
    return x


# ArviZ's converter (``arviz.from_numpyro``) replays ``kernel.model`` under NumPyro's
# ``init_to_sample``, which needs a bijection for every latent support and has none for a
# sphere or SO(3). ``kernel.model`` therefore shows manifold sites through a view whose support
# has an identity "bijection" registered for this private constraint type only: the log-density,
# draws and values are the original distribution's, and NumPyro's own samplers never see it.
# ``init_strategy`` runs on the same view (then :func:`_nearest_point`).
class _ManifoldSupport(constraints.Constraint):
    def __init__(self, base):
        self.base = base
        self.event_dim = base.event_dim

    def __call__(self, x):
        return self.base(x)

    def feasible_like(self, prototype):
        return self.base.feasible_like(prototype)


class _ManifoldIdentity(IdentityTransform):
    def __init__(self, constraint):
        self.constraint = constraint

    @property
    def domain(self):
        return self.constraint

    @property
    def codomain(self):
        return self.constraint


biject_to.register(_ManifoldSupport, _ManifoldIdentity)


class _ManifoldView(Distribution):
    def __init__(self, base):
        self.base = base
        super().__init__(base.batch_shape, base.event_shape)

    @property
    def support(self):
        return _ManifoldSupport(self.base.support)

    def sample(self, key, sample_shape=()):
        return self.base.sample(key, sample_shape)

    def log_prob(self, value):
        return self.base.log_prob(value)


class _ViewManifoldSites(numpyro.primitives.Messenger):
    def process_message(self, msg):
        if msg["type"] == "sample" and not msg["is_observed"] and _is_manifold(msg["fn"].support):
            msg["fn"] = _ManifoldView(msg["fn"])


def _check_flag(name, value, allowed, why):
    if value != allowed:
        raise ValueError(f"{name}={value!r} is not supported by GeometricHMC ({why}); allowed: "
                         f"{name}={allowed!r}")  # fmt: skip


def _dense_spec(dense_mass):
    """``dense_mass`` as NumPyro takes it (a bool, or a list of site-name tuples), or
    ``"auto"``."""
    if isinstance(dense_mass, bool) or (isinstance(dense_mass, str) and dense_mass == "auto"):
        return dense_mass
    message = (
        "dense_mass must be 'auto', a bool or a list of tuples of site names (NumPyro's "
        f"structured mass, e.g. [('a', 'b'), ('c',)]), got {dense_mass!r}"
    )
    if not isinstance(dense_mass, (list, tuple)):
        raise TypeError(message)
    groups = []
    for item in dense_mass:
        group = (item,) if isinstance(item, str) else item
        if not isinstance(group, (list, tuple)) or not all(isinstance(n, str) for n in group):
            raise TypeError(message)
        if group:
            groups.append(tuple(group))
    return groups


def _steps_argument(num_integration_steps):
    if num_integration_steps is None:
        return None
    if (
        isinstance(num_integration_steps, bool)
        or int(num_integration_steps) != num_integration_steps
        or num_integration_steps < 1
    ):
        raise ValueError(
            f"num_integration_steps (num_steps) must be an integer >= 1, got "
            f"{num_integration_steps!r}"
        )
    return int(num_integration_steps)


def _check_model(model, potential_fn, init_strategy, kinetic_fn, forward_mode_differentiation,
                 regularize_mass_matrix):  # fmt: skip
    """The model-side arguments of :class:`GeometricHMC` checked against NumPyro's HMC."""
    if potential_fn is not None and model is not None:
        raise ValueError("give model or potential_fn, not both (as numpyro.infer.HMC)")
    if potential_fn is None and not callable(model):
        raise TypeError(
            f"model must be a NumPyro model (a callable), or give potential_fn; got {model!r}"
        )
    if potential_fn is not None and not callable(potential_fn):
        raise TypeError(f"potential_fn must be a callable, got {potential_fn!r}")
    if kinetic_fn is not None:
        raise ValueError(
            "kinetic_fn is not supported by GeometricHMC (its kinetic energy is ½ pᵀM⁻¹p in "
            "algebra coordinates, set by the geometry); allowed: kinetic_fn=None"
        )
    _check_flag("forward_mode_differentiation", forward_mode_differentiation, False,
                "gradients are taken in reverse mode")  # fmt: skip
    _check_flag("regularize_mass_matrix", regularize_mass_matrix, True,
                "the adapted mass is always shrunk as Stan does")  # fmt: skip
    if init_strategy is not None and not callable(init_strategy):
        raise TypeError(
            f"init_strategy must be a NumPyro initialisation strategy, got {init_strategy!r}"
        )
    if init_strategy is not None and potential_fn is not None:
        raise ValueError(
            "init_strategy needs a model; with potential_fn give init_params to MCMC.run"
        )


def _trajectory_arguments(num_integration_steps, integration_time, num_steps,
                          trajectory_length):  # fmt: skip
    """``(L or None, T, whether T is learnt)`` from the trajectory arguments of
    :class:`GeometricHMC` and their NumPyro names, checked."""
    for alias, name, value in (
        ("num_steps", "num_integration_steps", num_integration_steps),
        ("trajectory_length", "integration_time", integration_time),
    ):
        given = num_steps if alias == "num_steps" else trajectory_length
        if given is not None and value is not None:
            raise ValueError(f"{alias} is NumPyro's name for {name}: give one of them")
    if num_steps is not None:
        num_integration_steps = num_steps
    if trajectory_length is not None:
        integration_time = trajectory_length
    if num_integration_steps is not None and integration_time is not None:
        raise ValueError(
            "give integration_time (trajectory_length) or num_integration_steps "
            "(num_steps), not both"
        )
    num_integration_steps = _steps_argument(num_integration_steps)
    time = DEFAULT_INTEGRATION_TIME if integration_time is None else integration_time
    time = finite_float("integration_time", time, positive=True)
    learn = integration_time is None and num_integration_steps is None
    return num_integration_steps, time, learn


def _chain_move(space, before, after, infos, inverse_mass):
    return chain_move(space, before, after, infos, inverse_mass, batched=True)


class GeometricHMC(MCMCKernel):
    """Geometric HMC on a NumPyro model's sites, on spheres, SO(3), circles and ``Rᵈ``; a
    ``numpyro.infer.mcmc.MCMCKernel`` with the keywords of ``numpyro.infer.HMC`` (module
    docstring). Nothing is traced or compiled until ``init``.

    Parameters
    ----------
    model : callable, optional
        A NumPyro model (module docstring for the supports it handles). Give ``model`` or
        ``potential_fn``.
    potential_fn : callable, optional
        NumPyro's model-free form: ``z ↦ −log π(z)`` of an array or a dict of arrays, every
        coordinate in ``Rᵈ`` (Lebesgue measure). ``init_params`` must then be given to
        ``MCMC.run`` (with a leading chain axis for several chains, as in NumPyro); the
        draws are ``z`` itself.
    step_size : float
        Initial step size of the warm-up (the step size when ``adapt_step_size=False``).
    num_integration_steps, num_steps : int, optional
        Fixed steps of the scheme per transition (``num_steps`` is NumPyro's name; give
        one), neither jittered nor learnt; by default ``ceil(u T / ε)`` (``jitter``).
    integration_time, trajectory_length : float, optional
        A fixed integration time ``T`` (``trajectory_length`` is NumPyro's name), in the
        units set by the mass. By default ``T`` is learnt in the warm-up by the ChEES-type
        rule of :mod:`liesample.tuning.trajectory` from ``π/2`` (kept at ``π/2`` without
        a warm-up or without ``Euclidean`` sites, the rule's coordinates).
    inverse_mass_matrix : None, float or dict
        Starting ``M⁻¹`` (unit by default): a positive scalar, or a dict keyed by site name
        or by tuple of site names (NumPyro's keys) → a value shaped as
        :func:`liesample.geometric_hmc` takes it (one value per copy of a sphere or group,
        one per coordinate of ``Euclidean`` and ``U1`` sites); a ``dense_mass`` group
        takes an ``(n, n)`` matrix (or ``(n,)`` diagonal) on its ``n`` unconstrained
        coordinates, in the group's order.
    dense_mass : "auto", bool or list of tuples of str
        ``"auto"`` (default): dense over the ``Euclidean`` sites together when they are few
        enough for the warm-up to estimate it (see the module's "Mass by default"), else
        diagonal. As in NumPyro: ``True`` is one dense ``M⁻¹`` over every latent site (sorted
        by name), ``[("a", "b"), ("c",)]`` one per group, ``False`` diagonal. Dense blocks
        are possible on ``Euclidean`` sites only; a sphere, rotation or circle site named
        is refused, by name, when the kernel is initialised.
    adapt_step_size, adapt_mass_matrix : bool
        What the warm-up adapts (of what ``liesample.geometric_hmc.adaptation`` declares).
    target_accept_prob : float, optional
        Dual averaging's target Metropolis rate (by default the declared one, 0.8).
    find_heuristic_step_size : bool
        As in NumPyro: with ``adapt_step_size``, before the warm-up and at the end of each
        mass window, double or halve the step size until one step's acceptance rate
        ``min(1, e^{−ΔH})`` crosses 0.8, and restart dual averaging from there.
    init_strategy : callable, optional
        A NumPyro initialisation strategy (``init_to_median()``, ``init_to_value(values=
        …)``, ``init_to_sample``, ``init_to_uniform``, …), retried with new keys until the
        log-density and its gradient are finite (at most 100 times); on sphere and SO(3)
        sites its value is taken to the nearest point. By default: uniform
        on manifold sites and in ``(−2, 2)`` in the unconstrained coordinates of the others
        (NumPyro's ``init_to_uniform``). ``init_params`` given to ``MCMC.run`` win.
    divergence_threshold : float
        ``ΔH`` above which a transition is flagged divergent.
    integrator : str or sequence of (effect, fraction) pairs
        The integration scheme, as for :func:`liesample.geometric_hmc` (``"leapfrog"`` by
        default, ``"minimal_norm"``, or a palindromic coefficient list).
    jitter : bool
        Integrate ``u T`` with ``u`` from the base-2 Halton sequence (default): a fixed
        ``T`` can sit at a resonance of the target (a direction whose half period is
        ``T``, whose chain then barely moves). ``False`` integrates ``T`` itself.
    check_convergence : bool
        Run :func:`liesample.sample`'s post-run checks at the end of ``MCMC.run`` with no extra
        call (module docstring). ``False`` (default): each kept draw would otherwise go to the
        host during the run, a round trip per transition; call
        ``liesample.interop.numpyro_checks.check_mcmc(mcmc)`` after the run instead, which
        costs nothing while the chains run.
    kinetic_fn, forward_mode_differentiation, regularize_mass_matrix
        NumPyro's, accepted at their defaults only (``None``, ``False``, ``True``): the
        kinetic energy is ``½ pᵀM⁻¹p`` in algebra coordinates, gradients are taken in
        reverse mode, and the adapted mass is always regularised (Stan's shrinkage).

    Raises
    ------
    TypeError, ValueError
        For a missing model, both ``model`` and ``potential_fn``, a setting out of range,
        two names given for one setting, or a NumPyro keyword at an unsupported value (the
        message names what is allowed).
    """

    sample_field = "z"

    def __init__(
        self,
        model: Callable | None = None,
        potential_fn: Callable | None = None,
        *,
        step_size: float = 0.1,
        num_integration_steps: int | None = None,
        integration_time: float | None = None,
        num_steps: int | None = None,
        trajectory_length: float | None = None,
        inverse_mass_matrix=None,
        dense_mass="auto",
        adapt_step_size: bool = True,
        adapt_mass_matrix: bool = True,
        target_accept_prob: float | None = None,
        find_heuristic_step_size: bool = False,
        init_strategy: Callable | None = None,
        divergence_threshold: float = 1000.0,
        integrator="leapfrog",
        jitter: bool = True,
        check_convergence: bool = False,
        kinetic_fn=None,
        forward_mode_differentiation: bool = False,
        regularize_mass_matrix: bool = True,
    ):
        """Set up the kernel (nothing is traced or compiled until ``init``); the parameters
        are documented on the class."""
        _check_model(model, potential_fn, init_strategy, kinetic_fn,
                     forward_mode_differentiation, regularize_mass_matrix)  # fmt: skip
        self._model = model
        self._potential_fn = potential_fn
        self._init_strategy = init_strategy
        self._step_size = finite_float("step_size", step_size, positive=True)
        num_integration_steps, time, learn = _trajectory_arguments(
            num_integration_steps, integration_time, num_steps, trajectory_length
        )
        self._lengths = trajectory_adaptation(time, learn=learn)
        flags = {"jitter": jitter, "adapt_step_size": adapt_step_size,
                 "adapt_mass_matrix": adapt_mass_matrix,
                 "find_heuristic_step_size": find_heuristic_step_size,
                 "check_convergence": check_convergence}  # fmt: skip
        for name, flag in flags.items():  # bool("no") would be True
            if not isinstance(flag, (bool, np.bool_)):
                raise TypeError(f"{name} must be a bool (True or False), got {flag!r}")
        self._jitter = jitter
        self._num_integration_steps = num_integration_steps
        if inverse_mass_matrix is not None and not isinstance(inverse_mass_matrix, dict):
            finite_float("inverse_mass_matrix", inverse_mass_matrix, positive=True)  # else a dict
        self._initial_mass = inverse_mass_matrix
        self._dense_mass = _dense_spec(dense_mass)
        declared = cast(Tunable, geometric_hmc.adaptation)  # geometric HMC declares its warm-up
        adapted = declared.adapted
        self._adapt_step_size = bool(adapt_step_size) and "step_size" in adapted
        self._adapt_mass = bool(adapt_mass_matrix) and "inverse_mass_matrix" in adapted
        self._find_heuristic = bool(find_heuristic_step_size) and self._adapt_step_size
        if target_accept_prob is None:
            target_accept_prob = declared.target_acceptance_rate
        target = finite_float("target_accept_prob", target_accept_prob)
        if not 0.0 < target < 1.0:
            raise ValueError(f"target_accept_prob must be in (0, 1), got {target}")
        self._target = target
        divergence_threshold = finite_float("divergence_threshold", divergence_threshold)
        self._kernel = geometric_hmc.build_kernel(divergence_threshold, integrator=integrator)
        # None until init sets the kernel up (and init runs before every other use): typed as
        # what they hold from then on.
        self._sites: dict[str, _Site] = None  # type: ignore[assignment]
        self._adaptation: Adaptation = None  # type: ignore[assignment]
        self._sample_fn: Callable[..., Any] = None  # type: ignore[assignment]
        self._num_warmup = 0
        self._array_params = False
        # (step size, flat inverse mass) of each chain adapted alone
        self._chain_adaptations: list[tuple[float, np.ndarray]] = []
        self._reported: set[int] = set()
        self._check_convergence = bool(check_convergence)
        # The post-run checks of the MCMC running this kernel (set by init; None: unchecked).
        self.run_checks: RunChecks | None = None

    # ------------------------------------------------------------------ the sites
    def _setup(self, rng_key, model_args, model_kwargs):
        # A feasible value per latent site (no sampling, so nothing is compiled for it).
        model = numpyro.handlers.substitute(
            numpyro.handlers.seed(self._model, rng_key), substitute_fn=_feasible_value
        )
        trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
        check_observed_sites(trace)  # concrete here; the log-density is only ever traced
        sites = {}
        for name, site in trace.items():
            if site["type"] == "sample" and not site["is_observed"]:
                sites[name] = _site_space(name, site)
        if not sites:
            raise ValueError("the model has no latent sample sites: nothing to sample")
        self._has_deterministic = any(s["type"] == "deterministic" for s in trace.values())
        self._set_sites(sites)

    def _setup_potential(self, init_params, batched):
        """Sites of ``potential_fn``: the arrays of ``init_params`` (one chain's shapes)."""
        self._array_params = not isinstance(init_params, dict)
        params = {"z": init_params} if self._array_params else init_params
        sites = {}
        for name, value in params.items():
            if not isinstance(name, str) or isinstance(value, (dict, list, tuple)):
                raise TypeError(
                    "with potential_fn, init_params must be an array or a dict of arrays keyed "
                    f"by str, got {jax.tree.structure(init_params)}"
                )
            shape = np.shape(value)[1:] if batched else np.shape(value)
            sites[name] = _Site(spaces.Euclidean(tuple(shape)), False)
        self._has_deterministic = False
        self._set_sites(sites)

    def _set_sites(self, sites):
        """The sites, then the sampler's blocks: each site alone, or a ``dense_mass`` group
        packed into one ``Euclidean`` vector (its sites raveled in the group's order)."""
        self._sites = sites
        self._space = {name: site.space for name, site in sites.items()}
        groups = self._dense_groups()
        grouped = {name for group in groups for name in group}
        self._blocks = {name: (name,) for name in sites if name not in grouped}
        self._dense_keys = []
        for group in groups:
            key = "+".join(group)
            while key in self._blocks or (len(group) > 1 and key in sites):
                key += "+"
            self._blocks[key] = group
            self._dense_keys.append(key)
        self._inner_space = {
            key: (
                spaces.Euclidean((sum(math.prod(self._space[n].shape) for n in group),))
                if key in self._dense_keys
                else self._space[group[0]]
            )
            for key, group in self._blocks.items()
        }
        self._adaptation = windows_adaptation(self._windows())

    def _windows(self) -> Windows:
        """What the warm-up adapts (:class:`liesample.tuning.windows.Windows`), as
        :func:`liesample.window_adaptation` does for ``liesample.geometric_hmc``."""
        space = self._inner_space
        fixed = self._num_integration_steps
        return Windows(
            self._target,
            "metropolis_rate",
            jax.vmap(functools.partial(statistic, space)),
            functools.partial(inverse_mass, space),
            self._adapt_mass,
            lengths=self._lengths if fixed is None else None,
            move=functools.partial(_chain_move, space),
            dimension=euclidean_size(space),
            fixed_steps=fixed,
            dense=DenseBlocks(tuple(self._dense_keys)) if self._dense_keys else None,
            jitter=self._jitter,
            step_size=None if self._adapt_step_size else self._step_size,
        )

    def _euclidean_sites(self):
        """The names of the ``Euclidean`` sites, sorted."""
        return sorted(n for n, s in self._space.items() if isinstance(s, spaces.Euclidean))

    def _auto_dense_groups(self):
        """``dense_mass="auto"``: the ``Euclidean`` sites as one group, or none."""
        if self._initial_mass is not None or not self._adapt_mass:
            return []
        euclidean = self._euclidean_sites()
        size = sum(math.prod(self._space[n].shape) for n in euclidean)
        enough = self._num_warmup >= AUTO_DENSE_WARMUP_PER_DIMENSION * size
        return [tuple(euclidean)] if 2 <= size <= AUTO_DENSE_MAX_DIMENSION and enough else []

    def _dense_groups(self):
        spec = self._dense_mass
        if spec == "auto":
            return self._auto_dense_groups()
        if spec is False:
            return []
        groups = [tuple(sorted(self._sites))] if spec is True else spec
        seen = set()
        euclidean = self._euclidean_sites()
        for group in groups:
            for name in group:
                if name not in self._sites:
                    raise ValueError(
                        f"dense_mass names {name!r}, which is not a latent site; the latent "
                        f"sites are {sorted(self._sites)}"
                    )
                if name in seen:
                    raise ValueError(f"dense_mass names the site {name!r} in two groups")
                seen.add(name)
                if name not in euclidean:
                    raise ValueError(
                        f"dense_mass: site {name!r} moves on {self._space[name]!r}, where "
                        "GeometricHMC's exact drift needs one inverse mass per copy; a dense "
                        "mass is possible on Euclidean sites only: allowed "
                        f"dense_mass=[{tuple(euclidean)!r}] or groups of these sites"
                    )
        return list(groups)

    def _pack(self, z):
        """Site values → the sampler's position (a dict of blocks)."""
        return {
            key: (
                jnp.concatenate([jnp.ravel(z[n]) for n in group])
                if key in self._dense_keys
                else z[group[0]]
            )
            for key, group in self._blocks.items()
        }

    def _unpack(self, position):
        """The sampler's position → site values."""
        z = {}
        for key, group in self._blocks.items():
            if key not in self._dense_keys:
                z[group[0]] = position[key]
                continue
            offset = 0
            for name in group:
                shape = self._space[name].shape
                size = math.prod(shape)
                z[name] = position[key][offset : offset + size].reshape(shape)
                offset += size
        return z

    def _to_user(self, z):
        return z["z"] if self._array_params else z

    def _from_user(self, params):
        return {"z": params} if self._array_params else params

    def _constrained_model(self, z, jacobians):
        """The model with its latent sites set from ``z``: each Euclidean site's value is the
        bijection of its support *as the model builds it now* (with the values of the sites
        before it, as NumPyro's ``potential_energy`` does: a bound may depend on another
        site) applied to its unconstrained value; the log-Jacobians go into ``jacobians``."""

        def constrain(site):
            name = site["name"]
            if site["type"] != "sample" or site["is_observed"] or name not in self._sites:
                return None
            if not self._sites[name].euclidean:
                return z[name]
            transform = biject_to(site["fn"].support)
            value = transform(z[name])
            jacobians[name] = transform.log_abs_det_jacobian(z[name], value)
            return value

        return numpyro.handlers.substitute(self._model, substitute_fn=constrain)

    def _logdensity_fn(self, model_args, model_kwargs):
        """``log π`` of site values."""
        if self._potential_fn is not None:
            return lambda z: -self._potential_fn(self._to_user(z))

        def logdensity(z):
            jacobians: dict[str, jax.Array] = {}
            model = self._constrained_model(z, jacobians)
            log_joint, _ = log_density(model, model_args, model_kwargs, {})
            for name, site in self._sites.items():
                if site.euclidean:
                    log_joint = log_joint + jnp.sum(jacobians[name])
            return log_joint

        return logdensity

    def _inner_logdensity(self, model_args, model_kwargs):
        """``log π`` of the sampler's position."""
        logdensity = self._logdensity_fn(model_args, model_kwargs)
        if not self._dense_keys:
            return logdensity
        return lambda position: logdensity(self._unpack(position))

    # ------------------------------------------------------------------ starts
    def _random_position(self, key):
        """Uniform on manifold sites, uniform in ``(−2, 2)`` in unconstrained coordinates
        (NumPyro's ``init_to_uniform``)."""
        keys = jax.random.split(key, len(self._sites))
        dtype = jnp.zeros(()).dtype
        out = {}
        for k, (name, site) in zip(keys, self._sites.items()):
            if not site.euclidean:
                out[name] = site.space.uniform(k, dtype)
            else:
                out[name] = jax.random.uniform(k, site.space.shape, dtype, -2.0, 2.0)
        return out

    def _strategy_position(self, key, model_args, model_kwargs):
        """The sites' values ``init_strategy`` gives (unconstrained; manifold sites taken to
        their nearest point)."""
        model = numpyro.handlers.substitute(
            numpyro.handlers.seed(self.model, key), substitute_fn=self._init_strategy
        )
        trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
        dtype = jnp.zeros(()).dtype
        out = {}
        for name, site in self._sites.items():
            value = jnp.asarray(trace[name]["value"], dtype)
            if not site.euclidean:
                out[name] = _nearest_point(site.space, value)
            else:  # the support as the strategy's trace built it
                out[name] = biject_to(trace[name]["fn"].support).inv(value)
            out[name] = jnp.broadcast_to(out[name], site.space.position_array_shape)
        return out

    def _find_start(self, key, logdensity, draw):
        """Starts from ``draw`` until log π and its gradient are finite (at most 100 draws)."""

        def body(carry):
            key, _, attempt = carry
            key, key_draw = jax.random.split(key)
            return key, draw(key_draw), attempt + 1

        def cond(carry):
            _, position, attempt = carry
            value, grad = jax.value_and_grad(logdensity)(position)
            finite = jnp.isfinite(value)
            for g in jax.tree.leaves(grad):
                finite = finite & jnp.all(jnp.isfinite(g))
            return ~finite & (attempt < MAX_INIT_ATTEMPTS)

        key, key_draw = jax.random.split(key)
        first = (key, draw(key_draw), jnp.asarray(1))
        return jax.lax.while_loop(cond, body, first)[1]

    def _check_init_params(self, init_params, batched):
        if not isinstance(init_params, dict) or set(init_params) != set(self._sites):
            raise ValueError(
                f"init_params must be a dict with the latent sites {sorted(self._sites)}: "
                "points on the manifold sites, unconstrained values on the others"
            )
        params = {name: init_params[name] for name in self._sites}
        chains = np.shape(jax.tree.leaves(params)[0])[0] if batched else None
        for c in range(cast(int, chains)) if batched else (None,):
            start = params if c is None else jax.tree.map(lambda x, c=c: x[c], params)
            spaces.check_position(
                self._space, start, "init_params" + ("" if c is None else f"[chain {c}]")
            )
        return params

    # ------------------------------------------------------------------ masses
    def _starting_mass(self, dtype):
        """The starting inverse mass (a dict of blocks; an ``(n, n)`` matrix for each dense
        block) from ``inverse_mass_matrix``."""
        given = self._initial_mass
        if isinstance(given, dict):
            by_key = {}
            for key, value in given.items():
                names = (key,) if isinstance(key, str) else tuple(key)
                block = [k for k, group in self._blocks.items() if group == names]
                if not block:
                    raise ValueError(
                        f"inverse_mass_matrix has the key {key!r}, which names no block; the "
                        f"keys are the sites or dense_mass groups {list(self._blocks.values())}"
                    )
                by_key[block[0]] = value
            missing = [self._blocks[k] for k in self._blocks if k not in by_key]
            if missing:
                raise ValueError(f"inverse_mass_matrix misses the sites or groups {missing}")
        else:
            by_key = None if given is None else dict.fromkeys(self._blocks, given)
        matrices = {}
        for key in self._dense_keys:
            n = self._inner_space[key].shape[0]
            value = jnp.ones((), dtype) if by_key is None else jnp.asarray(by_key[key], dtype)
            name = f"inverse mass of {self._blocks[key]}"
            if np.ndim(value) == 0:
                value = jnp.full(n, value)
            spaces.check_inverse_mass_matrix(value, n, name)
            if np.ndim(value) == 1:
                value = jnp.diag(value)
            matrices[key] = jnp.asarray(value, dtype)
            if by_key is not None:
                by_key[key] = jnp.ones(n, dtype)
        if by_key is not None and not self._dense_keys and not isinstance(given, dict):
            by_key = given  # a scalar, as before
        masses = cast(dict, spaces.check_inverse_mass(self._inner_space, by_key, dtype))  # a dict
        return {**masses, **matrices}

    def _adapt_state(self, parameters):
        masses = {self._blocks[key]: m for key, m in parameters["inverse_mass_matrix"].items()}
        return AdaptState(parameters["step_size"], masses, parameters["integration_time"])

    def _heuristic_step_size(self, key, inner, logdensity, mass, step_size):
        """NumPyro's ``find_heuristic_step_size``: from ``step_size``, double (or halve) the
        step while one step's ``min(1, e^{−ΔH})`` stays above (below) 0.8; the step at which
        that flips."""
        step_size = jnp.asarray(step_size)
        finfo = jnp.finfo(step_size.dtype)

        def body(carry):
            step, _, direction, key = carry
            key, key_move = jax.random.split(key)
            step = step * jnp.power(2.0, direction).astype(step.dtype)
            _, info = self._kernel(
                key_move,
                inner,
                logdensity,
                self._inner_space,
                step_size=step,
                num_integration_steps=1,
                inverse_mass_matrix=mass,
            )
            new_direction = jnp.where(info.metropolis_rate > HEURISTIC_ACCEPT_PROB, 1, -1)
            return step, direction, new_direction, key

        def cond(carry):
            step, last, direction, _ = carry
            in_range = ((step > finfo.tiny) | (direction >= 0)) & (
                (step < finfo.max) | (direction <= 0)
            )
            return in_range & ((last == 0) | (direction == last))

        zero = jnp.asarray(0)
        return jax.lax.while_loop(cond, body, (step_size, zero, zero, key))[0]

    # ------------------------------------------------------------------ MCMCKernel
    def init(self, rng_key, num_warmup, init_params, model_args, model_kwargs):
        model_kwargs = model_kwargs or {}
        batched = not is_prng_key(rng_key)
        self._num_warmup = int(num_warmup)  # before the sites: dense_mass="auto" reads it
        if self._potential_fn is not None:
            if init_params is None:
                raise ValueError(
                    "with potential_fn, give init_params to MCMC.run (an array or a dict of "
                    "arrays, with a leading axis of num_chains for vectorized chains), as "
                    "numpyro.infer.HMC needs"
                )
            self._setup_potential(init_params, batched)
            init_params = self._from_user(init_params)
        else:
            self._setup(rng_key[0] if batched else rng_key, model_args, model_kwargs)
            if init_params is not None:
                init_params = self._check_init_params(init_params, batched)
        if self._num_warmup == 0:
            self._warn_unadapted()
        checks = self._check_convergence
        self.run_checks = RunChecks.find(self, num_warmup, batched) if checks else None
        if self._num_warmup > 0:
            self._rows = schedule(self._num_warmup)  # constants, also under jit
        dtype = jnp.zeros(()).dtype
        starting_mass = self._starting_mass(dtype)
        logdensity = self._logdensity_fn(model_args, model_kwargs)
        inner_logdensity = self._inner_logdensity(model_args, model_kwargs)
        if self._init_strategy is None:
            draw = self._random_position
        else:

            def draw(key):
                return self._strategy_position(key, model_args, model_kwargs)

        def init_one(key, params):
            key, key_init = jax.random.split(key)
            if params is None:
                params = self._find_start(key_init, logdensity, draw)
            inner = geometric_hmc.init(self._pack(params), inner_logdensity, self._inner_space)
            dtype = inner.logdensity.dtype
            step_size = jnp.asarray(self._step_size, dtype)
            if self._find_heuristic:
                key, key_step = jax.random.split(key)
                step_size = self._heuristic_step_size(
                    key_step, inner, inner_logdensity, starting_mass, step_size
                )
            one = jax.tree.map(lambda x: jnp.asarray(x)[None], inner)  # a batch of one
            start = {"step_size": step_size, "inverse_mass_matrix": starting_mass}
            adaptation = self._adaptation.init(one, start)
            parameters = self._parameters(adaptation, jnp.asarray(0))
            zero = jnp.asarray(0.0, dtype)
            return GeometricHMCState(
                jnp.asarray(0),
                self._to_user(self._unpack(inner.position)),
                -inner.logdensity,
                -inner.logdensity,
                jnp.asarray(False),
                zero,
                zero,
                jnp.asarray(0),
                parameters["step_size"],
                zero,
                self._adapt_state(parameters),
                inner,
                adaptation,
                key,
            )

        if batched:
            state = jit(jax.vmap(init_one))(rng_key, init_params)
            self._sample_fn = self._sample_batch
        else:
            state = jit(init_one)(rng_key, init_params)
            self._sample_fn = self._sample_one
        energy = concrete_array(state.potential_energy)
        bad = np.zeros(1, bool) if energy is None else ~np.isfinite(np.atleast_1d(energy))
        if np.any(bad):
            raise ValueError(
                "the model's log-density is not finite at the initial parameters"
                + (f" of chains {np.flatnonzero(bad).tolist()}" if batched else "")
                + (
                    ""
                    if init_params is not None
                    else f" after {MAX_INIT_ATTEMPTS} random starts; give init_params"
                )
            )
        # The draws' shapes, deterministic sites included, settled now rather than after the run.
        first = jax.tree.map(lambda x: x[0], state.z) if batched else state.z
        jax.eval_shape(self.postprocess_fn(model_args, model_kwargs), first)
        return state

    def _warn_unadapted(self):
        """``num_warmup=0`` while something is to be adapted: say what the run keeps."""
        unadapted = [
            name
            for name, adapted in (
                (f"step_size={self._step_size:g}", self._adapt_step_size),
                ("the starting inverse_mass_matrix", self._adapt_mass),
                ("the starting integration_time", self._lengths.learn),
            )
            if adapted
        ]
        if unadapted:
            warnings.warn(
                "GeometricHMC with num_warmup=0 runs unadapted, with "
                + ", ".join(unadapted)
                + ", from starts that are not draws from the target: the draws may be biased "
                "and the chains far from converged. Pass num_warmup > 0 to MCMC (e.g. "
                "num_warmup=1000), or give step_size, inverse_mass_matrix and "
                "trajectory_length with adapt_step_size=False, adapt_mass_matrix=False.",
                UserWarning,
                stacklevel=4,
            )

    def _sample_one(self, state, model_args, model_kwargs):
        """One chain's transition: :meth:`_sample_batch` on a batch of one."""
        batch = jax.tree.map(lambda x: jnp.asarray(x)[None], state)
        new = jax.tree.map(lambda x: x[0], self._sample_batch(batch, model_args, model_kwargs))
        if self._num_warmup > 0 and (self._adapt_step_size or self._adapt_mass):
            adapted = new.adapt_state  # after the last warm-up transition: the final ones
            leaves = jax.tree.leaves(adapted.inverse_mass_matrix)
            diagonal = [jnp.ravel(jnp.diagonal(m) if m.ndim == 2 else m) for m in leaves]
            jax.lax.cond(
                state.i == self._num_warmup - 1,
                lambda: jax.debug.callback(
                    self._record_chain, adapted.step_size, jnp.concatenate(diagonal)
                ),
                lambda: None,
            )
        return new

    def _record_chain(self, step_size, inverse_mass):
        """Keep what a chain adapted alone ended with; warn for each chain far from the others
        (:func:`liesample.tuning.windows.far_adapted`), once per chain."""
        self._chain_adaptations.append((float(step_size), np.asarray(inverse_mass)))
        steps, masses = zip(*self._chain_adaptations, strict=True)
        if len({m.shape for m in masses}) != 1:
            return
        for chain, message in far_adapted(steps, np.stack(masses)):
            if chain in self._reported:
                continue
            self._reported.add(chain)
            warnings.warn(
                f"GeometricHMC: chains adapted alone (chain_method='sequential', or 'parallel' "
                f"on one device) ended far apart: {message} (chain = the order in which this "
                "kernel warmed chains up). That chain costs many more gradients per draw, or "
                "adapted to a different region, and its draws may be wrong. Use "
                "chain_method='vectorized' (the chains then adapt together: one step size, "
                "pooled mass), a longer num_warmup, or init_params near the posterior.",
                UserWarning,
                stacklevel=2,
            )

    @property
    def chain_adaptations(self) -> list:
        """``(step_size, inverse mass diagonal, flattened)`` of each chain this kernel warmed
        up alone (sequential chains), in order."""
        return list(self._chain_adaptations)

    def _sample_batch(self, state, model_args, model_kwargs):
        """One transition of every chain (a leading chain axis). The chains share the warm-up:
        one step size (dual averaging of their pooled rate), one mass (their pooled moments)
        and one ``T`` (ChEES centred on their mean); each chain carries a copy of the
        adaptation state (and its own running rate)."""
        i = state.i[0]
        logdensity = self._inner_logdensity(model_args, model_kwargs or {})
        keys = jax.vmap(jax.random.split)(state.rng_key)
        rng_key, key = keys[:, 0], keys[:, 1]
        key_step = jax.random.fold_in(key[0], 1) if self._find_heuristic else None
        shared = jax.tree.map(lambda x: x[0], state.adaptation)
        # each chain carries its own running rate: gathered, one per chain
        smoothed = state.adaptation.step.smoothed[:, 0]
        shared = shared._replace(step=shared.step._replace(smoothed=smoothed))
        parameters = self._parameters(shared, i)
        options = {name: parameters[name] for name in ("step_size", "num_integration_steps")}
        mass = parameters["inverse_mass_matrix"]

        def transition(key, inner):
            space = self._inner_space
            return self._kernel(key, inner, logdensity, space, **options, inverse_mass_matrix=mass)

        inner, info = jax.vmap(transition)(key, state.inner)
        dtype = inner.logdensity.dtype
        kinetic = cotangent_bundle(self._inner_space, mass, None, dtype).kinetic_energy
        energy = -inner.logdensity + jax.vmap(kinetic)(inner.momentum)
        new = shared
        if self._num_warmup > 0:
            new = self._adapt(shared, i, parameters, state.inner, inner, info, logdensity, key_step)
        # NumPyro's running mean, restarted when sampling begins.
        count = jnp.where(i < self._num_warmup, i + 1, i + 1 - self._num_warmup)
        mean_accept = state.mean_accept_prob + (
            info.acceptance_rate - state.mean_accept_prob
        ) / count.astype(dtype)
        num_chains = state.i.shape[0]
        share = lambda tree: jax.tree.map(
            lambda x: jnp.broadcast_to(x, (num_chains, *jnp.shape(x))), tree
        )
        smoothed = new.step.smoothed
        adaptation = share(new._replace(step=new.step._replace(smoothed=smoothed[:1])))
        adaptation = adaptation._replace(step=adaptation.step._replace(smoothed=smoothed[:, None]))
        new_state = GeometricHMCState(
            state.i + 1,
            jax.vmap(lambda p: self._to_user(self._unpack(p)))(inner.position),
            -inner.logdensity,
            energy,
            info.is_divergent,
            info.acceptance_rate,
            mean_accept,
            jnp.asarray(info.num_gradient_evaluations),
            share(parameters["step_size"]),
            share(parameters["step_size"] * parameters["num_integration_steps"]),
            share(self._adapt_state(self._parameters(new, i + 1))),
            inner,
            adaptation,
            rng_key,
        )
        if self.run_checks is not None:  # the draw, to the post-run checks (module docstring)
            fields = {"diverging": info.is_divergent, "accept_prob": info.acceptance_rate,
                      "energy": energy}  # fmt: skip
            latent = latent_values(self.postprocess_fn(model_args, model_kwargs), self._sites)
            self.run_checks.trace(i, state.rng_key, rng_key, latent, new_state.z, fields)
        return new_state

    def _parameters(self, adaptation, i):
        """The parameters of transition ``i``: the adaptation's ``current`` in the warm-up, its
        ``final`` after it (``L`` then the fixed one, or ``ceil(u T / ε)``)."""
        tuned = self._adaptation.final(adaptation)
        step_size = tuned["step_size"]
        if self._num_integration_steps is not None:
            steps = jnp.asarray(self._num_integration_steps)
            time = step_size * steps
        else:
            time = tuned["integration_time"]
            u = halton(i) if self._jitter else 1.0
            steps = jittered_steps(u, time, step_size)
        after = {**tuned, "num_integration_steps": steps, "integration_time": time}
        if self._num_warmup == 0:
            return after
        during = self._adaptation.current(adaptation, row_at(self._rows, i))
        during.setdefault("integration_time", during["step_size"] * steps)
        return jax.tree.map(lambda a, b: jnp.where(i < self._num_warmup, a, b), during, after)

    def _adapt(self, adaptation, i, parameters, before, inner, info, logdensity, key_step):
        """The shared warm-up's ``update`` after transition ``i`` of every chain; with
        ``find_heuristic_step_size`` dual averaging restarts from NumPyro's search at a mass
        window's end. After the warm-up nothing changes."""
        row = row_at(self._rows, i)
        update = cast(Callable, self._adaptation.update)  # the window adaptation has one
        updated = update(adaptation, row, parameters, before, inner, info)
        if self._find_heuristic and self._adapt_mass:

            def restart(state):  # NumPyro's search, from the first chain
                step = self._adaptation.current(state, row)["step_size"]
                first = jax.tree.map(lambda x: x[0], inner)
                step = self._heuristic_step_size(
                    key_step, first, logdensity, state.inverse_mass, step
                )
                return state._replace(step=restart_step_size(state.step, self._target, step))

            updated = jax.lax.cond(row.window_end, restart, lambda state: state, updated)
        in_warmup = i < self._num_warmup
        return jax.tree.map(lambda a, b: jnp.where(in_warmup, a, b), updated, adaptation)

    def sample(self, state, model_args, model_kwargs):
        return self._sample_fn(state, model_args, model_kwargs)

    @property
    def default_fields(self):
        return ("z", "diverging")

    def get_diagnostics_str(self, state):
        return (
            f"{int(state.num_steps)} gradients, step size {float(state.step_size):.2e}. "
            f"acc. prob={float(state.mean_accept_prob):.2f}"
        )

    def postprocess_fn(self, model_args, model_kwargs):
        model_kwargs = model_kwargs or {}
        if self._potential_fn is not None:
            return lambda z: z

        def postprocess(z):
            model = self._constrained_model(z, {})
            trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
            params = {name: trace[name]["value"] for name in self._sites}
            if not self._has_deterministic:
                return params
            extra = {n: s["value"] for n, s in trace.items() if s["type"] == "deterministic"}
            return {**params, **extra}

        return postprocess

    @property
    def model(self):
        """The model, its manifold sites shown to ``arviz.from_numpyro`` through a view (same
        log-density and draws; see the comment above ``_ManifoldSupport``); ``None`` with
        ``potential_fn``."""
        model = self._model
        if model is None:
            return None

        def viewed(*args, **kwargs):
            with _ViewManifoldSites():
                return model(*args, **kwargs)

        return viewed

    @property
    def spaces(self) -> dict:
        """Site name → the liesample space it is moved on (after ``init``)."""
        if self._sites is None:
            raise RuntimeError("the kernel is not initialised: run MCMC first")
        return dict(self._space)
