"""Mean-gap control on a free boundary, through the indentation depth.

On a periodic cell a mean gap fixes the offset of ``g = u - h + d`` directly
(``u`` has zero mean).  On a free boundary the displacement has a mean of its
own, which follows the pressure, so the mean gap is reached as the depth of an
:class:`~petgap.mechanics.problem.Indentation` solve whose depth moves during
the solve (:func:`solve_mean_gap_by_indentation`, :class:`DepthForMeanGap`).
"""
from dataclasses import dataclass, field
from typing import Optional

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
#: A read of an iterate's mean gap lies within about this many times the iterate's KKT
#: residual (both over ``h0``) of the converged mean gap at its depth (0.004-0.1 on the
#: benchmarks' rough maps, the most in the first iterations of a start), so a secant
#: between two reads is trusted to this times their residuals over the change of ``m``.
READ_ERROR = 0.1
#: The coarse levels of a cold mean-gap solve are solved to this tolerance (or the
#: solve's, if looser): their rigid surfaces' places are extrapolated to the fine grid
#: (:data:`OFFSET_RATIO`), which needs them to about ``1e-5 h0``, where the coarse
#: start's usual ``1e-3`` leaves the fine solve that much mean-gap error to move off.
LEVEL_TOLERANCE = 1e-5
#: The offset ``max(h) - d`` at a mean gap converges with the grid: each level's step
#: from the one below is some times smaller than the step below it, 2.7-2.8 between
#: the two finest levels of the benchmarks' maps at 1024^2-4096^2, 3.4-4.5 further down
#: and on 256^2 maps.  The fine grid's offset is the coarse one plus the last step over
#: this ratio: where the true ratio is anywhere from 1.5 to 4.5, that leaves at most
#: half the coarse offset's error (a tenth at 2.7).
OFFSET_RATIO = 3.0
#: The slope of the mean gap against the offset is measured (:func:`measured_slope`)
#: on the coarse level with a side at most this fraction of the fine grid's (or on the
#: coarsest level, if the levels stop above it): it hardly depends on the grid, within
#: 0.2-2 % of the fine grid's at an eighth of its side on the benchmarks' maps at
#: 1024^2-8192^2 (2-3 % on 256^2 maps), for two solves of a 64th of the fine grid's points.
SLOPE_LEVEL = 8
#: The relative error allowed for that slope on the finer levels: a secant must be
#: surer than this to replace it.
SLOPE_SPREAD = 0.03
#: The depth step of the measurement, over ``h0``: the size of a first move, so that
#: the contact's growth over a move is in the slope.
SLOPE_STEP = 1e-4
#: The tolerance of the measurement's two solves: their mean gaps are then read to
#: about 1e-8 ``h0``, 2e-4 of their difference.
SLOPE_TOLERANCE = 1e-7


