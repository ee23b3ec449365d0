"""The outer loop that reaches one control through solves under another.

Mean-gap control for TAO's built-ins, which minimise the load-control energy: a
secant on the multiplier ``log(P0)`` around inexact load solves
(:func:`solve_mean_gap_by_multiplier`).

:func:`solve_as` runs a solver type the registry resolved
(:mod:`petgap.io.solver_registry`) through the loop its control needs; the inner
solves are TAO solves (:func:`petgap.solvers.tao.tao_solve`).
"""
import math

import numpy as np
from mpi4py import MPI

from petgap.io.solver_registry import method
from petgap.mechanics.problem import Load
from petgap.solvers.convergence import Timer
from petgap.solvers.tao import tao_solve


def solve_as(problem, control, kind, settings, initial=None, monitor=None):
    """Solve a periodic ``problem`` (or a free map by the pressure solver) with type ``kind``.

    ``kind`` is a resolved solver type (never ``"pcg"``:
    :func:`petgap.io.solver_registry.resolve`), run through the loop its control needs
    (:func:`petgap.io.solver_registry.method`): mean-gap control of a TAO built-in by
    :func:`solve_mean_gap_by_multiplier`, anything else by one :func:`tao_solve`.
    ``initial`` is a warm start (a previous solution).  Collective.
    """
    how = method(kind, control.kind, problem.half_space.periodic)
    loops = {"multiplier": solve_mean_gap_by_multiplier, "direct": tao_solve}
    if how not in loops:
        raise ValueError(f"{kind} reaches {control.kind} control here by {how!r}, which "
                         f"petgap.solvers.dispatch.run runs, not a TAO solve")
    return loops[how](problem, control, kind, settings, initial, monitor)


def solve_mean_gap_by_multiplier(problem, control, kind, settings, initial=None, monitor=None,
                                 max_outer=60):
    """Mean-gap control for gap-space TAO types: secant on log(P0) until mean(g) = g_bar.

    Inexact: each inner load-control solve is only as accurate as the step it
    serves (:func:`_inner_tolerance`).  Why not a fixed inner tolerance well
    below the outer one: TAO's line searches compare energies, whose round-off
    hides the decrease of a step once the KKT residual nears it, so a fixed
    ``tolerance / 100`` may be out of reach and would spend the whole iteration
    budget of a step on its first inner solve, at a guessed ``P0`` that the secant
    would replace anyway.  Every constant here is in the problem's scales (``h0``,
    ``h0' E*``), so the iterations are the same in every unit system.
    """
    timer = Timer()
    target = float(control.mean_gap)
    tolerance = settings.tolerance
    apart = _apart(problem, control, kind, timer)
    if apart is not None:
        return apart
    start_ops = problem.operator_applications
    solution, iterations, history, exhausted = _multiplier_secant(
        problem, target, kind, settings, initial, monitor, max_outer)
    usable = _meets_kkt(solution, tolerance)
    converged = not exhausted and usable and \
        abs((solution.mean_gap - target) / problem.gap_scale) <= tolerance
    reason = "converged_kkt" if converged else "max_iterations" if exhausted else \
        (solution.reason if not usable else "multiplier_not_converged")
    return problem.make_solution(
        solution.gap, solution.pressure, solution.gap <= 0, control, converged=converged,
        reason=reason, solver=f"{kind}+multiplier", iterations=iterations,
        operator_applications=problem.operator_applications - start_ops, wall_time=timer(),
        history=history)


def _apart(problem, control, kind, timer):
    """The undeformed state when the hard wall's highest summit stays clear of the mean gap.

    No contact, no pressure: the rigid surface held ``g_bar`` above its mean height.
    None when there is contact to solve for (or an adhesive interaction).
    """
    target = float(control.mean_gap)
    grid = problem.grid
    top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
    if problem.interaction.adhesive or target < top - problem.mean_height:
        return None
    gap = target + problem.mean_height - problem.topography
    zero = np.zeros(grid.local_shape)
    return problem.make_solution(gap, zero, gap <= 0, control, converged=True,
                                 reason="no_contact", solver=f"{kind}+multiplier",
                                 iterations=0, operator_applications=0, wall_time=timer())


