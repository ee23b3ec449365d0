"""Mean-gap control on a free boundary, through the indentation depth.

On a periodic cell a mean gap fixes the offset of ``g = u - h + d`` directly
(``u`` has zero mean).  On a free boundary the displacement has a mean of its
own, so the mean gap is reached as the depth of an
:class:`~petgap.mechanics.problem.Indentation` solve
(:func:`solve_mean_gap_by_indentation`).
"""
from petgap.mechanics.problem import Indentation
from petgap.solvers.contact_limits import touching_state
from petgap.solvers.convergence import Timer
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings

#: The first indentation solve's tolerance (the rigid estimate of its depth is far off),
#: unless the solve's own is looser.
FIRST_TOLERANCE = 1e-3
#: A solve to a tolerance of at least this starts from the coarse grid rather than from
#: the last solve's pressure: at a depth still far from the last, the warm start must
#: first move the whole contact set, which the coarse start does for less.
COLD_ABOVE = 1e-4
#: Each later solve is converged to this share of the last solve's mean-gap error (over
#: ``h0``), or to the solve's tolerance where that is looser: a depth that secant steps
#: will move needs its mean gap only to the accuracy the next step can use.
TOLERANCE_SHARE = 0.01


def solve_mean_gap_by_indentation(problem, control, settings=SolverSettings(), *,
                                  initial_pressure=None, monitor=None, max_solves=50):
    """Mean-gap control on a free boundary: the indentation whose solution has the mean gap.

    On a free boundary the displacement has a mean of its own, so a mean gap
    fixes no offset (as it does on a periodic cell); it is found instead as the
    depth ``d`` of an :class:`~petgap.mechanics.problem.Indentation` solve.  The
    mean gap ``m(d) = mean(u) - mean(h) + max(h) - d`` falls with ``d`` at a slope
    between -1 (rigid) and 0, and is convex where the load grows faster than
    the depth (Hertz: ``d^{3/2}``): from the rigid estimate ``u = 0``, which lies
    below the answer since ``u >= 0`` under compression, secant steps through
    the last two solves (the first with slope -1) stay below it and converge
    from one side, each solve warm-started from the last.  Stops when
    ``|m - g_bar| <= tolerance h0`` after a solve to the tolerance; a solve that
    fails, or ``max_solves`` steps, ends it with ``converged=False`` and that
    reason.  The solves before the last are inexact: the first to
    :data:`FIRST_TOLERANCE`, each later one to :data:`TOLERANCE_SHARE` of the last
    mean-gap error, so that most iterations go to the depth's last digits once.

    Returns the last solve's solution with ``control`` set to the mean gap and
    iterations, operator applications and history summed over the solves.
    """
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    g_bar = float(control.mean_gap)
    timer = Timer()
    reach = problem.top_height - problem.mean_height   # mean gap at first touch
    if g_bar >= reach:   # apart: the rigid surface lifted off the touching state
        state = touching_state(problem, control, timer)
        state.gap += g_bar - reach
        state.mean_gap = g_bar
        return state
    start_ops = problem.operator_applications
    depth, previous = reach - g_bar, None
    iterations, history, pressure, solves = 0, [], initial_pressure, 0
    converged, reason = False, "max_solves"
    inner = max(tolerance, FIRST_TOLERANCE)
    while solves < max_solves:
        solution = polonsky_keer(problem, Indentation(depth), settings.but(
            tolerance=inner, max_iterations=max(max_iterations - iterations, 1),
            coarse_start=pressure is None or inner >= COLD_ABOVE),
            initial_pressure=None if inner >= COLD_ABOVE else pressure, monitor=monitor)
        solves += 1
        iterations += solution.iterations
        history.extend(solution.history)
        excess = solution.mean_gap - g_bar
        pressure = solution.pressure
        if not solution.converged:
            reason = solution.reason
            break
        if abs(excess) <= tolerance * problem.gap_scale:
            if inner <= tolerance:
                converged, reason = True, "converged_kkt"
                break
            inner = tolerance   # the depth is found: its solve to the tolerance
            continue
        inner = max(tolerance, TOLERANCE_SHARE * abs(excess) / problem.gap_scale)
        slope = -1.0
        if previous is not None and depth != previous[0]:
            slope = min((solution.mean_gap - previous[1]) / (depth - previous[0]), -1e-12)
        previous = (depth, solution.mean_gap)
        depth += excess / -slope
    solution.start = "; ".join(filter(None, [f"{solves} indentation solves to the mean gap, "
                                             f"last depth {solution.control.depth:.6g}",
                                             solution.start]))
    solution.control = control
    solution.converged, solution.reason = converged, reason
    solution.iterations, solution.history = iterations, history
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution
