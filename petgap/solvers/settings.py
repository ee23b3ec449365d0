"""The settings of a solve: one frozen value, checked once where it is made.

A scene's ``[solver]`` section (which the builder hands to :func:`petgap.solve` as its
keywords, :attr:`petgap.app.build.Model.solve_options`), the PETSc options of a run
(``-petgap_*``, ``-tao_type``) and the keywords of :func:`petgap.solve` all become one
:class:`SolverSettings` in one place, :func:`read_settings`, at the edge of the
program; the solvers receive it and never read an options database.  Each field is
checked here, once, with the key and what is allowed named in the error, so that no
solver re-validates what it was given.
"""
from dataclasses import dataclass, replace

import numpy as np
from petsc4py import PETSc

from petgap.io.solver_registry import (ALIASES, PRECISIONS, SINGLE_TOLERANCE_FLOOR, SOLVER_NAMES,
                                        choice_refusal)
from petgap.solvers.coarse import COARSE_TOLERANCE
from petgap.solvers.edge_correction import EDGE_CORRECTION
from petgap.solvers.patch_interaction import BLOCK

#: The floating-point precisions a field or a transform may run in.
FLOAT_PRECISIONS = ("single", "double")


@dataclass(frozen=True)
class SolverSettings:
    """How to solve, independent of what is solved.

    Attributes
    ----------
    tolerance : float
        Unit-free KKT tolerance (largest pressure violation over ``h0' E*``, gap
        violation over ``h0``), in (0, 1).
    max_iterations : int
        Iteration limit of the whole solve, outer loops included.
    coarse_start : bool
        A cold pressure solve starts from the solution on a coarser grid where the
        grid's shape allows (:mod:`petgap.solvers.coarse`).
    coarse_tolerance : float
        The tolerance of the coarse start's solves (or ``tolerance`` if looser).
    edge_correction : float
        The share, in [0, 1), of the contact-edge term taken off the pressure
        solver's preconditioner (:mod:`petgap.solvers.edge_correction`).
    interaction_block : int
        Side in pixels of the blocks of the preconditioner's patch interaction
        (:mod:`petgap.solvers.patch_interaction`); 0 leaves it out.
    search_precision : {"double", "single"}
        Precision of the pressure solver's two step-finding transforms on a double
        grid (:mod:`petgap.solvers.pressure_cg`, "Precision").
    preconditioned : bool
        Precondition the pressure solver with the restricted stiffness.
    two_level : bool
        The gap solver's two-level preconditioner (:mod:`petgap.solvers.gap_two_level`):
        the contact patches' pinning of long waves and the interaction's curvature on a
        coarse grid, conjugacy kept across projections.  On by default; off
        (``-petgap_two_level 0``) gives the plain compliance preconditioner.
    solver : str
        The solver type asked for (:data:`petgap.io.solver_registry.SOLVER_NAMES`);
        ``"pcg"`` is resolved for each problem and control
        (:func:`petgap.io.solver_registry.resolve`).
    precision : {"double", "single", "mixed"}
        The floating point of the solve, decided once against the problem's grid
        (:func:`read_settings`): single is a problem on a single-precision grid, mixed
        a double problem solved first on its single twin.
    """

    tolerance: float = 1e-8
    max_iterations: int = 10000
    coarse_start: bool = True
    coarse_tolerance: float = COARSE_TOLERANCE
    edge_correction: float = EDGE_CORRECTION
    interaction_block: int = BLOCK
    search_precision: str = "double"
    preconditioned: bool = True
    two_level: bool = True
    solver: str = "pcg"
    precision: str = "double"

    def __post_init__(self):
        for refusal in (choice_refusal("solver", self.solver, SOLVER_NAMES),
                        choice_refusal("precision", self.precision, PRECISIONS)):
            if refusal is not None:
                raise ValueError(refusal.message())
        problems = [problem for problem in (
            _number_in(self.tolerance, "tolerance", 0, 1, "the tolerance is a number in (0, 1), e.g. 1e-8"),
            None if _whole(self.max_iterations) and self.max_iterations >= 0 else
            ("max_iterations", self.max_iterations, "the iteration limit is a whole number >= 0"),
            _number_in(self.coarse_tolerance, "coarse_tolerance", 0, np.inf,
                       "the tolerance of the coarse start's solves is a positive number"),
            None if _real(self.edge_correction) and 0 <= self.edge_correction < 1 else
            ("edge_correction", self.edge_correction,
             "the share of the contact-edge term taken off the preconditioner is in [0, 1)"),
            None if _whole(self.interaction_block) and self.interaction_block >= 0 else
            ("interaction_block", self.interaction_block,
             "the side of the patch interaction's blocks is a whole number of pixels >= 1, "
             "or 0 to leave the interaction out"),
            None if self.search_precision in FLOAT_PRECISIONS else
            ("search_precision", self.search_precision, "need 'single' or 'double'"),
        ) if problem is not None]
        if problems:
            key, value, allowed = problems[0]
            raise ValueError(f"{key} = {value!r} is not allowed: {allowed}")

    def but(self, **changes):
        """A copy with ``changes`` (checked like any other)."""
        return replace(self, **changes)


