"""ILDG/LIME gauge configurations (:mod:`liesample.run.ildg`): the round trip is bit-exact in
both precisions, the records and their order are ILDG's, the SciDAC checksum catches a flipped
byte, and truncated files, wrong lattices and fields ILDG cannot hold are refused by name."""

import struct
import zlib

import numpy as np
import pytest

from liesample.run.ildg import (
    IldgFileError,
    ildg_header,
    load_ildg,
    save_ildg,
    scidac_checksum,
)
from liesample.systems import wilson_gauge


def haar_links(system, seed):
    """Haar-random SU(N) links of ``system`` in NumPy (no compilation): QR of a complex
    Gaussian, phases fixed, determinant divided out."""
    n, shape = system.n, system.space.position_array_shape
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(*shape, 2)) @ np.array([1.0, 1.0j])
    q, r = np.linalg.qr(z)
    diagonal = np.diagonal(r, axis1=-2, axis2=-1)
    q = q * (diagonal / np.abs(diagonal))[..., None, :]
    return q / np.linalg.det(q)[..., None, None] ** (1 / n)


SU3 = wilson_gauge("SU3", (2, 4, 2, 4))  # extents that differ: the axes cannot be swapped
LINKS = haar_links(SU3, 0)  # complex128


def lime_records(path):
    """``[(type, flags, data)]`` of a LIME file, read here from the format's definition."""
    blob, out, at = path.read_bytes(), [], 0
    while at < len(blob):
        magic, version, flags, length, kind = struct.unpack(">IHHQ128s", blob[at : at + 144])
        assert (magic, version) == (0x456789AB, 1)
        data = blob[at + 144 : at + 144 + length]
        out.append((kind.rstrip(b"\x00").decode(), flags, data))
        at += 144 + length + (-length % 8)
    return out


@pytest.mark.parametrize("precision", [64, 32])
def test_the_round_trip_is_bit_exact(tmp_path, precision):
    links = LINKS if precision == 64 else LINKS.astype(np.complex64)
    path = tmp_path / "config.lime"
    save_ildg(path, links, SU3)
    back = load_ildg(path, SU3)
    assert back.dtype == links.dtype and back.shape == links.shape
    assert back.tobytes() == links.tobytes()  # bit for bit
    assert load_ildg(path).tobytes() == links.tobytes()  # the system read from the file
    header = ildg_header(path)
    assert (header.field, header.group, header.shape) == ("su3gauge", "SU3", SU3.shape)
    assert header.precision == precision


def test_a_float64_field_saved_in_32_bits_is_rounded(tmp_path):
    path = tmp_path / "config.lime"
    save_ildg(path, LINKS, SU3, precision=32)
    np.testing.assert_array_equal(load_ildg(path), LINKS.astype(np.complex64))


def test_the_records_and_the_order_are_ildgs(tmp_path):
    path = tmp_path / "config.lime"
    save_ildg(path, LINKS, SU3, lfn="lfn://liesample/test")
    records = lime_records(path)
    kinds = [kind for kind, _, _ in records]
    assert kinds == ["ildg-format", "ildg-data-lfn", "ildg-binary-data", "scidac-checksum"]
    flags = [f for _, f, _ in records]
    assert flags[0] & 0x8000 and flags[-1] & 0x4000 and not any(f & 0xC000 for f in flags[1:-1])
    text = records[0][2].decode()
    for tag in ("<field>su3gauge</field>", "<precision>64</precision>", "<lx>2</lx>", "<lt>4</lt>"):
        assert tag in text
    # site-major, x fastest and t slowest; at each site the directions x, y, z, t; each matrix
    # row by row; each entry (re, im); big-endian
    data = np.frombuffer(records[2][2], ">f8")
    lx, ly, lz, _ = SU3.shape
    site = (1, 3, 0, 2)  # x, y, z, t
    rank = site[0] + lx * (site[1] + ly * (site[2] + lz * site[3]))
    mu, a, b = 2, 1, 0
    at = ((rank * 4 + mu) * 3 + a) * 3 + b
    entry = LINKS[(mu, *site, a, b)]
    assert (data[2 * at], data[2 * at + 1]) == (entry.real, entry.imag)
    assert ildg_header(path).lfn == "lfn://liesample/test"


