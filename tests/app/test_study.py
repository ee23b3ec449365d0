"""``petgap study``: one surface on many grids, the ladders, the errors, the command.

Every test makes all its collective calls before its first assertion, so a
failure on one rank cannot leave the other waiting in a collective.
"""
import csv
import json
import math

import numpy as np
import pytest

from petgap.app import study
from petgap.parallel.grid import Grid
from petgap.io.scene import Scene
from petgap.surfaces import resampling
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.statistics import statistics
from conftest import write_shared as write

SIZE = (24.0, 30.0)      # non-square pixels on the source grid: dx = 0.5, dy = 0.75
LAMBDA_MIN = 4.0         # band: |m| <= 6, n <= 7


def gather_all(grid, local):
    return np.concatenate(grid.comm.allgather(np.asarray(local)), axis=0)


def stats_tuple(s):
    return np.array([s.rms_height, s.rms_slope, s.rms_curvature])


# ------------------------------------------------------ one surface, many grids
def test_resample_keeps_the_band_exactly(comm):
    source = Grid((48, 40), size=SIZE, comm=comm, planner="estimate", wisdom=False)
    h = self_affine(source, 0.7, LAMBDA_MIN, 12.0, rms_slope=0.1, seed=5)
    h_global = gather_all(source, h)
    s_source = stats_tuple(statistics(source, h))
    band = resampling.band_spectrum(source, h, LAMBDA_MIN)

    fine = Grid((96, 80), size=SIZE, comm=comm, planner="estimate", wisdom=False)  # 2x finer
    coarse = Grid((17, 15), size=SIZE, comm=comm, planner="estimate", wisdom=False)  # odd, coarser
    h_fine = gather_all(fine, resampling.resample(band, fine))
    h_coarse_local = resampling.resample(band, coarse)
    h_coarse = gather_all(coarse, h_coarse_local)
    s_fine = stats_tuple(statistics(fine, fine.local_part(h_fine)))
    s_coarse = stats_tuple(statistics(coarse, h_coarse_local))
    back = gather_all(source, resampling.resample(
        resampling.band_spectrum(fine, fine.local_part(h_fine), LAMBDA_MIN), source))
    noise = np.random.default_rng(comm.rank).standard_normal(source.local_shape)
    dropped_noise = resampling.band_spectrum(source, noise, LAMBDA_MIN).dropped_power
    # the same seed on the finer grid is another surface (why the study resamples)
    other = gather_all(fine, self_affine(fine, 0.7, LAMBDA_MIN, 12.0, rms_slope=0.1, seed=5))

    scale = np.abs(h_global).max()
    assert band.kx == 6 and band.ky == 7 and band.coefficients.shape == (8, 13)
    # generated: band-limited to round-off.  dropped_power is a relative
    # difference of two sums of squared modes (all, and those in the band),
    # each exact to a few ulp, so round-off leaves up to ~1e-16 (seen: 2.2e-16
    # with some FFTW plans, below 1e-25 with others); 1e-12 is that floor with room for
    # the number of modes, and far below white noise's 0.5
    assert band.dropped_power < 1e-12
    assert dropped_noise > 0.5                   # white noise is not
    # the finer grid samples the same continuous surface: every other point is the source's
    assert np.max(np.abs(h_fine[::2, ::2] - h_global)) < 1e-12 * scale
    # and the round trip through the finer grid gives the source back
    assert np.max(np.abs(back - h_global)) < 1e-12 * scale
    # the coarse grid holds exactly the band's modes and nothing else
    a = np.fft.fft2(h_coarse) / h_coarse.size
    expected = np.zeros_like(a)
    for n in range(band.ky + 1):
        for m in range(-band.kx, band.kx + 1):
            expected[m % 17, n % 15] = band.coefficients[n, m + band.kx]
            expected[-m % 17, -n % 15] = np.conj(band.coefficients[n, m + band.kx])
    assert np.max(np.abs(a - expected)) < 1e-14 * np.abs(expected).max()
    # hence the same statistics on every grid
    np.testing.assert_allclose(s_fine, s_source, rtol=1e-12)
    np.testing.assert_allclose(s_coarse, s_source, rtol=1e-12)
    assert s_source[1] == pytest.approx(0.1, rel=1e-12)
    assert np.max(np.abs(other[::2, ::2] - h_global)) > 0.1 * scale


