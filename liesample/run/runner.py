"""Run many chains of a BlackJAX-style sampler, vmapped, in chunks with a progress bar.

Draw ``d`` of chain ``c`` uses the key ``fold_in(key_c, step)`` (a sampler that draws its noise
in blocks, as the orbit samplers do, ``fold_in(key_c, block)``:
:mod:`liesample.integrators.chain_loop`),
so the draws do not depend on the chunk size and a run can be split or resumed without changing
them.

The run is in three parts: this module's chunked loop (:func:`sample_chains`, :func:`sample`),
the run file (:mod:`liesample.run.store`, with the run's fingerprint in
:mod:`liesample.run.provenance` and the one-writer lock in :mod:`liesample.run.lock`) and the
checks of a finished run (:mod:`liesample.run.checks`); the arguments are checked by
:mod:`liesample.run.arguments` before any compilation: the algorithm, the key, every option's
range, the starts' chain axis, and whether the steps fit the chains' step counter and the kept
draws the host's and the device's memory (a run that cannot fit is refused, not started).

- **Devices.** ``devices=`` splits the chain axis over several devices with JAX's own sharding
  (:mod:`liesample.run.sharding`), ``lattice_sharding=`` the sites of one spin or gauge
  lattice; the draws are those of the unsharded run.
- **Pytree positions.** ``initial_positions`` may be a pytree (a dict or tuple of arrays, e.g.
  ``{"mu": (chains, 3), "log_kappa": (chains,)}`` for the geometric samplers) whose leaves share
  the leading chain axis; the draws are then a pytree of arrays ``(chains, draws, *event)``.
  A list is read as one array, as before.
- **Long runs lose nothing.** ``output=`` writes every chunk of draws, and the chain states after
  it, to a NetCDF-4 file that is an ArviZ ``DataTree`` (:mod:`liesample.run.store`) as soon as
  the chunk is done; ``resume=True`` continues a run from the last chunk saved there, after an
  interruption or to extend it to more draws, and returns the same draws as an uninterrupted run
  (bitwise). The file records what made the run and a checksum of every chunk: a resume with
  another sampler or setting, or from an edited file, is refused; one run at a time writes it.
  Chains over several processes: process 0 writes the file, every process reads it to resume.
- **Observables.** ``observables=`` evaluates functions of the position at every kept draw
  inside the compiled loop (magnetisation, correlation functions, spectra) and stores their
  values per draw; with ``keep_positions=False`` the full states are not stored (large lattices,
  Zeitlin's vorticity matrices). They are saved to ``output=``, restored on ``resume=`` and are
  posterior variables of :func:`sample`'s tree. The draws do not change.
- **Compilation.** The warm-up and the chunks are compiled once per sampler, chunk length and
  chain shapes through ``jax.jit``'s own cache: running the same sampler object again (a
  resumed run, more draws) reuses the executables.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from liesample.foundation.types import PRNGKey, PyTree
from liesample.run import arguments
from liesample.run.checks import (
    DEFAULT_MIN_ACCEPTANCE_RATE,
    MAX_ENERGY_RHAT,
    NonFiniteStateError,
    split_rhat,
)
from liesample.run.loop import ChainsResult, RunOptions, TreeSpec, run_attrs, run_chains
from liesample.run.store import load_chains, saved_num_warmup

if TYPE_CHECKING:
    import os

    import jax
    import xarray as xr
    from blackjax.base import SamplingAlgorithm
    from jax.sharding import NamedSharding
    from jax.typing import ArrayLike

__all__ = [
    "DEFAULT_MIN_ACCEPTANCE_RATE",
    "MAX_ENERGY_RHAT",
    "ChainsResult",
    "NonFiniteStateError",
    "load_chains",
    "sample",
    "sample_chains",
    "split_rhat",
]


_OPTIONS = {f.name for f in dataclasses.fields(RunOptions)} - {"progress_bar"}


def _progress_bar(progress_bar, progress, stacklevel=3) -> bool:
    """``progress_bar``, or the deprecated ``progress`` when it is given (with a warning)."""
    if progress is None:
        return progress_bar
    warnings.warn(
        "progress= is deprecated and will be removed in the next release: pass progress_bar= "
        "(the name BlackJAX and NumPyro use)",
        DeprecationWarning,
        stacklevel=stacklevel,
    )
    return progress


def sample_chains(
    algorithm: SamplingAlgorithm,
    rng_key: PRNGKey,
    initial_positions: PyTree,
    num_draws: int,
    *,
    num_warmup: int = 0,
    thinning: int = 1,
    progress_bar: bool = True,
    chunk_draws: int | None = None,
    on_nonfinite: str = "warn",
    devices: str | int | Sequence[jax.Device] | NamedSharding | None = None,
    lattice_sharding: int | Mapping[int, int] | None = None,
    output: str | os.PathLike | None = None,
    resume: bool = False,
    adapt: bool | None = None,
    min_acceptance_rate: float = DEFAULT_MIN_ACCEPTANCE_RATE,
    observables: Callable[[Any], PyTree] | Mapping[str, Callable[[Any], PyTree]] | None = None,
    keep_positions: bool = True,
    callback: Callable[[int], object] | None = None,
    log_likelihood: Mapping[str, Callable[[Any], ArrayLike]] | None = None,
    progress: bool | None = None,
) -> ChainsResult:
    """Run ``len(initial_positions)`` chains of ``algorithm`` in parallel (``jax.vmap``).

    Parameters
    ----------
    algorithm : blackjax.base.SamplingAlgorithm
        ``init(position)`` and ``step(rng_key, state) -> (state, info)``; ``state.position``
        is recorded, and the fields of ``info`` that are one number per step (NUTS' nested
        states and momentum are dropped). liesample's samplers
        (:class:`liesample.samplers.contract.Sampler`) also declare checks of the starts,
        settings, step-size tuning and noise blocks; any other algorithm gets the defaults.
    rng_key : jax.random.key or jax.random.PRNGKey
        One key, split over the chains here (a batch of keys, or an int seed, is refused).
    initial_positions : array ``(chains, *event_shape)``, or a pytree of such arrays
        A pytree (dict, tuple, named tuple; e.g. the positions of ``liesample.geometric_hmc``
        on a product space) gives draws with the same structure; every leaf has the chain axis
        first, with the same number of chains. A (nested) list is read as one array.
    num_draws : int
        Draws kept per chain, each ``thinning`` steps apart, after ``num_warmup`` steps.
    num_warmup : int
        Steps run and discarded before the first draw; the adaptation happens there. Default
        ``0`` here: this loop runs exactly the steps asked for. :func:`sample` means the same
        by ``num_warmup`` but defaults to a warm-up as long as the run and warns at ``0``.
    adapt : None, True or False
        Warm-up adaptation of what the sampler declares (:func:`liesample.tuning.warmup.warm_up`):
        the step size of an orbit sampler; the step size, mass and trajectory length of
        ``geometric_hmc`` / ``geometric_langevin``, all chains together (a given mass or
        ``num_integration_steps`` is kept). ``None`` (default): adapt a sampler built
        without ``step_size`` when ``num_warmup > 0``; ``True``: adapt even a given step size
        (from it); ``False``: never. A step size left unset and not adapted is the sampler's
        own choice for the run's starts (:func:`liesample.tuning.warmup.choose_from_starts`;
        the T*G samplers have none and refuse).
    progress_bar : bool
        Show a progress bar (tqdm) from the start of the run: its phase (checking the starts,
        warm-up, compiling, sampling), then the draws and their rate (on a resumed run from the
        draws already saved). ``progress=`` is its deprecated former name.
    chunk_draws : int, optional
        Draws per compiled chunk (default: about 20 chunks); also the unit of saving.
    on_nonfinite : {"warn", "raise"}
        What to do if any step diverged (``info.is_divergent``: a non-finite state or energy):
        a ``RuntimeWarning`` naming the chains, or :class:`NonFiniteStateError`.
    min_acceptance_rate : float
        In ``[0, 1)``: chains whose mean ``acceptance_rate`` is below this are reported as
        stuck; 0 disables the check. The other post-run checks: :mod:`liesample.run.checks`;
        the convergence checks of every variable run in :func:`sample` only (call
        :func:`liesample.analysis.convergence.convergence_warnings` on this loop's draws).
    devices : None, "all", int, sequence of jax devices, or NamedSharding
        Split the chains over these devices (:func:`liesample.run.sharding.chain_sharding`); the
        number of chains must be a multiple of the number of devices. ``None``: one device.
        With ``lattice_sharding``: the number of devices the chains are split over (an int).
    lattice_sharding : None, int or dict of int to int
        Split one lattice over several devices (:func:`liesample.run.sharding.run_sharding`):
        ``n`` splits lattice axis 0 over ``n`` devices, ``{axis: n, …}`` each given lattice
        axis (of the lattice, not of the position: a gauge field's direction axis does not
        count) over its ``n``; every extent must divide by its count. For the spin and gauge
        lattice samplers only; the draws are those of the unsharded run. The mesh is
        ``devices`` × the counts, on the first devices JAX lists.
    output : str or path, optional
        NetCDF-4 file written chunk by chunk: the ArviZ ``DataTree`` of :func:`sample` (read by
        :func:`load_chains`, verified) plus what a resume needs (:mod:`liesample.run.store`).
        One run writes a path at a time (a second is refused at once, naming the holder);
        refused before compiling if its directory is missing, or if it exists and ``resume``
        is False. Chains over several processes (``jax.distributed``): process 0 writes it
        alone, the same file as one process's (:mod:`liesample.run.sharding`).
    resume : bool
        Continue the run saved in ``output`` (bitwise the draws of one uninterrupted run; a
        larger ``num_draws`` extends it; no file yet: start afresh). What made it is checked
        (:mod:`liesample.run.provenance`: sampler, settings, key, starts, …; each differing
        field named with both values), and every saved chunk against its checksum. Over several
        processes every process reads the file: it must be on a file system they all see.
    callback : callable, optional
        ``callback(draws_done)`` after each chunk (saved first when ``output`` is given): to
        report progress elsewhere, or stop a run by raising (what was saved stays resumable).
        Over several processes it runs on each; if it raises on one, every process stops.
    log_likelihood : dict of str to callable, optional
        ``{observed variable: function of one chain's position}`` giving each observation's
        log-likelihood, recorded at every draw like ``observables``; :func:`sample` puts them
        in ArviZ's ``log_likelihood`` group, so ``arviz_stats.loo`` and ``compare`` work.
    observables : callable or dict of str to callable, optional
        Functions of one chain's position, evaluated at every kept draw inside the compiled
        loop. A callable may return an array or a pytree of arrays; a dict ``{name: function}``
        gives a dict of their values, stacked as ``(chains, draws, *shape)``. Saved and
        resumed with the draws, which do not depend on them.
    keep_positions : bool
        ``False`` stores only the observables (and info), not the positions (``positions`` is
        then ``None``): a run's memory is then that of the observables.

    Examples
    --------
    The magnetisation and energy of a spin chain at every draw, no states kept (two chains of
    10 draws show the call; a real run keeps thousands):

    >>> system = liesample.systems.heisenberg((4,))
    >>> starts = jnp.stack([system.default_position, -system.default_position])
    >>> result = liesample.sample_chains(
    ...     liesample.heisenberg_heat_bath(system, beta=1.0), jax.random.key(0), starts, 10,
    ...     observables={"m": lambda s: s.reshape(-1, 3).mean(0), "h": system.hamiltonian},
    ...     keep_positions=False, progress_bar=False,
    ... )
    >>> result.observables["m"].shape, result.observables["h"].shape, result.positions
    ((2, 10, 3), (2, 10), None)
    """
    options = {name: v for name, v in locals().items() if name in _OPTIONS}  # the keywords
    options = RunOptions(**options, progress_bar=_progress_bar(progress_bar, progress))
    spec = TreeSpec()
    return run_chains(algorithm, rng_key, initial_positions, num_draws, options, spec, False)[0]


def sample(
    algorithm: SamplingAlgorithm,
    rng_key: PRNGKey,
    initial_positions: PyTree,
    num_draws: int,
    *,
    num_warmup: int | None = None,
    exact_starts: bool = False,
    var_name: str | None = None,
    event_dims: Sequence[str] | Mapping[str, Sequence[str]] | None = None,
    coords: Mapping[str, Sequence[Any]] | None = None,
    attrs: Mapping[str, Any] | None = None,
    **run_options: Any,
) -> xr.DataTree:
    """Run chains with :func:`sample_chains` and return an ArviZ ``DataTree``.

    The tree has ``posterior/<var_name>`` with dims ``(chain, draw, *event_dims)`` and
    ``sample_stats`` under ArviZ's names (``diverging``, ``acceptance_rate``, ``energy`` where
    it is HMC's total energy, ``hamiltonian`` where it is ``h`` of a state without a momentum
    (:func:`liesample.samplers.contract.energy_name`), and the sampler's own fields such as
    ``casimir_error``); its attributes record ArviZ's
    ``sampling_time``, ``inference_library`` and its version, the number of steps, the
    sampler's settings (``sampler``, ``step_size`` and how it was chosen, ``stability``, …),
    whether the warm-up adapted, and ``attrs``.

    Parameters
    ----------
    algorithm, rng_key, initial_positions, num_draws
        As for :func:`sample_chains`.
    num_warmup : int, optional
        Steps run and discarded before the first draw (the sampler adapts there), as in
        :func:`sample_chains`; only the default differs: as many steps as the draws span
        (``num_draws * thinning``; on a resume, the saved run's): chains started from
        arbitrary points forget their starts before anything is kept, and a sampler built
        without a step size tunes it there. ``0`` keeps every step from the starts and warns,
        unless ``exact_starts=True``.
    exact_starts : bool
        The starts are already draws from the target (no warning at ``num_warmup=0``).
    var_name, event_dims
        Name and event dims of single-array positions. Default: the sampler's declaration
        (``R`` with dims ``(row, col)`` for ``SO(n)``, ``U`` for ``SU(n)``), else ``mu`` with
        dims named from the event's rank (``component``; ``row, col``). Pytree positions give
        one variable per leaf, named from its key path (``mu``, ``log_kappa``; tuple entries
        ``x0``, ``x1``…; nested keys joined with ``.``), with dims ``<name>_dim_k``
        (``event_dims`` may map a leaf's name to other dims); a complex leaf ``U`` is split into
        ``U.real`` and ``U.imag`` (:func:`liesample.analysis.diagnostics.to_datatree`). Names,
        dims and ``coords`` are checked against the starts before any sampling.
    coords, attrs
        Coordinates by dim name, and extra attributes for the tree.
    run_options
        The other keywords of :func:`sample_chains`: ``thinning``, ``progress_bar``,
        ``chunk_draws``, ``on_nonfinite``, ``devices``, ``lattice_sharding``, ``output``,
        ``resume``, ``adapt``, ``min_acceptance_rate``, ``observables``, ``keep_positions``,
        ``callback``, ``log_likelihood`` (the tree's ``log_likelihood`` group, for
        ``az.loo``). With ``output=``, the file holds this tree as it grows
        (:func:`load_chains`).

    Notes
    -----
    ``observables=`` adds its values to ``posterior`` (a dict's keys name them, a single
    array is ``observable``; dims ``<name>_dim_k``), so that ``az.summary``, ESS and R-hat act
    on them; with ``keep_positions=False`` the posterior holds only the observables. ESS and
    R-hat are those of the ambient coordinates (vector components, matrix entries).

    Examples
    --------
    Without ``step_size`` the adjusted sampler tunes it by dual averaging in the warm-up (as
    long as the draws span by default), then samples. Two chains of 10 draws show the call and
    the tree (the run warns that they are too few to trust):

    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> starts = jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]])
    >>> tree = liesample.sample(liesample.adjusted_lie_poisson(system, beta=3.0),
    ...                         jax.random.key(0), starts, 10, progress_bar=False)
    >>> tree.posterior["mu"].dims, tree.posterior["mu"].shape
    (('chain', 'draw', 'component'), (2, 10, 3))
    >>> int(tree.attrs["num_warmup"]), bool(tree.attrs["adapted"])  # the step size was tuned
    (10, True)
    """
    options = _sample_options(run_options, num_draws, num_warmup, exact_starts)
    arguments.check_tree_names(var_name, event_dims, coords, attrs)
    spec = TreeSpec(var_name, event_dims, coords, attrs)
    result, spec = run_chains(
        algorithm, rng_key, initial_positions, num_draws, options, spec, convergence=True
    )
    attrs = run_attrs(
        result.settings,
        on_nonfinite=options.on_nonfinite,
        wall_time=result.wall_time,
        num_steps=result.num_steps,
    )
    return spec.build(
        result.positions,
        result.info,
        result.observables,
        result.settings,
        thinning=options.thinning,
        attrs=attrs,
        log_likelihood=result.log_likelihood,
    )


def _sample_options(run_options, num_draws, num_warmup, exact_starts) -> RunOptions:
    """:func:`sample`'s keywords as the :class:`RunOptions` of its run: ``num_warmup`` as long
    as the run unless given (on a resume, the saved run's), a warning at 0 without
    ``exact_starts``."""
    if "progress" in run_options:
        run_options["progress_bar"] = _progress_bar(
            run_options.get("progress_bar", True), run_options.pop("progress"), stacklevel=4
        )
    unknown = sorted(set(run_options) - _OPTIONS - {"progress_bar"})
    if unknown or "num_warmup" in run_options:
        raise TypeError(
            f"sample() got unknown keywords {unknown}; its keywords are those of sample_chains "
            f"({', '.join(f.name for f in dataclasses.fields(RunOptions))}) and exact_starts, "
            "var_name, event_dims, coords, attrs"
        )
    if not isinstance(exact_starts, bool):
        raise TypeError(f"exact_starts must be a bool, got {exact_starts!r}")
    options = RunOptions(**run_options)
    arguments.check_output(options.output, options.resume)  # before reading a saved run
    if num_warmup is None and options.resume and options.output is not None:
        num_warmup = saved_num_warmup(options.output)
    if num_warmup is None:
        arguments.check_run_arguments(num_draws, 0, options.thinning, "warn", None, None)
        num_warmup = int(num_draws) * int(options.thinning)
    elif num_warmup == 0 and not exact_starts:
        warnings.warn(
            "num_warmup=0: every step from initial_positions is kept; unless the starts are "
            "draws from the target (then pass exact_starts=True), the draws are biased towards "
            "them. Leave num_warmup unset for a warm-up as long as the run.",
            UserWarning,
            stacklevel=3,
        )
    return dataclasses.replace(options, num_warmup=num_warmup)
