"""``petgap.contact``: the one-call solve on a global height array.

It must give what the objects give when built by hand, the analytic result where
there is one, the same state on any number of ranks, and argument errors that
name the argument on every rank.  Tolerances follow ``tests/solvers/test_contact.py``:
discretisation scales for the analytic check, round-off (1e-12 of the natural
scales) where only the order of sums changes.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

import petgap
from petgap import reference_solutions as ref

E_STAR = 2.5  # not 1: a misplaced E* must show

# The Westergaard set-up of tests/solvers/test_contact.py: 512 pixels per wavelength.
WG = dict(amplitude=0.02, wavelength=3.0, contact_modulus=E_STAR)
WG_SHAPE = (512, 4)

# Odd, non-square, a rank with few rows (as the rank tests of test_contact.py).
RANK_SHAPE, RANK_SIZE = (75, 50), (1.5, 1.0)


def max_abs(comm, local):
    return comm.allreduce(float(np.max(np.abs(local), initial=0.0)), op=MPI.MAX)


def sinusoid():
    """The global Westergaard wave ``h = ha cos(2 pi x / lambda)``, its positions and pixel."""
    nx, ny = WG_SHAPE
    dx = WG["wavelength"] / nx
    x = np.arange(nx) * dx
    h = WG["amplitude"] * np.cos(2 * np.pi * x / WG["wavelength"])
    return np.repeat(h[:, None], ny, axis=1), x, dx


def rough_heights(seed=4):
    """A self-affine surface as a global array, the same on every rank (drawn on COMM_SELF)."""
    serial = petgap.Grid(RANK_SHAPE, size=RANK_SIZE, comm=MPI.COMM_SELF, planner="estimate")
    h = petgap.self_affine(serial, 0.8, 8 * serial.dx, 0.75, rms_slope=0.1, seed=seed)
    return h, (serial.dx, serial.dy)


@pytest.mark.parametrize("fraction", [0.1, 0.5])
def test_westergaard(comm, fraction):
    """Partial contact of a sinusoid (Johnson 1985, section 13.2), to discretisation error."""
    h, x, dx = sinusoid()
    ha, lam = WG["amplitude"], WG["wavelength"]
    eps = dx / lam
    p_star = ref.westergaard_full_contact_pressure(**WG)
    load = fraction * p_star
    r = petgap.contact(h, dx, load=load, contact_modulus=E_STAR, comm=comm, tolerance=1e-10,
                       max_iterations=2000)
    assert r.converged and r.reason == "converged_kkt", (r.reason, r.iterations)
    assert r.mean_pressure == pytest.approx(load, rel=1e-12)
    assert abs(r.mean_gap - ref.westergaard_mean_gap(load, **WG)) <= ha * eps ** 1.5
    a = ref.westergaard_contact_half_width(load, **WG)
    assert abs(r.contact_fraction * lam - 2 * a) <= 2 * dx  # each edge within a pixel
    # The global fields on every rank, against the closed forms one pixel across the edge.
    assert r.gap.shape == r.pressure.shape == WG_SHAPE
    err = r.pressure - ref.westergaard_pressure(x, load, **WG)[:, None]
    assert math.sqrt(np.mean(err ** 2)) <= p_star * eps
    assert np.max(np.abs(err)) <= ref.westergaard_pressure(a - dx, load, **WG)
    gap_err = r.gap - ref.westergaard_gap(x, load, **WG)[:, None]
    assert np.max(np.abs(gap_err)) <= ref.westergaard_gap(a + dx, load, **WG)
    assert r.rms_height == pytest.approx(ha / math.sqrt(2), rel=1e-12)
    assert r.attractive_force == 0


@pytest.mark.parametrize("control", ["load", "mean_gap"])
def test_matches_the_objects_built_by_hand(comm, control):
    """The same grid, problem and solve, made by hand, give the same bits."""
    h, (dx, dy) = rough_heights()
    grid = petgap.Grid(h.shape, size=(h.shape[0] * dx, h.shape[1] * dy), comm=comm,
                       planner="estimate")
    problem = petgap.ContactProblem(grid, grid.local_part(h).copy(),
                                    petgap.ElasticHalfSpace(grid, E_STAR))
    value = (0.02 * problem.pressure_scale if control == "load" else 0.8 * problem.rms_height)
    by_hand = petgap.solve(problem, petgap.Load(value) if control == "load"
                           else petgap.MeanGap(value), tolerance=1e-10)
    stats = petgap.contact_statistics(grid, by_hand.gap, by_hand.pressure, problem.rms_slope,
                                      E_STAR)
    r = petgap.contact(h, (dx, dy), contact_modulus=E_STAR, comm=comm, tolerance=1e-10,
                       fields="local", **{control: value})
    assert r.converged and by_hand.converged
    assert r.fields == "local" and r.rows == grid.x_slice
    assert np.array_equal(r.gap, by_hand.gap) and np.array_equal(r.pressure, by_hand.pressure)
    scalars = by_hand.scalars()
    for key in ("contact_fraction", "mean_gap", "mean_pressure", "converged", "reason",
                "iterations", "kkt_pressure", "kkt_gap", "attractive_force", "repulsive_force"):
        assert getattr(r, key) == scalars[key], key
    assert r.rms_height == problem.rms_height and r.rms_slope == problem.rms_slope
    assert (r.perimeter, r.mean_diameter, r.g0) == (stats.perimeter, stats.mean_diameter, stats.g0)
    assert r.statistics == stats
    assert r.scalars()["g0"] == stats.g0 and math.isfinite(stats.g0)


def test_adhesion_by_work_and_range(comm):
    """``work_of_adhesion`` and ``interaction_range`` make the problem's ExponentialAdhesion."""
    h, (dx, dy) = rough_heights()
    grid = petgap.Grid(h.shape, size=(h.shape[0] * dx, h.shape[1] * dy), comm=comm,
                       planner="estimate")
    rho = 2 * dx
    w = 0.1 * E_STAR * rho ** 2 / dx  # process zone E* rho^2 / w = 10 pixels: resolved
    adhesion = petgap.ExponentialAdhesion(w, rho)
    problem = petgap.ContactProblem(grid, grid.local_part(h).copy(),
                                    petgap.ElasticHalfSpace(grid, E_STAR), adhesion)
    gap = 0.8 * problem.rms_height
    by_hand = petgap.solve(problem, petgap.MeanGap(gap), tolerance=1e-8)
    r = petgap.contact(h, (dx, dy), mean_gap=gap, contact_modulus=E_STAR, comm=comm,
                       work_of_adhesion=w, interaction_range=rho)
    assert r.problem.interaction == adhesion
    assert r.converged and by_hand.converged
    assert r.attractive_force == by_hand.attractive_force < 0
    force = petgap.attractive_force_of(r.problem, r.solution)
    assert force.force == pytest.approx(r.attractive_force, rel=1e-12)
    assert np.array_equal(r.gap[grid.x_slice], by_hand.gap)


