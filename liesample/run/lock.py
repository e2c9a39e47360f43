"""One writer per output file: an exclusive lock held for the whole run.

The lock is the file ``<output>.lock`` locked with ``flock`` (POSIX advisory locks): the
kernel drops it when its process ends, however it ends, so a run killed with SIGKILL leaves no
lock behind that could block its resume (the stale file is taken over). It is a file apart from
the output, which each saved chunk replaces by a rename (:mod:`liesample.run.atomic`): the lock
holds across those replacements, and while it is held no other writer's copy of the output can
be live, so the holder removes the copies a killed writer left. The file holds the
holder's process id, host and start time, so a refused writer can say who holds the path.
Advisory locks protect against other liesample runs, not against other programs writing the
file; on network file systems without ``flock`` support the lock may not hold.
"""

from __future__ import annotations

import os
import socket
import time


class OutputLockedError(RuntimeError):
    """Another run is writing to this output path."""


class OutputLock:
    """The lock of ``path`` (a context manager): :meth:`acquire` at once or refuse."""

    def __init__(self, path: str):
        self.path = os.fspath(path)
        self.lock_path = self.path + ".lock"
        self._fd: int | None = None

    def acquire(self):
        """Take the lock, or raise :class:`OutputLockedError` naming the holder (no waiting)."""
        import fcntl

        while True:
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as error:
                raise OSError(
                    f"cannot create the lock file {self.lock_path!r} for output {self.path!r}: "
                    f"{error.strerror or error}"
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 1000).decode(errors="replace").strip() or "unknown holder"
                os.close(fd)
                raise OutputLockedError(
                    f"output {self.path!r} is being written by another run ({holder}; lock "
                    f"file {self.lock_path!r}): wait for that run to finish, or choose another "
                    "output path"
                ) from None
            if self._still_at_path(fd):
                break
            os.close(fd)  # the holder removed the file as we opened it: take the new one
        os.ftruncate(fd, 0)
        stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime())
        os.write(fd, f"pid {os.getpid()} on host {socket.gethostname()} since {stamp}".encode())
        self._fd = fd
        return self

    def _still_at_path(self, fd) -> bool:
        try:
            return os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            return False

    def release(self):
        """Remove the lock file, then drop the lock (in that order: a writer that opened the
        removed file sees it is no longer at the path and opens a fresh one)."""
        if self._fd is None:
            return
        try:
            os.unlink(self.lock_path)
        except FileNotFoundError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
