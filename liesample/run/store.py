"""A run saved in one NetCDF-4 file that is an ArviZ ``DataTree``, grown chunk by chunk.

The file holds the groups of the tree that :func:`liesample.sample` returns (``posterior``,
``sample_stats``; same variables, dims, coords and attributes), with an unlimited ``draw``
dimension, so ``xarray.open_datatree(path)`` or :func:`load_chains` reads it as ArviZ data. One
more group, ``liesample_run``, holds what a resume needs and what proves the file whole:

- ``fingerprint``: what made the run (:mod:`liesample.run.provenance`), checked on resume;
- ``state_<slot>_<i>``: leaf ``i`` of the chains' states after the last saved chunk, in two
  slots written in turn;
- ``chunk_end``, ``chunk_sha256``: where each saved chunk ends and a SHA-256 of its stored
  draws (every variable's slice and the ``draw`` coordinate);
- ``info_names``: each ``sample_stats`` variable's ``info`` key and dtype;
- ``commit``: ``draws_done``, the number of chunks, the state's slot and its SHA-256, and a
  SHA-256 of every attribute the run wrote (the root's, each group's and variable's, each
  field of ``fingerprint`` and ``info_names``) with a short checksum per attribute, so that an
  edited setting is refused by name.

A committed chunk stays readable whatever happens after it: the file is never modified in
place (HDF5 is not crash-safe in place: a write that fails half-way may break metadata that
earlier chunks share). Each chunk is written to a copy of the file beside it, whose new chunk,
state and commit are read back, and which then replaces the file in one rename
(:mod:`liesample.run.atomic`; that module gives the cost of the copies); a full disk, an I/O
error, an interrupt or a kill before the rename leaves the file as it was, and the next writer
removes a copy that a killed one left. Every HDF5 handle is closed
on every path, an error's included, so a failed write does not fail again at exit. Resuming and
:func:`load_chains` verify every checksum (:mod:`liesample.run.checksums`, which also computes
them as each chunk is written); an edited, truncated, empty or foreign file is refused with its
path, what is wrong and what to do (:class:`RunFileError`).

In a run whose chains span several processes (``jax.distributed``), process 0 is the writer
(:meth:`RunFile.open`) and every other process a reader (:meth:`RunFile.reader`: no lock, no
writes); on a resume each reads and verifies the file itself, and :func:`check_same_file`
refuses the run on every process unless all of them find the file that process 0 finds.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
from typing import TYPE_CHECKING, Any, cast

import jax
import jax.numpy as jnp
import numpy as np

from liesample.run import atomic
from liesample.run.checksums import (
    _START_AFRESH,
    CHUNK_ATTRS,
    RUN_GROUP,
    RunFileError,
    _attribute_fields,
    _attribute_sums,
    _check_attributes,
    _chunk_digest,
    _chunk_fields,
    _json_attr,
    _read_back,
    _run_group,
    _slices,
    _state_arrays,
    verify,
)
from liesample.run.lock import OutputLock
from liesample.run.provenance import FORMAT, differences

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "CHUNK_ATTRS",
    "RUN_GROUP",
    "Layout",
    "RunFile",
    "RunFileError",
    "check_output_path",
    "check_same_file",
    "load_chains",
    "saved_num_warmup",
    "verify",
]


def check_output_path(output, resume: bool) -> str:
    """``output`` as a path, refused at once if its directory is missing, it is a directory, or
    it exists and ``resume`` is False."""
    path = os.fspath(output)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise FileNotFoundError(
            f"output {path!r}: its directory {directory!r} does not exist; create it first"
        )
    if os.path.isdir(path):
        raise IsADirectoryError(
            f"output {path!r} is a directory; give a file in it, such as "
            f"{os.path.join(path, 'run.nc')!r}"
        )
    if os.path.exists(path) and not resume:
        raise FileExistsError(
            f"output {path!r} exists; pass resume=True to continue the run saved there, or "
            "choose another path"
        )
    return path


def _unreadable(path, error) -> str:
    return (
        f"{path!r} is not a readable NetCDF-4 (HDF5) file: it is empty, truncated, damaged or "
        f"of another kind ({error}), and holds no draws that liesample can read; " + _START_AFRESH
    )


@contextlib.contextmanager
def _open(path):
    """``(f, h5)``: the file at ``path`` opened for reading with h5netcdf (its structure and
    attributes, ``f``) on an h5py handle (its data, read many times faster, ``h5``) closed
    however the block ends; any error reading it is a :class:`RunFileError` naming the path."""
    import h5netcdf
    import h5py

    try:
        h5 = h5py.File(path, "r")
    except Exception as error:
        raise RunFileError(_unreadable(path, error)) from None
    try:
        try:
            h5.attrs.get("_nc3_strict")  # what h5netcdf reads first, before it is set up
            f = h5netcdf.File(h5, "r")
        except Exception as error:
            raise RunFileError(_unreadable(path, error)) from None
        try:
            yield f, h5
        except RunFileError:
            raise
        except Exception as error:
            raise RunFileError(
                f"{path!r} is incomplete or corrupt ({error!r}): its draws cannot be read; "
                + _START_AFRESH
            ) from None
        finally:
            f.close()
    finally:
        h5.close()


@contextlib.contextmanager
def _writing(path, new: bool):
    """``path`` (the copy a new version of a run file is written to) opened for writing with
    h5netcdf (created if ``new``). Its HDF5 handle is closed however the block ends: after an
    error the copy, discarded anyway, is emptied first, which frees the space HDF5 needs to
    write out what it holds and close (a handle left open fails again, and may crash, at
    exit)."""
    import h5netcdf
    import h5py

    h5 = h5py.File(path, "w" if new else "r+", track_order=True)
    f = None
    try:
        f = h5netcdf.File(h5, "w" if new else "a")
        yield f
        f.flush()
        h5.flush()  # everything written out here, while nothing is closed: it may fail
        f.close()
        h5.close()
    except BaseException as error:
        with contextlib.suppress(OSError):
            os.truncate(path, 0)
        for close in ([] if f is None else [f.close]) + [h5.close, h5.close]:
            with contextlib.suppress(Exception):
                close()
        if isinstance(error, RuntimeError):  # h5py's word for some failed writes
            code = re.search(r"errno = (\d+)", str(error))
            raise OSError(int(code[1]) if code else errno.EIO, str(error)) from None
        raise


def _header(path: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(fingerprint, info_names)`` of the run file at ``path``, after checking its format,
    its commit record and its attributes (not yet its draws: :func:`verify`)."""
    with _open(path) as (f, _):
        group = _run_group(f, path)
        _check_attributes(f, path, _json_attr(group, "commit", path))
        return _json_attr(group, "fingerprint", path), _json_attr(group, "info_names", path)


