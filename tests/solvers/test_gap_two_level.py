"""The coarse term of the gap preconditioner (petgap.solvers.gap_two_level).

* the coarse compliance symbol is the Galerkin product ``R K^{-1} P`` of the
  bilinear hats, computed on the fine grid by a transform (to the weight of the
  aliases left out of the sum);
* the restriction and prolongation kernels are ``R = P^T / b^2`` and ``P`` of the
  hat matrices, on every rank's slab;
* ``P Fc R`` stays below ``K^{-1}`` (what keeps the preconditioner positive
  definite where the springs are), for cells of 2 to 16 pixels;
* the coarse system, solved on its fields' spectra, is solved: Parseval's
  inner product over the half plane and the solution against a dense solve, on
  even and odd coarse sides;
* the coarse grid is split over the ranks where they can split it, whole on every
  rank where not; split, the coarse system gives the correction and the eigenvalue
  estimate of the coarse system solved whole, to round-off;
* a two-level adhesive solve reaches the state of the default solver to the
  tolerance's reach, and the same state on 1 rank and on ``comm``;
* the springs on the contact set sum to the contact's stiffness ``1_C . K 1_C``;
* the Lanczos estimate of the coarse system's smallest eigenvalue is the dense one, and
  the softening's scale keeps that eigenvalue at the margin; on a sticky state it is
  below 1 and the solve takes fewer iterations than with the whole softening;
* the coarse cell is 8 pixels a side at every grid up to 8192^2, and the coarse
  solve's inner products survive a coarse grid that large.
"""
import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import ExponentialAdhesion
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers import _kernels as _k
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers import gap_two_level
from petgap.solvers.gap_two_level import (INNER_TOLERANCE, LANCZOS_TOLERANCE, MARGIN,
                                          CoarseTerm, block_for, coarse_compliance,
                                          coarse_grid, softening_for)
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine

from conftest import clean_env, wait_for_root

E_STAR = 2.5


