"""Stability at the extremes: each case converges to the right answer, or says why not.

Every rank asserts on its own data (``mpirun -n 2``); each test's docstring
states its pass criterion.  Tolerances are solver-tolerance or round-off scales
named next to them, not margins found by trial.  The 3-rank case and the
user-level sticky run go through the ``petgap`` command in a subprocess with a
timeout, so that no case can hang the suite.
"""
import math
import time

import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.grid import DecompositionError, Grid
from petgap.io.results import read_attrs
from petgap.mechanics.interactions import ExponentialAdhesion, check_resolution
from petgap.io.scene import Scene, SceneError
from petgap.solvers.dispatch import solve
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.statistics import statistics

import h5py  # after petgap.io.results, which selects the MPI build  # noqa: E402
from conftest import write_shared as write

E_STAR = 2.5  # not 1: a misplaced E* must show
TOL = 1e-9


# ------------------------------------------------------------------ helpers
def make_grid(shape, comm, size=None):
    return Grid(shape, size=size, comm=comm, planner="estimate")


def gmax(grid, local):
    return grid.comm.allreduce(float(np.max(local, initial=-np.inf)), op=MPI.MAX)


def gmin(grid, local):
    return grid.comm.allreduce(float(np.min(local, initial=np.inf)), op=MPI.MIN)


def gcount(grid, mask):
    return grid.comm.allreduce(int(np.count_nonzero(mask)), op=MPI.SUM)


def global_indices(grid, mask):
    """Sorted global ``(i, j)`` of the points where ``mask`` holds, on every rank."""
    i, j = np.nonzero(mask)
    local = [(int(a) + grid.x_slice.start, int(b)) for a, b in zip(i, j)]
    return sorted(p for part in grid.comm.allgather(local) for p in part)


def global_argmax(grid, local):
    """Global ``(i, j)`` of the largest value (the first of equal ones), on every rank."""
    if local.size:
        k = int(np.argmax(local))
        mine = (float(local.flat[k]), -(grid.x_slice.start * grid.ny + k))
    else:
        mine = (-np.inf, 0)
    value, neg = max(grid.comm.allgather(mine))
    return divmod(-neg, grid.ny)


def rough(grid, hurst=0.8, lambda_min_px=8, lambda_max=None, seed=3, interaction=None):
    h = self_affine(grid, hurst, lambda_min_px * grid.dx,
                    lambda_max or 0.5 * min(grid.Lx, grid.Ly), rms_slope=0.1, seed=seed)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR), interaction)


def tolerance_scales(problem, tol):
    """How far two states, each converged to ``tol``, may lie apart (as in test_contact).

    Gap: the pressure error ``tol h0' E*`` turned into a displacement at the
    longest wavelength, ``tol h0' L / pi`` (or ``tol h0``); pressure: a gap
    error ``tol h0`` held by the stiffness of one pixel, ``E* tol h0 / dx``.
    Both doubled: each state carries its own error.
    """
    grid = problem.grid
    gap = 2 * tol * max(problem.rms_slope * max(grid.Lx, grid.Ly) / math.pi, problem.rms_height)
    pressure = 2 * tol * E_STAR * problem.rms_height / min(grid.dx, grid.dy)
    return gap, pressure


def assert_hard_wall_solution(problem, sol, load, tol=TOL):
    """Converged, KKT within ``tol``, feasible, and carrying the load asked for."""
    grid = problem.grid
    assert sol.converged, sol.reason
    assert sol.kkt_pressure <= tol and sol.kkt_gap <= tol, (sol.kkt_pressure, sol.kkt_gap)
    assert gmin(grid, sol.gap) >= -tol * problem.gap_scale
    assert gmin(grid, sol.pressure) >= -tol * problem.pressure_scale
    assert abs(sol.mean_pressure - load) <= tol * problem.pressure_scale
    assert gcount(grid, ~np.isfinite(sol.gap) | ~np.isfinite(sol.pressure)) == 0


