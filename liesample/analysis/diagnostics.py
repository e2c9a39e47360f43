"""Convergence and accuracy diagnostics for sampler output.

Sampler runs produce ``positions`` shaped ``(chains, draws, *event_shape)`` and an ``info``
record of per-draw arrays shaped ``(chains, draws)``. This module turns them into an ArviZ
``xarray.DataTree``, tabulates Monte-Carlo estimates against exact values using ArviZ's
ESS, R-hat and MCSE, and computes the FFT autocovariances used to check time correlations.
Errors of means of correlated draws by blocking, and of functions of several means (specific
heat, susceptibility, Binder cumulant) by the jackknife over blocks.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, NamedTuple

import jax
import numpy as np
import numpy.typing as npt
import scipy.fft

from liesample.foundation.types import PyTree
from liesample.foundation.validation import is_single_array
from liesample.samplers.contract import SAMPLE_STATS_NAMES

if TYPE_CHECKING:  # ArviZ, xarray and pandas load when a function needs them (import liesample
    import pandas as pd  # stays as cheap as importing jax and blackjax)
    import xarray as xr

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

# Sampler info key -> ArviZ ``sample_stats`` name: the Info contract's, and ``nonfinite``
# (the divergence flag's name in liesample < 0.2 output) read as ``diverging``.
_SAMPLE_STATS_NAMES = {**SAMPLE_STATS_NAMES, "nonfinite": "diverging"}
_DIVERGENCE_KEYS = ("is_divergent", "diverging", "nonfinite")

# Quantiles for the tail ESS (Vehtari et al. 2021): min of the ESS of the 5% and 95% quantiles.
_TAIL_PROB = (0.05, 0.95)
_MIN_DRAWS = 4

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


# --------------------------------------------------------------------------- input handling


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


def _netcdf_attr(value):
    """Convert ``value`` to something NetCDF can store as an attribute, or ``None`` to drop it.

    NetCDF has no boolean attribute (xarray refuses to write one): a boolean (``adapted``,
    say) is stored as the integer ``1`` or ``0``, which keeps its truth value when read back
    (the strings ``"true"``/``"false"`` would not: ``"false"`` is truthy), as are the entries
    of a boolean array. Arrays become lists, other objects their ``str``."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (str, int, float)):
        return value
    arr = np.asarray(value) if not isinstance(value, Mapping) else None
    if arr is not None and arr.dtype.kind in "biuf":
        if arr.dtype.kind == "b":
            arr = arr.astype(np.int8)
        return arr.item() if arr.ndim == 0 else arr.ravel().tolist()
    if arr is not None and arr.dtype.kind == "U":
        return str(arr.item()) if arr.ndim == 0 else [str(s) for s in arr.ravel()]
    return str(value)


# --------------------------------------------------------------------------- DataTree


def _leaf_name(path) -> str:
    """A posterior variable's name from a pytree key path: dict keys as given, sequence
    entries ``x0``, ``x1``…, named-tuple fields by name; nested keys joined with ``.``."""
    parts = []
    for key in path:
        if isinstance(key, jax.tree_util.DictKey):
            parts.append(str(key.key))
        elif isinstance(key, jax.tree_util.SequenceKey):
            parts.append(f"x{key.idx}")
        elif isinstance(key, jax.tree_util.GetAttrKey):
            parts.append(key.name)
        elif isinstance(key, jax.tree_util.FlattenedIndexKey):
            parts.append(f"x{key.key}")
        else:
            parts.append(str(key))
    return ".".join(parts)


