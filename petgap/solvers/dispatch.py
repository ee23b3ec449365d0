"""Solving a contact problem: the edge where a solve's settings are read and its solver chosen.

:func:`solve` is the boundary of every solve: it puts the solve's own PETSc options
in the database for the length of the solve (:class:`petsc_options`), reads the
settings once (:func:`petgap.solvers.settings.read_settings`: the keywords, then
``-tao_type`` and ``-petgap_*``), asks the registry of solvers
(:mod:`petgap.io.solver_registry`) whether the combination is solved and by what, and
runs it (:func:`run`).  Sweeps: :mod:`petgap.solvers.sweeps`.

Every solve runs as a PETSc TAO solve (:mod:`petgap.solvers.tao`), so the PETSc
options database (``-tao_type``, ``-tao_monitor``, ``-tao_max_it``, ``-tao_view``,
``-log_view``...) has the final word, as every PETSc user expects.

Solver types
------------
``pcg`` (default, a TAO ``python`` type)
    petgap's preconditioned projected conjugate gradients, in the formulation
    that suits the problem (:func:`petgap.io.solver_registry.resolve`): on the
    pressure (``pcg-pressure``, :mod:`petgap.solvers.pressure_cg`) for non-adhesive
    load control, on the gap (``pcg-gap``, :mod:`petgap.solvers.gap_cg`) otherwise.
    Adhesive load control is one load-controlled gap solve started on a branch
    (the previous step, else the hard wall's state at that load), which says
    so when the load is beyond that branch's pull-off
    (:func:`petgap.solvers.control_loops.solve_adhesive_load`).
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
import dataclasses
import textwrap

from petsc4py import PETSc

from petgap.io import solver_registry as registry
from petgap.mechanics.problem import CONTROL_TYPES, Load
from petgap.solvers.free_boundary import PaddedCell
from petgap.solvers.mixed_precision import solve_mixed
from petgap.solvers.contact_limits import FullContact, touching_state
from petgap.solvers.indentation import solve_mean_gap_by_indentation
from petgap.solvers.progress import SolveProgress
from petgap.solvers.settings import read_settings
from petgap.solvers.control_loops import solve_as

#: Solver types a scene may name (:data:`petgap.io.solver_registry.SOLVER_NAMES`).
SOLVER_TYPES = registry.SOLVER_NAMES

#: The free-boundary solver on the padded cell, which keeps each map's cell problem.
PADDED_CELL = PaddedCell()
#: The full-contact end of the hard wall's load range, which keeps each problem's load.
FULL_CONTACT = FullContact()


def solve(problem, control, *, solver="pcg", tolerance=None, max_iterations=10000,
          initial=None, options=None, monitor=None, precision=None):
    """Solve one contact problem.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
    control : one of the controls below
        What is imposed.
    solver : str
        One of :data:`SOLVER_TYPES`; ``-tao_type`` in the options overrides it.
    tolerance : float, optional
        Unit-free KKT tolerance; default 1e-8, or in single precision its floor
        (:data:`petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR`).  A tolerance below
        that floor on a single-precision grid is refused up front: 32-bit rounding of
        the displacement decides the contact edge there, and the solve would only
        stall (``precision="mixed"`` refines in double to any tolerance).
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
        ``monitor(iteration, residual)``, called on every rank.  Without one a solve
        that runs for more than a few seconds logs its progress and its verdict
        (:class:`petgap.solvers.progress.SolveProgress`, the ``petgap`` logger at INFO).
    precision : {"double", "single", "mixed"}, optional
        Default: the grid's (``"double"`` or ``"single"``).  ``"mixed"`` needs a
        double problem (see "Precision" above).

    Returns
    -------
    petgap.mechanics.problem.ContactSolution

    Controls
    --------
    {controls}
    """
    # The options stay in force through the solve: TAO reads some of them there
    # (-tao_view, -tao_converged_reason), not in setFromOptions.
    with petsc_options(options):
        settings = read_settings(problem.grid.precision, solver=solver, tolerance=tolerance,
                                 max_iterations=max_iterations, precision=precision)
        if monitor is not None:
            return run(problem, control, settings, initial=initial, monitor=monitor)
        progress = SolveProgress(settings.tolerance)
        solution = run(problem, control, settings, initial=initial, monitor=progress)
        progress.verdict(solution)
        return solution


def controls_help(indent="    "):
    """The controls :func:`solve` takes, one paragraph each: the registry's
    (:data:`~petgap.io.solver_registry.CONTROLS`), with where the registry solves each
    (boundary, interaction), so that the list cannot fall behind it."""
    paragraphs = []
    for kind in registry.CONTROLS:
        control = CONTROL_TYPES[kind]
        where = [f"{registry.api_name('boundary', periodic)} with "
                 + " or ".join(registry.api_name("interaction", adhesive)
                               for adhesive in (False, True)
                               if registry.refusal(registry.Case(
                                   solver="pcg", control=kind, adhesive=adhesive,
                                   periodic=periodic)) is None)
                 for periodic in (True, False)]
        fields = ", ".join(f.name for f in dataclasses.fields(control))
        summary = control.__doc__.split("\n")[0] if control.__doc__ else ""
        solved = "; ".join(w for w in where if not w.endswith(" with "))
        text = textwrap.fill(f"{summary}  Solved on {solved}.", 80,
                             initial_indent=indent + "    ", subsequent_indent=indent + "    ")
        paragraphs.append(f"``{control.__name__}({fields})``\n{text}")
    return f"\n{indent}".join(paragraphs)


if solve.__doc__:   # (python -OO strips docstrings)
    solve.__doc__ = solve.__doc__.replace("{controls}", controls_help())


def case_of(problem, control, settings):
    """What ``solve`` combines, in the registry's words (:class:`~petgap.io.solver_registry.Case`)."""
    return registry.Case(
        solver=settings.solver, adhesive=problem.interaction.adhesive,
        periodic=problem.half_space.periodic, precision=settings.precision,
        grid=problem.grid.precision, tolerance=settings.tolerance,
        **registry.control_words(control))


