"""What every liesample sampler promises: one ``Info`` contract, one sampler object, one help().

**The Info contract.** The ``info`` that ``step(rng_key, state) -> (state, info)`` returns is a
NamedTuple with at least these scalar fields (per chain), in these meanings:

``is_divergent`` (bool)
    The step went wrong: its proposed state, or the energy there, was not finite (NaN/inf).
    The step was rejected (the chain kept its previous state). Magnetic HMC also flags a
    trajectory whose energy error exceeds its ``divergence_threshold``.
``acceptance_rate`` (float in [0, 1])
    The probability with which the step's proposal was accepted. **Rule for unadjusted
    samplers** (no Metropolis test): ``1.0`` for every step taken and ``0.0`` for a step
    rejected because it diverged, so the field is present for every sampler and a chain that
    only diverges reads as stuck.
``energy`` (float)
    The energy of the chain's state after the step: ``h`` on an orbit, ``H = −log π + ½pᵀM⁻¹p``
    on ``T*Rⁿ`` (magnetic HMC: of the proposal, as in BlackJAX).

Samplers add their own fields after these (``casimir_error``, ``is_accepted``, …); the
reduction of a field over the ``thinning`` steps of one stored draw is in
:data:`REDUCE_OVER_THINNING` (``any`` for divergences, mean for acceptance, max for the Casimir
drift, the last step otherwise) and ArviZ's ``sample_stats`` names in
:data:`SAMPLE_STATS_NAMES`. :func:`check_info` verifies a sampler against the contract.

**The sampler object.** ``as_top_level_api`` returns a :class:`Sampler`: BlackJAX's
``SamplingAlgorithm`` (``init``, ``step``; unpacks and duck-types as one) with three optional
hooks the runner uses: ``settings`` (recorded in the ``DataTree`` attributes),
``check_positions`` (checks every start in one vectorised call) and ``adapt`` (warm-up tuning).

**help().** :func:`sampling_api` builds the module-level ``liesample.<sampler>`` object, a
``blackjax.GenerateSamplingAPI`` whose ``help()`` is the top-level docstring.

**Precision.** Samplers run in the precision of their inputs: JAX's default is float32; call
``jax.config.update("jax_enable_x64", True)`` at start-up for float64 (what every test and
benchmark here uses). :func:`liesample.integrators.stability.check_precision` states when float32 is not
enough and warns once.
"""

from __future__ import annotations

import functools
import inspect
from typing import NamedTuple, Protocol, runtime_checkable

import blackjax
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "CONTRACT_FIELDS",
    "REDUCE_OVER_THINNING",
    "SAMPLE_STATS_NAMES",
    "Sampler",
    "SamplerInfo",
    "check_info",
    "first_bad_chain",
    "sampling_api",
    "setting",
]

CONTRACT_FIELDS = ("is_divergent", "acceptance_rate", "energy")
"""The fields every sampler's ``info`` has (module docstring)."""


@runtime_checkable
class SamplerInfo(Protocol):
    """The Info contract as a protocol (the module docstring gives the meanings)."""

    is_divergent: jax.Array
    acceptance_rate: jax.Array
    energy: jax.Array


def _mean(values):
    return jnp.mean(values.astype(jnp.result_type(float)), axis=0)


def _last(values):
    return values[-1]


REDUCE_OVER_THINNING = {
    "is_divergent": functools.partial(jnp.any, axis=0),
    "acceptance_rate": _mean,
    "casimir_error": functools.partial(jnp.max, axis=0),
}
"""How a per-step field is summarised over the steps one thinned draw spans (default: last)."""


def reduce_over_thinning(name: str):
    """The reduction of info field ``name`` over a thinning window (leading axis: steps)."""
    return REDUCE_OVER_THINNING.get(name, _last)


SAMPLE_STATS_NAMES = {
    "is_divergent": "diverging",
    "acceptance_rate": "acceptance_rate",
    "energy": "energy",
    "casimir_error": "casimir_error",
}
"""Info field -> ArviZ ``sample_stats`` name (other fields keep their own names)."""


