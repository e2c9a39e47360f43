"""Gauge configurations in the ILDG format: LIME records with the SciDAC checksum.

A file holds one LIME message (a sequence of records, each a 144-byte big-endian header — the
magic number ``0x456789ab``, version 1, the message-begin and message-end flags, the data length
and a type name of up to 128 bytes — then the data, padded with zeros to a multiple of 8
bytes). :func:`save_ildg` writes the records

- ``ildg-format``: XML with ``field`` (``su3gauge``), ``precision`` (32 or 64) and the extents
  ``lx``, ``ly``, ``lz``, ``lt``;
- ``ildg-data-lfn``: the logical file name, when one is given;
- ``ildg-binary-data``: the links, IEEE floating point, big-endian;
- ``scidac-checksum``: XML with ``suma`` and ``sumb`` (below).

**Ordering.** The binary data runs over the sites with ``x`` fastest and ``t`` slowest, and at
each site over the four directions ``μ = x, y, z, t``, each link a 3×3 complex matrix row by row
(the column index fastest), each entry its real then its imaginary part. A liesample field
``links`` of ``wilson_gauge("SU3", (lx, ly, lz, lt))`` has shape ``(4, lx, ly, lz, lt, 3, 3)``:
its lattice axes ``0, 1, 2, 3`` are ILDG's ``x, y, z, t`` (liesample's last axis is time, as
``polyakov_loop`` and ``wilson_loop`` take it), its direction axis ``μ`` is ILDG's direction
``μ``, and ``links[μ, x, y, z, t]`` is the link from ``x`` to ``x + μ̂`` with rows and columns
the colour indices ``a, b`` of ``U^{ab}``, which is ILDG's convention. So the file order is the
array transposed to ``(t, z, y, x, μ, a, b)``: nothing is conjugated or reordered within a
matrix, and the round trip is bit-exact in either precision.

**Checksum.** The SciDAC checksum is computed from its definition: for each site, the CRC-32
(:func:`zlib.crc32`) of its bytes as stored in the file, ``c``, is rotated left by ``r mod 29``
bits into ``suma`` and by ``r mod 31`` bits into ``sumb`` by exclusive or, ``r`` the site's
rank in the file order (``x + lx (y + ly (z + lz t))``); the two 32-bit sums are written in
lower-case hexadecimal. :func:`load_ildg` recomputes them and refuses a file whose sums differ
(a flipped byte); a file without a checksum record (some writers omit it) is read unchecked.

**Other groups and dimensions.** ILDG defines 4-D SU(3) (``su3gauge``). For 4-D SU(N) with
``N ≠ 3`` this module writes the natural extension, field ``su<N>gauge`` with ``N × N``
matrices in the same order; liesample reads it back, other ILDG readers may not. U(1) fields
(angles, not matrices: an ``exp(iθ)`` would not round-trip bit-exactly) and lattices of 2 or 3
dimensions (ILDG's sites have four directions) are refused: save those with
``liesample.sample(..., output=...)`` or ``numpy.save``.
"""

from __future__ import annotations

import contextlib
import os
import re
import struct
import xml.etree.ElementTree as ElementTree
import zlib
from typing import NamedTuple

import numpy as np

from liesample.run import atomic
from liesample.systems.wilson_gauge import WilsonGauge, wilson_gauge

__all__ = [
    "IldgFileError",
    "IldgHeader",
    "ildg_header",
    "load_ildg",
    "save_ildg",
    "scidac_checksum",
]

LIME_MAGIC = 0x456789AB
LIME_VERSION = 1
_HEADER = struct.Struct(">IHHQ128s")  # magic, version, flags, data length, type
_BEGIN, _END = 0x8000, 0x4000  # message-begin and message-end flags
_MAX_XML = 1 << 20  # an XML record longer than this is not one this module reads
_EXTENTS = ("lx", "ly", "lz", "lt")


class IldgFileError(ValueError):
    """A file that is not a readable ILDG configuration (the message names the path)."""


