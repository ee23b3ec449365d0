"""Where a cold gap solve starts (petgap.solvers.gap_start), and adhesive load control.

* a cold solve on a 512^2 periodic cell starts from the same solve on 256^2, and
  reaches the state of the solve from the rigid approach (``-petgap_coarse_start
  0``) to the tolerance's reach, under mean gap and under load, for ``w`` giving
  1/kappa_att about 0.8 and 1.5, with fewer fine
  iterations; the same state on 1 rank and on ``comm`` to round-off;
* the prolonged start keeps the fine roughness: the start's ``g + h`` is the
  coarse level's repeated over each block, except that with adhesion the blocks at
  the wall on the coarse level start at the wall;
* a sticky solve under load (1/kappa_att about 1.5) in few iterations from there;
* adhesive load control is one gap solve; past pull-off it ends with
  ``load_not_reached`` within a few iterations of losing the last contact, not
  at its iteration limit.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import ExponentialAdhesion
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers import coarse
from petgap.solvers.dispatch import solve
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers.gap_start import MIN_SIDE, coarse_start_gap
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine

TOL = 1e-9


def sticky(grid, work=0.15):
    """The GUIDE surface (lambda_min = 32 a0, rms slope 0.1) with w on the sticky side."""
    h = self_affine(grid, 0.8, 32 * grid.dx, grid.Lx / 2, rms_slope=0.1, seed=7)
    hard = ContactProblem(grid, h, ElasticHalfSpace(grid, 1.0))
    return hard, hard.with_interaction(ExponentialAdhesion(work * grid.dx, 4 * grid.dx))


def reach(problem):
    """How far two states converged to TOL may lie apart: gap, pressure (test_adhesion)."""
    gap = 2 * TOL * max(problem.rms_slope * problem.grid.Lx / math.pi, problem.rms_height)
    return gap, 2 * TOL * problem.pressure_scale


def gmax(grid, field):
    return grid.comm.allreduce(float(np.max(np.abs(field))), op=MPI.MAX)


@pytest.mark.parametrize("work", [0.15, 0.3])
@pytest.mark.parametrize("control", ["mean-gap", "load"])
def test_coarse_start_reaches_the_same_state_in_fewer_iterations(comm, control, work):
    grid = Grid((512, 512), size=(512.0, 512.0), comm=comm, planner="estimate")
    hard, problem = sticky(grid, work)
    if control == "mean-gap":
        target = MeanGap(solve(hard, Load(0.002), tolerance=1e-8).mean_gap)
    else:
        target = Load(0.002)
    nested = gap_cg(problem, target, SolverSettings(tolerance=TOL))
    rigid = gap_cg(problem, target, SolverSettings(tolerance=TOL, coarse_start=False))
    assert nested.converged and rigid.converged, (nested.reason, rigid.reason)
    assert nested.start.startswith(f"coarse {MIN_SIDE}x{MIN_SIDE}")
    assert not rigid.start.startswith("coarse")
    assert nested.iterations < rigid.iterations
    gap_reach, pressure_reach = reach(problem)
    assert gmax(grid, nested.gap - rigid.gap) <= gap_reach
    assert gmax(grid, nested.pressure - rigid.pressure) <= pressure_reach
    differ = grid.comm.allreduce(int(np.count_nonzero((nested.gap <= 0) != (rigid.gap <= 0))))
    assert differ == 0
    # the same state on one rank, to round-off
    one = Grid((512, 512), size=(512.0, 512.0), comm=MPI.COMM_SELF, planner="estimate")
    alone = gap_cg(sticky(one, work)[1], target, SolverSettings(tolerance=TOL))
    rows = grid.x_slice
    assert np.max(np.abs(alone.gap[rows] - nested.gap)) <= 1e-10 * problem.rms_height
    assert alone.iterations == nested.iterations


def test_the_start_is_the_coarse_deformed_surface_over_the_fine_roughness(comm):
    grid = Grid((512, 512), size=(512.0, 512.0), comm=comm, planner="estimate")
    problem = sticky(grid)[1]
    target = MeanGap(0.5 * problem.rms_height)
    levels = []

    def level(p, c, s):
        levels.append(gap_cg(p, c, s.but(coarse_start=False)))
        return levels[-1]

    gap, description = coarse_start_gap(problem, target, SolverSettings(tolerance=TOL), level)
    gap = gap.copy()
    coarse_level = coarse.coarse_problem(problem, precision="double", scales=problem.scales)
    smooth = levels[0].gap + coarse_level.topography
    first, whole = coarse_level.grid.x_slice.start, coarse.is_whole(grid, coarse_level.grid)
    expected = coarse.prolong(first, grid, smooth, 2, whole) - problem.topography
    wall = coarse.prolong(first, grid, (levels[0].gap <= 0).astype(float), 2, whole) > 0.5
    assert description.startswith("coarse 256x256")
    assert levels[0].gap.shape[1] == 256 and len(levels) == 1
    assert grid.comm.allreduce(int(np.count_nonzero(wall))) > 0
    assert np.all(gap[wall] == 0.0)
    assert np.max(np.abs(gap[~wall] - expected[~wall])) <= 1e-12 * problem.rms_height


def test_sticky_load_from_the_coarse_contact_in_few_iterations(comm):
    """1/kappa_att about 1.5 under load: from the coarse level's contact patches, closed, the
    fine solve does not first overfill them and release the excess an edge pixel at a time
    (22 iterations from the prolonged ``g + h``; 18 from the closed patches)."""
    grid = Grid((512, 512), size=(512.0, 512.0), comm=comm, planner="estimate")
    problem = sticky(grid, work=0.3)[1]
    s = gap_cg(problem, Load(0.002), SolverSettings(tolerance=TOL))
    assert s.converged and s.start.startswith("coarse 256x256"), (s.reason, s.start)
    assert s.iterations <= 20


def test_pull_off_under_load_ends_early(comm):
    """A tension no state of the branch carries: the surfaces separate and the solve says
    so soon after, far inside its limit, with the load the separated state carries."""
    grid = Grid((128, 128), size=(128.0, 128.0), comm=comm, planner="estimate")
    hard, problem = sticky(grid, work=0.05)
    law = problem.interaction
    strongest = law.work / law.range          # v'(0): no pixel pulls harder
    tension = Load(-1.5 * strongest)           # beyond what every pixel at the wall holds
    limit = 2000
    s = solve(problem, tension, tolerance=1e-8, max_iterations=limit)
    assert not s.converged and s.reason == "load_not_reached"
    assert s.iterations < limit // 4
    assert grid.comm.allreduce(int(np.count_nonzero(s.gap <= 0))) == 0
    assert abs(s.mean_pressure - tension.mean_pressure) > 1e-8 * problem.pressure_scale
