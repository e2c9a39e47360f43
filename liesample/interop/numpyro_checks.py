"""The post-run checks of :func:`liesample.sample` on a NumPyro ``MCMC`` run of
:class:`liesample.interop.numpyro_kernel.GeometricHMC`.

After ``MCMC(GeometricHMC(model), num_warmup=…, num_samples=…, num_chains=…).run(key)`` the
run is checked as :func:`liesample.sample` checks its own (:func:`liesample.run.checks.check_run`):
divergences and stuck chains (mean acceptance rate below
:data:`liesample.run.checks.DEFAULT_MIN_ACCEPTANCE_RATE`) as ``RuntimeWarning``\\ s, the split
R-hat of the energies, and one ``UserWarning`` with the rank-normalised split R-hat and the bulk
and tail ESS of every element of every latent site
(:func:`liesample.analysis.convergence.convergence_warnings`), on the constrained values
``mcmc.get_samples()`` holds, thinned as MCMC keeps them. A well-mixed run is quiet.
They run by themselves with ``GeometricHMC(model, check_convergence=True)``; by default
(``False``) call :func:`check_mcmc` on the finished run, which costs nothing while the chains
run, whereas the automatic checks send every kept draw to the host (below).

**The mechanism and its limits.** NumPyro's ``MCMCKernel`` interface tells a kernel
``num_warmup`` (an argument of ``init``) but not how many draws follow, and calls nothing on it
once the loop ends. So ``init`` looks, on the call stack, for the ``numpyro.infer.MCMC`` whose
``sampler`` is this kernel (:func:`calling_mcmc`) and reads its public ``num_samples``,
``num_chains``, ``thinning`` and ``chain_method``. Each transition after the warm-up sends the
draw's latent values, ``diverging``, ``accept_prob`` and ``energy`` to the host
(``jax.debug.callback``, with the chain's key before and after the transition, which tells the
chains apart whatever order they run in); once ``num_chains`` chains hold ``num_samples``
draws, the checks run and the copies are dropped. So:

- it works for ``chain_method`` ``"sequential"``, ``"vectorized"`` and ``"parallel"``, for
  ``mcmc.warmup`` followed by ``mcmc.run`` and for a continued run from ``post_warmup_state``
  (each run of ``num_samples`` draws is checked); with ``"parallel"`` the chains are numbered in
  the order their first draws reach the host;
- with a callable ``chain_method``, or a driver other than ``numpyro.infer.MCMC``, nothing is
  found and nothing is checked: call :func:`check_mcmc` on the finished ``MCMC``;
- the host holds a second copy of the kept draws until the check;
- JAX dispatches asynchronously: on an accelerator the warnings come when the computation reaches
  the last draw, which can be after ``MCMC.run`` returns (``jax.effects_barrier()`` waits for it);
- a warning turned into an error (``-W error``) is raised inside the host callback, so the run
  fails with JAX's ``JaxRuntimeError`` holding the message.
"""

from __future__ import annotations

import inspect
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

try:
    from numpyro.infer import MCMC
except ImportError as error:  # an optional integration module
    raise ImportError(
        "liesample.interop.numpyro_checks needs NumPyro: pip install numpyro (or the 'test' "
        "extras of liesample)"
    ) from error

from liesample.analysis.convergence import convergence_warnings
from liesample.run.checks import DEFAULT_MIN_ACCEPTANCE_RATE, check_run

__all__ = ["RunChecks", "calling_mcmc", "check_draws", "check_mcmc", "funnel_warnings"]

CHAIN_METHODS = ("sequential", "vectorized", "parallel")
DIVERGENCE_ADVICE = (
    "Raise target_accept_prob (e.g. GeometricHMC(model, target_accept_prob=0.95)), give a "
    "longer num_warmup, or reparametrise the model (a non-centred hierarchy)."
)
STUCK_ADVICE = (
    "Give a longer num_warmup so the step size adapts, a smaller step_size with "
    "adapt_step_size=False, or init_params near the posterior."
)
SILENCE = "GeometricHMC(..., check_convergence=False) (the default) turns these checks off"


