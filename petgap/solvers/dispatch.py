"""Solving a contact problem: the solver types and the choice among them (sweeps: :mod:`petgap.solvers.sweeps`).

Every solve runs as a PETSc TAO solve (:mod:`petgap.solvers.tao`), so the
PETSc options database (``-tao_type``, ``-tao_monitor``, ``-tao_max_it``,
``-tao_view``, ``-log_view``...) has the final word, as every PETSc user expects.

Solver types
------------
``pcg`` (default, a TAO ``python`` type)
    petgap's preconditioned projected conjugate gradients, in the formulation
    that suits the problem: on the pressure (``pcg-pressure``,
    :mod:`petgap.solvers.pressure_cg`) for non-adhesive load control, on the gap
    (``pcg-gap``, :mod:`petgap.solvers.gap_cg`) otherwise.  Adhesive load control is a
    secant iteration on the mean gap around warm-started mean-gap solves, so
    that each step reports which branch it landed on.
``pcg-pressure``, ``pcg-gap``
    Force one formulation.  A cold ``pcg-pressure`` solve starts from the
    solution on a grid twice as coarse where the shape allows
    (:mod:`petgap.solvers.coarse`); ``-petgap_coarse_start 0`` starts it from the
    uniform pressure instead.  Its preconditioner takes a share of the
    contact-edge term off the restricted stiffness
    (:mod:`petgap.solvers.edge_correction`); ``-petgap_edge_correction 0``
    keeps the plain restricted stiffness.
``bncg``, ``blmvm``, ``bqnls``, ``gpcg`` (TAO built-ins)
    Bound-constrained minimisation over the gap ``g >= 0`` of the load-control
    energy :meth:`petgap.mechanics.problem.ContactProblem.objective_gradient`, made
    dimensionless for TAO (gap over ``h0``, energy over ``k dx dy h0^2`` with
    ``k`` the diagonal of the stiffness; :class:`petgap.solvers.tao.DimensionlessGap`) so that
    TAO's absolute constants mean the same in every unit system and on every
    grid.  Mean-gap control wraps them in an exact multiplier update: the mean
    pressure ``P0`` is adjusted by a secant iteration on ``log(P0 / h0' E*)``
    around inexact inner solves until the mean gap matches.

Precision
---------
``precision="single"`` is a problem on a single-precision grid (the caller
makes it; :class:`petgap.parallel.grid.Grid` ``precision``); ``"mixed"`` is a
double problem solved first on its single twin and refined
(:mod:`petgap.solvers.mixed_precision`).  Both run ``pcg-pressure`` (``pcg``
means it here, under load and mean gap), non-adhesive and periodic; other
solvers, adhesion and the free boundary refuse them, saying so.

On a free boundary (:class:`petgap.mechanics.free_half_space.FreeHalfSpace`) the hard
wall runs ``pcg-pressure`` on the map: under load, under
:class:`~petgap.mechanics.problem.Indentation`, and under a mean gap through the
indentation (:func:`petgap.solvers.indentation.solve_mean_gap_by_indentation`).
Adhesion, and the solvers on the gap, run on the map's padded periodic cell
(:mod:`petgap.solvers.free_boundary`), under load or mean gap.

Every type stops on the same unit-free KKT test (largest pressure violation
over ``h0' E*`` and gap violation over ``h0`` below ``tolerance``), never on
TAO's unit-dependent gradient norms, and reports ``converged=False`` with
TAO's reason when it stops for any other cause.
"""

from petsc4py import PETSc

from petgap.mechanics.problem import Indentation, Load, MeanGap
from petgap.solvers.free_boundary import solve_on_cell
from petgap.solvers.mixed_precision import solve_mixed
from petgap.solvers.settings import SolverSettings
from petgap.solvers.contact_limits import full_contact_state, touching_state
from petgap.solvers.indentation import solve_mean_gap_by_indentation
from petgap.solvers.tao import (PETGAP_TYPES, petsc_options, pressure_solver_options,
                                solve_load_by_mean_gap, solve_mean_gap_by_multiplier,
                                tao_solve)

#: Solver types a scene may name.
SOLVER_TYPES = ("pcg", "pcg-pressure", "pcg-gap", "bncg", "blmvm", "bqnls", "gpcg")
#: Floating-point modes of a solve (``solver.precision`` of a scene).
PRECISIONS = ("double", "single", "mixed")


