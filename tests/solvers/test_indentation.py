"""Mean-gap control on a free boundary through the indentation depth: the start the coarse
levels give (the rigid surface's place, extrapolated; the slope, measured) and the rule
that moves the depth."""
import numpy as np
import pytest

import petgap
from petgap.mechanics.free_half_space import FreeHalfSpace
from petgap.parallel.grid import Grid
from petgap.solvers import indentation
from petgap.solvers.indentation import DepthForMeanGap, _coarse_depth, measured_slope
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.indenters import indenter


class _Iterate:
    """What DepthForMeanGap reads of a pressure iterate: its offset and mean gap."""

    def __init__(self, offset, mean):
        self.offset, self.mean = offset, mean

    def mean_gap(self, projected=False):
        return self.mean


class _Problem:
    gap_scale, top_height = 1.0, 10.0


def _second_move_slope(slope_error, residual):
    """The slope the rule uses after two moves, the second read at ``residual``; the
    reads lie on a line of slope 0.3 through (0, 0), the target is 1."""
    rule = DepthForMeanGap(_Problem(), 1.0, 1e-8, slope=0.5, slope_error=slope_error,
                           log=False)
    first = rule(_Iterate(0.0, 0.0), 1e-6)
    rule(_Iterate(first, 0.3 * first), residual)
    return rule.slope


def test_a_secant_through_unsettled_reads_keeps_a_measured_slope():
    """The first move goes to offset 2, where the mean gap reads 0.6 (0.4 from the
    target).  Read there at a residual of half the mean gap's change, the secant is
    known to 5 %: it does not replace a slope known to 3 %, it replaces the rigid
    guess (known to nothing); read at a small residual it replaces either."""
    assert _second_move_slope(0.03, residual=0.3) == 0.5
    assert _second_move_slope(1.0, residual=0.3) == pytest.approx(0.3)
    assert _second_move_slope(0.03, residual=1e-5) == pytest.approx(0.3)


def test_the_measured_slope_of_a_sphere_is_hertz_over_the_map(comm):
    """A sphere's contact pressure adds ``F / (pi E* r)`` to the map's mean displacement,
    ``F 4 ln(1 + sqrt 2) / (pi E* L)`` for a contact small against the square map's
    side ``L``, and ``dF/dd = 2 a E*`` (Hertz): the mean gap falls with the depth at
    ``1 - 8 a ln(1 + sqrt 2) / (pi L)``.  At ``a = 10`` pixels on a 128^2 map the
    measured slope's distance from 1 is within 2 % of that (0.35 %)."""
    n, radius, depth = 128, 200.0, 0.5
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    problem = petgap.ContactProblem(grid, indenter(grid, "paraboloid", radius),
                                    FreeHalfSpace(grid))
    pressure = petgap.solve(problem, petgap.Indentation(depth)).pressure
    slope = measured_slope(problem, depth, pressure, SolverSettings())
    a = np.sqrt(radius * depth)
    expected = 1 - 8 * a * np.log(1 + np.sqrt(2)) / (np.pi * n)
    assert (1 - slope) / (1 - expected) == pytest.approx(1.0, abs=0.02)


def test_the_coarse_start_extrapolates_the_rigid_surfaces_place(comm):
    """On a rough 256^2 map the levels below put the rigid surface (``max(h) - d``) ever
    nearer the fine grid's; extrapolated, the start's mean-gap error is less than half
    the coarse level's own (a tenth here), and the slope the start carries, measured
    on the 32^2 level, is within 3 % of the fine grid's."""
    n = 256
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    problem = petgap.ContactProblem(grid, h, FreeHalfSpace(grid))
    control = petgap.MeanGap(petgap.solve(problem, petgap.Load(0.002)).mean_gap)
    fine = petgap.solve(problem, control, tolerance=1e-10)
    assert fine.converged
    start = _coarse_depth(problem, control, SolverSettings(), 0.0, n // 8)
    fine_offset = problem.top_height - fine.depth
    started = abs(problem.top_height - start.depth - fine_offset)
    coarse = abs(start.coarse_offsets[0] - fine_offset)
    assert started < 0.5 * coarse, (started, coarse)
    fine_slope = measured_slope(problem, fine.depth, fine.pressure, SolverSettings())
    assert start.slope == pytest.approx(fine_slope, rel=indentation.SLOPE_SPREAD)
