"""Collective helpers: one rank decides and every rank acts on the verdict; global sums.

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
