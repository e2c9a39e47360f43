"""What the window adaptations of :mod:`liesample.tuning.adaptation` and
:mod:`liesample.tuning.magnetic_adaptation` share: the object they return, the check of their
flags, and the layout of their records."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["GeometricAdaptation", "check_flags", "steps_first"]


class GeometricAdaptation(NamedTuple):
    """What ``window_adaptation`` returns: ``run(rng_key, initial_position, num_steps)``."""

    run: Callable


def check_flags(**flags) -> None:
    """A ``TypeError`` naming the first flag that is not a bool (``"no"`` would read as true)."""
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool (True or False), got {value!r}")


def steps_first(records):
    """Per-chain records of :func:`liesample.tuning.protocol.run_adaptation` (chains,
    transitions, …) as BlackJAX lays them out (transitions, chains, …)."""
    return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), records)
