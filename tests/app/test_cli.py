"""The ``petgap`` command, run as a user runs it: ``mpirun -n 2 petgap ...`` in a subprocess."""
import sys
import time

import numpy as np

from petgap.io.results import read_attrs

import h5py  # after petgap.io.results, which selects the MPI build  # noqa: E402
from conftest import write_shared as write

SCENE = """
[grid]
nx = 64
ny = 32

[surface]
hurst = 0.8
lambda_min = "8 a0"
rms_slope = 0.1
seed = 3

[control]
kind = "load"
values = [0.002]

[solver]
planner = "estimate"
"""


def inspect(comm, path):
    """Root attributes, topography and its attributes of a result file, on every rank."""
    out = None
    if comm.rank == 0:
        with h5py.File(path, "r") as f:
            out = (read_attrs(f), f["topography"][...], read_attrs(f["topography"]))
    return comm.bcast(out, root=0)


def test_run_writes_result(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "small.toml", SCENE)
    out = mpi_tmp_path / "small.h5"
    proc = run_cli(["petgap", "run", scene, "--output", out, "--", "-tao_monitor"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert "rms slope" in proc.stdout and "wrote" in proc.stdout
    # progress is reported once (by rank 0), not once per rank
    assert proc.stdout.count("step 0 converged") == 1
    attrs, topography, topo_attrs = inspect(comm, out)
    assert attrs["complete"] is True and attrs["mpi_size"] == 2
    assert attrs["scene"] == SCENE and "petgap run" in attrs["command_line"]
    assert attrs["petsc_options"] == "-tao_monitor"
    assert topography.shape == (64, 32)
    # the statistics stored are those of the topography stored
    assert abs(topography.mean() - topo_attrs["statistics.mean"]) < 1e-12
    assert np.isclose(topography.std(), topo_attrs["statistics.rms_height"], rtol=1e-12)
    assert np.isclose(topo_attrs["statistics.rms_slope"], 0.1, rtol=1e-9)  # surface.rms_slope
    assert topo_attrs["statistics.rms_curvature"] > 0
    step = None
    if comm.rank == 0:
        with h5py.File(out, "r") as f:
            group = f["step_0000"]
            step = (read_attrs(group), group["gap"][...], group["pressure"][...])
    step_attrs, gap, pressure = comm.bcast(step, root=0)
    assert step_attrs["complete"] is True and step_attrs["solution.converged"] is True
    assert step_attrs["solution.reason"] == "converged_kkt"
    assert step_attrs["solution.kkt_gap"] <= 1e-8
    # how the solve started is provenance too (64 x 32 is too small for a coarse grid)
    assert step_attrs["solution.start"] == "uniform pressure"
    assert 0 <= step_attrs["solution.start_time"] <= step_attrs["solution.wall_time"]
    assert np.isclose(pressure.mean(), 0.002, rtol=1e-9)  # the load that was asked
    assert gap.min() >= -1e-8 * topo_attrs["statistics.rms_height"] and pressure.min() >= 0
    assert np.isclose(step_attrs["solution.mean_gap"], gap.mean(), rtol=1e-12)

    # the same scene on one rank gives the same surface
    serial = mpi_tmp_path / "serial.h5"
    proc = run_cli(["petgap", "run", scene, "--output", serial, "--quiet"], ranks=1)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""  # --quiet: warnings and errors only
    np.testing.assert_allclose(inspect(comm, serial)[1], topography, rtol=0, atol=1e-14)


def test_log_view_shows_the_operator_events(comm, mpi_tmp_path, run_cli):
    """``petgap run ... -- -log_view`` prints PETSc's log with petgap's own events."""
    scene = write(comm, mpi_tmp_path / "logged.toml", SCENE)
    proc = run_cli(["petgap", "run", scene, "--output", mpi_tmp_path / "logged.h5", "--quiet",
                    "--", "-log_view", f":{mpi_tmp_path / 'log.txt'}"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    rows = [line.split() for line in (mpi_tmp_path / "log.txt").read_text().splitlines()
            if line.startswith("petgap:")]
    names = {r[0] for r in rows}
    assert {"petgap:operator", "petgap:gapPass", "petgap:setUpdate"} <= names
    assert all(int(r[1]) > 0 for r in rows)


def test_default_output_is_scene_stem_in_cwd(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "stem.toml", SCENE.replace('"load"', '"none"')
                  .replace("values = [0.002]", ""))
    workdir = mpi_tmp_path / "work"
    if comm.rank == 0:
        workdir.mkdir()
    proc = run_cli(["petgap", "run", scene, "-q"], ranks=2, cwd=workdir)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # control.kind = "none": nothing to warn about
    assert (workdir / "stem.h5").is_file()


def test_bad_scene_is_one_clean_error(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "bad.toml", SCENE.replace("hurst = 0.8", "hurst = 1.8"))
    out = mpi_tmp_path / "bad.h5"
    proc = run_cli(["petgap", "run", scene, "--output", out], ranks=2)
    assert proc.returncode == 2
    assert "surface.hurst = 1.8" in proc.stderr and "in (0, 1)" in proc.stderr
    assert proc.stderr.count("petgap: error:") == 1
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_unknown_key_suggestion_on_command_line(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "typo.toml", SCENE.replace("seed", "sed"))
    proc = run_cli(["petgap", "run", scene], ranks=2, cwd=mpi_tmp_path)
    assert proc.returncode == 2
    assert "surface.sed" in proc.stderr and "did you mean surface.seed?" in proc.stderr


def test_missing_scene_file(comm, mpi_tmp_path, run_cli):
    proc = run_cli(["petgap", "run", mpi_tmp_path / "absent.toml"], ranks=2, cwd=mpi_tmp_path)
    assert proc.returncode == 2
    assert "absent.toml not found" in proc.stderr and "Traceback" not in proc.stderr


def test_undecomposable_grid_is_a_clean_error(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "thin.toml", SCENE.replace("nx = 64", "nx = 1")
                  .replace('lambda_min = "8 a0"', 'lambda_min = "8 a0"\nlambda_max = "16 a0"'))
    proc = run_cli(["petgap", "run", scene, "-o", mpi_tmp_path / "thin.h5"], ranks=2)
    assert proc.returncode == 2
    assert "cannot be split over 2 ranks" in proc.stderr and "Traceback" not in proc.stderr


def test_existing_output_is_not_overwritten(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "keep.toml", SCENE)
    out = mpi_tmp_path / "keep.h5"
    proc = run_cli(["petgap", "run", scene, "--output", out], ranks=2)
    assert proc.returncode == 0, proc.stderr
    before = out.read_bytes()
    # the same scene again: its result is complete, nothing to do, no error, no banner
    proc = run_cli(["petgap", "run", scene, "--output", out], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert f"{out} is complete" in proc.stdout and "nothing to do" in proc.stdout
    assert proc.stderr == ""
    assert out.read_bytes() == before
    # another scene: refused, naming the difference
    other = write(comm, mpi_tmp_path / "other.toml", SCENE.replace("seed = 3", "seed = 5"))
    proc = run_cli(["petgap", "run", other, "--output", out], ranks=2)
    assert proc.returncode == 2
    assert str(out) in proc.stderr and "--overwrite" in proc.stderr
    assert f"different scene (surface.seed = 3 in the file, 5 in {other})" in proc.stderr
    assert "MPI_ABORT" not in proc.stderr and "Traceback" not in proc.stderr
    assert out.read_bytes() == before
    # the same values written differently (a comment) are the same scene
    same = write(comm, mpi_tmp_path / "same.toml", "# the same scene\n" + SCENE)
    proc = run_cli(["petgap", "run", same, "--output", out, "-q"], ranks=2)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert out.read_bytes() == before
    time.sleep(1.1)  # a new start_time
    proc = run_cli(["petgap", "run", scene, "--output", out, "--overwrite"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes() != before


def test_failure_on_one_rank_aborts_instead_of_hanging(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "crash.toml", SCENE)
    script = (
        "import sys\n"
        "from mpi4py import MPI\n"
        "import petgap.app.build as build\n"
        "from petgap.app.main import main\n"
        "make_surface = build.make_surface\n"
        "def crash(scene, grid):\n"
        "    if MPI.COMM_WORLD.rank == 1:\n"
        "        raise RuntimeError('rank 1 lost its surface')\n"
        "    h = make_surface(scene, grid)\n"
        "    grid.comm.Barrier()  # rank 0 would wait here forever\n"
        "    return h\n"
        "build.make_surface = crash\n"
        "sys.exit(main(sys.argv[1:]))\n")
    start = time.monotonic()
    proc = run_cli([sys.executable, "-c", script, "run", scene, "-o", mpi_tmp_path / "crash.h5"],
                   ranks=2, env={"PETGAP_FAILURE_TIMEOUT": "2"}, timeout=120)
    assert time.monotonic() - start < 100
    assert proc.returncode != 0
    assert "rank 1 lost its surface" in proc.stderr
    assert "error on rank 1 of 2 only" in proc.stderr


def test_schema_command(comm, run_cli):
    proc = run_cli(["petgap", "schema"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("| `surface.hurst` |") == 1  # printed by rank 0 only


def test_check_command(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "check.toml", SCENE)
    proc = run_cli(["petgap", "check", scene], ranks=1)
    assert proc.returncode == 0, proc.stderr
    assert "lambda_max = 16.0" in proc.stdout and "valid" in proc.stdout


def test_usage_errors(comm, run_cli):
    proc = run_cli(["petgap", "run"], ranks=2)
    assert proc.returncode == 2 and proc.stderr.count("usage:") == 1
    proc = run_cli(["petgap", "schema", "--", "-tao_monitor"], ranks=1)
    assert proc.returncode == 2 and "only for `petgap run`" in proc.stderr


def test_collective_warnings_are_shown_once(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "coarse.toml", SCENE.replace('"8 a0"', '"3 a0"')
                  .replace('"load"', '"none"').replace("values = [0.002]", ""))
    proc = run_cli(["petgap", "run", scene, "-q", "-o", mpi_tmp_path / "coarse.h5"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if "warning:" in line]
    assert len(warnings) == 1 and "lambda_min" in warnings[0], proc.stderr


def test_logging_rank_zero_talks(comm):
    import io
    import logging
    from petgap.parallel.log import EVERY_RANK, configure
    out, err = io.StringIO(), io.StringIO()
    log = configure(comm, stdout=out, stderr=err)
    try:
        log.info("progress %d", 1)
        log.warning("collective warning")
        log.warning("my own slab is odd", extra=EVERY_RANK)
        log.error("broken")
        out, err = out.getvalue(), err.getvalue()
        if comm.rank == 0:
            assert "progress 1" in out and "warning:" not in out
            assert "warning: collective warning" in err and "my own slab" in err
        else:
            assert out == "" and "collective" not in err
            assert f"[rank {comm.rank}/{comm.size}]" in err and "my own slab" in err
        assert "error: broken" in err
        quiet_out = io.StringIO()
        log = configure(comm, quiet=True, stdout=quiet_out, stderr=io.StringIO())
        log.info("hidden")
        assert quiet_out.getvalue() == ""
    finally:
        logging.getLogger("petgap").handlers.clear()


def test_run_from_topography_file(comm, mpi_tmp_path, run_cli):
    heights = np.random.default_rng(5).standard_normal((24, 20))
    if comm.rank == 0:
        (mpi_tmp_path / "data").mkdir()
        np.save(mpi_tmp_path / "data" / "topo.npy", heights)
    scene = write(comm, mpi_tmp_path / "file.toml",
                  '[grid]\nnx = 24\nny = 20\n[surface]\nkind = "file"\npath = "data/topo.npy"\n'
                  '[solver]\nplanner = "estimate"\n')
    out = mpi_tmp_path / "file.h5"
    proc = run_cli(["petgap", "run", scene, "-o", out], ranks=2)
    assert proc.returncode == 0, proc.stderr
    attrs, topography, topo_attrs = inspect(comm, out)
    np.testing.assert_array_equal(topography, heights)
    assert np.isclose(topo_attrs["statistics.rms_height"], heights.std(), rtol=1e-12)
    # a result file is a topography file too (dataset "topography")
    again = write(comm, mpi_tmp_path / "again.toml", f'[grid]\nnx = 24\nny = 20\n[surface]\n'
                  f'kind = "file"\npath = "{out}"\n[solver]\nplanner = "estimate"\n')
    proc = run_cli(["petgap", "run", again, "-o", mpi_tmp_path / "again.h5"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_array_equal(inspect(comm, mpi_tmp_path / "again.h5")[1], heights)
    # a shape mismatch is a clean error on every rank
    wrong = write(comm, mpi_tmp_path / "wrong.toml", '[grid]\nnx = 20\nny = 20\n[surface]\n'
                  'kind = "file"\npath = "data/topo.npy"\n[solver]\nplanner = "estimate"\n')
    proc = run_cli(["petgap", "run", wrong, "-o", mpi_tmp_path / "wrong.h5"], ranks=2)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.count("petgap: error:") == 1