def run(problem, control, settings, *, initial=None, monitor=None):
    """Solve ``problem`` under ``control`` with ``settings`` read already (see :func:`solve`).

    Raises ValueError, naming what is refused and what is allowed, for a combination
    the registry does not solve.  Collective.
    """
    case = case_of(problem, control, settings)
    registry.check(case)
    kind = case.kind
    how = registry.method(kind, case.control, case.periodic)
    if how == "padded cell":
        return PADDED_CELL.solve(problem, control, kind, settings, initial=initial,
                                 monitor=monitor)
    if isinstance(control, Load) and not case.adhesive and control.mean_pressure == 0:
        return touching_state(problem, control)  # nothing to solve, for any solver
    if how == "indentation":
        return solve_mean_gap_by_indentation(
            problem, control, settings,
            initial_pressure=None if initial is None else initial.pressure, monitor=monitor)
    checked = 0
    if isinstance(control, Load) and not case.adhesive and case.periodic:
        before = problem.operator_applications
        full = FULL_CONTACT.state(problem, control)   # likewise, at the other end
        if full is not None:
            full.operator_applications = problem.operator_applications - before
            return full
        checked = problem.operator_applications - before   # the first step of a problem
    if settings.precision == "mixed":
        solution = solve_mixed(problem, control, settings, monitor=monitor,
                               initial_pressure=None if initial is None else initial.pressure)
    else:
        solution = solve_as(problem, control, kind, settings, initial, monitor)
    solution.operator_applications += checked
    return solution


class petsc_options:
    """Push PETSc options for the duration of a ``with`` block, then restore them."""

    def __init__(self, options):
        self.options = {str(k).lstrip("-"): ("" if v is None else str(v))
                        for k, v in (options or {}).items()}
        self.saved = {}

    def __enter__(self):
        db = PETSc.Options()
        for key, value in self.options.items():
            self.saved[key] = db.getString(key, None) if db.hasName(key) else None
            db.setValue(key, value)
        return db

    def __exit__(self, *exc):
        db = PETSc.Options()
        for key, old in self.saved.items():
            if old is None:
                db.delValue(key)
            else:
                db.setValue(key, old)
        return False
