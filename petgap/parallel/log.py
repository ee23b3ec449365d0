"""Progress messages and failure reports for runs on many ranks.

* Rank 0 talks: progress at INFO on stdout, warnings and errors on stderr, each
  line stamped with the time since :func:`configure`.  ``quiet`` keeps only
  warnings and errors.
* Every other rank is silent except for errors and for warnings about its own
  data, logged with ``extra=EVERY_RANK``; those lines are prefixed
  ``[rank r/size]``.  Warnings without it are taken to be collective (every
  rank issues the same) and are shown once, by rank 0; so are Python warnings
  (which petgap issues on every rank alike, see :mod:`petgap.surfaces.self_affine`).
* :func:`failed_everywhere` and :func:`report_failure` turn an exception into
  either one clean message (every rank raised) or an abort of the job (only
  some ranks raised, so the others may be waiting in a collective forever).

* :func:`event` names the PETSc log events of petgap's own kernels (the
  elastic operator, the contact-set kernels, the gap-CG passes), so that
  ``-log_view`` and ``PETSc.Log.Event.getPerfInfo`` see them beside PETSc's.

Nothing happens at import: call :func:`configure` once (the CLI does).
"""
import logging
import os
import sys
import time
import traceback
import warnings

LOGGER_NAME = "petgap"

#: ``logger.warning(msg, extra=EVERY_RANK)``: a warning about this rank's own data,
#: shown by every rank that issues it (other warnings are shown by rank 0 only).
EVERY_RANK = {"every_rank": True}

#: Seconds the ranks that raised wait for the others before concluding that only they
#: did (environment variable PETGAP_FAILURE_TIMEOUT overrides).
FAILURE_TIMEOUT = 10.0


def _failure_timeout(timeout):
    if timeout is not None:
        return float(timeout)
    return float(os.environ.get("PETGAP_FAILURE_TIMEOUT", FAILURE_TIMEOUT))


class _Formatter(logging.Formatter):
    def __init__(self, prefix, start):
        super().__init__()
        self.prefix, self.start = prefix, start

    def format(self, record):
        elapsed = record.created - self.start
        level = "" if record.levelno < logging.WARNING else f"{record.levelname.lower()}: "
        text = f"{self.prefix}[{elapsed:7.2f} s] {level}{record.getMessage()}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return text


class _RankLocal(logging.Filter):
    """On ranks other than 0: errors, and warnings logged with ``extra=EVERY_RANK``."""

    def filter(self, record):
        return record.levelno >= logging.ERROR or getattr(record, "every_rank", False)


class _Below(logging.Filter):
    def __init__(self, level):
        super().__init__()
        self.level = level

    def filter(self, record):
        return record.levelno < self.level


def configure(comm=None, quiet=False, stdout=None, stderr=None):
    """Set up the ``petgap`` logger for this rank and return it.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm, optional
        Communicator whose rank 0 reports progress (default ``COMM_WORLD``).
    quiet : bool
        Rank 0 reports warnings and errors only.
    stdout, stderr : file-like, optional
        Streams (default ``sys.stdout`` and ``sys.stderr`` at call time).
    """
    if comm is None:
        # Deferred: importing mpi4py initialises MPI, which nothing here needs at import.
        from mpi4py import MPI
        comm = MPI.COMM_WORLD
    stdout = sys.stdout if stdout is None else stdout
    stderr = sys.stderr if stderr is None else stderr
    logger = logging.getLogger(LOGGER_NAME)
    for handler in list(logger.handlers):
        logger.removeHandler(handler)
    logger.propagate = False
    start = time.time()
    root = comm.rank == 0
    prefix = "petgap " if comm.size == 1 or root else f"petgap [rank {comm.rank}/{comm.size}] "
    formatter = _Formatter(prefix, start)

    err = logging.StreamHandler(stderr)
    err.setLevel(logging.WARNING)
    err.setFormatter(formatter)
    if not root:
        err.addFilter(_RankLocal())
    logger.addHandler(err)
    if root:
        out = logging.StreamHandler(stdout)
        out.setLevel(logging.DEBUG)
        out.addFilter(_Below(logging.WARNING))
        out.setFormatter(formatter)
        logger.addHandler(out)
    logger.setLevel(logging.WARNING if (quiet or not root) else logging.INFO)

    # Python warnings: every rank issues the same ones (petgap.surfaces.self_affine does so on
    # purpose, for -W error); they go through the logger, so rank 0 shows them once.
    warnings.showwarning = _show_warning
    return logger


def configured(comm=None):
    """The ``petgap`` logger, set up by :func:`configure` unless a handler already shows it.

    For library calls that run long (:func:`petgap.contact`): a script that never set up
    logging still sees their progress on rank 0, and one that did keeps its own set-up
    (handlers of the ``petgap`` logger, or of the root logger it propagates to).
    """
    logger = logging.getLogger(LOGGER_NAME)
    if logger.handlers or logging.getLogger().handlers:
        return logger
    return configure(comm)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    kind = "" if category is UserWarning else f"{category.__name__}: "
    logging.getLogger(LOGGER_NAME).warning("%s%s", kind, message)


