"""The Reynolds flow through the gaps against closed forms, mass balance, ranks, bad input."""
import json
import sys
import textwrap
import warnings

import numpy as np
import pytest
from mpi4py import MPI

import petgap
from petgap.analysis import open_clusters
from petgap.flow import leakage, leakage_of
from petgap.parallel.grid import Grid


def grid_of(shape, size=None, comm=None):
    return Grid(shape, size=size, comm=comm, planner="estimate", wisdom=False)


def rows_of(grid):
    return np.arange(grid.x_slice.start, grid.x_slice.stop)[:, None]


def slab(grid, field):
    """This rank's rows of a global field."""
    return np.ascontiguousarray(field[grid.x_slice])


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("direction", ["x", "y"])
def test_parallel_plates_exact(comm, periodic, direction):
    """Q = g^3 / (12 mu) dp / L W between plates at gap g: transmissivity g^3, flow factor 1."""
    grid = grid_of((24, 10), size=(48.0, 5.0))
    g, mu, dp = 0.3, 2.5, 7.0
    result = leakage(grid, np.full(grid.local_shape, g), viscosity=mu, pressure_drop=dp,
                     direction=direction, periodic=periodic)
    length, width = (48.0, 5.0) if direction == "x" else (5.0, 48.0)
    assert result.converged and result.percolation.percolates
    assert result.leak_rate == pytest.approx(g ** 3 / (12 * mu) * dp / length * width, rel=1e-9)
    assert result.transmissivity == pytest.approx(g ** 3, rel=1e-9)
    assert result.flow_factor == pytest.approx(1.0, rel=1e-9)
    along = result.flux[0 if direction == "x" else 1]
    assert np.allclose(along, g ** 3 / (12 * mu) * dp / length, rtol=1e-8)
    if not periodic:   # linear pressure from dp at the inlet face to 0 at the outlet face
        n = (24, 10)[0 if direction == "x" else 1]
        centre = ((rows_of(grid) if direction == "x" else np.arange(10)[None, :]) + 0.5) / n
        assert np.allclose(result.pressure, dp * (1 - centre) + 0 * result.pressure,
                           atol=1e-8 * dp)


def sinusoidal_gap(grid, direction, amplitude, mean=1.0):
    n = grid.shape[0 if direction == "x" else 1]
    position = rows_of(grid) if direction == "x" else np.arange(grid.shape[1])[None, :]
    gap = mean * (1 + amplitude * np.sin(2 * np.pi * (position + 0.5) / n))
    return np.broadcast_to(gap, grid.local_shape).copy()


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("direction", ["x", "y"])
def test_sinusoidal_gap_in_series(comm, periodic, direction):
    """Cells in series: the harmonic means of g^3 add up to 1 / <g^-3>, exactly, on either
    boundary (the free map's outer half-pixels are the periodic seam's face split in two)."""
    grid = grid_of((20, 14))
    gap = sinusoidal_gap(grid, direction, 0.6)
    n = grid.shape[0 if direction == "x" else 1]
    cells = 1 + 0.6 * np.sin(2 * np.pi * (np.arange(n) + 0.5) / n)
    result = leakage(grid, gap, direction=direction, periodic=periodic)
    assert result.transmissivity == pytest.approx(1 / np.mean(cells ** -3.0), rel=1e-9)
    # the arithmetic mean of g^3 on the faces would give a different answer
    faces = 0.5 * (cells ** 3 + np.roll(cells, -1) ** 3)
    assert abs(result.transmissivity - 1 / np.mean(1 / faces)) > 1e-3


def test_sinusoidal_gap_continuum_limit(comm):
    """<(1 + a sin)^-3> = (1 + a^2 / 2) / (1 - a^2)^(5/2): the discrete answer converges to it."""
    a = 0.5
    exact = (1 - a ** 2) ** 2.5 / (1 + a ** 2 / 2)
    errors = []
    for n in (8, 16, 64):
        grid = grid_of((n, 4))
        result = leakage(grid, sinusoidal_gap(grid, "x", a), periodic=True)
        errors.append(abs(result.transmissivity / exact - 1))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-12       # the midpoint rule on a periodic smooth function


