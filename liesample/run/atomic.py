"""A file replaced whole or not at all: each new version is written beside it and published by
one rename.

The run file (:mod:`liesample.run.store`) is an HDF5 file, and HDF5 modified in place is not
crash-safe: a write that fails half-way (a full disk, a kill, a crash) may leave metadata that
earlier, committed chunks share unreadable. So the committed file is never opened for writing.
:func:`replacing` gives a temporary sibling in the same directory (``.<name>.tmp-<pid>``),
holding a copy of the committed file (``shutil.copyfile``, which lets the kernel copy), or
nothing for a new file; the caller writes the new version there, and when it is done the
sibling is synced to disk, renamed over the file (``os.replace``, atomic on POSIX and Windows
within one file system) and the directory synced, so that the rename itself is durable. Any
failure before the rename, however it happens, leaves the committed file as it was: the
sibling is removed, or, after a kill, left behind and removed by the next writer
(:func:`remove_leftovers`; the writer holds the output's lock, so no live writer owns it).

The cost: every version copies the whole file once, so a run saved in ``n`` chunks copies
about ``n / 2`` times its final size in all, and needs room for two copies of the file at the
moment of each rename. The free space is checked before the copy (:func:`check_space`), so a
disk that cannot hold the next version is refused before anything is written, naming the path,
the bytes needed and the bytes free.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil


def temporary_path(path: str) -> str:
    """The sibling that the next version of ``path`` is written to, in this process."""
    directory, name = os.path.split(os.path.abspath(path))
    return os.path.join(directory, f".{name}.tmp-{os.getpid()}")


def leftovers(path: str) -> list[str]:
    """The temporary siblings of ``path`` left by writers that were killed while writing."""
    directory, name = os.path.split(os.path.abspath(path))
    pattern = re.compile(rf"\.{re.escape(name)}\.tmp-\d+")
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    return sorted(os.path.join(directory, n) for n in names if pattern.fullmatch(n))


def remove_leftovers(path: str):
    """Remove the temporary siblings of ``path`` (call it only while holding its lock)."""
    for leftover in leftovers(path):
        with contextlib.suppress(FileNotFoundError):
            os.remove(leftover)


def free_bytes(path: str) -> int | None:
    """The bytes free to this user on the file system of ``path``'s directory (``None`` where
    the platform cannot say)."""
    if not hasattr(os, "statvfs"):
        return None
    try:
        stats = os.statvfs(os.path.dirname(os.path.abspath(path)))
    except OSError:
        return None
    return stats.f_bavail * stats.f_frsize


def check_space(path: str, needed: int, saving: str, kept: str | None):
    """Refuse (``OSError`` with ``errno.ENOSPC``) unless ``needed`` bytes are free beside
    ``path``: the message names the path, the bytes needed and free, and how to go on."""
    free = free_bytes(path)
    if free is not None and free < needed:
        raise OSError(
            errno.ENOSPC,
            f"not enough free space to save {saving} in {path!r}: about {needed} bytes are "
            f"needed (a new copy of the file and the new draws) and {free} are free on its file "
            f"system. {advice(kept)}",
        )


def advice(kept: str | None) -> str:
    """How to go on after a failed save: ``kept`` says what the file still holds (``None``: no
    file was written yet)."""
    if kept is None:
        return (
            "Nothing was saved and no file was left at that path; free some space (or choose "
            "an output on a disk with room), then run again"
        )
    return (
        f"The file is unchanged and still holds {kept}; free some space (or move the file to a "
        "disk with room and give its new path as output=), then pass resume=True to continue "
        "the run"
    )


def _sync(path: str, directory: bool = False):
    """Flush ``path`` (a file, or a directory: its entries) to disk. A directory that cannot be
    opened for this (Windows) is skipped: its rename is as durable as the platform makes it."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) if directory else os.O_RDONLY
    try:
        fd = os.open(path, flags)
    except OSError:
        if directory:
            return
        raise
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(path: str, *, copy: bool, extra_bytes: int, saving: str, kept: str | None):
    """The temporary sibling of ``path`` to write its next version to (holding a copy of
    ``path`` if ``copy``), published over ``path`` when the block ends without an error.

    ``extra_bytes``: about how much the new version adds; ``saving`` and ``kept`` name, in an
    error, what was being saved and what ``path`` still holds (:func:`advice`). Any error (or
    interrupt) before the rename removes the sibling and leaves ``path`` untouched; an
    ``OSError`` is raised again naming ``path`` and how to go on."""
    work = temporary_path(path)
    size = os.path.getsize(path) if copy else 0
    check_space(path, size + extra_bytes, saving, kept)  # before anything is written
    try:
        if copy:
            shutil.copyfile(path, work)
            shutil.copymode(path, work)
        yield work
        _sync(work)
        os.replace(work, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            os.remove(work)
        if isinstance(error, OSError):
            reason = " ".join((error.strerror or str(error)).split())  # HDF5's: many lines
            raise OSError(
                error.errno, f"cannot save {saving} in {path!r}: {reason}. {advice(kept)}"
            ) from None
        raise
    try:
        _sync(os.path.dirname(os.path.abspath(path)), directory=True)
    except OSError as error:
        raise OSError(
            error.errno,
            f"saved {saving} in {path!r}, but its directory could not be synced to disk "
            f"({error.strerror or error}): a power loss now may return the file to its previous "
            "version; pass resume=True to continue the run",
        ) from None