def assert_same_state(problem, a, b, tol=TOL):
    grid = problem.grid
    gap_tol, p_tol = tolerance_scales(problem, tol)
    assert gmax(grid, np.abs(a.gap - b.gap)) <= gap_tol
    assert gmax(grid, np.abs(a.pressure - b.pressure)) <= p_tol
    assert abs(a.mean_gap - b.mean_gap) <= gap_tol


def read_steps(comm, path):
    """Root attributes and ``{index: (attrs, {field: array})}`` of a result file, everywhere."""
    out = None
    if comm.rank == 0:
        with h5py.File(path, "r") as f:
            steps = {int(k[5:]): (read_attrs(f[k]), {n: f[k][n][...] for n in f[k]})
                     for k in f if k.startswith("step_")}
            out = (read_attrs(f), f["topography"][...] if "topography" in f else None, steps)
    return comm.bcast(out, root=0)


# -------------------------------------------------------------- Hurst extremes
@pytest.mark.parametrize("hurst", [0.05, 0.95])
def test_extreme_hurst_exponents_solve(comm, hurst):
    """H = 0.05 and 0.95: the surface has the asked rms slope, and the pressure (PK)
    and gap formulations, and load vs mean-gap control, give the same converged state."""
    grid = make_grid((64, 64), comm)
    problem = rough(grid, hurst=hurst, lambda_min_px=4, seed=11)
    stats = statistics(grid, problem.topography)
    assert stats.rms_slope == pytest.approx(0.1, rel=1e-12)
    load = 0.02 * problem.pressure_scale
    by_pressure = solve(problem, Load(load), solver="pcg-pressure", tolerance=TOL)
    by_gap = solve(problem, Load(load), solver="pcg-gap", tolerance=TOL)
    assert_hard_wall_solution(problem, by_pressure, load)
    assert_hard_wall_solution(problem, by_gap, load)
    assert 0 < by_pressure.contact_fraction < 0.5
    assert_same_state(problem, by_pressure, by_gap)
    by_mean_gap = solve(problem, MeanGap(by_pressure.mean_gap), tolerance=TOL)
    assert by_mean_gap.converged, by_mean_gap.reason
    assert abs(by_mean_gap.mean_pressure - load) <= 2 * TOL * problem.pressure_scale
    assert_same_state(problem, by_pressure, by_mean_gap)


# ----------------------------------------------------------- tiny contact
def test_single_pixel_and_handful_contact_at_highest_summit(comm):
    """A load so small that one pixel touches: converged; that pixel is the highest
    point of the surface and carries the whole force (p = P0 N there, 0 elsewhere);
    both formulations agree.  Raising the load grows the contact from there
    (never losing the summit): a handful of pixels, all at the wall, at the top."""
    grid = make_grid((64, 64), comm)
    problem = rough(grid, seed=5)
    top = global_argmax(grid, problem.topography)
    n = grid.npoints
    load = 1e-6 * problem.pressure_scale
    states = {s: solve(problem, Load(load), solver=s, tolerance=TOL)
              for s in ("pcg-pressure", "pcg-gap")}
    for sol in states.values():
        assert_hard_wall_solution(problem, sol, load)
        contact = (sol.gap <= 0) & (sol.pressure > 0)
        assert global_indices(grid, contact) == [top], sol.solver
        assert round(sol.contact_fraction * n) == 1
        # the one pixel carries the whole load, to the solver tolerance
        p_top = grid.comm.allreduce(float(sol.pressure[contact].sum()), op=MPI.SUM)
        assert p_top == pytest.approx(load * n, rel=1e-9)
        assert gmax(grid, np.where(contact, 0.0, np.abs(sol.pressure))) \
            <= TOL * problem.pressure_scale
    assert_same_state(problem, *states.values())

    counts, previous = [], None
    for factor in (1e-5, 1e-4, 3e-4):
        sol = solve(problem, Load(factor * problem.pressure_scale), tolerance=TOL,
                    initial=previous)
        assert_hard_wall_solution(problem, sol, factor * problem.pressure_scale)
        contact = (sol.gap <= 0) & (sol.pressure > 0)
        assert top in global_indices(grid, contact)
        counts.append(gcount(grid, contact))
        previous = sol
    assert counts == sorted(counts) and 1 <= counts[0] and counts[-1] <= 0.01 * n, counts
    assert counts[-1] > 1  # a handful, not one pixel any more