def test_rank_independent(comm):
    """On all ranks of ``comm`` the state is the one solved on ``COMM_SELF``, to round-off."""
    h, pixel = rough_heights()
    kwargs = dict(contact_modulus=E_STAR, tolerance=1e-10)
    for control in ({"load": 0.02 * 0.1 * E_STAR}, {"mean_gap": 0.01}):
        many = petgap.contact(h, pixel, comm=comm, **control, **kwargs)
        one = petgap.contact(h, pixel, comm=MPI.COMM_SELF, **control, **kwargs)
        h0, ps = one.problem.gap_scale, one.problem.pressure_scale
        assert one.converged and many.converged
        assert np.max(np.abs(many.gap - one.gap)) <= 1e-12 * h0
        assert np.max(np.abs(many.pressure - one.pressure)) <= 1e-12 * ps
        assert many.mean_gap == pytest.approx(one.mean_gap, rel=1e-12, abs=1e-12 * h0)
        assert many.mean_pressure == pytest.approx(one.mean_pressure, rel=1e-12)
        assert many.contact_fraction == one.contact_fraction
        assert many.iterations == one.iterations
        assert many.mean_diameter == pytest.approx(one.mean_diameter, rel=1e-12)
        assert many.g0 == pytest.approx(one.g0, rel=1e-12)
        # every rank holds the same global fields
        assert max_abs(comm, many.gap - comm.bcast(many.gap, root=0)) == 0


