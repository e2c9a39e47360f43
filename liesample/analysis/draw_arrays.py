"""What the diagnostics read: per-draw arrays shaped ``(chains, draws, ...)`` and a sampler's
``info`` record, each checked before use.

Sampler runs produce ``positions`` shaped ``(chains, draws, *event_shape)`` and an ``info``
record (a mapping, NamedTuple or dataclass) of per-draw arrays shaped ``(chains, draws)``;
:func:`_info_dict` reads the record as a dict of arrays and :func:`_chain_draw_array` checks an
array's rank and its chain and draw counts, for the DataTree
(:mod:`liesample.analysis.datatree`), the tables and health checks
(:mod:`liesample.analysis.diagnostics`) and the errors of means
(:mod:`liesample.analysis.correlated_errors`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

# The fewest draws per chain a table row or an error of a mean is computed from.
_MIN_DRAWS = 4


def _info_dict(info, name: str = "info") -> dict[str, np.ndarray]:
    """Return ``info`` as a ``{key: numpy array}`` dict (``None`` gives ``{}``)."""
    if info is None:
        return {}
    if hasattr(info, "_asdict"):
        items = info._asdict()
    elif isinstance(info, Mapping):
        items = info
    elif dataclasses.is_dataclass(info) and not isinstance(info, type):
        items = {f.name: getattr(info, f.name) for f in dataclasses.fields(info)}
    else:
        raise TypeError(
            f"{name} must be a mapping, a NamedTuple or a dataclass of arrays, "
            f"got {type(info).__name__}"
        )
    return {str(k): np.asarray(v) for k, v in items.items() if v is not None}


def _chain_draw_array(x, name: str, *, min_draws: int = 1, ndims: Sequence[int] = (2,)):
    """``np.asarray(x)`` after checking its rank and its (chain, draw) sizes."""
    arr = np.asarray(x)
    if arr.ndim not in ndims:
        want = " or ".join(str(n) for n in ndims)
        raise ValueError(
            f"{name} must have {want} dimensions (chain, draw, ...), got shape {arr.shape}"
        )
    if arr.shape[0] < 1:
        raise ValueError(f"{name} must have at least 1 chain, got shape {arr.shape}")
    if arr.shape[1] < min_draws:
        raise ValueError(
            f"{name} must have at least {min_draws} draws per chain, got shape {arr.shape}"
        )
    return arr