class DepthForMeanGap:
    """The depth whose indentation has the mean gap ``target``, moved during one pressure solve.

    The mean gap of an iterate, ``m = mean(u) - mean(h) + offset`` with
    ``g = u - h + offset`` and ``offset = max(h) - depth``, is a smooth functional of
    the pressure that settles long before the KKT residual does, so the depth is
    moved inside the one solve (:func:`~petgap.solvers.pressure_cg.polonsky_keer`'s
    ``retarget``), not by solves in an outer loop:

    * When: once the residual is below :data:`FORCING` times the mean-gap error over
      ``h0``; a solve converges only with the error within the tolerance.
    * How far: a step of ``m`` against the offset with the slope ``slope`` (between
      0, rigid-plastic, and 1, rigid), known to ``slope_error``: the coarse levels'
      measurement (:func:`measured_slope`), or the rigid 1 without one.  The secant
      between two moves replaces it where it is surer, its error taken as
      :data:`READ_ERROR` times the two reads' residuals over the change of ``m``: a
      secant through the unsettled reads of a start's first iterations is not.
    * How: the pressure moves with the depth along the shape of a flat punch on the
      contact set, which keeps the gap there near zero
      (:meth:`~petgap.solvers.pressure_cg.PressureCG.move_depth`).  Each move
      restarts the conjugate gradients and costs an iteration (two transform pairs,
      three at the first).

    ``log``: a line per move (:func:`~petgap.solvers.progress.outer_step`).  Collective.
    """

    def __init__(self, problem, target, tolerance, slope=1.0, slope_error=1.0, bound=None,
                 log=True):
        self.target, self.tolerance = target, tolerance
        self.slope, self.slope_error = slope, slope_error
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
            change = abs(mean - self.last[1]) / self.gap_scale
            sure = READ_ERROR * (self.last[2] + residual) / max(change, 1e-300)
            if measured > 1e-3 and sure < self.slope_error:
                self.slope, self.slope_error = min(measured, 1.0), sure
        self.last = (cg.offset, mean, residual)
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
    between -1 (rigid) and 0.

    A cold solve starts from the coarse start's grids (:mod:`petgap.solvers.coarse`,
    the topography block-averaged), each solving the same mean gap by this function
    to :data:`LEVEL_TOLERANCE`: the depth is where the last levels put the rigid
    surface, extrapolated to the fine grid (:data:`OFFSET_RATIO`,
    :func:`~petgap.solvers.coarse.extrapolated`), the slope is the one measured on the
    level :data:`SLOPE_LEVEL` times coarser (:func:`measured_slope`), and the pressure
    the first coarse level's, prolonged.
    Without a coarse grid (or a cold start asked off) it starts from the rigid
    estimate ``u = 0`` (a depth below the answer, since ``u >= 0`` under
    compression) with the rigid slope.  Converged when the KKT residual and
    ``|m - g_bar| / h0`` are within the tolerance.

    Returns the solution with ``control`` set to the mean gap, its ``depth`` and
    ``depth_slope`` (the slope of ``m`` against ``-d`` the moves used last) and the
    number of ``depth_moves``.
    """
    return _solve(problem, control, settings, initial_pressure, monitor,
                  problem.grid.nx // SLOPE_LEVEL, top=True)


def _solve(problem, control, settings, initial_pressure, monitor, slope_side, top=False):
    """:func:`solve_mean_gap_by_indentation` on one level.

    The slope is measured on this level if it is not the ``top`` (the grid asked
    for) and its side is ``slope_side``, or larger with no coarser level below it.
    The solution also carries ``coarse_offsets``, the offsets the levels below it
    found (finest first), for the extrapolation one level up.
    """
    g_bar = float(control.mean_gap)
    timer = Timer()
    reach = problem.top_height - problem.mean_height   # mean gap at first touch
    if g_bar >= reach:   # apart: the rigid surface lifted off the touching state
        state = touching_state(problem, control, timer)
        state.gap += g_bar - reach
        state.mean_gap = g_bar
        state.approach = state.depth = reach - g_bar
        state.depth_slope, state.slope_error, state.depth_moves = 1.0, 1.0, 0
        state.coarse_offsets = []
        return state
    start_ops = problem.operator_applications
    start = _Start(reach - g_bar)
    if initial_pressure is None and settings.coarse_start:
        start = _coarse_depth(problem, control, settings, start.depth, slope_side)
    else:
        start.pressure = initial_pressure
    rule = DepthForMeanGap(problem, g_bar, settings.tolerance, start.slope, start.slope_error,
                           bound=settings.max_iterations)
    solution = polonsky_keer(problem, Indentation(start.depth), settings.but(
        coarse_start=settings.coarse_start and start.pressure is None),
        initial_pressure=start.pressure, monitor=monitor, retarget=rule)
    solution.start = "; ".join(filter(None, [
        f"the depth moved {rule.moves} times to the mean gap", start.description,
        solution.start]))
    solution.depth, solution.depth_moves = solution.approach, rule.moves
    solution.depth_slope, solution.slope_error = rule.slope, rule.slope_error
    solution.coarse_offsets = start.coarse_offsets
    at_side = problem.grid.nx == slope_side or (start.lowest and problem.grid.nx > slope_side)
    if not top and at_side and solution.converged:
        measured = measured_slope(problem, solution.depth, solution.pressure, settings)
        if measured is not None:
            solution.depth_slope, solution.slope_error = measured, SLOPE_SPREAD
            solution.start += f"; slope {measured:.4g} measured here"
    solution.control = control
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution


def measured_slope(problem, depth, pressure, settings):
    """The slope of the mean gap against the offset near ``depth``, by two indentation solves.

    The mean gaps at ``depth`` and ``depth - SLOPE_STEP h0``, each solved to
    :data:`SLOPE_TOLERANCE` from the pressure before it (the first from
    ``pressure``), over the step; None if either did not converge or the slope is
    not in ``(0, 1]``.  Why two solves: the secant through the moves of a solve
    reads unsettled iterates, and is 5-15 % off at a start's first move; this one
    reads converged states.  Collective.
    """
    step = SLOPE_STEP * problem.gap_scale
    tight = settings.but(tolerance=min(settings.tolerance, SLOPE_TOLERANCE))
    deep = polonsky_keer(problem, Indentation(depth), tight, initial_pressure=pressure)
    if not deep.converged:
        return None
    shallow = polonsky_keer(problem, Indentation(depth - step), tight,
                            initial_pressure=deep.pressure)
    slope = (shallow.mean_gap - deep.mean_gap) / step
    return slope if shallow.converged and 0 < slope <= 1 else None


@dataclass
class _Start:
    """Where a level's solve starts: depth, slope and its error, pressure, and what
    they came from (``lowest``: no coarser level; ``coarse_offsets``: the offsets the
    levels below found, finest first, for the extrapolation one level up)."""

    depth: float
    slope: float = 1.0
    slope_error: float = 1.0
    pressure: Optional[np.ndarray] = None
    description: str = ""
    lowest: bool = True
    coarse_offsets: list = field(default_factory=list)


def _coarse_depth(problem, control, settings, depth, slope_side=0):
    """The :class:`_Start` from the same mean gap on the coarse grid.

    The coarse problem is solved by this module to :data:`LEVEL_TOLERANCE` (from its
    own coarse grid, the slope measured on the level ``slope_side`` says), and its
    pressure prolonged (:func:`petgap.solvers.coarse.prolong_pressure`).
    What carries over is the rigid surface's place against the mean height,
    ``offset = max(h) - depth``, which the block means keep, not its depth below the
    highest point, which they lower;
    where the coarse level had a coarse level of its own, the offset is
    extrapolated from the levels below (:func:`~petgap.solvers.coarse.extrapolated`).
    Where there is no coarse grid, or the coarse solve failed or found the surfaces
    apart, the rigid estimate ``depth`` with slope 1 and no pressure.  Collective.
    """
    coarse_problem = coarse.coarse_problem(problem)
    if coarse_problem is None:
        return _Start(depth)
    tolerance = max(settings.tolerance, min(settings.coarse_tolerance, LEVEL_TOLERANCE))
    solution = _solve(coarse_problem, control, settings.but(
        tolerance=tolerance, coarse_start=True, search_precision="double",
        preconditioned=True), None, None, slope_side)
    cgrid = coarse_problem.grid
    description = (f"coarse {cgrid.nx}x{cgrid.ny}: {solution.iterations} iterations, "
                   f"{solution.reason}")
    finite = problem.grid.comm.allreduce(bool(np.isfinite(solution.pressure).all()),
                                         op=MPI.LAND)
    if not (solution.converged and finite) or solution.reason == "zero_load":
        return _Start(depth, description=description + " (not used)", lowest=False)
    factor = problem.grid.nx // cgrid.nx
    pressure = coarse.prolong_pressure(problem, cgrid.x_slice.start, solution.pressure,
                                       factor, coarse.is_whole(problem.grid, cgrid))
    offsets = [coarse_problem.top_height - solution.depth] + solution.coarse_offsets
    offset = coarse.extrapolated(offsets, OFFSET_RATIO)
    if offset != offsets[0]:
        description += ", its offset extrapolated"
    return _Start(problem.top_height - offset, solution.depth_slope, solution.slope_error,
                  pressure, description, lowest=False, coarse_offsets=offsets)
