"""Mean-gap control on a free boundary, through the indentation depth.

On a periodic cell a mean gap fixes the offset of ``g = u - h + d`` directly
(``u`` has zero mean).  On a free boundary the displacement has a mean of its
own, so the mean gap is reached as the depth of an
:class:`~petgap.mechanics.problem.Indentation` solve
(:func:`solve_mean_gap_by_indentation`).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import Indentation
from petgap.solvers import coarse
from petgap.solvers.contact_limits import touching_state
from petgap.solvers.convergence import Timer, secant_tolerance
from petgap.solvers.progress import outer_step
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings

#: Each solve before the last is converged to this share of the last mean-gap error
#: (over ``h0``), or to the solve's tolerance where that is looser
#: (:func:`petgap.solvers.convergence.secant_tolerance`): a depth that secant steps will
#: move needs its mean gap only to the accuracy the next step can use.
TOLERANCE_SHARE = 0.01


def solve_mean_gap_by_indentation(problem, control, settings=SolverSettings(), *,
                                  initial_pressure=None, monitor=None, max_solves=50):
    """Mean-gap control on a free boundary: the indentation whose solution has the mean gap.

    On a free boundary the displacement has a mean of its own, so a mean gap
    fixes no offset (as it does on a periodic cell); it is found instead as the
    depth ``d`` of an :class:`~petgap.mechanics.problem.Indentation` solve.  The
    mean gap ``m(d) = mean(u) - mean(h) + max(h) - d`` falls with ``d`` at a slope
    between -1 (rigid) and 0, and is convex where the load grows faster than
    the depth (Hertz: ``d^{3/2}``).  Secant steps through the last two solves
    find ``d``, each solve warm-started from the last solve's pressure moved along
    the secant of the last two (``p + dp/dd step``; before the fine grid has two
    solves, scaled by the coarse grid's ``d log P0 / dd``): a re-solve at a depth
    that moved starts near its answer, not from the contact set of another load,
    and costs a few iterations.  They start where the
    same mean gap on the coarse start's grid (:mod:`petgap.solvers.coarse`, the
    topography block-averaged) put the depth, at the slope its last steps found,
    from its pressure prolonged: the depth is found level by level as the
    pressure of a load solve is, and the fine grid takes a few steps from near
    the answer.  Without a coarse grid (or a cold start asked off) the first
    depth is the rigid estimate ``u = 0`` with slope -1, which lies below the
    answer since ``u >= 0`` under compression.  The fine grid's first step takes the
    slope ``mean(u) d log P0 / dd - 1`` from its own ``mean(u)`` and the coarse grid's
    load response, which the discretisation moves less than the coarse mean gap's
    slope.  The solves before the last are
    inexact, to :data:`TOLERANCE_SHARE` of the last mean-gap error (the first to
    the coarse tolerance).  Stops when ``|m - g_bar| <= tolerance h0`` after a
    solve to the tolerance; a solve that fails, or ``max_solves`` steps, ends it
    with ``converged=False`` and that reason.

    Returns the last solve's solution with ``control`` set to the mean gap,
    iterations, operator applications and history summed over the solves, and its
    ``depth`` and the secant's last ``depth_slope``.
    """
    tolerance = settings.tolerance
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
    depth, slope, pressure, load_slope, description = \
        reach - g_bar, -1.0, initial_pressure, None, ""
    if initial_pressure is None and settings.coarse_start:
        depth, slope, pressure, load_slope, description = _coarse_depth(
            problem, control, settings, depth)
    inner = secant_tolerance(tolerance, None, TOLERANCE_SHARE, settings.coarse_tolerance)
    loop = _Secant(problem, settings, monitor, g_bar, max_solves)
    loop.load_slope = load_slope
    solution = loop.run(depth, slope, pressure, inner)
    solution.start = "; ".join(filter(None, [
        f"{loop.solves} indentation solves to the mean gap, last depth {loop.depth:.6g}",
        description, solution.start]))
    solution.depth, solution.depth_slope = loop.depth, loop.slope
    solution.load_slope = loop.load_slope
    solution.control = control
    solution.converged, solution.reason = loop.converged, loop.reason
    solution.iterations, solution.history = loop.iterations, loop.history
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution


class _Secant:
    """The secant steps on the depth, each an indentation solve warm from the last."""

    def __init__(self, problem, settings, monitor, g_bar, max_solves):
        self.problem, self.settings, self.monitor = problem, settings, monitor
        self.g_bar, self.max_solves = g_bar, max_solves
        self.iterations, self.history, self.solves = 0, [], 0
        self.converged, self.reason = False, "max_solves"
        self.depth, self.slope = None, -1.0
        #: ``dp / dd`` through the last two solves (a field), and ``d log P0 / dd`` (the
        #: mean pressure's, given by the coarse grid before the fine grid has two solves)
        self.pressure_slope, self.load_slope = None, None
        self.timer = Timer()

    def run(self, depth, slope, pressure, inner):
        """Solve from ``depth`` with the first step's ``slope``; the last solution."""
        problem, settings, tolerance = self.problem, self.settings, self.settings.tolerance
        previous = None
        while self.solves < self.max_solves:
            solution = polonsky_keer(problem, Indentation(depth), settings.but(
                tolerance=inner, coarse_start=pressure is None,
                max_iterations=max(settings.max_iterations - self.iterations, 1)),
                initial_pressure=pressure, monitor=self.monitor)
            self.solves += 1
            self.iterations += solution.iterations
            self.history.extend(solution.history)
            self.depth, pressure = depth, solution.pressure
            excess = solution.mean_gap - self.g_bar
            outer_step("the mean gap by the indentation", self.solves, self.max_solves,
                       self.timer, f"mean gap off by {abs(excess) / problem.gap_scale:.3e} h0 "
                       f"(target {tolerance:.0e}) after {solution.iterations} iterations "
                       f"to {inner:.0e}")
            if not solution.converged:
                self.reason = solution.reason
                break
            if abs(excess) <= tolerance * problem.gap_scale:
                if inner <= tolerance:
                    self.converged, self.reason = True, "converged_kkt"
                    break
                inner = tolerance   # the depth is found: its solve to the tolerance
                continue
            inner = secant_tolerance(tolerance, excess / problem.gap_scale, TOLERANCE_SHARE,
                                     settings.coarse_tolerance)
            if previous is not None and depth != previous[0]:
                slope = min((solution.mean_gap - previous[1]) / (depth - previous[0]), -1e-12)
                self.pressure_slope = (pressure - previous[2]) / (depth - previous[0])
                if previous[3] > 0:   # a depth short of contact carries no load to scale
                    self.load_slope = (solution.mean_pressure / previous[3] - 1) \
                        / (depth - previous[0])
            elif self.load_slope is not None:
                # one fine solve: m = mean(u) - mean(h) + top - d with mean(u) proportional
                # to the load, whose response d log P0 / dd the coarse grid measured
                mean_u = solution.mean_gap + problem.mean_height - problem.top_height + depth
                slope = min(mean_u * self.load_slope - 1.0, -1e-12)
            self.slope = slope
            previous = (depth, solution.mean_gap, pressure, solution.mean_pressure)
            step = excess / -slope
            depth += step
            # the pressure's secant too: the next solve starts near its answer
            if self.pressure_slope is not None:
                pressure = pressure + self.pressure_slope * step
            elif self.load_slope is not None:
                pressure = pressure * max(1 + self.load_slope * step, 0.0)
        return solution


