"""Mixed precision: a single-precision pressure solve, refined in double to the tolerance.

Why: in single precision the pressure solver's iterations stream half the bytes
and its memory is about half (:mod:`petgap.solvers.pressure_cg`, "Precision"),
but the gap ``u - h + d`` is a difference of 7-digit numbers, so its KKT
residual stops near ``1e-7 max|h| / h0``.  Most iterations of a solve are
spent finding the contact set, which single precision finds as well as double;
the last digits need double.  So: solve the problem's single-precision twin to
:data:`petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR` (or the requested tolerance, if
looser), drop it, and continue in double from its pressure.  The double solve
starts on the single solution's contact set, which the refinement changes only
at a few edge points.

The twin is the same cell, topography (rounded to 32 bits), modulus and
interaction on a single-precision :class:`~petgap.parallel.grid.Grid` of the
same shape and communicator; its peak memory is below the double solve's, and
it is freed before the double solve allocates its own.  The double solve finds
its steps in single precision (``search_precision="single"`` of
:func:`~petgap.solvers.pressure_cg.polonsky_keer`): its answer is double's, and
its path depends on the decomposition at the level the single solve's already does.
"""
import numpy as np

from petgap.io.solver_registry import SINGLE_TOLERANCE_FLOOR
from petgap.mechanics.problem import ContactProblem
from petgap.parallel.grid import Grid
from petgap.solvers.convergence import Timer
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings


def single_precision_twin(problem):
    """The same contact problem on a single-precision grid (collective).

    What single precision solves (the hard wall on a periodic cell) is the
    registry's rule (:mod:`petgap.io.solver_registry`), asked before a solve.
    """
    grid = problem.grid
    sgrid = Grid(grid.shape, size=(grid.Lx, grid.Ly), comm=grid.comm, planner=grid.planner,
                 wisdom=grid.wisdom, precision="single")
    return ContactProblem(sgrid, problem.topography.astype(np.float32),
                          problem.half_space.on_grid(sgrid), problem.interaction)


def solve_mixed(problem, control, settings=SolverSettings(search_precision="single"), *,
                monitor=None, initial_pressure=None):
    """Solve ``problem`` (double precision) under load or mean gap, first in single.

    The single-precision solve runs to ``max(tolerance, SINGLE_TOLERANCE_FLOOR)``
    from the coarse start (or from ``initial_pressure``, a sweep's previous step);
    the double solve to ``tolerance`` from its pressure, with its search in
    ``settings.search_precision``.
    Whatever the single solve ends with (converged or not) is only a start: the
    double solve's verdict is the result's.  The result's iterations, operator
    applications and history are the sums over both solves (the coarse start's
    not counted, as in every pressure solve); ``start`` says how each went, and
    ``precision`` is ``"mixed"``.  What it solves (the hard wall on a periodic cell,
    under load or mean gap) the registry says (:mod:`petgap.io.solver_registry`),
    asked by :func:`petgap.solvers.dispatch.run` first.  Collective.
    """
    timer = Timer()
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    twin = single_precision_twin(problem)
    single = polonsky_keer(twin, control, settings.but(
                               tolerance=max(tolerance, SINGLE_TOLERANCE_FLOOR),
                               search_precision="double"),
                           monitor=monitor,
                           initial_pressure=None if initial_pressure is None
                           else initial_pressure.astype(np.float32))
    start_ops = single.operator_applications
    pressure = single.pressure.astype(np.float64)
    description = (f"single precision: {single.iterations} iterations, {single.reason} "
                   f"(KKT {single.kkt_gap:.1e}); {single.start}")
    single_iterations, single_history = single.iterations, list(single.history)
    del twin, single
    double = polonsky_keer(problem, control, settings.but(
                               max_iterations=max(max_iterations - single_iterations, 1)),
                           initial_pressure=pressure, monitor=monitor)
    del pressure
    double.start = f"{description}; refined in double from its pressure"
    double.iterations += single_iterations
    double.history = single_history + list(double.history)
    double.operator_applications += start_ops
    double.wall_time = timer()
    double.precision = "mixed"
    return double