def test_resample_onto_and_from_single_precision_grids(comm):
    """A band taken on a single-precision grid, and put on one, is the double band to
    float32 round-off."""
    source = Grid((48, 40), size=SIZE, comm=comm, planner="estimate", wisdom=False)
    single = Grid((48, 40), size=SIZE, comm=comm, planner="estimate", wisdom=False,
                  precision="single")
    fine = Grid((96, 80), size=SIZE, comm=comm, planner="estimate", wisdom=False,
                precision="single")
    h = self_affine(source, 0.7, LAMBDA_MIN, 12.0, rms_slope=0.1, seed=5)
    band = resampling.band_spectrum(source, h, LAMBDA_MIN)
    band_single = resampling.band_spectrum(single, h, LAMBDA_MIN)
    h_fine = resampling.resample(band, fine)
    h_fine_global = gather_all(fine, h_fine)
    h_global = gather_all(source, h)
    scale = np.abs(band.coefficients).max()
    assert band_single.coefficients.shape == band.coefficients.shape
    assert np.max(np.abs(band_single.coefficients - band.coefficients)) < 2e-6 * scale
    assert h_fine.dtype == np.float32
    assert np.max(np.abs(h_fine_global[::2, ::2] - h_global)) < 2e-6 * np.abs(h_global).max()


def test_resample_refuses_a_grid_that_cannot_hold_the_band(comm):
    source = Grid((48, 40), size=SIZE, comm=comm, planner="estimate", wisdom=False)
    h = self_affine(source, 0.7, LAMBDA_MIN, 12.0, rms_slope=0.1, seed=5)
    band = resampling.band_spectrum(source, h, LAMBDA_MIN)
    too_coarse = Grid((12, 16), size=SIZE, comm=comm, planner="estimate", wisdom=False)
    other_size = Grid((48, 40), size=(24.0, 31.0), comm=comm, planner="estimate", wisdom=False)
    with pytest.raises(ValueError, match="Nyquist"):
        resampling.resample(band, too_coarse)
    with pytest.raises(ValueError, match="differs"):
        resampling.resample(band, other_size)
    with pytest.raises(ValueError, match="Nyquist"):
        resampling.band_spectrum(source, h, 2 * source.dx)  # band at the source's own Nyquist


# ------------------------------------------------------------------ the ladders
SCENE = """
[grid]
nx = 64
ny = 32
a0 = 0.5

[surface]
hurst = 0.8
lambda_min = "16 a0"
lambda_max = "32 a0"
rms_slope = 0.1
seed = 3

[interaction]
kind = "exponential"
work_of_adhesion = 1e-4
range = "2 a0"

[control]
kind = "mean-gap"
values = ["3 a0"]

[solver]
tolerance = 1e-7
planner = "estimate"
"""


def test_ladders_keep_the_physics(comm):
    scene = Scene.from_text(SCENE, comm)
    tol = study.tolerance_ladder(scene, [1e-6, 1e-4, 1e-8, 1e-6])
    res = study.resolution_ladder(scene, [32, 8, 16, 64, 4.5], max_points=128 * 64)

    assert [r.value for r in tol] == [1e-4, 1e-6, 1e-8]          # loosest first, no repeats
    for r in tol:
        assert r.scene.solver.tolerance == r.value
        assert (r.nx, r.ny, r.a0) == (64, 32, 0.5) and r.scene.grid == scene.grid
        assert r.scene.surface == scene.surface and r.scene.control == scene.control
    assert [r.value for r in res] == [4.5, 8, 16, 32, 64]           # coarsest first
    # L = 32 x 16, lambda_min = 8: nx = r L / lambda_min = 4 r, a0 = 8 / r
    assert [(r.nx, r.ny) for r in res[:4]] == [(18, 9), (32, 16), (64, 32), (128, 64)]
    assert [r.a0 for r in res[1:4]] == [1.0, 0.5, 0.25]
    assert res[0].a0 == pytest.approx(32 / 18)                      # L kept, ratio rounded
    assert res[4].skipped and "--max-points 8192" in res[4].skipped and res[4].scene is None
    for r in res[:4]:
        assert r.skipped is None
        g, s = r.scene.grid, r.scene.surface
        assert g.size == pytest.approx((32.0, 16.0), rel=1e-14)
        assert (s.lambda_min, s.lambda_max, s.rms_slope, s.seed) == (8.0, 16.0, 0.1, 3)
        assert r.scene.interaction.range == 1.0                     # physical, not pixels
        assert r.scene.control.values == (1.5,)
        assert r.scene.solver.tolerance == 1e-7
    # the scene's own grid is the rung 16 a0
    assert res[2].scene.grid == scene.grid
    # an adhesive scene: only double precision solves it, and the ladder says why
    prec = study.precision_ladder(scene)
    assert [r.label for r in prec] == ["single", "mixed", "double"]
    assert all(r.skipped and "non-adhesive" in r.skipped and r.scene is None for r in prec[:2])
    assert prec[2].skipped is None and prec[2].scene.solver == scene.solver
    assert study.quantities_of(scene) == ["c", "d_rep", "mean_pressure", "exponent",
                                          "prefactor", "F_att"]


