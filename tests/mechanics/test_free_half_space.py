"""The free-boundary half-space: Love's coefficients, Hockney's padding, and the classical
contacts it must reproduce (Hertz, the flat punch), against the periodic cell."""
import numpy as np
import pytest
from mpi4py import MPI

import petgap
from petgap.mechanics.free_half_space import (FreeHalfSpace, PaddedCellHalfSpace,
                                               influence_coefficients, influence_grid,
                                               margin_cell, padded_kernel)
from petgap.parallel.dottest import dottest
from petgap.parallel.grid import Grid
from petgap.surfaces.indenters import indenter


def _gather(comm, local):
    return np.concatenate(comm.allgather(local))


def test_influence_coefficients_limits():
    """The pixel's own centre in closed form; far away, the point load dx dy / (pi E* r)."""
    dx, dy, e = 0.7, 1.3, 2.5
    centre = influence_coefficients(0.0, 0.0, dx, dy, e)
    expected = 2 / (np.pi * e) * (dx * np.arcsinh(dy / dx) + dy * np.arcsinh(dx / dy))
    assert centre == pytest.approx(expected, rel=1e-14)
    r = np.array([50.0, 200.0, 800.0])
    far = influence_coefficients(r * 0.6, r * 0.8, dx, dy, e)
    point = dx * dy / (np.pi * e * r)
    # the pixel's second moment corrects the point load by O((dx / r)^2)
    assert np.all(np.abs(far / point - 1) < 0.2 * (max(dx, dy) / r) ** 2)
    # the integral over the pixel: mean of 1/r by a fine midpoint rule, at a near point
    s = (np.arange(400) + 0.5) / 400 - 0.5
    xs, ys = np.meshgrid(s * dx, s * dy, indexing="ij")
    near = np.mean(1 / np.hypot(2.0 - xs, 1.0 - ys)) * dx * dy / (np.pi * e)
    assert influence_coefficients(2.0, 1.0, dx, dy, e) == pytest.approx(near, rel=1e-5)


def test_influence_grid_is_the_pointwise_formula():
    """The corner-shared evaluation equals the pointwise one, negative offsets included."""
    dx, dy, e = 0.7, 1.3, 2.5
    grid = influence_grid(-5, 40, -3, 30, dx, dy, e)
    i, j = np.meshgrid(np.arange(-5, 40), np.arange(-3, 30), indexing="ij")
    pointwise = influence_coefficients(i * dx, j * dy, dx, dy, e)
    np.testing.assert_allclose(grid, pointwise, rtol=1e-11)


@pytest.mark.parametrize("shape", [(12, 10), (9, 7)])
def test_compliance_is_the_linear_convolution(comm, shape):
    """Hockney's padded transform equals the direct sum over the map, on any rank count."""
    nx, ny = shape
    grid = Grid(shape, size=(nx * 0.7, ny * 1.3), comm=comm, planner="estimate", wisdom=False)
    half_space = FreeHalfSpace(grid, 2.0)
    p = np.random.default_rng(1).random(shape)      # the same on every rank
    u = _gather(comm, half_space.displacement(p[grid.x_slice]))
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    direct = np.array([[np.sum(influence_coefficients((a - i) * grid.dx, (b - j) * grid.dy,
                                                      grid.dx, grid.dy, 2.0) * p)
                        for b in range(ny)] for a in range(nx)])
    np.testing.assert_allclose(u, direct, rtol=1e-13, atol=1e-13 * np.abs(direct).max())
    # the sparse path of the solvers gives the same, gathered on the points
    pidx = np.flatnonzero(np.ones(grid.padded.shape, bool)[:, :].reshape(-1) &
                          (np.arange(grid.padded.size) % grid.padded.shape[1] < ny))
    values = p[grid.x_slice].ravel()
    gathered = np.empty(len(pidx))
    half_space.apply_sparse(pidx, values, inverse=True, gathered=gathered)
    np.testing.assert_allclose(gathered, direct[grid.x_slice].ravel(), rtol=1e-12,
                               atol=1e-13 * np.abs(direct).max())
    # the complementary energy is (1/2) p.u dx dy, and positive (C is positive definite)
    energy = half_space.complementary_energy(p[grid.x_slice])
    assert energy == pytest.approx(0.5 * grid.pixel_area * np.sum(p * direct), rel=1e-12)
    with pytest.raises(NotImplementedError, match="displacements from pressures only"):
        half_space.pressure(u[grid.x_slice])


