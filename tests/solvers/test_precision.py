"""Single and mixed precision of the pressure solver (petgap.solvers.mixed_precision).

Single precision is a trade, and these tests pin down its terms on a rough surface:
the single solve reaches its tolerance floor with the double solve's contact set to
within a few edge points (contact fraction within 0.2 %, as the fields are rounded to
7 digits), its fields are 32-bit, and it does not depend on the decomposition beyond
round-off; the mixed solve reaches the double tolerance and the double answer.  The
refusals name what single and mixed precision do not solve.
"""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.io.scene import SINGLE_TOLERANCE_FLOOR
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import ExponentialAdhesion
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers.dispatch import solve
from petgap.solvers.mixed_precision import single_precision_twin
from petgap.solvers.pressure_cg import STALL_FACTOR, STALL_ITERATIONS, polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine

SHAPE = (256, 256)


def rough(comm, precision="double", shape=SHAPE):
    """The same surface (made in double) on a grid of either precision."""
    double = Grid(shape, comm=comm, planner="estimate")
    h = self_affine(double, 0.8, 16.0, shape[0] / 2, rms_slope=0.1, seed=7)
    if precision == "double":
        return ContactProblem(double, h, ElasticHalfSpace(double, 1.0))
    grid = Grid(shape, comm=comm, planner="estimate", precision=precision)
    return ContactProblem(grid, h.astype(np.float32), ElasticHalfSpace(grid, 1.0))


def contact_difference(grid, a, b):
    """Points in contact in one solution and not the other, over all ranks."""
    return grid.comm.allreduce(int(np.count_nonzero((a.pressure > 0) != (b.pressure > 0))))


@pytest.mark.parametrize("control", [Load(0.004), MeanGap(0.5)])
def test_single_precision_solve_is_the_double_one_rounded(comm, control):
    double = rough(comm)
    single = rough(comm, "single")
    if isinstance(control, MeanGap):
        control = MeanGap(control.mean_gap * double.rms_height)
    ref = solve(double, control, tolerance=1e-8)
    sol = solve(single, control, tolerance=SINGLE_TOLERANCE_FLOOR)
    assert ref.converged and sol.converged and sol.precision == "single"
    assert sol.gap.dtype == np.float32 and sol.pressure.dtype == np.float32
    assert sol.kkt_gap <= SINGLE_TOLERANCE_FLOOR
    assert abs(sol.contact_fraction - ref.contact_fraction) <= 2e-3 * ref.contact_fraction
    # the fields agree to the tolerance's scale, not only in their means
    grid = double.grid
    dg = grid.comm.allreduce(float(np.abs(sol.gap - ref.gap).max()), op=MPI.MAX)
    assert dg <= 10 * SINGLE_TOLERANCE_FLOOR * double.gap_scale
    assert sol.mean_pressure == pytest.approx(ref.mean_pressure, rel=1e-5)
    assert sol.mean_gap == pytest.approx(ref.mean_gap, rel=1e-5)


def test_mixed_precision_reaches_the_double_answer(comm):
    double = rough(comm)
    control = Load(0.004)
    ref = solve(double, control, tolerance=1e-9)
    mixed = solve(double, control, tolerance=1e-9, precision="mixed")
    assert mixed.converged and mixed.precision == "mixed" and mixed.kkt_gap <= 1e-9
    assert mixed.gap.dtype == np.float64
    assert mixed.start.startswith("single precision: ") and "refined in double" in mixed.start
    assert contact_difference(double.grid, mixed, ref) == 0
    grid = double.grid
    dp = grid.comm.allreduce(float(np.abs(mixed.pressure - ref.pressure).max()), op=MPI.MAX)
    assert dp <= 1e-8 * double.pressure_scale * 100
    assert mixed.contact_fraction == ref.contact_fraction


def test_single_precision_does_not_depend_on_the_ranks(comm):
    """One rank and all ranks, the same single-precision problem: round-off only."""
    one = rough(MPI.COMM_SELF, "single", shape=(96, 80))
    many = rough(comm, "single", shape=(96, 80))
    a = solve(one, Load(0.004), tolerance=1e-5)
    b = solve(many, Load(0.004), tolerance=1e-5)
    grid = many.grid
    assert a.converged and b.converged
    assert a.contact_fraction == b.contact_fraction
    dp = grid.comm.allreduce(float(np.abs(b.pressure - a.pressure[grid.x_slice]).max()),
                             op=MPI.MAX)
    assert dp <= 1e-4 * many.pressure_scale


