"""A NumPyro model as the spaces :class:`liesample.interop.numpyro_kernel.GeometricHMC` moves.

The model → space translation of the kernel, with no sampler in it: each latent site's space
from its support (:func:`site_space`; the supports are listed in
:mod:`liesample.interop.numpyro_kernel`), the ``dense_mass`` groups (:func:`dense_groups`), the
packing of site values into the sampler's blocks (:class:`Layout`), the log-density of site
values with the log-Jacobians of the supports' bijections (:func:`logdensity_fn`), the starts
(:func:`random_position`, :func:`strategy_position`, :func:`find_start`, the nearest manifold
point :func:`nearest_point`), the starting inverse mass of the blocks (:func:`starting_mass`)
and the view of manifold sites that ArviZ's converter and ``init_strategy`` see
(:func:`viewed_model`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple, cast

try:
    import numpyro
    from numpyro.distributions import Distribution, constraints
    from numpyro.distributions.transforms import IdentityTransform, biject_to
    from numpyro.infer.util import log_density
except ImportError as error:  # an optional integration module
    raise ImportError(
        "liesample.interop.numpyro_sites needs NumPyro: pip install numpyro (or the 'test' "
        "extras of liesample)"
    ) from error

import jax
import jax.numpy as jnp
import numpy as np

from liesample.geometry import spaces
from liesample.interop.numpyro_distributions import check_observed_sites, rotation

__all__ = [
    "AUTO_DENSE_MAX_DIMENSION",
    "AUTO_DENSE_WARMUP_PER_DIMENSION",
    "MAX_INIT_ATTEMPTS",
    "SUPPORTED",
    "Layout",
    "Site",
    "check_init_params",
    "dense_groups",
    "find_start",
    "hierarchical_scales",
    "layout",
    "logdensity_fn",
    "model_sites",
    "nearest_point",
    "postprocess_fn",
    "potential_sites",
    "random_position",
    "site_space",
    "starting_mass",
    "strategy_position",
    "viewed_model",
]

AUTO_DENSE_MAX_DIMENSION = 32
"""``dense_mass="auto"``: the most unconstrained ``Euclidean`` coordinates adapted densely."""
AUTO_DENSE_WARMUP_PER_DIMENSION = 25
"""``dense_mass="auto"``: warm-up iterations needed per coordinate of a dense block."""

MAX_INIT_ATTEMPTS = 100
"""The most draws :func:`find_start` makes for a start with a finite log-density."""
SUPPORTED = (
    "constraints.sphere (Sphere), liesample.interop.numpyro_distributions.rotation (SO(3)), "
    "constraints.circular (U1), or a continuous support with a bijection to R^d "
    "(numpyro.distributions.biject_to)"
)
"""The supports :func:`site_space` handles, as its refusal names them."""


class Site(NamedTuple):
    """A latent site: the liesample space it is moved on, and whether it is moved in the
    unconstrained coordinates of its support's bijection (``euclidean``)."""

    space: spaces.Space
    euclidean: bool


# ------------------------------------------------------------------ sites to spaces
def _base_constraint(constraint):
    """The constraint under any ``independent(…)`` wrappers."""
    while hasattr(constraint, "base_constraint"):
        constraint = constraint.base_constraint
    return constraint


def site_space(name, site) -> Site:
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
        return Site(spaces.Sphere(value.shape[-1] - 1, shape=value.shape[:-1]), False)
    if base is rotation:
        if value.ndim < 2 or value.shape[-2:] != (3, 3):
            raise ValueError(f"site {name!r} on SO(3) must have 3 x 3 matrices, got {value.shape}")
        return Site(spaces.SO(3, shape=value.shape[:-2]), False)
    if type(base) is type(constraints.circular):
        return Site(spaces.U1(shape=value.shape), False)
    try:
        transform = biject_to(support)
    except NotImplementedError:
        raise ValueError(
            f"site {name!r} has the support {support}, which GeometricHMC cannot handle; "
            f"supported: {SUPPORTED}"
        ) from None
    shape = jnp.shape(transform.inv(value))
    return Site(spaces.Euclidean(shape), True)


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