def _full_padded(p, dx, dy, modulus):
    """``C * p`` by the whole padded cell's transform pair (Hockney unpruned), on one rank."""
    nx, ny = p.shape
    cell = Grid((2 * nx, 2 * ny), size=(2 * nx * dx, 2 * ny * dy), comm=MPI.COMM_SELF,
                planner="estimate", wisdom=False)
    kernel = padded_kernel(cell, modulus)
    cell.real[...] = 0.0
    cell.real[:nx, :ny] = p
    cell.forward()
    cell.fourier *= kernel / cell.npoints
    return cell.backward()[:nx, :ny].copy()


@pytest.mark.parametrize("shape", [(16, 12), (9, 7), (7, 13)])
def test_pruned_compliance_equals_the_full_padded_one(comm, shape):
    """The pruned transform gives the whole padded cell's result to round-off, whole,
    gathered and split into its halves (``begin_sparse`` / ``finish``), with the form
    ``(t, C t)`` of the forward half; ``C`` and the stiffness pass the dot test."""
    nx, ny = shape
    grid = Grid(shape, size=(nx * 0.7, ny * 1.3), comm=comm, planner="estimate", wisdom=False)
    body = FreeHalfSpace(grid, 2.0)
    p = np.random.default_rng(1).random(shape)
    p[p < 0.5] = 0.0
    expected = _full_padded(p, grid.dx, grid.dy, 2.0)
    tol = 1e-13 * np.abs(expected).max()
    np.testing.assert_allclose(body.displacement(p[grid.x_slice]), expected[grid.x_slice],
                               rtol=0, atol=tol)
    mask = np.zeros(grid.padded.shape, bool)
    mask[:, :ny] = p[grid.x_slice] > 0
    pidx = np.flatnonzero(mask).astype(np.int32)
    values = p[grid.x_slice][mask[:, :ny]]
    form = comm.allreduce(body.begin_sparse(pidx, values, inverse=True))
    assert form == pytest.approx(float(np.vdot(p, expected)), rel=1e-13)
    before = body.applications
    body.finish()
    assert body.applications == before + 0.5
    np.testing.assert_allclose(grid.real, expected[grid.x_slice], rtol=0, atol=tol)
    with pytest.raises(RuntimeError, match="no half-made transform"):
        body.finish()
    dottest(grid, body.displacement)
    dottest(grid, lambda x: _stiffness(grid, body, x))


def test_the_stiffness_does_not_reach_across_the_map(comm):
    """The preconditioning stiffness is the half-space's on the map alone: a unit gap at the
    first row moves the last row by nothing the margin's kernel lets through, where the
    map's periodic grid couples them as neighbours."""
    grid = Grid((32, 24), comm=comm, planner="estimate", wisdom=False)
    body = FreeHalfSpace(grid)
    assert margin_cell(grid) == (48, 40)
    unit = np.zeros(grid.shape)
    unit[0, 5] = 1.0
    free = _gather(comm, _stiffness(grid, body, unit[grid.x_slice]))
    periodic = _gather(comm, _stiffness(grid, petgap.ElasticHalfSpace(grid), unit[grid.x_slice]))
    assert abs(periodic[-1, 5]) > 0.2 and abs(free[-1, 5]) < 1e-3
    assert free[1, 5] == pytest.approx(periodic[1, 5], rel=2e-2)


def _stiffness(grid, body, x):
    np.copyto(grid.real, x)
    return body.apply_in_buffer(inverse=False).copy()


def test_single_precision_free_half_space(comm):
    """On a single-precision grid the compliance runs in 32 bits (a double kernel) and
    agrees with double to single's rounding."""
    shape = (20, 14)
    p = np.random.default_rng(4).random(shape)
    results = {}
    for precision in ("double", "single"):
        grid = Grid(shape, comm=comm, planner="estimate", wisdom=False, precision=precision)
        u = FreeHalfSpace(grid).displacement(p[grid.x_slice])
        assert u.dtype == grid.dtype
        results[precision] = u
    np.testing.assert_allclose(results["single"], results["double"], rtol=2e-6)