def hats(n, b):
    """The dense ``(n, n // b)`` matrix of periodic hats of half-width ``b``."""
    x = np.arange(n)
    d = (x[:, None] - b * np.arange(n // b)[None, :] + n / 2) % n - n / 2
    return np.maximum(1 - np.abs(d) / b, 0.0)


def compliance(shape, size):
    """``K^{-1}`` on a serial periodic grid (symbol ``2 / (E* |q|)``, no mean)."""
    nx, ny = shape
    qx = 2 * np.pi * np.fft.fftfreq(nx, size[0] / nx)
    qy = 2 * np.pi * np.fft.rfftfreq(ny, size[1] / ny)
    q = np.hypot(qx[:, None], qy[None, :])
    symbol = np.where(q > 0, 2 / (E_STAR * np.where(q > 0, q, 1)), 0.0)
    return lambda f: np.fft.irfft2(np.fft.rfft2(f) * symbol, s=shape)


@pytest.mark.parametrize("shape, size, b", [((128, 96), (2.0, 1.5), 8), ((64, 64), (1.0, 1.0), 4)])
def test_coarse_compliance_is_the_galerkin_product(shape, size, b):
    inverse = compliance(shape, size)
    px, py = hats(shape[0], b), hats(shape[1], b)
    e0 = np.zeros((shape[0] // b, shape[1] // b))
    e0[0, 0] = 1.0
    column = px.T @ inverse(px @ e0 @ py.T) @ py / b ** 2
    exact = np.fft.rfft2(column).real
    symbol = coarse_compliance(shape, size, b, E_STAR)
    assert np.max(np.abs(symbol - exact)) <= 1e-4 * np.max(np.abs(exact))


@pytest.mark.parametrize("rows", [64, 72])
def test_transfer_kernels_are_the_hat_matrices(comm, rows):
    """The residual's pass writes the residual on the free set and restricts it, the free
    set's springs and the wall's counts by the hats' matrices; the prolongation, riding on
    the preconditioned residual's sums, is the hats' matrix.  On 2 ranks 72 rows split the
    coarse row of pixels 32-39 between the slabs, each of which restricts its part."""
    grid = Grid((rows, 48), size=(1.0, 0.75), comm=comm, planner="estimate")
    b, cs = 8, (rows // 8, 6)
    px, py = hats(rows, b), hats(48, b)
    rng = np.random.default_rng(1)
    pel_whole, vp_whole = rng.standard_normal((rows, 48)), -rng.random((rows, 48))
    g_whole = np.maximum(rng.standard_normal((rows, 48)), 0.0)   # about half at the wall
    y = rng.standard_normal(cs)
    lam_f, lam, divisor = 0.3, 0.2, 4.0
    pel, vp, g = (np.ascontiguousarray(f[grid.x_slice]) for f in (pel_whole, vp_whole, g_whole))
    local = np.zeros((3,) + cs)
    _k.coarse_residual(pel, g, vp, None, True, divisor, lam_f, lam, grid.padded,
                       grid.x_slice.start, b, local[0], local[1], local[2])
    comm.Allreduce(MPI.IN_PLACE, local)
    grad = pel_whole + vp_whole
    free = (g_whole > 0) | (grad + lam_f < 0)
    residual = np.where(free, grad + lam, 0.0)
    assert np.array_equal(grid.real, residual[grid.x_slice])
    scale = np.abs(residual).sum()
    assert np.allclose(local[1], px.T @ residual @ py, rtol=0, atol=1e-12 * scale)
    softening = np.where(g_whole > 0, -vp_whole / divisor, 0.0)
    assert np.allclose(local[0], px.T @ softening @ py, rtol=0, atol=1e-12 * scale)
    wall = (g_whole <= 0).reshape(cs[0], b, cs[1], b).sum(axis=(1, 3))
    assert np.array_equal(local[2], wall) and wall.min() > 0
    grid.real[...] = 0.0
    _k.gcg_precond_sums(grid.padded, pel, g, vp, True, lam_f, lam, y=y, x0=grid.x_slice.start,
                        b=b)
    assert np.allclose(-grid.real, (px @ y @ py.T)[grid.x_slice], rtol=0, atol=1e-12)


@pytest.mark.parametrize("b", [2, 4, 8, 16])
def test_coarse_term_stays_below_the_compliance(b):
    """Largest eigenvalue of ``K^{1/2} P Fc R K^{1/2}`` below 1 (power iteration)."""
    n = 128
    shape, size = (n, n), (float(n), float(n))
    q = np.hypot(2 * np.pi * np.fft.fftfreq(n)[:, None], 2 * np.pi * np.fft.rfftfreq(n)[None, :])
    half = np.sqrt(E_STAR * q / 2)
    root = lambda f: np.fft.irfft2(np.fft.rfft2(f) * half, s=shape)
    p1 = hats(n, b)
    symbol = coarse_compliance(shape, size, b, E_STAR)
    fc = lambda y: np.fft.irfft2(np.fft.rfft2(y) * symbol, s=y.shape)
    v = np.random.default_rng(2).standard_normal(shape)
    for _ in range(80):
        v = root(p1 @ fc(p1.T @ root(v) @ p1 / b ** 2) @ p1.T)
        largest = math.sqrt(np.sum(v * v))
        v /= largest
    assert largest < 1.0


def root_of(term):
    """``H = Fc^{1/2}`` of ``term``'s coarse grid on real fields, by NumPy (zero mean mode)."""
    grid, cs = term.grid, term.coarse_shape
    half = np.sqrt(coarse_compliance(grid.shape, (grid.Lx, grid.Ly), term.block, E_STAR))
    return lambda y: np.fft.irfft2(np.fft.rfft2(y) * half, s=cs)


def dense_system(term, springs):
    """``I + H W H`` of ``term``'s coarse grid as a dense matrix (real space)."""
    cs, root = term.coarse_shape, root_of(term)
    unit = np.eye(cs[0] * cs[1]).reshape((-1,) + cs)
    return np.array([(e + root(springs * root(e))).ravel() for e in unit]).T


@pytest.mark.parametrize("shape", [(128, 96), (80, 112)])
def test_coarse_system_is_solved_on_its_spectrum(shape):
    """``(I + H W H) v = b`` by the coarse term's conjugate gradients on the fields'
    spectra (FFTW's transposed half plane), against a dense solve; ``_dot`` is the
    real-space inner product (coarse sides 8 x 6 and 5 x 7: with and without a Nyquist
    row)."""
    term = CoarseTerm(Grid(shape, size=(1.0, 0.75), comm=MPI.COMM_SELF, planner="estimate"),
                      E_STAR, 16)
    cs = term.coarse_shape
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal(cs), rng.standard_normal(cs)
    dot = term._dot(term.spectrum(a), term.spectrum(b)) / a.size
    assert dot == pytest.approx(np.sum(a * b), rel=1e-13)
    assert np.allclose(term.space(term.spectrum(a)), a, rtol=0, atol=1e-14)
    springs = rng.uniform(0.0, 50.0, cs)
    v = term.space(term._solve(springs, term.spectrum(b)))
    exact = np.linalg.solve(dense_system(term, springs), b.ravel())
    assert np.max(np.abs(v.ravel() - exact)) <= 10 * INNER_TOLERANCE * np.max(np.abs(exact))
    assert term.inner_iterations > 1


def test_a_coarse_grid_is_split_where_the_ranks_can_split_it(comm, monkeypatch):
    """Above :data:`WHOLE_POINTS` the coarse grid lives on the fine grid's ranks, unless
    FFTW-MPI would leave a rank without a row: an 8 x 1 coarse grid has one Fourier row,
    which two ranks cannot share, and is solved whole on every rank."""
    monkeypatch.setattr(gap_two_level, "WHOLE_POINTS", 0)
    split = coarse_grid(Grid((64, 64), comm=comm, planner="estimate"), 8)
    assert split.shape == (8, 8) and split.comm.size == comm.size
    narrow = coarse_grid(Grid((64, 8), comm=comm, planner="estimate"), 8)
    assert narrow.shape == (8, 1) and narrow.comm.size == 1
    monkeypatch.setattr(gap_two_level, "WHOLE_POINTS", 64)
    assert coarse_grid(Grid((64, 64), comm=comm, planner="estimate"), 8).comm.size == 1


def test_the_coarse_system_split_over_the_ranks_is_the_whole_one(comm, monkeypatch):
    """With the coarse grid split over ``comm``'s ranks (every coarse grid, for the test),
    the correction gathered on every rank and the smallest eigenvalue's estimate are the
    whole system's (on ``MPI.COMM_SELF``) to round-off, with a softening that takes the
    unscaled system past zero; on 2 ranks the 12 coarse rows split 6 / 6, the 9 Fourier
    rows 5 / 4."""
    monkeypatch.setattr(gap_two_level, "WHOLE_POINTS", 0)
    shape, size, block = (96, 128), (1.0, 1.25), 8
    split = CoarseTerm(Grid(shape, size=size, comm=comm, planner="estimate"), E_STAR, block)
    whole = CoarseTerm(Grid(shape, size=size, comm=MPI.COMM_SELF, planner="estimate"),
                       E_STAR, block)
    assert split.cgrid.comm.size == comm.size and whole.cgrid.comm.size == 1
    contact, free = sticky_springs(whole, 20.0)
    rhs = np.random.default_rng(6).standard_normal(whole.coarse_shape)
    rows = split.cgrid.x_slice
    for term, part in ((whole, slice(None)), (split, rows)):
        term.contact = contact[part]
        term.form_springs(free[part], estimate=True)
        term.rhs = rhs[part]
    assert whole.softening < 1.0
    assert split.softening == pytest.approx(whole.softening, rel=1e-10)
    y_whole, y_split = whole.correction(), split.correction()
    assert y_split.shape == whole.coarse_shape
    assert np.max(np.abs(y_split - y_whole)) <= 1e-10 * np.max(np.abs(y_whole))
    assert split.inner_iterations == whole.inner_iterations


def sticky_springs(term, scale):
    """Contact springs (positive, on a few nodes) and a softening (negative, elsewhere)
    whose sum makes ``I + H W H`` indefinite for ``scale`` large enough."""
    rng = np.random.default_rng(5)
    cs = term.coarse_shape
    contact = np.where(rng.random(cs) < 0.2, rng.uniform(1.0, 5.0, cs), 0.0)
    free = np.where(contact > 0, 0.0, -scale * rng.uniform(0.5, 1.0, cs))
    return contact, free


@pytest.mark.parametrize("scale", [1.0, 10.0, 100.0])
def test_smallest_eigenvalue_and_the_softening_margin(scale):
    """The Lanczos estimate of ``lambda_min(I + H W H)`` is the dense one from above, within
    its stopping residual :data:`LANCZOS_TOLERANCE`, and the softening's scale ``theta``
    keeps ``I + H (W_C + theta W_D) H`` at least :data:`MARGIN` less that residual (the
    concavity bound), the whole softening where it already is.  Scale 10 puts the
    unscaled system within the margin of zero, 100 past it."""
    term = CoarseTerm(Grid((96, 128), size=(1.0, 1.25), comm=MPI.COMM_SELF,
                           planner="estimate"), E_STAR, 16)
    contact, free = sticky_springs(term, scale)
    exact = np.linalg.eigvalsh(dense_system(term, contact + free))[0]
    estimate = term.smallest_eigenvalue(contact + free)
    assert exact - 1e-12 <= estimate <= exact + LANCZOS_TOLERANCE
    theta = softening_for(estimate)
    kept = np.linalg.eigvalsh(dense_system(term, contact + theta * free))[0]
    if exact >= MARGIN:
        assert theta == 1.0
    else:
        assert 0.0 < theta < 1.0
        assert kept >= MARGIN - LANCZOS_TOLERANCE
    assert (exact < MARGIN) == (scale > 5)
    assert (exact < 0) == (scale > 50)


def test_the_next_estimate_starts_from_the_last_ritz_vector():
    """After a small change of the springs (a few per cent of them), the estimate starts
    from the last Ritz vector and takes a fraction of the first one's steps; after a
    change that puts a softer mode where the last Ritz vector has least weight (one
    node's softening made thirty times stronger), the estimate still finds it.  Both
    within :data:`LANCZOS_TOLERANCE` of the dense estimate, from above."""
    term = CoarseTerm(Grid((256, 256), size=(1.0, 1.0), comm=MPI.COMM_SELF,
                           planner="estimate"), E_STAR, 8)
    contact, free = sticky_springs(term, 10.0)
    springs = contact + free
    first = term.smallest_eigenvalue(springs)
    assert first == pytest.approx(np.linalg.eigvalsh(dense_system(term, springs))[0],
                                  abs=LANCZOS_TOLERANCE)
    cold = term.lanczos_steps
    moved = springs * np.where(np.random.default_rng(8).random(springs.shape) < 0.03, 1.1, 1.0)
    second = term.smallest_eigenvalue(moved)
    warm = term.lanczos_steps - cold
    exact = np.linalg.eigvalsh(dense_system(term, moved))[0]
    assert exact - 1e-12 <= second <= exact + LANCZOS_TOLERANCE
    assert 2 * warm <= cold, (warm, cold)   # both runs of the recurrence counted
    ritz = term.space(term.ritz)
    far = np.unravel_index(np.argmin(np.abs(ritz) + 10.0 * (contact > 0)), ritz.shape)
    softer = moved.copy()
    softer[far] *= 30.0
    exact = np.linalg.eigvalsh(dense_system(term, softer))[0]
    assert exact < second - 0.1    # the new mode is the softest by far
    third = term.smallest_eigenvalue(softer)
    assert exact - 1e-12 <= third <= exact + LANCZOS_TOLERANCE


def test_an_indefinite_coarse_system_backs_off_the_softening():
    """Springs whose softening outweighs the contact, given to the term without the
    estimate: its conjugate gradients meet non-positive curvature, and it solves again
    with less softening (counted), not with none."""
    term = CoarseTerm(Grid((96, 128), size=(1.0, 1.25), comm=MPI.COMM_SELF,
                           planner="estimate"), E_STAR, 16)
    contact, free = sticky_springs(term, 12.0)
    term.contact, term.springs = contact, contact + free
    term.rhs = np.random.default_rng(6).standard_normal(term.coarse_shape)
    assert np.linalg.eigvalsh(dense_system(term, term.springs))[0] < 0
    assert np.all(np.isfinite(term.correction()))
    assert term.clipped >= 1
    assert gap_two_level.MIN_SOFTENING <= term.softening < 1.0
    assert np.allclose(term.springs, contact + term.softening * free)
    assert np.linalg.eigvalsh(dense_system(term, term.springs))[0] > 0


def sticky_guide_problem(grid):
    """The GUIDE surface of the adhesive benchmark with ``w = 0.5``, ``rho = 4 a0``."""
    h = self_affine(grid, 0.8, 32 * grid.dx, 0.5 * grid.Lx, rms_slope=0.1, seed=7)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR))


def test_sticky_mean_gap_keeps_the_coarse_system_off_zero(comm, monkeypatch):
    """The sticky side (benchmark surface, 1024^2, ``w = 0.5``, mean gap): the coarse
    system with the whole softening comes within :data:`MARGIN` of zero, the term scales
    the softening back, and the solve reaches the state of 16-pixel cells with the whole
    softening in at least three iterations fewer (21 against 25)."""
    grid = Grid((1024, 1024), comm=comm, planner="estimate")
    hard = sticky_guide_problem(grid)
    settings = SolverSettings(tolerance=1e-8)
    reference = gap_cg(hard, Load(0.002 * E_STAR), settings)
    sticky = hard.with_interaction(ExponentialAdhesion(0.5 * E_STAR * grid.dx, 4 * grid.dx))
    target = MeanGap(reference.mean_gap)
    scales = []
    original = gap_two_level.softening_for
    monkeypatch.setattr(gap_two_level, "softening_for",
                        lambda mu: scales.append(original(mu)) or scales[-1])
    kept = gap_cg(sticky, target, settings)
    kept_gap = kept.gap.copy()
    monkeypatch.setattr(gap_two_level, "MARGIN", -np.inf)
    monkeypatch.setattr(gap_two_level, "BLOCK", 16)
    whole = gap_cg(sticky, target, settings)
    assert kept.converged and whole.converged
    assert min(scales) < 1.0
    assert kept.iterations + 3 <= whole.iterations
    assert np.max(np.abs(kept_gap - whole.gap)) < 1e-6 * hard.gap_scale


def adhesive_problem(grid):
    h = self_affine(grid, 0.8, 8 * grid.dx, 0.5 * grid.Lx, rms_slope=0.1, seed=4)
    law = ExponentialAdhesion(0.05 * E_STAR * grid.dx, 2 * grid.dx)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR), law)


def test_two_level_reaches_the_same_state_on_any_ranks(comm):
    tol = 1e-10
    settings = SolverSettings(tolerance=tol)
    one = adhesive_problem(Grid((128, 128), comm=MPI.COMM_SELF, planner="estimate"))
    many = adhesive_problem(Grid((128, 128), comm=comm, planner="estimate"))
    target = MeanGap(0.5 * one.rms_height)
    plain = gap_cg(one, target, settings)
    a = gap_cg(one, target, settings, two_level=True)
    b = gap_cg(many, target, settings, two_level=True)
    assert plain.converged and a.converged and b.converged
    assert a.step_counts["coarse_iterations"] > 0 and a.step_counts["projected"] > 0
    # plain numbers, for JSON and result files (no NumPy scalars from the reductions)
    assert all(type(v) is int for s in (plain, a, b) for v in s.step_counts.values())
    # two states converged to tol lie within tol's reach of each other (test_adhesion)
    gap_scale = 2 * tol * max(one.rms_slope * one.grid.Lx / math.pi, one.rms_height)
    pressure_scale = 2 * tol * E_STAR * one.rms_height / one.grid.dx
    assert np.max(np.abs(a.gap - plain.gap)) <= gap_scale
    assert np.max(np.abs(a.pressure - plain.pressure)) <= pressure_scale
    assert np.array_equal(a.gap <= 0, plain.gap <= 0)
    # round-off apart: the coarse fields are summed over the ranks, then solved alike
    rows = many.grid.x_slice
    assert np.max(np.abs(b.gap - a.gap[rows])) <= 1e-10 * one.rms_height
    assert np.max(np.abs(b.pressure - a.pressure[rows])) <= 1e-9 * one.pressure_scale
    assert b.iterations == a.iterations


def test_the_option_reaches_the_gap_solver(comm):
    """``-petgap_two_level`` (a scene's ``solver.petsc_options`` or ``petgap.solve``'s
    ``options``) reaches the gap solver through the settings read once (on by default,
    ``0`` turns the coarse term off), and is a known, checked boolean option."""
    from petgap.solvers.dispatch import solve   # deferred: the solve API, this test only
    from petgap.solvers.options import check_petsc_options
    problem = adhesive_problem(Grid((128, 128), comm=comm, planner="estimate"))
    target = MeanGap(0.5 * problem.rms_height)
    direct = gap_cg(problem, target, SolverSettings(tolerance=1e-9), two_level=True)
    run = solve(problem, target, tolerance=1e-9)
    plain = solve(problem, target, tolerance=1e-9, options={"petgap_two_level": "0"})
    assert SolverSettings().two_level
    assert run.converged and direct.converged and plain.converged
    assert run.iterations == direct.iterations != plain.iterations
    assert "coarse_iterations" not in getattr(plain, "step_counts", {}) \
        or plain.step_counts["coarse_iterations"] == 0
    assert run.step_counts["coarse_iterations"] > 0
    errors, unknown = check_petsc_options({"petgap_two_level": "maybe"})
    assert errors and errors[0][0] == "petgap_two_level" and not unknown


@pytest.mark.parametrize("work", [0.0, 0.05])
def test_springs_are_the_contacts_stiffness(comm, work):
    """The coarse term's springs are ``R (1_C K 1_C)`` on the contact set plus ``R v''(g)``
    off it, to round-off, on a rough hard-wall contact and an adhesive one, on ``comm``'s
    slabs: the contact's own stiffness cell by cell, which a count of edge neighbours
    gives only in sum (the module docstring: near sticky edges the coarse model sees the
    balance of the springs and the softening)."""
    from petgap.solvers.gap_cg import _Fields, _State
    grid = Grid((256, 256), comm=comm, planner="estimate")
    h = self_affine(grid, 0.8, 32 * grid.dx, 0.5 * grid.Lx, rms_slope=0.1, seed=7)
    law = ExponentialAdhesion(work * E_STAR * grid.dx, 4 * grid.dx) if work else None
    problem = ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR), law)
    state = gap_cg(problem, Load(0.002 * E_STAR), SolverSettings(tolerance=1e-6))
    contact = (state.gap <= 0).astype(float)
    stiffness = problem.elastic_pressure(contact - h)          # K 1_C
    f = _Fields(problem, True, None, two_level=True)
    f.g[...] = state.gap
    f.fill_stress()
    f.coarse.write_residual(f, _State())
    b = f.coarse.block
    curvature = -f.vp / f.divisor if work else 0.0
    fine = np.where(contact > 0, stiffness, f.coarse.softening * curvature)
    whole = np.zeros((grid.nx, grid.ny))
    whole[grid.x_slice] = fine
    comm.Allreduce(MPI.IN_PLACE, whole)
    px, py = hats(grid.nx, b), hats(grid.ny, b)
    expected = px.T @ whole @ py / b ** 2
    assert 0.02 < comm.allreduce(float(contact.sum())) / grid.npoints < 0.3
    assert np.allclose(f.coarse.springs, expected, rtol=0,
                       atol=1e-12 * np.abs(expected).max())
    assert f.coarse.respring == 1


