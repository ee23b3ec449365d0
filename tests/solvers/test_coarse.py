"""The coarse-grid start of the pressure solver (petgap.solvers.coarse).

Restriction and prolongation are checked against NumPy on the gathered global
array, on grids whose blocks of rows straddle two ranks' slabs (so the row
exchange between the two decompositions is exercised under ``mpirun -n 2``);
the coarse start must reach the state the uniform start reaches, in fewer
iterations, and the same state on one rank as on two.
"""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.solvers import coarse as coarse_module
from petgap.solvers.coarse import (EDGE_BLOCKS, coarse_problem, coarsening_factor,
                                   edge_profile, edge_shares, is_whole, prolong, restrict)
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.grid import Grid
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.pressure_start import coarse_start_pressure
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine
from test_contact import (E_STAR, assert_same_state, max_abs, solve_on_three_ranks,
                          tolerance_scales)


def make_grid(shape, comm, size=None):
    return Grid(shape, size=size, comm=comm, planner="estimate")


def test_coarsening_depends_on_the_shape_alone():
    assert coarsening_factor((1024, 1024)) == 2
    assert coarsening_factor((64, 64)) == 2            # 32 x 32 coarse
    assert coarsening_factor((130, 64)) == 2
    assert coarsening_factor((62, 64)) is None         # 62 / 2 < 32
    assert coarsening_factor((75, 50)) is None
    assert coarsening_factor((512, 4)) is None


