"""Convergence checks on every posterior variable, cheap enough to run after every sample.

:func:`convergence_warnings` computes, for every element of every variable (positions and
observables), the rank-normalised split R-hat and the bulk and tail effective sample sizes of
Vehtari, Gelman, Simpson, Carpenter and Bürkner (2021), as ArviZ defines them
(``arviz_stats``: ``rhat(method="rank")``, ``ess(method="bulk")``, ``ess(method="tail",
prob=(0.05, 0.95))``), and returns a message for each kind of failure: R-hat above
:data:`MAX_RHAT` (chains in different modes, chains that have not forgotten their starts, a
drifting target) or an ESS below :data:`MIN_ESS_PER_CHAIN` per chain. ArviZ computes these one
element at a time in Python; here every element of a variable is computed in one pass of array
operations (ranks by one sort, autocovariances by one FFT, Geyer's truncation by cumulative
reductions); the values are ArviZ's to round-off.

**Large variables.** A variable with more than :data:`MAX_RANKED_ELEMENTS` varying elements (a
lattice's links or spins) is not ranked whole: ranks and FFTs of every site would cost more
than a short run. Every element is first *screened* by cheap statistics of one pass over its
draws: the plain split R-hat of the values and of their distances from the pooled mean (chains
in different places or with different spreads) and the lag-1 autocorrelation pooled over the
split chains (slow mixing). The rank-normalised R-hat and the bulk and tail ESS are then
computed on the :data:`MAX_RANKED_ELEMENTS` most suspicious elements: half the elements with
the largest screened R-hat, the rest those with the largest autocorrelation (ties by position,
so the subset is a function of the draws alone). An element outside that subset whose screened
R-hat is above :data:`MAX_RHAT` is still reported, with that R-hat. A stuck or displaced chain
moves every site's screen, and a single site that has not converged tops it, so neither is
missed; what the rule gives up is the rank-normalised values of the unremarkable sites, whose
law (on a lattice with its translations) the ranked ones share.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt
import scipy.fft
from scipy.special import ndtri

__all__ = [
    "MAX_RANKED_ELEMENTS",
    "MAX_RHAT",
    "MIN_ESS_PER_CHAIN",
    "convergence_warnings",
    "rank_diagnostics",
    "screen",
]

MAX_RHAT = 1.01
"""An element whose rank-normalised split R-hat is above this is reported (Vehtari et al.)."""
MIN_ESS_PER_CHAIN = 100
"""An element whose bulk or tail ESS is below this many per chain is reported."""
MAX_RANKED_ELEMENTS = 128
"""The most elements of one variable (within one law group) given the rank-normalised R-hat
and ESS; the others are screened (module docstring, "Large variables")."""

_MIN_DRAWS = 4  # split chains need at least two draws per half
_TAIL_PROB = (0.05, 0.95)
_SHOWN = 5  # elements named per message
_BATCH_VALUES = 2**22  # draws of the elements checked at once


def _split(x):
    """``(E, C, N) -> (E, 2C, N // 2)``: each chain's first and last halves as chains."""
    half = x.shape[-1] // 2
    return np.concatenate([x[..., :half], x[..., x.shape[-1] - half :]], axis=1)


def _z_scale(x):
    """Normal scores of the ranks over every chain and draw of each element (ties get their
    average rank; Blom's offset 3/8)."""
    elements, chains, draws = x.shape
    size = chains * draws
    flat = x.reshape(elements, size)
    order = np.argsort(flat, axis=1)
    ordered = np.take_along_axis(flat, order, axis=1)
    index = np.arange(size)
    new = np.ones(ordered.shape, bool)
    new[:, 1:] = ordered[:, 1:] != ordered[:, :-1]
    end = np.ones(ordered.shape, bool)
    end[:, :-1] = new[:, 1:]
    first = np.maximum.accumulate(np.where(new, index, 0), axis=1)
    last = np.minimum.accumulate(np.where(end, index, size - 1)[:, ::-1], axis=1)[:, ::-1]
    # the average rank of a tie is (first + last) / 2 + 1: score every half-integer rank once
    scores = ndtri((0.5 * np.arange(2 * size - 1) + 1.0 - 0.375) / (size + 0.25))
    z = np.empty_like(flat)
    np.put_along_axis(z, order, scores[first + last], axis=1)
    return z.reshape(x.shape)


def _rhat(x):
    """Gelman-Rubin R-hat of ``(E, C, n)`` (chains as given)."""
    n = x.shape[-1]
    within = x.var(-1, ddof=1).mean(-1)
    between = n * x.mean(-1).var(-1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt((between / within + n - 1) / n)


def _ess(x):
    """ESS of ``(E, C, n)`` (chains as given): autocorrelations pooled over chains, summed up to
    Geyer's initial positive sequence made monotone."""
    elements, chains, n = x.shape
    size = chains * n
    centred = x - x.mean(-1, keepdims=True)
    length = scipy.fft.next_fast_len(2 * n)
    spectrum = scipy.fft.rfft(centred, n=length, axis=-1)
    acov = scipy.fft.irfft(spectrum * spectrum.conj(), n=length, axis=-1)[..., :n] / n
    mean_var = acov[..., 0].mean(-1) * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if chains > 1:
        var_plus = var_plus + x.mean(-1).var(-1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = 1.0 - (mean_var[:, None] - acov.mean(1)) / var_plus[:, None]
    rho[:, 0] = 1.0
    pairs = rho[:, : 2 * (n // 2)].reshape(elements, -1, 2).sum(-1)
    last_pair = -(-(n - 2) // 2) - 1  # the last pair (2k, 2k + 1) that Geyer's scan looks at
    if last_pair < 1:
        stop = np.zeros(elements, int)
    else:
        ended = pairs[:, : last_pair + 1] <= 0
        stop = np.where(ended.any(1), ended.argmax(1), last_pair)
    monotone = np.minimum.accumulate(pairs, axis=1)
    kept = np.arange(pairs.shape[1]) < stop[:, None]
    rows = np.arange(elements)
    even = rho[rows, 2 * stop]
    included = (stop > 0) & (pairs[rows, stop] >= 0)
    tau = -1.0 + 2.0 * np.where(kept, monotone, 0.0).sum(1)
    tau = tau + np.where((even > 0) | included, even, 0.0)
    ess = size / np.maximum(tau, 1.0 / np.log10(size))
    ess = np.where(np.isnan(rho).any(1), np.nan, ess)
    constant = np.ptp(x.reshape(elements, -1), axis=1) < np.finfo(float).resolution
    return np.where(constant, float(size), ess)


def rank_diagnostics(x: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r_hat, ess_bulk, ess_tail)`` of every element of ``x (elements, chains, draws)``:
    ArviZ's rank-normalised split R-hat (NaN with one chain), bulk ESS and tail ESS (the smaller
    of the 5 % and 95 % quantiles' ESS), each an array ``(elements,)``. Needs 4 draws."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 3 or x.shape[-1] < _MIN_DRAWS:
        raise ValueError(f"x must have shape (elements, chains, draws >= 4), got {x.shape}")
    split = _split(x)
    scores = _z_scale(split)  # the R-hat's and the bulk ESS's, ranked once
    if x.shape[1] > 1:
        folded = np.abs(split - np.median(split.reshape(len(x), -1), axis=1)[:, None, None])
        r_hat = np.maximum(_rhat(scores), _rhat(_z_scale(folded)))
    else:
        r_hat = np.full(len(x), np.nan)
    ess_bulk = _ess(scores)
    flat = x.reshape(len(x), -1)
    ess_tail = np.minimum(
        *(
            _ess(_split((x <= np.quantile(flat, p, axis=1)[:, None, None]).astype(float)))
            for p in _TAIL_PROB
        )
    )
    return r_hat, ess_bulk, ess_tail


def screen(x: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``(r_hat, rho)`` of every element of ``x (elements, chains, draws >= 4)`` in one pass of
    array operations, no sort and no FFT: the larger of the plain split R-hat of the values and
    of their distances from the pooled mean (NaN where a within-chain variance vanishes), and
    the lag-1 autocorrelation pooled over the split chains. What picks the elements of a large
    variable that get the rank-normalised diagnostics (module docstring)."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 3 or x.shape[-1] < _MIN_DRAWS:
        raise ValueError(f"x must have shape (elements, chains, draws >= 4), got {x.shape}")
    split = _split(x)
    folded = np.abs(split - split.mean(axis=(1, 2), keepdims=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_hat = np.fmax(_rhat(split), _rhat(folded))
        centred = split - split.mean(-1, keepdims=True)
        lagged = np.sum(centred[..., 1:] * centred[..., :-1], axis=(1, 2))
        rho = lagged / np.sum(centred * centred, axis=(1, 2))
    return r_hat, rho


def _suspects(r_hat, rho, budget):
    """The ``budget`` elements to rank: half with the largest screened R-hat, the rest with the
    largest autocorrelation among the others (NaN counts as largest; ties by position)."""

    def worst_first(values):
        return np.argsort(-np.where(np.isnan(values), np.inf, values), kind="stable")

    chosen = worst_first(r_hat)[: budget // 2]
    by_rho = worst_first(rho)
    by_rho = by_rho[~np.isin(by_rho, chosen)][: budget - len(chosen)]
    return np.sort(np.concatenate([chosen, by_rho]))


def _chain_groups(groups, num_chains):
    """``groups`` (None, a label per chain, or lists of chain indices) as index arrays."""
    if groups is None:
        return [np.arange(num_chains)]
    labels = np.asarray(groups, dtype=object)
    if labels.ndim == 1 and len(labels) == num_chains and all(np.ndim(g) == 0 for g in groups):
        labels = np.asarray(groups)
        return [np.flatnonzero(labels == label) for label in np.unique(labels)]
    indices = [np.asarray(group, dtype=int).reshape(-1) for group in groups]
    every = np.sort(np.concatenate(indices)) if indices else np.array([], int)
    if not np.array_equal(every, np.arange(num_chains)):
        raise ValueError(
            f"groups must give a label to each of the {num_chains} chains, or list every chain "
            f"index once; got {groups!r}"
        )
    return indices


def _element_names(name, event_shape):
    if not event_shape:
        return [name]
    return [f"{name}[{','.join(map(str, i))}]" for i in np.ndindex(*event_shape)]


def _chains_text(chains):
    shown = ", ".join(str(int(c)) for c in chains[:6])
    return shown + (f", … ({len(chains)} in all)" if len(chains) > 6 else "")


def _real_parts(variables):
    """``(name, array)`` for every variable, complex ones as their ``.real`` and ``.imag``."""
    for name, values in variables.items():
        values = np.asarray(values)
        if np.iscomplexobj(values):
            yield f"{name}.real", values.real
            yield f"{name}.imag", values.imag
        else:
            yield name, values


def _checked(x):
    """``(finite, varies)`` masks of the elements of ``x (elements, chains, draws)``: finite
    draws, and a spread above round-off (constants such as Casimirs say nothing)."""
    finite = np.isfinite(x).all((1, 2))
    flat = x.reshape(len(x), -1)
    with np.errstate(invalid="ignore"):
        size = np.max(np.abs(flat), axis=1, initial=1e-300)
        varies = finite & (np.ptp(flat, axis=1) > 1e-9 * size)
    return finite, varies


class _Variable:
    """One real variable's draws ``(chains, draws, elements)`` taken in batches of about
    :data:`_BATCH_VALUES` draws (bounded temporaries): ``elements(index, group)`` is the
    ``(elements, chains of group, draws)`` array of the elements ``index``."""

    def __init__(self, name, array):
        chains, draws = array.shape[:2]
        self.names = np.array(_element_names(name, array.shape[2:]), dtype=object)
        self.flat = array.reshape(chains, draws, -1)
        self.batch = max(1, _BATCH_VALUES // (chains * draws))

    def batches(self, index):
        for first in range(0, len(index), self.batch):
            yield index[first : first + self.batch]

    def elements(self, index, group):
        return np.moveaxis(self.flat[..., index].astype(float), -1, 0)[:, group]


def _group_rows(variable, group):
    """Rows ``(name, r_hat, ess_bulk, ess_tail, chains)`` of the elements of one variable
    that are finite and vary, within the chains ``group``, and the count of non-finite ones; a
    variable of more than :data:`MAX_RANKED_ELEMENTS` such elements is screened and ranked in
    part (module docstring)."""
    every = np.arange(variable.flat.shape[-1])
    masks = [_checked(variable.elements(index, group)) for index in variable.batches(every)]
    finite = np.concatenate([m[0] for m in masks])
    checked = every[np.concatenate([m[1] for m in masks])]
    rows = []
    if len(checked) > MAX_RANKED_ELEMENTS:
        screens = [screen(variable.elements(i, group)) for i in variable.batches(checked)]
        screened = np.concatenate([r for r, _ in screens])
        rho = np.concatenate([a for _, a in screens])
        ranked = _suspects(screened, rho, MAX_RANKED_ELEMENTS)
        if len(group) > 1:  # R-hat compares chains
            others = np.setdiff1d(np.arange(len(checked)), ranked, assume_unique=True)
            flagged = others[~(screened[others] <= MAX_RHAT)]  # NaN (frozen chains) counts
            values = np.nan_to_num(screened[flagged], nan=np.inf)
            rows = [(n, r, np.nan, np.nan, group)
                    for n, r in zip(variable.names[checked[flagged]], values)]  # fmt: skip
        checked = checked[ranked]
    for index in variable.batches(checked):
        r_hat, bulk, tail = rank_diagnostics(variable.elements(index, group))
        names = variable.names[index]
        rows += [(n, r, b, t, group) for n, r, b, t in zip(names, r_hat, bulk, tail)]
    return rows, int(np.sum(~finite))


def _rows(variables, groups):
    """One row per checked element and law group: ``(name, r_hat, ess_bulk, ess_tail,
    chains)``, and the number of elements left out as not finite."""
    rows, not_finite = [], 0
    for name, array in _real_parts(variables):
        variable = _Variable(name, array)
        for group in groups:
            found, bad = _group_rows(variable, group)
            rows += found
            not_finite += bad
    return rows, not_finite


def convergence_warnings(
    variables: Mapping[str, npt.ArrayLike], groups: npt.ArrayLike | Sequence | None = None
) -> list[str]:
    """Messages on the convergence of every element of every variable (empty: nothing found).

    Parameters
    ----------
    variables : dict[str, array]
        Name -> draws ``(chains, draws, *event)`` (positions and observables; a complex array
        is checked as its real and imaginary parts). Every variable has the same chains and
        draws.
    groups : None, array of labels ``(chains,)``, or lists of chain indices
        The chains that sample one law (an orbit sampler's ``law_groups``): R-hat and ESS are
        computed within each group. ``None``: all chains sample one law.

    Each element (a vector component, a matrix entry) that varies by more than round-off
    (a Casimir does not) gets the rank-normalised split R-hat and the bulk and tail ESS
    (:func:`rank_diagnostics`); the messages name the elements and the values where R-hat is
    above :data:`MAX_RHAT` (chains in different modes, chains still near their starts, a
    drifting, improper target) and where an ESS is below :data:`MIN_ESS_PER_CHAIN` per chain
    of the group. They also say when the checks cannot be made: fewer than 4 draws, or no law
    group with two chains (R-hat compares chains).
    """
    if not variables:
        return []
    shapes = {np.shape(values)[:2] for values in variables.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(
            "every variable must have shape (chains, draws, ...) with the same chains and draws, "
            f"got {sorted(map(str, shapes))}"
        )
    num_chains, num_draws = next(iter(shapes))
    if num_draws < _MIN_DRAWS:
        return [
            (
                f"convergence cannot be checked with {num_draws} draw(s) per chain: split "
                f"R-hat and ESS need at least {_MIN_DRAWS} (and a few hundred to be reliable)"
            )
        ]
    groups = _chain_groups(groups, num_chains)
    messages = []
    if max(len(group) for group in groups) < 2:
        messages.append(
            "R-hat cannot be computed: "
            + ("the run has one chain" if num_chains == 1 else "no two chains sample one law")
            + ", so nothing shows whether the draws depend on where the chain started or which "
            "mode it found. Run 4 or more chains from spread-out starts"
            + ("" if num_chains == 1 else " on each law (orbit)")
        )
    rows, not_finite = _rows(variables, groups)
    if not_finite:
        messages.append(f"{not_finite} element(s) hold non-finite draws and were not checked")
    several = len(groups) > 1

    def label(row):
        return row[0] + (f" (chains {_chains_text(row[4])})" if several else "")

    high = sorted((row for row in rows if row[1] > MAX_RHAT), key=lambda row: -row[1])
    if high:
        shown = "; ".join(f"{label(row)}: {row[1]:.3g}" for row in high[:_SHOWN])
        more = f" (and {len(high) - _SHOWN} more)" if len(high) > _SHOWN else ""
        messages.append(
            f"R-hat > {MAX_RHAT:g} for {len(high)} element(s): {shown}{more}. The chains "
            "disagree: they sit in different modes, have not forgotten their starts, or drift "
            "(an improper target); their pooled draws are not the posterior. Run longer, start "
            "from spread-out points, or reparametrise a multimodal or improper model"
        )
    low = sorted(
        (row for row in rows if min(row[2], row[3]) < MIN_ESS_PER_CHAIN * len(row[4])),
        key=lambda row: min(row[2], row[3]) / len(row[4]),
    )
    if low:
        shown = "; ".join(
            f"{label(row)}: bulk {row[2]:.0f}, tail {row[3]:.0f}" for row in low[:_SHOWN]
        )
        more = f" (and {len(low) - _SHOWN} more)" if len(low) > _SHOWN else ""
        messages.append(
            f"ESS below {MIN_ESS_PER_CHAIN} per chain for {len(low)} element(s) ({num_draws} "
            f"draws per chain): {shown}{more}. Estimates and R-hat are unreliable; run more "
            "draws"
        )
    return messages
