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
from petgap.solvers.progress import outer_step
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings


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
    ``|m - g_bar| <= tolerance h0``; a solve that fails, or ``max_solves``
    steps, ends it with ``converged=False`` and that reason.

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
        state.approach = reach - g_bar
        return state
    start_ops = problem.operator_applications
    depth, previous = reach - g_bar, None
    iterations, history, pressure, solves = 0, [], initial_pressure, 0
    converged, reason = False, "max_solves"
    while solves < max_solves:
        solution = polonsky_keer(problem, Indentation(depth), settings.but(
            max_iterations=max(max_iterations - iterations, 1), coarse_start=pressure is None),
            initial_pressure=pressure, monitor=monitor)
        solves += 1
        iterations += solution.iterations
        history.extend(solution.history)
        excess = solution.mean_gap - g_bar
        outer_step("the mean gap by the indentation", solves, max_solves, timer,
                   f"mean gap off by {abs(excess) / problem.gap_scale:.3e} h0 (target "
                   f"{tolerance:.0e}) after {solution.iterations} iterations")
        if not solution.converged:
            reason = solution.reason
            break
        if abs(excess) <= tolerance * problem.gap_scale:
            converged, reason = True, "converged_kkt"
            break
        slope = -1.0
        if previous is not None and depth != previous[0]:
            slope = min((solution.mean_gap - previous[1]) / (depth - previous[0]), -1e-12)
        previous = (depth, solution.mean_gap)
        depth += excess / -slope
        pressure = solution.pressure
    solution.start = "; ".join(filter(None, [f"{solves} indentation solves to the mean gap, "
                                             f"last depth {solution.control.depth:.6g}",
                                             solution.start]))
    solution.control = control
    solution.converged, solution.reason = converged, reason
    solution.iterations, solution.history = iterations, history
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution
