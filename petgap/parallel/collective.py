"""Collective decisions: one rank decides, every rank acts on the same verdict.

Checks that touch the file system (does the file exist? is it a petgap file?)
must give the same answer on every rank, or one rank raises while the others
wait in the next collective call and the job hangs.  Rank 0 decides; the value,
or the exception, reaches every rank.

Global sums (:func:`global_sums`) go in one reduction of doubles, however many
numbers a step needs: a reduction costs a latency, not a bandwidth.
"""
import numpy as np
from mpi4py import MPI


def root_decides(comm, func):
    """Run ``func()`` on rank 0; return its value everywhere, or raise its exception everywhere."""
    result = None
    if comm.rank == 0:
        try:
            result = ("ok", func())
        except Exception as exc:  # re-raised on every rank below
            result = ("error", exc)
    status, value = comm.bcast(result, root=0)
    if status == "error":
        raise value
    return value


def global_sums(comm, *values, dtype=np.float64):
    """The sums over the ranks of ``comm`` of ``values``, in one ``Allreduce``.

    ``values`` are numbers (``a, b = global_sums(comm, x, y)``) or a single
    array-like whose shape is kept; they are summed as ``dtype`` (doubles by
    default; ``np.int64`` for counts that must stay exact).  Returns a new
    array, the same on every rank; the caller's values are left alone.
    """
    local = np.array(values[0] if len(values) == 1 and np.ndim(values[0]) else values,
                     dtype=dtype)
    comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
    return local