def model_sites(model, rng_key, model_args, model_kwargs) -> tuple[dict[str, Site], bool]:
    """The latent sites of ``model`` (name → :class:`Site`, in the model's order) and whether
    it has deterministic sites; the observed sites are checked on the way."""
    # A feasible value per latent site (no sampling, so nothing is compiled for it).
    model = numpyro.handlers.substitute(
        numpyro.handlers.seed(model, rng_key), substitute_fn=_feasible_value
    )
    trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
    check_observed_sites(trace)  # concrete here; the log-density is only ever traced
    sites = {}
    for name, site in trace.items():
        if site["type"] == "sample" and not site["is_observed"]:
            sites[name] = site_space(name, site)
    if not sites:
        raise ValueError("the model has no latent sample sites: nothing to sample")
    return sites, any(s["type"] == "deterministic" for s in trace.values())


def _scale_of(fn):
    """The ``scale`` of a distribution under any ``expand`` / ``to_event`` wrappers, or
    ``None``."""
    while not hasattr(fn, "scale") and hasattr(fn, "base_dist"):
        fn = fn.base_dist
    scale = getattr(fn, "scale", None)
    return None if scale is None else np.asarray(scale)


def hierarchical_scales(model, rng_key, model_args, model_kwargs) -> dict[str, tuple[str, ...]]:
    """The positive latent sites that are the ``scale`` of other latent sites' distributions,
    a centred hierarchy (``theta ~ Normal(mu, tau)``: ``{"tau": ("theta",)}``), whose
    posterior is a funnel. Found on the host by tracing the model at feasible values, then
    again with each positive site doubled: a latent site whose distribution's ``scale``
    doubles with it is its child. Eager (a few traces of the model, as :func:`model_sites`
    makes one); a doubled value the model refuses (``ValueError``) names no child."""
    seeded = numpyro.handlers.seed(model, rng_key)

    def trace(**substitute):
        handled = numpyro.handlers.substitute(seeded, **substitute)
        return numpyro.handlers.trace(handled).get_trace(*model_args, **model_kwargs)

    first = trace(substitute_fn=_feasible_value)
    latent = {n: t for n, t in first.items() if t["type"] == "sample" and not t["is_observed"]}
    values = {n: t["value"] for n, t in latent.items()}
    out = {}
    for name, site in latent.items():
        if _base_constraint(site["fn"].support) is not constraints.positive:
            continue
        try:
            doubled = trace(data={**values, name: 2.0 * jnp.asarray(values[name])})
        except ValueError:
            continue
        children = []
        for child in latent:
            a, b = _scale_of(latent[child]["fn"]), _scale_of(doubled[child]["fn"])
            if child == name or a is None or b is None or a.shape != b.shape:
                continue
            if np.all(np.isfinite(a)) and np.any(a != 0) and np.allclose(b, 2.0 * a):
                children.append(child)
        if children:
            out[name] = tuple(children)
    return out


def potential_sites(init_params, batched) -> tuple[dict[str, Site], bool]:
    """Sites of ``potential_fn``: the arrays of ``init_params`` (one chain's shapes), and
    whether ``init_params`` is one array (then its site is named ``"z"``)."""
    array_params = not isinstance(init_params, dict)
    params = {"z": init_params} if array_params else init_params
    sites = {}
    for name, value in params.items():
        if not isinstance(name, str) or isinstance(value, (dict, list, tuple)):
            raise TypeError(
                "with potential_fn, init_params must be an array or a dict of arrays keyed "
                f"by str, got {jax.tree.structure(init_params)}"
            )
        shape = np.shape(value)[1:] if batched else np.shape(value)
        sites[name] = Site(spaces.Euclidean(tuple(shape)), False)
    return sites, array_params


