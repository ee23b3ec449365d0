"""The patch interaction of the pressure solver's preconditioner (petgap.solvers.patch_interaction).

The block sums and the subtraction are checked against NumPy on the gathered
fields, on a grid whose blocks do not divide it evenly and whose slab boundary
cuts through a block under ``mpirun -n 2``; the coarse solve against a dense
solve of ``(F^{-1} + D) y = w`` built from the compliance's symbol; the solver
with the interaction must reach the state it reaches without, in fewer
iterations, on any number of ranks, go on without the term where it is not
positive, and withdraw it after a step that raised the residual; beyond
``MAX_SIDE`` blocks a side the coarse grid is clamped.
"""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.free_half_space import FreeHalfSpace, influence_coefficients
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Indentation, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers import _contact_set as _cs
from petgap.solvers import patch_interaction as patch_interaction_module
from petgap.solvers import preconditioners
from petgap.solvers.dispatch import solve
from petgap.solvers.mixed_precision import solve_mixed
from petgap.solvers.patch_interaction import (FREE_MIN_SIDE, MAX_SIDE, MIN_SIDE,
                                              PatchInteraction, blocks, patch_interaction)
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine
from test_contact import E_STAR, assert_same_state, max_abs, tolerance_scales
from test_edge_correction import assert_same_state_sooner, solver_notices

SIZE = (3.0, 2.0)   # rectangular pixels


def block_of(shape, m):
    """Each point's block ``(I, J)`` as a flat index ``I my + J``, by NumPy."""
    (nx, ny), (mx, my) = shape, m
    rows = np.arange(nx) * mx // nx
    cols = np.arange(ny) * my // ny
    return rows[:, None] * my + cols[None, :]


def gathered_set(grid, full_mask):
    """This rank's indices of the mask's points (into its unpadded slab)."""
    return np.flatnonzero(grid.local_part(full_mask)).astype(np.int32)


@pytest.mark.parametrize("precision, tol", [("double", 1e-13), ("single", 1e-6)])
def test_block_sums_and_subtraction(comm, precision, tol):
    shape = (70, 45)   # blocks of 8: 8 x 5 blocks of 8-9 rows and 9 columns
    grid = Grid(shape, size=SIZE, comm=comm, planner="estimate", precision=precision)
    rng = np.random.default_rng(7)
    full_mask = rng.random(shape) < 0.3
    full_kappa = rng.random(shape) + 0.5
    full_g = rng.standard_normal(shape)
    full_z = rng.standard_normal(shape)
    far = PatchInteraction(grid, E_STAR, theta=0.6, block=8)
    assert (far.mx, far.my) == (8, 5)
    idx = gathered_set(grid, full_mask)
    dtype = grid.dtype
    kappa = grid.local_part(full_kappa).astype(dtype)
    gS = grid.local_part(full_g).ravel()[idx].astype(dtype)
    w, d = far.sums(gS, kappa, idx)
    b = block_of(shape, (8, 5))
    expected_w = 0.4 * np.bincount(b[full_mask], (full_kappa * full_g)[full_mask], minlength=40)
    expected_d = 0.4 * np.bincount(b[full_mask], full_kappa[full_mask], minlength=40)
    assert np.abs(w - expected_w).max() <= tol * np.abs(expected_w).max()
    assert np.abs(d - expected_d).max() <= tol * expected_d.max()

    y = rng.standard_normal(40)
    zS = grid.local_part(full_z).ravel()[idx].astype(dtype)
    far.subtract(zS, kappa, idx, y)
    expected = full_z - 0.4 * full_kappa * y[b]
    assert max_abs(grid, zS - grid.local_part(expected).ravel()[idx]) <= tol * 10


def test_the_kernels_refuse_mixed_precisions():
    idx = np.arange(3, dtype=np.int32)
    with pytest.raises(TypeError, match=r"block_sums: .*gS float32, kappa float64"):
        _cs.block_sums(np.zeros(3, np.float32), np.zeros((1, 3)), idx, 0, 1, 3, 1, 1,
                       np.zeros(1), np.zeros(1))