@pytest.mark.parametrize("shape, f", [((36, 16), 4), ((130, 64), 2)])
@pytest.mark.parametrize("chunk", [coarse_module.PROLONG_CHUNK, 3])
@pytest.mark.parametrize("one_rank", [False, True])
def test_restriction_and_prolongation_match_numpy(comm, shape, f, chunk, one_rank, monkeypatch):
    """Block means and block repeats, whatever the two decompositions.

    (36, 16) on 2 ranks: fine rows 18 + 18, coarse rows 5 + 4, so coarse row 4
    takes fine rows 16-19 from both ranks; (130, 64): 65 + 65 and 33 + 32.  Also
    on one rank (no messages), and prolonged 3 rows at a time (chunks that cut
    blocks).
    """
    monkeypatch.setattr(coarse_module, "PROLONG_CHUNK", chunk)
    if one_rank:
        comm = MPI.COMM_SELF
    grid = make_grid(shape, comm, size=(2.0, 1.0))
    coarse = make_grid((shape[0] // f, shape[1] // f), comm, size=(2.0, 1.0))
    rng = np.random.default_rng(7)
    full = rng.standard_normal(shape)
    means = restrict(grid, coarse, grid.local_part(full).copy(), f)
    expected = full.reshape(shape[0] // f, f, shape[1] // f, f).mean(axis=(1, 3))
    coarse_field = rng.standard_normal(coarse.shape)
    fine = prolong(coarse.x_slice.start, grid, coarse.local_part(coarse_field).copy(), f)
    repeated = np.repeat(np.repeat(coarse_field, f, axis=0), f, axis=1)
    # judged over all ranks, so that every rank fails together
    assert max_abs(coarse, means - coarse.local_part(expected)) <= 1e-14
    assert max_abs(grid, fine - grid.local_part(repeated)) == 0.0


@pytest.mark.parametrize("f", [2, 3, 4])
def test_edge_shares_are_the_square_root_profiles_pixel_integrals(f):
    """Each pixel's share of its block is its part of the block's integral of
    ``s^(-1/2)`` (a midpoint sum here, not the closed form); shares of a block sum to
    ``f``; the far side mirrors the near one; pixels farther in keep their value."""
    n = 8 * f * EDGE_BLOCKS
    w = edge_shares(n, f)
    s = (np.arange(200_000) + 0.5) / 200_000   # midpoints of a pixel, distance in pixels
    for k in range(EDGE_BLOCKS):
        integrals = np.array([np.mean(1 / np.sqrt(m + s)) for m in range(f * k, f * k + f)])
        assert np.abs(w[f * k:f * k + f] - f * integrals / integrals.sum()).max() <= 2e-3
        assert w[f * k:f * k + f].sum() == pytest.approx(f, rel=1e-12)
    assert w[0] == pytest.approx(f * 1 / np.sqrt(f), rel=1e-12)   # 2 / sqrt 2 for f = 2
    assert np.array_equal(w, w[::-1])
    assert np.all(w[f * EDGE_BLOCKS:n - f * EDGE_BLOCKS] == 1.0)


def test_edge_profile_matches_numpy_on_any_decomposition(comm):
    """Rows of the x-edges lie on the first and last ranks' slabs (130 rows: 65 + 65)."""
    shape = (130, 64)
    grid = make_grid(shape, comm, size=(2.0, 1.0))
    full = np.random.default_rng(3).random(shape)
    local = grid.local_part(full).copy()
    assert edge_profile(grid, local, 2) is local
    expected = full * np.outer(edge_shares(130, 2), edge_shares(64, 2))
    assert max_abs(grid, local - grid.local_part(expected)) <= 1e-15
    # on a prolonged field the block means, hence the load, are kept
    coarse = make_grid((65, 32), comm, size=(2.0, 1.0))
    blocks = coarse.local_part(full[::2, ::2]).copy()
    shaped = edge_profile(grid, prolong(coarse.x_slice.start, grid, blocks, 2), 2)
    assert max_abs(coarse, restrict(grid, coarse, shaped, 2) - blocks) <= 1e-15


def test_a_free_start_has_the_edges_square_root_profile(comm, monkeypatch):
    """A gently curved punch pressed into full contact with a free 128^2 map: the fine
    pressure rises like ``s^(-1/2)`` towards the map's edges.  The start prolonged with
    the edges' profile is five times nearer it in the four pixels by the edges than
    the start that repeats the coarse blocks there; inside, they differ only by what
    the levels below, themselves started with or without the profile, left."""
    from petgap.mechanics.free_half_space import FreeHalfSpace
    n = 128
    grid = make_grid((n, n), comm)
    x = (np.arange(n)[grid.x_slice] + 0.5 - n / 2)[:, None]
    y = (np.arange(n) + 0.5 - n / 2)[None, :]
    h = np.ascontiguousarray(-(x ** 2 + y ** 2) / (200.0 * n))
    problem = ContactProblem(grid, h, FreeHalfSpace(grid, E_STAR))
    control = Load(0.05 * E_STAR)
    fine = polonsky_keer(problem, control, SolverSettings(tolerance=1e-9)).pressure.copy()
    assert grid.comm.allreduce(int((fine > 0).sum())) == n * n
    band = np.zeros((n, n), dtype=bool)
    band[:4] = band[-4:] = band[:, :4] = band[:, -4:] = True
    band = band[grid.x_slice]

    def start_errors():
        p = coarse_start_pressure(problem, control, SolverSettings(tolerance=1e-8),
                                  polonsky_keer)[0]
        e = (p - fine) ** 2
        return [np.sqrt(grid.comm.allreduce(float(e[m].sum()))
                        / grid.comm.allreduce(int(m.sum()))) for m in (band, ~band)]

    shaped = start_errors()
    monkeypatch.setattr(coarse_module, "edge_profile", lambda grid, field, f: field)
    repeated = start_errors()
    assert shaped[0] < 0.3 * repeated[0]
    assert shaped[1] == pytest.approx(repeated[1], rel=1e-3)


def test_whole_coarse_grid_on_every_rank_matches_numpy(comm):
    """A coarse grid solved whole on every rank: each rank restricts to all of it and
    prolongs from it to its own fine rows, whatever the fine decomposition."""
    shape, f = (130, 64), 2
    grid = make_grid(shape, comm, size=(2.0, 1.0))
    whole = make_grid((65, 32), MPI.COMM_SELF, size=(2.0, 1.0))
    assert is_whole(grid, whole) == (comm.size > 1)
    rng = np.random.default_rng(11)
    full = rng.standard_normal(shape)
    means = restrict(grid, whole, grid.local_part(full).copy(), f)
    expected = full.reshape(65, f, 32, f).mean(axis=(1, 3))
    coarse_field = rng.standard_normal((65, 32))
    fine = prolong(0, grid, coarse_field, f, whole=True)
    repeated = np.repeat(np.repeat(coarse_field, f, axis=0), f, axis=1)
    assert grid.comm.allreduce(float(np.abs(means - expected).max()), op=MPI.MAX) <= 1e-14
    assert max_abs(grid, fine - grid.local_part(repeated)) == 0.0


@pytest.mark.parametrize("whole", [False, True])
def test_prolongation_into_the_fine_grids_fft_buffer(comm, whole):
    """``out`` takes the block repeats in its own dtype (a single-precision start into
    a double grid's buffer) and is what is returned: no slab of its own."""
    shape, f = (130, 64), 2
    grid = make_grid(shape, comm, size=(2.0, 1.0))
    coarse = make_grid((65, 32), MPI.COMM_SELF if whole else comm, size=(2.0, 1.0))
    coarse_field = np.random.default_rng(5).standard_normal((65, 32)).astype(np.float32)
    local = coarse_field if whole else coarse.local_part(coarse_field).copy()
    out = grid.scratch()
    fine = prolong(coarse.x_slice.start, grid, local, f, whole=whole, out=out)
    repeated = np.repeat(np.repeat(coarse_field, f, axis=0), f, axis=1).astype(np.float64)
    assert fine is out and fine.dtype == np.float64
    assert np.shares_memory(fine, grid.padded)
    assert max_abs(grid, fine - grid.local_part(repeated)) == 0.0


def test_the_coarse_start_lies_in_the_fine_grids_fft_buffer(comm):
    """The prolonged start borrows the fine grid's real FFT buffer (read once, before the
    first transform) in the grid's precision, instead of a slab of its own."""
    grid = make_grid((128, 128), comm)
    problem = _rough(grid)
    pressure, description = coarse_start_pressure(
        problem, Load(0.05), SolverSettings(tolerance=1e-8, max_iterations=1000), polonsky_keer)
    assert description.startswith("coarse 64x64")
    assert pressure.shape == grid.local_shape and pressure.dtype == grid.dtype
    assert np.shares_memory(pressure, grid.padded)
    assert grid.comm.allreduce(float(pressure.sum())) / grid.npoints == pytest.approx(0.05)


def test_small_coarse_grids_are_solved_whole_on_every_rank(comm, monkeypatch):
    grid = make_grid((256, 256), comm)
    problem = _rough(grid)
    level = coarse_problem(problem)
    assert level.grid.shape == (128, 128)
    assert level.grid.comm.size == (1 if comm.size > 1 else comm.size)
    assert level.grid.comm.allreduce(level.topography.size) == 128 * 128
    monkeypatch.setattr(coarse_module, "WHOLE_POINTS", 0)
    assert coarse_problem(problem).grid.comm.size == comm.size   # spread as the fine grid


def _rough(grid, seed=2):
    h = self_affine(grid, 0.8, 8 * grid.dx, 0.5 * grid.Lx, rms_slope=0.1, seed=seed)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR))


@pytest.mark.parametrize("control", ["load", "mean-gap"])
def test_coarse_start_reaches_the_uniform_start_state_sooner(comm, control):
    grid = make_grid((256, 256), comm)
    problem = _rough(grid)
    ctrl = Load(0.02 * problem.pressure_scale) if control == "load" \
        else MeanGap(0.8 * problem.rms_height)
    tol = 1e-9
    coarse = polonsky_keer(problem, ctrl, SolverSettings(tolerance=tol))
    plain = polonsky_keer(problem, ctrl, SolverSettings(tolerance=tol, coarse_start=False))
    assert coarse.converged and plain.converged
    assert coarse.start.startswith("coarse 128x128:") and "64x64" in coarse.start \
        and "32x32" in coarse.start
    assert plain.start in ("uniform pressure", "overlap of the undeformed surfaces")
    assert coarse.iterations < plain.iterations
    assert_same_state(grid, coarse, plain, *tolerance_scales(problem, tol))
    assert coarse_problem(problem).grid.shape == (128, 128)
    assert coarse_problem(problem) is not coarse_problem(problem)  # not kept: no memory held
    # a start in single precision, the answer in the problem's own
    assert coarse_problem(problem).grid.precision == "single"
    assert coarse_problem(problem).topography.dtype == np.float32
    assert coarse.pressure.dtype == coarse.gap.dtype == np.float64


def test_coarse_levels_of_a_free_boundary_stay_double(comm):
    """The free half-space is double only: its coarse levels are too."""
    from petgap.mechanics.free_half_space import FreeHalfSpace
    grid = make_grid((128, 128), comm)
    h = self_affine(grid, 0.8, 8 * grid.dx, 0.5 * grid.Lx, rms_slope=0.1, seed=2)
    problem = ContactProblem(grid, h, FreeHalfSpace(grid, E_STAR))
    coarse = coarse_problem(problem)
    assert coarse.grid.shape == (64, 64) and coarse.grid.precision == "double"
    assert not coarse.half_space.periodic


@pytest.mark.parametrize("whole_points", [0, None])
@pytest.mark.parametrize("control", ["load", "mean-gap"])
def test_coarse_start_on_two_ranks_equals_one(comm, control, whole_points, monkeypatch):
    """Straddling blocks (130 rows: fine 65 + 65, coarse 33 + 32) sum in another order only;
    with the coarse levels spread over the ranks (``whole_points = 0``) and solved whole
    on every rank (the default for grids this small)."""
    if whole_points is not None:
        monkeypatch.setattr(coarse_module, "WHOLE_POINTS", whole_points)
    shape, size = (130, 64), (2.03125, 1.0)
    serial = make_grid(shape, MPI.COMM_SELF, size=size)
    h = self_affine(serial, 0.8, 8 * serial.dx, 0.5, rms_slope=0.1, seed=3)
    grid = make_grid(shape, comm, size=size)
    one_problem = ContactProblem(serial, h, ElasticHalfSpace(serial, E_STAR))
    many_problem = ContactProblem(grid, grid.local_part(h).copy(), ElasticHalfSpace(grid, E_STAR))
    ctrl = Load(0.02 * one_problem.pressure_scale) if control == "load" \
        else MeanGap(0.8 * one_problem.rms_height)
    one = polonsky_keer(one_problem, ctrl, SolverSettings(tolerance=1e-10))
    many = polonsky_keer(many_problem, ctrl, SolverSettings(tolerance=1e-10))
    assert one.converged and many.converged and one.start.startswith("coarse 65x32")
    assert many.iterations == one.iterations and many.start == one.start
    h0, ps = one_problem.gap_scale, one_problem.pressure_scale
    assert max_abs(grid, many.gap - one.gap[grid.x_slice]) <= 1e-12 * h0
    assert max_abs(grid, many.pressure - one.pressure[grid.x_slice]) <= 1e-12 * ps
    assert many.contact_fraction == one.contact_fraction


def test_coarse_start_on_three_ranks_equals_one(comm, mpi_tmp_path, run_cli):
    """134 rows on 3 ranks: fine 45 + 45 + 44, coarse 23 + 23 + 21: coarse row 22 sums fine
    rows of two ranks, and the two grids' slabs are cut at different rows."""
    shape, size = (134, 64), (2.09375, 1.0)
    serial = make_grid(shape, MPI.COMM_SELF, size=size)
    h = self_affine(serial, 0.8, 8 * serial.dx, 0.5, rms_slope=0.1, seed=6)
    three = solve_on_three_ranks(comm, mpi_tmp_path, run_cli, h, size, solver="polonsky_keer")
    problem = ContactProblem(serial, h, ElasticHalfSpace(serial, E_STAR))
    controls = [Load(0.02 * problem.pressure_scale), MeanGap(0.8 * problem.rms_height)]
    for (gap, pressure, scalars), control in zip(three, controls):
        one = polonsky_keer(problem, control, SolverSettings(tolerance=1e-10))
        assert scalars["ranks"] == 3 and scalars["converged"] and one.converged
        assert one.start.startswith("coarse 67x32")
        assert scalars["iterations"] == one.iterations and scalars["start"] == one.start
        assert np.abs(gap - one.gap).max() <= 1e-12 * problem.gap_scale
        assert np.abs(pressure - one.pressure).max() <= 1e-12 * problem.pressure_scale


def test_coarse_planning_time_is_said_per_level(comm):
    """What planning the coarse grids' FFTs cost is logged where it is spent: per level and
    per cold start (the coarse problems are not kept), with the grid and the planner, which
    is FFTW's "estimate" whatever the fine grid's."""
    import logging  # deferred: only this test listens to the log
    seen = []

    class Listen(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())
    logger = logging.getLogger("petgap.coarse")
    handler, level = Listen(), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        grid = make_grid((256, 256), comm)
        problem = _rough(grid)
        for load in (0.01, 0.02):
            polonsky_keer(problem, Load(load * problem.pressure_scale), SolverSettings(tolerance=1e-8))
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    planned = [m for m in seen if "FFTs planned in" in m]
    # on several ranks the first level, 128^2, is small enough to be solved whole on each
    first = "single, whole on every rank from here down" if comm.size > 1 else "single"
    levels = [f"coarse grid {n}x{n} ({how}) for the start"
              for n, how in ((128, first), (64, "single"), (32, "single"))]
    assert [m.split(":")[0] for m in planned] == levels * 2
    assert all(m.endswith("(estimate)") for m in planned)


def test_the_coarse_tolerance_reaches_the_solvers(comm):
    """``-petgap_coarse_tolerance`` (and the keyword) sets where every coarse level stops:
    looser, the levels take fewer iterations, and the fine solve still converges."""
    from petgap.solvers.dispatch import solve
    from petgap.solvers.mixed_precision import solve_mixed
    problem = _rough(make_grid((256, 256), comm))
    control = Load(0.02 * problem.pressure_scale)
    default = polonsky_keer(problem, control, SolverSettings(tolerance=1e-8))
    loose = solve(problem, control, solver="pcg-pressure", tolerance=1e-8,
                  options={"petgap_coarse_tolerance": "0.05"})
    direct = polonsky_keer(problem, control, SolverSettings(tolerance=1e-8, coarse_tolerance=0.05))
    assert default.converged and loose.converged
    assert loose.start == direct.start != default.start
    assert list(loose.history) == list(direct.history)

    def coarse_iterations(solution):
        return sum(int(part.split(": ")[1].split()[0]) for part in solution.start.split("; "))
    assert coarse_iterations(loose) < coarse_iterations(default)
    mixed = solve(problem, control, tolerance=1e-8, precision="mixed",
                  options={"petgap_coarse_tolerance": "0.05"})
    assert mixed.start == solve_mixed(problem, control, SolverSettings(tolerance=1e-8, coarse_tolerance=0.05, search_precision="single")).start
    assert mixed.start != solve_mixed(problem, control, SolverSettings(tolerance=1e-8, search_precision="single")).start


@pytest.mark.parametrize("value", [0, -1e-3, float("inf"), float("nan"), "1e-3"])
def test_a_coarse_tolerance_that_is_not_positive_is_refused(comm, value):
    problem = _rough(make_grid((64, 64), comm))
    with pytest.raises(ValueError, match=r"coarse_tolerance = .* is not allowed: the tolerance "
                                         r"of the coarse start's solves is a positive number"):
        polonsky_keer(problem, Load(0.02 * problem.pressure_scale), SolverSettings(coarse_tolerance=value))


@pytest.mark.parametrize("ratio", [3.0, 4.0])
def test_a_level_quantity_is_extrapolated_over_the_ratio_of_its_steps(ratio):
    """Steps shrinking by the ratio are continued exactly; steps that do not shrink,
    or change sign, say nothing of the next one; two levels take the ratio as given."""
    step = 0.01   # the last step; the one below it ratio times larger
    values = [1.0, 1.0 + step, 1.0 + step + ratio * step]   # finest first
    expected = pytest.approx(1.0 - step / ratio, rel=0, abs=1e-15)
    assert coarse_module.extrapolated(values, ratio) == expected
    assert coarse_module.extrapolated(values[:2], ratio) == expected
    assert coarse_module.extrapolated([1.0, 1.01, 1.015], ratio) == 1.0   # below is smaller
    assert coarse_module.extrapolated([1.0, 1.01, 1.0], ratio) == 1.0     # sign changes
    assert coarse_module.extrapolated([1.0], ratio) == 1.0
