"""Where the gap solver starts when no warm start is given.

A cold gap solve (:func:`petgap.solvers.gap_cg.gap_cg`) starts from one of:

* **the same solve on a grid twice as coarse** (:func:`coarse_start_gap`), on a
  periodic cell (a free map's padded cell too) whose sides allow it (:data:`MIN_SIDE`), unless
  ``-petgap_coarse_start 0``.  Why: the two-level preconditioner
  (:mod:`petgap.solvers.gap_two_level`) makes each iteration's progress nearly
  independent of the grid, but a sticky interface starting from the rigid
  approach must first grow its contact patches to their adhesive size, one
  edge pixel at a time at the crack tips, which costs iterations in proportion
  to the patches' width in pixels.  On the coarse grid that growth costs a
  quarter per iteration and half the iterations; the fine solve is left the
  edges' last pixels.  The coarse problem is solved the same way, so large
  grids descend level by level to :data:`MIN_SIDE`.
* **the hard wall's state at the load** (:func:`hard_wall_seed`), for an adhesive
  load-controlled solve that is not coarsened: the non-adhesive contact the
  adhesion then grows from, which puts the solve on the branch connected to it
  (a tensile load peels it).
* otherwise the solver's own start: the rigid approach.

Conventions: the coarse problem is :func:`petgap.solvers.coarse.coarse_problem`
in the fine grid's precision (the gap solver works in double) and with the fine
problem's KKT scales, so that its tolerance means what the fine one's does (a
free map's padded cell has the map's scales, not those of its far surface,
:mod:`petgap.solvers.free_boundary`); what is
prolonged is the smooth part of the state, ``g + h`` (the surface's deformed
position, whose stiffness gives ``p_el``), repeated over each block, and the
fine gap is that less the fine topography, so that the fine roughness inside
each block is not smeared into the start.  With adhesion, a block whose
coarse point is at the wall starts at the wall on all its fine points: the
adhesion holds a patch's interior closed over the fine roughness, and
prolonging ``g + h`` there would open the half of each block that lies below
its mean, which the first fine step closes again past the patch's edges, the
overshoot then released an edge pixel at a time.  The coarse solve stops at
``max(tolerance, coarse_tolerance)``; a coarse solve that did not converge
still gives its state (one with NaN gives none).  The choice depends on the
grid's shape only, never on the number of ranks.
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import Load
from petgap.solvers import coarse
from petgap.solvers.pressure_cg import polonsky_keer

#: Smallest side of a coarse level of the gap solver's start.  Below it a level
#: saves the fine solve too little to pay for its own iterations.
MIN_SIDE = 256


def cold_start(problem, control, settings, solver):
    """``(gap, description)`` to start a cold gap solve from, or ``(None, "")``.

    ``solver(problem, control, settings)`` solves a coarse level (the gap solver
    itself, which starts that level the same way).  Collective.
    """
    gap, description = coarse_start_gap(problem, control, settings, solver)
    if gap is None and isinstance(control, Load) and problem.interaction.adhesive:
        return hard_wall_seed(problem, control, settings)
    return gap, description


def coarse_start_gap(problem, control, settings, solver):
    """The gap of the same solve on a grid twice as coarse, prolonged (module docstring).

    ``(None, "")`` where the grid is not coarsened (a free map itself, whose gap
    solves run on its padded cell, which is coarsened; ``settings.coarse_start`` off;
    a shape without a level of :data:`MIN_SIDE`), or
    ``(None, why)`` when the coarse solve produced NaN.  The gap is on the fine grid's
    :meth:`~petgap.parallel.grid.Grid.scratch`: read it before the next transform.
    """
    grid = problem.grid
    f = coarse.coarsening_factor(grid.shape)
    if not settings.coarse_start or not problem.half_space.periodic or f is None \
            or min(grid.shape) // f < MIN_SIDE:
        return None, ""
    level = coarse.coarse_problem(problem, precision=grid.precision, scales=problem.scales)
    if level is None:
        return None, ""
    solution = solver(level, control, settings.but(
        tolerance=max(settings.tolerance, settings.coarse_tolerance)))
    smooth = solution.gap + level.topography
    finite = grid.comm.allreduce(bool(np.isfinite(smooth).all()), op=MPI.LAND)
    cgrid = level.grid
    description = (f"coarse {cgrid.nx}x{cgrid.ny}: {solution.iterations} iterations, "
                   f"{solution.reason}"
                   + (f"; {solution.start}" if solution.start else ""))
    if not finite:
        return None, description + " (NaN: not used)"
    first_row, whole = cgrid.x_slice.start, coarse.is_whole(grid, cgrid)
    if problem.interaction.adhesive:
        smooth[solution.gap <= 0] = np.nan   # marks the blocks that start at the wall
    del solution, level, cgrid  # before the fine solve makes its fields
    gap = coarse.prolong(first_row, grid, smooth, f, whole, out=grid.scratch())
    gap -= problem.topography
    np.copyto(gap, 0.0, where=np.isnan(gap))
    return gap, description


def hard_wall_seed(problem, load, settings):
    """The hard wall's state at ``load`` (at least ``1e-3 h0' E*``): ``(gap, description)``.

    The pressure solver's, to ``max(tolerance, 1e-6)``: a start, not a result.
    """
    hard = problem.with_interaction(None)
    seed = polonsky_keer(hard, Load(max(float(load.mean_pressure), 1e-3 * problem.pressure_scale)),
                         settings.but(tolerance=max(settings.tolerance, 1e-6)))
    return seed.gap, f"hard wall at the load: {seed.iterations} iterations, {seed.reason}"