def dense_compliance(m, size, modulus, cell):
    """The coarse compliance ``F`` as a dense matrix, column by column from its symbol."""
    mx, my = m
    qx = 2 * np.pi * np.fft.fftfreq(mx, d=size[0] / mx)
    qy = 2 * np.pi * np.fft.fftfreq(my, d=size[1] / my)
    q = np.hypot(qx[:, None], qy[None, :])
    symbol = np.where(q > 0, 2 / (modulus * np.where(q > 0, q, 1) * cell), 0.0)
    columns = []
    for k in range(mx * my):
        e = np.zeros(mx * my)
        e[k] = 1
        columns.append(np.fft.ifft2(np.fft.fft2(e.reshape(m)) * symbol).real.ravel())
    return np.array(columns).T


def test_the_coarse_solve_is_the_woodbury_middle(comm):
    """``y = F (I + D F)^{-1} w``, i.e. ``(F^{-1} + D) y = w`` off F's null space."""
    grid = Grid((96, 60), size=SIZE, comm=comm, planner="estimate")
    far = PatchInteraction(grid, E_STAR, theta=0.6, block=12)
    m = (far.mx, far.my)
    assert m == (8, 5)
    rng = np.random.default_rng(11)
    w, d = rng.standard_normal(40), rng.random(40) * 50
    f = dense_compliance(m, SIZE, E_STAR, cell=(96 / 8) * (60 / 5))
    expected = f @ np.linalg.solve(np.eye(40) + np.diag(d) @ f, w)
    y = far.solve(w, d)
    assert np.abs(y - expected).max() <= 1e-5 * np.abs(expected).max()   # INNER_TOLERANCE 1e-6
    assert far.inner_iterations > 0


def test_the_free_coarse_solve_is_the_free_maps(comm):
    """On a free map, ``(F^{-1} + D) y = w`` with ``F`` Love's block compliance over the
    map's blocks alone (a dense direct sum, no transform, no images)."""
    grid = Grid((96, 60), size=SIZE, comm=comm, planner="estimate")
    far = PatchInteraction(grid, E_STAR, theta=0.6, block=12, periodic=False)
    mx, my = far.mx, far.my
    bx, by = SIZE[0] / mx, SIZE[1] / my
    i, j = np.meshgrid(np.arange(mx), np.arange(my), indexing="ij")
    f = influence_coefficients((i.ravel()[:, None] - i.ravel()[None, :]) * bx,
                               (j.ravel()[:, None] - j.ravel()[None, :]) * by, bx, by,
                               E_STAR) / far.block_area
    rng = np.random.default_rng(12)
    w, d = rng.standard_normal(mx * my), rng.random(mx * my) * 50
    expected = np.linalg.solve(np.linalg.inv(f) + np.diag(d), w)
    y = far.solve(w, d)
    assert np.abs(y - expected).max() <= 1e-5 * np.abs(expected).max()
    assert patch_interaction(FreeHalfSpace(Grid((1024, 1024), comm=comm, planner="estimate")),
                             0.6).shape == (64, 64)


def test_no_interaction_where_it_does_not_apply(comm):
    small = Grid((960, 1200), comm=comm, planner="estimate")
    assert MIN_SIDE * 32 > 960
    assert patch_interaction(ElasticHalfSpace(small, E_STAR), 0.6) is None  # 30 blocks a side
    assert patch_interaction(ElasticHalfSpace(small, E_STAR), 0.6, block=30) is not None
    assert patch_interaction(ElasticHalfSpace(small, E_STAR), 0.6, block=0) is None
    # a free map's term carries its mean mode too: made from FREE_MIN_SIDE blocks
    assert FREE_MIN_SIDE < MIN_SIDE
    assert patch_interaction(FreeHalfSpace(small, E_STAR), 0.6).shape == (60, 74)
    smaller = Grid((FREE_MIN_SIDE * 32 - 32, 1200), comm=comm, planner="estimate")
    assert patch_interaction(FreeHalfSpace(smaller, E_STAR), 0.6) is None
    # beyond MAX_SIDE blocks along a side the blocks grow: the coarse grid stays that small
    assert 1200 // 4 == 300 > MAX_SIDE and blocks(1200, 4) == MAX_SIDE
    far = patch_interaction(ElasticHalfSpace(small, E_STAR), 0.6, block=4)
    assert (far.mx, far.my) == (240, MAX_SIDE)


