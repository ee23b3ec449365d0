"""Finding the contact state: one entry point, its TAO bridge and petgap's own solvers.

:func:`solve` takes a :class:`~petgap.mechanics.problem.ContactProblem` and a
control and returns a :class:`~petgap.mechanics.problem.ContactSolution`;
:func:`sweep` solves a list of controls, each step warm-started from the
previous one.  Every solver stops on the same unit-free KKT test.

Modules
-------
:mod:`.dispatch`
    :func:`solve`: the edge where a solve's settings are read once
    (:mod:`.settings`) and the solver the registry of solvers chooses
    (:mod:`petgap.io.solver_registry`, solver types :data:`SOLVER_TYPES`) is run;
    ``-tao_type`` and the other PETSc options have the last word.
:mod:`.sweeps`
    :func:`sweep` and :func:`annotate_step`.
:mod:`.control_loops`
    The outer loops that turn one control into another around inner solves.
:mod:`.tao`
    The bridge to PETSc TAO (petgap's own solvers as a ``python`` type, TAO's
    built-ins on the dimensionless gap); :mod:`.options`, the options a run may give.
:mod:`.free_boundary`, :mod:`.indentation`, :mod:`.mixed_precision`
    A free map's adhesion on its padded cell; a free map's mean gap through the
    indentation; a single solve refined in double.
:mod:`.pressure_cg`
    Polonsky-Keer conjugate gradients on the pressure: the core, calling its
    preconditioner (:mod:`.preconditioners`) and started by :mod:`.pressure_start`;
    :mod:`.contact_limits`, the zero-load and full-contact ends of the load range.
:mod:`.gap_cg`
    Projected conjugate gradients on the gap, preconditioned by the
    compliance (mean-gap control, adhesion).
:mod:`.coarse`, :mod:`.edge_correction`, :mod:`.patch_interaction`
    The coarse grid of the pressure solver's start; its preconditioner's edge term
    and patch interaction.
:mod:`.contact_set`, :mod:`._contact_set`, :mod:`._kernels`
    The contact set as index lists and the compiled kernels of the solvers.
"""
from petgap.solvers.dispatch import SOLVER_TYPES, solve
from petgap.solvers.sweeps import annotate_step, sweep

__all__ = ["solve", "sweep", "annotate_step", "SOLVER_TYPES"]