def _coarse_depth(problem, control, settings, depth):
    """``(depth, slope, pressure, load_slope, description)`` from the same mean gap on the
    coarse grid.

    The coarse problem is solved by this module to the coarse tolerance (from its
    own coarse grid), and its pressure prolonged to the fine grid's scratch.  Where
    there is no coarse grid, or the coarse solve failed, the rigid estimate
    ``depth`` with slope -1 and no pressure.  ``load_slope``, the coarse secant's last
    ``d log P0 / dd``, scales the fine grid's first pressure into its second solve's
    start (None where the coarse grid took one solve).  Collective.
    """
    coarse_problem = coarse.coarse_problem(problem)
    if coarse_problem is None:
        return depth, -1.0, None, None, ""
    solution = solve_mean_gap_by_indentation(coarse_problem, control, settings.but(
        tolerance=max(settings.tolerance, settings.coarse_tolerance), coarse_start=True,
        search_precision="double", preconditioned=True))
    cgrid = coarse_problem.grid
    description = (f"coarse {cgrid.nx}x{cgrid.ny}: {solution.iterations} iterations, "
                   f"{solution.reason}")
    finite = problem.grid.comm.allreduce(bool(np.isfinite(solution.pressure).all()),
                                         op=MPI.LAND)
    if not (solution.converged and finite):
        return depth, -1.0, None, None, description + " (not used)"
    factor = problem.grid.nx // cgrid.nx
    pressure = coarse.prolong(cgrid.x_slice.start, problem.grid, solution.pressure, factor,
                              coarse.is_whole(problem.grid, cgrid))
    return solution.depth, solution.depth_slope, pressure, solution.load_slope, description
