"""Inputs that must end in a clear error or warning, never in an internal error.

PETSc options (unknown names, malformed values, ``--strict``), absurd grids and
the memory estimate; each is run as a user runs it where the point is what the
user sees (``petgap run`` in a subprocess).
"""
import io
import logging
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import clean_env, wait_for_root
from conftest import write_shared as write
from petgap.app.build import (BYTES_PER_POINT_FLOW, BYTES_PER_POINT_FREE,
                              BYTES_PER_POINT_PRESSURE, BYTES_PER_POINT_PRESSURE_SINGLE,
                              BYTES_PER_POINT_SOLVE, check_options, check_size)
from petgap.io.scene import Scene, SceneError
from petgap.solvers.options import check_petsc_options

SCENE = """
[grid]
nx = 32

[surface]
hurst = 0.8
lambda_min = "8 a0"
seed = 3

[control]
kind = "load"
values = [0.002]

[solver]
planner = "estimate"
{solver}
"""


def test_petsc_option_values_are_parsed_as_petsc_does():
    errors, unknown = check_petsc_options({
        "tao_max_it": "notanumber", "tao_max_funcs": "1e3", "tao_gatol": "1e-x",
        "tao_grtol": "1e-9", "petgap_coarse_start": "maybe", "tao_monitor": "",
        "-tao_view": "ascii:view.txt", "tao_catol": "", "options_left": "no",
        "tao_bncg_type": "ssml_bfgs", "tao_ls_type": "armijo", "help": "yes"})
    assert [(n, v, p) for n, v, p, _ in errors] == [
        ("tao_max_it", "notanumber", "is not an integer"),
        ("tao_gatol", "1e-x", "is not a number"),
        ("petgap_coarse_start", "maybe", "is not a boolean"),
        ("tao_catol", "", "has no value"),
        ("help", "yes", "takes no value")]
    assert unknown == []
    errors, unknown = check_petsc_options({"tao_monitr": "", "tao_max_iter": "5",
                                           "totally_unknown": "1"})
    assert errors == []
    assert unknown == [("tao_monitr", "tao_monitor"), ("tao_max_iter", "tao_max_it"),
                       ("totally_unknown", None)]


def test_check_options_names_the_source(comm):
    scene = Scene.from_text(SCENE.format(solver='petsc_options = {tao_max_it = "many"}'), comm)
    with pytest.raises(SceneError, match=r"-tao_max_it 'many' \(solver.petsc_options\): "
                                         r"is not an integer"):
        check_options(scene)
    scene = Scene.from_text(SCENE.format(solver=""), comm)
    with pytest.raises(SceneError, match=r"-tao_type 'lbfgs' \(the command line after --\)"):
        check_options(scene, ["-tao_type", "lbfgs"])
    with pytest.raises(SceneError, match=r"-tao_monitr .*did you mean -tao_monitor\?.*--strict"):
        check_options(scene, ["-tao_monitr"], strict=True)
    stream = io.StringIO()
    log = logging.getLogger("petgap-test-inputs")
    log.addHandler(logging.StreamHandler(stream))
    log.propagate = False
    check_options(scene, ["-tao_monitr", "-tao_max_it", "7"], log=log)
    assert "-tao_monitr (the command line after --) is not read by petgap" in stream.getvalue()
    assert "tao_max_it" not in stream.getvalue()