def pytree_variables(positions: PyTree) -> dict[str, tuple[np.ndarray, str]]:
    """``{variable name: (real array, leaf name)}`` for the leaves of a pytree of draws.

    Each leaf ``(chains, draws, *event)`` is named from its key path (:func:`_leaf_name`); a
    complex leaf ``U`` gives two real variables ``U.real`` and ``U.imag`` (ArviZ's ESS and R-hat
    need real arrays), both with the event dims of ``U``.

    Examples
    --------
    A complex leaf is split into its real and imaginary parts:

    >>> import numpy as np
    >>> from liesample.diagnostics import pytree_variables
    >>> draws = {"mu": np.zeros((2, 5, 3)), "U": np.zeros((2, 5, 2, 2), complex)}
    >>> sorted(pytree_variables(draws))
    ['U.imag', 'U.real', 'mu']
    """
    paths, _ = jax.tree_util.tree_flatten_with_path(positions)
    if not paths:
        raise ValueError("positions is an empty pytree: it has no arrays")
    variables: dict[str, tuple[np.ndarray, str]] = {}
    for path, leaf in paths:
        name = _leaf_name(path)
        leaf = np.asarray(leaf)
        if leaf.ndim < 2:
            raise ValueError(
                f"positions leaf {name!r} must have shape (chains, draws, *event_shape), got "
                f"shape {leaf.shape}"
            )
        parts = (
            {f"{name}.real": leaf.real, f"{name}.imag": leaf.imag}
            if np.iscomplexobj(leaf)
            else {name: leaf}
        )
        for part, value in parts.items():
            if part in variables:
                raise ValueError(
                    f"two leaves of positions are both named {part!r}: rename the pytree's keys"
                )
            variables[part] = (value, name)
    shapes = {value.shape[:2] for value, _ in variables.values()}
    if len(shapes) > 1:
        raise ValueError(
            "every leaf of positions must have the same (chains, draws) sizes, got "
            f"{sorted(shapes)}"
        )
    return variables


DEFAULT_EVENT_DIMS = {0: (), 1: ("component",), 2: ("row", "col")}
"""Dims of a single array's event axes by their number, when ``event_dims`` is not given."""


