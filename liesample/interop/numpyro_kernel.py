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
  the bijection added to the log-density.

Discrete sites, and supports with neither a space nor a bijection, are refused when the kernel
is initialised, naming the site. The log-density is the model's joint log-density (NumPyro's
``log_density``) with respect to the area of spheres, Haar measure on SO(3) and Lebesgue
measure in the unconstrained coordinates: these differ from the samplers' reference measures by
constants only.

**Warm-up.** During NumPyro's ``num_warmup`` iterations the kernel adapts exactly as
:func:`liesample.window_adaptation` does, sharing its code
(:func:`liesample.tuning.adaptation.warmup_pieces` and
:func:`liesample.tuning.adaptation.window_schedule`) and reading what to adapt from
``liesample.geometric_hmc.adaptation``: Stan's windows, dual averaging of the step size towards
``target_accept_prob``, the inverse mass from Welford moments in algebra coordinates, and a
fixed integration time ``T = π/2`` (``L = ceil(T/ε)`` steps of the ``integrator`` scheme)
unless ``num_integration_steps`` is given. At the last warm-up iteration the step size becomes
dual averaging's average; after that nothing changes.

**State and diagnostics.** The sample field is ``z``: the manifold sites' points and the other
sites' unconstrained values (``init_params`` takes the same form); ``postprocess_fn`` maps it to
the constrained values and adds deterministic sites, so ``mcmc.get_samples()`` holds what the
model sees. The state also carries ``diverging`` (collected by default: ``print_summary``
counts divergences), ``accept_prob``, ``potential_energy``, ``num_steps`` and ``step_size``
(``extra_fields``; ``arviz.from_numpyro`` names them ``acceptance_rate``, ``lp``, ``n_steps``).

**Chains.** ``chain_method="vectorized"`` vmaps init and transition over chains;
``"sequential"`` works as well. NumPyro compiles its loop with plain ``jax.jit``, not
:func:`liesample.jit`; the vmapped chains were checked against the same chains run alone (equal
to round-off, a slow test), as XLA:CPU's vmapped-loop miscompile
(:mod:`liesample.foundation.compile`) would show there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

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
from liesample.interop.numpyro_distributions import rotation
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.tuning.adaptation import (
    DEFAULT_INTEGRATION_TIME,
    WarmupState,
    integration_steps,
    warmup_pieces,
    window_schedule,
)

__all__ = ["GeometricHMC", "GeometricHMCState"]

MAX_INIT_ATTEMPTS = 100
SUPPORTED = (
    "constraints.sphere (Sphere), liesample.interop.numpyro_distributions.rotation (SO(3)), "
    "constraints.circular (U1), or a continuous support with a bijection to R^d "
    "(numpyro.distributions.biject_to)"
)


class GeometricHMCState(NamedTuple):
    """One chain's state; ``z`` is the sample field (module docstring)."""

    i: jax.Array
    z: dict
    potential_energy: jax.Array
    diverging: jax.Array
    accept_prob: jax.Array
    num_steps: jax.Array
    step_size: jax.Array
    inner: object  # the liesample.geometric_hmc state
    warmup: WarmupState
    rng_key: jax.Array


def _base_constraint(constraint):
    """The constraint under any ``independent(…)`` wrappers."""
    while hasattr(constraint, "base_constraint"):
        constraint = constraint.base_constraint
    return constraint


class _Site(NamedTuple):
    space: object
    transform: object  # None for manifold sites


def _site_space(name, site):
    """The liesample space of a latent site, and its bijection for a Euclidean one."""
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
        return _Site(spaces.Sphere(value.shape[-1] - 1, shape=value.shape[:-1]), None)
    if base is rotation:
        return _Site(spaces.SO(3, shape=value.shape[:-2]), None)
    if type(base) is type(constraints.circular):
        return _Site(spaces.U1(shape=value.shape), None)
    try:
        transform = biject_to(support)
    except NotImplementedError:
        raise ValueError(
            f"site {name!r} has the support {support}, which GeometricHMC cannot handle; "
            f"supported: {SUPPORTED}"
        ) from None
    shape = jnp.shape(transform.inv(value))
    return _Site(spaces.Euclidean(shape), transform)


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


