"""The map's mean gap on a free map's padded cell (petgap.solvers.free_boundary): the rule
that moves the cell's target during one gap solve, its predictor, and the start the coarse
levels hand up (the cell target, and the slope measured on one level)."""
import numpy as np
import pytest

import petgap
from petgap.mechanics.free_half_space import FreeHalfSpace
from petgap.mechanics.problem import MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers import free_boundary
from petgap.solvers.free_boundary import MapMeanGap, cell_problem, first_cell_target, \
    map_mean, map_mean_gap
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers.settings import SolverSettings


class _Reads(MapMeanGap):
    """A rule whose map mean gap is read from a list, not from a cell's gap."""

    def __init__(self, reads, **kwargs):
        super().__init__(None, None, 1.0, 1.0, 1e-8, 0.0, log=False, **kwargs)
        self.reads = reads

    def map_mean(self, g):
        return self.reads.pop(0)


def _second_move_slope(slope_error, residual):
    """The slope the rule uses after two moves, the second read at ``residual``: the reads
    lie on a line of slope 0.3 through (0, 0), the target is 1."""
    rule = _Reads([0.0, 0.6], slope=0.5, slope_error=slope_error)
    g = np.ones(3)
    assert rule(g, 1e-6) == pytest.approx(2.0)      # (1 - 0) / 0.5
    rule(g, residual)
    return rule.slope


def test_a_secant_through_unsettled_reads_keeps_a_measured_slope():
    """Read at a residual of half the mean gap's change, the secant is known to 5 %: it
    does not replace a slope known to 3 %, it replaces the guess known to nothing; read at
    a small residual it replaces either."""
    assert _second_move_slope(0.03, residual=0.3) == 0.5
    assert _second_move_slope(1.0, residual=0.3) == pytest.approx(0.3)
    assert _second_move_slope(0.03, residual=1e-5) == pytest.approx(0.3)


def test_a_move_that_turns_back_leaves_the_wall_points_at_the_wall():
    """The predictor carries the gap along the last move's response, scaled to the new
    step; a second move that turns back scales it negative, which would lift the point
    the first move closed.  It stays at the wall; the free points follow the response."""
    rule = _Reads([])
    before = np.array([1.0, 0.5, 2.0])
    g = before.copy()
    rule._predict(g, 1.0)                      # the first move keeps the state before it
    g[:] = [0.0, 0.3, 2.5]                     # its response: the first point closed
    rule._predict(g, -0.5)
    np.testing.assert_allclose(g, [0.0, 0.3 + 0.1, 2.5 - 0.25])
    np.testing.assert_allclose(rule.before, [0.0, 0.3, 2.5])   # the state before the move


def _adhesive_map(comm, n=256, lambda_min=16.0, work=0.1, rho=2.0):
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, lambda_min, n / 2, rms_slope=0.1, seed=7)
    hard = petgap.ContactProblem(grid, h, FreeHalfSpace(grid))
    reference = petgap.solve(hard, petgap.Load(0.002))
    return hard.with_interaction(petgap.ExponentialAdhesion(work, rho)), reference.mean_gap


def test_a_level_hands_up_the_cell_target_of_its_maps_mean_gap(comm):
    """A coarse level stops at the coarse tolerance, its map's mean gap up to that far off
    the target; the cell target it hands up is corrected by what it read last, so that the
    cell at that target, solved tightly, has the map's mean gap to within 1e-5 h0 (the
    last read's error, where the level's own target left it 1.8e-4 h0 off)."""
    problem, target = _adhesive_map(comm, 128, 8.0, 0.05, 2.0)
    on_cell = cell_problem(problem)
    settings = SolverSettings(tolerance=1e-3)
    guess = first_cell_target(problem, on_cell, target)
    solution, rule = map_mean_gap(on_cell, problem.grid.shape, target, guess, settings,
                                  level=True)
    tight = gap_cg(on_cell, MeanGap(rule.cell_target), SolverSettings(tolerance=1e-9),
                   initial_gap=solution.gap)
    mean = map_mean(on_cell.grid, problem.grid.shape, tight.gap)
    assert tight.converged
    assert abs(mean - target) <= 1e-5 * problem.gap_scale


