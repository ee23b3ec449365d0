"""Adhesion on a free boundary: the map's problem solved on its padded periodic cell.

The gap formulation of adhesion (:mod:`petgap.solvers.gap_cg`) applies the
half-space's stiffness, which a free map has in no fast form
(:mod:`petgap.mechanics.free_half_space`).  Its ``2 nx x 2 ny`` padded cell has one:
there the compliance ``C`` is a circulant with a positive symbol, so
``K = C^{-1}`` is diagonal in Fourier space
(:class:`~petgap.mechanics.free_half_space.PaddedCellHalfSpace`).  The map's problem is
the cell's problem with the surface out of reach outside the map:

* Outside the map the cell's topography is ``min(h) - far``, with ``far`` the map's
  height range plus :data:`REACH` times the interaction law's length scale (or the
  rms height, if larger): the gap there stays above that (the map's own gaps are
  smaller, and ``u`` is continuous), where the wall never acts and ``v'`` is nothing
  (``exp(-REACH)`` of its largest for the exponential, less for the laws with a
  cut-off or a Gaussian tail, ``REACH^-4`` for the Lennard-Jones tail).  So at the cell's
  solution the pressure outside the map is zero, and on the map the cell's
  compliance is the linear convolution of the free map (Hockney): the cell's solution
  restricted to the map is the free map's solution.
* The cell's ``q = 0`` mode is the control's, as on any periodic cell: a map load
  ``P0`` is the cell load ``P0 nx ny / (4 nx ny) = P0 / 4``.  A mean gap of the map is
  not a constraint of the cell's energy: its multiplier would act on the map's points
  alone, and the outside pressure would not vanish.  The cell keeps its own mean-gap
  constraint (its multiplier a uniform pressure over the whole cell), and the map's mean
  gap, which differs from the cell's by the gaps outside (about ``far`` each, a quarter
  of the points being inside) and follows the map's pressure, moves the cell's target
  during one gap solve (:class:`MapMeanGap`, :func:`map_mean_gap`); the coarse levels of
  its start do the same on their maps.  The TAO solvers on the gap take secant steps of
  whole cell solves instead (:meth:`PaddedCell._mean_gap`).
* The KKT scales are the map's (:class:`~petgap.mechanics.problem.Scales`): the cell's
  problem is made with them, so that its residuals mean what they mean for the map.

The solver (:class:`PaddedCell`) keeps the cell's problem of each map's problem while
that lives: a sweep makes it once.  It solves the cell with the solver type the
registry chose (:func:`petgap.solvers.control_loops.solve_as`), as it would a periodic problem.

Cost: the whole solve runs on four times the points (fields and passes, not only the
transforms as for the hard wall, which :mod:`petgap.solvers.pressure_cg` solves on the
map with the padded transform alone).
"""
import weakref

import numpy as np
from mpi4py import MPI

from petgap.mechanics.free_half_space import PaddedCellHalfSpace
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.collective import move_rows
from petgap.solvers import coarse
from petgap.solvers.convergence import Timer, secant_tolerance
from petgap.solvers.control_loops import solve_as
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers.gap_start import coarse_start_gap
from petgap.solvers.progress import outer_step

#: Interaction length scales between the cell's surface outside the map and the map's
#: lowest point: the gap outside stays above this many of them.
REACH = 200.0


def cell_problem(problem):
    """The free map ``problem`` on its padded cell, with the map's KKT scales.  Collective."""
    grid, cell = problem.grid, problem.half_space.cell
    comm = grid.comm
    h = problem.topography
    low = comm.allreduce(float(np.min(h, initial=np.inf)), op=MPI.MIN)
    reach = max(problem.interaction.length_scale, problem.gap_scale)
    far = problem.top_height - low + REACH * reach
    heights = np.full(cell.local_shape, low - far)
    _to_cell(grid, cell, h, heights)
    body = PaddedCellHalfSpace(cell, problem.half_space.contact_modulus)
    return ContactProblem(cell, heights, body, problem.interaction, scales=problem.scales)