def _multiplier_secant(problem, target, kind, settings, initial, monitor, max_outer):
    """The secant on ``log(P0 / h0' E*)`` of :func:`solve_mean_gap_by_multiplier`.

    An adhesive state may hold its mean gap under tension (``P0 < 0``), which no
    logarithm reaches: there the variable is ``asinh(P0 / c)``, ``c = 0.01 h0' E*``
    the starting load, which is ``log(2 P0 / c)`` well above ``c`` and linear through
    zero.  Its steps are at most 1 (5 for the logarithm): a tensile load beyond the
    pull-off has no state, and a longer step into tension finds none.  The inner
    tolerance sees the variable's ``dP0 / dv = sqrt(P0^2 + c^2)`` where the
    logarithm's is ``P0``.

    Returns the last inner solution, the iterations summed, the history of
    ``(P0, mean gap)`` and whether the iteration limit ended it.
    """
    h0, ps = problem.gap_scale, problem.pressure_scale
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    iterations = 0
    history = []
    # Starting guess: the previous multiplier, or a typical rough-contact pressure.
    adhesive = problem.interaction.adhesive
    pressure = initial.mean_pressure if initial is not None and \
        (initial.mean_pressure > 0 or adhesive) else 0.01 * ps
    scale = 0.01 * ps
    to_variable = (lambda p: math.asinh(p / scale)) if adhesive else (lambda p: math.log(p / ps))
    from_variable = (lambda v: scale * math.sinh(v)) if adhesive else (lambda v: ps * math.exp(v))
    reach = 1.0 if adhesive else 5.0
    # The secant works on log(P0 / (h0' E*)), not log(P0): the same numbers, to the
    # last bit, in unit systems that differ by powers of two.  Its slope
    # d g_bar / d log P0 ~ -gamma h0 with gamma ~ 0.5 for rough contact, until measured.
    slope = -0.5 * h0
    inner = tolerance  # P0 is a guess: resolving its state any further is wasted
    points = []
    solution = initial
    for outer in range(max_outer):
        budget = max_iterations - iterations  # the limit is per step, not per inner solve
        if budget < 1:
            return solution, iterations, history, True
        solution = tao_solve(problem, Load(pressure), kind,
                             settings.but(tolerance=inner, max_iterations=budget), solution,
                             monitor)
        iterations += solution.iterations
        error = (solution.mean_gap - target) / h0
        history.append((pressure, solution.mean_gap))
        # Judged on the state, not on the inner solve's own target: an inner solve
        # that stopped short of a tighter inner tolerance (a line search lost in the
        # round-off of the energy) may still leave a state that meets the test, and
        # its mean gap is still the best the secant can have.
        if not _meets_kkt(solution, tolerance) or abs(error) <= tolerance:
            break
        if len(history) >= 3 and history[-1][1] == history[-2][1] == history[-3][1]:
            break  # the inner solves no longer move the mean gap: reported as not converged
        points.append((to_variable(pressure), solution.mean_gap))
        if len(points) > 1:
            (l1, g1), (l2, g2) = points[-2], points[-1]
            measured = (g2 - g1) / (l2 - l1) if l2 != l1 else slope
            slope = measured if measured < 0 else -0.5 * h0
        step = min(max((target - points[-1][1]) / slope, -reach), reach)
        pressure = from_variable(points[-1][0] + step)
        load = pressure / ps if not adhesive else math.hypot(pressure, scale) / ps
        inner = _inner_tolerance(tolerance, error, load, slope / h0)
    return solution, iterations, history, False


def _meets_kkt(solution, tolerance):
    """Whether a state's own unit-free KKT residuals are within ``tolerance``."""
    return solution.kkt_pressure <= tolerance and solution.kkt_gap <= tolerance


def _inner_tolerance(tolerance, error, load, slope, forcing=0.5):
    """KKT tolerance of the next inner solve of the multiplier loop (unit-free).

    Why: a pressure residual ``r h0' E*`` left by an inner solve acts on the
    surfaces apart like an error of that size in ``P0``, which moves the mean
    gap by ``|d g_bar / d log P0| r h0' E* / P0``.  That must stay below a
    fraction ``forcing`` of the mean-gap error the next step is to remove
    (an inexact secant, as inexact Newton methods choose their forcing terms),
    and, near the end, below that fraction of the test ``|g_bar - target| <=
    tolerance h0``; and never above ``tolerance``, which the returned state must
    meet.  Compliant (lightly loaded) contact therefore asks for tighter inner
    solves than stiff contact.  The bound is pessimistic -- a residual bounded
    in the max norm seldom has that size everywhere at once -- which leaves
    margin for the secant.

    Parameters
    ----------
    tolerance : float
        The unit-free tolerance of the whole solve.
    error : float
        Mean-gap error of the last inner solve over ``h0``.
    load : float
        ``P0 / (h0' E*)`` of the next inner solve.
    slope : float
        ``d g_bar / d log P0`` over ``h0`` (negative).
    """
    wanted = forcing * max(abs(error), tolerance) * load / abs(slope)
    return min(tolerance, wanted)
