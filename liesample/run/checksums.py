"""The checks that prove a run file whole: its run format, and the checksums of its commit record.

A run file (:mod:`liesample.run.store`) ends each chunk with a commit record in its
``liesample_run`` group: ``draws_done``, the number of chunks, the state's slot and a SHA-256 of
the state's leaves, and a SHA-256 of every attribute the run wrote (the root's, each group's and
variable's, each field of ``fingerprint`` and ``info_names``) with a short checksum per
attribute, so that an edited setting is refused by name. Beside it, ``chunk_sha256`` holds a
SHA-256 of each chunk's stored draws (every variable's slice and the ``draw`` coordinate).

This module computes those checksums as a chunk is written (:func:`_attribute_fields`,
:func:`_chunk_fields`, :func:`_attribute_sums`, :func:`_chunk_digest`), reads a new version back
before it is published (:func:`_read_back`), and verifies a saved file whole (:func:`verify`):
its format, its attributes, its chunk table, every chunk and the saved state, each failure a
:class:`RunFileError` naming the path, what is wrong and what to do.
"""

from __future__ import annotations

import errno
import hashlib
import json
import re
from typing import cast

import numpy as np

from liesample.run.provenance import FORMAT

RUN_GROUP = "liesample_run"
"""The group of a run file that holds its fingerprint, states and checksums."""


class RunFileError(ValueError):
    """A run file that cannot be read, resumed or trusted (the message names the path)."""


_START_AFRESH = (
    "delete it (or move it away) to start the run afresh at this path, or choose another output"
)


CHUNK_ATTRS = ("sampling_time", "num_steps", "casimir_drift")
"""The tree's attributes that change from chunk to chunk (the others are written once)."""


def _run_group(f, path):
    if RUN_GROUP not in f.groups:
        if f.attrs.get("format") == "liesample-chains-1":
            raise RunFileError(
                f"{path!r} was written by an older liesample (format 'liesample-chains-1'): it "
                "cannot be resumed or verified; read it with xarray.open_dataset"
            )
        raise RunFileError(
            f"{path!r} has no {RUN_GROUP!r} group: it was not written by liesample's "
            "sample_chains or sample, or its writer stopped before its first chunk was "
            "committed, and it holds no committed draws. Read it with xarray.open_datatree; "
            + _START_AFRESH
        )
    group = f.groups[RUN_GROUP]
    found = group.attrs.get("format")
    if found in _OLDER_FORMATS:
        raise RunFileError(
            f"{path!r} was written by an older liesample (run format {found!r}, whose "
            "checksums do not cover the run's settings): it cannot be resumed or verified by "
            f"this one (format {FORMAT!r}); read it with xarray.open_datatree, and start a new "
            "output to go on sampling"
        )
    if found != FORMAT:
        raise RunFileError(
            f"{path!r} has run format {found!r}; this liesample reads {FORMAT!r}: read it "
            "with xarray.open_datatree, or with the liesample that wrote it"
        )
    return group


_OLDER_FORMATS = ("liesample-run-1", "liesample-run-2")
_JSON_ATTRS = ("fingerprint", "info_names")


def _attr_bytes(value) -> bytes:
    """An attribute's value as the bytes its checksum covers (text and numbers apart)."""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str):
        return b"str|" + value.encode()
    array = np.asarray(value)
    if array.dtype.kind in "OSU":
        items = [v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
                 for v in array.reshape(-1)]  # fmt: skip
        return f"text|{array.shape}|".encode() + json.dumps(items).encode()
    array = np.ascontiguousarray(array)
    return f"{array.dtype.str}|{array.shape}|".encode() + array.tobytes()


def _attribute_fields(f, path) -> dict[str, bytes]:
    """Every attribute the run wrote, by a name that says where it is (``attrs['beta']`` of
    the root, ``posterior.attrs['beta']``, ``sample_stats/diverging.attrs['dtype']``, and each
    field of the run's JSON records: ``fingerprint['num_warmup']``), as :func:`_attr_bytes`.
    The commit record, which holds their checksums, is not one of them."""
    fields = {}

    def add(where, attrs, skip=()):
        for name in attrs:
            if name not in skip:
                fields[_field(where, name)] = _attr_bytes(attrs[name])

    add("", f.attrs)
    for group_name in sorted(f.groups):
        group = f.groups[group_name]
        if group_name == RUN_GROUP:
            add(f"{group_name}.", group.attrs, skip=("commit", *_JSON_ATTRS))
            for name in _JSON_ATTRS:
                for key, value in _json_attr(group, name, path).items():
                    fields[f"{name}[{key!r}]"] = json.dumps(value, sort_keys=True).encode()
        else:
            add(f"{group_name}.", group.attrs)
        for var in sorted(group.variables):
            add(f"{group_name}/{var}.", group.variables[var].attrs)
    return fields


