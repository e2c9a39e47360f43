"""The points at which the processes of one run (``jax.distributed``) agree, so that an error on
any of them stops every one there.

A run whose chains span several processes is one program on every process: each waits for the
others in every collective (the gather of a chunk's draws). A process that raises alone would
leave the others waiting in their next collective. So, around each step that only some
processes take or that may fail on one of them (process 0 opening, checking and writing the
run file; each process reading it on a resume; the ``callback`` after each chunk, which may be
given on some processes only), every process runs :func:`agreement`: at its end each process
sends to every other whether it failed, with its error's type and message, and a short text of
what it found (``value``), in one small gather (``multihost_utils.process_allgather`` of a
fixed-size byte array: one compiled program for every agreement). A process that failed raises
its own error; every other raises :class:`OtherProcessError`, naming the process, the step and
that error. A process killed outright (SIGKILL, a lost node) never sends: the gather the others
wait in fails when its connection drops (gloo's, on CPUs), and JAX's coordination service ends
every process once it misses the dead process's heartbeats (``heartbeat_timeout_seconds`` of
``jax.distributed.initialize``), or at once when the dead process is process 0, which runs the
service.

In a run within one process an agreement is the block alone: nothing is gathered.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

RECORD_BYTES = 4096
"""The size of each process's record in a gather (its error message is shortened to fit)."""


class OtherProcessError(RuntimeError):
    """Another process of this run (``jax.distributed``) failed at a point where every process
    agrees (:func:`agreement`); this one stops there too. The message names the process, what
    it was doing and its error, which that process raised itself (see its log)."""


@dataclass
class Agreement:
    """What a block of :func:`agreement` reports: set ``value`` (a short text) in the block;
    after it, ``values`` holds every process's, by process index."""

    where: str
    value: str = ""
    values: list[str] = field(default_factory=list)


@contextlib.contextmanager
def agreement(where: str, across_processes: bool) -> Iterator[Agreement]:
    """Run the block, then (``across_processes``) share with every process of the run whether
    it failed, and its ``value``.

    Parameters
    ----------
    where : str
        What the block does, for the message of :class:`OtherProcessError` ("saving draws 0 to
        9 of the run").
    across_processes : bool
        Whether the run spans several processes; if not, the block runs alone.

    Raises
    ------
    OtherProcessError
        On every process whose block succeeded, when another's failed (the failed ones raise
        their own error).

    Examples
    --------
    In one process the block runs as it is, and ``values`` holds its own value:

    >>> from liesample.run.agreement import agreement
    >>> with agreement("reading the run file", across_processes=False) as agreed:
    ...     agreed.value = "draws_done=10"
    >>> agreed.values
    ['draws_done=10']
    """
    agreed = Agreement(where)
    if not across_processes:
        yield agreed
        agreed.values = [agreed.value]
        return
    try:
        yield agreed
    except BaseException as error:
        _share(agreed, error)
        raise
    _share(agreed, None)


def _share(agreed: Agreement, error: BaseException | None) -> None:
    """Gather every process's record; raise :class:`OtherProcessError` if another one failed
    (and this one did not); else set ``agreed.values``."""
    import jax
    from jax.experimental import multihost_utils

    message = None if error is None else f"{type(error).__name__}: {error}"
    rows = multihost_utils.process_allgather(_record(message, agreed.value))
    records = [_read(row) for row in np.asarray(rows).reshape(jax.process_count(), -1)]
    agreed.values = [record["value"] for record in records]
    if error is not None:
        return  # this process raises its own error
    failed = [(index, record["error"]) for index, record in enumerate(records) if record["error"]]
    if failed:
        index, message = failed[0]
        others = f" (and processes {[i for i, _ in failed[1:]]})" if len(failed) > 1 else ""
        raise OtherProcessError(
            f"process {index} of {len(records)}{others} failed while {agreed.where}, so this "
            f"process (process {jax.process_index()}) stops too; its error: {message}"
        )


def _record(message: str | None, value: str) -> np.ndarray:
    """``message`` and ``value`` as JSON in :data:`RECORD_BYTES` bytes (zero-padded), the
    message shortened to fit."""
    while True:
        data = json.dumps({"error": message, "value": value}).encode()
        if len(data) <= RECORD_BYTES or message is None or len(message) <= 20:
            break
        message = message[: max(20, len(message) - (len(data) - RECORD_BYTES) - 20)] + " …"
    if len(data) > RECORD_BYTES:
        raise ValueError(f"an agreement's value is too long ({len(value)} characters)")
    row = np.zeros(RECORD_BYTES, np.uint8)
    row[: len(data)] = np.frombuffer(data, np.uint8)
    return row


def _read(row: np.ndarray) -> dict:
    return json.loads(bytes(np.asarray(row, np.uint8)).rstrip(b"\0").decode())
