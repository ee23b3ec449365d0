"""Collective helpers: one rank decides and every rank acts on the verdict; global sums.

Checks that touch the file system (does the file exist? is it a petgap file?)
must give the same answer on every rank, or one rank raises while the others
wait in the next collective call and the job hangs.  Rank 0 decides; the value,
or the exception, reaches every rank.
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