def _hertz(comm, n=256, a=64.0, radius=1000.0):
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    h = indenter(grid, "paraboloid", radius)
    return grid, petgap.ContactProblem(grid, h, FreeHalfSpace(grid, 1.0))


def test_hertz_on_a_free_boundary(comm):
    """64 pixels per contact radius on a map just four radii wide: no periodic correction.

    Load control at Hertz's load ``P = 4 E* a^3 / 3R``: contact radius (from the
    area) and peak pressure ``2 E* a / (pi R)`` within 0.5 %; indentation
    control at Hertz's ``d = a^2 / R``: the load within 0.5 %.
    """
    a, radius = 64.0, 1000.0
    grid, problem = _hertz(comm, a=a, radius=radius)
    load = 4 * a ** 3 / (3 * radius)
    s = petgap.solve(problem, petgap.Load(load / grid.area))
    assert s.converged and s.reason == "converged_kkt"
    assert np.sqrt(s.contact_fraction * grid.area / np.pi) == pytest.approx(a, rel=5e-3)
    p0 = comm.allreduce(float(s.pressure.max()), op=MPI.MAX)
    assert p0 == pytest.approx(2 * a / (np.pi * radius), rel=5e-3)
    # the pressure is Hertz's ellipse inside, away from the edge
    x, y = grid.local_positions()
    r = np.hypot(x - grid.nx // 2, y - grid.ny // 2)
    inner = r < 0.9 * a
    hertz = 2 * a / (np.pi * radius) * np.sqrt(np.maximum(1 - (r / a) ** 2, 0))
    assert np.all(np.abs(s.pressure[inner] - hertz[inner]) < 0.01 * p0)

    d = petgap.solve(problem, petgap.Indentation(a ** 2 / radius))
    assert d.converged
    assert d.mean_pressure * grid.area == pytest.approx(load, rel=5e-3)
    assert d.control.kind == "indentation" and d.control.value == a ** 2 / radius
    # the elastic energy of Hertz's contact: (2/5) P d
    assert d.elastic_energy == pytest.approx(0.4 * load * a ** 2 / radius, rel=1e-2)


def test_mean_gap_on_a_free_boundary_is_reached_through_the_indentation(comm):
    grid, problem = _hertz(comm, n=128, a=32.0)
    by_depth = petgap.solve(problem, petgap.Indentation(1.0))
    s = petgap.solve(problem, petgap.MeanGap(by_depth.mean_gap))
    assert s.converged and s.control.kind == "mean-gap"
    # the mean gap to the solve's tolerance, 1e-8 h0
    assert s.mean_gap == pytest.approx(by_depth.mean_gap, rel=0, abs=1e-8 * problem.gap_scale)
    assert s.mean_pressure == pytest.approx(by_depth.mean_pressure, rel=1e-5)
    assert "the depth moved" in s.start and s.depth == pytest.approx(1.0, rel=1e-6)
    # beyond first touch the surfaces stay apart, unloaded
    apart = petgap.solve(problem, petgap.MeanGap(10 * by_depth.mean_gap))
    assert apart.mean_pressure == 0 and apart.mean_gap == pytest.approx(10 * by_depth.mean_gap)


def test_flat_punch_stiffness(comm):
    """Boussinesq's rigid circular punch: ``P = 2 E* a d``, within 1 % at 64 pixels per radius."""
    n, a = 256, 64.0
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    problem = petgap.ContactProblem(grid, indenter(grid, "flat-punch", a), FreeHalfSpace(grid))
    s = petgap.solve(problem, petgap.Indentation(0.5))
    assert s.converged
    assert s.mean_pressure * grid.area == pytest.approx(2 * a * 0.5, rel=1e-2)
    # the whole face is in contact, nothing around it
    face = comm.allreduce(int(np.count_nonzero(problem.topography == 0)))
    assert s.contact_fraction * grid.npoints == face


def test_free_and_periodic_differ_by_the_images(comm):
    """A small Hertz contact at the centre of a periodic cell and of a free map.

    The free solution does not see the map's size (no pressure outside the
    contact); the periodic one feels its images, whose field at the contact
    falls as ``(a / L)^3``.  The two discretisations (pixel-uniform pressure
    here, the spectral symbol there) differ by a constant of order
    ``(a0 / a)^2`` besides, so the difference in peak pressure is
    ``D(L) = D_inf + c (a / L)^3``, and each doubling of the cell divides
    ``D(L) - D(2L)`` by eight.
    """
    a, radius = 24.0, 2000.0
    load = 4 * a ** 3 / (3 * radius)
    peaks = {}
    sizes = (192, 384, 768)
    for n in sizes:
        grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
        h = indenter(grid, "paraboloid", radius)
        for name, body in (("free", FreeHalfSpace(grid)), ("periodic",
                                                           petgap.ElasticHalfSpace(grid))):
            s = petgap.solve(petgap.ContactProblem(grid, h, body), petgap.Load(load / grid.area))
            assert s.converged
            peaks[name, n] = comm.allreduce(float(s.pressure.max()), op=MPI.MAX)
    assert peaks["free", 192] == pytest.approx(peaks["free", 768], rel=1e-6)
    d = [peaks["periodic", n] / peaks["free", n] - 1 for n in sizes]
    assert 1e-4 < abs(d[0]) < 1e-2
    assert 7 < (d[0] - d[1]) / (d[1] - d[2]) < 9


def test_free_boundary_is_rank_independent(comm):
    """The same indentation on ``comm`` and on every rank alone agree to round-off."""
    def solve(c):
        grid = Grid((96, 80), size=(96 * 0.5, 80 * 0.5), comm=c, planner="estimate",
                    wisdom=False)
        problem = petgap.ContactProblem(grid, indenter(grid, "sphere", 30.0),
                                        FreeHalfSpace(grid))
        s = petgap.solve(problem, petgap.Load(0.002))
        return grid, s
    grid, together = solve(comm)
    _, alone = solve(MPI.COMM_SELF)
    assert together.iterations == alone.iterations
    np.testing.assert_allclose(together.pressure, alone.pressure[grid.x_slice], rtol=0,
                               atol=1e-12 * np.abs(alone.pressure).max())


def test_what_a_free_boundary_cannot_do(comm):
    grid, problem = _hertz(comm, n=64, a=16.0)
    adhesive = problem.with_interaction(petgap.ExponentialAdhesion(1e-3, 1.0))
    with pytest.raises(ValueError, match="indentation control is for the hard wall"):
        petgap.solve(adhesive, petgap.Indentation(1.0))
    with pytest.raises(ValueError, match="solver 'bncg' does not solve indentation control"):
        petgap.solve(problem, petgap.Indentation(1.0), solver="bncg")
    periodic = petgap.ContactProblem(grid, problem.topography, petgap.ElasticHalfSpace(grid))
    with pytest.raises(ValueError, match="indentation control needs a free boundary"):
        petgap.solve(periodic, petgap.Indentation(1.0))
    with pytest.raises(ValueError, match="depth -1.0 < 0"):
        petgap.solve(problem, petgap.Indentation(-1.0))


def test_padded_cell_is_the_free_map(comm):
    """The hard wall solved on the padded cell (the gap solver's route) is the map's own
    free solution; the cell's stiffness inverts its compliance."""
    grid, problem = _hertz(comm, n=64, a=16.0, radius=200.0)
    on_map = petgap.solve(problem, petgap.Load(0.002))
    on_cell = petgap.solve(problem, petgap.Load(0.002), solver="pcg-gap")
    assert on_map.converged and on_cell.converged
    assert "padded cell" in on_cell.start and "padded cell" not in on_map.start
    scale = comm.allreduce(float(np.abs(on_map.pressure).max()), op=MPI.MAX)
    assert comm.allreduce(float(np.abs(on_map.pressure - on_cell.pressure).max()),
                          op=MPI.MAX) < 1e-6 * scale
    assert on_cell.contact_fraction == on_map.contact_fraction
    cell = problem.half_space.cell
    body = PaddedCellHalfSpace(cell, 1.0)
    u = np.random.default_rng(cell.x_slice.start).standard_normal(cell.local_shape)
    u -= cell.mean(u)
    np.testing.assert_allclose(body.displacement(body.pressure(u)), u, atol=1e-10)
    assert body.energy(u) == pytest.approx(body.complementary_energy(body.pressure(u)),
                                           rel=1e-10)


def test_the_padded_cells_energy_is_half_the_work_of_its_pressure(comm):
    """The padded cell's energies, summed over the spectrum in blocks of the Fourier slab
    (several on a 512^2 cell), are ``(1/2) dx dy sum p u`` summed in real space."""
    cell = Grid((512, 512), comm=comm, planner="estimate", wisdom=False)
    body = PaddedCellHalfSpace(cell, 2.0)
    u = np.random.default_rng(cell.x_slice.start).standard_normal(cell.local_shape)
    u -= cell.mean(u)
    p = body.pressure(u)
    work = 0.5 * cell.pixel_area * comm.allreduce(float(np.sum(p * u)))
    assert body.energy(u) == pytest.approx(work, rel=1e-12)
    assert body.complementary_energy(p) == pytest.approx(work, rel=1e-10)


def _adhesive_sphere(comm, n, body):
    grid = Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    half_space = FreeHalfSpace(grid) if body == "free" else petgap.ElasticHalfSpace(grid)
    problem = petgap.ContactProblem(grid, indenter(grid, "paraboloid", 200.0), half_space,
                                    petgap.ExponentialAdhesion(0.02, 1.0))
    s = petgap.solve(problem, petgap.Load(4.096 / grid.area))   # the same force on every map
    return grid, problem, s


def test_adhesive_sphere_free_and_periodic(comm):
    """An adhesive sphere (rho = a0, a ~ 19 a0) on free maps of 128^2 and 192^2 and on a
    periodic cell of 512^2, under the same force: the same contact, peak pressure and
    attractive force.  On the free maps the surface ends at the map's edge, where the gap
    is above 10 rho; the periodic cell's attraction runs on beyond it, and its spectral
    discretisation differs from the pixels' uniform pressures (a few 1e-4 in F_att).  The
    larger map's ring beyond the smaller's edge adds its attraction (2.5e-5 of F_att
    here), which the same force balances by as much more repulsion: the peak pressure
    rises by at most that share of F_rep (a third of it for Hertz, ``p_max ~ F^(1/3)``)."""
    results = {(body, n): _adhesive_sphere(comm, n, body)
               for body, n in (("free", 128), ("free", 192), ("periodic", 512))}
    summary = {}
    for key, (grid, problem, s) in results.items():
        summary[key] = (s.converged, round(s.contact_fraction * grid.npoints),
                        comm.allreduce(float(s.pressure.max()), op=MPI.MAX), s.attractive_force,
                        s.repulsive_force)
    small, large, periodic = summary["free", 128], summary["free", 192], summary["periodic", 512]
    assert small[0] and large[0] and periodic[0]
    assert small[1] == large[1] == periodic[1]
    ring = abs(large[3] - small[3]) / small[4]   # the ring's attraction over F_rep
    assert 0 < ring < 1e-4
    assert small[2] < large[2] <= small[2] * (1 + ring)
    assert small[2] == pytest.approx(periodic[2], rel=1e-4)
    assert small[3] < 0 and small[3] == pytest.approx(large[3], rel=1e-4)
    assert small[3] == pytest.approx(periodic[3], rel=1e-3)


def test_adhesive_free_map_under_mean_gap_and_on_any_rank_count(comm):
    grid, problem, by_load = _adhesive_sphere(comm, 64, "free")
    s = petgap.solve(problem, petgap.MeanGap(by_load.mean_gap))
    assert s.converged and s.mean_gap == pytest.approx(by_load.mean_gap, rel=1e-7)
    assert s.mean_pressure == pytest.approx(by_load.mean_pressure, rel=1e-4)
    _, _, alone = _adhesive_sphere(MPI.COMM_SELF, 64, "free")
    np.testing.assert_allclose(by_load.pressure, alone.pressure[grid.x_slice], rtol=0,
                               atol=1e-9 * np.abs(alone.pressure).max())


def test_adhesive_free_mean_gap_is_one_solve(comm):
    """A rough free map's adhesive mean gap is one gap solve on its padded cell, whose
    mean-gap target follows the map's mean gap (free_boundary.MapMeanGap), within the
    iterations of a few restarts beyond a load solve's; the secant of whole cell solves
    took 81 on this map.  The state is the map's: its mean gap is the target to the
    tolerance, the load it reports gives back that state under load control, and one rank
    finds it as two do."""
    def mean_gap_state(comm):
        grid = Grid((128, 128), comm=comm, planner="estimate", wisdom=False)
        h = petgap.self_affine(grid, 0.8, 8.0, 64.0, rms_slope=0.1, seed=7)
        hard = petgap.ContactProblem(grid, h, FreeHalfSpace(grid))
        reference = petgap.solve(hard, petgap.Load(0.002))
        problem = hard.with_interaction(petgap.ExponentialAdhesion(0.05, 2.0))
        return grid, problem, reference, petgap.solve(problem, petgap.MeanGap(reference.mean_gap))
    grid, problem, reference, s = mean_gap_state(comm)
    assert s.converged and s.iterations <= 45
    assert "moved its target" in s.start
    assert abs(s.mean_gap - reference.mean_gap) <= 1e-8 * problem.gap_scale
    loaded = petgap.solve(problem, petgap.Load(s.mean_pressure))
    _, _, _, alone = mean_gap_state(MPI.COMM_SELF)
    # two states converged to the KKT tolerance 1e-8 lie within a displacement of a
    # pressure error at the longest wave, 2e-8 h0' L / pi, and a pressure holding a gap
    # error on one pixel, 2e-8 E* h0 / a0 (tests/solvers/test_adhesion.py's scales)
    gap_bound = 2e-8 * max(problem.rms_slope * grid.Lx / np.pi, problem.gap_scale)
    pressure_bound = 2e-8 * problem.gap_scale
    assert loaded.converged and abs(loaded.mean_gap - s.mean_gap) <= gap_bound
    for other in (loaded.pressure, alone.pressure[grid.x_slice]):
        assert comm.allreduce(float(np.abs(other - s.pressure).max()),
                              op=MPI.MAX) <= pressure_bound


def test_adhesive_free_map_with_an_odd_side(comm):
    """A map with an odd side has a padded cell that does not coarsen (its blocks would
    straddle the map's edge): the gap solve starts without the coarse level, and a map with
    even sides keeps it."""
    from petgap.solvers import coarse
    from petgap.solvers.free_boundary import cell_problem
    law = petgap.ExponentialAdhesion(0.02, 1.0)
    levels = {}
    for shape in ((257, 258), (258, 258)):
        grid = Grid(shape, comm=comm, planner="estimate", wisdom=False)
        problem = petgap.ContactProblem(grid, indenter(grid, "paraboloid", 800.0),
                                        FreeHalfSpace(grid), law)
        levels[shape] = coarse.coarse_problem(cell_problem(problem))
    assert levels[(257, 258)] is None and levels[(258, 258)] is not None
    grid = Grid((257, 258), comm=comm, planner="estimate", wisdom=False)
    problem = petgap.ContactProblem(grid, indenter(grid, "paraboloid", 800.0),
                                    FreeHalfSpace(grid), law)
    s = petgap.solve(problem, petgap.Load(16.0 / grid.area))
    assert s.converged and s.contact_fraction > 0


def test_free_mean_gap_costs_less_than_two_load_solves(comm):
    """The mean gap of a rough free map in one indentation solve whose depth moves as the
    iterate's mean gap settles: fewer than twice the operator applications of the load
    solve with that mean gap (a solve per depth, each warm from the last, took 2.0x)."""
    grid = Grid((256, 256), comm=comm, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 16.0, grid.Lx / 2, rms_slope=0.1, seed=1)
    problem = petgap.ContactProblem(grid, h, FreeHalfSpace(grid))
    by_load = petgap.solve(problem, petgap.Load(0.002), tolerance=1e-8)
    s = petgap.solve(problem, petgap.MeanGap(by_load.mean_gap), tolerance=1e-8)
    assert s.converged and s.mean_gap == pytest.approx(by_load.mean_gap, rel=1e-8)
    assert s.mean_pressure == pytest.approx(by_load.mean_pressure, rel=1e-6)
    assert s.operator_applications <= 1.85 * by_load.operator_applications, \
        (s.operator_applications, by_load.operator_applications)


def _moved_once(grid, h, move):
    """A converged indentation (at the load 0.002's depth) moved by ``move h0`` once its
    residual is below 1e-9, solved on to 1e-10: ``(solution, depth, delta, the first
    residual after the move, whether the patch interaction was in use at the move)``."""
    from petgap.mechanics.problem import Indentation
    from petgap.solvers.pressure_cg import polonsky_keer
    from petgap.solvers.settings import SolverSettings
    problem = petgap.ContactProblem(grid, h, FreeHalfSpace(grid))
    depth = petgap.solve(problem, petgap.Load(0.002), tolerance=1e-10).approach
    delta = move * problem.gap_scale
    seen = []

    def rule(cg, residual):
        if not seen and residual < 1e-9:
            seen.append(cg.preconditioner.patch_used)
            return cg.offset + delta
        if len(seen) == 1:
            seen.append(residual)   # the first residual after the move
        return None

    s = polonsky_keer(problem, Indentation(depth), SolverSettings(tolerance=1e-10),
                      retarget=rule)
    assert len(seen) == 2, seen
    return s, depth, delta, seen[1], seen[0]


@pytest.mark.parametrize("move", [1e-3, -1e-3])
def test_a_depth_move_takes_the_pressure_with_it(comm, move):
    """``PressureCG.move_depth`` moves the pressure along a flat punch's shape on the contact
    set, so a converged indentation moved by ``delta`` keeps the gap there well below
    ``delta`` (a bare move of the depth leaves ``delta`` on every contact point), and the
    solve ends at the new depth."""
    grid = Grid((128, 128), comm=comm, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 8.0, grid.Lx / 2, rms_slope=0.1, seed=3)
    s, depth, delta, after, _ = _moved_once(grid, h, move)
    assert s.converged
    assert 0 < after < 0.6 * abs(move), after / abs(move)
    assert s.approach == pytest.approx(depth - delta, rel=0, abs=1e-12 * depth)


def test_a_depth_move_shares_the_punch_between_the_patches(comm):
    """On a 512^2 map, where the preconditioner has the patch interaction, a move takes the
    pressure along the preconditioner's own flat punch ``M 1_S``, whose far field shares
    the punch's force between the patches: the residual after a move is below 0.3 of it
    (0.22; with ``P_S K 1_S`` alone, each patch punched as if it were alone, 0.41)."""
    move = 1e-5
    grid = Grid((512, 512), comm=comm, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 32.0, grid.Lx / 2, rms_slope=0.1, seed=1)
    s, _, _, after, patch_used = _moved_once(grid, h, move)
    assert s.converged and patch_used
    assert 0 < after < 0.3 * move, after / move


def test_the_coarse_start_carries_the_rigid_surface_not_its_depth(comm):
    """A free mean-gap solve starts from the coarse grid's answer.  Block means lower the
    highest point (here a sphere's apex, by 0.01), so the depth below it differs between
    the grids where the rigid surface's place against the mean height does not: carried
    over as that place, the start's depth is nearer the answer than the coarse depth."""
    from petgap.solvers import coarse
    from petgap.solvers.indentation import _coarse_depth, solve_mean_gap_by_indentation
    from petgap.solvers.settings import SolverSettings
    grid = Grid((128, 128), comm=comm, planner="estimate", wisdom=False)
    problem = petgap.ContactProblem(grid, indenter(grid, "paraboloid", 50.0), FreeHalfSpace(grid))
    depth = 0.5
    control = petgap.MeanGap(petgap.solve(problem, petgap.Indentation(depth)).mean_gap)
    settings = SolverSettings()
    start = _coarse_depth(problem, control, settings, 0.0).depth
    on_coarse = solve_mean_gap_by_indentation(coarse.coarse_problem(problem), control,
                                              settings.but(tolerance=settings.coarse_tolerance))
    assert abs(start - depth) < 0.5 * abs(on_coarse.depth - depth), (start, on_coarse.depth)