# ------------------------------------------------------------------ dense groups and packing
def _euclidean_sites(sites):
    """The names of the ``Euclidean`` sites, sorted."""
    return sorted(n for n, s in sites.items() if isinstance(s.space, spaces.Euclidean))


def _auto_dense_groups(sites, initial_mass, adapt_mass, num_warmup):
    """``dense_mass="auto"``: the ``Euclidean`` sites as one group, or none."""
    if initial_mass is not None or not adapt_mass:
        return []
    euclidean = _euclidean_sites(sites)
    size = sum(math.prod(sites[n].space.shape) for n in euclidean)
    enough = num_warmup >= AUTO_DENSE_WARMUP_PER_DIMENSION * size
    return [tuple(euclidean)] if 2 <= size <= AUTO_DENSE_MAX_DIMENSION and enough else []


def dense_groups(spec, sites, initial_mass, adapt_mass, num_warmup) -> list[tuple[str, ...]]:
    """The ``dense_mass`` groups of site names (``spec`` as
    :func:`liesample.interop.numpyro_kernel.GeometricHMC` checked it: ``"auto"``, a bool or
    a list of tuples), each checked to name ``Euclidean`` latent sites, each once."""
    if spec == "auto":
        return _auto_dense_groups(sites, initial_mass, adapt_mass, num_warmup)
    if spec is False:
        return []
    groups = [tuple(sorted(sites))] if spec is True else spec
    seen = set()
    euclidean = _euclidean_sites(sites)
    for group in groups:
        for name in group:
            if name not in sites:
                raise ValueError(
                    f"dense_mass names {name!r}, which is not a latent site; the latent "
                    f"sites are {sorted(sites)}"
                )
            if name in seen:
                raise ValueError(f"dense_mass names the site {name!r} in two groups")
            seen.add(name)
            if name not in euclidean:
                raise ValueError(
                    f"dense_mass: site {name!r} moves on {sites[name].space!r}, where "
                    "GeometricHMC's exact drift needs one inverse mass per copy; a dense "
                    "mass is possible on Euclidean sites only: allowed "
                    f"dense_mass=[{tuple(euclidean)!r}] or groups of these sites"
                )
    return list(groups)


class Layout(NamedTuple):
    """The sites and the sampler's blocks: each site alone, or a ``dense_mass`` group packed
    into one ``Euclidean`` vector (its sites raveled in the group's order) under a key in
    ``dense_keys``. ``inner_space`` is the sampler's space (block key → space);
    ``array_params``: the sample field is one array (``potential_fn`` given one)."""

    sites: dict[str, Site]
    blocks: dict[str, tuple[str, ...]]
    dense_keys: list[str]
    inner_space: dict[str, spaces.Space]
    array_params: bool
    has_deterministic: bool

    @property
    def space(self) -> dict[str, spaces.Space]:
        """Site name → its space."""
        return {name: site.space for name, site in self.sites.items()}

    def pack(self, z):
        """Site values → the sampler's position (a dict of blocks)."""
        return {
            key: (
                jnp.concatenate([jnp.ravel(z[n]) for n in group])
                if key in self.dense_keys
                else z[group[0]]
            )
            for key, group in self.blocks.items()
        }

    def unpack(self, position):
        """The sampler's position → site values."""
        z = {}
        for key, group in self.blocks.items():
            if key not in self.dense_keys:
                z[group[0]] = position[key]
                continue
            offset = 0
            for name in group:
                shape = self.sites[name].space.shape
                size = math.prod(shape)
                z[name] = position[key][offset : offset + size].reshape(shape)
                offset += size
        return z

    def to_user(self, z):
        """Site values → the sample field ``z`` as the user gave ``init_params``."""
        return z["z"] if self.array_params else z

    def from_user(self, params):
        """The sample field as the user gives it → site values."""
        return {"z": params} if self.array_params else params