def _check_names(f, tree, path):
    """Refuse to add ``tree``'s draws to a file whose groups lack one of its variables (a file
    written by a liesample that named them otherwise: ``h`` of a momentum-free sampler was once
    ``sample_stats/energy``, now ``hamiltonian``)."""
    missing = [
        f"{name}/{var}"
        for name, child in tree.children.items()
        for var in child.data_vars
        if name not in f.groups or var not in f.groups[name].variables
    ]
    if missing:
        raise RunFileError(
            f"cannot resume {path!r}: it has no variables {missing} (it was written by a "
            "liesample that named its draws otherwise); load_chains still reads it; start a "
            "new output to go on sampling"
        )


def load_chains(path: str | os.PathLike[str]) -> xr.DataTree:
    """The run saved by ``sample_chains(..., output=path)`` or ``sample(..., output=path)``
    (complete or interrupted) as an ArviZ ``DataTree``: the groups, variables and attributes of
    the tree :func:`liesample.sample` returns, up to the last saved draw.

    Every checksum (the attributes', every chunk's and the saved state's) is verified first:
    an edited, truncated, empty or foreign file is refused with its path
    (:class:`RunFileError`). A run stopped by a full disk, an error or a kill holds every chunk
    it committed, and a copy that a killed writer left beside the file is not read.

    Examples
    --------
    A run saved as it goes, read back (10 draws only show the call: the run warns that they are
    too few):

    >>> import os, tempfile
    >>> system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    >>> starts = jnp.array([[1.5, 0.0, 0.0], [0.0, 1.5, 0.0]])
    >>> path = os.path.join(tempfile.mkdtemp(), "run.nc")
    >>> _ = liesample.sample_chains(liesample.adjusted_lie_poisson(system, beta=3.0, step_size=0.2),
    ...                             jax.random.key(0), starts, 10, progress_bar=False, output=path)
    >>> liesample.load_chains(path).posterior["mu"].shape  # (chain, draw, component)
    (2, 10, 3)
    """
    import xarray as xr

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no run file at {path!r}")
    with _open(path) as (f, h5):
        done = verify(f, h5, path)[0]["draws_done"]
    try:
        with xr.open_datatree(path, engine="h5netcdf") as tree:
            children = {
                name: child.to_dataset().isel(draw=slice(0, done)).load()
                for name, child in tree.children.items()
                if name != RUN_GROUP
            }
            root = dict(tree.attrs)
    except Exception as error:
        raise RunFileError(
            f"{path!r} passed its checks but xarray cannot read it ({error!r}); read it with "
            "xarray.open_datatree to see why"
        ) from None
    loaded = xr.DataTree.from_dict(children)
    loaded.attrs = root
    return loaded