def _to_cell(grid, cell, field, out):
    """Write this rank's map rows ``field`` into the cell's slab ``out`` (rows 0..nx-1, columns 0..ny-1)."""
    lo, hi = cell.x_slice.start, min(cell.x_slice.stop, grid.nx)
    for row, piece in move_rows(grid.comm, field, grid.x_slice.start, lo, max(hi, lo)):
        out[row - lo:row - lo + len(piece), :grid.ny] = piece


def _to_map(grid, cell, field):
    """This rank's map rows of the cell's slab ``field``."""
    lo, hi = cell.x_slice.start, min(cell.x_slice.stop, grid.nx)
    held = np.ascontiguousarray(field[:max(hi - lo, 0), :grid.ny])
    out = np.empty(grid.local_shape)
    start, stop = grid.x_slice.start, grid.x_slice.stop
    for row, piece in move_rows(grid.comm, held, lo, start, stop):
        out[row - start:row - start + len(piece)] = piece
    return out


def map_mean(cell, map_shape, field):
    """The mean over the map's points of a cell field (this rank's slab).  Collective.

    The map is the cell's first ``nx`` rows and ``ny`` columns: summed where they lie,
    no rows moved.
    """
    nx, ny = map_shape
    rows = max(min(cell.x_slice.stop, nx) - cell.x_slice.start, 0)
    local = float(field[:rows, :ny].sum(dtype=np.float64))
    return cell.comm.allreduce(local) / (nx * ny)


def first_cell_target(problem, on_cell, target):
    """The cell's mean gap to start from for the map's mean gap ``target``.  Collective.

    The outside points' gaps taken as if ``u`` were the same outside as inside: the
    cell's surface outside lies at its lowest height, the map's at its mean.
    """
    h_out = on_cell.grid.comm.allreduce(float(np.min(on_cell.topography, initial=np.inf)),
                                        op=MPI.MIN)
    fraction = problem.grid.npoints / on_cell.grid.npoints
    return target + (1 - fraction) * (problem.mean_height - h_out)


#: The mean-gap secant's inner solves (:func:`~petgap.solvers.convergence.secant_tolerance`):
#: each to a tenth of the mean-gap error left, the first to 1e-4.
SECANT_FORCING, SECANT_LOOSEST = 0.1, 1e-4
#: A read of an iterate's map mean gap lies within about this many times its KKT
#: residual (both over ``h0``) of the converged one at its cell target, so a secant
#: between two moves is trusted to this times their residuals over the change of the
#: map's mean gap (:class:`MapMeanGap`) ...
READ_ERROR = 0.1
#: ... or to this many times the change of the read over its last iteration at the same
#: target, where that is less: a read that has stopped moving is surer than its residual
#: says (within 1e-3 of its residual on the 4096^2 benchmark map); five times trusted
#: secants through the jumps of a map whose mean gap jumps with the target.
SETTLED = 10.0
#: The slope of the map's mean gap against the cell's is measured (:func:`measured_slope`)
#: on the coarse level whose map side is at most this fraction of the fine map's (or on
#: the coarsest level, if the levels stop above it): the slope hardly depends on the
#: grid (1.29-1.31 on the levels of the 1024^2 benchmark map, ``w = 0.15``), where the
#: secants through a coarse level's unsettled moves carried 1.04-1.18 up to the fine
#: solve.
SLOPE_LEVEL = 8
#: The relative error allowed for that slope on the finer levels: a secant must be
#: surer than this to replace it.
SLOPE_SPREAD = 0.03
#: The measurement's step of the cell's mean gap, over ``h0``: the size of a first move.
SLOPE_STEP = 1e-4
#: The tolerance of the measurement's two solves.
SLOPE_TOLERANCE = 1e-7
#: The cell target that puts a level's map at the mean gap converges with the grid at
#: second order: each level's step from the one below is about this many times smaller
#: than the step below it (4.2-5.1 between the levels of the benchmark maps at
#: 1024^2-2048^2, ``w = 0.05`` and ``0.15``), so a level starts from the target of the
#: one below plus its step over this ratio
#: (:func:`~petgap.solvers.coarse.extrapolated`).  Without it the fine solve started
#: 8e-5-1.3e-4 ``h0`` off, a move's worth.
TARGET_RATIO = 4.0
#: A move of the cell target by ``delta`` shifts the free points against the wall points,
#: which loads every contact edge: the residual rises to about this times ``delta / h0``
#: times ``h0 / (h0' a0)`` (the edge's stiffness ``E* / a0`` over the KKT unit ``h0' E*``;
#: 0.64 at 1024^2 and 0.73 at 4096^2 on the benchmark maps, ``w = 0.15``).  So a move is
#: made as soon as its read has settled once the residual is below that rise, where
#: waiting for it to fall further buys nothing the move does not undo (:class:`MapMeanGap`).
SHIFT_JUMP = 0.5
#: A read has settled when it changed by at most this fraction of the mean-gap error over
#: the iteration before ...
EARLY_DRIFT = 0.1
#: ... and is taken early only below this residual: above it the iterate is still the
#: coarse level's prolonged state, whose read may pause and move on (it did on a map
#: sticky at a pixel's range, whose mean gap jumps with the target).
EARLY_RESIDUAL = 1e-3