def _field(where, name) -> str:
    return f"{where}attrs[{name!r}]"


def _chunk_fields(f, fields, groups) -> dict[str, bytes]:
    """``fields`` (:func:`_attribute_fields` of the file before this chunk) with the attributes
    that change from chunk to chunk read again from ``f``, at the root and in ``groups``."""
    fields = dict(fields)
    for where, attrs in [("", f.attrs), *((f"{g}.", f.groups[g].attrs) for g in groups)]:
        for name in CHUNK_ATTRS:
            if name in attrs:
                fields[_field(where, name)] = _attr_bytes(attrs[name])
    return fields


def _attribute_sums(fields) -> dict:
    """The commit's checksums of the attributes ``fields`` (:func:`_attribute_fields`):
    ``attrs_sha256``, a SHA-256 of them all, and ``attr_sums``, the first 16 hex digits of each
    one's (which name an edited one)."""
    full, short = hashlib.sha256(), {}
    for name, value in sorted(fields.items()):
        digest = hashlib.sha256(value).hexdigest()
        full.update(f"{name}={digest};".encode())
        short[name] = digest[:16]
    return {"attrs_sha256": full.hexdigest(), "attr_sums": short}


def _check_attributes(f, path, commit) -> dict[str, bytes]:
    """The attributes of ``f`` (:func:`_attribute_fields`); refused unless they are those its
    commit records, naming each one that was changed, added or removed."""
    fields = _attribute_fields(f, path)
    sums = _attribute_sums(fields)
    if sums["attrs_sha256"] == commit.get("attrs_sha256"):
        return fields
    saved, now = commit.get("attr_sums"), sums["attr_sums"]
    if not isinstance(saved, dict):
        saved = {}
    found = [f"{name} was changed" for name in now if name in saved and saved[name] != now[name]]
    found += [f"{name} was added" for name in now if name not in saved]
    found += [f"{name} was removed" for name in saved if name not in now]
    raise RunFileError(
        f"{path!r}: "
        + ("; ".join(found) if found and saved else "its attributes do not match their checksum")
        + " since the run wrote it: the file was edited or is corrupt, and its draws cannot be "
        "trusted to be the saved run's. Restore the file as it was written, or " + _START_AFRESH
    )


def _json_attr(group, name, path):
    try:
        return json.loads(group.attrs[name])
    except (KeyError, TypeError, ValueError):
        raise RunFileError(f"{path!r}: its {name!r} record is missing or unreadable") from None


def _chunk_digest(arrays) -> bytes:
    """SHA-256 of ``(name, array)`` pairs in the given order (name, dtype, shape and bytes)."""
    digest = hashlib.sha256()
    for name, array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    return digest.digest()


def _tree_groups(f):
    return sorted(name for name in f.groups if name != RUN_GROUP)


def _stored_draws(f, h5, done):
    """Every group's ``draw`` coordinate and draw variables (dims ``(chain, draw, …)``) up to
    draw ``done``, as stored, in the order the checksums take them (read once each)."""
    stored = {}
    for group_name in _tree_groups(f):
        group = f.groups[group_name]
        stored[f"{group_name}/draw"] = np.asarray(h5[group_name]["draw"][:done])
        for name in sorted(group.variables):
            if group.variables[name].dimensions[:2] == ("chain", "draw"):
                stored[f"{group_name}/{name}"] = np.asarray(h5[group_name][name][:, :done])
    return stored


def _slices(stored, first, end):
    """The chunk ``first … end`` of the arrays of :func:`_stored_draws` (or of one chunk's,
    ``first=0``): what its checksum covers."""
    for name, array in stored.items():
        yield name, array[first:end] if name.endswith("/draw") else array[:, first:end]