# -------------------------------------------------------- near full contact
def test_near_full_contact_is_consistent_with_the_load(comm):
    """Full contact has an exact threshold: with g = 0 everywhere p = P0 + K h, so the
    contact is complete iff P0 >= P_full = -min(K h).  Pass: every solve converges
    (pressure and gap formulations); c grows with the load, exceeds 0.95 well below
    P_full, is < 1 below P_full and exactly 1 above it, where p = P0 + K h to
    round-off; the last open pixel is where K h is lowest; the mean gap falls to 0;
    mean-gap control at the mean gap found gives the load back."""
    grid = make_grid((64, 64), comm)
    problem = rough(grid, seed=2)
    kh = problem.elastic_pressure(np.zeros(grid.local_shape)).copy()
    p_full = -gmin(grid, kh)
    deepest = global_argmax(grid, -kh)
    fractions, mean_gaps = [], []
    for factor in (0.3, 0.7, 0.9, 0.99, 1.001, 1.5):
        load = factor * p_full
        pair = [solve(problem, Load(load), solver=s, tolerance=TOL, max_iterations=2000)
                for s in ("pcg-pressure", "pcg-gap")]
        for sol in pair:
            assert_hard_wall_solution(problem, sol, load)
            assert sol.iterations <= 200  # no slow-down near full contact
        assert_same_state(problem, *pair)
        sol = pair[0]
        c = sol.contact_fraction
        fractions.append(c)
        mean_gaps.append(sol.mean_gap)
        if factor < 1:
            assert c < 1 and sol.mean_gap > 0
            open_points = global_indices(grid, sol.gap > 0)
            assert deepest in open_points
            if factor >= 0.9:
                assert c > 0.95
                back = solve(problem, MeanGap(sol.mean_gap), tolerance=TOL)
                assert back.converged, back.reason
                assert abs(back.mean_pressure - load) <= 1e-6 * load
        else:
            assert c == 1.0 and sol.mean_gap == 0.0
            # p = P0 + K h exactly, up to the round-off of one transform pair
            assert gmax(grid, np.abs(sol.pressure - (load + kh))) <= 1e-11 * p_full
    assert fractions == sorted(fractions), fractions
    assert mean_gaps == sorted(mean_gaps, reverse=True), mean_gaps


# ------------------------------------------------------------- wavelengths
def test_lambda_min_two_pixels_warns_unresolved(comm):
    """lambda_min = 2 a0 (Nyquist) is allowed but warned about, on every rank, with a
    message that says it is not resolved; the surface still has the asked slope and
    solves.  Below 2 a0 the scene is refused, naming the Nyquist limit."""
    grid = make_grid((64, 64), comm)
    with pytest.warns(UserWarning, match=r"lambda_min = 2 is 2 pixels.*not resolved"):
        h = self_affine(grid, 0.8, 2.0, 32.0, rms_slope=0.1, seed=7)
    assert statistics(grid, h).rms_slope == pytest.approx(0.1, rel=1e-12)
    problem = ContactProblem(grid, h, ElasticHalfSpace(grid, E_STAR))
    load = 0.02 * problem.pressure_scale
    assert_hard_wall_solution(problem, solve(problem, Load(load), tolerance=TOL), load)
    text = '[grid]\nnx = 64\n[surface]\nhurst = 0.8\nlambda_min = "{}"\n'
    Scene.from_text(text.format("2 a0"), comm)  # valid
    with pytest.raises(SceneError, match=r"surface.lambda_min = 1.5.*Nyquist.*>= 2 a0"):
        Scene.from_text(text.format("1.5 a0"), comm)


