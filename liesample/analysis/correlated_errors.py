"""Errors of means of correlated draws: blocking, and the jackknife over blocks for functions
of several means.

:func:`blocking_error` gives the standard error of one mean by blocking (Flyvbjerg and
Petersen 1989), the level chosen automatically; :func:`jackknife` gives the error of a function
of several means (a variance, a ratio) by leaving out one block at a time. The thermodynamic
quantities built on the jackknife are in :mod:`liesample.analysis.fluctuations`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from liesample.analysis.draw_arrays import _MIN_DRAWS, _chain_draw_array

__all__ = ["BlockingResult", "JackknifeResult", "blocking_error", "jackknife"]


class BlockingResult(NamedTuple):
    """The blocking estimate of the standard error of a mean (:func:`blocking_error`).

    mean : float
        Mean over every chain and draw.
    error : float
        Standard error of ``mean`` at the chosen level.
    level : int
        The chosen level ``k``: blocks of ``2**k`` consecutive draws.
    errors, errors_error : numpy.ndarray
        The error estimate at every level ``0, 1, …`` and its own standard error (the plateau
        plot of Flyvbjerg and Petersen).
    tau_int : float
        Integrated autocorrelation time ``(error / errors[0])**2`` (``1`` for independent
        draws; ``Var(mean) = tau_int · Var(x) / draws``).
    num_blocks : int
        Blocks over all chains at the chosen level.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import blocking_error
    >>> result = blocking_error(np.random.default_rng(0).normal(size=(2, 1024)))
    >>> result.num_blocks == 2 * 1024 // 2**result.level  # blocks over both chains
    True
    """

    mean: float
    error: float
    level: int
    errors: np.ndarray
    errors_error: np.ndarray
    tau_int: float
    num_blocks: int


_BLOCKING_CONFIDENCE = 0.99
_MIN_BLOCKS = 32  # fewer blocks at the chosen level: the error is itself uncertain (warned)


def _blocking_levels(x):
    """Per level ``k``: ``(n_k, variance (chains,), lag-1 autocovariance (chains,))`` of the
    series of means of ``2**k`` consecutive draws of each chain (an odd last draw dropped)."""
    levels = []
    y = x
    while y.shape[1] >= 2:
        n = y.shape[1]
        centred = y - y.mean(axis=1, keepdims=True)
        variance = np.mean(centred**2, axis=1)
        lag1 = np.sum(centred[:, :-1] * centred[:, 1:], axis=1) / n
        levels.append((n, variance, lag1))
        y = y[:, : 2 * (n // 2)]
        y = 0.5 * (y[:, 0::2] + y[:, 1::2])
    return levels


def blocking_error(x: npt.ArrayLike, *, warn: bool = True) -> BlockingResult:
    """Standard error of the mean of correlated draws by blocking (Flyvbjerg and Petersen 1989),
    with the level chosen automatically (Jonsson 2018).

    Each chain's draws are averaged in pairs, again and again: at level ``k`` a chain has
    ``n_k`` means of ``2**k`` consecutive draws, and ``s_k^2 / (n_k - 1)`` (their variance over
    their number) estimates the variance of the chain's mean, growing with ``k`` until the
    blocks are longer than the autocorrelation time and then constant (the plateau). Blocks
    of length ``b`` still underestimate the error by a relative ``O(tau_int / b)``, while the
    error's own noise grows as ``sqrt(b / draws)``; the level chosen is the later of two:

    - the first from which the blocks' lag-1 autocorrelations are all compatible with zero
      (Jonsson 2018): ``M_j = sum over chains and levels k >= j of n_k (gamma_k / s_k^2)^2``
      below the 99% quantile of chi-square with as many degrees of freedom as terms;
    - the first whose block length balances that bias against the noise (Wolff 2004; Lee,
      Booth and Alavi 2011): ``b^3 > 2 · draws · tau_k^2``, ``draws`` over all chains and
      ``tau_k = (error_k / error_0)^2``.

    Chains are combined at that common level:
    ``Var(mean) = sum_c s_{c,k}^2 / (n_k - 1) / chains^2`` (the grand mean averages the chains'
    means; a chain that sits apart from the others is not seen here:
    use R-hat for that).

    Parameters
    ----------
    x : array_like, shape (draws,) or (chains, draws)
        One scalar quantity per draw (e.g. an observable recorded by ``liesample.sample``).
    warn : bool
        Warn (``RuntimeWarning``) when the chosen level leaves fewer than 32 blocks in all,
        i.e. the draws are too few for their autocorrelation time and the error is uncertain.

    Returns
    -------
    BlockingResult

    Example: ``blocking_error(tree.posterior["h"].values).error`` is the standard error of
    the mean energy of a run with ``observables={"h": system.hamiltonian}``.

    Examples
    --------
    Independent draws: the error is ``σ/√n`` within its own noise, and ``tau_int`` near 1:

    >>> import numpy as np
    >>> from liesample.diagnostics import blocking_error
    >>> result = blocking_error(np.random.default_rng(0).normal(size=(2, 1024)))
    >>> bool(0.5 < result.error * np.sqrt(2048) < 1.5), bool(result.tau_int < 2)
    (True, True)
    """
    import scipy.stats

    arr = np.asarray(x, dtype=float)
    arr = arr[None] if arr.ndim == 1 else arr
    arr = _chain_draw_array(arr, "x", min_draws=_MIN_DRAWS)
    if not np.all(np.isfinite(arr)):
        raise ValueError("x must be finite")
    num_chains = arr.shape[0]
    levels = _blocking_levels(arr)
    sizes = np.array([n for n, _, _ in levels])
    variances = np.array([v for _, v, _ in levels])  # (levels, chains)
    lag1 = np.array([g for _, _, g in levels])
    per_level = np.sum(variances / (sizes[:, None] - 1), axis=1) / num_chains**2
    errors = np.sqrt(per_level)
    errors_error = errors / np.sqrt(2.0 * num_chains * (sizes - 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        terms = np.where(variances > 0, sizes[:, None] * (lag1 / variances) ** 2, 0.0).sum(axis=1)
    statistic = np.cumsum(terms[::-1])[::-1]  # M_j: levels j and above
    dof = num_chains * (len(levels) - np.arange(len(levels)))
    uncorrelated = np.flatnonzero(statistic < scipy.stats.chi2.ppf(_BLOCKING_CONFIDENCE, dof))
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = per_level / per_level[0]
    block_lengths = 2.0 ** np.arange(len(levels))
    balanced = np.flatnonzero(block_lengths**3 > 2.0 * arr.size * tau**2)
    last = len(levels) - 1
    level = max(
        int(uncorrelated[0]) if uncorrelated.size else last,
        int(balanced[0]) if balanced.size else last,
    )
    if per_level[0] == 0:  # constant draws: no error at any level
        level = 0
    num_blocks = int(num_chains * sizes[level])
    if warn and num_blocks < _MIN_BLOCKS:
        warnings.warn(
            f"blocking_error: the chosen level {level} leaves {num_blocks} blocks of "
            f"{2**level} draws (fewer than {_MIN_BLOCKS}): the draws are few for their "
            "autocorrelation time and the error is itself uncertain "
            f"(relative standard error {errors_error[level] / max(errors[level], 1e-300):.2f});"
            " run longer chains",
            RuntimeWarning,
            stacklevel=2,
        )
    error = float(errors[level])
    tau_int = (error / errors[0]) ** 2 if errors[0] > 0 else math.nan
    return BlockingResult(
        float(np.mean(arr)), error, level, errors, errors_error, float(tau_int), num_blocks
    )


class JackknifeResult(NamedTuple):
    """A function of means and its jackknife error (:func:`jackknife`).

    estimate : float or numpy.ndarray
        ``function`` of the means over every chain and draw.
    error : float or numpy.ndarray
        Its jackknife standard error over the blocks of every chain.
    bias : float or numpy.ndarray
        The jackknife estimate of its bias (``estimate - bias`` is the bias-corrected value).
    per_chain, per_chain_error : numpy.ndarray
        The same estimate and error from each chain alone (leading axis: chains), to compare
        the chains with each other.
    block_size : int
        Draws per block.
    num_blocks : int
        Blocks over all chains.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import jackknife
    >>> x = np.random.default_rng(0).normal(size=(2, 1024))
    >>> result = jackknife(lambda m, m2: m2 - m**2, x, x**2, block_size=64)  # the variance
    >>> result.num_blocks, result.per_chain.shape  # 16 blocks per chain; one estimate per chain
    (32, (2,))
    """

    estimate: object
    error: object
    bias: object
    per_chain: np.ndarray
    per_chain_error: np.ndarray
    block_size: int
    num_blocks: int


def _leave_one_out(function, block_means):
    """``(f(all), jackknife error, jackknife bias)`` over the leading (block) axis of each
    array in ``block_means``."""
    num = block_means[0].shape[0]
    totals = [b.sum(axis=0) for b in block_means]
    full = np.asarray(function(*[t / num for t in totals]), dtype=float)
    left_out = np.stack(
        [
            np.asarray(
                function(
                    *[(t - b[i]) / (num - 1) for t, b in zip(totals, block_means, strict=True)]
                )
            )
            for i in range(num)
        ]
    ).astype(float)
    mean_left_out = left_out.mean(axis=0)
    error = np.sqrt((num - 1) / num * np.sum((left_out - mean_left_out) ** 2, axis=0))
    return full, error, (num - 1) * (mean_left_out - full)


def jackknife(
    function: Callable[..., float], *series: npt.ArrayLike, block_size: int | None = None
) -> JackknifeResult:
    """Jackknife estimate and error of ``function(mean of series[0], mean of series[1], …)``.

    For variance-type quantities, which are functions of several means (the specific heat
    from ``⟨E⟩`` and ``⟨E²⟩``, a Binder cumulant from ``⟨m²⟩`` and ``⟨m⁴⟩``), whose error the
    MCSE of a single mean does not give. Each chain's draws are cut into blocks of
    ``block_size`` consecutive draws (the draws after the last whole block dropped); leaving
    out one block at a time among all ``B`` blocks of all chains gives ``B`` values ``f_i`` of
    the function of the remaining means, and the error
    ``sqrt((B - 1)/B · sum_i (f_i - mean f)^2)`` and bias ``(B - 1)(mean f - f)``. Blocks much
    longer than the autocorrelation time are nearly independent, which the error assumes.

    Parameters
    ----------
    function : callable
        ``function(*means) -> float or array``, numpy-compatible; ``means[j]`` is the mean of
        ``series[j]`` over chains and draws (shape ``series[j].shape[2:]``).
    *series : array_like, each shape (chains, draws, ...) (or (draws, ...) for one chain)
        Per-draw values, all with the same chains and draws.
    block_size : int, optional
        Draws per block. Default: the longest block length the automatic blocking level of
        :func:`blocking_error` picks for any component of any series.

    Returns
    -------
    JackknifeResult

    Example: the specific heat per site of ``N`` spins at ``beta`` from a run with
    ``observables={"h": system.hamiltonian}``,
    ``jackknife(lambda e, e2: beta**2 * (e2 - e**2) / N, h, h**2)``
    (:func:`liesample.analysis.fluctuations.specific_heat` does this, with the energy shifted
    first).

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import jackknife
    >>> e = np.random.default_rng(0).normal(size=(2, 1024))  # an energy, (chains, draws)
    >>> result = jackknife(lambda e1, e2: e2 - e1**2, e, e**2, block_size=64)
    >>> bool(np.isclose(result.estimate, e.var())), bool(result.error > 0)
    (True, True)
    """
    if not callable(function):
        raise TypeError(f"function must be callable, got {type(function).__name__}")
    if not series:
        raise ValueError("jackknife needs at least one series")
    arrays = []
    for j, values in enumerate(series):
        arr = np.asarray(values, dtype=float)
        arrays.append(arr[None] if arr.ndim == 1 else arr)
        _chain_draw_array(arrays[-1], f"series[{j}]", min_draws=2, ndims=(arrays[-1].ndim,))
        if arrays[-1].shape[:2] != arrays[0].shape[:2]:
            raise ValueError(
                f"every series must have the same (chains, draws): series[0] has "
                f"{arrays[0].shape[:2]}, series[{j}] has {arrays[-1].shape[:2]}"
            )
        if not np.all(np.isfinite(arrays[-1])):
            raise ValueError(f"series[{j}] must be finite")
    num_chains, num_draws = arrays[0].shape[:2]
    if block_size is None:
        block_size = max(
            2 ** blocking_error(arr.reshape(num_chains, num_draws, -1)[..., i], warn=False).level
            for arr in arrays
            for i in range(int(np.prod(arr.shape[2:], dtype=int)))
        )
    if isinstance(block_size, bool) or not isinstance(block_size, (int, np.integer)):
        raise TypeError(f"block_size must be an integer, got {block_size!r}")
    blocks_per_chain = num_draws // block_size if block_size >= 1 else 0
    if blocks_per_chain < 1 or num_chains * blocks_per_chain < 2:
        raise ValueError(
            f"block_size={block_size} leaves fewer than 2 blocks in {num_chains} chain(s) of "
            f"{num_draws} draws"
        )
    kept = blocks_per_chain * block_size
    # (chains, blocks, ...) block means of each series
    block_means = [
        arr[:, :kept].reshape(num_chains, blocks_per_chain, block_size, *arr.shape[2:]).mean(2)
        for arr in arrays
    ]
    estimate, error, bias = _leave_one_out(
        function, [b.reshape(-1, *b.shape[2:]) for b in block_means]
    )
    per_chain, per_chain_error = [], []
    for c in range(num_chains):
        if blocks_per_chain >= 2:
            value, spread, _ = _leave_one_out(function, [b[c] for b in block_means])
        else:
            value = np.asarray(function(*[b[c].mean(axis=0) for b in block_means]), float)
            spread = np.full_like(value, math.nan)
        per_chain.append(value)
        per_chain_error.append(spread)

    def scalar(value):
        return float(value) if np.ndim(value) == 0 else value

    return JackknifeResult(
        scalar(estimate),
        scalar(error),
        scalar(bias),
        np.stack(per_chain),
        np.stack(per_chain_error),
        int(block_size),
        int(num_chains * blocks_per_chain),
    )