def to_datatree(
    positions: PyTree | None,
    info: Mapping | tuple | object | None = None,
    *,
    var_name: str | None = None,
    event_dims: Sequence[str] | Mapping[str, Sequence[str]] | None = None,
    coords: Mapping[str, Sequence] | None = None,
    step_size: float | None = None,
    thinning: int = 1,
    attrs: Mapping | None = None,
    observables: PyTree | None = None,
    energy_name: str = "energy",
) -> xr.DataTree:
    """Package sampler output as an ArviZ ``DataTree``.

    Parameters
    ----------
    positions : array_like ``(chains, draws, *event_shape)``, a pytree of such arrays, or None
        Sampled states (``None``: only ``observables`` were kept). A pytree (dict, tuple, named
        tuple: the positions of the geometric samplers on product spaces) gives one posterior
        variable per leaf, named from its key path: dict keys and named-tuple fields as given
        (``mu``, ``log_kappa``), tuple entries ``x0``, ``x1``…, nested keys joined with ``.``
        (``{"a": {"b": …}}`` -> ``a.b``). Its event dims are ``<name>_dim_0``, ``<name>_dim_1``…. A
        complex leaf ``U`` (``SU(n)`` matrices) is stored as the two real variables ``U.real`` and
        ``U.imag``, sharing the dims of ``U``. ESS, R-hat and MCSE computed from the tree are those
        of these ambient coordinates (vector components, matrix entries), not of intrinsic
        coordinates on the group or sphere. A list is read as one array.
    info : mapping, NamedTuple or dataclass, optional
        Per-draw arrays shaped ``(chains, draws)`` (the Info contract of
        :mod:`liesample.samplers.contract`). Recognised keys are renamed to ArviZ's
        ``sample_stats`` names: ``is_divergent`` -> ``diverging`` (stored as bool; a legacy
        ``nonfinite`` too), ``energy`` -> ``energy_name``, ``acceptance_rate`` and
        ``casimir_error`` unchanged. Other keys are stored under their own names. ``None``
        gives a tree without ``sample_stats``.
    var_name : str, default "mu"
        Name of the sampled variable in the ``posterior`` group (single-array positions, split
        into ``<var_name>.real`` and ``<var_name>.imag`` when complex; a pytree's variables are
        named from its key paths).
    event_dims : sequence of str, optional
        Dimension names for the event axes; one per axis after (chain, draw). Default: by the
        event's rank, ``()``, ``("component",)``, ``("row", "col")``, else ``dim_k``. For pytree
        positions, optionally a mapping from a leaf's name to its dims (the others keep
        ``<name>_dim_k``).
    coords : mapping, optional
        Coordinate values by dimension name. Event dimensions without coordinates get
        ``["x", "y", "z"]`` for a single axis of length 3, otherwise ``0, 1, ...``.
    step_size : float, optional
        Integrator step size, stored as an attribute.
    thinning : int, default 1
        Thinning factor between stored draws, stored as an attribute.
    attrs : mapping, optional
        Extra run metadata (sampler name, seed, ...). Stored on the root and on both groups;
        ``None`` values are dropped and the others made NetCDF-safe, so that
        ``tree.to_netcdf(path)`` writes them: a boolean is stored as ``1`` or ``0``
        (:func:`_netcdf_attr`).
    observables : array_like ``(chains, draws, *shape)`` or a pytree of such arrays, optional
        Functions of the state recorded at each draw (``observables=`` of
        :func:`liesample.sample`): extra ``posterior`` variables, so that ArviZ's summary, ESS
        and R-hat act on them. A dict's keys (key paths, as for pytree positions) name them, a
        single array is named ``observable``; dims ``<name>_dim_k`` unless ``event_dims`` (a
        mapping) names them. Their names must differ from the positions'.
    energy_name : str, default "energy"
        The ``sample_stats`` name of ``info["energy"]``: ``"energy"`` (ArviZ's, which its
        ``bfmi`` and ``plot_energy`` read as HMC's total energy) or ``"hamiltonian"`` (``h``
        of a state without a momentum; :func:`liesample.samplers.contract.energy_name`).

    Returns
    -------
    xarray.DataTree
        Groups ``posterior`` and (if ``info`` is given) ``sample_stats``.

    Examples
    --------
    >>> import numpy as np
    >>> from liesample.diagnostics import to_datatree
    >>> tree = to_datatree(np.zeros((2, 5, 3)), {"is_divergent": np.zeros((2, 5), bool)})
    >>> tree.posterior["mu"].dims, list(tree.sample_stats.data_vars)
    (('chain', 'draw', 'component'), ['diverging'])
    """
    if positions is None and observables is None:
        raise ValueError("to_datatree needs positions, observables or both; got neither")
    single = positions is not None and is_single_array(positions)
    variables, leaf_dims = _posterior_variables(positions, var_name, event_dims, observables)
    if isinstance(thinning, bool) or int(thinning) != thinning or thinning < 1:
        raise ValueError(f"thinning must be a positive integer, got {thinning!r}")
    dims, all_coords = _dims_and_coords(variables, leaf_dims, single, coords)
    sample_shape = next(iter(variables.values()))[0].shape[:2]
    sample_stats = _sample_stats(info, sample_shape, energy_name)
    run_attrs = _tree_attrs({"thinning": int(thinning), "step_size": step_size, **(attrs or {})})
    data = {"posterior": {name: value for name, (value, _) in variables.items()}}
    group_attrs = {"/": run_attrs, "posterior": run_attrs}
    if sample_stats:
        data["sample_stats"] = sample_stats
        group_attrs["sample_stats"] = run_attrs
    from arviz_base import from_dict

    return from_dict(data, dims=dims, coords=all_coords, attrs=group_attrs)


def _tree_attrs(attrs: Mapping) -> dict:
    """``attrs`` as NetCDF-safe attributes (:func:`_netcdf_attr`), ``None`` values dropped."""
    converted = {str(k): _netcdf_attr(v) for k, v in attrs.items()}
    return {k: v for k, v in converted.items() if v is not None}


def _posterior_variables(positions, var_name, event_dims, observables):
    """``({variable: (array, leaf name)}, {leaf name: event dims})`` of the positions and the
    observables, which must have the same ``(chains, draws)`` sizes."""
    variables, leaf_dims = _position_variables(positions, var_name, event_dims)
    observed = _observed_variables(observables, variables)
    if positions is None or not is_single_array(positions):
        leaf_dims = _pytree_leaf_dims(event_dims, [*variables.values(), *observed.values()])
    variables = {**variables, **observed}
    for value, leaf in variables.values():
        leaf_dims.setdefault(leaf, tuple(f"{leaf}_dim_{k}" for k in range(value.ndim - 2)))
    shapes = {value.shape[:2] for value, _ in variables.values()}
    if len(shapes) > 1:
        raise ValueError(
            "positions and observables must have the same (chains, draws) sizes, got "
            f"{sorted(shapes)}"
        )
    return variables, leaf_dims


