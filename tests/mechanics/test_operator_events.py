"""The elastic operator counts and logs its own applications (PETSc log events, -log_view)."""
import sys

import numpy as np
from petsc4py import PETSc

from petgap.mechanics.half_space import COMPLIANCE_EVENT, STIFFNESS_EVENT
from petgap.mechanics.interactions import ExponentialAdhesion
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers.dispatch import solve
from petgap.surfaces.self_affine import self_affine


def _counts():
    return sum(event.getPerfInfo()["count"] for event in (STIFFNESS_EVENT, COMPLIANCE_EVENT))


def _problem(comm, interaction=None):
    grid = Grid((64, 48), comm=comm, planner="estimate", wisdom=False)
    h = self_affine(grid, 0.8, 8.0, rms_slope=0.1, seed=3)
    return ContactProblem(grid, h, interaction=interaction, contact_modulus=2.0)


def test_each_solver_counts_exactly_the_logged_applications(comm):
    """Every solve's ``operator_applications`` is what the operator's log events counted."""
    PETSc.Log.begin()
    hard = _problem(comm)
    sticky = hard.with_interaction(ExponentialAdhesion(1e-4, 0.05))
    cases = [(hard, Load(0.005), "pcg"), (hard, MeanGap(0.2), "pcg"),
             (hard, Load(0.005), "bncg"), (sticky, MeanGap(0.2), "pcg"),
             (sticky, Load(0.005), "pcg")]
    for problem, control, solver in cases:
        before, counted_before = _counts(), problem.operator_applications
        solution = solve(problem, control, solver=solver, tolerance=1e-6, max_iterations=2000)
        assert solution.operator_applications > 0
        assert _counts() - before == solution.operator_applications, (solver, control)
        assert problem.operator_applications - counted_before == solution.operator_applications


def test_problem_with_another_interaction_shares_the_counter(comm):
    hard = _problem(comm)
    sticky = hard.with_interaction(ExponentialAdhesion(1e-4, 0.05))
    assert sticky.half_space is hard.half_space and sticky.grid is hard.grid
    assert sticky.topography is hard.topography and not hard.interaction.adhesive
    before = hard.operator_applications
    sticky.elastic_pressure(np.zeros(hard.grid.local_shape))
    assert hard.operator_applications == before + 1 == sticky.operator_applications


def test_problem_makes_its_half_space_from_a_modulus(comm):
    problem = _problem(comm)
    assert problem.half_space.contact_modulus == 2.0
    assert problem.pressure_scale == problem.rms_slope * 2.0


def test_log_view_lists_the_operator_events(run_cli, mpi_tmp_path):
    """``-log_view`` of a solve shows petgap's operator events with their counts.

    The coarse-grid start is off: its solve on the coarse grid runs the same
    operator (and is logged), but a solution counts only its own grid's applications.
    """
    log, count = mpi_tmp_path / "log.txt", mpi_tmp_path / "applications.txt"
    script = (
        "import sys, petsc4py; petsc4py.init(sys.argv)\n"
        "from mpi4py import MPI\n"
        "from petgap.mechanics.problem import ContactProblem, Load\n"
        "from petgap.parallel.grid import Grid\n"
        "from petgap.solvers.dispatch import solve\n"
        "from petgap.surfaces.self_affine import self_affine\n"
        "grid = Grid((64, 64), comm=MPI.COMM_WORLD, planner='estimate', wisdom=False)\n"
        "problem = ContactProblem(grid, self_affine(grid, 0.8, 8.0, rms_slope=0.1, seed=1))\n"
        "s = solve(problem, Load(0.005), tolerance=1e-8, options={'petgap_coarse_start': '0'})\n"
        f"MPI.COMM_WORLD.rank or open({str(count)!r}, 'w').write(str(s.operator_applications))\n")
    result = run_cli([sys.executable, "-c", script, "-log_view", f":{log}"], ranks=2)
    assert result.returncode == 0, result.stdout + result.stderr
    applications = int(count.read_text())
    rows = [line.split() for line in log.read_text().splitlines() if line.startswith("petgap: K")]
    assert {" ".join(r[:3]) for r in rows} == {"petgap: K u", "petgap: K^-1 p"}
    # -log_view's first column after the name is the count (max over ranks)
    assert sum(int(r[3]) for r in rows) == applications > 0
