"""One writer per result file: an advisory lock that a crashed job cannot leave stuck.

Rank 0 of a run holds an exclusive ``flock`` on the sidecar file ``.<name>.lock``
beside the result for as long as the run may write it.  The kernel drops the
lock when the process ends, however it ends (``kill -9``, a node crash, ``MPI_Abort``),
so a stale sidecar file never blocks a later run: only a live job does.  The
sidecar holds who has the lock (host, PID, start time, command line), for the
refusal of a second job.  ``flock`` locks are per open file on the local
machine; on a network file system without ``flock`` support (some NFS set-ups)
acquiring fails, and petgap says so instead of running unprotected.
"""
import datetime
import fcntl
import os
import socket
import sys
from pathlib import Path

from petgap.parallel.collective import root_decides


class ResultLockedError(OSError):
    """Another live petgap job is writing the same result file."""


def lock_path(output):
    """The sidecar lock file of result file ``output``: ``.<name>.lock`` beside it."""
    output = Path(output)
    return output.with_name(f".{output.name}.lock")


class ResultLock:
    """The writer's lock on a result file (collective: acquired and released by rank 0).

    Use as a context manager around everything that may write the file::

        with ResultLock(output, comm):
            ...

    Raises :class:`ResultLockedError` on every rank if another job holds it.
    """

    def __init__(self, output, comm):
        self.output, self.comm = Path(output), comm
        self.path = lock_path(output)
        self._fd = None

    def __enter__(self):
        self._fd = root_decides(self.comm, self._acquire)
        return self

    def __exit__(self, *exc):
        if self.comm.rank == 0 and self._fd is not None:
            try:
                os.unlink(self.path)        # before unlocking: a waiting job re-checks it
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None
        return False

    def _acquire(self):
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:  # a directory or a device there, a read-only directory
                what = "a directory" if self.path.is_dir() else exc.strerror
                raise ResultLockedError(
                    f"cannot make the lock file {self.path} of {self.output}: {what}; remove "
                    f"or rename it, or choose another --output") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read(fd)
                os.close(fd)
                raise ResultLockedError(
                    f"another petgap job is writing {self.output} ({holder or 'holder unknown'}; "
                    f"lock file {self.path}): wait for it to end, or choose another "
                    f"--output") from None
            except OSError as exc:
                os.close(fd)
                raise ResultLockedError(
                    f"cannot lock {self.path} for {self.output}: {exc} (file locking is not "
                    f"supported here?); choose an --output on a local file system") from None
            # the file may have been unlinked by the previous holder between open and flock
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        text = (f"host {socket.gethostname()}, pid {os.getpid()}, since {now}, "
                f"command: {' '.join(sys.argv)}\n")
        os.ftruncate(fd, 0)
        os.pwrite(fd, text.encode(), 0)
        return fd if self.comm.rank == 0 else None


def _read(fd):
    try:
        return os.pread(fd, 4096, 0).decode(errors="replace").strip()
    except OSError:
        return ""