def test_resolution_ladder_skips_what_it_cannot_build(comm):
    scene = Scene.from_text(SCENE.replace("ny = 32", "ny = 33"), comm)
    res = study.resolution_ladder(scene, [8, 16], max_points=10 ** 6)
    assert res[0].skipped and "square pixels" in res[0].skipped     # Ly = 16.5 at a0 = 1
    assert res[1].skipped is None and (res[1].nx, res[1].ny) == (64, 33)


# ------------------------------------------------------------------- the errors
def test_errors_against_the_most_accurate_converged_rung():
    rows = [{"c": 0.030, "d_rep": 10.0, "exponent": -0.30, "converged": True},
            {"c": 0.033, "d_rep": 11.0, "exponent": None, "converged": True},
            {"skipped": "too big"},
            {"c": 0.040, "d_rep": 12.0, "exponent": -0.33, "converged": True},
            {"c": 0.050, "d_rep": 13.0, "exponent": -0.34, "converged": False}]
    ref = study.apply_errors(rows, ["c", "d_rep", "exponent"])
    assert ref == 3 and rows[3]["reference"] and not rows[4]["reference"]
    assert rows[0]["err_c"] == pytest.approx(0.25)
    assert rows[0]["err_d_rep"] == pytest.approx(1 / 6)
    assert rows[0]["err_exponent"] == pytest.approx(0.03 / 0.33)
    assert math.isnan(rows[1]["err_exponent"])                        # missing value
    assert math.isnan(rows[2]["err_c"])                               # skipped rung
    assert rows[3]["err_c"] == 0.0 and rows[4]["err_c"] == pytest.approx(0.25)
    assert study.relative_error(0.0, 0.0) == 0.0 and study.relative_error(1.0, 0.0) == math.inf
    assert math.isnan(study.relative_error(float("nan"), 1.0))
    # nothing converged: the most accurate rung that ran
    rows = [{"c": 1.0, "converged": False}, {"c": 2.0, "converged": False}, {"skipped": "x"}]
    assert study.apply_errors(rows, ["c"]) == 1 and rows[0]["err_c"] == pytest.approx(0.5)
    assert study.apply_errors([{"skipped": "x"}], ["c"]) is None


# ------------------------------------------------ a whole study, adhesive protocol
def test_study_of_the_papers_protocol(comm):
    text = SCENE.replace('kind = "mean-gap"\nvalues = ["3 a0"]',
                         'kind = "load"\nvalues = [0.004]\nreference = "non-adhesive"')
    text = text.replace("nx = 64\nny = 32", "nx = 32\nny = 32")
    scene = Scene.from_text(text, comm)
    result = study.run_study(scene, comm, tolerances=[1e-5, 1e-7], resolutions=[8, 16])
    table = study.format_table(result)

    tol, res = result.rows["tolerance"], result.rows["resolution"]
    assert result.quantities == ["c", "d_rep", "mean_gap", "exponent", "prefactor", "F_att"]
    assert [r["rung"] for r in tol] == ["1e-05", "1e-07"] and result.references["tolerance"] == 1
    assert [(r["nx"], r["ny"]) for r in res] == [(16, 16), (32, 32)]
    assert res[1]["shared_with"] == "tolerance rung 1e-07"          # the same solve, once
    for r in tol + res:
        assert r["converged"] and r["fft_pairs"] > 0 and r["iterations"] > 0
        assert 0 < r["c"] < 0.5 and r["F_att"] < 0 and r["d_rep"] > 0
        assert r["rms_slope"] == pytest.approx(0.1, rel=1e-12)      # one physical surface
    assert tol[1]["err_F_att"] == 0.0 and tol[0]["err_F_att"] < 1e-2
    assert res[0]["err_c"] > 0 and res[0]["lambda_min_a0"] == 8.0
    assert "tolerance ladder" in table and "resolution ladder" in table and "ref" in table