def test_the_checksum_follows_its_definition():
    sites = [bytes([r]) * 12 for r in range(40)]  # 40 ranks: the rotations wrap at 29 and 31
    rotl = lambda c, k: ((c << k) | (c >> (32 - k))) & 0xFFFFFFFF
    suma = sumb = 0
    for r, site in enumerate(sites):
        suma ^= rotl(zlib.crc32(site), r % 29)
        sumb ^= rotl(zlib.crc32(site), r % 31)
    assert scidac_checksum(b"".join(sites), len(sites)) == (suma, sumb)


def test_a_flipped_byte_is_caught_by_the_checksum(tmp_path):
    path = tmp_path / "config.lime"
    save_ildg(path, LINKS, SU3)
    blob = bytearray(path.read_bytes())
    data_start = blob.index(b"ildg-binary-data") + 128  # the record's data follows its type
    blob[data_start + 1000] ^= 0x10
    path.write_bytes(bytes(blob))
    with pytest.raises(IldgFileError, match=r"SciDAC checksum.*altered or damaged"):
        load_ildg(path, SU3)


def test_a_truncated_file_is_refused(tmp_path):
    path = tmp_path / "config.lime"
    save_ildg(path, LINKS, SU3)
    blob = path.read_bytes()
    checksum_record = blob.index(b"scidac-checksum") - 16  # its header starts 16 bytes earlier
    # inside the binary data; inside the first header; the checksum record cut off whole
    for cut in (len(blob) // 2, 100, checksum_record):
        path.write_bytes(blob[:cut])
        with pytest.raises(IldgFileError, match="truncated"):
            load_ildg(path, SU3)
    path.write_bytes(b"")
    with pytest.raises(IldgFileError, match="empty"):
        load_ildg(path, SU3)


def test_a_wrong_lattice_is_refused_by_name(tmp_path):
    path = tmp_path / "config.lime"
    save_ildg(path, LINKS, SU3)
    with pytest.raises(ValueError, match=r"system is SU3 on \(4, 4, 2, 2\).*\(2, 4, 2, 4\)"):
        load_ildg(path, wilson_gauge("SU3", (4, 4, 2, 2)))
    with pytest.raises(ValueError, match="system is SU2"):
        load_ildg(path, wilson_gauge("SU2", SU3.shape))


def test_foreign_files_and_existing_paths_are_refused(tmp_path):
    path = tmp_path / "config.lime"
    path.write_bytes(b"not a LIME file" * 20)
    with pytest.raises(IldgFileError, match="not a LIME file"):
        load_ildg(path)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_ildg(path, LINKS, SU3)
    save_ildg(path, LINKS, SU3, overwrite=True)
    assert load_ildg(path).tobytes() == LINKS.tobytes()
    with pytest.raises(FileNotFoundError, match="no ILDG file"):
        load_ildg(tmp_path / "missing.lime")


def test_an_su2_field_round_trips_as_su2gauge(tmp_path):
    system = wilson_gauge("SU2", (2, 2, 2, 2))
    links = haar_links(system, 1)
    path = tmp_path / "su2.lime"
    save_ildg(path, links, system)
    assert ildg_header(path).field == "su2gauge"
    assert load_ildg(path).tobytes() == links.tobytes()


@pytest.mark.parametrize(
    ("system", "match"),
    [
        (wilson_gauge("U1", (2, 2, 2, 2)), "4-D SU\\(N\\).*'U1'"),
        (wilson_gauge("SU3", (2, 2)), "in 2 dimensions"),
        (wilson_gauge("SU3", (2, 2, 2, 2), boundary="open"), "must be periodic"),
    ],
    ids=["u1", "two-d", "open"],
)
def test_fields_ildg_cannot_hold_are_refused_by_name(tmp_path, system, match):
    with pytest.raises(ValueError, match=match) as raised:
        save_ildg(tmp_path / "x.lime", np.zeros(system.space.position_array_shape), system)
    assert "system" in str(raised.value)
    assert not (tmp_path / "x.lime").exists()


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"precision": 16}, ValueError, "precision must be 32 or 64"),
        ({"precision": 32.0}, TypeError, "precision must be the int"),
        ({"lfn": 3}, TypeError, "lfn must be a str"),
    ],
    ids=["precision", "float-precision", "lfn"],
)
def test_bad_save_arguments_are_refused_by_name(tmp_path, kwargs, error, match):
    with pytest.raises(error, match=match):
        save_ildg(tmp_path / "x.lime", LINKS, SU3, **kwargs)
    assert not list(tmp_path.iterdir())  # nothing written, no temporary left


def test_links_of_the_wrong_shape_are_refused(tmp_path):
    with pytest.raises(ValueError, match="links must have shape"):
        save_ildg(tmp_path / "x.lime", LINKS[:, :1], SU3)