def saved_num_warmup(path) -> int | None:
    """The ``num_warmup`` recorded in the run file at ``path`` (``None`` if there is none)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        return None
    fingerprint = _header(path)[0]
    try:
        return int(fingerprint["num_warmup"])
    except (KeyError, TypeError, ValueError):
        raise RunFileError(f"{path!r}: its fingerprint records no num_warmup") from None


def _to_stored(leaf):
    leaf = np.asarray(leaf)
    if leaf.dtype == bool:
        return leaf.astype(np.int8)
    return leaf


def _state_leaves(states):
    return [
        np.asarray(jax.random.key_data(leaf))
        if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key)
        else np.asarray(leaf)
        for leaf in jax.tree.leaves(states)
    ]


def _update_attrs(stored, attrs):
    for name in CHUNK_ATTRS:
        if name in attrs:
            stored[name] = attrs[name]


def check_same_file(views: list[str], output) -> None:
    """Refuse to go on unless every process of a run over several processes finds at
    ``output`` what process 0 does (``views``: each process's :meth:`RunFile.view`, by
    process index): on a resume every process reads the saved run, so the file must be on a
    file system that all of them see."""
    first = json.loads(views[0])
    problems = []
    for index, view in enumerate(views[1:], start=1):
        path, exists, seen = json.loads(view)
        if [exists, seen] == first[1:]:
            continue
        if first[1] and not exists:
            problems.append(f"process {index} finds no file at {path!r}")
        elif exists and not first[1]:
            problems.append(f"process {index} finds a file at {path!r}, process 0 none")
        else:
            problems.append(f"process {index} reads another run file at {path!r}")
    if problems:
        raise RunFileError(
            f"output {os.fspath(output)!r}: process 0 of {len(views)} "
            + ("resumes the run saved at" if first[1] else "finds no file at")
            + f" {first[0]!r}, but "
            + "; ".join(problems)
            + ". In a run over several processes process 0 alone writes the run file and on a "
            "resume every process reads it, so it must be on a file system that every process "
            "sees (a cluster's shared home or scratch directory, not a node's local disk such "
            "as /tmp), at a path that names it on every process (absolute, or relative to a "
            "working directory that is the same everywhere): move or copy it there, and resume "
            "with that output"
        )


class RunFile:
    """The run file of one ``sample_chains`` call: locked for its whole run (:meth:`open`),
    checked against the run's fingerprint, read to resume, and grown chunk by chunk, each chunk
    published whole or not at all (:mod:`liesample.run.atomic`). On the processes of a run over
    several processes other than process 0, a reader (:meth:`reader`): checked and read to
    resume alike, never locked nor written."""

    def __init__(self, path: str, lock: OutputLock | None, exists: bool | None = None):
        self.path = path
        self.lock = lock  # None: a reader, which never writes (:meth:`reader`)
        self.exists = os.path.exists(path) if exists is None else exists
        # what a resume adopts and checks, read (format, commit, attributes checked) at once
        self.header: tuple[dict[str, Any], dict[str, Any]] | None = (
            _header(path) if self.exists else None
        )
        self.chunks = 0
        self.state_slot = 1  # the slot the next state goes to is the other one
        # the attributes of the file as committed (_attribute_fields)
        self.fields: dict[str, Any] | None = None
        self.commit: dict[str, Any] | None = None  # the commit record read by resume()

    @classmethod
    def open(cls, output, resume: bool) -> RunFile:
        """Check ``output`` (:func:`check_output_path`), take its lock, remove what a killed
        writer left beside it, and read the saved run's header, before any work."""
        path = check_output_path(output, resume=True)
        lock = OutputLock(path).acquire()  # a writer at work is named before anything else
        try:
            check_output_path(path, resume)
            atomic.remove_leftovers(path)  # no live writer owns them: we hold the lock
            return cls(path, lock)
        except BaseException:
            lock.release()
            raise

    @classmethod
    def reader(cls, output, resume: bool) -> RunFile:
        """The run file as a process other than the writer sees it, in a run over several
        processes: with ``resume``, the saved run's header read from ``output`` if this process
        finds a file there; without, nothing is read (the writer checks the path). It takes no
        lock, removes nothing and never writes (:meth:`append` refuses)."""
        path = os.fspath(output)
        exists = bool(resume) and os.path.isfile(path)
        return cls(path, None, exists=exists)

    @property
    def writes(self) -> bool:
        """Whether this process writes the file (it holds the lock)."""
        return self.lock is not None

    def view(self) -> str:
        """What this process finds at the path, as a short JSON text that two processes reading
        the same file give alike (the absolute path apart): whether a file is there, and a
        SHA-256 of its header (fingerprint and variable names), or after :meth:`resume` of its
        commit record."""
        seen = None
        if self.exists:
            record = self.header if self.commit is None else self.commit
            seen = hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()
        return json.dumps([os.path.abspath(self.path), self.exists, seen])

    def close(self):
        if self.lock is not None:
            self.lock.release()

    def names(self, spec):
        """``spec`` (a :class:`liesample.run.runner.TreeSpec`) with the saved run's
        ``var_name``, ``event_dims`` and name of ``info.energy`` where ``spec`` leaves them
        unset, so that a resume writes the variables the file has (a given name that differs is
        refused by :meth:`check`)."""
        import dataclasses

        if not self.exists:
            return spec
        saved, info_names = cast(tuple[dict, dict], self.header)  # it exists: read
        energy = [name for name, (key, _) in info_names.items() if key == "energy"]
        var_name, event_dims = json.loads(saved.get("names", "[null, null]"))
        if isinstance(event_dims, list):
            event_dims = tuple(event_dims)
        elif isinstance(event_dims, dict):
            event_dims = {leaf: tuple(dims) for leaf, dims in event_dims.items()}
        return dataclasses.replace(
            spec,
            var_name=spec.var_name if spec.var_name is not None else var_name,
            event_dims=spec.event_dims if spec.event_dims is not None else event_dims,
            energy_name=spec.energy_name or (energy[0] if energy else None),
        )

    def check(self, fingerprint: dict, required=()):
        """Refuse to resume unless the file's fingerprint records the fields of ``fingerprint``
        as it does (each differing field is named with both values); a field the file lacks is
        refused if it is ``required`` (:func:`liesample.run.provenance.differences`)."""
        if not self.exists:
            return
        saved = cast(tuple[dict, dict], self.header)[0]  # it exists: read in __init__
        found = differences(saved, json.loads(json.dumps(fingerprint)), required)
        if found:
            raise RunFileError(
                f"cannot resume from {self.path!r}: it was saved by another run: "
                + "; ".join(found)
                + ". Resume with the sampler, settings and arguments of the saved run, or write "
                "to another output."
            )

    def resume(self, states, layout, num_draws):
        """``(draws_done, states, draws)`` of the saved run, verified; ``draws`` is a dict with
        ``positions``, ``info``, ``observables``, ``log_likelihood`` (``None`` for the last two
        items when nothing is saved). ``states`` gives the state's
        structure and dtypes; ``layout`` is the :class:`Layout` of the run's variables."""
        with _open(self.path) as (f, h5):
            commit, self.fields = verify(f, h5, self.path)
            self.commit = commit
            done = commit["draws_done"]
            if done > num_draws:
                raise RunFileError(
                    f"cannot resume from {self.path!r} with num_draws={num_draws}: it already "
                    f"holds {done} draws"
                )
            self.chunks, self.state_slot = commit["chunks"], commit["state_slot"]
            if done == 0:
                return 0, None, None
            names = _json_attr(f.groups[RUN_GROUP], "info_names", self.path)
            stats = h5["sample_stats"]
            info = {
                key: np.asarray(stats[name][:, :done]).astype(dtype)
                for name, (key, dtype) in names.items()
            }
            draws = layout.read(h5, done) | {"info": info}
            saved = _state_arrays(h5, self.state_slot)
        leaves, treedef = jax.tree.flatten(states)
        restored = []
        for leaf, (name, value) in zip(leaves, saved, strict=True):
            if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
                restored.append(jax.random.wrap_key_data(value, impl=jax.random.key_impl(leaf)))
            else:
                restored.append(jnp.asarray(value.astype(leaf.dtype)))
            if restored[-1].shape != leaf.shape:
                raise RunFileError(
                    f"cannot resume from {self.path!r}: saved state {name} has shape "
                    f"{restored[-1].shape}, the sampler's has {leaf.shape}"
                )
        return done, jax.tree.unflatten(treedef, restored), draws

    def append(self, first, tree, info_names, states, fingerprint):
        """Write the draws ``first …`` of ``tree`` (a ``DataTree`` of this chunk: the groups
        and attributes of the run's tree), the ``states`` after them, their checksums, and then
        the commit, to a copy of the file that then replaces it (the first call creates it with
        the run's ``fingerprint``). A failure leaves the file as it was (``OSError`` naming the
        path, the draws it holds and how to go on)."""
        if not self.writes:
            raise RuntimeError(
                f"{self.path!r} is written by process 0 of the run alone; this process only "
                "reads it"
            )
        states = _state_leaves(states)
        count = tree["posterior"].sizes["draw"]
        end = first + count
        chunk = {}  # what is written, as stored, in the order the checksum takes it
        for name in sorted(tree.children):
            chunk[f"{name}/draw"] = np.arange(first, end, dtype=np.int64)
            for var in sorted(tree[name].data_vars):
                chunk[f"{name}/{var}"] = np.ascontiguousarray(_to_stored(tree[name][var].values))
        new_bytes = sum(a.nbytes for a in chunk.values()) + sum(a.nbytes for a in states)
        with atomic.replacing(
            self.path,
            copy=self.exists,
            extra_bytes=new_bytes,
            saving=f"draws {first} to {end - 1} of the run",
            kept=f"its {first} committed draws" if self.exists else None,
        ) as work:
            with _writing(work, new=not self.exists) as f:
                if self.exists:
                    _check_names(f, tree, self.path)
                else:
                    self._create(f, tree, info_names, states, fingerprint)
                commit, fields = self._write_chunk(f, tree, chunk, states, first, end)
            _read_back(work, chunk, states, first, commit)
        self.exists, self.fields = True, fields
        self.chunks, self.state_slot = commit["chunks"], commit["state_slot"]

    def _write_chunk(self, f, tree, chunk, states, first, end):
        """Write one chunk's draws, the tree's attributes then, the states after it, its
        checksum and the commit (last) into the open copy ``f``; the commit record and the
        attributes it covers."""
        slot = 1 - self.state_slot
        for name, child in tree.children.items():
            group = f.groups[name]
            group.resize_dimension("draw", end)
            group.variables["draw"][first:end] = chunk[f"{name}/draw"]
            for var in child.data_vars:
                group.variables[var][:, first:end] = chunk[f"{name}/{var}"]
            _update_attrs(group.attrs, child.attrs)
        _update_attrs(f.attrs, tree.attrs)
        run = f.groups[RUN_GROUP]
        for i, leaf in enumerate(states):
            run.variables[f"state_{slot}_{i}"][...] = leaf
        run.resize_dimension("chunk", self.chunks + 1)
        run.variables["chunk_end"][self.chunks] = end
        run.variables["chunk_sha256"][self.chunks] = np.frombuffer(
            _chunk_digest(_slices(chunk, 0, end - first)), np.uint8
        )
        state_sha = _chunk_digest([(f"state_{slot}_{i}", leaf) for i, leaf in enumerate(states)])
        if self.fields is None:  # a new file (or one not read yet): every attribute, once
            fields = _attribute_fields(f, self.path)
        else:  # the committed file's, and those this chunk changed
            fields = _chunk_fields(f, self.fields, tree.children)
        commit = {"draws_done": end, "chunks": self.chunks + 1, "state_slot": slot}
        commit |= {"state_sha256": state_sha.hex(), **_attribute_sums(fields)}
        run.attrs["commit"] = json.dumps(commit)
        return commit, fields

    def _create(self, f, tree, info_names, states, fingerprint):
        """Lay out a new run file in ``f``: the tree's groups, coordinates and (empty)
        variables with their attributes, and the run group."""
        import h5py

        f.attrs.update(tree.attrs)
        for name, child in tree.children.items():
            group = f.create_group(name)
            group.attrs.update(child.attrs)
            group.dimensions = {
                dim: None if dim == "draw" else size for dim, size in child.sizes.items()
            }
            group.create_variable("draw", ("draw",), np.int64)
            for coord, value in child.coords.items():
                if coord == "draw":
                    continue
                value = np.asarray(value.values)
                if value.dtype.kind in "UO":
                    value = value.astype(object)
                    dtype = h5py.string_dtype()
                else:
                    dtype = value.dtype
                group.create_variable(coord, (coord,), dtype, data=value)
            for var, value in child.data_vars.items():
                stored = _to_stored(value.values)
                variable = group.create_variable(var, value.dims, stored.dtype)
                if value.dtype == bool:
                    variable.attrs["dtype"] = "bool"  # xarray reads it back as booleans
        self._create_run_group(f, info_names, states, fingerprint)

    def _create_run_group(self, f, info_names, states, fingerprint):
        run = f.create_group(RUN_GROUP)
        run.dimensions = {"chunk": None, "sha256": 32}
        run.create_variable("chunk_end", ("chunk",), np.int64)
        run.create_variable("chunk_sha256", ("chunk", "sha256"), np.uint8)
        for slot in (0, 1):
            for i, leaf in enumerate(states):
                dims = tuple(f"state_{i}_dim_{j}" for j in range(leaf.ndim))
                for dim, size in zip(dims, leaf.shape, strict=True):
                    if dim not in run.dimensions:
                        run.dimensions[dim] = size
                run.create_variable(f"state_{slot}_{i}", dims, leaf.dtype)
        run.attrs["format"] = FORMAT
        run.attrs["fingerprint"] = json.dumps(fingerprint)
        run.attrs["info_names"] = json.dumps(info_names)


