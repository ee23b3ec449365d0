"""The pressure solver's search in single precision on a double grid (``search_precision``).

The preconditioner's transform and the direction's image in 32 bits, everything the
answer is taken from in 64: the solve reaches the double tolerance and the double
search's answer (the same contact set, the pressure within the tolerance's reach), on
one rank and on all; what it gives up -- results equal across rank counts to round-off
-- is measured here too, which is why double is the default and only mixed precision
uses it.  The option reaches the solver from PETSc's database and is checked there.
"""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers.dispatch import solve
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.solvers.options import check_petsc_options
from petgap.surfaces.self_affine import self_affine


def rough(comm, shape=(192, 160), seed=7):
    grid = Grid(shape, comm=comm, planner="estimate")
    h = self_affine(grid, 0.8, 12.0, shape[1] / 2, rms_slope=0.1, seed=seed)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, 1.0))


def largest(comm, a):
    return comm.allreduce(float(np.abs(a).max()), op=MPI.MAX)


def contact_difference(comm, a, b):
    return comm.allreduce(int(np.count_nonzero((a.pressure > 0) != (b.pressure > 0))))


@pytest.mark.parametrize("control", ["load", "mean-gap"])
def test_a_single_search_reaches_the_double_answer(comm, control):
    problem = rough(comm)
    ctrl = (Load(0.004) if control == "load" else MeanGap(0.6 * problem.rms_height))
    ref = polonsky_keer(problem, ctrl, SolverSettings(tolerance=1e-9, search_precision="double"))
    before = problem.operator_applications
    sol = polonsky_keer(problem, ctrl, SolverSettings(tolerance=1e-9, search_precision="single"))
    assert SolverSettings().search_precision == "double"
    assert ref.converged and sol.converged and sol.kkt_gap <= 1e-9
    assert sol.pressure.dtype == np.float64 and sol.gap.dtype == np.float64
    assert sol.operator_applications == problem.operator_applications - before > 0
    assert abs(sol.iterations - ref.iterations) <= 2
    assert contact_difference(comm, sol, ref) == 0
    # both within 1e-9 h0 of the solution: their pressures agree to that scale, far
    # above round-off and far below what a 32-bit pressure would give (1e-7)
    ps = problem.pressure_scale
    assert largest(comm, sol.pressure - ref.pressure) <= 1e-8 * ps
    assert largest(comm, sol.pressure - ref.pressure) > 0 or comm.size > 1


def test_a_single_search_depends_on_the_ranks_within_the_tolerance(comm):
    """One rank against all ranks: the double search agrees to round-off, the single search
    to the tolerance's reach only (the path follows the decomposition's 32-bit rounding)."""
    one, many = rough(MPI.COMM_SELF, shape=(130, 64)), rough(comm, shape=(130, 64))
    grid, ps = many.grid, many.pressure_scale
    for search, bound in (("double", 1e-12), ("single", 1e-8)):
        a = polonsky_keer(one, Load(0.004), SolverSettings(tolerance=1e-9, search_precision=search))
        b = polonsky_keer(many, Load(0.004), SolverSettings(tolerance=1e-9, search_precision=search))
        assert a.converged and b.converged
        assert largest(comm, b.pressure - a.pressure[grid.x_slice]) <= bound * ps
        assert a.contact_fraction == b.contact_fraction


def test_the_option_reaches_the_solver_and_is_checked(comm):
    problem = rough(comm, shape=(96, 80))
    direct = polonsky_keer(problem, Load(0.004), SolverSettings(tolerance=1e-8, search_precision="single"))
    double = polonsky_keer(problem, Load(0.004), SolverSettings(tolerance=1e-8))
    run = solve(problem, Load(0.004), tolerance=1e-8, solver="pcg",
                options={"petgap_search_precision": "single"})
    assert run.converged and run.iterations == direct.iterations
    np.testing.assert_array_equal(run.pressure, direct.pressure)
    assert largest(comm, double.pressure - direct.pressure) > 0 or comm.size > 1
    errors, unknown = check_petsc_options({"petgap_search_precision": "half"})
    assert errors == [("petgap_search_precision", "half", "is not a precision",
                       "single or double")] and not unknown
    with pytest.raises(ValueError, match="search_precision = 'half' is not allowed: need "
                                         "'single' or 'double'"):
        polonsky_keer(problem, Load(0.004), SolverSettings(search_precision="half"))


def test_a_single_search_on_a_free_boundary(comm):
    """The free compliance is applied in double (its image stays double, no 32-bit slab to
    read it from); the preconditioner, the periodic stiffness, runs in single: Hertz's
    contact to the same answer as the double search."""
    from petgap.mechanics.free_half_space import FreeHalfSpace
    from petgap.mechanics.problem import Indentation
    from petgap.surfaces.indenters import indenter
    grid = Grid((96, 96), comm=comm, planner="estimate", wisdom=False)
    problem = ContactProblem(grid, indenter(grid, "paraboloid", 400.0), FreeHalfSpace(grid, 1.0))
    assert not problem.half_space.transforms_in_single
    control = Indentation(24.0 ** 2 / 400.0)
    ref = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9))
    sol = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, search_precision="single"))
    assert ref.converged and sol.converged and contact_difference(comm, sol, ref) == 0
    assert largest(comm, sol.pressure - ref.pressure) <= 1e-8 * largest(comm, ref.pressure)
    assert sol.mean_pressure == pytest.approx(ref.mean_pressure, rel=1e-9)