# ArviZ's converter (``arviz.from_numpyro``) replays ``kernel.model`` under NumPyro's
# ``init_to_sample``, which needs a bijection for every latent support and has none for a
# sphere or SO(3). ``kernel.model`` therefore shows manifold sites through a view whose support
# has an identity "bijection" registered for this private constraint type only: the log-density,
# draws and values are the original distribution's, and NumPyro's own samplers never see it.
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


class GeometricHMC(MCMCKernel):
    """Geometric HMC on a NumPyro model's sites, on spheres, SO(3), circles and ``Rᵈ``.

    Parameters
    ----------
    model : callable
        A NumPyro model (module docstring for the supports it handles).
    step_size : float
        Initial step size of the warm-up (the step size when ``adapt_step_size=False``).
    num_integration_steps : int, optional
        Fixed leapfrog steps per transition; by default ``ceil(integration_time / ε)``.
    integration_time : float, optional
        ``T`` of a trajectory (default ``π/2`` in the units set by the mass).
    inverse_mass_matrix : None, float or dict
        Starting ``M⁻¹`` (unit by default): a positive scalar or a dict site → value shaped as
        :func:`liesample.geometric_hmc` takes it (one value per copy of a sphere or group, one
        per coordinate of ``Euclidean`` and ``U1`` sites).
    adapt_step_size, adapt_mass_matrix : bool
        What the warm-up adapts (of what ``liesample.geometric_hmc.adaptation`` declares).
    target_accept_prob : float, optional
        Dual averaging's target Metropolis rate (by default the declared one, 0.8).
    divergence_threshold : float
        ``ΔH`` above which a transition is flagged divergent.
    integrator : str or sequence of (effect, fraction) pairs
        The integration scheme, as for :func:`liesample.geometric_hmc` (``"leapfrog"`` by
        default, ``"minimal_norm"``, or a palindromic coefficient list).
    """

    sample_field = "z"

    def __init__(
        self,
        model: Callable,
        *,
        step_size: float = 0.1,
        num_integration_steps: int | None = None,
        integration_time: float | None = None,
        inverse_mass_matrix=None,
        adapt_step_size: bool = True,
        adapt_mass_matrix: bool = True,
        target_accept_prob: float | None = None,
        divergence_threshold: float = 1000.0,
        integrator="leapfrog",
    ):
        if not callable(model):
            raise TypeError(f"model must be a NumPyro model (a callable), got {model!r}")
        self._model = model
        self._step_size = finite_float("step_size", step_size, positive=True)
        if num_integration_steps is not None:
            if integration_time is not None:
                raise ValueError("give integration_time or num_integration_steps, not both")
            if (
                isinstance(num_integration_steps, bool)
                or int(num_integration_steps) != num_integration_steps
                or num_integration_steps < 1
            ):
                raise ValueError(
                    f"num_integration_steps must be an integer >= 1, got {num_integration_steps!r}"
                )
            num_integration_steps = int(num_integration_steps)
        time = DEFAULT_INTEGRATION_TIME if integration_time is None else integration_time
        self._integration_time = finite_float("integration_time", time, positive=True)
        self._num_integration_steps = num_integration_steps
        self._initial_mass = inverse_mass_matrix
        adapted = geometric_hmc.adaptation["adapted"]
        self._adapt_step_size = bool(adapt_step_size) and "step_size" in adapted
        self._adapt_mass = bool(adapt_mass_matrix) and "inverse_mass_matrix" in adapted
        if target_accept_prob is None:
            target_accept_prob = geometric_hmc.adaptation["target_acceptance_rate"]
        target = finite_float("target_accept_prob", target_accept_prob)
        if not 0.0 < target < 1.0:
            raise ValueError(f"target_accept_prob must be in (0, 1), got {target}")
        self._target = target
        self._kernel = geometric_hmc.build_kernel(divergence_threshold, integrator=integrator)
        self._sites = None
        self._pieces = None
        self._sample_fn = None
        self._num_warmup = 0

    # ------------------------------------------------------------------ the model
    def _setup(self, rng_key, model_args, model_kwargs):
        # A feasible value per latent site (no sampling, so nothing is compiled for it).
        model = numpyro.handlers.substitute(
            numpyro.handlers.seed(self._model, rng_key), substitute_fn=_feasible_value
        )
        trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
        sites = {}
        for name, site in trace.items():
            if site["type"] == "sample" and not site["is_observed"]:
                sites[name] = _site_space(name, site)
        if not sites:
            raise ValueError("the model has no latent sample sites: nothing to sample")
        self._sites = sites
        self._space = {name: site.space for name, site in sites.items()}
        self._has_deterministic = any(s["type"] == "deterministic" for s in trace.values())
        self._pieces = warmup_pieces(self._space, self._target, self._adapt_mass)

    def _constrain(self, z):
        return {
            name: z[name] if site.transform is None else site.transform(z[name])
            for name, site in self._sites.items()
        }

    def _logdensity_fn(self, model_args, model_kwargs):
        def logdensity(z):
            params = self._constrain(z)
            log_joint, _ = log_density(self._model, model_args, model_kwargs, params)
            for name, site in self._sites.items():
                if site.transform is not None:
                    jacobian = site.transform.log_abs_det_jacobian(z[name], params[name])
                    log_joint = log_joint + jnp.sum(jacobian)
            return log_joint

        return logdensity

    def _random_position(self, key):
        """Uniform on manifold sites, uniform in ``(−2, 2)`` in unconstrained coordinates
        (NumPyro's ``init_to_uniform``)."""
        keys = jax.random.split(key, len(self._sites))
        dtype = jnp.zeros(()).dtype
        out = {}
        for k, (name, site) in zip(keys, self._sites.items()):
            if site.transform is None:
                out[name] = site.space.uniform(k, dtype)
            else:
                out[name] = jax.random.uniform(k, site.space.shape, dtype, -2.0, 2.0)
        return out

    # ------------------------------------------------------------------ MCMCKernel
    def init(self, rng_key, num_warmup, init_params, model_args, model_kwargs):
        model_kwargs = model_kwargs or {}
        batched = not is_prng_key(rng_key)
        self._setup(rng_key[0] if batched else rng_key, model_args, model_kwargs)
        self._num_warmup = int(num_warmup)
        if self._num_warmup > 0:
            self._schedule = window_schedule(self._num_warmup)  # constants (also under jit)
        logdensity = self._logdensity_fn(model_args, model_kwargs)
        if init_params is not None:
            self._check_init_params(init_params, batched)

        def init_one(key, params):
            key, key_init = jax.random.split(key)
            if params is None:
                params = self._find_start(key_init, logdensity)
            inner = geometric_hmc.init(params, logdensity, self._space)
            return self._state(jnp.asarray(0), inner, key, dtype=inner.logdensity.dtype)

        if batched:
            state = jit(jax.vmap(init_one))(rng_key, init_params)
            self._sample_fn = jax.vmap(self._sample_one, in_axes=(0, None, None))
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
        return state

    def _check_init_params(self, init_params, batched):
        if not isinstance(init_params, dict) or set(init_params) != set(self._sites):
            raise ValueError(
                f"init_params must be a dict with the latent sites {sorted(self._sites)}: "
                "points on the manifold sites, unconstrained values on the others"
            )
        params = {name: init_params[name] for name in self._sites}
        chains = np.shape(jax.tree.leaves(params)[0])[0] if batched else None
        for c in range(chains) if batched else (None,):
            start = params if c is None else jax.tree.map(lambda x, c=c: x[c], params)
            spaces.check_position(
                self._space, start, "init_params" + ("" if c is None else f"[chain {c}]")
            )

    def _find_start(self, key, logdensity):
        """Random starts until log π and its gradient are finite (at most 100 draws)."""

        def body(carry):
            key, _, attempt = carry
            key, key_draw = jax.random.split(key)
            return key, self._random_position(key_draw), attempt + 1

        def cond(carry):
            _, position, attempt = carry
            value, grad = jax.value_and_grad(logdensity)(position)
            finite = jnp.isfinite(value)
            for g in jax.tree.leaves(grad):
                finite = finite & jnp.all(jnp.isfinite(g))
            return ~finite & (attempt < MAX_INIT_ATTEMPTS)

        key, key_draw = jax.random.split(key)
        first = (key, self._random_position(key_draw), jnp.asarray(1))
        return jax.lax.while_loop(cond, body, first)[1]

    def _state(self, i, inner, rng_key, dtype, info=None, warm=None, step_size=None):
        if warm is None:
            mass = spaces.check_inverse_mass(self._space, self._initial_mass, dtype)
            warm = self._pieces.init(inner, self._step_size, mass)
            step_size = warm.step_size
        return GeometricHMCState(
            i,
            inner.position,
            -inner.logdensity,
            jnp.asarray(False) if info is None else info.is_divergent,
            jnp.asarray(0.0, dtype) if info is None else info.acceptance_rate,
            jnp.asarray(0) if info is None else jnp.asarray(info.num_integration_steps),
            step_size,
            inner,
            warm,
            rng_key,
        )

    def _steps_for(self, step_size):
        if self._num_integration_steps is not None:
            return jnp.asarray(self._num_integration_steps)
        return integration_steps(step_size, self._integration_time)

    def _sample_one(self, state, model_args, model_kwargs):
        logdensity = self._logdensity_fn(model_args, model_kwargs or {})
        rng_key, key = jax.random.split(state.rng_key)
        warm = state.warmup
        step_size = warm.step_size
        steps = self._steps_for(step_size)
        inner, info = self._kernel(
            key,
            state.inner,
            logdensity,
            self._space,
            step_size=step_size,
            num_integration_steps=steps,
            inverse_mass_matrix=warm.inverse_mass,
        )
        if self._num_warmup > 0:
            index = jnp.minimum(state.i, self._num_warmup - 1)
            stage, window_end = (jnp.asarray(column)[index] for column in self._schedule)
            updated = self._pieces.update(warm, inner, info, stage, window_end)
            final = jnp.where(
                state.i == self._num_warmup - 1,
                self._pieces.final_step_size(updated),
                updated.step_size,
            )
            if not self._adapt_step_size:
                final = jnp.asarray(self._step_size, final.dtype)
            updated = updated._replace(step_size=final)
            in_warmup = state.i < self._num_warmup
            warm = jax.tree.map(lambda a, b: jnp.where(in_warmup, a, b), updated, warm)
        dtype = inner.logdensity.dtype
        return self._state(state.i + 1, inner, rng_key, dtype, info, warm, step_size)

    def sample(self, state, model_args, model_kwargs):
        return self._sample_fn(state, model_args, model_kwargs)

    @property
    def default_fields(self):
        return ("z", "diverging")

    def get_diagnostics_str(self, state):
        return f"step size {float(state.step_size):.2e}, acc. prob={float(state.accept_prob):.2f}"

    def postprocess_fn(self, model_args, model_kwargs):
        model_kwargs = model_kwargs or {}

        def postprocess(z):
            params = self._constrain(z)
            if not self._has_deterministic:
                return params
            model = numpyro.handlers.substitute(self._model, data=params)
            trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
            extra = {n: s["value"] for n, s in trace.items() if s["type"] == "deterministic"}
            return {**params, **extra}

        return postprocess

    @property
    def model(self):
        """The model, its manifold sites shown to ``arviz.from_numpyro`` through a view (same
        log-density and draws; see the comment above ``_ManifoldSupport``)."""
        model = self._model

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

