"""Convergence diagnostics for sampler output: the table of estimates against exact values,
time correlations and the health checks of a run.

Sampler runs produce ``positions`` shaped ``(chains, draws, *event_shape)`` and an ``info``
record of per-draw arrays shaped ``(chains, draws)``. This module tabulates Monte-Carlo
estimates against exact values using ArviZ's ESS, R-hat and MCSE (:func:`expectation_table`,
:func:`format_table`), computes the FFT autocovariances used to check time correlations
(:func:`autocovariance`), and reads the Casimir drift and the divergent draws from ``info``
(:func:`casimir_drift`, :func:`count_nonfinite`).

The rest of the analysis of a run lives next to it and is importable from here too (as
``liesample.diagnostics``): the ArviZ ``DataTree`` of a run (:func:`to_datatree`,
:func:`pytree_variables`) in :mod:`liesample.analysis.datatree`; errors of means of correlated
draws by blocking and by the jackknife over blocks (:func:`blocking_error`, :func:`jackknife`)
in :mod:`liesample.analysis.correlated_errors`; the specific heat, susceptibility and Binder
cumulant with their jackknife errors in :mod:`liesample.analysis.fluctuations`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import scipy.fft

from liesample.analysis.correlated_errors import (
    BlockingResult,
    JackknifeResult,
    blocking_error,
    jackknife,
)
from liesample.analysis.datatree import pytree_variables, to_datatree
from liesample.analysis.draw_arrays import _MIN_DRAWS, _chain_draw_array, _info_dict
from liesample.analysis.fluctuations import binder_cumulant, specific_heat, susceptibility

if TYPE_CHECKING:  # ArviZ and pandas load when a function needs them (import liesample stays
    import pandas as pd  # as cheap as importing jax and blackjax)

__all__ = [
    "BlockingResult",
    "JackknifeResult",
    "autocovariance",
    "binder_cumulant",
    "blocking_error",
    "casimir_drift",
    "count_nonfinite",
    "expectation_table",
    "format_table",
    "jackknife",
    "pytree_variables",
    "specific_heat",
    "susceptibility",
    "to_datatree",
]

_DIVERGENCE_KEYS = ("is_divergent", "diverging", "nonfinite")

# Quantiles for the tail ESS (Vehtari et al. 2021): min of the ESS of the 5% and 95% quantiles.
_TAIL_PROB = (0.05, 0.95)

TABLE_COLUMNS = (
    "estimate",
    "exact",
    "mcse",
    "z",
    "ess_bulk",
    "ess_tail",
    "r_hat",
    "ess_per_second",
)


# --------------------------------------------------------------------------- tables


def expectation_table(
    draws: Mapping[str, np.ndarray],
    exact: Mapping[str, float] | None = None,
    wall_time: float | None = None,
) -> pd.DataFrame:
    """Tabulate Monte-Carlo estimates of expectations with ArviZ diagnostics.

    Parameters
    ----------
    draws : mapping of str to array_like, each shape (chains, draws)
        Per-draw values of each test function, e.g. ``{"mu_z": positions[..., 2]}``.
    exact : mapping of str to float, optional
        Exact expectations; quantities without one get ``NaN`` in ``exact`` and ``z``.
    wall_time : float, optional
        Sampling wall time in seconds, for ``ess_per_second``.

    Returns
    -------
    pandas.DataFrame
        Indexed by quantity, with columns ``estimate`` (mean over all chains and draws),
        ``exact``, ``mcse`` (ArviZ MCSE of the mean), ``z = (estimate - exact) / mcse``,
        ``ess_bulk``, ``ess_tail`` (5%/95% quantiles), ``r_hat`` (rank-normalised split
        R-hat; ``NaN`` for a single chain) and ``ess_per_second = ess_bulk / wall_time``
        (``NaN`` without ``wall_time``).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import expectation_table
    >>> draws = {"x": np.random.default_rng(0).normal(size=(2, 500))}  # (chains, draws)
    >>> table = expectation_table(draws, exact={"x": 0.0})
    >>> list(table.columns)
    ['estimate', 'exact', 'mcse', 'z', 'ess_bulk', 'ess_tail', 'r_hat', 'ess_per_second']
    """
    if not isinstance(draws, Mapping) or len(draws) == 0:
        raise ValueError("draws must be a non-empty mapping of name -> array (chains, draws)")
    exact = dict(exact or {})
    unknown = sorted(set(exact) - set(draws))
    if unknown:
        raise ValueError(f"exact has quantities not in draws: {unknown}")
    if wall_time is not None:
        try:
            seconds = float(wall_time)
        except (TypeError, ValueError):
            seconds = math.nan
        if not (math.isfinite(seconds) and seconds > 0):
            raise ValueError(f"wall_time must be a finite number of seconds > 0, got {wall_time!r}")
        wall_time = seconds

    import arviz_stats as azs
    import pandas as pd

    rows = {}
    for name, values in draws.items():
        x = _chain_draw_array(values, f"draws[{name!r}]", min_draws=_MIN_DRAWS).astype(float)
        estimate = float(np.mean(x))
        truth = float(exact[name]) if name in exact else math.nan
        mcse = float(azs.mcse(x, method="mean"))
        ess_bulk = float(azs.ess(x, method="bulk"))
        with np.errstate(invalid="ignore", divide="ignore"):  # constant draws: R-hat is 0/0
            r_hat = float(azs.rhat(x))
        rows[name] = {
            "estimate": estimate,
            "exact": truth,
            "mcse": mcse,
            "z": (estimate - truth) / mcse if mcse > 0 else math.nan,
            "ess_bulk": ess_bulk,
            "ess_tail": float(azs.ess(x, method="tail", prob=_TAIL_PROB)),
            "r_hat": r_hat,
            "ess_per_second": ess_bulk / wall_time if wall_time is not None else math.nan,
        }
    df = pd.DataFrame.from_dict(rows, orient="index", columns=list(TABLE_COLUMNS))
    df.index.name = "quantity"
    return df


def _format_cell(column: str, value) -> str:
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if not isinstance(value, (int, float, np.integer, np.floating)):
        return str(value)
    v = float(value)
    if not math.isfinite(v):
        return str(v)
    if column.startswith("ess") or column in ("n", "draws", "chains"):
        return f"{v:.0f}" if abs(v) >= 10 or v == 0 else f"{v:.2g}"
    if column == "r_hat":
        return f"{v:.3f}"
    if column == "z":
        return f"{v:+.2f}"
    return f"{v:.4g}"


def format_table(df: pd.DataFrame) -> str:
    """Render a table as fixed-width text for a terminal.

    Numbers get column-appropriate precision: 4 significant digits in general, whole numbers
    for ESS columns, 3 decimals for ``r_hat``, signed 2 decimals for ``z``; ``NaN`` shows as
    ``-``.

    Parameters
    ----------
    df : pandas.DataFrame
        Typically the output of :func:`expectation_table`.

    Returns
    -------
    str
        The table, one line per row, with a header and an underline.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import expectation_table, format_table
    >>> table = expectation_table({"x": np.random.default_rng(0).normal(size=(2, 500))})
    >>> print(format_table(table).splitlines()[0])
    quantity  estimate  exact  mcse  z  ess_bulk  ess_tail  r_hat  ess_per_second
    """
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame, got {type(df).__name__}")
    index_name = str(df.index.name or "")
    columns = [str(c) for c in df.columns]
    body = [
        [str(idx)] + [_format_cell(col, val) for col, val in zip(columns, row, strict=True)]
        for idx, row in zip(df.index, df.itertuples(index=False), strict=True)
    ]
    header = [index_name] + columns
    widths = [max(len(r[i]) for r in [header, *body]) for i in range(len(header))]

    def line(cells):
        first = cells[0].ljust(widths[0])
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]
        return "  ".join([first, *rest]).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(header), rule, *(line(r) for r in body)])


# --------------------------------------------------------------------------- time correlations


def autocovariance(x: npt.ArrayLike, max_lag: int, *, center: bool = True) -> np.ndarray:
    """Autocovariance over lags ``0..max_lag``, averaged over chains and time, via FFT.

    ``c[k] = sum over chains and t of (x_t - m) . (x_{t+k} - m) / (chains * (draws - k))``,
    i.e. each lag is divided by its number of pairs. ``m`` is the mean over all chains and
    draws (per component); for 3-D input ``.`` is the inner product over the last axis.

    Parameters
    ----------
    x : array_like, shape (chains, draws) or (chains, draws, d)
        Chains of scalar or vector observations.
    max_lag : int
        Largest lag, ``0 <= max_lag < draws``.
    center : bool, default True
        Subtract ``m`` first. Use ``False`` when the exact mean is known to be zero (e.g.
        ``E[mu(t) . mu(0)]`` on the isotropic sphere), which avoids the bias of estimating it.

    Returns
    -------
    numpy.ndarray, shape (max_lag + 1,)

    Examples
    --------
    An alternating chain: covariance ``±1`` at even and odd lags:

    >>> import numpy as np
    >>> from liesample.diagnostics import autocovariance
    >>> autocovariance(np.array([[1.0, -1.0, 1.0, -1.0]]), max_lag=2)
    array([ 1., -1.,  1.])
    """
    arr = _chain_draw_array(x, "x", ndims=(2, 3)).astype(float)
    if arr.ndim == 2:
        arr = arr[..., None]
    n_chains, n_draws, _ = arr.shape
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)):
        raise TypeError(f"max_lag must be an integer, got {max_lag!r}")
    if not 0 <= max_lag < n_draws:
        raise ValueError(f"max_lag must satisfy 0 <= max_lag < draws = {n_draws}, got {max_lag}")
    if center:
        arr = arr - arr.mean(axis=(0, 1), keepdims=True)
    n_fft = scipy.fft.next_fast_len(2 * n_draws, real=True)  # zero-pad: no wrap-around
    spectrum = scipy.fft.rfft(arr, n=n_fft, axis=1)
    lagged = scipy.fft.irfft(spectrum * spectrum.conj(), n=n_fft, axis=1)[:, : max_lag + 1]
    total = lagged.sum(axis=(0, 2))
    pairs = n_chains * (n_draws - np.arange(max_lag + 1))
    return total / pairs


# --------------------------------------------------------------------------- health checks


def casimir_drift(info: Mapping | tuple | object) -> dict[str, float]:
    """Summarise the relative Casimir error recorded by the sampler.

    Parameters
    ----------
    info : mapping, NamedTuple or dataclass
        Must contain ``casimir_error`` shaped ``(chains, draws)``.

    Returns
    -------
    dict
        ``max``: largest error over all chains and draws; ``final``: largest error at the last
        draw over chains. Both are ``nan`` if any considered value is ``nan`` (a chain that
        became non-finite).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import casimir_drift
    >>> casimir_drift({"casimir_error": np.array([[0.0, 1e-15], [2e-15, 0.0]])})  # (chains, draws)
    {'max': 2e-15, 'final': 1e-15}
    """
    items = _info_dict(info)
    if "casimir_error" not in items:
        raise ValueError(f"info must contain 'casimir_error', got keys {sorted(items)}")
    err = _chain_draw_array(items["casimir_error"], "info['casimir_error']")
    return {"max": float(np.max(err)), "final": float(np.max(err[:, -1]))}


def count_nonfinite(info: Mapping | tuple | object) -> int:
    """Number of draws, over all chains, flagged divergent (non-finite state or energy).

    Parameters
    ----------
    info : mapping, NamedTuple or dataclass
        Must contain ``is_divergent`` (the Info contract), ``diverging`` (ArviZ's name) or
        ``nonfinite`` (legacy), bool, shaped ``(chains, draws)``.

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import count_nonfinite
    >>> count_nonfinite({"is_divergent": np.array([[False, True], [False, False]])})
    1
    """
    items = _info_dict(info)
    key = next((k for k in _DIVERGENCE_KEYS if k in items), None)
    if key is None:
        raise ValueError(
            f"info must contain one of {list(_DIVERGENCE_KEYS)}, got keys {sorted(items)}"
        )
    flags = _chain_draw_array(items[key], f"info[{key!r}]")
    return int(np.count_nonzero(flags))
