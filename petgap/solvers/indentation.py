"""Mean-gap control on a free boundary, through the indentation depth.

On a periodic cell a mean gap fixes the offset of ``g = u - h + d`` directly
(``u`` has zero mean).  On a free boundary the displacement has a mean of its
own, which follows the pressure, so the mean gap is reached as the depth of an
:class:`~petgap.mechanics.problem.Indentation` solve whose depth moves during
the solve (:func:`solve_mean_gap_by_indentation`, :class:`DepthForMeanGap`).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import Indentation
from petgap.solvers import coarse
from petgap.solvers.contact_limits import touching_state
from petgap.solvers.convergence import Timer
from petgap.solvers.progress import outer_step
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings

#: The depth moves once the KKT residual is below this many times the mean-gap error
#: over ``h0`` (the forcing term of an inexact Newton method): the iterate's mean gap is
#: then read to about its error, and a secant step through two such reads removes most
#: of it (a move restarts the iteration, so fewer, surer moves are what is wanted).
FORCING = 1.0


class DepthForMeanGap:
    """The depth whose indentation has the mean gap ``target``, moved during one pressure solve.

    The mean gap of an iterate, ``m = mean(u) - mean(h) + offset`` with
    ``g = u - h + offset`` and ``offset = max(h) - depth``, is a smooth functional of
    the pressure that settles long before the KKT residual does, so the depth is
    moved inside the one solve (:func:`~petgap.solvers.pressure_cg.polonsky_keer`'s
    ``retarget``), not by solves in an outer loop:

    * When: once the residual is below :data:`FORCING` times the mean-gap error over
      ``h0``; a solve converges only with the error within the tolerance.
    * How far: a secant step of ``m`` against the offset, its slope (between 0,
      rigid-plastic, and 1, rigid) measured between moves, before the second
      ``slope`` (the coarse grid's, where there is one).
    * How: the pressure moves with the depth along the shape of a flat punch on the
      contact set, which keeps the gap there near zero
      (:meth:`~petgap.solvers.pressure_cg.PressureCG.move_depth`).  Each move
      restarts the conjugate gradients and costs an iteration (two transform pairs,
      three at the first).

    ``log``: a line per move (:func:`~petgap.solvers.progress.outer_step`).  Collective.
    """

    def __init__(self, problem, target, tolerance, slope=1.0, bound=None, log=True):
        self.target, self.tolerance, self.slope = target, tolerance, slope
        self.gap_scale = problem.gap_scale
        self.top = problem.top_height
        self.last, self.moves, self.error = None, 0, None
        self.bound, self.timer = bound, (Timer() if log else None)

    def __call__(self, cg, residual):
        """The offset of ``g = u - h + offset`` to move to, or None to hold the depth.

        At a residual within the tolerance the error is the stored state's (the gap
        projected onto the contact state), so that the mean gap a converged solve
        reports is within the tolerance; before, the iterate's own."""
        mean = cg.mean_gap(projected=residual <= self.tolerance)
        self.error = (mean - self.target) / self.gap_scale
        error = abs(self.error)
        if error <= self.tolerance or residual > max(self.tolerance, FORCING * error):
            return None
        if self.last is not None and cg.offset != self.last[0]:
            measured = (mean - self.last[1]) / (cg.offset - self.last[0])
            self.slope = min(measured, 1.0) if measured > 1e-3 else self.slope
        self.last = (cg.offset, mean)
        offset = cg.offset + (self.target - mean) / self.slope
        if offset >= self.top:   # past first touch: halve the depth instead
            offset = 0.5 * (cg.offset + self.top)
        self.moves += 1
        if self.timer is not None:
            outer_step("the mean gap by the indentation depth", self.moves, self.bound,
                       self.timer, f"mean gap off by {error:.3e} h0 (target "
                       f"{self.tolerance:.0e}) at KKT residual {residual:.1e}: depth moved")
        return offset