def test_petsc_options_on_the_command_line(comm, mpi_tmp_path, run_cli):
    """A misspelt option is a warning naming it (an error with --strict, before the result
    file is made); a malformed value is an error naming option and value, not PETSc's
    error code."""
    scene = write(comm, mpi_tmp_path / "s.toml", SCENE.format(solver=""))
    out = mpi_tmp_path / "warn.h5"
    proc = run_cli(["petgap", "run", scene, "-o", out, "-q", "--", "-tao_monitr"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("warning: PETSc option -tao_monitr") == 1  # once, by rank 0
    assert "did you mean -tao_monitor?" in proc.stderr and out.exists()

    cases = [(["--strict", "--", "-tao_monitr"], ["-tao_monitr", "--strict"]),
             (["--", "-tao_max_it", "notanumber"], ["-tao_max_it 'notanumber'",
                                                    "is not an integer"]),
             (["--", "-tao_gatol", "small"], ["-tao_gatol 'small'", "is not a number"])]
    for i, (extra, fragments) in enumerate(cases):
        out = mpi_tmp_path / f"bad{i}.h5"
        proc = run_cli(["petgap", "run", scene, "-o", out] + extra, ranks=2)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count("petgap: error:") == 1 and "internal error" not in proc.stderr
        assert all(f in proc.stderr for f in fragments), proc.stderr
        assert "making the surface" not in proc.stdout and not out.exists()

    bad = write(comm, mpi_tmp_path / "bad.toml",
                SCENE.format(solver='petsc_options = {petgap_coarse_start = "perhaps"}'))
    proc = run_cli(["petgap", "run", bad, "-o", mpi_tmp_path / "bad.h5"], ranks=2)
    assert proc.returncode == 2
    assert ("-petgap_coarse_start 'perhaps' (solver.petsc_options): is not a boolean"
            in proc.stderr), proc.stderr
    assert not Path(mpi_tmp_path / "bad.h5").exists()


def test_slab_beyond_the_index_range_names_the_grid(comm):
    scene = Scene.from_text(SCENE.format(solver="").replace("nx = 32", "nx = 46341"), comm)
    if comm.size == 1:
        with pytest.raises(SceneError, match=r"grid.nx = 46341, grid.ny = 46341: a rank's slab "
                                             r".*run on at least 2 ranks"):
            check_size(scene, comm)
    huge = Scene.from_text(SCENE.format(solver="").replace("nx = 32", "nx = 1000000000"),
                           comm)
    with pytest.raises(SceneError, match=r"grid.nx = 1000000000, grid.ny = 1000000000: .*"
                                         r"beyond the 2147483647 points"):
        check_size(huge, comm)


def test_memory_estimate_refuses_what_cannot_fit(comm):
    """32768^2 needs some 60 GB in all for the pressure solver: more than any test machine has."""
    scene = Scene.from_text(SCENE.format(solver="").replace("nx = 32", "nx = 32768"), comm)
    with pytest.raises(SceneError) as info:
        check_size(scene, comm)
    message = str(info.value)
    gib = 32768 * 32768 // comm.size * BYTES_PER_POINT_PRESSURE / 2**30
    assert f"needs about {gib:.3g} GiB per rank" in message, message
    assert "MemAvailable" in message and "more ranks" in message and "smaller grid" in message
    small = Scene.from_text(SCENE.format(solver=""), comm)
    assert check_size(small, comm) == 32 * 32 // comm.size * BYTES_PER_POINT_PRESSURE
    # the pressure solver in single precision, and the solvers on the gap
    single = Scene.from_text(SCENE.format(solver='precision = "single"\ntolerance = 3e-6'), comm)
    assert check_size(single, comm) == 32 * 32 // comm.size * BYTES_PER_POINT_PRESSURE_SINGLE
    gap = Scene.from_text(SCENE.format(solver='tao_type = "bncg"'), comm)
    assert check_size(gap, comm) == 32 * 32 // comm.size * BYTES_PER_POINT_SOLVE
    # a free boundary adds the padded cell (and solves adhesion on it)
    text = SCENE.format(solver="")
    assert "[surface]\n" in text
    free = Scene.from_text(text.replace("[surface]\n", "[surface]\nperiodic = false\n"), comm)
    assert check_size(free, comm) == 32 * 32 // comm.size * BYTES_PER_POINT_FREE
    # a flow step: its multigrid, not the contact solve, sets the peak
    flow = Scene.from_text(text + '\n[flow]\nkind = "reynolds"\n', comm)
    assert check_size(flow, comm) == 32 * 32 // comm.size * BYTES_PER_POINT_FLOW


def test_memory_refusal_under_an_address_space_limit(comm, mpi_tmp_path):
    """``ulimit -v`` of about 2 GB and a 32768^2 scene: exit 2 within seconds, the message
    gives the estimate, MemAvailable, the address-space limit and what to do, and no
    result file is made (run as a user runs it, under mpirun)."""
    scene = write(comm, mpi_tmp_path / "big.toml",
                  SCENE.format(solver="").replace("nx = 32", "nx = 32768"))
    out = mpi_tmp_path / "big.h5"
    command = f"ulimit -v 2000000; mpirun -n 2 --oversubscribe petgap run {scene} -o {out}"

    def run():
        start = time.monotonic()
        proc = subprocess.run(["bash", "-c", command], capture_output=True, text=True,
                              timeout=120, env=clean_env())
        return proc, time.monotonic() - start
    proc, seconds = wait_for_root(run)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr
    assert err.count("petgap: error:") == 1 and "internal error" not in err, err
    assert "grid.nx = 32768, grid.ny = 32768" in err and "GiB per rank on 2 ranks" in err
    assert "MemAvailable" in err and "address space left under its limit (ulimit -v)" in err
    assert "use more ranks" in err and "a smaller grid" in err
    assert "planning FFTs" not in proc.stdout and not out.exists()
    assert seconds < 30


CHECK_SCENE = """
[grid]
nx = 16
ny = 12

[surface]
kind = "file"
path = "{path}"

[control]
kind = "load"
values = [0.002]
"""


def test_check_reads_the_topography_file(comm, mpi_tmp_path, run_cli):
    """``petgap check`` refuses what ``petgap run`` would about the file, before any solve:
    an unrecognised format, a line scan, the wrong shape, integer heights, undefined points,
    a 3D array; and describes a good file."""
    rng = np.random.default_rng(4)
    files = {
        "good.npy": lambda p: np.save(p, rng.standard_normal((16, 12))),
        "notes.txt": lambda p: p.write_text("measured on a Tuesday\n"),
        "line.txt": lambda p: p.write_text("\n".join(f"{0.1 * i} {i % 3}" for i in range(20))),
        "wide.npy": lambda p: np.save(p, np.zeros((16, 13))),
        "integer.npy": lambda p: np.save(p, np.zeros((16, 12), dtype=np.int32)),
        "holey.npy": lambda p: np.save(p, np.where(np.eye(16, 12) > 0, np.nan, 1.0)),
        "cube.npy": lambda p: np.save(p, np.zeros((16, 12, 2))),
    }
    expected = {
        "notes.txt": ["SurfaceTopography does not recognise its format"],
        "line.txt": ["is a line scan"],
        "wide.npy": ["shape (16, 13)", "grid is (16, 12)"],
        "integer.npy": ["int32", "not floating point"],
        "holey.npy": ["12 undefined points", 'surface.undefined = "harmonic"'],
        "cube.npy": ["3D with shape (16, 12, 2)"],
    }
    if comm.rank == 0:
        for name, make in files.items():
            make(mpi_tmp_path / name)
            (mpi_tmp_path / f"{name}.toml").write_text(CHECK_SCENE.format(path=name))
    comm.Barrier()
    good = run_cli(["petgap", "check", mpi_tmp_path / "good.npy.toml"], ranks=2)
    assert good.returncode == 0, good.stderr
    assert "# topography:" in good.stdout and "good.npy: petgap" in good.stdout
    for name, fragments in expected.items():
        proc = run_cli(["petgap", "check", mpi_tmp_path / f"{name}.toml"], ranks=2)
        assert proc.returncode == 2, (name, proc.stdout, proc.stderr)
        assert proc.stderr.count("petgap: error:") == 1 and "Traceback" not in proc.stderr
        for fragment in fragments:
            assert fragment in proc.stderr, (name, fragment, proc.stderr)