def _state_arrays(h5, slot):
    """The saved state's leaves in slot ``slot``, read from the h5py file ``h5``."""
    group = h5[RUN_GROUP]
    leaf = re.compile(rf"state_{int(slot)}_(\d+)")  # not the dimensions state_<i>_dim_<j>
    names = sorted(
        (n for n in group if leaf.fullmatch(n)),
        key=lambda n: int(cast(re.Match[str], leaf.fullmatch(n))[1]),  # matched: filtered
    )
    return [(name, np.asarray(group[name][...])) for name in names]


def verify(f, h5, path) -> tuple[dict, dict]:
    """The commit record of the run in ``f`` (its data read through h5py as ``h5``, as the run
    file opens it: :mod:`liesample.run.store`) and its attributes (:func:`_attribute_fields`),
    after checking the attributes, the chunk table, every chunk's checksum and the saved
    state's (:class:`RunFileError` naming what is wrong)."""
    group = _run_group(f, path)
    commit = _json_attr(group, "commit", path)
    fields = _check_attributes(f, path, commit)
    done, chunks = commit.get("draws_done"), commit.get("chunks")
    if not all(isinstance(v, int) and v >= 0 for v in (done, chunks)):
        raise RunFileError(f"{path!r}: draws_done {done!r} and chunks {chunks!r} are invalid")
    ends = np.asarray(h5[RUN_GROUP]["chunk_end"][:chunks]).tolist()
    sums = np.asarray(h5[RUN_GROUP]["chunk_sha256"][:chunks])
    sizes = {f.groups[g].dimensions["draw"].size for g in _tree_groups(f)}
    if len(ends) != chunks or any(b <= a for a, b in zip([0, *ends], ends, strict=False)):
        raise RunFileError(f"{path!r}: its chunk table {ends} is not increasing")
    if (ends[-1] if ends else 0) != done:
        raise RunFileError(
            f"{path!r}: draws_done = {done} disagrees with its saved chunks, which end at "
            f"draw {ends[-1] if ends else 0}: the file was edited or is corrupt"
        )
    if min(sizes, default=0) < done:
        raise RunFileError(f"{path!r}: it holds {min(sizes)} draws, draws_done = {done}")
    stored = _stored_draws(f, h5, done)
    for k, (first, end) in enumerate(zip([0, *ends], ends, strict=False)):
        if _chunk_digest(_slices(stored, first, end)) != bytes(sums[k]):
            intact = f"; draws 0 to {first - 1} before it match theirs" if first else ""
            raise RunFileError(
                f"{path!r}: chunk {k} (draws {first} to {end - 1}) does not match its "
                f"checksum: the file was edited or is corrupt{intact}. Restore the file as it "
                "was written, or " + _START_AFRESH
            )
    if done and _chunk_digest(_state_arrays(h5, commit["state_slot"])).hex() != commit.get(
        "state_sha256"
    ):
        raise RunFileError(
            f"{path!r}: the saved chain states do not match their checksum: the file was "
            "edited or is corrupt, and the run cannot be resumed"
        )
    return commit, fields


def _read_back(work, chunk, states, first, commit):
    """Refuse (``OSError``) to publish the copy ``work`` of a run file unless its ``commit``
    record, its new ``chunk`` (the arrays written from draw ``first``, by ``group/name``) and
    its ``states`` read back as they were written: HDF5 may lose a write without raising (a
    dataset closed on a full disk). Read with h5py alone, and only what was written."""
    import h5py

    end, slot = commit["draws_done"], commit["state_slot"]
    try:
        with h5py.File(work, "r") as h5:
            saved = h5[RUN_GROUP].attrs["commit"]
            saved = json.loads(saved.decode() if isinstance(saved, bytes) else saved)
            stored = [
                (name, h5[name][first:end] if name.endswith("/draw") else h5[name][:, first:end])
                for name in chunk
            ]
            states = [
                (f"state_{slot}_{i}", h5[f"{RUN_GROUP}/state_{slot}_{i}"][...])
                for i in range(len(states))
            ]
            row = bytes(np.asarray(h5[f"{RUN_GROUP}/chunk_sha256"][commit["chunks"] - 1]))
    except Exception as error:
        raise OSError(errno.EIO, f"its new version does not read back ({error!r})") from None
    expected = _chunk_digest(chunk.items())
    if (
        saved != commit
        or row != expected
        or _chunk_digest(stored) != expected
        or _chunk_digest(states).hex() != commit["state_sha256"]
    ):
        raise OSError(errno.EIO, "its new version does not read back as it was written")