# -------------------------------------------------------------------- the command
TINY = """
[grid]
nx = 32

[surface]
hurst = 0.8
lambda_min = "8 a0"
rms_slope = 0.1
seed = 3

[control]
kind = "load"
values = [0.005]

[solver]
planner = "estimate"
"""


def test_cli_quick_writes_table_and_figure(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "tiny.toml", TINY)
    out = mpi_tmp_path / "out"
    proc = run_cli(["petgap", "study", scene, "--quick", "--output-dir", out], ranks=2)
    again = run_cli(["petgap", "study", scene, "--quick", "--output-dir", out])
    files = None
    if comm.rank == 0:
        with open(out / "study.csv") as fh:
            rows = list(csv.DictReader(fh))
        files = (rows, json.loads((out / "study.json").read_text()),
                 (out / "study.png").read_bytes()[:8])
    rows, doc, png = comm.bcast(files, root=0)

    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("tolerance ladder at 32 x 32") == 1     # once, by rank 0
    assert "resolution ladder at tolerance 1e-08" in proc.stdout and "err c" in proc.stdout
    assert [(r["ladder"], r["rung"]) for r in rows] == [
        ("tolerance", "1e-04"), ("tolerance", "1e-06"), ("tolerance", "1e-08"),
        ("resolution", "8 a0"), ("resolution", "16 a0"), ("resolution", "32 a0"),
        ("precision", "single"), ("precision", "mixed"), ("precision", "double")]
    assert [r["nx"] for r in rows[3:6]] == ["32", "64", "128"]
    assert [r["reference"] for r in rows] == ["False", "False", "True"] * 3
    assert doc["references"] == {"tolerance": "1e-08", "resolution": "32 a0",
                                 "precision": "double"}
    # single at its tolerance floor, mixed and double at the scene's; double is the
    # tolerance ladder's 1e-08 solve, measured once
    assert [(r["precision"], r["tolerance"]) for r in rows[6:]] == [
        ("single", "3e-06"), ("mixed", "1e-08"), ("double", "1e-08")]
    assert rows[8]["shared_with"] == "tolerance rung 1e-08"
    assert all(r["converged"] == "True" and float(r["err_c"]) < 1e-3 for r in rows[6:8])
    assert "precision ladder at tolerance 1e-08, 32 x 32" in proc.stdout
    assert doc["settings"]["surface_band"]["dropped_power"] < 1e-12  # round-off: see above
    assert png == b"\x89PNG\r\n\x1a\n"
    # an existing output is never overwritten without --overwrite
    assert again.returncode == 2 and "refusing to overwrite" in again.stderr
    assert "study.csv" in again.stderr


@pytest.mark.parametrize("args, named", [
    (["--tolerances", "0.5"], "--tolerances"),
    (["--resolutions", "2"], "--resolutions"),
    (["--max-points", "lots"], "--max-points"),
    (["--fit-range", "0.1", "0.01"], "--fit-range"),
    (["--ladders", "speed"], "--ladders"),
])
def test_cli_bad_options(comm, mpi_tmp_path, run_cli, args, named):
    scene = write(comm, mpi_tmp_path / "tiny.toml", TINY)
    proc = run_cli(["petgap", "study", scene, "--output-dir", mpi_tmp_path / "o"] + args)
    assert proc.returncode == 2, proc.stderr
    assert named in proc.stderr and "error" in proc.stderr


def test_cli_scene_without_control(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "none.toml",
                  TINY.replace('kind = "load"\nvalues = [0.005]', 'kind = "none"'))
    proc = run_cli(["petgap", "study", scene, "--output-dir", mpi_tmp_path / "o"])
    assert proc.returncode == 2 and 'control.kind = "none"' in proc.stderr