def test_local_fields_are_rows_of_the_global_ones(comm):
    h, pixel = rough_heights()
    glob = petgap.contact(h, pixel, load=0.005, comm=comm)
    loc = petgap.contact(h, pixel, load=0.005, comm=comm, fields="local")
    assert glob.rows == slice(0, h.shape[0]) and glob.gap.shape == h.shape
    assert np.array_equal(glob.gap[loc.rows], loc.gap)
    assert np.array_equal(glob.pressure[loc.rows], loc.pressure)
    assert loc.scalars() == glob.scalars()


def _error(comm, **kwargs):
    """The ValueError message ``petgap.contact`` raises, checked to be raised on every rank."""
    h, pixel = rough_heights()
    args = dict(heights=h, pixel_size=pixel, load=0.005, comm=comm)
    args.update(kwargs)
    with pytest.raises(ValueError) as info:
        petgap.contact(args.pop("heights"), args.pop("pixel_size"), **args)
    return str(info.value)


@pytest.mark.parametrize("kwargs, words", [
    (dict(load=None), ["exactly one of load, mean_gap"]),
    (dict(mean_gap=0.01), ["exactly one of load, mean_gap"]),
    (dict(load=None, mean_gap=-1.0), ["mean_gap", "-1.0"]),
    (dict(load=float("nan")), ["load", "nan"]),
    (dict(load=-0.01), ["load", "hard wall"]),
    (dict(heights=np.ones(8)), ["heights", "2D", "(8,)"]),
    (dict(heights=None), ["heights", "None"]),
    (dict(heights=[["a"]]), ["heights", "numbers"]),
    (dict(heights=np.full((8, 8), np.nan)), ["heights", "non-finite"]),
    (dict(pixel_size=0.0), ["pixel_size", "positive"]),
    (dict(pixel_size=(0.1, -0.1)), ["pixel_size[1]", "positive"]),
    (dict(pixel_size="a"), ["pixel_size"]),
    (dict(contact_modulus=-1), ["contact_modulus", "positive"]),
    (dict(work_of_adhesion=0.1), ["work_of_adhesion", "interaction_range"]),
    (dict(work_of_adhesion=0.1, interaction_range=0.1,
          interaction=petgap.HardWall()), ["interaction", "not both"]),
    (dict(interaction="sticky"), ["interaction", "sticky"]),
    (dict(fields="everywhere"), ["fields", "everywhere"]),
])
def test_bad_arguments_name_the_argument(comm, kwargs, words):
    message = _error(comm, **kwargs)
    for word in words:
        assert word in message, message


def test_bad_heights_on_one_rank_raise_on_every_rank(comm):
    """A rank whose array differs (or is missing) stops every rank, naming it."""
    h, pixel = rough_heights()
    mine = h if comm.rank == 0 else h + 1.0
    if comm.size > 1:
        assert "heights differ between rank 0 and rank 1" in _error(comm, heights=mine)
        missing = h if comm.rank == 0 else None
        assert "(on rank 1)" in _error(comm, heights=missing)
    loads = 0.005 * (1 + comm.rank)
    if comm.size > 1:
        assert "arguments differ between rank 0 and rank 1" in _error(comm, load=loads)


# ------------------------------------------------ measured maps: one boundary rule
TOP = __import__("pathlib").Path(__file__).resolve().parents[1] / "data" / "topographies" \
    / "top-1.top"   # WSxM, 256 x 256 pixels over 600 x 600 nm, not periodic


