"""What a long solve tells the person waiting for it: progress, outer steps, a verdict.

Progress goes through the ``petgap`` logger at INFO (rank 0 shows it,
:mod:`petgap.parallel.log`), so that ``petgap run`` and a script that configured
logging (:func:`petgap.contact` does, if nothing has) see it alike:

* :class:`SolveProgress`, the monitor :func:`petgap.solve` uses when its caller gives
  none: the iteration, the KKT residual against its target and the time so far, at
  most every :data:`PROGRESS_INTERVAL` seconds, so that a short solve stays silent;
  and, if it said anything, the verdict at the end.
* :func:`outer_step`: one line per step of an outer loop (the secant of adhesive load
  control, the mean-gap steps of a free map's padded cell), with the step's number
  against the loop's bound, which every outer loop has.
"""
import time

from petgap.parallel.log import get_logger

#: Seconds between two progress lines of one solve (and before the first).
PROGRESS_INTERVAL = 5.0


def _log():
    return get_logger("solvers")


class SolveProgress:
    """A solver monitor that logs the iteration, the residual against ``tolerance`` and
    the time, at most every :data:`PROGRESS_INTERVAL` seconds; :meth:`verdict` ends it."""

    def __init__(self, tolerance):
        self.tolerance = float(tolerance)
        self.start = self.last = time.perf_counter()
        self.talked = False

    def __call__(self, iteration, residual):
        now = time.perf_counter()
        if now - self.last >= PROGRESS_INTERVAL:
            self.last, self.talked = now, True
            _log().info("  iteration %d: KKT residual %.3e (target %.0e), %.1f s",
                        iteration, residual, self.tolerance, now - self.start)

    def verdict(self, solution):
        """Log how the solve ended, if it reported progress (a long solve) or failed."""
        if solution.converged and not self.talked:
            return
        what = "converged" if solution.converged else f"NOT converged ({solution.reason})"
        _log().log(20 if solution.converged else 30,
                   "solve %s after %d iterations, %.1f s: KKT residuals %.2e (pressure), "
                   "%.2e (gap), target %.0e", what, solution.iterations,
                   time.perf_counter() - self.start, solution.kkt_pressure, solution.kkt_gap,
                   self.tolerance)


def outer_step(loop, step, bound, timer, text):
    """Log step ``step`` (from 1) of at most ``bound`` of the outer loop ``loop``."""
    _log().info("  %s: step %d of at most %d, %s (%.1f s)", loop, step, bound, text, timer())
