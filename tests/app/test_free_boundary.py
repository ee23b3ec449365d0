"""Free boundaries in scenes: indenters, surface.periodic and its defaults, what is refused,
and a measured map run end to end on a free boundary.

Every test makes all its collective calls before its first assertion.
"""
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from petgap.app.build import build, load_scene
from petgap.io import scene as scene_module
from petgap.io.scene import Scene, SceneError
from petgap.surfaces import indenters
from petgap.surfaces.topography import map_header

TOPOGRAPHIES = Path(__file__).resolve().parents[1] / "data" / "topographies"

HERTZ = {"grid": {"nx": 128}, "surface": {"kind": "paraboloid", "radius": 500.0},
         "control": {"kind": "indentation", "values": [0.5, 2.0]},
         "solver": {"planner": "estimate"}}


def _scene(data, comm):
    return Scene.from_dict(json.loads(json.dumps(data)), comm)


def test_indenter_heights():
    """Apex at height 0 on the centre pixel, the classical profiles around it."""
    class G:   # the attributes of a grid indenter() reads
        nx, ny, dx, dy = 9, 8, 0.5, 2.0

        def local_positions(self):
            return np.meshgrid(np.arange(9) * 0.5, np.arange(8) * 2.0, indexing="ij")
    x, y = G().local_positions()
    x, y = x - 4 * 0.5, y - 4 * 2.0
    r2 = x ** 2 + y ** 2
    assert scene_module.INDENTERS == indenters.KINDS
    np.testing.assert_allclose(indenters.indenter(G(), "paraboloid", 3.0), -r2 / 6.0)
    np.testing.assert_allclose(indenters.indenter(G(), "cylinder", 3.0), -x ** 2 / 6.0)
    sphere = indenters.indenter(G(), "sphere", 3.0)
    np.testing.assert_allclose(sphere[r2 <= 9], np.sqrt(9 - r2[r2 <= 9]) - 3.0)
    assert np.all(sphere[r2 > 9] == -3.0) and sphere[4, 4] == 0.0
    punch = indenters.indenter(G(), "flat-punch", 3.0)
    assert np.all(punch[r2 <= 9] == 0.0) and np.all(punch[r2 > 9] == -3.0)
    with pytest.raises(ValueError, match="radius must be positive"):
        indenters.indenter(G(), "sphere", 0.0)


def test_periodic_defaults(comm, mpi_tmp_path):
    """Generated surfaces are periodic, indenters are not, files are what they say."""
    generated = _scene({"grid": {"nx": 32}, "surface": {"hurst": 0.8, "lambda_min": 8}}, comm)
    assert generated.surface.periodic is True
    assert _scene(HERTZ, comm).surface.periodic is False
    npy, said, unsaid = (mpi_tmp_path / n for n in ("map.npy", "said.h5", "unsaid.h5"))
    if comm.rank == 0:
        np.save(npy, np.zeros((8, 6)))
        with h5py.File(said, "w") as f:
            f.create_dataset("topography", data=np.zeros((8, 6))).attrs["periodic"] = True
        with h5py.File(unsaid, "w") as f:
            f.create_dataset("topography", data=np.zeros((8, 6)))
            f.attrs["scene_resolved"] = json.dumps({"surface": {"kind": "self-affine"}})
    comm.Barrier()
    assert map_header(npy)["periodic"] is False
    assert map_header(said)["periodic"] is True
    assert map_header(unsaid)["periodic"] is True      # a petgap result of a generated surface
    assert map_header(TOPOGRAPHIES / "top-1.top")["periodic"] is False
    text = '[surface]\nkind = "file"\npath = "{}"\n[control]\nkind = "none"\n'
    for path, periodic in ((npy, False), (said, True)):
        (mpi_tmp_path / "s.toml").write_text(text.format(path)) if comm.rank == 0 else None
        comm.Barrier()
        assert load_scene(mpi_tmp_path / "s.toml", comm).surface.periodic is periodic
        comm.Barrier()


@pytest.mark.parametrize("change, key, words", [
    ({"surface": {"kind": "paraboloid", "radius": 500.0, "periodic": True}}, "control.kind",
     "needs a free boundary"),
    ({"interaction": {"kind": "exponential", "work_of_adhesion": 1e-3, "range": 1.0}},
     "control.kind", "is for the hard wall"),
    ({"solver": {"planner": "estimate", "tao_type": "bncg"}}, "solver.tao_type",
     "does not solve indentation control"),
    ({"surface": {"kind": "flat-punch"}}, "surface.radius", "missing"),
    ({"surface": {"kind": "paraboloid", "radius": -1.0}}, "surface.radius", "out of range"),
])
def test_what_a_free_boundary_refuses(comm, change, key, words):
    with pytest.raises(SceneError) as info:
        _scene({**HERTZ, **change}, comm)
    assert key in str(info.value) and words in str(info.value)


def test_hertz_scene_is_solved_on_a_free_boundary(comm):
    """An indentation sweep of a paraboloid: Hertz's load P = (4/3) E* sqrt(R) d^(3/2)."""
    model = build(_scene(HERTZ, comm), comm)
    states = list(model.sweep())
    assert not model.half_space.periodic
    for step, state in zip(model.steps, states):
        depth = step.control.depth
        hertz = 4 / 3 * np.sqrt(500.0) * depth ** 1.5
        assert state.converged
        assert state.mean_pressure * model.grid.area == pytest.approx(hertz, rel=0.02)


