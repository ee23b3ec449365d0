"""Collective helpers: one rank decides and every rank acts on the verdict; global sums;
rows moved between two slab decompositions.

Checks that touch the file system (does the file exist? is it a petgap file?)
must give the same answer on every rank, or one rank raises while the others
wait in the next collective call and the job hangs.  Rank 0 decides; the value,
or the exception, reaches every rank.
"""
import pickle
import time

import numpy as np
from mpi4py import MPI


def root_decides(comm, func, *, poll=None):
    """Run ``func()`` on rank 0; return its value everywhere, or raise its exception everywhere.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
    func : callable
        Called on rank 0 only, without arguments.
    poll : float, optional
        Seconds between the other ranks' looks at whether rank 0 is done; they
        sleep in between.  For long work on rank 0 (drawing a figure, running a
        subprocess): Open MPI's blocking collectives busy-wait, and on a machine
        with as many cores as ranks the waiting ranks would starve rank 0.
    """
    result = failure = None
    if comm.rank == 0:
        try:
            result = ("ok", func())
        except Exception as exc:  # re-raised on every rank below
            failure, result = exc, ("error", _portable(exc))
    if poll is not None:
        request = comm.Ibarrier()
        while not request.Test():
            time.sleep(poll)
    status, value = comm.bcast(result, root=0)
    if failure is not None:
        raise failure  # rank 0 keeps its own exception, with its traceback
    if status == "error":
        raise value
    return value


def _portable(exc):
    """``exc`` if it survives pickling, else a RuntimeError that names it (no rank may hang)."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")


def global_sums(comm, *values, dtype=np.float64):
    """The sums over ``comm`` of scalars or equally shaped arrays, in one reduction.

    ``global_sums(comm, a, b, c)`` returns an array ``[sum a, sum b, sum c]``
    (one ``Allreduce``, so one synchronisation however many sums a step
    needs); a single array (or list) argument is summed element by element and
    keeps its shape.  Sums are taken in ``dtype`` (double by default, also for
    single-precision inputs).
    """
    single_array = len(values) == 1 and np.ndim(values[0]) > 0
    buf = np.array(values[0] if single_array else values, dtype=dtype)
    comm.Allreduce(MPI.IN_PLACE, buf, op=MPI.SUM)
    return buf


def move_rows(comm, block, first, lo, hi):
    """Give each rank the rows it wants of those held here, in one ``Alltoallv``.

    ``block`` holds global rows ``first, first + 1, ...``; this rank wants rows
    ``lo <= row < hi`` from whoever holds them.  Returns ``(first row, rows)``
    for every non-empty piece received, in rank order; pieces overlap where
    two ranks hold parts of the same row (partial sums).  On one rank the one
    piece is a view of ``block`` (no message to itself), so callers copy the
    pieces out before they change ``block``.
    """
    if comm.size == 1:
        start, stop = max(lo, first), min(hi, first + len(block))
        return [(start, block[start - first:stop - first])] if stop > start else []
    block = np.ascontiguousarray(block, dtype=float)
    k, width = block.shape
    held = comm.allgather((first, first + k))
    wanted = comm.allgather((lo, hi))
    send_counts, send_offsets = [], []
    for a, b in wanted:
        start, stop = max(a, first), min(b, first + k)
        rows = max(stop - start, 0)
        send_counts.append(rows * width)
        send_offsets.append((start - first) * width if rows else 0)
    recv_counts, recv_offsets, pieces, total = [], [], [], 0
    for a, b in held:
        start, stop = max(a, lo), min(b, hi)
        rows = max(stop - start, 0)
        recv_counts.append(rows * width)
        recv_offsets.append(total)
        pieces.append((start, rows))
        total += rows * width
    received = np.empty(total)
    comm.Alltoallv([block, (send_counts, send_offsets), MPI.DOUBLE],
                   [received, (recv_counts, recv_offsets), MPI.DOUBLE])
    return [(start, received[offset:offset + rows * width].reshape(rows, width))
            for (start, rows), offset in zip(pieces, recv_offsets) if rows]
