"""Packaging: ``pip install --no-build-isolation .`` in a venv on Debian's stack installs nothing else.

pip resolves ``[project] dependencies`` by distribution metadata.  Each one
petgap lists must therefore already be visible to pip in the environment the
suite runs in (the venv of scripts/bootstrap.sh), or pip would fetch it from
PyPI; and h5py must not be listed at all, because Debian's MPI build is not
named "h5py" for pip, which would fetch a serial h5py that shadows it.
"""
import importlib.metadata
import re
import tomllib
from pathlib import Path

import petgap.io.results  # noqa: F401 (selects the MPI build before anything else loads h5py)

import h5py  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _requirements():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0] for r in project["dependencies"]]


def test_every_dependency_is_already_installed_for_pip():
    missing = []
    for name in _requirements():
        try:
            importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            missing.append(name)
    assert not missing, f"pip would fetch {missing} from PyPI instead of using Debian's"


def test_h5py_is_the_mpi_build_and_not_a_pip_requirement():
    assert "h5py" not in {name.lower() for name in _requirements()}
    assert h5py.get_config().mpi


def test_surface_topography_leaves_debians_numpy_and_mpi_h5py():
    """SurfaceTopography comes from PyPI without its dependencies (scripts/bootstrap.sh):
    after importing it, NumPy and h5py are still Debian's (h5py the MPI build), and no
    PyPI numpy or h5py sits in the venv to shadow them after a restart."""
    import numpy
    from petgap.surfaces.measured import surface_topography
    surface_topography()
    assert numpy.__file__.startswith("/usr/lib/python3/dist-packages/")
    assert h5py.__file__.startswith("/usr/lib/python3/dist-packages/") and h5py.get_config().mpi
    for name in ("numpy", "h5py"):
        try:       # Debian's MPI h5py has no distribution named h5py: nothing to shadow it
            location = Path(str(importlib.metadata.distribution(name).locate_file("")))
        except importlib.metadata.PackageNotFoundError:
            continue
        assert ".venv" not in location.parts, f"a pip {name} in the venv: {location}"


def _set_up_packages(tmp_path, script):
    """The Debian packages ``scripts/<script>`` would install on a machine that has none:
    the scripts run from a copy of ``scripts/`` with ``dpkg-query`` saying nothing is
    installed and ``apt-get``, ``mpirun`` and ``timeout`` stubbed (the venv is this one)."""
    import os
    import shutil
    import subprocess
    import sys
    from conftest import clean_env
    root, fake = tmp_path / "clone", tmp_path / "bin"
    shutil.copytree(ROOT / "scripts", root / "scripts")
    fake.mkdir()
    calls = tmp_path / "apt-get.txt"
    stubs = {"dpkg-query": "exit 1", "apt-get": f'echo "$@" >> "{calls}"',
             "sudo": 'exec "$@"', "timeout": "exit 0",
             "mpirun": 'mkdir -p out/default-post'}
    for name, body in stubs.items():
        (fake / name).write_text(f"#!/bin/sh\n{body}\n")
        (fake / name).chmod(0o755)
    # without this job's MPI variables: the set-up imports petgap, which starts MPI
    env = clean_env({"PATH": f"{fake}:{os.environ['PATH']}",
                     "PETGAP_VENV": str(Path(sys.executable).parents[1])})
    env.pop("PETGAP_EXTRA_PACKAGES", None)
    proc = subprocess.run(["bash", str(root / "scripts" / script)], env=env, cwd=root,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    installs = [line.split() for line in calls.read_text().splitlines() if "install" in line]
    return {p for line in installs for p in line if not p.startswith("-")} - {"install"}


def test_the_main_job_installs_no_browser_and_the_tests_do(tmp_path):
    """Only the tests render the report in a browser: main.sh's set-up leaves chromium out,
    test.sh's brings it (with everything main.sh installs)."""
    main = _set_up_packages(tmp_path / "main", "main.sh")
    tests = _set_up_packages(tmp_path / "tests", "test.sh")
    assert "python3-petsc4py" in main and "chromium" not in main
    assert "chromium" in tests and main <= tests