def test_measured_map_end_to_end_on_a_free_boundary(comm, mpi_tmp_path, run_cli):
    """An AFM map (WSxM .top, 256 x 256 pixels over 600 x 600 nm) from scene to report: the
    grid from the file, solved free (the file does not say it is periodic), with h0' taken
    inside the map, and post-processed without patches or perimeter across its edges."""
    scene = mpi_tmp_path / "afm.toml"
    if comm.rank == 0:
        scene.write_text(f'[surface]\nkind = "file"\npath = "{TOPOGRAPHIES / "top-1.top"}"\n'
                         f'detrend = "height"\n[units]\nlength = "nm"\n'
                         f'[control]\nkind = "load"\nvalues = [0.01]\n'
                         f'[solver]\nplanner = "estimate"\n')
    comm.Barrier()
    out = mpi_tmp_path / "afm.h5"
    run = run_cli(["petgap", "run", scene, "--output", out], ranks=2)
    post = run_cli(["petgap-post", out, "-o", mpi_tmp_path / "post"], ranks=2)
    assert run.returncode == 0, run.stderr
    assert "free boundary" in run.stderr + run.stdout
    assert "edges do not match" not in run.stderr + run.stdout
    assert post.returncode == 0, post.stderr
    with h5py.File(out, "r") as f:
        resolved = json.loads(f.attrs["scene_resolved"])
        step = dict(f["step_0000"].attrs)
    assert resolved["surface"]["periodic"] is False
    assert resolved["grid"]["nx"] == 256 and resolved["grid"]["dx"] == pytest.approx(600 / 256)
    assert step["solution.converged"]
    # h0' of the solve: finite differences inside the map, below the seam-raised spectrum
    assert step["rms_slope"] < step["surface.rms_slope"]
    analysis = json.loads((mpi_tmp_path / "post" / "gap-analysis.json").read_text())
    (row,) = analysis["rows"]
    assert row["rms_slope"] == pytest.approx(step["rms_slope"])
    assert (mpi_tmp_path / "post" / "report.html").exists()


def test_one_call_contact_on_a_free_boundary(comm):
    """petgap.contact(..., periodic=False) is the free solve of the same map."""
    import petgap
    from petgap.mechanics.free_half_space import FreeHalfSpace
    from petgap.parallel.grid import Grid
    x = np.arange(64) - 32
    h = -(x[:, None] ** 2 + x[None, :] ** 2) / 400.0
    result = petgap.contact(h, 1.0, load=1e-3, periodic=False, comm=comm)
    grid = Grid((64, 64), comm=comm, planner="estimate")
    direct = petgap.solve(petgap.ContactProblem(grid, h[grid.x_slice], FreeHalfSpace(grid)),
                          petgap.Load(1e-3))
    assert result.converged and result.contact_fraction == direct.contact_fraction
    np.testing.assert_allclose(result.pressure[grid.x_slice], direct.pressure, rtol=0,
                               atol=1e-12 * np.abs(direct.pressure).max())


def test_free_solutions_report_their_approach(comm):
    """A free boundary's load-controlled solution says how far the rigid body moved past
    first contact, as an indentation does: the load of Indentation(d) gives back d, with
    and without a vanishing adhesion; a periodic solution has no such position (NaN)."""
    from petgap.mechanics import (ContactProblem, ExponentialAdhesion, FreeHalfSpace,
                                  Indentation, Load)
    from petgap.parallel import Grid
    from petgap.solvers import solve
    grid = Grid((64, 64), comm=comm, planner="estimate", wisdom=False)
    h = indenters.indenter(grid, "paraboloid", 200.0)
    problem = ContactProblem(grid, h, FreeHalfSpace(grid, 1.0))
    pressed = solve(problem, Indentation(2.0))
    loaded = solve(problem, Load(pressed.mean_pressure))
    weak = problem.with_interaction(ExponentialAdhesion(1e-9, 0.5))
    adhesive = solve(weak, Load(pressed.mean_pressure), tolerance=1e-7)
    periodic = solve(ContactProblem(grid, h, None), Load(pressed.mean_pressure))
    assert pressed.approach == pytest.approx(2.0, rel=1e-12)
    assert pressed.scalars()["approach"] == pressed.approach
    assert loaded.converged and loaded.approach == pytest.approx(2.0, rel=1e-6)
    assert adhesive.converged and adhesive.approach == pytest.approx(2.0, rel=1e-4)
    assert np.isnan(periodic.approach)


def test_a_free_mean_gap_reports_its_outer_steps(comm):
    """Mean-gap control on a free boundary moves the depth of one indentation solve: each
    move is reported with the solve's bound and its mean-gap error against the target."""
    import logging
    from petgap.mechanics import ContactProblem, FreeHalfSpace, Indentation, MeanGap
    from petgap.parallel import Grid
    from petgap.solvers import solve
    grid = Grid((64, 64), comm=comm, planner="estimate", wisdom=False)
    problem = ContactProblem(grid, indenters.indenter(grid, "paraboloid", 200.0),
                             FreeHalfSpace(grid, 1.0))
    pressed = solve(problem, Indentation(2.0))
    lines, logger = [], logging.getLogger("petgap")
    handler, level = logging.Handler(), logger.level
    handler.emit = lambda record: lines.append(record.getMessage())
    logger.addHandler(handler)
    logger.setLevel("INFO")
    try:
        solution = solve(problem, MeanGap(pressed.mean_gap))
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    assert solution.converged and solution.approach == pytest.approx(2.0, rel=1e-6)
    if comm.rank == 0:
        steps = [line for line in lines if "the mean gap by the indentation depth: step" in line]
        # (the coarse grid's depth search reports its own moves, to its own target)
        assert steps and all("of at most 10000" in line and "h0 (target " in line
                             for line in steps)
        assert "h0 (target 1e-08)" in steps[-1]
