"""Inputs that must end in a clear error or warning, never in an internal error.

PETSc options (unknown names, malformed values, ``--strict``), absurd grids and
the memory estimate; each is run as a user runs it where the point is what the
user sees (``petgap run`` in a subprocess).
"""
import io
import logging
from pathlib import Path

import pytest

from conftest import write_shared as write
from petgap.app.build import check_options
from petgap.io.scene import Scene, SceneError
from petgap.solvers.tao import check_petsc_options

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