def funnel_warnings(variables: dict[str, np.ndarray], fields: dict[str, np.ndarray],
                    scales: dict[str, tuple[str, ...]]) -> list[str]:  # fmt: skip
    """A message for each hierarchical scale (``scales``: scale site → the sites it is the
    scale of, :func:`liesample.interop.numpyro_sites.hierarchical_scales`) when the run shows
    the funnel: divergent transitions, or the scale's own R-hat or ESS failing
    (:func:`liesample.analysis.convergence.convergence_warnings`). Centred, the chains cannot
    reach the scale's small values (the funnel's neck), so they under-sample them; the fix is
    the non-centred form, ``numpyro.infer.reparam.LocScaleReparam``. Returns the messages."""
    divergent = int(np.sum(fields["diverging"])) if "diverging" in fields else 0
    out = []
    for scale, children in scales.items():
        if scale not in variables:
            continue
        unconverged = convergence_warnings({scale: np.log(np.asarray(variables[scale]))})
        if not divergent and not unconverged:
            continue
        evidence = [f"{divergent} divergent transition(s)"] if divergent else []
        evidence += [m.split(". ", 1)[0] for m in unconverged]  # what failed, not the advice
        config = ", ".join(f"{child!r}: LocScaleReparam(0)" for child in children)
        out.append(
            f"{scale} is the scale of {', '.join(children)} (a centred hierarchy, a funnel): "
            f"the chains cannot reach its small values, where the neck narrows, and "
            f"under-sample them ({'; '.join(evidence)}), so the draws of {scale} and "
            f"{', '.join(children)} are likely wrong. Reparametrise non-centred: "
            f"numpyro.handlers.reparam(model, config={{{config}}}) with "
            "numpyro.infer.reparam.LocScaleReparam"
        )
    return out


def calling_mcmc(kernel) -> MCMC | None:
    """The ``numpyro.infer.MCMC`` on the call stack whose ``sampler`` is ``kernel`` (the one
    whose ``run`` or ``warmup`` is calling ``kernel.init``), or ``None``."""
    frame = inspect.currentframe()
    try:
        while frame is not None:
            candidate = frame.f_locals.get("self")
            if isinstance(candidate, MCMC) and candidate.sampler is kernel:
                return candidate
            frame = frame.f_back
        return None
    finally:
        del frame  # no reference cycle through the frames


def _key_bytes(keys) -> np.ndarray:
    """``(chains, …)`` raw key data, one row of bytes per chain."""
    keys = np.asarray(keys)
    return keys.reshape(len(keys), -1)


class _Chain:
    """One chain's draws on the host: latent values, and the per-draw fields."""

    def __init__(self):
        self.count = 0
        self.values: list[dict[str, np.ndarray]] = []
        self.fields: list[dict[str, np.ndarray]] = []


class RunChecks:
    """The host side of the checks of one ``MCMC`` set-up (module docstring): ``trace`` is
    called in the kernel's traced transition, ``receive`` on the host with each draw after the
    warm-up; the checks run when ``num_chains`` chains hold ``num_samples`` draws."""

    def __init__(self, num_warmup: int, num_samples: int, num_chains: int, thinning: int):
        self.settings = (int(num_warmup), int(num_samples), int(num_chains), int(thinning))
        # the model's hierarchical scales, for funnel_warnings (the kernel sets them)
        self.scales: dict[str, tuple[str, ...]] = {}
        self._chains: list[_Chain] = []
        self._by_key: dict[bytes, _Chain] = {}

    @classmethod
    def find(cls, kernel, num_warmup, batched) -> RunChecks | None:
        """The checks for the ``MCMC`` calling ``kernel.init`` (``batched``: with every chain
        at once), or ``None`` when there is none (or its ``chain_method`` is a callable).
        ``kernel.run_checks`` is kept when its settings are the same, as sequential chains
        call ``init`` once each; what it holds is dropped when it can only be left from an
        interrupted run (a chain part way, or any chain when all chains start at once)."""
        mcmc = calling_mcmc(kernel)
        if mcmc is None or mcmc.chain_method not in CHAIN_METHODS:
            return None
        settings = (int(num_warmup), mcmc.num_samples, mcmc.num_chains, mcmc.thinning)
        current = getattr(kernel, "run_checks", None)
        if not isinstance(current, RunChecks) or current.settings != settings:
            return cls(*settings)
        if batched or current._by_key:
            current._chains, current._by_key = [], {}
        return current

    def trace(self, i, keys_before, keys_after, latent_fn, z, fields: dict[str, Any]):
        """In the transition of draw ``i`` (chains on the leading axis): after the warm-up,
        send ``latent_fn(z)`` (the constrained latent values) and ``fields`` to
        :meth:`receive`."""

        def key_data(keys):
            if jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key):
                return jax.random.key_data(keys)
            return keys

        def send():
            values = latent_fn(z)
            before, after = key_data(keys_before), key_data(keys_after)
            jax.debug.callback(self.receive, before, after, values, fields)

        jax.lax.cond(i >= self.settings[0], send, lambda: None)

    def receive(self, keys_before, keys_after, values, fields):
        """One draw of every chain in the batch; runs the checks when the run is complete."""
        before, after = _key_bytes(keys_before), _key_bytes(keys_after)
        values = {k: np.asarray(v) for k, v in values.items()}  # indexed on the host below
        fields = {k: np.asarray(v) for k, v in fields.items()}
        _, num_samples, num_chains, thinning = self.settings
        # MCMC keeps the last draw of each group of `thinning` after the first `offset` draws
        offset = num_samples % thinning
        for c in range(len(before)):
            chain = self._by_key.pop(before[c].tobytes(), None)
            if chain is None:
                chain = _Chain()
                self._chains.append(chain)
            if chain.count >= offset and (chain.count - offset) % thinning == thinning - 1:
                chain.values.append({k: v[c] for k, v in values.items()})
                chain.fields.append({k: v[c] for k, v in fields.items()})
            chain.count += 1
            if chain.count < num_samples:
                self._by_key[after[c].tobytes()] = chain
        complete = [chain for chain in self._chains if chain.count >= num_samples]
        if len(complete) >= num_chains:
            self._chains, self._by_key = [], {}
            check_draws(
                _stacked([chain.values for chain in complete[:num_chains]]),
                _stacked([chain.fields for chain in complete[:num_chains]]),
                self.scales,
            )