def layout(sites, groups, array_params=False, has_deterministic=False) -> Layout:
    """The :class:`Layout` of ``sites`` with the ``dense_mass`` ``groups`` packed."""
    grouped = {name for group in groups for name in group}
    blocks: dict[str, tuple[str, ...]] = {n: (n,) for n in sites if n not in grouped}
    dense_keys = []
    for group in groups:
        key = "+".join(group)
        while key in blocks or (len(group) > 1 and key in sites):
            key += "+"
        blocks[key] = group
        dense_keys.append(key)
    inner_space = {
        key: (
            spaces.Euclidean((sum(math.prod(sites[n].space.shape) for n in group),))
            if key in dense_keys
            else sites[group[0]].space
        )
        for key, group in blocks.items()
    }
    return Layout(sites, blocks, dense_keys, inner_space, array_params, has_deterministic)


# ------------------------------------------------------------------ log-density
def _constrained_model(model, sites, z, jacobians):
    """The model with its latent sites set from ``z``: each Euclidean site's value is the
    bijection of its support *as the model builds it now* (with the values of the sites
    before it, as NumPyro's ``potential_energy`` does: a bound may depend on another
    site) applied to its unconstrained value; the log-Jacobians go into ``jacobians``."""

    def constrain(site):
        name = site["name"]
        if site["type"] != "sample" or site["is_observed"] or name not in sites:
            return None
        if not sites[name].euclidean:
            return z[name]
        transform = biject_to(site["fn"].support)
        value = transform(z[name])
        jacobians[name] = transform.log_abs_det_jacobian(z[name], value)
        return value

    return numpyro.handlers.substitute(model, substitute_fn=constrain)


def logdensity_fn(model, potential_fn, layout, model_args, model_kwargs) -> Callable:
    """``log π`` of site values: ``−potential_fn`` of the sample field, or the model's joint
    log-density with the log-Jacobians of its ``Euclidean`` sites' bijections."""
    if potential_fn is not None:
        return lambda z: -potential_fn(layout.to_user(z))
    sites = layout.sites

    def logdensity(z):
        jacobians: dict[str, jax.Array] = {}
        constrained = _constrained_model(model, sites, z, jacobians)
        log_joint, _ = log_density(constrained, model_args, model_kwargs, {})
        for name, site in sites.items():
            if site.euclidean:
                log_joint = log_joint + jnp.sum(jacobians[name])
        return log_joint

    return logdensity


def postprocess_fn(model, layout, model_args, model_kwargs) -> Callable:
    """``z ↦`` the constrained values of the latent sites, and the deterministic sites."""

    def postprocess(z):
        constrained = _constrained_model(model, layout.sites, z, {})
        trace = numpyro.handlers.trace(constrained).get_trace(*model_args, **model_kwargs)
        params = {name: trace[name]["value"] for name in layout.sites}
        if not layout.has_deterministic:
            return params
        extra = {n: s["value"] for n, s in trace.items() if s["type"] == "deterministic"}
        return {**params, **extra}

    return postprocess


# ------------------------------------------------------------------ the manifold view
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
# ``init_strategy`` runs on the same view (then :func:`nearest_point`).
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


def viewed_model(model) -> Callable:
    """``model`` with its manifold sites shown through the view above (same log-density and
    draws, a support with an identity bijection)."""

    def viewed(*args, **kwargs):
        with _ViewManifoldSites():
            return model(*args, **kwargs)

    return viewed


# ------------------------------------------------------------------ starts
def nearest_point(space, x):
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


def random_position(sites, key):
    """Uniform on manifold sites, uniform in ``(−2, 2)`` in unconstrained coordinates
    (NumPyro's ``init_to_uniform``)."""
    keys = jax.random.split(key, len(sites))
    dtype = jnp.zeros(()).dtype
    out = {}
    for k, (name, site) in zip(keys, sites.items()):
        if not site.euclidean:
            out[name] = site.space.uniform(k, dtype)
        else:
            out[name] = jax.random.uniform(k, site.space.shape, dtype, -2.0, 2.0)
    return out