class Layout:
    """Where a run's recorded draws sit in the file: for each leaf of the positions and of the
    observables (in ``jax.tree.leaves`` order) its ``posterior`` variable, or its ``.real`` and
    ``.imag`` variables; each pointwise log-likelihood under its name in ``log_likelihood``."""

    def __init__(self, positions, observables, log_likelihood, var_name):
        from liesample.analysis.diagnostics import pytree_variables
        from liesample.foundation.validation import is_single_array

        def leaves_of(tree, single):
            if tree is None:
                return None
            if is_single_array(tree):
                dtype = np.asarray(tree).dtype
                parts = [f"{single}.real", f"{single}.imag"] if dtype.kind == "c" else [single]
                return jax.tree.structure(tree), [parts], [dtype]
            grouped: dict[Any, list[str]] = {}
            for var, (_, leaf) in pytree_variables(tree).items():
                grouped.setdefault(leaf, []).append(var)
            dtypes = [np.asarray(leaf).dtype for leaf in jax.tree.leaves(tree)]
            return jax.tree.structure(tree), list(grouped.values()), dtypes

        self.trees = {
            "positions": ("posterior", leaves_of(positions, var_name)),
            "observables": ("posterior", leaves_of(observables, "observable")),
            "log_likelihood": (
                "log_likelihood",
                None if log_likelihood is None else leaves_of(dict(log_likelihood), None),
            ),
        }

    def read(self, h5, done) -> dict:
        """The first ``done`` draws of each recorded tree (``None`` where none is recorded), from
        the run file opened with h5py as ``h5``."""
        read = {}
        for name, (group, layout) in self.trees.items():
            if layout is None:
                read[name] = None
                continue
            variables, (treedef, names, dtypes) = h5[group], layout
            leaves = []
            for parts, dtype in zip(names, dtypes, strict=True):
                values = [np.asarray(variables[part][:, :done]) for part in parts]
                leaf = values[0] if len(values) == 1 else values[0] + 1j * values[1]
                leaves.append(leaf.astype(dtype))
            read[name] = jax.tree.unflatten(treedef, leaves)
        return read