class MapMeanGap:
    """The cell's mean gap that gives the map's mean gap ``target``, moved during one gap solve.

    The map's mean gap is the cell's less the outside points' share, which follows
    the map's pressure (the outside displacement is the compliance applied to it):
    a function of the state, not a constraint of the cell's energy, whose
    multiplier must stay a uniform pressure over the whole cell (the outside
    pressure vanishes only then).  So the cell keeps its own mean-gap constraint,
    and :func:`~petgap.solvers.gap_cg.gap_cg` asks this rule on every iteration
    (its ``retarget``) whether to move it.

    * When: once the KKT residual is below ``forcing`` times the map's mean-gap
      error over ``h0`` (the forcing term of an inexact Newton method).  The map's
      mean gap of an iterate settles long before its residual does (a smooth
      functional of the gap), so the move reads a nearly converged mean gap; read
      earlier, on sticky maps, the secant's slopes go astray (docs/design.md).  Or
      earlier, once the read has settled (:data:`EARLY_DRIFT`) and the residual is
      below the rise the move itself will cause, ``jump`` times the error
      (:data:`SHIFT_JUMP`; 0: never), and below :data:`EARLY_RESIDUAL`.
    * How far: a secant step on the map's mean gap against the cell's.  Its slope is
      ``slope``, known to ``slope_error`` (the coarse levels' measurement,
      :func:`measured_slope`, or 1 without one), until a secant between two moves is
      surer: its error taken as the two reads' errors over the change of the map's mean
      gap, a read's error as :data:`READ_ERROR` times its residual or :data:`SETTLED`
      times its change over the iteration before, whichever is less.  So a secant
      through a start's unsettled iterates does not replace a measured slope, and one
      through settled reads does (the slope of a coarse level can be some per cent off
      the fine grid's: 1.31 against 1.23 at 4096^2, ``w = 0.15``).
    * How: from the second move on, the gap is first carried along the last move's
      response, scaled to the new step, its points at the wall kept there
      (:meth:`_predict`); gap_cg then projects it onto the new mean.  The first move is
      the projection's shift of the free points alone.

    ``log``: a line per move (:func:`~petgap.solvers.progress.outer_step`), against the
    solve's iteration limit ``bound`` (a move costs an iteration).  Collective.
    """

    def __init__(self, cell, map_shape, target, gap_scale, tolerance, cell_target,
                 slope=1.0, slope_error=1.0, forcing=3.0, jump=0.0, log=False, bound=None):
        self.cell, self.map_shape = cell, map_shape
        self.target, self.gap_scale, self.tolerance = target, gap_scale, tolerance
        self.cell_target, self.slope, self.forcing = cell_target, slope, forcing
        self.slope_error = slope_error
        self.last, self.moves, self.error, self.previous = None, 0, None, None
        self.before, self.last_step = None, None
        self.timer, self.bound = (Timer() if log else None), bound
        self.jump = jump
        self.levels = []   # with map_mean_gap's levels: their cell targets, finest first

    def map_mean(self, g):
        """The mean of the cell's gap ``g`` (this rank's slab) over the map's points."""
        return map_mean(self.cell, self.map_shape, g)

    def __call__(self, g, residual):
        """The cell's new mean-gap target, or None to hold it (gap_cg's ``retarget``)."""
        mean = self.map_mean(g)
        self.error = (mean - self.target) / self.gap_scale
        error = abs(self.error)
        drift = np.inf if self.previous is None else abs(mean - self.previous) / self.gap_scale
        self.previous = mean
        early = (drift <= EARLY_DRIFT * error
                 and residual <= min(EARLY_RESIDUAL, self.jump * error))
        if error <= self.tolerance or (residual > max(self.tolerance, self.forcing * error)
                                       and not early):
            return None
        read = min(READ_ERROR * residual, SETTLED * drift)
        if self.last is not None and self.cell_target != self.last[0]:
            measured = (mean - self.last[1]) / (self.cell_target - self.last[0])
            change = abs(mean - self.last[1]) / self.gap_scale
            sure = (self.last[2] + read) / max(change, 1e-300)
            if measured > 1e-3 and sure < self.slope_error:
                self.slope, self.slope_error = measured, sure
        self.last = (self.cell_target, mean, read)
        self.previous = None     # the next read is at another target
        step = (self.target - mean) / self.slope
        self._predict(g, step)
        self.cell_target += step
        self.moves += 1
        if self.timer is not None:
            outer_step("the map's mean gap on its padded cell", self.moves, self.bound,
                       self.timer, f"mean gap off by {error:.3e} h0 (target "
                       f"{self.tolerance:.0e}) at KKT residual {residual:.1e}: target moved")
        return self.cell_target

    def _predict(self, g, step):
        """Carry ``g`` along the last move's response, scaled to ``step`` (in place).

        Why: the projection's uniform shift of the free points loads every contact
        edge like a crack tip, and the residual rises by about :data:`SHIFT_JUMP` times
        the step over ``h0' a0``, tens of times the step over ``h0``; the state's
        own response to the last move, the difference of the gaps
        before the two moves, is a secant predictor of the whole state, and the
        residual barely rises.  Points at the wall stay there: a move that turns back
        (the usual second move, which takes back the first one's overshoot) would
        otherwise lift the edge points the last move closed, each loading its
        neighbour like a crack tip (adhesive edges do not retrace their path), and the
        residual rose a few hundred times the step over ``h0`` (``w = 0.15`` at
        1024^2); points leave the wall through the gap solver's free set instead.
        Keeps the gap before this move (one cell field).
        """
        if self.before is None:
            self.before, self.last_step = g.copy(), step
            return
        diff = self.before
        np.subtract(g, diff, out=diff)          # the last move's response (and progress)
        diff *= step / self.last_step
        np.copyto(diff, 0.0, where=g <= 0)
        g += diff
        np.subtract(g, diff, out=diff)          # the state before this move
        self.last_step = step