def solve(problem, control, *, solver="pcg", tolerance=1e-8, max_iterations=10000,
          initial=None, options=None, monitor=None, precision=None):
    """Solve one contact problem.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
    control : petgap.mechanics.problem.Load or petgap.mechanics.problem.MeanGap
    solver : str
        One of :data:`SOLVER_TYPES`; ``-tao_type`` in the options overrides it.
    tolerance : float
        Unit-free KKT tolerance.
    max_iterations : int
        Iteration limit of the whole solve, summed over the inner solves of the
        outer loops (adhesive load control, mean-gap control with TAO
        built-ins), so that a sweep step never costs more (``-tao_max_it``
        overrides it for each TAO solve).
    initial : petgap.mechanics.problem.ContactSolution, optional
        Warm start: the previous state of a sweep.
    options : dict, optional
        PETSc options (without the leading dash) set for this solve only.
    monitor : callable, optional
        ``monitor(iteration, residual)``, called on every rank.
    precision : {"double", "single", "mixed"}, optional
        Default: the grid's (``"double"`` or ``"single"``).  ``"mixed"`` needs a
        double problem (see "Precision" above).

    Returns
    -------
    petgap.mechanics.problem.ContactSolution
    """
    if solver not in SOLVER_TYPES:
        raise ValueError(f"solver {solver!r} is not one of {', '.join(SOLVER_TYPES)}")
    if not (isinstance(tolerance, float) or isinstance(tolerance, int)) or not 0 < tolerance < 1:
        raise ValueError(f"tolerance must be in (0, 1), got {tolerance!r}")
    with petsc_options(options):
        tao_type = PETSc.Options().getString("tao_type", solver)
    if tao_type == "python":
        tao_type = "pcg"
    if tao_type not in SOLVER_TYPES:
        raise ValueError(f"-tao_type {tao_type} is not supported; use one of {', '.join(SOLVER_TYPES)}")
    adhesive = problem.interaction.adhesive
    periodic = problem.half_space.periodic
    grid_precision = problem.grid.precision
    precision = grid_precision if precision is None else precision
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r} is not one of {', '.join(PRECISIONS)}")
    if precision != "double":
        if (precision == "mixed") != (grid_precision == "double"):
            raise ValueError(f"precision {precision!r} on a {grid_precision}-precision grid: "
                             f"single solves a problem on a single-precision grid, mixed one "
                             f"on a double grid")
        if adhesive or not periodic or tao_type not in ("pcg", "pcg-pressure") \
                or not isinstance(control, (Load, MeanGap)):
            raise ValueError(f"precision {precision!r} is for non-adhesive contact on a "
                             f"periodic cell under load or mean gap, solved by pcg or "
                             f"pcg-pressure (here: {'adhesive' if adhesive else 'hard wall'}, "
                             f"{'periodic' if periodic else 'free boundary'}, {tao_type}, "
                             f"{type(control).__name__}); use double precision")
        tao_type = "pcg-pressure"
    if not periodic and (adhesive or tao_type not in ("pcg", "pcg-pressure")):
        if isinstance(control, Indentation):
            raise ValueError("indentation control is for the hard wall with pcg or "
                             "pcg-pressure; adhesion (and the gap solvers) on a free boundary "
                             "take load or mean-gap control")
        def on_cell(cell_problem, cell_control, warm):
            return _solve(cell_problem, cell_control, tao_type, adhesive, tolerance,
                          max_iterations, warm, options, monitor)
        return solve_on_cell(problem, control, on_cell, tolerance=tolerance,
                             max_iterations=max_iterations, initial=initial)
    if isinstance(control, Indentation) and periodic:
        raise ValueError("indentation control needs a free boundary (surface.periodic = "
                         "false): on a periodic cell an approach fixes no load; use load or "
                         "mean-gap control")
    if isinstance(control, Load) and not adhesive and control.mean_pressure == 0:
        return touching_state(problem, control)  # nothing to solve, for any solver
    if not periodic and isinstance(control, MeanGap):
        with petsc_options(options):
            return solve_mean_gap_by_indentation(
                problem, control, SolverSettings(
                    tolerance=tolerance, max_iterations=max_iterations,
                    edge_correction=pressure_solver_options()["edge_correction"]),
                initial_pressure=None if initial is None else initial.pressure, monitor=monitor)
    checked = 0
    if isinstance(control, Load) and not adhesive and periodic:
        before = problem.operator_applications
        full = full_contact_state(problem, control)   # likewise, at the other end
        if full is not None:
            full.operator_applications = problem.operator_applications - before
            return full
        checked = problem.operator_applications - before   # the first step of a problem
    if precision == "mixed":
        with petsc_options(options):
            settings = pressure_solver_options()
        solution = solve_mixed(problem, control, SolverSettings(
                                   tolerance=tolerance, max_iterations=max_iterations,
                                   **{"search_precision": "single", **settings}),
                               monitor=monitor,
                               initial_pressure=None if initial is None else initial.pressure)
    else:
        solution = _solve(problem, control, tao_type, adhesive, tolerance, max_iterations,
                          initial, options, monitor)
    solution.operator_applications += checked
    return solution


def _solve(problem, control, tao_type, adhesive, tolerance, max_iterations, initial, options,
           monitor):
    if tao_type == "pcg":
        tao_type = ("pcg-pressure" if isinstance(control, (Load, Indentation)) and not adhesive
                    else "pcg-gap")
    if tao_type == "pcg-pressure" and adhesive:
        raise ValueError("solver 'pcg-pressure' (Polonsky-Keer on the pressure) is for "
                         "non-adhesive contact; use pcg or pcg-gap for adhesion")
    if isinstance(control, Load) and adhesive and tao_type == "pcg-gap":
        return solve_load_by_mean_gap(problem, control, tolerance, max_iterations, initial,
                                       options, monitor)
    if isinstance(control, MeanGap) and tao_type not in PETGAP_TYPES:
        return solve_mean_gap_by_multiplier(problem, control, tao_type, tolerance,
                                            max_iterations, initial, options, monitor)
    return tao_solve(problem, control, tao_type, tolerance, max_iterations, initial, options,
                     monitor)
