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