def _stacked(chains) -> dict[str, np.ndarray]:
    """Per-chain lists of per-draw dicts → name → ``(chains, draws, …)``."""
    return {name: np.stack([[d[name] for d in draws] for draws in chains]) for name in chains[0][0]}


def check_draws(variables: dict[str, np.ndarray], fields: dict[str, np.ndarray],
                scales: dict[str, tuple[str, ...]] | None = None) -> list[str]:  # fmt: skip
    """The checks of :func:`liesample.sample` on a finished run: ``variables`` name →
    ``(chains, draws, …)`` (the latent sites), ``fields`` NumPyro's per-draw ``diverging``,
    ``accept_prob`` and ``energy`` ``(chains, draws)`` (any may be missing). Warns as the module
    docstring says; with ``scales`` (the model's hierarchical scales), also
    :func:`funnel_warnings`. Returns the convergence and funnel messages."""
    info = {
        new: np.asarray(fields[old])
        for old, new in (
            ("diverging", "is_divergent"),
            ("accept_prob", "acceptance_rate"),
            ("energy", "energy"),
        )
        if old in fields
    }
    check_run(
        info,
        variables,
        None,
        on_nonfinite="warn",
        min_acceptance_rate=DEFAULT_MIN_ACCEPTANCE_RATE,
        stuck_advice=STUCK_ADVICE,
        divergence_advice=DIVERGENCE_ADVICE,
        convergence=False,  # below, with NumPyro's wording
        stacklevel=3,
    )
    messages = convergence_warnings(variables)
    if messages:
        warnings.warn(
            "GeometricHMC, convergence checks of the MCMC run's draws: "
            + "; ".join(messages)
            + f". ({SILENCE}.)",
            UserWarning,
            stacklevel=3,
        )
    funnels = funnel_warnings(variables, fields, scales or {})
    for message in funnels:
        warnings.warn(f"GeometricHMC: {message}. ({SILENCE}.)", UserWarning, stacklevel=3)
    return messages + funnels


def check_mcmc(mcmc: MCMC) -> list[str]:
    """The checks of a finished ``mcmc`` run (:func:`check_draws` on
    ``mcmc.get_samples(group_by_chain=True)``, latent sites only, and its extra fields): the
    explicit call for a run the kernel could not check itself (module docstring)."""
    samples = mcmc.get_samples(group_by_chain=True)
    spaces = getattr(mcmc.sampler, "spaces", None)
    latent = spaces if isinstance(samples, dict) and spaces else None
    if not isinstance(samples, dict):
        variables = {"z": np.asarray(samples)}
    else:
        variables = {k: np.asarray(v) for k, v in samples.items() if latent is None or k in latent}
    extra = mcmc.get_extra_fields(group_by_chain=True)
    # per-draw arrays only: adapt_state, say, is a tuple of them
    fields = {k: np.asarray(v) for k, v in extra.items()
              if isinstance(v, (np.ndarray, jax.Array)) and v.ndim == 2}  # fmt: skip
    return check_draws(variables, fields, getattr(mcmc.sampler, "hierarchical_scales", None))


def latent_values(postprocess, names):
    """``z (chains, …) ↦`` the constrained values of the latent sites ``names`` (the kernel's
    ``postprocess_fn`` without its deterministic sites), vmapped over chains."""

    def latent(z):
        out = postprocess(z)
        if not isinstance(out, dict):
            return {"z": jnp.asarray(out)}
        return {name: out[name] for name in names if name in out}

    return jax.vmap(latent)
