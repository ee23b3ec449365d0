"""When an iterative solver stops, and how long it took.

Shared by the conjugate-gradient solvers (:mod:`petgap.solvers.pressure_cg`,
:mod:`petgap.solvers.gap_cg`) and the TAO bridge (:mod:`petgap.solvers.tao`).
"""
import time

import numpy as np


def judge(residual, tolerance, fresh, iteration, max_iterations, history, monitor,
          objective=None):
    """The verdict of an iterative solver on the residual at the start of an iteration.

    The conjugate-gradient solvers update their fields by recurrences between
    fresh transforms: a converged verdict is only given on a fresh
    evaluation, so that accumulated round-off never passes for convergence.

    Returns
    -------
    str
        ``"diverged_nan"``; ``"refresh"`` (converged on a recurrence: evaluate
        afresh and judge again; nothing is recorded); ``"converged_kkt"`` or
        ``"max_iterations"`` (stop); or ``""`` (carry on).  Except for the first
        two, the residual is appended to ``history`` and passed to ``monitor``:
        ``monitor(iteration, residual)``, or ``monitor(iteration, residual, F)`` with
        ``F = objective()`` if the monitor has a true ``wants_objective`` attribute
        (TAO's ``-tao_monitor``) and the solver can say what it minimises; ``objective``
        is collective, and costs a pass over the fields, so it is only called then.
    """
    if not np.isfinite(residual):
        return "diverged_nan"
    if residual <= tolerance and not fresh:
        return "refresh"
    history.append(residual)
    if monitor is not None:
        if objective is not None and getattr(monitor, "wants_objective", False):
            monitor(iteration, residual, objective())
        else:
            monitor(iteration, residual)
    if residual <= tolerance:
        return "converged_kkt"
    if iteration >= max_iterations:
        return "max_iterations"
    return ""


def secant_tolerance(tolerance, error, forcing, loosest):
    """KKT tolerance of the next inner solve of an inexact secant on a control (unit-free).

    Why: a solve's KKT residual ``r`` moves the mean gap it is judged by by about
    ``r h0``, so a step that has a mean-gap error ``error h0`` left to remove needs
    its solve only to a fraction ``forcing`` of it (as inexact Newton methods
    choose their forcing terms), never looser than ``loosest`` and never tighter
    than ``tolerance``, which the last solve meets.  The first solve, whose error
    is not known yet (``error`` None), goes to ``loosest``.
    """
    if error is None:
        return max(tolerance, loosest)
    return max(tolerance, min(loosest, forcing * abs(error)))


class Timer:
    """Wall-clock seconds since construction (``time.perf_counter``)."""

    def __init__(self):
        self.start = time.perf_counter()

    def __call__(self):
        return time.perf_counter() - self.start


class BestResidual:
    """The lowest residual of a solve and the iteration it came at, what the solvers'
    stall rules count from: a residual is better only below ``factor`` times the best,
    so that a residual wandering at its floor does not keep renewing it."""

    def __init__(self, factor):
        self.factor = float(factor)
        self.value, self.at = np.inf, 0

    def since(self, iteration, residual):
        """Record ``residual`` at ``iteration``; the iterations since the best (0 if it is)."""
        if residual < self.factor * self.value:
            self.value, self.at = residual, iteration
        return iteration - self.at


class ResidualTrend:
    """When will the residual reach the tolerance?  An estimate from its decay so far.

    Conjugate-gradient residuals fall roughly geometrically once the contact set
    has settled, so ``log(residual)`` is fitted by least squares as a straight line
    in wall time over the most recent ``window`` observations and extrapolated to
    the tolerance.  The estimate is for people watching a long run (a progress line
    with "about N s to go"), not for decisions: it is ``None`` until there are
    ``min_points`` observations or while the fitted residual does not fall.
    """

    def __init__(self, tolerance, window=30, min_points=4):
        self.tolerance = float(tolerance)
        self.window, self.min_points = int(window), int(min_points)
        self.times, self.logs = [], []

    def add(self, seconds, residual):
        """Record the residual at ``seconds`` since the start (non-positive residuals
        mean converged and end the estimate)."""
        if residual > 0 and np.isfinite(residual):
            self.times.append(float(seconds))
            self.logs.append(float(np.log(residual)))
            del self.times[:-self.window], self.logs[:-self.window]

    def remaining(self):
        """Seconds until the fitted residual reaches the tolerance, or None."""
        if len(self.times) < self.min_points:
            return None
        t, y = np.array(self.times), np.array(self.logs)
        if np.ptp(t) <= 0:
            return None
        slope, intercept = np.polyfit(t, y, 1)
        if not slope < 0:
            return None
        finish = (np.log(self.tolerance) - intercept) / slope
        return max(0.0, float(finish - t[-1]))
