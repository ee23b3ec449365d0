"""The contact-edge term of the pressure solver's preconditioner (petgap.solvers.edge_correction).

``kappa = K 1_S`` is checked against a NumPy transform of the gathered mask,
after a transform and after windowed updates (points entering and leaving S
near slab boundaries and across the periodic wrap, so that under ``mpirun -n
2`` the windows reach into the other rank's rows); the solver with the
correction must reach the state the plain preconditioner reaches, in fewer
iterations, and fall back to the plain preconditioner where the correction is
not positive.
"""
import contextlib
import logging

import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers.dispatch import solve
from petgap.solvers.edge_correction import WINDOW, EdgeCorrection, kernel_window
from petgap.solvers.mixed_precision import solve_mixed
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine
from test_contact import E_STAR, assert_same_state, max_abs, tolerance_scales

SIZE = (3.0, 2.0)   # rectangular pixels: dx = 3 / nx, dy = 2 / ny


def numpy_stiffness(field, size, modulus=E_STAR):
    """``K field`` by NumPy: symbol ``E* |q| / 2``, the q = 0 mode dropped."""
    nx, ny = field.shape
    qx = 2 * np.pi * np.fft.fftfreq(nx, d=size[0] / nx)
    qy = 2 * np.pi * np.fft.rfftfreq(ny, d=size[1] / ny)
    q = np.hypot(qx[:, None], qy[None, :])
    return np.fft.irfft2(np.fft.rfft2(field) * modulus * q / 2, s=field.shape)


def random_mask(shape, seed, fraction=0.1):
    return (np.random.default_rng(seed).random(shape) < fraction).astype(np.uint8)


@pytest.mark.parametrize("shape", [(64, 48), (45, 64), (600, 400)])
def test_the_window_is_the_stiffness_of_one_point(shape):
    """The half-space's own operator on a delta: exact where the grid is at most
    256 points a side (odd sides too); within 3e-4 of K(0) beyond."""
    grid = Grid(shape, size=SIZE, comm=MPI.COMM_SELF, planner="estimate", wisdom=False)
    table = kernel_window(grid, E_STAR)
    w = table.shape[0] // 2
    assert table.shape == (2 * WINDOW + 1,) * 2
    delta = np.zeros(shape)
    delta[0, 0] = 1.0
    exact = ElasticHalfSpace(grid, E_STAR).pressure(delta)
    rows, cols = np.arange(-w, w + 1) % shape[0], np.arange(-w, w + 1) % shape[1]
    error = np.abs(table - exact[np.ix_(rows, cols)]).max() / exact[0, 0]
    assert error <= (1e-12 if max(shape) <= 256 else 3e-4)


def test_the_window_fits_a_small_grid():
    grid = Grid((32, 12), comm=MPI.COMM_SELF, planner="estimate", wisdom=False)
    assert kernel_window(grid, E_STAR).shape == (11, 11)   # 2 W + 1 <= 12


