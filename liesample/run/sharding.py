"""Chains, and one lattice's sites, across devices: JAX's own sharding (``NamedSharding``).

Chains are independent, so the runner splits the leading (chain) axis of the states and of the
per-chain keys over a one-dimensional device mesh and lets ``jax.jit`` partition the vmapped
step (GSPMD): no chain ever talks to another, so there is no communication until the draws are
copied back to the host. Each chain runs the same operations on the same key
``fold_in(key_c, step)`` as in the unsharded run, so the draws agree (bitwise on CPU).

Several processes (``jax.distributed``)
---------------------------------------
Start every process with the same script; right after ``import liesample`` (which starts no XLA
backend, nor does reading ``liesample.sharding``; reading ``liesample.sample`` or a sampler
imports BlackJAX, whose import does), call :func:`initialize_distributed` (a guarded
``jax.distributed.initialize``, which reads a SLURM, Open MPI, Kubernetes or Cloud TPU job
from the environment and selects gloo CPU collectives), before any other JAX call. Then
``jax.devices()`` lists the devices of every process and ``devices="all"`` spreads the chains
over all of them. Every process passes the same ``rng_key`` and ``initial_positions`` (the
whole chain axis); :func:`shard_chains` builds global arrays from them
(``jax.make_array_from_callback``: each process places the shards of its own devices), each
process computes its own chains, and :func:`to_host` gathers every chain's draws to every
process (``multihost_utils.process_allgather``): every process returns the whole tree, the
draws of one process running every chain.

A run file (``output=``) is written by process 0 alone: after each chunk every process gathers
the draws and the chain states, process 0 writes them (it alone takes the file's lock,
:mod:`liesample.run.lock`), and the others write nothing, so the file is, chunk for chunk, the
one a single process running every chain would write. On ``resume=True`` every process reads
the file, checks it and the saved run's fingerprint, and places its own chains' saved states;
the file must therefore be on a file system that every process sees, at a path that names it
on each: a process that finds no file, or another file, where process 0 finds the saved run is
refused on every process, with where to put it (:func:`liesample.run.store.check_same_file`).
After each of these steps, and after the ``callback``, the processes agree
(:mod:`liesample.run.agreement`): an error on one process (process 0 failing to write, a
refused resume, a ``callback`` that raises) is raised on every process there, instead of
leaving the others waiting in the next gather. Every process passes the same ``output=`` and
``resume=`` (else the run is refused on all; a ``callback`` may differ), and
:func:`check_output` refuses ``output=`` for chains over only some of the processes.

One lattice over several devices (``lattice_sharding=``)
-------------------------------------------------------
A spin lattice or a gauge field too large for one device is split along its lattice axes
(:func:`run_sharding`, :class:`LatticeSharding`): ``lattice_sharding=2`` puts half of every
chain's sites (lattice axis 0) on each of two devices, ``{0: 2, 1: 2}`` a quarter on each of
four, and ``devices=2`` beside it splits the chains too (a mesh of chains × lattice axes, on
the first devices JAX lists). The positions and states are placed with a ``NamedSharding``
per leaf, a leaf that holds the lattice split along its lattice axes and any other (a key, an
energy) along the chains only; ``jax.jit`` propagates the split through the step, and XLA's
SPMD partitioner turns the neighbour shifts (``jnp.roll``) and the checkerboard's gathers into
exchanges between the devices: there is no communication of liesample's own. Every site draws
the same random numbers (partitionable Threefry) and runs the same arithmetic whatever the
split, so the draws are those of the unsharded run, bitwise on CPU; a chain's energy, a sum over
its sites, is added in another order and agrees to round-off; so does a step size that a
warm-up adapts on the split lattice (to sums over the sites), and with it the draws. Every
lattice sampler shards:
the spin heat bath and its over-relaxation (:func:`liesample.heisenberg_heat_bath`),
Metropolis, the cluster moves (Swendsen–Wang, Wolff: their cluster search gathers every site's
label, one integer per site, on each device; the spins stay split) and, for
:func:`liesample.systems.wilson_gauge`, the heat bath with over-relaxation and
:func:`liesample.samplers.gauge.hmc.gauge_hmc`. Refused before anything is compiled, each by
name with its fix: a sampler of no lattice, an axis that does not exist or whose extent does
not divide by its count, more devices than JAX sees, and ``devices=`` other than an int (the
chains' devices). The starts are read on one device before they are split, and the kept draws
come back to the host, as for chains.

What is tested
--------------
One process with several (forced host) CPU devices: chains over them, bitwise equal to the
unsharded run; one lattice, the spin heat bath on 2 devices and (slow tests) every spin and
gauge sampler above on 4, over two lattice axes and over chains × a lattice axis, bitwise equal
to the unsharded run, and gauge HMC's window warm-up on 4, equal to round-off. Two processes on the
loopback interface with one CPU device each (the project's test suite), chains over both:
the draws bitwise those of one process; with ``output=``, the file that one process writes
(every chunk's checksum, the saved states, the draws) and no lock or write by process 1; a run
stopped by its ``callback`` after one chunk, resumed by two new processes started as the tasks
of a SLURM job step (:func:`initialize_distributed` without arguments), bitwise one
uninterrupted run's draws and file; a resume refused on both processes where process 1 does not
see the file, and ``output=`` given on process 0 only; a ``callback`` raising on process 1
only, and process 0 failing to write a chunk, each raised on both. Several machines, a file
system shared over a network, GPUs over several processes, a lattice over several processes,
and the window warm-ups across processes are not tested.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import jax
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from liesample.foundation.types import PyTree

__all__ = [
    "CHAIN_AXIS",
    "LatticeLayout",
    "LatticeSharding",
    "chain_sharding",
    "check_output",
    "initialize_distributed",
    "lattice_axis_name",
    "lattice_layout",
    "run_sharding",
    "shard_chains",
    "spans_processes",
    "to_host",
]

CHAIN_AXIS = "chain"
"""Name of the mesh axis over which chains are split."""


def chain_sharding(
    devices: str | int | Sequence[jax.Device] | NamedSharding | None, num_chains: int
) -> NamedSharding | None:
    """The sharding of the chain axis, or ``None`` for an unsharded run.

    Parameters
    ----------
    devices : None, "all", int, sequence of ``jax.Device`` or ``NamedSharding``
        ``None``: run on the default device, unsharded. ``"all"``: every device JAX sees
        (every host's, after :func:`initialize_distributed`). An int ``n``: the first ``n``.
        A ``NamedSharding`` is used as given (its spec must split axis 0 only).
    num_chains : int
        Must be a multiple of the number of devices (each device runs the same number of chains).

    Examples
    --------
    On one device (the doctests' CPU) the chains all stay there; ``None`` is an unsharded run:

    >>> from liesample.sharding import chain_sharding
    >>> chain_sharding(None, 4) is None, tuple(chain_sharding("all", 4).spec)
    (True, ('chain',))
    """
    if devices is None:
        return None
    if isinstance(devices, NamedSharding):
        sharding = devices
    else:
        if isinstance(devices, str):
            if devices != "all":
                raise ValueError(
                    f"devices must be None, 'all', a positive int, a sequence of jax devices or "
                    f"a NamedSharding; got {devices!r}"
                )
            chosen = jax.devices()
        elif isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
            count = operator.index(devices)
            available = jax.devices()
            if not 1 <= count <= len(available):
                raise ValueError(
                    f"devices must be between 1 and the {len(available)} available device(s), "
                    f"got {count}"
                )
            chosen = available[:count]
        else:
            try:
                chosen = list(cast(Sequence[jax.Device], devices))  # else the TypeError below
            except TypeError:
                raise TypeError(
                    f"devices must be None, 'all', a positive int, a sequence of jax devices or "
                    f"a NamedSharding; got {devices!r}"
                ) from None
            if not chosen or not all(isinstance(d, jax.Device) for d in chosen):
                raise TypeError(
                    f"devices must be a non-empty sequence of jax.Device, got {devices!r}"
                )
        mesh = jax.sharding.Mesh(np.asarray(chosen), (CHAIN_AXIS,))
        sharding = NamedSharding(mesh, PartitionSpec(CHAIN_AXIS))
    spec = tuple(sharding.spec)
    if len(spec) > 1 and any(s is not None for s in spec[1:]):
        raise ValueError(f"devices: the sharding must split the chain axis only, got {spec}")
    count = int(np.prod([sharding.mesh.shape[a] for a in _axis_names(spec[0] if spec else None)]))
    if num_chains % count:
        raise ValueError(
            f"the number of chains ({num_chains}) must be a multiple of the number of devices "
            f"({count}) it is split over"
        )
    return sharding


# --------------------------------------------------------------------------- one lattice


def lattice_axis_name(axis: int) -> str:
    """The name of the mesh axis over which lattice axis ``axis`` is split.

    Examples
    --------
    >>> liesample.sharding.lattice_axis_name(1)
    'lattice1'
    """
    return f"lattice{axis}"


@dataclass(frozen=True)
class LatticeLayout:
    """Where a lattice sampler's sites lie in one chain's position: the lattice ``shape`` on the
    event axes ``offset … offset + len(shape) − 1`` (``offset`` 0 for spins ``(*shape, n)``,
    1 for a gauge field ``(d, *shape, …)``); ``system`` names it in messages.

    Examples
    --------
    A gauge field's lattice comes after its direction axis:

    >>> system = liesample.systems.wilson_gauge("SU2", (4, 6))
    >>> layout = liesample.sharding.lattice_layout(liesample.wilson_heat_bath(system, beta=1.0))
    >>> layout.shape, layout.offset
    ((4, 6), 1)
    """

    shape: tuple[int, ...]
    offset: int
    system: str


LATTICE_SAMPLERS = (
    "a spin lattice (liesample.systems.heisenberg or n_vector with heisenberg_heat_bath, "
    "heisenberg_metropolis, heisenberg_cluster or heisenberg_wolff) or a gauge field "
    "(liesample.systems.wilson_gauge with wilson_heat_bath or "
    "liesample.samplers.gauge.hmc.gauge_hmc)"
)


def lattice_layout(sampler) -> LatticeLayout | None:
    """The lattice of ``sampler``'s positions, read from its declared structure (the spin
    samplers' and the gauge heat bath's system, ``gauge_hmc``'s log density); ``None`` for a
    sampler of no lattice.

    Examples
    --------
    >>> from liesample.sharding import lattice_layout
    >>> system = liesample.systems.wilson_gauge("U1", (4, 6))
    >>> lattice_layout(liesample.wilson_heat_bath(system, beta=1.0)).shape
    (4, 6)
    """
    # imported here: reading liesample.sharding must not import BlackJAX (module notes)
    from liesample.samplers.contract import Rebuild
    from liesample.samplers.gauge.hmc import WilsonLogDensity
    from liesample.systems.heisenberg import SpinLatticeSystem
    from liesample.systems.n_vector import NVectorSystem
    from liesample.systems.wilson_gauge import WilsonGauge

    structure = getattr(sampler, "structure", None)
    build = None if structure is None else structure.build
    system = getattr(build, "system", None)
    if system is None and isinstance(build, Rebuild):  # geometric_hmc(density, space, …)
        args = build.static[0]
        if args and isinstance(args[0], WilsonLogDensity):
            system = args[0].system
    if isinstance(system, (SpinLatticeSystem, NVectorSystem)):
        return LatticeLayout(tuple(system.event_shape[:-1]), 0, repr(system))
    if isinstance(system, WilsonGauge):
        return LatticeLayout(tuple(system.shape), 1, repr(system))
    return None


@dataclass(frozen=True)
class LatticeSharding:
    """The chains and a lattice's axes over one device mesh (``lattice_sharding=``): the mesh
    has the axis :data:`CHAIN_AXIS` (the devices the chains are split over, maybe 1) then one
    axis per split lattice axis (:func:`lattice_axis_name`). A leaf of the states whose event
    axes hold the lattice (:class:`LatticeLayout`) is split along those axes too; any other
    leaf (a key, a chain's energy) along the chain axis only, each device of a chain's lattice
    holding a copy.

    Examples
    --------
    Built by :func:`run_sharding`; on one device (the doctests' CPU) every axis has one:

    >>> system = liesample.systems.heisenberg((4, 4), periodic=True)
    >>> sampler = liesample.heisenberg_heat_bath(system, beta=1.0)
    >>> sharding = liesample.sharding.run_sharding(1, {1: 1}, 2, sampler)
    >>> dict(sharding.mesh.shape), tuple(sharding.of(jnp.zeros(2)).spec)
    ({'chain': 1, 'lattice1': 1}, ('chain',))
    """

    mesh: jax.sharding.Mesh
    layout: LatticeLayout
    axes: tuple[int, ...]

    @property
    def chains(self) -> NamedSharding:
        """The sharding of a leaf with no lattice axes."""
        return NamedSharding(self.mesh, PartitionSpec(CHAIN_AXIS))

    @property
    def is_fully_addressable(self) -> bool:
        return self.chains.is_fully_addressable

    @property
    def device_set(self) -> set:
        return set(self.mesh.devices.flat)

    def of(self, leaf) -> NamedSharding:
        """The sharding of ``leaf`` (chains first)."""
        shape, start = tuple(np.shape(leaf)), 1 + self.layout.offset
        if shape[start : start + len(self.layout.shape)] != self.layout.shape:
            return self.chains
        spec: list[str | None] = [CHAIN_AXIS] + [None] * (len(shape) - 1)
        for axis in self.axes:
            spec[start + axis] = lattice_axis_name(axis)
        return NamedSharding(self.mesh, PartitionSpec(*spec))


def run_sharding(devices, lattice_sharding, num_chains: int, sampler):
    """The sharding of a run: :func:`chain_sharding` without ``lattice_sharding``, else the
    :class:`LatticeSharding` of chains × lattice axes, every argument checked before anything
    is compiled.

    Parameters
    ----------
    devices : None or int
        With ``lattice_sharding``: the number of devices the chains are split over (``None``:
        1); the mesh is this many times the lattice's devices, the first devices JAX lists.
    lattice_sharding : None, int or dict of int to int
        ``n``: lattice axis 0 split over ``n`` devices; ``{axis: n, …}``: each lattice axis
        (0 … d−1 of the lattice, whatever axes come before it in a position) over its ``n``.
        Every extent must divide by its count.
    num_chains : int
        A multiple of ``devices``.
    sampler : liesample.samplers.contract.Sampler
        A lattice sampler (:func:`lattice_layout`).

    Examples
    --------
    On one device (the doctests' CPU) a split over one device is the whole lattice:

    >>> from liesample.sharding import run_sharding
    >>> system = liesample.systems.heisenberg((4, 4), periodic=True)
    >>> sampler = liesample.heisenberg_heat_bath(system, beta=1.0)
    >>> tuple(run_sharding(None, {0: 1}, 2, sampler).of(jnp.zeros((2, 4, 4, 3))).spec)
    ('chain', 'lattice0', None, None)
    """
    if lattice_sharding is None:
        return chain_sharding(devices, num_chains)
    counts = _lattice_counts(lattice_sharding)
    layout = lattice_layout(sampler)
    if layout is None:
        settings = getattr(sampler, "settings", None) or {}
        name = settings.get("sampler", type(sampler).__name__)
        raise ValueError(
            f"lattice_sharding={lattice_sharding!r}: {name} samples no lattice; lattice_sharding "
            f"splits the sites of {LATTICE_SAMPLERS}. To spread chains over devices, pass "
            "devices= instead"
        )
    shape = layout.shape
    for axis, count in counts.items():
        if axis >= len(shape):
            raise ValueError(
                f"lattice_sharding={lattice_sharding!r}: lattice axis {axis} does not exist; "
                f"the lattice {shape} of {layout.system} has axes 0 to {len(shape) - 1}"
            )
        if shape[axis] % count:
            divisors = [k for k in range(2, shape[axis] + 1) if shape[axis] % k == 0]
            raise ValueError(
                f"lattice_sharding={lattice_sharding!r}: lattice axis {axis} has {shape[axis]} "
                f"sites, which do not split evenly over {count} devices; give it a count that "
                f"divides {shape[axis]} ({', '.join(map(str, divisors)) or 'none above 1'}), or "
                "split another axis"
            )
    chains = _chain_devices(devices)
    if num_chains % chains:
        raise ValueError(
            f"the number of chains ({num_chains}) must be a multiple of devices={chains}, the "
            "devices the chains are split over (with lattice_sharding, devices= counts the "
            "chains' devices only)"
        )
    return _mesh_sharding(chains, counts, layout, lattice_sharding)


def _lattice_counts(value) -> dict[int, int]:
    """``lattice_sharding`` as ``{lattice axis: device count}``, checked by type and range."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = {0: value}
    if not isinstance(value, Mapping) or not value:
        raise TypeError(
            "lattice_sharding must be None, a device count n (lattice axis 0 split over n "
            "devices) or a non-empty dict {lattice axis: device count}, e.g. {0: 2} or "
            f"{{0: 2, 1: 2}}; got {value!r}"
        )
    counts = {}
    for axis, count in value.items():
        good_axis = isinstance(axis, (int, np.integer)) and not isinstance(axis, bool)
        if not good_axis or axis < 0:
            raise ValueError(
                f"lattice_sharding={value!r}: its keys are lattice axes, ints 0 to d-1 (0 is "
                f"the lattice's first axis, whatever comes before it in a position); got {axis!r}"
            )
        good_count = isinstance(count, (int, np.integer)) and not isinstance(count, bool)
        if not good_count or count < 1:
            raise ValueError(
                f"lattice_sharding={value!r}: lattice axis {axis} must be split over a positive "
                f"int number of devices, got {count!r}"
            )
        counts[int(axis)] = int(count)
    return counts


def _chain_devices(devices) -> int:
    """``devices=`` beside ``lattice_sharding``: the count of the chains' devices."""
    if devices is None:
        return 1
    if isinstance(devices, (int, np.integer)) and not isinstance(devices, bool) and devices >= 1:
        return int(devices)
    raise ValueError(
        f"devices={devices!r} with lattice_sharding: the mesh is built from the first devices "
        "JAX lists, so devices= is then the number of devices the chains are split over (a "
        "positive int, e.g. devices=2: 2 × the lattice's devices in all) or None (the chains "
        "on one device's share of the lattice each)"
    )


def _mesh_sharding(chains, counts, layout, lattice_sharding) -> LatticeSharding:
    """The mesh ``(chains, *counts)`` on the first devices, refused if there are too few."""
    needed = chains * math.prod(counts.values())
    available = jax.devices()
    if needed > len(available):
        raise ValueError(
            f"lattice_sharding={lattice_sharding!r} with devices={chains} needs {chains} × "
            f"{' × '.join(map(str, counts.values()))} = {needed} devices, more than the "
            f"{len(available)} JAX sees ({available[0].platform}): lower the counts, or start "
            f"JAX with more devices (on a CPU, XLA_FLAGS=--xla_force_host_platform_device_count="
            f"{needed} before JAX starts simulates them)"
        )
    axes = tuple(sorted(counts))
    grid = np.asarray(available[:needed], dtype=object).reshape(chains, *(counts[a] for a in axes))
    names = (CHAIN_AXIS, *(lattice_axis_name(a) for a in axes))
    return LatticeSharding(jax.sharding.Mesh(grid, names), layout, axes)


def spans_processes(sharding: NamedSharding | LatticeSharding | None) -> bool:
    """Whether a run with this sharding spans several processes (its devices are not all this
    process's).

    Examples
    --------
    >>> liesample.sharding.spans_processes(liesample.sharding.chain_sharding("all", 4))
    False
    """
    return sharding is not None and not sharding.is_fully_addressable


def check_output(output, sharding: NamedSharding | LatticeSharding | None) -> None:
    """Refuse ``output=`` for chains spread over some but not all of the processes of
    ``jax.distributed``: process 0 writes the run file, with the draws gathered from every
    process, and a resume reads it on every process, so the run must span all of them.

    Examples
    --------
    Chains in one process, or over every process (``devices="all"``), may write a file:

    >>> liesample.sharding.check_output("run.nc", None)
    """
    if output is None or not spans_processes(sharding):
        return
    found = {getattr(device, "process_index", 0) for device in cast(Any, sharding).device_set}
    count = jax.process_count()
    if found != set(range(count)):
        raise ValueError(
            f"output={output!r}: the chains run on the devices of processes {sorted(found)} of "
            f"the {count} of jax.distributed; a run file is written by process 0 and resumed "
            "by every process, so with output= the chains must span every process: pass "
            "devices='all' (or a sharding over devices of every process), or output=None"
        )


def _axis_names(entry):
    if entry is None:
        return ()
    return (entry,) if isinstance(entry, str) else tuple(entry)


def shard_chains[T: PyTree](tree: T, sharding: NamedSharding | LatticeSharding | None) -> T:
    """Place every leaf of ``tree`` (leading axis = chains) with ``sharding`` (or leave it); a
    :class:`LatticeSharding` places each leaf by :meth:`LatticeSharding.of`.

    Examples
    --------
    >>> from liesample.sharding import chain_sharding, shard_chains
    >>> starts = shard_chains(jnp.zeros((4, 3)), chain_sharding("all", 4))  # 4 chains
    >>> starts.shape, tuple(starts.sharding.spec)
    ((4, 3), ('chain',))
    """
    if sharding is None:
        return tree
    if isinstance(sharding, LatticeSharding):  # each leaf by whether it holds the lattice
        if sharding.is_fully_addressable:
            return jax.tree.map(lambda leaf: jax.device_put(leaf, sharding.of(leaf)), tree)
        return jax.tree.map(lambda leaf: _global_array(leaf, sharding.of(leaf)), tree)
    if sharding.is_fully_addressable:  # one process: its own devices
        return jax.device_put(tree, sharding)
    return jax.tree.map(lambda leaf: _global_array(leaf, sharding), tree)


def _global_array(leaf, sharding: NamedSharding) -> jax.Array:
    """``leaf`` (the whole chain axis, equal on every process) as one array over the devices of
    every process, each process placing the shards of its own devices
    (``jax.make_array_from_callback``); an array already spread over several processes is
    resharded by a compiled identity. Typed PRNG keys travel as their key data."""
    if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
        return jax.jit(lambda x: x, out_shardings=sharding)(leaf)
    if isinstance(leaf, jax.Array) and jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key):
        data = _global_array(jax.random.key_data(leaf), sharding)
        return jax.random.wrap_key_data(data, impl=jax.random.key_impl(leaf))
    host = np.asarray(leaf)
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


def to_host(tree: PyTree) -> PyTree:
    """The leaves of ``tree`` as NumPy arrays on this host (gathered from every process).

    Examples
    --------
    >>> from liesample.sharding import to_host
    >>> to_host({"mu": jnp.ones(2)})
    {'mu': array([1., 1.])}
    """
    return jax.tree.map(_leaf_to_host, tree)


def _leaf_to_host(leaf) -> np.ndarray:
    """One leaf on this host: an array spread over several processes gathered from all of them
    (``multihost_utils.process_allgather``), any other copied (a run within one process of
    ``jax.distributed`` keeps its own chains)."""
    if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(leaf, tiled=True))
    return np.asarray(leaf)


def initialize_distributed(**kwargs: Any) -> bool:
    """``jax.distributed.initialize(**kwargs)`` once; ``False`` if it was already initialised.

    Call it at the top of every process of a multi-host run, before any other JAX call. Without
    arguments JAX reads the job from the environment of the clusters it knows
    (``jax._src.clusters``): a SLURM job step (``SLURM_JOB_ID``, ``SLURM_STEP_NODELIST``,
    ``SLURM_NTASKS``, ``SLURM_PROCID``, ``SLURM_LOCALID``: the coordinator is the step's first
    node), Open MPI's ``mpirun`` (Open MPI 5 through ``mpi4py``), a Kubernetes job (with the
    ``kubernetes`` package) and Cloud TPU VMs; ``cluster_detection_method="mpi4py"`` asks for
    ``mpi4py``'s communicator; ``JAX_COORDINATOR_ADDRESS`` and ``JAX_COORDINATOR_PORT`` set the
    coordinator. Elsewhere pass ``coordinator_address=``, ``num_processes=`` and
    ``process_id=``. Every keyword is passed on to ``jax.distributed.initialize``.

    Examples
    --------
    Skipped in the doctests, which run in one process: the first line of each process of a
    multi-host run (here its cluster comes from SLURM's environment):

    >>> from liesample.sharding import initialize_distributed
    >>> initialize_distributed()  # doctest: +SKIP
    True
    """
    if jax.distributed.is_initialized():
        return False
    if jax.config.jax_cpu_collectives_implementation in (None, "", "none"):
        # CPU devices of several processes exchange the draws through gloo (TCP)
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(**kwargs)
    return True
