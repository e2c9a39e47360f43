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
:func:`liesample.tuning.protocol.pooled_rate`, by the median of their running rates after the
initial fast window, :data:`liesample.interop.numpyro_hmc.POOLING`, so a minority stuck in a
degenerate mode cannot lower the step of the rest; such a chain is named in a warning at the
end of the warm-up), one mass (pooled moments) and one ``T``;
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
naming them, and a funnel warning naming a centred hierarchy's scale site
(``hierarchical_scales``, found in the model at ``init``) with
``numpyro.infer.reparam.LocScaleReparam`` as the fix; it costs nothing while the chains run.
By default (``check_convergence=True``) the same checks run at the end of ``MCMC.run`` with no
extra call: the chains keep a copy of the draws MCMC keeps on the device, sent to the host once,
after the run's last draw. NumPyro does not tell a kernel how many draws follow its warm-up, so
``init`` finds the calling ``MCMC`` on the call stack; the mechanism and its limits are in
:mod:`liesample.interop.numpyro_checks`.

**Chains.** ``chain_method="vectorized"`` vmaps init and transition over chains;
``"sequential"`` works as well. NumPyro compiles its loop with plain ``jax.jit``, not
:func:`liesample.jit`; the vmapped chains were checked against the same chains run alone (equal
to round-off, a slow test), as XLA:CPU's vmapped-loop miscompile
(:mod:`liesample.foundation.compile`) would show there.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import cast

try:
    from numpyro.infer.mcmc import MCMCKernel
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
from liesample.interop.numpyro_checks import RunChecks, latent_values
from liesample.interop.numpyro_hmc import (
    HEURISTIC_ACCEPT_PROB as HEURISTIC_ACCEPT_PROB,  # re-exported, as before the split
)
from liesample.interop.numpyro_hmc import (
    AdaptState,
    Core,
    GeometricHMCState,
    Settings,
    core,
    init_state,
    record_chain,
    sample_batch,
    sample_one,
    warn_unadapted,
)
from liesample.interop.numpyro_sites import (
    AUTO_DENSE_MAX_DIMENSION,
    AUTO_DENSE_WARMUP_PER_DIMENSION,
    MAX_INIT_ATTEMPTS,
    Layout,
    check_init_params,
    dense_groups,
    hierarchical_scales,
    layout,
    logdensity_fn,
    model_sites,
    postprocess_fn,
    potential_sites,
    random_position,
    starting_mass,
    strategy_position,
    viewed_model,
)
from liesample.interop.numpyro_sites import (
    SUPPORTED as SUPPORTED,  # re-exported, as before the split
)
from liesample.samplers.contract import Tunable
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc
from liesample.tuning.protocol import schedule
from liesample.tuning.trajectory import DEFAULT_INTEGRATION_TIME, trajectory_adaptation

# The model → space translation is liesample.interop.numpyro_sites, the functional step, init
# and adaptation core liesample.interop.numpyro_hmc; the names below are re-exported from them.
__all__ = [
    "AUTO_DENSE_MAX_DIMENSION",
    "AUTO_DENSE_WARMUP_PER_DIMENSION",
    "AdaptState",
    "GeometricHMC",
    "GeometricHMCState",
]


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


