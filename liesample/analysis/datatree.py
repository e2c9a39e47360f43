"""Sampler output as an ArviZ ``xarray.DataTree``: posterior variables, their dims and
coordinates, the ``sample_stats`` group and NetCDF-safe run attributes.

:func:`to_datatree` packages ``positions`` (an array or a pytree of arrays shaped
``(chains, draws, *event_shape)``), recorded observables and the ``info`` record into the
``posterior`` and ``sample_stats`` groups that ArviZ's ESS, R-hat and plots read;
:func:`pytree_variables` names the variables of a pytree of draws (complex leaves split into
real and imaginary parts).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import jax
import numpy as np

from liesample.analysis.draw_arrays import _chain_draw_array, _info_dict
from liesample.foundation.types import PyTree
from liesample.foundation.validation import is_single_array
from liesample.samplers.contract import SAMPLE_STATS_NAMES

if TYPE_CHECKING:  # xarray loads when a function needs it (import liesample stays as cheap as
    import xarray as xr  # importing jax and blackjax)

__all__ = ["pytree_variables", "to_datatree"]


# Sampler info key -> ArviZ ``sample_stats`` name: the Info contract's, and ``nonfinite``
# (the divergence flag's name in liesample < 0.2 output) read as ``diverging``.
_SAMPLE_STATS_NAMES = {**SAMPLE_STATS_NAMES, "nonfinite": "diverging"}


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

    with warnings.catch_warnings():  # ArviZ guesses swapped axes when chains outnumber draws;
        # here the first two axes are named chain and draw, so a short run's tree is as meant
        warnings.filterwarnings("ignore", message="Found chain dimension to be longer")
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