class IldgHeader(NamedTuple):
    """What the ``ildg-format`` and checksum records of an ILDG file say (:func:`ildg_header`).

    Examples
    --------
    >>> import os, tempfile
    >>> from liesample.run.ildg import ildg_header, save_ildg
    >>> system = liesample.systems.wilson_gauge("SU3", (2, 2, 2, 2))
    >>> path = os.path.join(tempfile.mkdtemp(), "cold.lime")
    >>> save_ildg(path, system.cold_start(jnp.float64), system)
    >>> header = ildg_header(path)
    >>> header.group, header.shape, header.precision
    ('SU3', (2, 2, 2, 2), 64)
    """

    field: str
    group: str
    shape: tuple[int, int, int, int]
    precision: int
    lfn: str | None
    checksum: tuple[int, int] | None


def _check_system(system, name: str = "system") -> WilsonGauge:
    if not isinstance(system, WilsonGauge):
        raise TypeError(
            f"{name} must be a WilsonGauge (liesample.systems.wilson_gauge), got "
            f"{type(system).__name__}"
        )
    if system.abelian or system.dim != 4:
        raise ValueError(
            f"{name} must be a 4-D SU(N) gauge field for ILDG (4-D SU(3) is ILDG's own; "
            f"SU(N) writes su<N>gauge), got group {system.group!r} in {system.dim} dimensions; "
            "save other fields with liesample.sample(..., output=...) or numpy.save"
        )
    if system.boundary != "periodic":
        raise ValueError(
            f"{name} must be periodic (an ILDG configuration lives on a torus), got boundary "
            f"{system.boundary!r}"
        )
    return system


def _format_xml(field: str, precision: int, shape) -> bytes:
    extents = "".join(f"<{k}>{n}</{k}>" for k, n in zip(_EXTENTS, shape, strict=True))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<ildgFormat xmlns="http://www.lqcd.org/ildg" '
        'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:schemaLocation="http://www.lqcd.org/ildg http://www.lqcd.org/ildg/filefmt.xsd">'
        f"<version>1.0</version><field>{field}</field><precision>{precision}</precision>"
        f"{extents}</ildgFormat>"
    ).encode()


def _checksum_xml(suma: int, sumb: int) -> bytes:
    return (
        '<?xml version="1.0" encoding="UTF-8"?>'
        f"<scidacChecksum><version>1.0</version><suma>{suma:x}</suma><sumb>{sumb:x}</sumb>"
        "</scidacChecksum>"
    ).encode()


def scidac_checksum(data: bytes, num_sites: int) -> tuple[int, int]:
    """``(suma, sumb)`` of binary data holding ``num_sites`` sites of equal size, in file order
    (module docstring): the CRC-32 of site ``r`` rotated left by ``r mod 29`` (``r mod 31``)
    bits, combined by exclusive or.

    Examples
    --------
    >>> from liesample.run.ildg import scidac_checksum
    >>> import zlib
    >>> scidac_checksum(b"site", 1) == (zlib.crc32(b"site"),) * 2  # rank 0: no rotation
    True
    """
    site_bytes = len(data) // num_sites
    view = memoryview(data)
    crcs = np.fromiter(
        (zlib.crc32(view[r * site_bytes : (r + 1) * site_bytes]) for r in range(num_sites)),
        dtype=np.uint64,
        count=num_sites,
    )
    ranks = np.arange(num_sites, dtype=np.uint64)
    sums = []
    for modulus in (29, 31):
        shift = ranks % np.uint64(modulus)
        rotated = ((crcs << shift) | (crcs >> (np.uint64(32) - shift))) & np.uint64(0xFFFFFFFF)
        sums.append(int(np.bitwise_xor.reduce(rotated)) if num_sites else 0)
    return sums[0], sums[1]


def _record(kind: str, data: bytes, flags: int) -> bytes:
    header = _HEADER.pack(LIME_MAGIC, LIME_VERSION, flags, len(data), kind.encode())
    return header + data + bytes(-len(data) % 8)


def _to_file_order(links: np.ndarray) -> np.ndarray:
    """``(4, lx, ly, lz, lt, N, N)`` → ``(lt, lz, ly, lx, 4, N, N)``."""
    return np.transpose(links, (4, 3, 2, 1, 0, 5, 6))