def _check_start(potential_energy, batched, given):
    """The first states' log-density must be finite (``given``: from ``init_params``)."""
    energy = concrete_array(potential_energy)
    bad = np.zeros(1, bool) if energy is None else ~np.isfinite(np.atleast_1d(energy))
    if np.any(bad):
        raise ValueError(
            "the model's log-density is not finite at the initial parameters"
            + (f" of chains {np.flatnonzero(bad).tolist()}" if batched else "")
            + ("" if given else f" after {MAX_INIT_ATTEMPTS} random starts; give init_params")
        )


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
        Energy error ``H(z_k) − H(z_0)`` above which a transition is flagged divergent, at
        any step ``k`` of its trajectory (NumPyro's ``diverging``, as its NUTS counts it).
    integrator : str or sequence of (effect, fraction) pairs
        The integration scheme, as for :func:`liesample.geometric_hmc` (``"leapfrog"`` by
        default, ``"minimal_norm"``, or a palindromic coefficient list).
    jitter : bool
        Integrate ``u T`` with ``u`` from the base-2 Halton sequence (default): a fixed
        ``T`` can sit at a resonance of the target (a direction whose half period is
        ``T``, whose chain then barely moves). ``False`` integrates ``T`` itself.
    check_convergence : bool
        Run :func:`liesample.sample`'s post-run checks at the end of ``MCMC.run`` with no extra
        call (default; module docstring): the chains carry a second copy of the kept draws on
        the device, sent to the host once per run. ``False`` keeps no copy; then
        ``liesample.interop.numpyro_checks.check_mcmc(mcmc)`` checks the finished run.
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
        check_convergence: bool = True,
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
        step_size = finite_float("step_size", step_size, positive=True)
        num_integration_steps, time, learn = _trajectory_arguments(
            num_integration_steps, integration_time, num_steps, trajectory_length
        )
        lengths = trajectory_adaptation(time, learn=learn)
        flags = {"jitter": jitter, "adapt_step_size": adapt_step_size,
                 "adapt_mass_matrix": adapt_mass_matrix,
                 "find_heuristic_step_size": find_heuristic_step_size,
                 "check_convergence": check_convergence}  # fmt: skip
        for name, flag in flags.items():  # bool("no") would be True
            if not isinstance(flag, (bool, np.bool_)):
                raise TypeError(f"{name} must be a bool (True or False), got {flag!r}")
        if inverse_mass_matrix is not None and not isinstance(inverse_mass_matrix, dict):
            finite_float("inverse_mass_matrix", inverse_mass_matrix, positive=True)  # else a dict
        self._initial_mass = inverse_mass_matrix
        self._dense_mass = _dense_spec(dense_mass)
        declared = cast(Tunable, geometric_hmc.adaptation)  # geometric HMC declares its warm-up
        adapted = declared.adapted
        adapt_step = bool(adapt_step_size) and "step_size" in adapted
        adapt_mass = bool(adapt_mass_matrix) and "inverse_mass_matrix" in adapted
        if target_accept_prob is None:
            target_accept_prob = declared.target_acceptance_rate
        target = finite_float("target_accept_prob", target_accept_prob)
        if not 0.0 < target < 1.0:
            raise ValueError(f"target_accept_prob must be in (0, 1), got {target}")
        divergence_threshold = finite_float("divergence_threshold", divergence_threshold)
        kernel = geometric_hmc.build_kernel(divergence_threshold, integrator=integrator)
        self._settings = Settings(step_size, num_integration_steps, jitter, lengths, adapt_step,
                                  adapt_mass, bool(find_heuristic_step_size) and adapt_step,
                                  target, kernel)  # fmt: skip
        # None until init sets the kernel up (and init runs before every other use): typed as
        # what they hold from then on.
        self._layout: Layout = None  # type: ignore[assignment]
        self._core: Core = None  # type: ignore[assignment]
        self._batched = False
        # Set by init: NumPyro's MCMC calls init again before a run from a warm-up's state
        # (MCMC.warmup then MCMC.run, or post_warmup_state) unless the kernel has it, as
        # numpyro.infer.HMC does; that second init would rebuild and recompile what the
        # warm-up's init settled, for every chain.
        self._sample_fn: Callable | None = None
        # (step size, flat inverse mass) of each chain adapted alone
        self._chain_adaptations: list[tuple[float, np.ndarray]] = []
        self._reported: set[int] = set()
        self._check_convergence = bool(check_convergence)
        # The post-run checks of the MCMC running this kernel (set by init; None: unchecked).
        self.run_checks: RunChecks | None = None
        # Scale site -> the sites it is the scale of (a centred hierarchy; set by init).
        self.hierarchical_scales: dict[str, tuple[str, ...]] = {}

    # ------------------------------------------------------------------ the sites
    def _set_sites(self, sites, array_params, has_deterministic):
        """The sites' layout (each site a block, or a ``dense_mass`` group packed into one),
        then the functional core on it."""
        settings = self._settings
        groups = dense_groups(self._dense_mass, sites, self._initial_mass, settings.adapt_mass,
                              settings.num_warmup)  # fmt: skip
        self._layout = layout(sites, groups, array_params, has_deterministic)
        self._core = core(settings, self._layout)

    def _logdensity_fn(self, model_args, model_kwargs):
        """``log π`` of site values."""
        return logdensity_fn(self._model, self._potential_fn, self._layout, model_args,
                             model_kwargs)  # fmt: skip

    def _inner_logdensity(self, model_args, model_kwargs):
        """``log π`` of the sampler's position."""
        logdensity = self._logdensity_fn(model_args, model_kwargs)
        unpack = self._layout.unpack
        if not self._layout.dense_keys:
            return logdensity
        return lambda position: logdensity(unpack(position))

    def _draw(self, model_args, model_kwargs):
        """``key ↦`` a start (site values): ``init_strategy``'s, or uniform."""
        sites = self._layout.sites
        if self._init_strategy is None:
            return functools.partial(random_position, sites)
        model, strategy = self.model, self._init_strategy
        return lambda key: strategy_position(model, strategy, sites, key, model_args,
                                             model_kwargs)  # fmt: skip

    # ------------------------------------------------------------------ MCMCKernel
    def init(self, rng_key, num_warmup, init_params, model_args, model_kwargs):
        model_kwargs = model_kwargs or {}
        batched = not is_prng_key(rng_key)
        # before the sites: dense_mass="auto" reads it
        self._settings = settings = self._settings._replace(num_warmup=int(num_warmup))
        if self._potential_fn is not None:
            if init_params is None:
                raise ValueError(
                    "with potential_fn, give init_params to MCMC.run (an array or a dict of "
                    "arrays, with a leading axis of num_chains for vectorized chains), as "
                    "numpyro.infer.HMC needs"
                )
            sites, array_params = potential_sites(init_params, batched)
            self._set_sites(sites, array_params, False)
            init_params = self._layout.from_user(init_params)
        else:
            key = rng_key[0] if batched else rng_key
            sites, deterministic = model_sites(self._model, key, model_args, model_kwargs)
            self.hierarchical_scales = hierarchical_scales(self._model, key, model_args,
                                                           model_kwargs)  # fmt: skip
            self._set_sites(sites, False, deterministic)
            if init_params is not None:
                init_params = check_init_params(sites, init_params, batched)
        if settings.num_warmup == 0:
            warn_unadapted(settings)
        checks = self._check_convergence
        self.run_checks = RunChecks.find(self, num_warmup, batched) if checks else None
        if self.run_checks is not None:
            self.run_checks.scales = self.hierarchical_scales
        if settings.num_warmup > 0:  # constants, also under jit
            self._core = self._core._replace(rows=schedule(settings.num_warmup))
        mass = starting_mass(self._initial_mass, self._layout, jnp.zeros(()).dtype)
        logdensity = self._logdensity_fn(model_args, model_kwargs)
        inner_logdensity = self._inner_logdensity(model_args, model_kwargs)
        draw, c = self._draw(model_args, model_kwargs), self._core

        def init_one(key, params):
            return init_state(c, key, params, logdensity, inner_logdensity, draw, mass)

        self._batched = batched
        state = jit(jax.vmap(init_one) if batched else init_one)(rng_key, init_params)
        _check_start(state.potential_energy, batched, init_params is not None)
        # The draws' shapes, deterministic sites included, settled now rather than after the run.
        first = jax.tree.map(lambda x: x[0], state.z) if batched else state.z
        jax.eval_shape(self.postprocess_fn(model_args, model_kwargs), first)
        self._sample_fn = self.sample
        return self._with_buffer(state, model_args, model_kwargs)

    def _on_draw(self, model_args, model_kwargs):
        """The post-run checks' ``trace`` of each draw (module docstring), or ``None``."""
        checks = self.run_checks
        if checks is None:
            return None
        latent = self._latent(model_args, model_kwargs)
        return lambda i, z, fields, kept: checks.trace(i, latent, z, fields, kept)

    def _latent(self, model_args, model_kwargs):
        """The constrained latent values of draws ``z`` (chains on the leading axis)."""
        return latent_values(self.postprocess_fn(model_args, model_kwargs), self._layout.sites)

    def _with_buffer(self, state, model_args, model_kwargs):
        """``state`` with the post-run checks' buffer of kept draws (none without checks)."""
        checks = self.run_checks
        if checks is None:
            return state
        draw = (state.z, {"diverging": state.diverging, "accept_prob": state.accept_prob,
                          "energy": state.energy})  # fmt: skip
        if not self._batched:  # a chain axis of one, as sample_one steps it
            draw = jax.tree.map(lambda x: jnp.asarray(x)[None], draw)
        kept = checks.buffer(self._latent(model_args, model_kwargs), *draw)
        return state._replace(kept=kept if self._batched else jax.tree.map(lambda x: x[0], kept))

    @property
    def chain_adaptations(self) -> list:
        """``(step_size, inverse mass diagonal, flattened)`` of each chain this kernel warmed
        up alone (sequential chains), in order."""
        return list(self._chain_adaptations)

    def sample(self, state, model_args, model_kwargs):
        logdensity = self._inner_logdensity(model_args, model_kwargs or {})
        on_draw = self._on_draw(model_args, model_kwargs)
        if self._batched:
            return sample_batch(self._core, state, logdensity, on_draw)
        record = functools.partial(record_chain, self._chain_adaptations, self._reported)
        return sample_one(self._core, state, logdensity, record, on_draw)

    @property
    def default_fields(self):
        return ("z", "diverging")

    def get_diagnostics_str(self, state):
        return (
            f"{int(state.num_steps)} gradients, step size {float(state.step_size):.2e}. "
            f"acc. prob={float(state.mean_accept_prob):.2f}"
        )

    def postprocess_fn(self, model_args, model_kwargs):
        if self._potential_fn is not None:
            return lambda z: z
        return postprocess_fn(self._model, self._layout, model_args, model_kwargs or {})

    @property
    def model(self):
        """The model, its manifold sites shown to ``arviz.from_numpyro`` through a view (same
        log-density and draws; the comment above ``_ManifoldSupport`` in
        :mod:`liesample.interop.numpyro_sites`); ``None`` with ``potential_fn``."""
        return None if self._model is None else viewed_model(self._model)

    @property
    def spaces(self) -> dict:
        """Site name → the liesample space it is moved on (after ``init``)."""
        if self._layout is None:
            raise RuntimeError("the kernel is not initialised: run MCMC first")
        return self._layout.space
