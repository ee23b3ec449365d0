"""PETSc log events of petgap's kernels: ``-log_view`` sees the elastic operator.

The half-space counts its own applications and runs each inside the event
``petgap:operator``; a solution's ``operator_applications`` is the count's
difference over the solve, so the event's count (with half that of
``petgap:operatorHalf``, the halves a solver runs apart) must grow by exactly that much
(on a grid the pressure solver does not coarsen, or with the coarse start off:
the coarse levels' applications are the event's too, not the solution's).
"""
import numpy as np
import pytest
from petsc4py import PETSc

from petgap.mechanics.interactions import ExponentialAdhesion
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.parallel.log import (GAP_CG_EVENT, GAP_PASS_EVENT, OPERATOR_EVENT,
                                 OPERATOR_HALF_EVENT, SET_UPDATE_EVENT, event)
from petgap.solvers.dispatch import solve
from petgap.surfaces.self_affine import self_affine


def _problem(comm, interaction=None):
    grid = Grid((32, 32), comm=comm, planner="estimate", wisdom=False)
    h = self_affine(grid, 0.8, 4.0, rms_slope=0.1, seed=5)
    return ContactProblem(grid, h, interaction=interaction, contact_modulus=2.0)


def _count(name):
    return event(name).getPerfInfo()["count"]


@pytest.mark.parametrize("solver, control, adhesive, kernels", [
    ("pcg-pressure", Load(0.02), False, (GAP_PASS_EVENT, SET_UPDATE_EVENT)),
    ("pcg-gap", MeanGap(0.5), True, (GAP_CG_EVENT,)),
    ("pcg", Load(0.02), True, (GAP_CG_EVENT,)),   # adhesive load: a hard-wall seed, then gap CG
    ("blmvm", MeanGap(0.5), False, ()),
])
def test_operator_event_counts_the_solutions_applications(comm, solver, control, adhesive,
                                                          kernels):
    PETSc.Log.begin()
    interaction = ExponentialAdhesion(0.002, 1.0) if adhesive else None
    problem = _problem(comm, interaction)
    scale = problem.gap_scale if isinstance(control, MeanGap) else problem.pressure_scale
    control = type(control)(control.value * scale)
    before = {name: _count(name) for name in (OPERATOR_EVENT, OPERATOR_HALF_EVENT) + kernels}
    applications = problem.operator_applications
    solution = solve(problem, control, solver=solver, tolerance=1e-6,
                     options={"petgap_coarse_start": "0"})
    assert solution.operator_applications > 0
    assert problem.operator_applications - applications == solution.operator_applications
    halves = _count(OPERATOR_HALF_EVENT) - before[OPERATOR_HALF_EVENT]
    assert (_count(OPERATOR_EVENT) - before[OPERATOR_EVENT] + halves / 2
            == solution.operator_applications)
    if solver != "blmvm":
        assert halves > 0   # step lengths from the forward half of the direction's image
    for name in kernels:
        assert _count(name) > before[name]


def test_log_view_lists_the_operator_event(comm, mpi_tmp_path):
    """What ``-log_view`` prints at the end of a run: the event's line, with its count."""
    PETSc.Log.begin()
    problem = _problem(comm)
    solution = solve(problem, Load(0.02 * problem.pressure_scale), solver="pcg-pressure",
                     tolerance=1e-8, options={"petgap_coarse_start": "0"})
    assert solution.converged and solution.operator_applications > 0
    total = _count(OPERATOR_EVENT)
    assert total >= solution.operator_applications
    path = mpi_tmp_path / "log_view.txt"
    viewer = PETSc.Viewer().createASCII(str(path), comm=comm)
    try:
        PETSc.Log.view(viewer)
    finally:
        viewer.destroy()
    comm.Barrier()
    lines = [line.split() for line in path.read_text().splitlines()]
    rows = [fields for fields in lines if fields and fields[0] == OPERATOR_EVENT]
    assert rows, f"{OPERATOR_EVENT} is not in the log:\n{path.read_text()}"
    assert int(rows[0][1]) == total  # the count column (the largest over the ranks)


def test_half_space_counts_dense_and_sparse_applications(comm):
    """Every transforming method counts once; the energies (forward only) do not."""
    problem = _problem(comm)
    half_space, grid = problem.half_space, problem.grid
    start = half_space.applications
    field = np.ones(grid.local_shape)
    half_space.pressure(field)
    half_space.displacement(field)
    half_space.apply_in_buffer()
    half_space.apply_in_buffer(inverse=True)
    pidx = np.arange(0, min(3, grid.local_shape[1]), dtype=np.int32)
    half_space.apply_sparse(pidx, np.ones(len(pidx)))
    problem.elastic_pressure(field)
    problem.displacement(field)
    assert half_space.applications - start == 7
    half_space.energy(field)
    half_space.complementary_energy(field)
    assert half_space.applications - start == 7
    assert problem.operator_applications == half_space.applications
