"""Sweeps: solves in order, each warm-started from the one before.

A sweep follows one branch of a possibly multistable (adhesive) problem by
warm-starting every step from the previous state, and marks each state with
the direction of the step and whether it jumped to another branch, so that
hysteresis (snap-in, pull-off) is recorded rather than averaged away.
"""
import math

from petgap.mechanics.problem import Load
from petgap.solvers.dispatch import solve


def sweep(problem, controls, **kwargs):
    """Solve a list of controls in order, each warm-started from the previous one.

    Yields each :class:`~petgap.mechanics.problem.ContactSolution` as soon as it is done,
    so the caller can store it before the next step starts.  Each solution gets

    * ``direction``: ``"loading"`` when the control pushes the surfaces together
      (larger load, smaller mean gap) relative to the previous step,
      ``"unloading"`` when it pulls them apart, ``"start"`` for the first;
    * ``jump``: True when the area at zero gap (``zero_gap_fraction``: repulsive
      and tensile contact alike) changed faster (per unit control) than 3 times
      the previous step did *and* by more than 1 % of the cell -- the signature
      of an instability (snap-in, pull-off) where the warm start left one branch
      of an adhesive, multistable problem for another.  A sweep that reverses
      direction therefore exposes hysteresis: the same control value may carry
      different states on loading and unloading, and which one was found is
      recorded, never averaged away.

      Why not the repulsive area (``contact_fraction``): near the end of a
      JKR-like branch under mean-gap control the surfaces are still stuck, but
      all in tension, so the repulsive area is already zero and pull-off leaves
      it unchanged.  Being a comparison of rates, the test needs a step onto the
      instability not much longer than the steps before it: near the end of a
      branch the area changes like ``sqrt(g_end - g_bar)``, ever faster, and a
      step that ends just short of pull-off sets a high rate for the next one
      to beat (``tests/solvers/test_adhesion.py`` resolves Johnson's pull-off with
      steps of 0.2, 0.1, 0.07 and 0.03 ``h_a``).
    """
    previous = kwargs.pop("initial", None)
    last_rate = None
    for control in controls:
        solution = solve(problem, control, initial=previous, **kwargs)
        last_rate = annotate_step(solution, previous, last_rate)
        previous = solution
        yield solution


def annotate_step(solution, previous, last_rate):
    """Set ``solution.direction`` and ``solution.jump`` relative to ``previous`` (see :func:`sweep`).

    Returns the rate of change of the area at zero gap per unit control, for
    the next step's comparison (None when there is no previous step to compare
    with: the first step of a sweep has no reference and is never a jump; nor
    is a step after a state whose ``zero_gap_fraction`` is None, a step read
    back from a result file that stores neither it nor the gap).
    """
    solution.direction, solution.jump = "start", False
    if previous is None or previous.control.kind != solution.control.kind:
        return None
    change = solution.control.value - previous.control.value
    pushes = change > 0 if isinstance(solution.control, Load) else change < 0
    solution.direction = "loading" if pushes else "unloading"
    if solution.zero_gap_fraction is None or previous.zero_gap_fraction is None:
        return None
    dc = solution.zero_gap_fraction - previous.zero_gap_fraction
    rate = abs(dc / change) if change != 0 else (math.inf if dc else 0.0)
    solution.jump = bool(last_rate is not None and abs(dc) > 0.01 and rate > 3 * last_rate)
    return rate