@pytest.mark.parametrize("shape, block", [((64, 64), 8), ((200, 64), 8), ((8192, 8192), 8),
                                          ((16384, 16384), 16), ((16384, 8192), 16),
                                          ((32768, 32768), 32), ((44, 40), 0), ((24, 64), 0)])
def test_coarse_cells_are_8_pixels_up_to_8192(shape, block):
    """8-pixel cells wherever they fit, 1024 nodes a side at most (so 16 at 16384^2, 32 at
    32768^2); no coarse term where the grid is not a whole number of cells or has fewer
    than 4.  Why not larger cells: the sticky side's iterations grow with the cell
    (docs/design.md, the two-level preconditioner)."""
    assert block_for(shape) == block


def _in_fresh_process(tmp_path, source):
    """Run ``source`` (dedented) as a script in a Python process of its own, from rank 0
    (:func:`conftest.wait_for_root`), so that a crash or an import fails the test only."""
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent(source))
    return wait_for_root(lambda: subprocess.run([sys.executable, str(script)],
                                                capture_output=True, text=True, timeout=300,
                                                env=clean_env()))


def test_inner_products_of_a_large_coarse_grid(tmp_path):
    """Parseval's inner product on a 1024^2 coarse grid's spectrum (8192^2 at 8-pixel
    cells) equals the real fields' product, with each field ending exactly at the end of
    a mapping of its own: a strided BLAS product of a complex column read past the array
    and killed the process (run in a process of its own, so that a crash fails here)."""
    done = _in_fresh_process(tmp_path, """
        import mmap, types
        import numpy as np
        from mpi4py import MPI
        from petgap.parallel.grid import Grid
        from petgap.solvers.gap_two_level import CoarseTerm

        def at_mapping_end(values):
            nbytes = values.nbytes
            size = -(-nbytes // mmap.PAGESIZE) * mmap.PAGESIZE
            out = np.frombuffer(mmap.mmap(-1, size), dtype=values.dtype, count=values.size,
                                offset=size - nbytes).reshape(values.shape)
            out[...] = values
            return out

        rng = np.random.default_rng(0)
        for n in (1024, 512, 1022):
            x, y = rng.random((n, n)), rng.random((n, n))
            a, b = (at_mapping_end(np.ascontiguousarray(np.fft.rfft2(v).T)) for v in (x, y))
            term = types.SimpleNamespace(cgrid=Grid((n, n), comm=MPI.COMM_SELF,
                                                    planner="estimate", wisdom=False))
            dot = CoarseTerm._dot(term, a, b) / (n * n)
            assert abs(dot - float(np.sum(x * y))) <= 1e-10 * float(np.sum(x * y)), n
        print("ok")
        """)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
