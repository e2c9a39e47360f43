"""Chains across devices: JAX's own sharding of the chain axis (``jax.sharding.NamedSharding``).

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
``jax.distributed.initialize``, which reads a SLURM, Open MPI or Kubernetes job from the
environment and selects gloo CPU collectives), before any other JAX call. Then
``jax.devices()`` lists the devices of every process and ``devices="all"`` spreads the chains
over all of them. Every process passes the same ``rng_key`` and ``initial_positions`` (the
whole chain axis); :func:`shard_chains` builds global arrays from them
(``jax.make_array_from_callback``: each process places the shards of its own devices), each
process computes its own chains, and :func:`to_host` gathers every chain's draws to every
process (``multihost_utils.process_allgather``): every process returns the whole tree, the
draws of one process running every chain. A run file (``output=``) is refused for such a run
(:func:`check_output`): save the returned tree from one process.

The test suite runs one process with several (forced host) CPU devices, bitwise equal to the
unsharded run, and two processes on the loopback interface with one CPU device each, bitwise
equal to one process (and the refusal of ``output=``). Several machines, GPUs over several
processes, and the window warm-ups across processes are not tested.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import Any, cast

import jax
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from liesample.foundation.types import PyTree

__all__ = [
    "CHAIN_AXIS",
    "chain_sharding",
    "check_output",
    "initialize_distributed",
    "shard_chains",
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


def check_output(output, sharding: NamedSharding | None) -> None:
    """Refuse ``output=`` for chains spread over several processes: a run file is written by
    one process, and its resume needs every chain's state there.

    Examples
    --------
    Chains in one process (no sharding, or devices of this process only) may write a file:

    >>> liesample.sharding.check_output("run.nc", None)
    """
    if output is None or sharding is None or sharding.is_fully_addressable:
        return
    processes = len({getattr(device, "process_index", 0) for device in sharding.device_set})
    raise ValueError(
        f"output={output!r}: a run file is not written for chains spread over {processes} "
        "processes (devices of jax.distributed); pass output=None and save the tree that "
        "liesample.sample returns on every process from one of them, e.g. "
        "`if jax.process_index() == 0: tree.to_netcdf(path)` (a run over several processes "
        "is not resumed: run it again whole)"
    )


def _axis_names(entry):
    if entry is None:
        return ()
    return (entry,) if isinstance(entry, str) else tuple(entry)


def shard_chains[T: PyTree](tree: T, sharding: NamedSharding | None) -> T:
    """Place every leaf of ``tree`` (leading axis = chains) with ``sharding`` (or leave it).

    Examples
    --------
    >>> from liesample.sharding import chain_sharding, shard_chains
    >>> starts = shard_chains(jnp.zeros((4, 3)), chain_sharding("all", 4))  # 4 chains
    >>> starts.shape, tuple(starts.sharding.spec)
    ((4, 3), ('chain',))
    """
    if sharding is None:
        return tree
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
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return jax.tree.map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))
    return jax.tree.map(np.asarray, tree)


def initialize_distributed(**kwargs: Any) -> bool:
    """``jax.distributed.initialize(**kwargs)`` once; ``False`` if it was already initialised.

    Call it at the top of every process of a multi-host run, before any other JAX call. Without
    arguments JAX reads the cluster from the environment (SLURM, Open MPI, Kubernetes, or
    ``JAX_COORDINATOR_ADDRESS``, ``JAX_NUM_PROCESSES``, ``JAX_PROCESS_ID``); pass
    ``coordinator_address=``, ``num_processes=``, ``process_id=`` otherwise.

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