def benchmark_problem(comm, n=1024, seed=1):
    grid = Grid((n, n), comm=comm, planner="estimate")
    h = self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=seed)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR))


def test_the_interaction_reaches_the_same_state_sooner(comm):
    """Fewer iterations on a grid of 1024^2 (32 blocks a side), the same state."""
    problem = benchmark_problem(comm)
    control = Load(0.002 * 0.1 * E_STAR)
    local = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, interaction_block=0))
    assert_same_state_sooner(problem, local, polonsky_keer(problem, control, SolverSettings(tolerance=1e-9)),
                             1e-9)


@pytest.mark.parametrize("n, control", [(1024, "load"), (1024, "indentation"),
                                        (512, "indentation")])
def test_the_free_interaction_reaches_the_same_state_sooner(comm, n, control):
    """On a free map of 1024^2 (32 blocks a side), under load and under indentation; on
    one of 512^2 (16 blocks, :data:`FREE_MIN_SIDE`) under indentation, whose mean mode
    the local stiffness does not see."""
    grid = Grid((n, n), comm=comm, planner="estimate")
    h = self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    problem = ContactProblem(grid, h, FreeHalfSpace(grid, E_STAR))
    control = (Load(0.002 * 0.1 * E_STAR) if control == "load"
               else Indentation(problem.top_height - problem.mean_height))
    local = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, interaction_block=0))
    far = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9))
    assert_same_state_sooner(problem, local, far, 1e-9)


def test_no_interaction_under_mean_gap_control(comm):
    """Where it took more iterations than it saved: the solve without it, step for step."""
    problem = benchmark_problem(comm)
    control = MeanGap(0.5 * problem.rms_height)
    default = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9))
    local = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, interaction_block=0))
    assert default.converged
    assert list(default.history) == list(local.history)


def test_the_interaction_does_not_depend_on_the_ranks(comm):
    """Decompositions only reorder sums: agreement to 1e-12 of the natural scales."""
    serial, problem = benchmark_problem(MPI.COMM_SELF), benchmark_problem(comm)
    control = Load(0.002 * 0.1 * E_STAR)
    one = polonsky_keer(serial, control, SolverSettings(tolerance=1e-10))
    many = polonsky_keer(problem, control, SolverSettings(tolerance=1e-10))
    assert one.converged and many.converged
    assert many.iterations == one.iterations
    grid = problem.grid
    assert max_abs(grid, many.gap - one.gap[grid.x_slice]) <= 1e-12 * problem.gap_scale
    assert (max_abs(grid, many.pressure - one.pressure[grid.x_slice])
            <= 1e-12 * problem.pressure_scale)


def test_the_option_reaches_the_solvers(comm):
    problem = benchmark_problem(comm)
    control = Load(0.002 * 0.1 * E_STAR)
    default = solve(problem, control, solver="pcg-pressure", tolerance=1e-8)
    off = solve(problem, control, solver="pcg-pressure", tolerance=1e-8,
                options={"petgap_interaction_block": "0"})
    direct = polonsky_keer(problem, control, SolverSettings(tolerance=1e-8, interaction_block=0))
    assert list(off.history) == list(direct.history) != list(default.history)
    mixed = solve(problem, control, tolerance=1e-8, precision="mixed",
                  options={"petgap_interaction_block": "0"})
    mixed_direct = solve_mixed(problem, control, SolverSettings(tolerance=1e-8, interaction_block=0, search_precision="single"))
    assert mixed.start == mixed_direct.start
    assert list(mixed.history) == list(mixed_direct.history)


@pytest.mark.parametrize("block", [-1, 2.5])
def test_a_block_that_is_not_a_whole_number_is_refused(comm, block):
    problem = benchmark_problem(comm, n=64)
    with pytest.raises(ValueError, match=rf"interaction_block = {block} is not allowed"):
        polonsky_keer(problem, Load(0.001), SolverSettings(interaction_block=block))


def assert_dropped_once(problem, control, notice):
    """Solved cold with the term made to fail: converged, ``notice`` logged once, and the
    state of the solve without the term."""
    with solver_notices() as records:
        dropped = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False))
    local = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False, interaction_block=0))
    assert dropped.converged
    assert sum(notice in r.getMessage() for r in records) == 1
    assert_same_state(problem.grid, local, dropped, *tolerance_scales(problem, 1e-9))


