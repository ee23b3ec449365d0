"""When an iterative solver stops, and how long it took.

Shared by the conjugate-gradient solvers (:mod:`petgap.solvers.pressure_cg`,
:mod:`petgap.solvers.gap_cg`) and the TAO bridge (:mod:`petgap.solvers.tao`).
"""
import time

import numpy as np


def judge(residual, tolerance, fresh, iteration, max_iterations, history, monitor):
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
        two, the residual is appended to ``history`` and passed to ``monitor``.
    """
    if not np.isfinite(residual):
        return "diverged_nan"
    if residual <= tolerance and not fresh:
        return "refresh"
    history.append(residual)
    if monitor is not None:
        monitor(iteration, residual)
    if residual <= tolerance:
        return "converged_kkt"
    if iteration >= max_iterations:
        return "max_iterations"
    return ""


class Timer:
    """Wall-clock seconds since construction (``time.perf_counter``)."""

    def __init__(self):
        self.start = time.perf_counter()

    def __call__(self):
        return time.perf_counter() - self.start