def _position_variables(positions, var_name, event_dims):
    """``({variable: (array, leaf name)}, {leaf name: event dims})`` of the positions (the
    second is empty for a pytree, whose dims :func:`_pytree_leaf_dims` reads)."""
    if positions is None:
        if var_name is not None:
            raise ValueError("var_name names the positions, and there are none (positions=None)")
        return {}, {}
    if not is_single_array(positions):
        if var_name is not None:
            raise ValueError(
                "var_name names a single array of positions; the variables of pytree positions "
                "are named from their key paths"
            )
        return pytree_variables(positions), {}
    var_name = "mu" if var_name is None else var_name
    if not isinstance(var_name, str) or not var_name:
        raise ValueError(f"var_name must be a non-empty string, got {var_name!r}")
    if isinstance(event_dims, Mapping):
        raise TypeError("event_dims must be a sequence of dim names for array positions")
    pos = np.asarray(positions)
    if pos.ndim < 2:
        raise ValueError(
            f"positions must have shape (chains, draws, *event_shape), got shape {pos.shape}"
        )
    if event_dims is None:
        event_dims = DEFAULT_EVENT_DIMS.get(
            pos.ndim - 2, tuple(f"dim_{k}" for k in range(pos.ndim - 2))
        )
    if np.iscomplexobj(pos):  # as for a pytree's complex leaf: two real variables
        variables = {f"{var_name}.real": (pos.real, var_name)}
        variables[f"{var_name}.imag"] = (pos.imag, var_name)
    else:
        variables = {var_name: (pos, var_name)}
    return variables, {var_name: tuple(event_dims)}


def _observed_variables(observables, variables) -> dict[str, tuple[np.ndarray, str]]:
    """The observables' variables (as :func:`pytree_variables`), whose names must differ from
    the positions' ``variables``."""
    if observables is None:
        return {}
    observed = {"observable": observables} if is_single_array(observables) else observables
    try:
        observed = pytree_variables(observed)
    except ValueError as error:
        raise ValueError(str(error).replace("positions", "observables")) from None
    clash = sorted(set(observed) & set(variables))
    if clash:
        raise ValueError(f"observables {clash} have the names of position variables: rename them")
    return observed


def _pytree_leaf_dims(event_dims, variables) -> dict[str, tuple[str, ...]]:
    """The event dims that ``event_dims`` (a mapping, or ``None``) gives the leaves of pytree
    positions and observables, whose ``(value, leaf name)`` pairs are ``variables``."""
    given = {} if event_dims is None else event_dims
    if not isinstance(given, Mapping):
        raise TypeError(
            "event_dims for pytree positions must be a mapping {leaf name: dims}, got "
            f"{event_dims!r}"
        )
    unknown = sorted(set(given) - {leaf for _, leaf in variables})
    if unknown:
        raise ValueError(f"event_dims names no leaf of positions: {unknown}")
    return {leaf: tuple(dims) for leaf, dims in given.items()}


def _dims_and_coords(variables, leaf_dims, single, coords):
    """``({variable: its event dims}, {dim: coordinate values})``: ``coords`` where given, else
    ``x, y, z`` for a single axis of length 3, else ``0, 1, …``; checked against the sizes."""
    all_coords: dict[str, Sequence] = {}
    dims: dict[str, list[str]] = {}
    for name, (value, leaf) in variables.items():
        label = "positions" if single else f"positions {name!r}"
        value = _chain_draw_array(value, label, ndims=(value.ndim,))
        event_shape, event = value.shape[2:], leaf_dims[leaf]
        if len(event) != len(event_shape):
            raise ValueError(
                f"event_dims must name each event axis of positions: got {event} for "
                f"event shape {event_shape}"
            )
        dims[name] = list(event)
        for dim, size in zip(event, event_shape, strict=True):
            if len(event_shape) == 1 and size == 3:
                all_coords.setdefault(dim, ["x", "y", "z"])
            else:
                all_coords.setdefault(dim, list(range(size)))
    if coords is not None:
        all_coords.update(coords)
    for name, (value, _) in variables.items():
        for dim, size in zip(dims[name], value.shape[2:], strict=True):
            if len(all_coords[dim]) != size:
                raise ValueError(
                    f"coords[{dim!r}] has {len(all_coords[dim])} values but positions "
                    f"{name!r} has {size} along that axis"
                )
    return dims, all_coords