def test_lambda_max_equal_to_system_size(comm):
    """lambda_max = L is valid (L + a0 is refused), puts power into the longest
    wavelength of the cell, shifts weight to long wavelengths relative to the default
    L / 2 (same random draws: larger h0 / h0'), and solves."""
    text = '[grid]\nnx = 64\n[surface]\nhurst = 0.8\nlambda_min = "8 a0"\nlambda_max = "{}"\n'
    scene = Scene.from_text(text.format("64 a0"), comm)
    assert scene.surface.lambda_max == 64.0
    with pytest.raises(SceneError, match="surface.lambda_max = 65.*larger than the system"):
        Scene.from_text(text.format("65 a0"), comm)
    grid = make_grid((64, 64), comm)
    h_full = self_affine(grid, 0.8, 8.0, 64.0, rms_slope=0.1, seed=4)
    h_half = self_affine(grid, 0.8, 8.0, 32.0, rms_slope=0.1, seed=4)
    c = grid.forward(h_full)
    q = grid.q_magnitude()
    longest = np.isclose(q, 2 * np.pi / grid.Lx)
    assert grid.comm.allreduce(float(np.sum(np.abs(c[longest]) ** 2)), op=MPI.SUM) > 0
    full, half = statistics(grid, h_full), statistics(grid, h_half)
    assert full.rms_slope == pytest.approx(0.1, rel=1e-12)
    assert full.rms_height / full.rms_slope > half.rms_height / half.rms_slope
    problem = ContactProblem(grid, h_full, ElasticHalfSpace(grid, E_STAR))
    load = 0.02 * problem.pressure_scale
    assert_hard_wall_solution(problem, solve(problem, Load(load), tolerance=TOL), load)


# ---------------------------------------------------------------- zero load
def test_zero_load(comm):
    """Hard wall, any solver: the touching state (gap 0 at the highest point only,
    no pressure, no iterations).  Adhesive: the zero-load state converges, touches,
    and its force balances, F_rep + F_att = A0 P0 = 0, with attraction and wall
    reaction both non-zero."""
    grid = make_grid((64, 64), comm)
    problem = rough(grid, seed=8)
    top = global_argmax(grid, problem.topography)
    for solver in ("pcg", "pcg-gap", "blmvm"):
        sol = solve(problem, Load(0.0), solver=solver)
        assert sol.converged and sol.reason == "zero_load" and sol.iterations == 0
        assert global_indices(grid, sol.gap <= 0) == [top]
        assert gmax(grid, np.abs(sol.pressure)) == 0.0 and sol.contact_fraction == 0.0
    adhesion = ExponentialAdhesion(1e-3 * E_STAR, 1.0)
    sticky = ContactProblem(grid, problem.topography, problem.half_space, adhesion)
    sol = solve(sticky, Load(0.0), tolerance=TOL)
    assert sol.converged, sol.reason
    assert abs(sol.mean_pressure) <= TOL * sticky.pressure_scale
    assert sol.contact_fraction > 0 and sol.attractive_force < 0 < sol.repulsive_force
    assert abs(sol.repulsive_force + sol.attractive_force) \
        <= TOL * sticky.pressure_scale * grid.area


# -------------------------------------------------------------- sticky cases
STICKY = [(0.01, 1.0), (0.05, 10.0), (0.001, 100.0)]  # (rho / a0, w / (E* a0))