def checkerboard(grid, block, k1, k2):
    i = rows_of(grid) // block
    j = np.arange(grid.shape[1])[None, :] // block
    return np.where((i + j) % 2 == 0, k1, k2) ** (1 / 3)


def test_checkerboard_keller_dykhne(comm):
    """A 50/50 checkerboard of conductivities k1, k2 conducts sqrt(k1 k2) (Keller 1964,
    Dykhne 1970).  The corners' field singularity makes the pixels converge slowly, as a
    power of the block size; the Aitken extrapolation of three block sizes meets it."""
    k1, k2 = 1.0, 16.0
    values = []
    for block in (16, 32, 64):
        grid = grid_of((2 * block, 2 * block))
        values.append(leakage(grid, checkerboard(grid, block, k1, k2)).transmissivity)
    exact = np.sqrt(k1 * k2)
    assert values[0] < values[1] < values[2] < exact
    d1, d2 = values[1] - values[0], values[2] - values[1]
    limit = values[2] - d2 ** 2 / (d2 - d1)
    assert limit == pytest.approx(exact, rel=0.01)
    # neither the arithmetic nor the harmonic mean, which a wrong face rule would approach
    assert abs(values[2] - 0.5 * (k1 + k2)) > 1 and abs(values[2] - 2 / (1 / k1 + 1 / k2)) > 1


@pytest.fixture(scope="module")
def rough_contact():
    """A self-affine contact at about 10 % contact: open clusters, pockets and all."""
    grid = grid_of((64, 48))
    h = petgap.self_affine(grid, 0.8, 8.0, rms_slope=0.1, seed=3)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    solution = petgap.solve(problem, petgap.Load(0.005), tolerance=1e-10)
    assert 0.05 < solution.contact_fraction < 0.3
    return problem, solution


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("direction", ["x", "y"])
def test_mass_conservation(comm, rough_contact, periodic, direction):
    """The flux through every cross-section is the same (inflow = outflow) to the solver's
    tolerance, and no fluid crosses a closed pixel."""
    problem, solution = rough_contact
    result = leakage(problem.grid, solution.gap, direction=direction, periodic=periodic)
    assert result.converged and result.percolation.percolates
    assert result.conservation < 1e-7
    assert result.inflow == pytest.approx(result.outflow, rel=1e-7)
    # Wiener's upper bound: no arrangement of the pixels conducts more than their mean g^3
    mean_cube = comm.allreduce(float(np.sum(solution.gap ** 3))) / problem.grid.npoints
    assert 0 < result.transmissivity < mean_cube
    closed = solution.gap <= result.percolation.gap_tolerance
    assert np.all(result.flux[0][closed] == 0) and np.all(result.flux[1][closed] == 0)
    assert np.all(np.isnan(result.pressure[closed]))


def test_leakage_of_a_solution(comm, rough_contact):
    """leakage_of takes the grid, gap, boundary and mean gap from the problem and solution."""
    problem, solution = rough_contact
    direct = leakage(problem.grid, solution.gap, viscosity=3.0, pressure_drop=2.0)
    of = leakage_of(problem, solution, viscosity=3.0, pressure_drop=2.0)
    assert of.leak_rate == pytest.approx(direct.leak_rate, rel=1e-12)
    assert of.mean_gap == pytest.approx(solution.mean_gap, rel=1e-12)
    assert of.flow_factor == pytest.approx(of.transmissivity / solution.mean_gap ** 3)


def test_ranks_agree_with_one_rank(comm, rough_contact):
    """The run's ranks against every rank's own serial solve of the gathered gap."""
    problem, solution = rough_contact
    full = problem.grid.gather(solution.gap)
    full = comm.bcast(full, root=0)
    serial_grid = grid_of(problem.grid.shape, comm=MPI.COMM_SELF)
    for periodic in (True, False):
        many = leakage(problem.grid, solution.gap, periodic=periodic)
        one = leakage(serial_grid, full, periodic=periodic)
        assert many.leak_rate == pytest.approx(one.leak_rate, rel=1e-8)
        assert many.percolation.clusters == one.percolation.clusters
        assert np.allclose(many.pressure, slab(problem.grid, one.pressure), atol=1e-7,
                           equal_nan=True)


SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from mpi4py import MPI
    import petgap
    from petgap.flow import leakage

    grid = petgap.Grid((90, 70), comm=MPI.COMM_WORLD, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 6.0, rms_slope=0.1, seed=11)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    solution = petgap.solve(problem, petgap.Load(0.02), tolerance=1e-10)
    out = {}
    for periodic in (True, False):
        for direction in "xy":
            r = leakage(grid, solution.gap, periodic=periodic, direction=direction)
            out[f"{periodic}-{direction}"] = [r.leak_rate, r.percolation.clusters,
                                              r.percolation.largest_fraction]
    if MPI.COMM_WORLD.rank == 0:
        print("RESULT", json.dumps(out))
""")


def test_one_two_three_ranks(comm, mpi_tmp_path, run_cli):
    """The same leak rates and clusters on 1, 2 and 3 ranks (an uneven split: 90 rows)."""
    if comm.rank == 0:
        (mpi_tmp_path / "flow.py").write_text(SCRIPT)
    comm.Barrier()
    results = []
    for ranks in (1, 2, 3):
        done = run_cli([sys.executable, mpi_tmp_path / "flow.py"], ranks=ranks, timeout=120)
        assert done.returncode == 0, done.stderr[-3000:]
        line = [t for t in done.stdout.splitlines() if t.startswith("RESULT")][0]
        results.append(json.loads(line.split(" ", 1)[1]))
    for key, (leak, clusters, largest) in results[0].items():
        for other in results[1:]:
            assert other[key][0] == pytest.approx(leak, rel=1e-8), key
            assert other[key][1:] == [clusters, largest], key


def test_sealed_band_leaks_nothing(comm):
    """A closed band across the flow: zero leakage, no solve, and the reason in words."""
    grid = grid_of((16, 12))
    gap = np.full(grid.local_shape, 0.5)
    gap[(rows_of(grid) == 7)[:, 0]] = 0.0
    for periodic in (True, False):
        result = leakage(grid, gap, periodic=periodic)
        assert result.leak_rate == 0 and result.flow_factor == 0
        assert result.reason == "no_percolation" and result.iterations == 0
        assert "does not percolate" in result.message
        assert not result.percolation.percolates
        assert result.percolation.largest_fraction == pytest.approx(0.5 if not periodic
                                                                    else 15 / 16)
        # along the band it leaks (a channel on each side on the free map)
        along = leakage(grid, gap, periodic=periodic, direction="y")
        assert along.percolation.percolates and along.transmissivity == pytest.approx(
            0.5 ** 3 * 15 / 16, rel=1e-9)
    closed = leakage(grid, np.zeros(grid.local_shape))
    assert closed.leak_rate == 0 and "whole map is closed" in closed.message


def test_wrapping_on_the_periodic_cell(comm):
    """A channel that crosses the seam along x but winds round y only carries no x flow on
    the periodic cell; a diagonal channel that closes a loop along x does."""
    n = 16
    grid = grid_of((n, n))
    i, j = np.broadcast_arrays(rows_of(grid), np.arange(n)[None, :])
    diagonal = np.where((i - j) % n < 3, 1.0, 0.0)        # wraps along x and along y
    result = leakage(grid, diagonal)
    assert result.percolation.percolates and result.leak_rate > 0
    assert result.conservation < 1e-8
    # a closed ring round y (row band) cuts every x path: the channel part is bounded in x
    band = np.where((i % n >= 2) & (i % n < 6), 1.0, 0.0)
    clusters = open_clusters(grid, band, direction="x")
    assert clusters.clusters == 1 and not clusters.percolates
    assert open_clusters(grid, band, direction="y").percolates


def test_dead_ends_and_pockets(comm):
    """On a free map a pocket is left out (no pressure) and a dead end off the inlet sits at
    the inlet pressure; the leak is that of the straight channel alone."""
    grid = grid_of((12, 9))
    i, j = np.broadcast_arrays(rows_of(grid), np.arange(9)[None, :])
    gap = np.zeros(grid.local_shape)
    gap[j == 4] = 1.0                              # the channel, inlet to outlet
    gap[(j == 1) & (i < 5)] = 1.0                  # a dead end off the inlet
    gap[(j == 7) & (i > 3) & (i < 8)] = 1.0        # a sealed pocket
    result = leakage(grid, gap, periodic=False, pressure_drop=2.0)
    assert result.transmissivity == pytest.approx(1.0 / 9, rel=1e-9)
    assert np.all(result.pressure[(j == 1) & (i < 5)] == 2.0)
    assert np.all(np.isnan(result.pressure[(j == 7) & (i > 3) & (i < 8)]))
    assert result.percolation.clusters == 3
    assert int(np.count_nonzero(result.percolation.spanning)) == 1


@pytest.mark.parametrize("kwargs, words", [
    ({"viscosity": 0.0}, "viscosity = 0.0"),
    ({"viscosity": -1.0}, "viscosity = -1.0"),
    ({"pressure_drop": 0.0}, "pressure_drop = 0.0"),
    ({"pressure_drop": float("nan")}, "pressure_drop = nan"),
    ({"direction": "z"}, "direction = 'z'"),
])
def test_bad_input_is_refused_on_every_rank(comm, kwargs, words):
    grid = grid_of((8, 8))
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        leakage(grid, np.ones(grid.local_shape), **kwargs)


def test_direction_on_a_map_too_small(comm):
    grid = grid_of((8, 1), comm=MPI.COMM_SELF)   # one column splits over no two ranks
    with pytest.raises(ValueError, match="1 pixel along y"):
        leakage(grid, np.ones(grid.local_shape), direction="y")


def test_adhesive_solution_is_warned_about(comm):
    grid = grid_of((32, 32))
    h = petgap.self_affine(grid, 0.8, 8.0, rms_slope=0.1, seed=3)
    law = petgap.ExponentialAdhesion(1e-4, 0.5)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid), law)
    solution = petgap.solve(problem, petgap.MeanGap(0.5), tolerance=1e-8)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        leakage_of(problem, solution)
    assert any("interaction range 0.5" in str(w.message) for w in caught)


def test_petsc_options_reach_the_solve(comm, rough_contact):
    """-flow_pc_type and -flow_ksp_rtol go through the prefix; the answer does not change."""
    problem, solution = rough_contact
    gamg = leakage_of(problem, solution, options={"flow_pc_type": "gamg"})
    hypre = leakage_of(problem, solution, options={"flow_pc_type": "hypre",
                                                   "flow_ksp_rtol": "1e-11"})
    assert gamg.pc_type == "gamg" and hypre.pc_type == "hypre"
    assert hypre.leak_rate == pytest.approx(gamg.leak_rate, rel=1e-8)


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("direction", ["x", "y"])
def test_flux_pieces_are_the_whole_fluxes(comm, periodic, direction):
    """The balance check sums the fluxes a few rows at a time (beside the multigrid
    hierarchy): the pieces, put together, are the whole fields, on any split of the rows."""
    from petgap.flow.reynolds import Faces, face_fluxes, flux_pieces
    grid = grid_of((13, 9))
    rng = np.random.default_rng(5)
    k = slab(grid, rng.uniform(0.1, 2.0, (13, 9)))
    u = slab(grid, rng.uniform(0.0, 1.0, (13, 9)))
    axis = 0 if direction == "x" else 1
    faces = Faces(grid, k, axis, periodic)
    whole = face_fluxes(grid, faces, u, axis, periodic)
    for rows in (1, 2, 5, 100):
        pieces = list(flux_pieces(grid, faces, u, axis, periodic, rows))
        assert [lo for lo, *_ in pieces] == list(range(0, max(len(u), 1), rows))
        for field, part in zip(whole, zip(*(fluxes for _, *fluxes in pieces))):
            np.testing.assert_array_equal(np.concatenate(part), field)