def get_logger(name=None):
    """The ``petgap`` logger, or its child ``petgap.<name>``."""
    return logging.getLogger(LOGGER_NAME if not name else f"{LOGGER_NAME}.{name}")


class timed:
    """Context manager logging ``what`` and, at the end, how long it took.

    >>> with timed(log, "building the surface"):
    ...     ...
    """

    def __init__(self, logger, what):
        self.logger, self.what = logger, what

    def __enter__(self):
        self.start = time.perf_counter()
        self.logger.info("%s ...", self.what)
        return self

    def __exit__(self, exc_type, exc, tb):
        self.seconds = time.perf_counter() - self.start
        if exc_type is None:
            self.logger.info("%s: done in %.2f s", self.what, self.seconds)
        return False


# ------------------------------------------------------ failures across ranks
def failed_everywhere(comm, timeout=None, poll=0.01):
    """Call on every rank that caught an exception: did every rank of ``comm`` do so?

    A non-blocking barrier on ``comm``, which must be a communicator reserved
    for this purpose (a ``Dup`` made while all ranks were healthy), so that it
    cannot match any collective the healthy ranks are blocked in.  Returns True
    once every rank has called it, False if that does not happen within
    ``timeout`` seconds (default :data:`FAILURE_TIMEOUT`); then the caller
    should abort the job (the barrier is left pending).
    """
    if comm.size == 1:
        return True
    timeout = _failure_timeout(timeout)
    request = comm.Ibarrier()
    deadline = time.monotonic() + timeout
    while not request.Test():
        if time.monotonic() > deadline:
            return False
        time.sleep(poll)
    return True


def report_failure(exc, comm, failure_comm, clean_types=(ValueError, OSError),
                   timeout=None, program="petgap", stream=None):
    """Report an exception caught on this rank and return the exit code, or abort.

    * Raised on every rank (see :func:`failed_everywhere`) and an instance of
      ``clean_types`` (a user error: invalid scene, impossible decomposition,
      existing output...): rank 0 prints ``<program>: error: <message>``, no
      traceback; returns 2 on every rank.
    * Raised on every rank, any other type: rank 0 prints the traceback;
      returns 1.
    * Raised on every rank with ``exc.abort_job`` true (a failed write into an
      HDF5 file, :class:`petgap.io.results.ResultWriteError`): reported as above,
      then ``comm.Abort(2)``, so that nothing -- not even the interpreter's
      shutdown -- closes the damaged file.
    * Raised on some ranks only: this rank prints its traceback, prefixed with
      its rank, and calls ``comm.Abort(1)`` (the other ranks may never return
      from a collective).
    """
    stream = sys.stderr if stream is None else stream
    timeout = _failure_timeout(timeout)
    if failed_everywhere(failure_comm, timeout):
        if comm.rank == 0:
            if isinstance(exc, clean_types):
                print(f"{program}: error: {exc}", file=stream, flush=True)
            else:
                text = "".join(traceback.format_exception(exc))
                print(f"{text}{program}: internal error: {type(exc).__name__}: {exc}",
                      file=stream, flush=True)
        if getattr(exc, "abort_job", False):
            failure_comm.Barrier()  # rank 0 has printed
            comm.Abort(2)
        return 2 if isinstance(exc, clean_types) else 1
    text = "".join(traceback.format_exception(exc))
    print(f"{text}{program}: error on rank {comm.rank} of {comm.size} only "
          f"(the other ranks did not fail within {timeout:g} s): {type(exc).__name__}: {exc}\n"
          f"{program}: aborting all ranks", file=stream, flush=True)
    comm.Abort(1)
    return 1  # not reached


# ------------------------------------------------------------------ PETSc events
#: Every whole application of the elastic operator ``K`` or ``K^{-1}``, dense or sparse
#: (:class:`petgap.mechanics.half_space.ElasticHalfSpace`); its count and half that of
#: :data:`OPERATOR_HALF_EVENT` are the solutions' ``operator_applications``.
OPERATOR_EVENT = "petgap:operator"
#: Half an application: the forward or the inverse half of the operator applied to a
#: search direction, run apart (``ElasticHalfSpace.begin_sparse``, ``begin_in_buffer``
#: and ``finish``); each counts half of one of the solutions' ``operator_applications``.
OPERATOR_HALF_EVENT = "petgap:operatorHalf"
#: The pressure solver's pass over the slab that finds the gap and its penetrations.
GAP_PASS_EVENT = "petgap:gapPass"
#: The pressure solver's update of the contact set (projected step, merge).
SET_UPDATE_EVENT = "petgap:setUpdate"
#: The gap solver's passes over the slab (sums, direction, step, projection).
GAP_CG_EVENT = "petgap:gapCG"

_events = {}


def event(name):
    """The PETSc log event ``name``, registered on first use and kept for the process.

    Use as ``with event(OPERATOR_EVENT): ...``; ``-log_view`` lists it, and
    ``event(name).getPerfInfo()`` gives its count and time once logging is on
    (``PETSc.Log.begin()``).  Registration is local to the process, not
    collective.
    """
    found = _events.get(name)
    if found is None:
        # Deferred: importing petsc4py initialises PETSc, which the modules that
        # only log messages (post-processing) never need.
        from petsc4py import PETSc
        found = _events[name] = PETSc.Log.Event(name)
    return found