def _sample_stats(info, sample_shape, energy_name: str) -> dict[str, np.ndarray]:
    """``info``'s arrays under their ``sample_stats`` names (the divergence flag as bool,
    ``energy`` as ``energy_name``), each checked to have the ``(chains, draws)`` sizes
    ``sample_shape``."""
    if not isinstance(energy_name, str) or not energy_name:
        raise ValueError(
            f'energy_name must be a non-empty string ("energy" or "hamiltonian"), got '
            f"{energy_name!r}"
        )
    names = {**_SAMPLE_STATS_NAMES, "energy": energy_name}
    sample_stats: dict[str, np.ndarray] = {}
    for key, value in _info_dict(info).items():
        if value.shape[:2] != sample_shape:
            raise ValueError(
                f"info[{key!r}] must have leading shape (chains, draws) = "
                f"{sample_shape} like positions, got shape {value.shape}"
            )
        name = names.get(key, key)
        if name == "diverging":
            value = value.astype(bool)
        sample_stats[name] = value
    return sample_stats


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


# --------------------------------------------------------------------------- errors of means


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
    (:func:`specific_heat` does this, with the energy shifted first).

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


def _per_draw(values):
    arr = np.asarray(values, dtype=float)
    return arr[None] if arr.ndim == 1 else arr


def _magnetisation_norm(magnetisation):
    """``|m|`` per draw: the value of a scalar magnetisation ``(chains, draws)``, the norm of
    a vector one ``(chains, draws, components)``."""
    m = np.asarray(magnetisation, dtype=float)
    if m.ndim == 3:
        return np.linalg.norm(m, axis=-1)
    if m.ndim in (1, 2):
        return np.abs(_per_draw(m))
    raise ValueError(
        "magnetisation must have shape (chains, draws) or (chains, draws, components), got "
        f"shape {m.shape}"
    )


def _positive(name, value):
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def specific_heat(
    energy: npt.ArrayLike, beta: float, num_sites: int, *, block_size: int | None = None
) -> JackknifeResult:
    """Specific heat per site ``C = β² (⟨E²⟩ − ⟨E⟩²) / N`` with its jackknife error.

    Parameters
    ----------
    energy : array_like, shape (chains, draws) or (draws,)
        The total energy ``E`` (the Hamiltonian) at each draw, e.g. recorded with
        ``observables={"h": system.hamiltonian}``.
    beta : float
        Inverse temperature of the run (any sign).
    num_sites : int or float
        ``N``, the number of sites (spins, vortices) the heat capacity is divided by; ``1``
        gives the total heat capacity.
    block_size : int, optional
        As for :func:`jackknife`.

    Notes
    -----
    The energy is shifted by its overall mean first (the variance is unchanged, the
    cancellation in ``⟨E²⟩ − ⟨E⟩²`` is avoided).

    Examples
    --------
    A constant energy has no fluctuations, so no specific heat:

    >>> import numpy as np
    >>> from liesample.diagnostics import specific_heat
    >>> float(specific_heat(np.full((2, 100), -3.0), beta=1.0, num_sites=4, block_size=10).estimate)
    0.0
    """
    beta = float(beta)
    num_sites = _positive("num_sites", num_sites)
    e = _per_draw(energy)
    e = e - np.mean(e)
    return jackknife(
        lambda m1, m2: beta**2 * (m2 - m1**2) / num_sites, e, e**2, block_size=block_size
    )