def test_an_interaction_that_is_not_positive_is_dropped(comm, monkeypatch):
    """Made to look too large on the gap, the term is never applied: the solve without it."""
    original = PatchInteraction.solve
    monkeypatch.setattr(PatchInteraction, "solve",
                        lambda self, w, d: 1e6 * original(self, w, d))
    assert_dropped_once(benchmark_problem(comm), Load(0.002 * 0.1 * E_STAR),
                        "patch interaction of the preconditioner is not positive")


@pytest.mark.parametrize("block", [32, 64])
def test_a_step_after_which_the_residual_rose_withdraws_the_interaction(comm, monkeypatch,
                                                                       block):
    """Every step with the term made to count as a rise: it is withdrawn each time, let in
    again only after an iteration that changed ``WITHDRAWN_FACTOR`` times less of the set
    than the fraction that let it in before (at first ``SETTLED_FRACTION``, a quarter of it
    for blocks of 64 pixels), and the solve still reaches the state it reaches without the
    term."""
    monkeypatch.setattr(preconditioners, "RISE_FACTOR", 0.0)   # every residual "rose"
    monkeypatch.setattr(patch_interaction_module, "MIN_SIDE", 16)   # 64-pixel blocks at 1024^2
    problem = benchmark_problem(comm)
    control = Load(0.002 * 0.1 * E_STAR)
    with solver_notices() as records:
        withdrawn = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False, interaction_block=block))
    local = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False, interaction_block=0))
    notices = [r.getMessage() for r in records if "withdrawn until" in r.getMessage()]
    assert withdrawn.converged and len(notices) >= 2
    admitted = [float(m.split("changes at most ")[1].split()[0]) for m in notices]
    first = preconditioners.SETTLED_FRACTION * min(1.0, (32 / block) ** 2)
    expected = [first * preconditioners.WITHDRAWN_FACTOR ** (k + 1) for k in range(len(notices))]
    np.testing.assert_allclose(admitted, expected, rtol=1e-2)
    assert_same_state(problem.grid, local, withdrawn, *tolerance_scales(problem, 1e-9))


def test_a_rise_after_a_depth_move_withdraws_nothing():
    """A residual that rose after a step with the term withdraws it; one that rose after a
    move of the depth (``moved``) is the move's, and leaves the term and its admission."""
    admission = preconditioners.PatchAdmission(None)
    admission.used, admission.used_from = True, 1e-4
    assert admission.withdraws(5, 2e-4)
    assert admission.admit == pytest.approx(preconditioners.SETTLED_FRACTION
                                            * preconditioners.WITHDRAWN_FACTOR)
    admission = preconditioners.PatchAdmission(None)
    admission.used, admission.used_from = True, 1e-4
    admission.moved()
    assert not admission.withdraws(5, 2e-4)
    assert admission.admit == preconditioners.SETTLED_FRACTION


def test_larger_blocks_wait_for_a_more_settled_set(monkeypatch):
    """The admitted fraction scales with 32-pixel blocks' area over the blocks' own, grown
    blocks (beyond MAX_SIDE a side) included, and is never more than SETTLED_FRACTION."""
    grid = Grid((256, 192), comm=MPI.COMM_SELF, planner="estimate", wisdom=False)
    settled = preconditioners.SETTLED_FRACTION
    assert preconditioners.settled_fraction(None) == settled
    for block, area in [(16, 256), (32, 1024), (64, 4096)]:
        far = PatchInteraction(grid, E_STAR, 0.6, block)
        assert far.block_area == area
        assert preconditioners.settled_fraction(far.block_area) == pytest.approx(settled * min(1, 1024 / area))
    monkeypatch.setattr(patch_interaction_module, "MAX_SIDE", 4)   # 32-pixel blocks grow
    far = PatchInteraction(grid, E_STAR, 0.6, 32)
    assert (far.mx, far.my, far.block_area) == (4, 4, 64 * 48)
    assert preconditioners.settled_fraction(far.block_area) == pytest.approx(settled * 1024 / (64 * 48))