def save_ildg(
    path: str | os.PathLike[str],
    links,
    system: WilsonGauge,
    *,
    precision: int | None = None,
    lfn: str | None = None,
    overwrite: bool = False,
) -> None:
    """Write a 4-D SU(N) gauge field to ``path`` as an ILDG file (LIME records, SciDAC
    checksum; module docstring for the records and the ordering).

    Parameters
    ----------
    path : str or path
        The file to write; refused if it exists unless ``overwrite``, or if its directory is
        missing. Written beside it and renamed into place (:mod:`liesample.run.atomic`): a
        failed write leaves no partial file (and a file it was to replace as it was).
    links : array, shape (4, lx, ly, lz, lt, N, N), complex
        A field of ``system`` (``system.hot_start(key)``, a sampler's ``state.position``).
    system : WilsonGauge
        ``liesample.systems.wilson_gauge("SU3", (lx, ly, lz, lt))`` (any ``SU<N>``: module
        docstring); periodic.
    precision : {32, 64}, optional
        Bits per real number in the file. Default: that of ``links`` (complex64: 32,
        complex128: 64); 32 for a float64 field rounds it.
    lfn : str, optional
        An ILDG logical file name, written as the ``ildg-data-lfn`` record.
    overwrite : bool
        Replace an existing file at ``path``.

    Examples
    --------
    >>> import os, tempfile
    >>> from liesample.run.ildg import load_ildg, save_ildg
    >>> system = liesample.systems.wilson_gauge("SU3", (2, 2, 2, 4))
    >>> links = system.hot_start(jax.random.key(0), jnp.float64)
    >>> path = os.path.join(tempfile.mkdtemp(), "config.lime")
    >>> save_ildg(path, links, system)
    >>> bool((load_ildg(path, system) == links).all())  # bit for bit
    True
    """
    system = _check_system(system)
    system.check_links(links)
    if not isinstance(overwrite, bool):
        raise TypeError(f"overwrite must be a bool, got {overwrite!r}")
    path = _output_path(path, overwrite)
    array = np.asarray(links)
    if precision is None:
        precision = 32 if array.dtype == np.complex64 else 64
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)):
        raise TypeError(
            f"precision must be the int 32 or 64 (bits per real number), got {precision!r}"
        )
    if precision not in (32, 64):
        raise ValueError(f"precision must be 32 or 64 (bits per real number), got {precision!r}")
    precision = int(precision)
    if not np.all(np.isfinite(array)):
        raise ValueError("links must be finite; the field holds NaN or infinite entries")
    if lfn is not None and (not isinstance(lfn, str) or "\x00" in lfn):
        raise TypeError(f"lfn must be a str (a logical file name) without NUL bytes, got {lfn!r}")
    dtype = np.dtype(">c8" if precision == 32 else ">c16")
    data = np.ascontiguousarray(_to_file_order(array)).astype(dtype).tobytes()
    suma, sumb = scidac_checksum(data, int(np.prod(system.shape)))
    field = f"su{system.n}gauge"
    records = [("ildg-format", _format_xml(field, precision, system.shape))]
    if lfn is not None:
        records.append(("ildg-data-lfn", lfn.encode()))
    records += [("ildg-binary-data", data), ("scidac-checksum", _checksum_xml(suma, sumb))]
    last = len(records) - 1
    content = b"".join(
        _record(kind, payload, (_BEGIN if i == 0 else 0) | (_END if i == last else 0))
        for i, (kind, payload) in enumerate(records)
    )
    work = atomic.temporary_path(path)  # written beside the file, then renamed over it
    try:
        with open(work, "wb") as f:
            f.write(content)
            f.flush()
            os.fsync(f.fileno())
        os.replace(work, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(work)
        raise


def _output_path(path, overwrite: bool) -> str:
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise FileNotFoundError(f"path {path!r}: its directory {directory!r} does not exist")
    if os.path.isdir(path):
        raise IsADirectoryError(f"path {path!r} is a directory; give a file in it")
    if os.path.exists(path) and not overwrite:
        raise FileExistsError(
            f"path {path!r} exists; pass overwrite=True to replace it, or choose another path"
        )
    return path


def _records(path: str) -> dict[str, bytes]:
    """The LIME records of ``path`` by type (the first of each type), or an
    :class:`IldgFileError`."""
    found: dict[str, bytes] = {}
    size, flags, name = os.path.getsize(path), 0, ""
    if size == 0:
        raise IldgFileError(f"{path!r} is empty: not an ILDG gauge configuration")
    with open(path, "rb") as f:
        while f.tell() < size:
            start = f.tell()
            raw = f.read(_HEADER.size)
            if len(raw) < _HEADER.size:
                raise IldgFileError(
                    f"{path!r} is truncated: a LIME record header at byte {start} has "
                    f"{len(raw)} of its {_HEADER.size} bytes"
                )
            magic, version, flags, length, kind = _HEADER.unpack(raw)
            if magic != LIME_MAGIC:
                raise IldgFileError(
                    f"{path!r} is not a LIME file: the record at byte {start} starts with "
                    f"{magic:#010x}, not the LIME magic number {LIME_MAGIC:#010x}"
                )
            if version != LIME_VERSION:
                raise IldgFileError(f"{path!r}: LIME version {version} (this reader knows 1)")
            name = kind.rstrip(b"\x00").decode("ascii", "replace")
            if f.tell() + length > size:
                raise IldgFileError(
                    f"{path!r} is truncated: its record {name!r} at byte {start} announces "
                    f"{length} bytes of data and the file holds {size - f.tell()} after its "
                    "header"
                )
            if length <= _MAX_XML or (name == "ildg-binary-data" and name not in found):
                data = f.read(length)
            else:
                f.seek(length, os.SEEK_CUR)  # a large record of no interest here
                data = b""
            found.setdefault(name, data)
            f.seek(min(size, f.tell() + (-length % 8)))  # the padding (absent at the very end)
    if not flags & _END:  # the file's last record must end its message
        raise IldgFileError(
            f"{path!r} is truncated: its last record, {name!r}, does not end a LIME message "
            "(the records after it are missing)"
        )
    return found


def _xml_fields(path: str, name: str, data: bytes) -> dict[str, str]:
    """``{local tag: text}`` of an XML record's elements, or an :class:`IldgFileError`."""
    try:
        root = ElementTree.fromstring(data.rstrip(b"\x00"))
    except ElementTree.ParseError as error:
        raise IldgFileError(f"{path!r}: its {name!r} record is not XML ({error})") from None
    return {el.tag.rsplit("}", 1)[-1]: (el.text or "").strip() for el in root.iter()}


def _header_from(path: str, records: dict[str, bytes]) -> IldgHeader:
    for needed in ("ildg-format", "ildg-binary-data"):
        if needed not in records:
            raise IldgFileError(
                f"{path!r} has no {needed!r} record (it holds {sorted(records)}): not an ILDG "
                "gauge configuration"
            )
    fields = _xml_fields(path, "ildg-format", records["ildg-format"])
    try:
        field = fields["field"]
        precision = int(fields["precision"])
        shape = tuple(int(fields[k]) for k in _EXTENTS)
    except (KeyError, ValueError) as error:
        raise IldgFileError(
            f"{path!r}: its ildg-format record lacks a valid {error} (it needs field, "
            "precision, lx, ly, lz, lt)"
        ) from None
    match = re.fullmatch(r"su(\d+)gauge", field)
    if match is None or int(match[1]) < 2 or precision not in (32, 64) or min(shape) < 1:
        raise IldgFileError(
            f"{path!r}: field {field!r}, precision {precision}, extents {shape}: this reader "
            "knows su<N>gauge fields (N >= 2) in precision 32 or 64"
        )
    checksum = None
    if "scidac-checksum" in records:
        sums = _xml_fields(path, "scidac-checksum", records["scidac-checksum"])
        try:
            checksum = (int(sums["suma"], 16), int(sums["sumb"], 16))
        except (KeyError, ValueError):
            raise IldgFileError(
                f"{path!r}: its scidac-checksum record has no valid suma/sumb"
            ) from None
    lfn = records.get("ildg-data-lfn")
    lfn = None if lfn is None else lfn.rstrip(b"\x00").decode("utf-8", "replace")
    return IldgHeader(field, f"SU{match[1]}", shape, precision, lfn, checksum)  # type: ignore[arg-type]


def ildg_header(path: str | os.PathLike[str]) -> IldgHeader:
    """The field, group, lattice extents ``(lx, ly, lz, lt)``, precision, logical file name and
    stored SciDAC checksum of the ILDG file at ``path`` (no check of the data).

    Examples
    --------
    (See :class:`IldgHeader`.)

    >>> from liesample.run.ildg import ildg_header
    >>> ildg_header("no/such/file.lime")
    Traceback (most recent call last):
    ...
    FileNotFoundError: no ILDG file at 'no/such/file.lime'
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no ILDG file at {path!r}")
    return _header_from(path, _records(path))


def load_ildg(path: str | os.PathLike[str], system: WilsonGauge | None = None) -> np.ndarray:
    """The gauge field stored in the ILDG file at ``path``, as a NumPy array of the shape
    ``(4, lx, ly, lz, lt, N, N)`` of ``wilson_gauge(f"SU{N}", (lx, ly, lz, lt))``.

    Parameters
    ----------
    path : str or path
        A file written by :func:`save_ildg` or by another ILDG writer (LIME records
        ``ildg-format`` and ``ildg-binary-data``; the SciDAC checksum is verified when the file
        has one).
    system : WilsonGauge, optional
        The system the field is for: its group and lattice must be the file's (refused
        otherwise, naming both). Default: the file's own
        (:func:`ildg_header` tells it: ``wilson_gauge(header.group, header.shape)``).

    Returns
    -------
    numpy.ndarray
        complex64 for a 32-bit file, complex128 for a 64-bit one, in native byte order: the
        values written, bit for bit (``jnp.asarray`` makes it a JAX array; with
        ``jax_enable_x64`` off JAX holds it in complex64).

    Raises
    ------
    IldgFileError
        Not a LIME file, truncated, missing records, data of the wrong size, or a checksum that
        differs from the data's (the message names the path).

    Examples
    --------
    >>> import os, tempfile
    >>> from liesample.run.ildg import load_ildg, save_ildg
    >>> system = liesample.systems.wilson_gauge("SU2", (2, 2, 2, 2))
    >>> path = os.path.join(tempfile.mkdtemp(), "cold.lime")
    >>> save_ildg(path, system.cold_start(jnp.float32), system)
    >>> links = load_ildg(path)
    >>> links.shape, links.dtype
    ((4, 2, 2, 2, 2, 2, 2), dtype('complex64'))
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no ILDG file at {path!r}")
    records = _records(path)
    header = _header_from(path, records)
    if system is None:
        system = wilson_gauge(header.group, header.shape)
    system = _check_system(system)
    if (system.group, system.shape) != (header.group, header.shape):
        raise ValueError(
            f"system is {system.group} on {system.shape}, but {path!r} holds {header.group} on "
            f"{header.shape} (lx, ly, lz, lt); pass wilson_gauge({header.group!r}, "
            f"{header.shape}) or system=None"
        )
    n, num_sites = system.n, int(np.prod(header.shape))
    dtype = np.dtype(">c8" if header.precision == 32 else ">c16")
    data = records["ildg-binary-data"]
    expected = num_sites * 4 * n * n * dtype.itemsize
    if len(data) != expected:
        raise IldgFileError(
            f"{path!r}: its ildg-binary-data holds {len(data)} bytes, and {header.field} on "
            f"{header.shape} in precision {header.precision} needs {expected}"
        )
    if header.checksum is not None:
        computed = scidac_checksum(data, num_sites)
        if computed != header.checksum:
            raise IldgFileError(
                f"{path!r}: the SciDAC checksum of its data is suma {computed[0]:x}, sumb "
                f"{computed[1]:x}; the file records {header.checksum[0]:x}, "
                f"{header.checksum[1]:x}: the data was altered or damaged"
            )
    lx, ly, lz, lt = header.shape
    stored = np.frombuffer(data, dtype).reshape(lt, lz, ly, lx, 4, n, n)
    native = stored.astype(dtype.newbyteorder("="))
    return np.ascontiguousarray(np.transpose(native, (4, 3, 2, 1, 0, 5, 6)))