@pytest.mark.parametrize("rho, work", STICKY)
def test_sticky_adhesion_ends_within_the_iteration_limit(comm, rho, work):
    """Very short range, very large work of adhesion (unresolved, multistable): each
    solve ends within max_iterations -- the limit of the whole step, outer secant
    included -- and either converged (KKT within tolerance, load or mean gap met) or
    says it did not: converged=False, a reason, a finite state.  The grid check
    warns that the interaction is not resolved."""
    grid = make_grid((32, 32), comm)
    base = rough(grid, seed=9)
    adhesion = ExponentialAdhesion(work * E_STAR, rho)
    with pytest.warns(UserWarning, match="not resolved"):
        check_resolution(adhesion, grid.dx, E_STAR)
    problem = ContactProblem(grid, base.topography, base.half_space, adhesion)
    limit = 150
    for control in (Load(0.02 * problem.pressure_scale), Load(0.0),
                    MeanGap(0.5 * problem.rms_height)):
        start = time.perf_counter()
        sol = solve(problem, control, tolerance=1e-8, max_iterations=limit)
        assert time.perf_counter() - start < 60
        assert sol.iterations <= limit, (control, sol.iterations)
        assert gcount(grid, ~np.isfinite(sol.gap) | ~np.isfinite(sol.pressure)) == 0
        assert gmin(grid, sol.gap) >= 0
        if sol.converged:
            assert sol.reason == "converged_kkt" and sol.kkt_pressure <= 1e-8
            if isinstance(control, Load):
                assert abs(sol.mean_pressure - control.value) <= 1e-8 * problem.pressure_scale
            else:
                assert abs(sol.mean_gap - control.value) <= 1e-8 * problem.gap_scale
        else:
            assert sol.reason and not sol.reason.startswith("converged"), sol.reason


