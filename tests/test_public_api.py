"""``import petgap`` is the public API: its names, its help text, a solve through it alone."""
import inspect
import pydoc
import re
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest

import petgap

ROOT = Path(__file__).resolve().parents[1]

#: What a notebook reaches for first (issue 13's list of the public API).
MAIN_NAMES = ["Grid", "self_affine", "statistics", "radial_psd", "load_topography",
              "save_topography_npy", "ElasticHalfSpace", "ContactProblem", "Load", "MeanGap",
              "HardWall", "ExponentialAdhesion", "ContactSolution", "solve", "sweep", "Scene",
              "SceneError", "run_scene", "contact", "contact_statistics_of",
              "gap_distribution_of", "attractive_force_of", "contact_statistics",
              "gap_distribution", "collapse", "fit_power_law", "attractive_force_measured",
              "analysis", "reference_solutions", "__version__"]


def test_all_names_exist():
    missing = [name for name in petgap.__all__ if not hasattr(petgap, name)]
    assert not missing
    assert len(set(petgap.__all__)) == len(petgap.__all__)
    assert set(MAIN_NAMES) <= set(petgap.__all__)


def test_public_names_are_documented():
    """Every public function and class says what it does."""
    bare = [name for name in petgap.__all__
            if (inspect.isfunction(getattr(petgap, name)) or inspect.isclass(getattr(petgap, name)))
            and not inspect.getdoc(getattr(petgap, name))]
    assert not bare


def test_subpackages_are_reexported_from():
    """The top level takes its names from the subpackages (their __init__ is the seam)."""
    assert petgap.Grid is petgap.parallel.Grid
    assert petgap.ContactProblem is petgap.mechanics.ContactProblem
    assert petgap.solve is petgap.solvers.solve and petgap.sweep is petgap.solvers.sweep
    assert petgap.Scene is petgap.io.Scene
    assert petgap.run_scene is petgap.app.run_scene
    assert petgap.contact_statistics_of is petgap.analysis.contact_statistics_of
    assert petgap.leakage_of is petgap.flow.leakage_of and petgap.leakage is petgap.flow.leakage
    # where a function shares its module's name, the subpackage keeps the module
    assert inspect.ismodule(petgap.surfaces.self_affine)
    assert inspect.ismodule(petgap.app.contact)
    assert petgap.self_affine is petgap.surfaces.self_affine.self_affine
    assert petgap.contact is petgap.app.contact.contact


def test_help_shows_the_api():
    text = pydoc.render_doc(petgap, renderer=pydoc.plaintext)
    for name in MAIN_NAMES:
        assert re.search(rf"\b{re.escape(name)}\b", text), name
    assert "10.1007/s11249-021-01454-6" in text
    assert "Example" in text


def docstring_example():
    """The code block after ``Example`` in petgap's docstring."""
    doc = petgap.__doc__
    start = doc.index("::", doc.index("Example")) + 2
    block = []
    for line in doc[start:].splitlines()[1:]:
        if line.strip() and not line.startswith("    "):
            break
        block.append(line)
    return textwrap.dedent("\n".join(block))


def test_docstring_example_runs(capsys):
    code = docstring_example()
    assert "petgap.solve" in code
    exec(compile(code, "petgap.__doc__", "exec"), {})
    printed = capsys.readouterr().out.split()
    assert printed[0] == "True"  # converged
    assert 0 < float(printed[1]) < 1  # contact fraction


def test_end_to_end_through_the_public_api(comm):
    """Surface, problem, sweep, analysis, one-call solve: nothing but ``petgap.``."""
    grid = petgap.Grid((32, 24), size=(1.0, 0.75), comm=comm, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 4 * grid.dx, rms_slope=0.1, seed=2)
    assert petgap.statistics(grid, h).rms_slope == pytest.approx(0.1, rel=1e-12)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid, 2.0))
    controls = [petgap.Load(f * problem.pressure_scale) for f in (0.05, 0.1)]
    first, second = petgap.sweep(problem, controls, tolerance=1e-10)
    assert first.converged and second.converged
    assert second.direction == "loading"
    assert 0 < first.contact_fraction < second.contact_fraction < 1
    stats = petgap.contact_statistics_of(problem, second)
    assert stats.contact_fraction == second.contact_fraction and stats.g0 > 0
    assert stats == petgap.contact_statistics(grid, second.gap, second.pressure,
                                              problem.rms_slope, 2.0)
    dist = petgap.gap_distribution_of(problem, second)
    by_parts = petgap.gap_distribution(grid, second.gap, second.pressure)
    assert np.array_equal(dist.edges, by_parts.edges)
    assert np.array_equal(dist.counts, by_parts.counts) and dist.counts.sum() > 0
    assert petgap.attractive_force_of(problem, second).force == 0  # hard wall
    near = petgap.near_contact_area_of(problem, second, [stats.g0], g0=stats.g0)
    assert 0 < near.measured[0] < 1
    # the one call, on the global surface, gives the second state
    heights = comm.allgather(h)
    result = petgap.contact(np.concatenate(heights), (grid.dx, grid.dy),
                            load=controls[1].mean_pressure, contact_modulus=2.0, comm=comm,
                            tolerance=1e-10)
    assert result.converged
    assert result.contact_fraction == pytest.approx(second.contact_fraction, abs=2 / grid.npoints)
    assert result.mean_gap == pytest.approx(second.mean_gap, rel=1e-6)


def test_version_is_the_package_metadata():
    """pyproject.toml reads the version from petgap/_version.py, as petgap does (one source)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" in project.get("dynamic", [])
    dynamic = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["dynamic"]
    assert dynamic["version"] == {"attr": "petgap._version.__version__"}
    assert petgap._version.__version__ == petgap.__version__
    assert re.fullmatch(r"\d+\.\d+\.\d+", petgap.__version__)


IMPORT_SIDE_EFFECTS = """
import logging, os, sys, warnings
import numpy, mpi4py.MPI, petsc4py.PETSc  # their own import-time filters are not petgap's
before = (sorted(os.listdir(".")), list(warnings.filters), list(sys.argv))
import petgap
after = (sorted(os.listdir(".")), list(warnings.filters), list(sys.argv))
assert before == after, (before, after)
assert not logging.getLogger("petgap").handlers
assert logging.getLogger().handlers == []
print("clean")
"""


def test_import_has_no_side_effects(mpi_tmp_path, run_cli):
    """Importing writes no file, prints nothing, sets no logging or warning filters."""
    result = run_cli([sys.executable, "-c", IMPORT_SIDE_EFFECTS], cwd=mpi_tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "clean\n"


def test_citation_matches_the_version():
    text = (ROOT / "CITATION.cff").read_text()
    assert re.search(rf"^version: {re.escape(petgap.__version__)}$", text, flags=re.MULTILINE)
    assert "doi: 10.1007/s11249-021-01454-6" in text


def test_help_of_solve_lists_every_control_of_the_registry():
    """help(petgap.solve) names every control the registry solves, and where."""
    from petgap.io.solver_registry import CONTROLS
    from petgap.mechanics.problem import CONTROL_TYPES
    text = pydoc.render_doc(petgap.solve, renderer=pydoc.plaintext)
    assert set(CONTROL_TYPES) == set(CONTROLS)
    for kind in CONTROLS:
        assert f"{CONTROL_TYPES[kind].__name__}(" in text, kind
    assert "Indentation(depth)" in text and "Solved on a free boundary with the hard wall." \
        in " ".join(text.split())