def measured_slope(on_cell, map_shape, cell_target, gap, settings):
    """``(slope, map mean gap)`` at ``cell_target`` by two tight gap solves, or None.

    The map's mean gap at ``cell_target`` and at ``cell_target + SLOPE_STEP h0``, each
    solved to :data:`SLOPE_TOLERANCE` from the state before it (the first from
    ``gap``), and the slope between them.  Why: the secants through a solve's moves
    read unsettled iterates, and on sticky maps a coarse level's moves are many and
    far apart (secants of 0.27-1.05 on the coarsest level of the 2048^2 benchmark map,
    ``w = 0.15``, where the measured slope is 1.27).  None if either solve did not
    converge or the slope is not positive.  Collective.
    """
    cell = on_cell.grid
    step = SLOPE_STEP * on_cell.gap_scale
    tight = settings.but(tolerance=min(settings.tolerance, SLOPE_TOLERANCE))
    at = gap_cg(on_cell, MeanGap(cell_target), tight, initial_gap=gap)
    if not at.converged:
        return None
    moved = gap_cg(on_cell, MeanGap(cell_target + step), tight, initial_gap=at.gap)
    if not moved.converged:
        return None
    mean = map_mean(cell, map_shape, at.gap)
    slope = (map_mean(cell, map_shape, moved.gap) - mean) / step
    return (slope, mean) if slope > 0 else None