def test_a_measured_map_is_free_with_its_size_and_unit(comm):
    """A file or a SurfaceTopography topography is solved as ``petgap run`` solves it: on a
    free boundary (the file does not say it is periodic), with its pixel size and unit;
    an array stays a periodic cell unless told otherwise."""
    from petgap.surfaces.measured import surface_topography
    measured = petgap.read_measured(TOP)
    topography = surface_topography().read_topography(str(TOP))
    load = 0.01 * 0.165
    by_path = petgap.contact(TOP, load=load, comm=comm)
    by_topography = petgap.contact(topography, load=load, comm=comm)
    in_um = petgap.contact(topography, load=load, unit="um", comm=comm)
    by_array = petgap.contact(measured.heights, 600 / 256, load=load, periodic=False, comm=comm)
    as_cell = petgap.contact(measured.heights, 600 / 256, load=load, comm=comm)
    assert measured.heights.shape == (256, 256) and measured.unit == "nm"
    assert measured.physical_size == pytest.approx((600.0, 600.0)) and not measured.periodic
    for r in (by_path, by_topography):
        assert not r.periodic and r.unit == "nm" and r.converged
        assert r.problem.grid.dx == pytest.approx(600 / 256)
        assert r.contact_fraction == by_array.contact_fraction
        assert r.mean_gap == pytest.approx(by_array.mean_gap, rel=1e-12)
    assert in_um.unit == "um" and in_um.problem.grid.dx == pytest.approx(0.6 / 256)
    assert in_um.mean_gap == pytest.approx(1e-3 * by_array.mean_gap, rel=1e-6)
    assert as_cell.periodic and as_cell.unit is None
    assert as_cell.contact_fraction != by_array.contact_fraction


def test_a_measured_map_takes_the_users_word(comm):
    """``periodic`` and ``pixel_size`` given override what the file says; a unit for a
    bare array is refused, naming it."""
    r = petgap.contact(TOP, 1.0, load=0.002, periodic=True, comm=comm)
    with pytest.raises(ValueError, match="unit = 'nm' is given for an array"):
        petgap.contact(np.ones((8, 8)), load=0.1, unit="nm", comm=comm)
    assert r.periodic and r.problem.grid.dx == 1.0 and r.converged


# ------------------------------------------------------------- no silent stalls
class _Lines:
    """The ``petgap`` logger's lines while it is in force (rank 0 logs INFO)."""

    def __init__(self):
        import logging
        self.logger, self.lines = logging.getLogger("petgap"), []
        self.handler = logging.Handler()
        self.handler.emit = lambda record: self.lines.append(record.getMessage())

    def __enter__(self):
        self.level = self.logger.level
        self.logger.addHandler(self.handler)
        self.logger.setLevel("INFO")
        return self.lines

    def __exit__(self, *exc):
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.level)


def test_adhesive_free_load_reports_progress_and_ends_in_a_verdict(comm, monkeypatch, capfd):
    """Adhesive load control on a free boundary (one gap solve on the padded cell, from
    the hard wall's state at the load): the iterations are reported with the residual
    against the target and the time, and the solve ends in a verdict within its iteration
    limit: converged, or -- with too few iterations -- max_iterations, said as a warning.
    ``-petgap_coarse_start 0`` keeps the coarse ladder off; ``-tao_monitor`` prints."""
    from petgap.solvers import progress
    monkeypatch.setattr(progress, "PROGRESS_INTERVAL", 0.0)   # every iteration, for the test
    grid = petgap.Grid((64, 64), comm=MPI.COMM_SELF, planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.8, 8.0, 32.0, rms_slope=0.1, seed=1)
    adhesion = dict(periodic=False, work_of_adhesion=0.05 * float(h.std()),
                    interaction_range=1.0, load=0.002, comm=comm)
    with _Lines() as lines:
        done = petgap.contact(h, 1.0, max_iterations=2000, **adhesion)
    said, lines[:] = list(lines), []
    with _Lines() as lines:
        cut = petgap.contact(h, 1.0, max_iterations=10, **adhesion)
    cut_said, lines[:] = list(lines), []
    with _Lines() as lines:
        plain = petgap.contact(h, 1.0, max_iterations=2000, options={
            "petgap_coarse_start": 0, "tao_monitor": None}, **adhesion)
    printed = capfd.readouterr().out
    assert done.converged and done.iterations <= 2000
    assert plain.converged and plain.iterations <= 2000
    if comm.rank == 0:
        assert any("iteration" in line and "(target 1e-08)" in line for line in said)
        assert any(line.startswith("solve converged after") for line in said)
        assert any("coarse grid" in line for line in said)
        assert not any("coarse grid" in line for line in lines)
        assert "TAO,  Function value" in printed
    assert not cut.converged and cut.reason == "max_iterations" and cut.iterations <= 10
    if comm.rank == 0:
        assert any("NOT converged (max_iterations)" in line for line in cut_said)