def solve_mean_gap_by_indentation(problem, control, settings=SolverSettings(), *,
                                  initial_pressure=None, monitor=None):
    """Mean-gap control on a free boundary: the indentation whose solution has the mean gap.

    On a free boundary the displacement has a mean of its own, so a mean gap
    fixes no offset (as it does on a periodic cell); it is found instead as the
    depth ``d`` of one :class:`~petgap.mechanics.problem.Indentation` solve whose
    depth :class:`DepthForMeanGap` moves as the iterate's mean gap settles.  The mean
    gap ``m(d) = mean(u) - mean(h) + max(h) - d`` falls with ``d`` at a slope
    between -1 (rigid) and 0.  A cold solve starts where the same mean gap on the
    coarse start's grid (:mod:`petgap.solvers.coarse`, the topography
    block-averaged; solved by this function, level by level) put the depth, with
    the slope its moves measured and its pressure prolonged; without a coarse grid
    (or a cold start asked off), from the rigid estimate ``u = 0`` (a depth below
    the answer, since ``u >= 0`` under compression) with the rigid slope.  Converged when
    the KKT residual and ``|m - g_bar| / h0`` are within the tolerance.

    Returns the solution with ``control`` set to the mean gap, its ``depth`` and
    ``depth_slope`` (the rule's last slope of ``m`` against ``-d``) and the number of
    ``depth_moves``.
    """
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
    depth, slope, pressure, description = reach - g_bar, 1.0, initial_pressure, ""
    if initial_pressure is None and settings.coarse_start:
        depth, slope, pressure, description = _coarse_depth(problem, control, settings, depth)
    rule = DepthForMeanGap(problem, g_bar, settings.tolerance, slope,
                           bound=settings.max_iterations)
    solution = polonsky_keer(problem, Indentation(depth), settings.but(
        coarse_start=settings.coarse_start and pressure is None),
        initial_pressure=pressure, monitor=monitor, retarget=rule)
    solution.start = "; ".join(filter(None, [
        f"the depth moved {rule.moves} times to the mean gap", description, solution.start]))
    solution.depth, solution.depth_slope, solution.depth_moves = \
        solution.approach, rule.slope, rule.moves
    solution.control = control
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution


def _coarse_depth(problem, control, settings, depth):
    """``(depth, slope, pressure, description)`` from the same mean gap on the coarse grid.

    The coarse problem is solved by this module to the coarse tolerance (from its
    own coarse grid), and its pressure prolonged to the fine grid's scratch.  What
    carries over is the rigid surface's place against the mean height, which the
    block means keep, not its depth below the highest point, which they lower:
    the fine depth is the coarse one plus the difference of the two highest points
    (``offset = max(h) - depth`` is the same on both grids).  Where
    there is no coarse grid, or the coarse solve failed, the rigid estimate
    ``depth`` with slope 1 and no pressure.  Collective.
    """
    coarse_problem = coarse.coarse_problem(problem)
    if coarse_problem is None:
        return depth, 1.0, None, ""
    solution = solve_mean_gap_by_indentation(coarse_problem, control, settings.but(
        tolerance=max(settings.tolerance, settings.coarse_tolerance), coarse_start=True,
        search_precision="double", preconditioned=True))
    cgrid = coarse_problem.grid
    description = (f"coarse {cgrid.nx}x{cgrid.ny}: {solution.iterations} iterations, "
                   f"{solution.reason}")
    finite = problem.grid.comm.allreduce(bool(np.isfinite(solution.pressure).all()),
                                         op=MPI.LAND)
    if not (solution.converged and finite):
        return depth, 1.0, None, description + " (not used)"
    factor = problem.grid.nx // cgrid.nx
    pressure = coarse.prolong(cgrid.x_slice.start, problem.grid, solution.pressure, factor,
                              coarse.is_whole(problem.grid, cgrid))
    depth = solution.depth + problem.top_height - coarse_problem.top_height
    return depth, solution.depth_slope, pressure, description