def susceptibility(
    magnetisation: npt.ArrayLike,
    beta: float,
    num_sites: int,
    *,
    connected: bool = True,
    block_size: int | None = None,
) -> JackknifeResult:
    """Magnetic susceptibility per site with its jackknife error.

    ``connected=True``: ``χ = β N (⟨m²⟩ − ⟨|m|⟩²)``, the finite-lattice convention that stays
    finite through an ordered phase (the order parameter of a finite lattice without field
    is ``⟨|m|⟩``, its ``⟨m⟩`` vanishes by symmetry). ``connected=False``:
    ``χ = β N ⟨m²⟩``, the susceptibility of the symmetric (disordered) phase, equal to the
    sum of the spin correlations ``β/N Σ_kl ⟨s_k·s_l⟩``.

    Parameters
    ----------
    magnetisation : array_like, shape (chains, draws), (chains, draws, components) or (draws,)
        The magnetisation per site ``m = (1/N) Σ_k s_k`` at each draw: a scalar (Ising-like)
        or a vector (Heisenberg spins; ``m² = |m|²``).
    beta : float
    num_sites : int or float
        ``N``.
    connected : bool
    block_size : int, optional
        As for :func:`jackknife`.

    Examples
    --------
    The disconnected susceptibility ``β N ⟨m²⟩`` of fully aligned spins is ``β N``:

    >>> import numpy as np
    >>> from liesample.diagnostics import susceptibility
    >>> m = np.tile([0.0, 0.0, 1.0], (2, 100, 1))
    >>> chi = susceptibility(m, beta=1.0, num_sites=4, connected=False, block_size=10)
    >>> float(chi.estimate)
    4.0
    """
    beta = float(beta)
    num_sites = _positive("num_sites", num_sites)
    norm = _magnetisation_norm(magnetisation)
    if connected:
        return jackknife(
            lambda a, m2: beta * num_sites * (m2 - a**2), norm, norm**2, block_size=block_size
        )
    return jackknife(lambda m2: beta * num_sites * m2, norm**2, block_size=block_size)


def binder_cumulant(
    magnetisation: npt.ArrayLike, *, block_size: int | None = None
) -> JackknifeResult:
    """Binder cumulant ``U = 1 − ⟨m⁴⟩ / (3 ⟨m²⟩²)`` with its jackknife error.

    ``m² = |m|²`` for a vector magnetisation. With this (Ising) normalisation ``U → 2/3`` in
    an ordered phase and, for a Gaussian ``n``-component ``m`` (disordered phase),
    ``U → 1 − (n + 2)/(3n)``: ``0`` for a scalar, ``4/9`` for Heisenberg spins.

    Parameters
    ----------
    magnetisation : array_like
        The magnetisation per site at each draw: ``(draws, components)`` for one chain or
        ``(chains, draws, components)`` for several, ``components`` being 2, 3 or 4 (O(2),
        O(3), O(4) spins); or a scalar one, ``(draws,)`` or ``(chains, draws)`` with more than
        4 draws per chain. Any other shape is a ``ValueError`` naming these.
    block_size : int, optional
        As for :func:`jackknife`.

    Examples
    --------
    Perfectly ordered spins (``|m| = 1`` at every draw) give the ordered phase's ``U = 2/3``:

    >>> import numpy as np
    >>> from liesample.diagnostics import binder_cumulant
    >>> m = np.tile([0.0, 0.0, 1.0], (2, 100, 1))  # (chains, draws, components)
    >>> bool(np.isclose(binder_cumulant(m, block_size=10).estimate, 2 / 3))
    True
    """
    m = np.asarray(magnetisation, dtype=float)
    if m.ndim == 2 and 2 <= m.shape[1] <= 4:
        m = m[None]  # one chain of a vector magnetisation
    if m.ndim not in (1, 2, 3) or (m.ndim == 2 and m.shape[1] < 2):
        raise ValueError(
            "magnetisation must have shape (draws, components) for one chain or (chains, draws, "
            "components) for several (components 2, 3 or 4), or (draws,) / (chains, draws) for "
            f"a scalar magnetisation; got shape {m.shape}"
        )
    squared = _magnetisation_norm(m) ** 2
    return jackknife(
        lambda m2, m4: 1.0 - m4 / (3.0 * m2**2), squared, squared**2, block_size=block_size
    )