def _real(value):
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _whole(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _number_in(value, key, low, high, allowed):
    """None when ``low < value < high``, else ``(key, value, allowed)``."""
    return None if _real(value) and low < value < high else (key, value, allowed)


#: petgap's own PETSc options: the :class:`SolverSettings` field each sets, and the kind
#: of value it takes (as :data:`petgap.solvers.options.KNOWN_OPTIONS` says it).
PETGAP_OPTIONS = {"petgap_coarse_start": ("coarse_start", "bool"),
                  "petgap_coarse_tolerance": ("coarse_tolerance", "real"),
                  "petgap_edge_correction": ("edge_correction", "real"),
                  "petgap_interaction_block": ("interaction_block", "int"),
                  "petgap_search_precision": ("search_precision", "precision"),
                  "petgap_two_level": ("two_level", "bool")}


#: The tolerance of a solve that names none; single precision stops at its floor instead.
DEFAULT_TOLERANCE = 1e-8


def read_settings(grid_precision, *, solver="pcg", tolerance=None, max_iterations=10000,
                  precision=None):
    """The settings of one solve: the keywords of :func:`petgap.solve` and PETSc's options.

    The options database is read as it stands: the caller puts a solve's own options
    in it first (:class:`petgap.solvers.dispatch.petsc_options`).  ``-tao_type`` has
    the last word on the solver (TAO's ``python`` is ``pcg``), ``-petgap_*`` set the
    fields of :data:`PETGAP_OPTIONS`.  ``precision`` defaults to the grid's
    (``grid_precision``); a mixed solve finds its steps in single precision unless
    ``-petgap_search_precision`` says otherwise.  ``tolerance`` defaults to
    :data:`DEFAULT_TOLERANCE`, or in single precision to its floor
    (:data:`~petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR`), below which a single
    solve stalls on round-off: a tolerance asked for below it is the registry's to
    refuse.  Raises ValueError naming the keyword or option and what is allowed.
    """
    refusal = choice_refusal("solver", solver, SOLVER_NAMES)
    if refusal is not None:
        raise ValueError(refusal.message())
    db = PETSc.Options()
    asked = db.getString("tao_type", solver)
    refusal = choice_refusal("-tao_type", ALIASES.get(asked, asked), SOLVER_NAMES)
    if refusal is not None:
        raise ValueError(refusal.message())
    precision = grid_precision if precision is None else precision
    if tolerance is None:
        tolerance = SINGLE_TOLERANCE_FLOOR if precision == "single" else DEFAULT_TOLERANCE
    defaults = SolverSettings(search_precision="single" if precision == "mixed" else "double")
    read = {"bool": db.getBool, "real": db.getReal, "int": db.getInt,
            "precision": db.getString}
    options = {field: read[kind](name, getattr(defaults, field))
               for name, (field, kind) in PETGAP_OPTIONS.items()}
    return SolverSettings(tolerance=tolerance, max_iterations=max_iterations,
                          solver=ALIASES.get(asked, asked), precision=precision, **options)