def test_sticky_scene_reports_non_convergence(comm, mpi_tmp_path, run_cli):
    """The same through ``petgap run``: warned as unresolved, finished well within the
    timeout, exit 0, and the step is stored with its verdict -- converged=False with a
    reason and a warning saying so, or converged with its KKT residual in tolerance."""
    scene = write(comm, mpi_tmp_path / "sticky.toml", """
[grid]
nx = 32

[surface]
hurst = 0.8
lambda_min = "8 a0"
seed = 9

[interaction]
kind = "exponential"
work_of_adhesion = 10.0
range = "0.05 a0"

[control]
kind = "load"
values = [0.002]

[solver]
max_iterations = 150
planner = "estimate"
""")
    out = mpi_tmp_path / "sticky.h5"
    proc = run_cli(["petgap", "run", scene, "-o", out], ranks=2, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "interaction not resolved" in proc.stderr
    _, _, steps = read_steps(comm, out)
    attrs = steps[0][0]
    assert attrs["complete"] is True and attrs["solution.iterations"] <= 150
    if attrs["solution.converged"]:
        assert attrs["solution.kkt_pressure"] <= 1e-8
    else:
        reason = attrs["solution.reason"]
        assert reason and not reason.startswith("converged")
        assert f"step 0 did not converge: {reason}" in proc.stderr


# ------------------------------------------------------------ degenerate grids
@pytest.mark.parametrize("shape", [(64, 1), (1, 64)])
def test_one_pixel_wide_grid(comm, shape):
    """A 1-pixel-wide grid cannot be split into two slabs (64 x 1 has one Fourier row,
    1 x 64 one real row): every rank raises the same DecompositionError naming the
    grid, the rank count and the rows each rank would get.  On one rank (COMM_SELF)
    it is a line-contact problem, and must equal the same profile extruded to a
    2-pixel-wide grid, to round-off, under load and mean-gap control."""
    with pytest.raises(DecompositionError) as info:
        make_grid(shape, comm)
    message = str(info.value)
    assert f"a {shape[0]} x {shape[1]} grid cannot be split over {comm.size} ranks" in message
    assert ("Fourier rows [1, 0]" if shape[1] == 1 else "real-space rows [1, 0]") in message

    axis = 1 if shape[1] == 1 else 0
    thin = make_grid(shape, MPI.COMM_SELF)
    wide_shape = tuple(2 if s == 1 else s for s in shape)
    wide = make_grid(wide_shape, MPI.COMM_SELF)
    x = np.arange(64) * 2 * np.pi / 64
    profile = 0.3 * np.cos(x) + 0.1 * np.cos(3 * x + 1) + 0.05 * np.sin(7 * x)
    h_thin = profile.reshape(shape)
    h_wide = np.repeat(h_thin, 2, axis=axis)
    thin_problem = ContactProblem(thin, h_thin.copy(), ElasticHalfSpace(thin, E_STAR))
    wide_problem = ContactProblem(wide, h_wide.copy(), ElasticHalfSpace(wide, E_STAR))
    for control in (Load(0.05 * thin_problem.pressure_scale),
                    MeanGap(0.5 * thin_problem.rms_height)):
        a = solve(thin_problem, control, tolerance=TOL)
        b = solve(wide_problem, control, tolerance=TOL)
        assert a.converged and b.converged, (a.reason, b.reason)
        assert 0 < a.contact_fraction < 1
        assert a.contact_fraction == b.contact_fraction
        scale = thin_problem.rms_height
        np.testing.assert_allclose(np.repeat(a.gap, 2, axis=axis), b.gap, rtol=0,
                                   atol=1e-12 * scale)
        np.testing.assert_allclose(np.repeat(a.pressure, 2, axis=axis), b.pressure, rtol=0,
                                   atol=1e-12 * thin_problem.pressure_scale * 10)


# ----------------------------------------------------------- uneven slabs
UNEVEN = """
[grid]
nx = 100
ny = 60
a0 = 0.5

[surface]
hurst = 0.7
lambda_min = "6 a0"
seed = 21

[material]
contact_modulus = 2.5

[control]
kind = "load"
values = [0.003, 0.012]

[solver]
tolerance = 1e-10
planner = "estimate"
"""


def test_three_ranks_on_two_cores_uneven_slabs(comm, mpi_tmp_path, run_cli):
    """``mpirun -n 3`` (oversubscribed) on 100 x 60: FFTW-MPI gives blocks of
    ceil(100 / 3) = 34 real rows (34/34/32) and ceil(31 / 3) = 11 Fourier rows
    (11/11/9).  Pass: the run completes, and its surface, fields, iterations and
    scalars equal a 1-rank solve of the same scene to round-off."""
    scene_path = write(comm, mpi_tmp_path / "uneven.toml", UNEVEN)
    out = mpi_tmp_path / "uneven.h5"
    proc = run_cli(["petgap", "run", scene_path, "-o", out, "-q"], ranks=3, timeout=180)
    assert proc.returncode == 0, proc.stderr[-3000:]
    attrs, topography, steps = read_steps(comm, out)
    assert attrs["complete"] is True and attrs["mpi_size"] == 3

    scene = Scene.from_text(UNEVEN, MPI.COMM_SELF)
    serial = make_grid((100, 60), MPI.COMM_SELF, size=scene.grid.size)
    s = scene.surface
    h = self_affine(serial, s.hurst, s.lambda_min, s.lambda_max, rms_slope=s.rms_slope,
                    seed=s.seed)
    np.testing.assert_allclose(topography, h, rtol=0, atol=1e-14 * np.abs(h).max())
    problem = ContactProblem(serial, h, ElasticHalfSpace(serial, 2.5))
    previous = None
    for index, load in enumerate(scene.control.values):
        sol = solve(problem, Load(load), tolerance=1e-10, initial=previous)
        previous = sol
        step_attrs, fields = steps[index]
        assert step_attrs["complete"] is True and step_attrs["solution.converged"] is True
        assert step_attrs["solution.iterations"] == sol.iterations
        assert step_attrs["solution.contact_fraction"] == sol.contact_fraction
        assert step_attrs["solution.mean_gap"] == pytest.approx(sol.mean_gap, rel=1e-12)
        np.testing.assert_allclose(fields["gap"], sol.gap, rtol=0,
                                   atol=1e-12 * problem.gap_scale)
        np.testing.assert_allclose(fields["pressure"], sol.pressure, rtol=0,
                                   atol=1e-12 * problem.pressure_scale)


def test_full_contact_load_is_westergaards(comm):
    """P_full of a sinusoid h0 cos(2 pi x / L) is Westergaard's p* = pi E* h0 / L."""
    from petgap.solvers.contact_limits import full_contact_load  # deferred: one test needs it
    grid = make_grid((64, 16), comm, size=(3.0, 0.75))
    x, _ = grid.local_positions()
    h = 0.02 * np.cos(2 * np.pi * x / 3.0)
    problem = ContactProblem(grid, h, contact_modulus=E_STAR)
    assert full_contact_load(problem) == pytest.approx(np.pi * E_STAR * 0.02 / 3.0, rel=1e-12)


@pytest.mark.parametrize("factor", [1.0, 1e3, 1e300])
def test_loads_beyond_full_contact_need_no_iteration(comm, factor):
    """At or beyond P_full = -min(K h) the solution is known: gap 0, p = P0 + K h.  It is
    returned at once (reason full_contact), also for a load of 1e300 E*, where an
    iterative solver would run to its limit as its contact set grows to every point."""
    grid = make_grid((32, 32), comm)
    problem = rough(grid, seed=4)
    kh = problem.elastic_pressure(np.zeros(grid.local_shape)).copy()
    p_full = -gmin(grid, kh)
    load = min(factor * p_full, 1e300 * E_STAR)
    before = problem.operator_applications
    sol = solve(problem, Load(load), tolerance=TOL, max_iterations=5)
    assert sol.converged and sol.reason == "full_contact" and sol.iterations == 0
    assert sol.operator_applications == problem.operator_applications - before
    assert gmax(grid, np.abs(sol.gap)) == 0.0
    # at P_full exactly the deepest point touches with p = 0: not in repulsive contact
    assert sol.contact_fraction == (1.0 if factor > 1 else 1.0 - 1.0 / grid.npoints)
    assert gmax(grid, np.abs(sol.pressure - (load + kh))) <= 1e-12 * max(load, p_full)
    assert sol.mean_pressure == pytest.approx(load, rel=1e-12)
    below = solve(problem, Load(0.999 * p_full), tolerance=TOL, max_iterations=2000)
    assert below.converged and below.reason != "full_contact" and below.contact_fraction < 1


@pytest.mark.parametrize("solver", ["pcg-pressure", "pcg-gap"])
def test_monitor_objective_is_what_the_solver_minimises(comm, solver):
    """A monitor that asks for the objective (as -tao_monitor does) gets, every iteration,
    the functional the solver minimises: for the pressure solver the complementary energy
    (1/2) <p, K^-1 p> - <p, h> (load control), for the gap solver the elastic energy plus
    the load's work P0 sum(g) dx dy.  Its final value equals the same functional
    computed independently from the solution's fields, and it falls overall."""
    grid = make_grid((48, 48), comm)
    problem = rough(grid, seed=5)
    load = 0.01 * E_STAR
    seen = []

    def monitor(it, residual, objective=None):
        seen.append((it, residual, objective))
    monitor.wants_objective = True
    sol = solve(problem, Load(load), solver=solver, tolerance=TOL, monitor=monitor)
    assert sol.converged and len(seen) >= 3
    assert all(f is not None and math.isfinite(f) for _, _, f in seen)
    values = [f for _, _, f in seen]
    assert values[-1] < values[0]
    area = grid.pixel_area
    if solver == "pcg-pressure":
        u = problem.displacement(sol.pressure).copy()
        expected = area * (0.5 * grid.sum(sol.pressure * u) - grid.sum(sol.pressure * problem.topography))
    else:
        pel = problem.elastic_pressure(sol.gap).copy()
        expected = area * (0.5 * grid.sum(pel * (sol.gap + problem.topography))
                           + load * grid.sum(sol.gap))
    assert values[-1] == pytest.approx(expected, rel=1e-6)
    plain = []
    solve(problem, Load(load), solver=solver, tolerance=TOL,
          monitor=lambda it, residual: plain.append(it))   # no objective asked: 2 arguments
    assert plain
