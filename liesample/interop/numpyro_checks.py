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
They run by themselves at the end of ``MCMC.run`` (``GeometricHMC(model)``'s default,
``check_convergence=True``); with ``check_convergence=False`` call :func:`check_mcmc` on the
finished run.

**The mechanism and its limits.** NumPyro's ``MCMCKernel`` interface tells a kernel
``num_warmup`` (an argument of ``init``) but not how many draws follow, and calls nothing on it
once the loop ends. So ``init`` looks, on the call stack, for the ``numpyro.infer.MCMC`` whose
``sampler`` is this kernel (:func:`calling_mcmc`) and reads its public ``num_samples``,
``num_chains``, ``thinning`` and ``chain_method``. The kernel's state then carries a buffer of
the draws MCMC keeps (their latent values, ``diverging``, ``accept_prob`` and ``energy``;
:meth:`RunChecks.buffer`): each transition after the warm-up writes its draw there when MCMC
keeps it, and after the run's last draw the buffer goes to the host in one
``jax.debug.callback``; once ``num_chains`` chains have arrived, the checks run and the copies
are dropped. So:

- it works for ``chain_method`` ``"sequential"``, ``"vectorized"`` and ``"parallel"``, for
  ``mcmc.warmup`` followed by ``mcmc.run`` and for a continued run from ``post_warmup_state``
  (each run of ``num_samples`` draws is checked); the chains are numbered in the order their
  draws reach the host (with ``"parallel"``, not necessarily MCMC's);
- with a callable ``chain_method``, or a driver other than ``numpyro.infer.MCMC``, nothing is
  found and nothing is checked: call :func:`check_mcmc` on the finished ``MCMC``;
- the device holds a second copy of the kept draws during the run (``check_convergence=False``
  keeps none); a sequential run interrupted part way leaves the chains it finished, which the
  next run's checks would count: build a new kernel after an interruption;
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
SILENCE = "GeometricHMC(..., check_convergence=False) turns these checks off"


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


class RunChecks:
    """The host side of the checks of one ``MCMC`` set-up (module docstring): ``trace`` is
    called in the kernel's traced transition, ``receive`` on the host with a run's kept draws;
    the checks run when ``num_chains`` chains have arrived."""

    def __init__(self, num_warmup: int, num_samples: int, num_chains: int, thinning: int):
        self.settings = (int(num_warmup), int(num_samples), int(num_chains), int(thinning))
        # the model's hierarchical scales, for funnel_warnings (the kernel sets them)
        self.scales: dict[str, tuple[str, ...]] = {}
        # each chain's kept (latent values, fields), as they arrive
        self._chains: list[tuple[dict, dict]] = []

    @classmethod
    def find(cls, kernel, num_warmup, batched) -> RunChecks | None:
        """The checks for the ``MCMC`` calling ``kernel.init`` (``batched``: with every chain
        at once), or ``None`` when there is none (or its ``chain_method`` is a callable).
        ``kernel.run_checks`` is kept when its settings are the same, as sequential chains
        call ``init`` once each; what it holds is dropped when all chains start at once (it can
        only be left from an interrupted run)."""
        mcmc = calling_mcmc(kernel)
        if mcmc is None or mcmc.chain_method not in CHAIN_METHODS:
            return None
        settings = (int(num_warmup), mcmc.num_samples, mcmc.num_chains, mcmc.thinning)
        current = getattr(kernel, "run_checks", None)
        if not isinstance(current, RunChecks) or current.settings != settings:
            return cls(*settings)
        if batched:
            current._chains = []
        return current

    @property
    def num_kept(self) -> int:
        """The draws of a run MCMC keeps per chain (``num_samples // thinning``)."""
        _, num_samples, _, thinning = self.settings
        return num_samples // thinning

    def buffer(self, latent_fn, z, fields: dict[str, Any]):
        """The zero buffer of one run's kept draws, chains on the leading axis of ``z`` and of
        ``fields``' arrays: ``(latent values, fields)``, each ``(chains, num_kept, …)``."""
        values = jax.eval_shape(latent_fn, z)
        zeros = lambda x: jnp.zeros((x.shape[0], self.num_kept, *x.shape[1:]), x.dtype)
        return jax.tree.map(zeros, (values, fields))

    def trace(self, i, latent_fn, z, fields: dict[str, Any], kept):
        """In the transition of draw ``i`` (chains on the leading axis): after the warm-up,
        write ``latent_fn(z)`` (the constrained latent values) and ``fields`` into ``kept``
        (:meth:`buffer`) where MCMC keeps the draw, and send the whole buffer to
        :meth:`receive` after the run's last draw, one host round trip per run. Returns the
        buffer."""
        num_warmup, num_samples, _, thinning = self.settings
        if self.num_kept == 0:
            return kept
        # a continued run (post_warmup_state) goes on counting: the run's own index
        j = jnp.mod(i - num_warmup, num_samples)
        # MCMC keeps the last draw of each group of `thinning` after the first `offset` draws
        offset = num_samples % thinning
        keep = (i >= num_warmup) & (j >= offset) & (jnp.mod(j - offset, thinning) == thinning - 1)
        slot = jnp.clip((j - offset) // thinning, 0, self.num_kept - 1)

        def write(kept):
            new = (latent_fn(z), fields)
            put = lambda buf, x: jax.lax.dynamic_update_index_in_dim(buf, x.astype(buf.dtype),
                                                                     slot, 1)  # fmt: skip
            return jax.tree.map(put, kept, new)

        kept = jax.lax.cond(keep, write, lambda kept: kept, kept)
        last = (i >= num_warmup) & (j == num_samples - 1)
        jax.lax.cond(last, lambda: jax.debug.callback(self.receive, *kept), lambda: None)
        return kept

    def receive(self, values, fields):
        """The kept draws of one run of every chain in the batch (``(chains, draws, …)``);
        runs the checks once ``num_chains`` chains have arrived."""
        values = {k: np.asarray(v) for k, v in values.items()}
        fields = {k: np.asarray(v) for k, v in fields.items()}
        for c in range(len(next(iter(fields.values())))):
            self._chains.append(({k: v[c] for k, v in values.items()},
                                 {k: v[c] for k, v in fields.items()}))  # fmt: skip
        num_chains = self.settings[2]
        if len(self._chains) >= num_chains:
            complete, self._chains = self._chains[:num_chains], []
            stack = lambda part: {k: np.stack([chain[part][k] for chain in complete])
                                  for k in complete[0][part]}  # fmt: skip
            check_draws(stack(0), stack(1), self.scales)


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