def strategy_position(model, init_strategy, sites, key, model_args, model_kwargs):
    """The sites' values ``init_strategy`` gives on ``model`` (:func:`viewed_model` of the
    model; unconstrained, manifold sites taken to their nearest point)."""
    model = numpyro.handlers.substitute(
        numpyro.handlers.seed(model, key), substitute_fn=init_strategy
    )
    trace = numpyro.handlers.trace(model).get_trace(*model_args, **model_kwargs)
    dtype = jnp.zeros(()).dtype
    out = {}
    for name, site in sites.items():
        value = jnp.asarray(trace[name]["value"], dtype)
        if not site.euclidean:
            out[name] = nearest_point(site.space, value)
        else:  # the support as the strategy's trace built it
            out[name] = biject_to(trace[name]["fn"].support).inv(value)
        out[name] = jnp.broadcast_to(out[name], site.space.position_array_shape)
    return out


def find_start(key, logdensity, draw):
    """Starts from ``draw`` until log π and its gradient are finite (at most
    :data:`MAX_INIT_ATTEMPTS` draws)."""

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


def check_init_params(sites, init_params, batched):
    """``init_params`` given to ``MCMC.run`` with a model, checked (every latent site, each
    chain's points on its manifold); the dict in the sites' order."""
    if not isinstance(init_params, dict) or set(init_params) != set(sites):
        raise ValueError(
            f"init_params must be a dict with the latent sites {sorted(sites)}: "
            "points on the manifold sites, unconstrained values on the others"
        )
    params = {name: init_params[name] for name in sites}
    space = {name: site.space for name, site in sites.items()}
    chains = np.shape(jax.tree.leaves(params)[0])[0] if batched else None
    for c in range(cast(int, chains)) if batched else (None,):
        start = params if c is None else jax.tree.map(lambda x, c=c: x[c], params)
        spaces.check_position(space, start, "init_params" + ("" if c is None else f"[chain {c}]"))
    return params


# ------------------------------------------------------------------ masses
def _mass_by_block(given, layout):
    """``inverse_mass_matrix`` as a dict keyed by block (``None`` when not given)."""
    if not isinstance(given, dict):
        return None if given is None else dict.fromkeys(layout.blocks, given)
    by_key = {}
    for key, value in given.items():
        names = (key,) if isinstance(key, str) else tuple(key)
        block = [k for k, group in layout.blocks.items() if group == names]
        if not block:
            raise ValueError(
                f"inverse_mass_matrix has the key {key!r}, which names no block; the "
                f"keys are the sites or dense_mass groups {list(layout.blocks.values())}"
            )
        by_key[block[0]] = value
    missing = [layout.blocks[k] for k in layout.blocks if k not in by_key]
    if missing:
        raise ValueError(f"inverse_mass_matrix misses the sites or groups {missing}")
    return by_key


def starting_mass(given, layout, dtype):
    """The starting inverse mass (a dict of blocks; an ``(n, n)`` matrix for each dense
    block) from ``inverse_mass_matrix`` (``given``)."""
    by_key = _mass_by_block(given, layout)
    matrices = {}
    for key in layout.dense_keys:
        n = layout.inner_space[key].shape[0]
        value = jnp.ones((), dtype) if by_key is None else jnp.asarray(by_key[key], dtype)
        name = f"inverse mass of {layout.blocks[key]}"
        if np.ndim(value) == 0:
            value = jnp.full(n, value)
        spaces.check_inverse_mass_matrix(value, n, name)
        if np.ndim(value) == 1:
            value = jnp.diag(value)
        matrices[key] = jnp.asarray(value, dtype)
        if by_key is not None:
            by_key[key] = jnp.ones(n, dtype)
    if by_key is not None and not layout.dense_keys and not isinstance(given, dict):
        by_key = given  # a scalar, as before
    masses = cast(dict, spaces.check_inverse_mass(layout.inner_space, by_key, dtype))  # a dict
    return {**masses, **matrices}