def map_mean_gap(on_cell, map_shape, target, guess, settings, *, slope=1.0, slope_error=1.0,
                 slope_side=0, initial_gap=None, monitor=None, log=False, level=False):
    """The cell's gap solve whose map has mean gap ``target``: ``(solution, rule)``.

    One :func:`~petgap.solvers.gap_cg.gap_cg` solve with a moving cell target
    (:class:`MapMeanGap`).  A cold solve starts as gap_cg's coarse-grid start would
    (:func:`~petgap.solvers.gap_start.coarse_start_gap`), but each coarse level is this
    same solve on its own map (the map's blocks): it finds the cell target on a quarter
    of the points, and the fine solve starts from it.  The slope of the map's mean gap
    against the cell's is measured (:func:`measured_slope`) on the coarse ``level`` whose
    map side is ``slope_side``, or larger with no coarser level below it; the levels above
    it start from that slope, known to :data:`SLOPE_SPREAD`, and from the cell target
    that puts the levels' maps exactly at ``target``, extrapolated to this grid
    (:data:`TARGET_RATIO`).  Collective.
    """
    cell = on_cell.grid
    start = ""
    lowest, found = True, []
    if initial_gap is None:

        def solve_level(coarse_cell, control, coarse_settings):
            f = cell.nx // coarse_cell.grid.nx
            solution, rule = map_mean_gap(coarse_cell, (map_shape[0] // f, map_shape[1] // f),
                                          target, control.mean_gap, coarse_settings,
                                          slope=slope, slope_error=slope_error,
                                          slope_side=slope_side, level=True)
            found.append(rule)
            return solution
        initial_gap, start = coarse_start_gap(on_cell, MeanGap(guess), settings, solve_level)
        lowest = not found
        if found and initial_gap is not None:
            guess = coarse.extrapolated(found[0].levels, TARGET_RATIO)
            slope, slope_error = found[0].slope, found[0].slope_error
    jump = SHIFT_JUMP * on_cell.gap_scale / (on_cell.rms_slope * cell.dx)   # h0 / (h0' a0)
    rule = MapMeanGap(cell, map_shape, target, on_cell.gap_scale, settings.tolerance, guess,
                      slope, slope_error, jump=jump, log=log, bound=settings.max_iterations)
    solution = gap_cg(on_cell, MeanGap(guess), settings, initial_gap=initial_gap,
                      monitor=monitor, retarget=rule)
    rule.before = None  # the predictor's field: not kept with the solution
    if level:
        side, mean = map_shape[0], None
        if slope_side and side >= slope_side and (lowest or side < 2 * slope_side) \
                and rule.slope_error > SLOPE_SPREAD:
            measured = measured_slope(on_cell, map_shape, rule.cell_target, solution.gap,
                                      settings)
            if measured is not None:
                (rule.slope, mean), rule.slope_error = measured, SLOPE_SPREAD
        # the level stopped at the coarse tolerance, its map's mean gap up to that far off
        # the target: the level above starts from the cell target that removes the rest,
        # extrapolated with the levels below it
        if mean is None:
            mean = rule.map_mean(solution.gap)     # reduced: NaN on every rank or none
        if np.isfinite(mean):
            rule.cell_target += (target - mean) / rule.slope
        rule.levels = [rule.cell_target] + (found[0].levels if found else [])
    if start:
        solution.start = "; ".join(filter(None, [start, solution.start]))
    return solution, rule


class PaddedCell:
    """The free-boundary solver of the solvers on the gap: the map solved on its padded cell.

    Keeps the cell's problem of every map's problem it has solved while that problem
    lives (a sweep's steps share it); the key is the problem itself, so that a problem
    with another interaction (:meth:`~petgap.mechanics.problem.ContactProblem.with_interaction`)
    gets a cell of its own.
    """

    def __init__(self, max_solves=50):
        self.max_solves = max_solves
        self._cells = weakref.WeakKeyDictionary()

    def cell_problem(self, problem):
        """The padded cell's problem of ``problem`` (made on the first call).  Collective."""
        if problem not in self._cells:
            self._cells[problem] = cell_problem(problem)
        return self._cells[problem]

    def solve(self, problem, control, kind, settings, *, initial=None, monitor=None):
        """Solve the free map ``problem`` under ``control`` on its padded cell with ``kind``.

        ``kind`` is the registry's resolved solver type; ``settings`` the solve's.
        Returns the map's :class:`~petgap.mechanics.problem.ContactSolution`, with the
        cell's solution kept as ``solution.cell_solution`` for the next warm start.
        Collective.
        """
        timer = Timer()
        on_cell = self.cell_problem(problem)
        start_ops = problem.operator_applications + on_cell.operator_applications
        warm = getattr(initial, "cell_solution", None)
        if isinstance(control, Load):
            fraction = problem.grid.npoints / on_cell.grid.npoints
            solution = solve_as(on_cell, Load(control.mean_pressure * fraction), kind, settings,
                                warm, monitor)
            solves, history = 1, list(solution.history)
            iterations, converged, reason = solution.iterations, solution.converged, \
                solution.reason
            note = ""
        elif isinstance(control, MeanGap) and kind == "pcg-gap":
            solution, moves = self._moving_mean_gap(problem, on_cell, control, settings, warm,
                                                    monitor)
            solves, history = 1, list(solution.history)
            iterations, converged, reason = solution.iterations, solution.converged, \
                solution.reason
            note = f" (the map's mean gap moved its target {moves} times)"
        elif isinstance(control, MeanGap):
            solution, solves, iterations, history, converged, reason = self._mean_gap(
                problem, on_cell, control, kind, settings, warm, monitor)
            note = f" ({solves} mean-gap solves)" if solves > 1 else ""
        else:
            raise ValueError(f"control {control!r}: a free boundary with adhesion takes load "
                             f"or mean-gap control")
        mapped = self._on_map(problem, on_cell, control, solution, note, timer,
                              converged=converged, reason=reason, iterations=iterations,
                              history=history, start_ops=start_ops)
        mapped.negative_curvature_steps = solution.negative_curvature_steps
        mapped.cell_solution = solution
        return mapped

    @staticmethod
    def _moving_mean_gap(problem, on_cell, control, settings, warm, monitor):
        """One gap solve whose cell target follows the map's mean gap (:func:`map_mean_gap`).

        The first cell target takes the outside points' gaps as if ``u`` were the same
        outside as inside; a warm start's takes its own cell target, moved by the map's
        mean-gap error over its measured slope.  Returns the cell's solution (its
        ``map_rule`` the rule, for the next warm start) and the moves of the target.
        """
        grid = problem.grid
        target = control.mean_gap
        rule = getattr(warm, "map_rule", None)
        if warm is not None and rule is not None:
            guess = rule.cell_target + (target - rule.map_mean(warm.gap)) / rule.slope
            slope, slope_error, initial_gap = rule.slope, rule.slope_error, warm.gap
        else:
            guess = first_cell_target(problem, on_cell, target)
            slope, slope_error, initial_gap = 1.0, 1.0, None if warm is None else warm.gap
        solution, rule = map_mean_gap(on_cell, grid.shape, target, guess, settings, slope=slope,
                                      slope_error=slope_error, slope_side=grid.nx // SLOPE_LEVEL,
                                      initial_gap=initial_gap, monitor=monitor, log=True)
        solution.map_rule = rule
        return solution, rule.moves

    def _mean_gap(self, problem, on_cell, control, kind, settings, warm, monitor):
        """Secant steps on the cell's mean gap until the map's is ``control``'s.

        The cell's mean gap less the map's is the outside points' share, estimated
        first as if ``u`` were the same outside as inside (the secant steps correct it).
        The steps are inexact: a solve is taken only as far as the step it serves
        needs (:func:`~petgap.solvers.convergence.secant_tolerance`), and the answer
        is a solve to the whole tolerance whose map mean gap meets the target.  Returns
        the last cell solution, the solves, iterations and history summed, and the
        verdict.
        """
        grid, cell = problem.grid, on_cell.grid
        target = control.mean_gap
        guess = first_cell_target(problem, on_cell, target)
        previous, solves, iterations, history = None, 0, 0, []
        converged, reason = False, "max_solves"
        inner = secant_tolerance(settings.tolerance, None, SECANT_FORCING, SECANT_LOOSEST)
        timer = Timer()
        while solves < self.max_solves:
            solution = solve_as(on_cell, MeanGap(guess), kind, settings.but(tolerance=inner),
                                warm, monitor)
            solves += 1
            iterations += solution.iterations
            history.extend(solution.history)
            mean = map_mean(cell, grid.shape, solution.gap)
            outer_step("the map's mean gap on its padded cell", solves, self.max_solves, timer,
                       f"mean gap off by {abs(mean - target) / problem.gap_scale:.3e} h0 "
                       f"(target {settings.tolerance:.0e}) after {solution.iterations} "
                       f"iterations to {inner:.0e}")
            if not solution.converged:
                reason = solution.reason
                break
            error = abs(mean - target) / problem.gap_scale
            if error <= settings.tolerance and inner <= settings.tolerance:
                converged, reason = True, solution.reason
                break
            inner = secant_tolerance(settings.tolerance, error, SECANT_FORCING, SECANT_LOOSEST)
            slope = 1.0
            if previous is not None and guess != previous[0]:
                slope = (mean - previous[1]) / (guess - previous[0])
                slope = slope if slope > 1e-3 else 1.0
            previous = (guess, mean)
            guess += (target - mean) / slope
            warm = solution
        return solution, solves, iterations, history, converged, reason

    @staticmethod
    def _on_map(problem, on_cell, control, solution, note, timer, *, start_ops, **verdict):
        """The map's solution from the cell's: its rows, judged as the map's."""
        grid, cell = problem.grid, on_cell.grid
        gap = _to_map(grid, cell, solution.gap)
        pressure = _to_map(grid, cell, solution.pressure)
        start = "; ".join(filter(None, [f"solved on the {cell.nx}x{cell.ny} padded cell" + note,
                                        solution.start]))
        # the rigid body's position d of g = d + u - h, with the map's own u = C p (the
        # cell's displacement lacks the mean its periodic q = 0 mode leaves to the control)
        offset = gap + problem.topography - problem.half_space.displacement(pressure)
        approach = problem.top_height - grid.comm.allreduce(float(offset.sum())) / grid.npoints
        return problem.make_solution(
            gap, pressure, gap <= 0, control, solver=solution.solver,
            operator_applications=problem.operator_applications
            + on_cell.operator_applications - start_ops, wall_time=timer(), start=start,
            start_time=solution.start_time, approach=approach, **verdict)