@pytest.mark.parametrize("precision, tol", [("double", 1e-12), ("single", 2e-6)])
def test_kappa_follows_the_mask(comm, precision, tol):
    """A transform, then windows for a few changes, then a transform for many."""
    shape = (320, 256)   # room for 141 windows before a transform is cheaper
    grid = Grid(shape, size=SIZE, comm=comm, planner="estimate", precision=precision)
    half_space = ElasticHalfSpace(grid, E_STAR)
    full = random_mask(shape, 1)
    mask = grid.local_part(full).copy()
    edge = EdgeCorrection(half_space, mask, theta=0.5)
    edge.update()
    delta = np.zeros(shape)
    delta[0, 0] = 1.0
    kernel = numpy_stiffness(delta, SIZE)
    unit = kernel[0, 0]   # K(0): the scale of kappa
    assert edge.transforms == 1
    assert max_abs(grid, edge.kappa - grid.local_part(numpy_stiffness(full, SIZE))) <= tol * unit

    # a few points flip, by rank boundaries and across the periodic wrap of both axes
    middle = grid.nx // 2   # the boundary between two ranks' slabs
    changed = [(0, 0), (0, 255), (319, 40), (middle - 1, 3), (middle, 60), (147, 41), (2, 250)]
    for i, j in changed:
        full[i, j] ^= 1
    np.copyto(mask, grid.local_part(full))
    edge.update()
    assert edge.transforms == 1   # windows, no transform
    exact = grid.local_part(numpy_stiffness(full, SIZE))
    # what the windows leave out: each changed point's kernel beyond W pixels
    far = np.ones(shape, dtype=bool)
    far[np.ix_(np.arange(-WINDOW, WINDOW + 1) % shape[0],
               np.arange(-WINDOW, WINDOW + 1) % shape[1])] = False
    bound = len(changed) * np.abs(kernel[far]).max() + tol * unit
    error = max_abs(grid, edge.kappa - exact)
    assert 0 < error <= bound

    # many changes: the transform again, exact
    full = random_mask(shape, 2)
    np.copyto(mask, grid.local_part(full))
    edge.update()
    assert edge.transforms == 2
    assert max_abs(grid, edge.kappa - grid.local_part(numpy_stiffness(full, SIZE))) <= tol * unit


def test_kappa_does_not_depend_on_the_ranks(comm):
    """Windows applied on two ranks give the one-rank field to round-off."""
    shape = (256, 160)
    full = random_mask(shape, 3)
    later = full.copy()
    later[[0, 127, 128, 255, 10], [0, 5, 159, 20, 10]] ^= 1
    last = later.copy()
    last[[40, 50, 60], [7, 80, 150]] ^= 1   # all in the first half's rows, beyond W of its ends
    fields = []
    for c in (comm, MPI.COMM_SELF):
        grid = Grid(shape, comm=c, planner="estimate")
        mask = grid.local_part(full).copy()
        edge = EdgeCorrection(ElasticHalfSpace(grid, E_STAR), mask)
        edge.update()
        for step in (later, last):   # on two ranks, the second reaches one rank only
            np.copyto(mask, grid.local_part(step))
            edge.update()
        assert edge.transforms == 1
        fields.append((grid, edge.kappa))
    (grid, kappa), (_, whole) = fields
    assert max_abs(grid, kappa - grid.local_part(whole)) <= 1e-13


def test_the_correction_is_theta_kappa_g(comm):
    grid = Grid((40, 30), comm=comm, planner="estimate")
    full = random_mask(grid.shape, 4)
    mask = grid.local_part(full).copy()
    edge = EdgeCorrection(ElasticHalfSpace(grid, E_STAR), mask, theta=0.6)
    idx = np.flatnonzero(mask).astype(np.int32)
    rng = np.random.default_rng(5 + comm.rank)
    z, g = rng.standard_normal(len(idx)), rng.standard_normal(len(idx))
    kappa = grid.local_part(numpy_stiffness(full, (grid.Lx, grid.Ly)))
    expected = z - 0.6 * kappa.ravel()[idx] * g
    sums = edge.sums(g, idx)
    edge.subtract(z, g, idx)
    assert max_abs(grid, z - expected) <= 1e-12
    scale = np.abs(kappa).max() * (1 + np.abs(g).max()) ** 2 * len(idx)
    assert abs(sums[0] - np.dot(kappa.ravel()[idx], g)) <= 1e-12 * scale
    assert abs(sums[1] - np.dot(kappa.ravel()[idx], g * g)) <= 1e-12 * scale


@contextlib.contextmanager
def solver_notices():
    """The records petgap's logger emits inside the block, at level INFO and up.

    Taken on petgap's own logger: once set up for a run it does not propagate
    to pytest's.
    """
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    logger = logging.getLogger("petgap")
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield records
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def benchmark_problem(comm, n=256, seed=1):
    grid = Grid((n, n), comm=comm, planner="estimate")
    h = self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=seed)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR))