def test_the_fine_solve_moves_on_a_measured_slope_and_keeps_its_residual(comm, monkeypatch):
    """On a free adhesive map the slope is measured on a coarse level and known to
    SLOPE_SPREAD; the moves after the first raise the residual at most five-fold (the
    predictor lifting the points the first move closed raised it 125-fold at the second),
    and the map's mean gap is the target."""
    problem, target = _adhesive_map(comm)
    seen, call = [], MapMeanGap.__call__

    def traced(rule, g, residual):
        moved = call(rule, g, residual)
        if rule.cell.nx == 2 * problem.grid.nx:
            seen.append((residual, moved is not None))
        return moved
    monkeypatch.setattr(MapMeanGap, "__call__", traced)
    s = petgap.solve(problem, petgap.MeanGap(target))
    assert s.converged and abs(s.mean_gap - target) <= 1e-8 * problem.gap_scale
    assert s.cell_solution.map_rule.slope_error == free_boundary.SLOPE_SPREAD
    moves = [k for k, (_, moved) in enumerate(seen) if moved]
    assert len(moves) >= 2
    for k in moves[1:]:
        assert seen[k + 1][0] <= 5 * seen[k][0], (seen[k], seen[k + 1])


def test_a_settled_read_is_trusted_beyond_its_residual():
    """A read taken at a residual of half the mean gap's change is known to 5 %, but one
    that has stopped moving over the iteration before it is as sure as its change says: a
    secant through it replaces even a measured slope."""
    def second_slope(settled):
        reads = [0.0, 0.6, 0.6] if settled else [0.0, 0.5, 0.6]
        rule = _Reads(reads, slope=0.5, slope_error=0.03)
        g = np.ones(3)
        assert rule(g, 1e-6) == pytest.approx(2.0)
        assert rule(g, 2.0) is None                 # not yet: residual > 3 x error
        rule(g, 0.3)
        return rule.slope
    assert second_slope(settled=False) == 0.5
    assert second_slope(settled=True) == pytest.approx(0.3)


def test_the_fine_solve_starts_from_the_levels_cell_target_extrapolated(comm, monkeypatch):
    """The cell target that puts a level's map at the mean gap converges at second order
    with the grid; continued from the two levels below over TARGET_RATIO, it starts the
    512^2 map's fine solve at least four times nearer its final target than the level
    below's own target (27 times here)."""
    problem, target = _adhesive_map(comm, 512, 32.0, 0.15, 4.0)
    rules, init = [], MapMeanGap.__init__

    def kept(rule, *args, **kwargs):
        init(rule, *args, **kwargs)
        rules.append((rule, rule.cell_target))
    monkeypatch.setattr(MapMeanGap, "__init__", kept)
    s = petgap.solve(problem, petgap.MeanGap(target))
    assert s.converged and abs(s.mean_gap - target) <= 1e-8 * problem.gap_scale
    final = s.cell_solution.map_rule.cell_target
    (level, _), (_, start) = rules[-2:]
    assert len(level.levels) == 2
    assert abs(start - final) <= abs(level.levels[0] - final) / 4


def test_a_settled_read_moves_once_the_residual_is_below_the_moves_own_rise():
    """The rule moves at a residual of 5e-4 (not below 3 times the error of 1e-5) where the
    read did not change over the iteration before and a move would raise the residual to
    ``jump`` times the error, 1e-3; not where the read still moves, where the residual is
    above EARLY_RESIDUAL, or without a jump."""
    def moves(second_read, residual, jump):
        rule = _Reads([1.0 - 1e-5, second_read], jump=jump)
        g = np.ones(3)
        assert rule(g, residual) is None       # no read before it: not known to settle
        return rule(g, residual) is not None
    assert moves(1.0 - 1e-5, 5e-4, jump=100.0)
    assert not moves(1.0 - 2e-5, 5e-4, jump=100.0)            # the read moved
    assert not moves(1.0 - 1e-5, 2e-3, jump=1000.0)           # above EARLY_RESIDUAL
    assert not moves(1.0 - 1e-5, 5e-4, jump=0.0)
    assert _Reads([1.0 - 1e-5])(np.ones(3), 2e-5) is not None   # the forcing rule
