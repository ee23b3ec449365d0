"""Solving a contact problem: the solver types and the choice among them, and sweeps of controls.

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
    solution on a grid 2 or 4 times coarser where the shape allows
    (:mod:`petgap.solvers.coarse`); ``-petgap_coarse_start 0`` starts it from the
    uniform pressure instead.
``bncg``, ``blmvm``, ``bqnls``, ``gpcg`` (TAO built-ins)
    Bound-constrained minimisation over the gap ``g >= 0`` of the load-control
    energy :meth:`petgap.mechanics.problem.ContactProblem.objective_gradient`, made
    dimensionless for TAO (gap over ``h0``, energy over ``k dx dy h0^2`` with
    ``k`` the diagonal of the stiffness; :class:`petgap.solvers.tao.DimensionlessGap`) so that
    TAO's absolute constants mean the same in every unit system and on every
    grid.  Mean-gap control wraps them in an exact multiplier update: the mean
    pressure ``P0`` is adjusted by a secant iteration on ``log(P0 / h0' E*)``
    around inexact inner solves until the mean gap matches.

Every type stops on the same unit-free KKT test (largest pressure violation
over ``h0' E*`` and gap violation over ``h0`` below ``tolerance``), never on
TAO's unit-dependent gradient norms, and reports ``converged=False`` with
TAO's reason when it stops for any other cause.
"""
import math

from petsc4py import PETSc

from petgap.mechanics.problem import Load, MeanGap
from petgap.solvers.pressure_cg import touching_state
from petgap.solvers.tao import (PETGAP_TYPES, petsc_options, solve_load_by_mean_gap,
                                solve_mean_gap_by_multiplier, tao_solve)

#: Solver types a scene may name.
SOLVER_TYPES = ("pcg", "pcg-pressure", "pcg-gap", "bncg", "blmvm", "bqnls", "gpcg")


def solve(problem, control, *, solver="pcg", tolerance=1e-8, max_iterations=10000,
          initial=None, options=None, monitor=None):
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
    if isinstance(control, Load) and not adhesive and control.mean_pressure == 0:
        return touching_state(problem, control)  # nothing to solve, for any solver
    if tao_type == "pcg":
        tao_type = "pcg-pressure" if (isinstance(control, Load) and not adhesive) else "pcg-gap"
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


def sweep(problem, controls, **kwargs):
    """Solve a list of controls in order, each warm-started from the previous one.

    Yields each :class:`~petgap.mechanics.problem.ContactSolution` as soon as it is done,
    so the caller can store it before the next step starts.  Each solution gets

    * ``direction``: ``"loading"`` when the control pushes the surfaces together
      (larger load, smaller mean gap) relative to the previous step,
      ``"unloading"`` when it pulls them apart, ``"start"`` for the first;
    * ``jump``: True when the area at zero gap (``zero_gap_fraction``: repulsive
      and tensile contact alike) changed faster (per unit control) than 3 times
      the previous step did *and* by more than 1 % of the cell -- the signature
      of an instability (snap-in, pull-off) where the warm start left one branch
      of an adhesive, multistable problem for another.  A sweep that reverses
      direction therefore exposes hysteresis: the same control value may carry
      different states on loading and unloading, and which one was found is
      recorded, never averaged away.

      Why not the repulsive area (``contact_fraction``): near the end of a
      JKR-like branch under mean-gap control the surfaces are still stuck, but
      all in tension, so the repulsive area is already zero and pull-off leaves
      it unchanged.  Being a comparison of rates, the test needs a step onto the
      instability not much longer than the steps before it: near the end of a
      branch the area changes like ``sqrt(g_end - g_bar)``, ever faster, and a
      step that ends just short of pull-off sets a high rate for the next one
      to beat (``tests/test_adhesion.py`` resolves Johnson's pull-off with
      steps of 0.2, 0.1, 0.07 and 0.03 ``h_a``).
    """
    previous = kwargs.pop("initial", None)
    last_rate = None
    for control in controls:
        solution = solve(problem, control, initial=previous, **kwargs)
        last_rate = annotate_step(solution, previous, last_rate)
        previous = solution
        yield solution


def annotate_step(solution, previous, last_rate):
    """Set ``solution.direction`` and ``solution.jump`` relative to ``previous`` (see :func:`sweep`).

    Returns the rate of change of the area at zero gap per unit control, for
    the next step's comparison (None when there is no previous step to compare
    with: the first step of a sweep has no reference and is never a jump; nor
    is a step after a state whose ``zero_gap_fraction`` is None, a step read
    back from a result file that stores neither it nor the gap).
    """
    solution.direction, solution.jump = "start", False
    if previous is None or previous.control.kind != solution.control.kind:
        return None
    change = solution.control.value - previous.control.value
    pushes = change > 0 if isinstance(solution.control, Load) else change < 0
    solution.direction = "loading" if pushes else "unloading"
    if solution.zero_gap_fraction is None or previous.zero_gap_fraction is None:
        return None
    dc = solution.zero_gap_fraction - previous.zero_gap_fraction
    rate = abs(dc / change) if change != 0 else (math.inf if dc else 0.0)
    solution.jump = bool(last_rate is not None and abs(dc) > 0.01 and rate > 3 * last_rate)
    return rate