def test_a_single_solve_below_its_round_off_stops_as_stalled(comm):
    """Asked for what 32 bits cannot resolve, a single solve stops and says so.

    Without the stall rule it would chatter at its round-off floor up to the
    iteration limit; the double solve of the same tolerance converges.
    """
    single = rough(comm, "single")
    sol = polonsky_keer(single, Load(0.004), SolverSettings(tolerance=1e-10, max_iterations=2000))
    assert not sol.converged and sol.reason == "stalled_round_off"
    assert STALL_ITERATIONS < sol.iterations < 200
    assert 1e-10 < sol.kkt_gap < 1e-5        # near its floor, not lost
    assert len(sol.history) > STALL_ITERATIONS
    best = min(sol.history)
    assert min(sol.history[-STALL_ITERATIONS:]) >= STALL_FACTOR * best
    double = polonsky_keer(rough(comm), Load(0.004), SolverSettings(tolerance=1e-10, max_iterations=2000))
    assert double.converged and double.kkt_gap <= 1e-10


def test_single_precision_twin_is_the_same_problem(comm):
    double = rough(comm, shape=(64, 64))
    twin = single_precision_twin(double)
    assert twin.grid.precision == "single" and twin.topography.dtype == np.float32
    assert twin.grid.shape == double.grid.shape and twin.grid.comm is double.grid.comm
    assert twin.rms_height == pytest.approx(double.rms_height, rel=1e-6)
    assert twin.rms_slope == pytest.approx(double.rms_slope, rel=1e-6)


def test_refusals_name_what_is_not_solved(comm):
    double = rough(comm, shape=(64, 64))
    single = rough(comm, "single", shape=(64, 64))
    sticky = double.with_interaction(ExponentialAdhesion(0.01, 1.0))
    with pytest.raises(ValueError, match="precision 'mixed' is for non-adhesive"):
        solve(sticky, Load(0.004), precision="mixed")
    with pytest.raises(ValueError, match="precision 'single' on a double-precision grid"):
        solve(double, Load(0.004), precision="single")
    with pytest.raises(ValueError, match="precision 'mixed' on a single-precision grid"):
        solve(single, Load(0.004), precision="mixed")
    with pytest.raises(ValueError, match="bncg"):
        solve(single, Load(0.004), solver="bncg", tolerance=1e-5)
    with pytest.raises(ValueError, match="precision 'half' is not one of"):
        solve(double, Load(0.004), precision="half")
    # below single precision's floor: said up front, with the floor and what to do,
    # not found out by a solve that stalls on round-off
    with pytest.raises(ValueError, match=r"tolerance 1e-08 is below what single precision "
                                         r"resolves.*>= 3e-06 .*\"mixed\""):
        solve(single, Load(0.004), tolerance=1e-8)
    # no tolerance given: the floor, reached
    at_floor = solve(single, Load(0.004))
    assert at_floor.converged and at_floor.kkt_gap <= SINGLE_TOLERANCE_FLOOR


def test_adhesion_refuses_single_and_mixed_with_the_reason(comm):
    """Adhesion is solved in double only, and the refusal says why and where it is measured
    (docs/accuracy.md), on every rank, for both precisions and both controls."""
    sticky = rough(comm, shape=(64, 64)).with_interaction(ExponentialAdhesion(0.01, 1.0))
    single = rough(comm, "single", shape=(64, 64)).with_interaction(
        ExponentialAdhesion(0.01, 1.0))
    reason = (r"is for non-adhesive contact: adhesion is solved in double only\..*K \(g \+ h\)"
              r".*docs/accuracy\.md.*\(here: an adhesive interaction\); allowed: double")
    for control in (Load(0.004), MeanGap(0.5)):
        with pytest.raises(ValueError, match=r"precision 'mixed' " + reason):
            solve(sticky, control, precision="mixed")
        with pytest.raises(ValueError, match=r"precision 'single' " + reason):
            solve(single, control)