def check_info(info) -> None:
    """Raise ``TypeError`` unless ``info`` (an instance or a NamedTuple class) has the contract's
    fields."""
    fields = getattr(info, "_fields", None)
    if fields is None:
        raise TypeError(f"info must be a NamedTuple, got {type(info).__name__}")
    missing = [name for name in CONTRACT_FIELDS if name not in fields]
    if missing:
        raise TypeError(
            f"{getattr(info, '__name__', type(info).__name__)} lacks the Info contract's "
            f"fields {missing} (liesample.samplers.contract)"
        )


class Sampler(blackjax.base.SamplingAlgorithm):
    """``SamplingAlgorithm(init, step)`` plus the runner's hooks (all optional).

    Attributes
    ----------
    settings : dict
        What the sampler was built with (name, step size, how it was chosen, …), recorded in
        the attributes of the ``DataTree`` that :func:`liesample.sample` returns.
    check_positions : callable or None
        ``positions (chains, ...) -> None``: every start checked in one vectorised call, raising
        an error that names the first bad chain (``initial_positions[c]: …``).
    adapt : callable or None
        ``(rng_key, chain_keys, states, initial_positions, num_warmup) -> (sampler, states)``:
        warm-up tuning; ``states`` is ``None`` when the runner should run the plain warm-up
        with the returned sampler.
    """

    def __new__(cls, init, step, *, settings=None, check_positions=None, adapt=None):
        self = super().__new__(cls, init, step)
        self.settings = {} if settings is None else settings
        self.check_positions = check_positions
        self.adapt = adapt
        return self


def setting(value):
    """A scalar parameter as a plain number for :attr:`Sampler.settings` (``None`` if traced)."""
    try:
        return np.asarray(value).item()
    except (jax.errors.TracerArrayConversionError, ValueError, TypeError):
        return None


def first_bad_chain(ok) -> int | None:
    """Index of the first ``False`` in a boolean per-chain array, or ``None``."""
    bad = np.flatnonzero(~np.asarray(ok, dtype=bool))
    return int(bad[0]) if bad.size else None


_PRECISION_NOTE = """
Notes
-----
Precision: the sampler computes in the dtype of its inputs. JAX defaults to float32; for
float64 call ``jax.config.update("jax_enable_x64", True)`` before creating arrays.

Info contract (:mod:`liesample.samplers.contract`): ``info.is_divergent``,
``info.acceptance_rate`` and ``info.energy``, plus the sampler's own fields.

Low-level pieces: ``{name}.init``, ``{name}.build_kernel`` (BlackJAX-shaped).
"""


def sampling_api(as_top_level_api, init, build_kernel, name: str, module: str):
    """``blackjax.GenerateSamplingAPI(as_top_level_api, init, build_kernel)`` whose ``help()``
    and ``__doc__`` are ``as_top_level_api``'s docstring (plus the precision rule) and whose
    call signature is that of ``as_top_level_api``."""
    doc = inspect.cleandoc(as_top_level_api.__doc__ or "") + "\n" + _PRECISION_NOTE.format(name=name)

    @functools.wraps(as_top_level_api)
    def __call__(self, *args, **kwargs):
        return self.differentiable(*args, **kwargs)

    __call__.__doc__ = doc
    cls = type(
        name,
        (blackjax.GenerateSamplingAPI,),
        {
            "__doc__": doc,
            "__module__": module,
            "__qualname__": name,
            "__call__": __call__,
            # help() shows how the sampler is called, not the dataclass fields.
            "__signature__": inspect.signature(as_top_level_api),
        },
    )
    return cls(as_top_level_api, init, build_kernel)


class PositionCheck(NamedTuple):
    """Per-chain results of a vectorised start check (used by :func:`raise_first_bad`)."""

    ok: np.ndarray
    message: str


def raise_first_bad(checks, positions, recheck=None, exception=ValueError):
    """Raise for the first chain failing any of ``checks`` (``PositionCheck``s, in order).

    ``recheck(position, name)`` (e.g. ``system.check_position``) is called on that chain first
    so that the error is the system's own message; otherwise ``exception(message)``.
    """
    for check in checks:
        chain = first_bad_chain(check.ok)
        if chain is None:
            continue
        name = f"initial_positions[{chain}]"
        if recheck is not None:
            recheck(positions[chain], name)
        raise exception(f"{name}: {check.message}")