@pytest.mark.parametrize("control", ["load", "mean-gap"])
def test_the_corrected_preconditioner_reaches_the_same_state_sooner(comm, control):
    problem = benchmark_problem(comm)
    control = (Load(0.002 * 0.1 * E_STAR) if control == "load"
               else MeanGap(0.5 * problem.rms_height))
    plain = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, edge_correction=0.0))
    assert_same_state_sooner(problem, plain, polonsky_keer(problem, control, SolverSettings(tolerance=1e-9)), 1e-9)


def assert_same_state_sooner(problem, without, with_term, tol):
    """A preconditioner's term took fewer iterations to the state reached without it."""
    assert without.converged and with_term.converged
    assert with_term.iterations < without.iterations
    # the same contact set but for points at the edge with pressure and gap within tolerance
    comm = problem.grid.comm
    differ = comm.allreduce(int(np.count_nonzero((without.pressure > 0)
                                                 ^ (with_term.pressure > 0))))
    assert differ <= 1e-3 * comm.allreduce(int(np.count_nonzero(without.pressure > 0)))
    assert_same_state(problem.grid, without, with_term, *tolerance_scales(problem, tol))


def test_the_option_reaches_the_solver(comm):
    problem = benchmark_problem(comm, n=128)
    control = Load(0.002 * 0.1 * E_STAR)
    default = solve(problem, control, solver="pcg-pressure", tolerance=1e-8)
    plain = solve(problem, control, solver="pcg-pressure", tolerance=1e-8,
                  options={"petgap_edge_correction": "0"})
    direct = polonsky_keer(problem, control, SolverSettings(tolerance=1e-8, edge_correction=0.0))
    assert plain.iterations == direct.iterations != default.iterations


def test_the_option_reaches_the_mixed_solve(comm):
    """Both of its solves, the single one and the double refinement."""
    problem = benchmark_problem(comm, n=128)
    control = Load(0.002 * 0.1 * E_STAR)
    default = solve(problem, control, tolerance=1e-8, precision="mixed")
    plain = solve(problem, control, tolerance=1e-8, precision="mixed",
                  options={"petgap_edge_correction": "0"})
    direct = solve_mixed(problem, control, SolverSettings(tolerance=1e-8, edge_correction=0.0, search_precision="single"))
    assert plain.iterations == direct.iterations != default.iterations
    assert plain.start == direct.start


@pytest.mark.parametrize("theta", [-0.1, 1.0, float("nan")])
def test_a_share_outside_zero_to_one_is_refused(comm, theta):
    problem = benchmark_problem(comm, n=64)
    with pytest.raises(ValueError, match=r"edge_correction = .* is not allowed.*\[0, 1\)"):
        polonsky_keer(problem, Load(0.001), SolverSettings(edge_correction=theta))


def test_a_correction_that_is_not_positive_is_dropped(comm, monkeypatch):
    """Made to look negative on the gap, the correction is never applied: the plain solve."""
    problem = benchmark_problem(comm, n=128)
    control = Load(0.002 * 0.1 * E_STAR)
    plain = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, edge_correction=0.0))
    original = EdgeCorrection.sums

    def overdone(self, gS, idx):
        sum_kg, sum_kgg = original(self, gS, idx)
        return sum_kg, 1e6 * sum_kgg   # theta sum kappa g^2 far above (g, K g)

    monkeypatch.setattr(EdgeCorrection, "sums", overdone)
    with solver_notices() as records:
        dropped = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False))
        plain = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9, coarse_start=False, edge_correction=0.0))
    assert dropped.converged
    assert sum("going on without it" in r.getMessage() for r in records) == 1
    # dropped at its first preconditioned iteration: the plain solve, step for step
    assert dropped.iterations == plain.iterations
    np.testing.assert_allclose(dropped.history, plain.history, rtol=1e-10)
    assert max_abs(problem.grid, dropped.pressure - plain.pressure) == 0
