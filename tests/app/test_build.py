"""The builder from a scene to the objects that are solved (petgap.app.build).

Every test makes all its collective calls before its first assertion, so a
failure on one rank cannot leave the other waiting in a collective.
"""
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from petgap.app import protocol
from petgap.app.build import Model, build, load_scene, petsc_options_dict
from petgap.io.scene import Scene, SceneError
from petgap.mechanics.interactions import LAWS, ExponentialAdhesion, HardWall, check_resolution
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.solvers.sweeps import SweepStep

SCENE = {
    "grid": {"nx": 64, "ny": 32, "a0": 0.5},
    "surface": {"hurst": 0.8, "lambda_min": "8 a0", "rms_slope": 0.1, "seed": 3},
    "material": {"contact_modulus": 2.0},
    "control": {"kind": "load", "values": [0.002, 0.004]},
    "solver": {"planner": "estimate", "tolerance": 1e-7, "max_iterations": 500,
               "petsc_options": {"tao_max_it": 400}},
}

PROTOCOL = dict(SCENE, interaction={"kind": "exponential", "work_of_adhesion": 2e-4,
                                    "range": "2 a0", "resolution_check": "off"},
                control={"kind": "load", "values": [0.002, 0.004],
                         "reference": "non-adhesive"})


def gather_all(grid, local):
    return np.concatenate(grid.comm.allgather(np.asarray(local)), axis=0)


def test_scene_from_dict_is_the_scene_of_its_text(comm):
    scene = Scene.from_dict(SCENE, comm)
    again = Scene.from_text(scene.text, comm)
    assert again.to_dict() == scene.to_dict()
    assert scene.grid.shape == (64, 32) and scene.grid.size == (32.0, 16.0)
    assert scene.surface.lambda_min == 4.0
    assert dict(scene.solver.petsc_options) == {"tao_max_it": "400"}


def test_hard_wall_scene_builds_grid_problem_and_steps(comm):
    scene = Scene.from_dict(SCENE, comm)
    model = build(scene, comm, petsc_args=["-tao_monitor"])
    serial = build(scene, MPI.COMM_SELF)  # the same scene on one rank
    heights = gather_all(model.grid, model.topography)
    stats = model.statistics

    assert isinstance(model, Model)
    assert model.grid.shape == (64, 32) and model.grid.comm is comm
    assert (model.grid.dx, model.grid.dy) == (0.5, 0.5)
    assert model.topography.shape == model.grid.local_shape
    assert isinstance(model.problem, ContactProblem)
    assert isinstance(model.problem.interaction, HardWall)
    assert model.half_space.contact_modulus == 2.0 and model.problem.half_space is model.half_space
    assert model.adhesive_problem is None and model.interaction is None
    assert model.resolution is None
    assert model.steps == protocol.plan(scene)
    assert [s.control for s in model.steps] == [Load(0.002), Load(0.004)]
    assert model.petsc_args == ["-tao_max_it", "400", "-tao_monitor"]
    assert model.options == {"tao_max_it": "400", "tao_monitor": ""}
    assert model.solve_options == {"solver": "pcg", "tolerance": 1e-7, "max_iterations": 500,
                                   "options": model.options, "precision": "double"}
    assert model.grid.precision == "double" and model.topography.dtype == np.float64
    assert stats.rms_slope == pytest.approx(0.1, rel=1e-9)
    # the same surface and problem on 1 and on all ranks
    np.testing.assert_array_equal(heights, serial.topography)
    assert model.problem.rms_height == pytest.approx(serial.problem.rms_height, rel=1e-12)
    assert model.problem.rms_slope == pytest.approx(serial.problem.rms_slope, rel=1e-12)
    steps = model.sweep_steps()
    assert [type(s) for s in steps] == [SweepStep] * 2
    assert all(s.problem is model.problem and s.chain == "sweep" and s.state is None
               for s in steps)


def test_protocol_scene_builds_both_problems_and_chains(comm):
    scene = Scene.from_dict(PROTOCOL, comm)
    model = build(scene, comm)
    steps = model.sweep_steps({0: "a state read back"})

    assert isinstance(model.interaction, ExponentialAdhesion)
    assert model.interaction.work == 2e-4 and model.interaction.range == 1.0
    assert model.adhesive_problem.interaction is model.interaction
    assert model.adhesive_problem.half_space is model.half_space
    assert set(model.resolution) >= {"resolved", "message"}
    assert [(s.index, s.chain, s.adhesive, s.reference_step) for s in model.steps] == \
        [(0, "reference", False, None), (1, "reference", False, None),
         (2, "adhesive", True, 0), (3, "adhesive", True, 1)]
    assert [model.problem_of(s) for s in model.steps] == \
        [model.problem, model.problem, model.adhesive_problem, model.adhesive_problem]
    assert steps[0].state == "a state read back" and steps[1].state is None
    assert steps[1].control == Load(0.004)
    # the adhesive steps impose the mean gap their reference step found
    assert callable(steps[3].control)

    class Found:
        mean_gap = 0.25
    assert steps[3].control([None, Found()]) == MeanGap(0.25)


@pytest.mark.parametrize("kind", [k for k in LAWS if k not in ("hard-wall", "exponential")])
def test_every_law_of_the_registry_builds_from_its_scene(comm, kind):
    """A scene names any law of the registry; the builder makes it and judges its resolution
    in its own terms (the range is 2 pixels, the process zone E* w / sigma0^2 > 2 pixels)."""
    scene = Scene.from_dict(dict(PROTOCOL, interaction=dict(PROTOCOL["interaction"], kind=kind,
                                                            resolution_check="warn")), comm)
    model = build(scene, comm)
    assert type(model.interaction) is LAWS[kind]
    assert (model.interaction.work, model.interaction.range) == (2e-4, 1.0)
    assert model.adhesive_problem.interaction is model.interaction
    assert model.resolution["resolved"], model.resolution["message"]
    assert f"{model.interaction.LENGTH} = 2 a0" in model.resolution["message"]
    assert [s.adhesive for s in model.steps] == [False, False, True, True]


def test_surface_only_scene_builds_no_problem(comm):
    data = dict(SCENE, control={"kind": "none"})
    data["surface"] = dict(SCENE["surface"])
    model = build(Scene.from_dict(data, comm), comm)
    assert model.steps == [] and model.problem is None and model.half_space is None
    assert model.topography.shape == model.grid.local_shape


def test_surface_and_resolution_check_can_be_given(comm):
    scene = Scene.from_dict(dict(PROTOCOL, interaction=dict(PROTOCOL["interaction"],
                                                            resolution_check="error")), comm)
    seen = []

    def flat_plus_bump(grid):
        seen.append(grid.shape)
        h = np.zeros(grid.local_shape)
        h[:, :1] = 1.0
        return h
    model = build(scene, comm, surface=flat_plus_bump, resolution_check="off")
    assert seen == [(64, 32)]
    assert np.all(model.topography[:, 1:] == 0.0)
    assert model.resolution is not None


def test_petsc_options_dict():
    assert petsc_options_dict(["-a", "1", "-b", "-c", "-1e-3", "--d", "x"]) == \
        {"a": "1", "b": "", "c": "-1e-3", "d": "x"}


# ------------------------------------------------------------ grid from the file
TOPOGRAPHIES = Path(__file__).resolve().parent.parent / "data" / "topographies"


def _scene_file(comm, directory, text):
    path = directory / "scene.toml"
    if comm.rank == 0:
        path.write_text(text)
    comm.Barrier()
    return path


def test_grid_comes_from_the_file_unless_the_scene_gives_it(comm, mpi_tmp_path):
    """A file scene may leave out the grid: the file's pixels, and its pixel size where it
    knows its physical size (converted to units.length); what the scene gives wins."""
    top = TOPOGRAPHIES / "top-1.top"                         # 256 x 256, 600 x 600 nm
    bare = f'[surface]\nkind = "file"\npath = "{top}"\n[control]\nkind = "none"\n'
    scene = load_scene(_scene_file(comm, mpi_tmp_path, bare), comm)
    assert scene.grid.shape == (256, 256)
    assert scene.grid.dx == scene.grid.dy == scene.grid.a0 == pytest.approx(600 / 256)
    in_um = load_scene(_scene_file(comm, mpi_tmp_path, bare + '[units]\nlength = "um"\n'), comm)
    assert in_um.grid.size == pytest.approx((0.6, 0.6), rel=1e-12)
    given = load_scene(_scene_file(comm, mpi_tmp_path, bare + "[grid]\na0 = 2.0\n"), comm)
    assert given.grid.shape == (256, 256) and given.grid.dx == given.grid.dy == 2.0
    # the pixels of a .npy file, which knows no size: a0 = 1
    if comm.rank == 0:
        np.save(mpi_tmp_path / "map.npy", np.zeros((24, 18)))
    npy = load_scene(_scene_file(comm, mpi_tmp_path, bare.replace(str(top), "map.npy")), comm)
    assert npy.grid.shape == (24, 18) and npy.grid.a0 == 1.0
    # without the reader of topography files (Scene.from_file) the grid must be given
    with pytest.raises(SceneError, match="grid.nx is missing: the topography file would give "
                                         "it, but: the scene was read without a reader"):
        Scene.from_file(mpi_tmp_path / "scene.toml", comm)


def test_non_square_pixels_from_the_file_are_solved(comm, mpi_tmp_path):
    """A map of 16 x 12 pixels over 8 x 12 um has pixels of 0.5 x 1 um: the scene's grid
    and the solve take them."""
    from petgap.surfaces.measured import surface_topography  # deferred: one test writes a map
    heights = np.random.default_rng(1).standard_normal((16, 12)) * 0.05
    if comm.rank == 0:
        surface_topography().Topography(heights, (8.0, 12.0), unit="um").to_netcdf(
            str(mpi_tmp_path / "rect.nc"))
    comm.Barrier()
    text = ('[surface]\nkind = "file"\npath = "rect.nc"\n[control]\nkind = "load"\n'
            'values = [0.01]\n[units]\nlength = "um"\n')
    scene = load_scene(_scene_file(comm, mpi_tmp_path, text), comm)
    assert scene.grid.shape == (16, 12) and (scene.grid.dx, scene.grid.dy) == (0.5, 1.0)
    model = build(scene, comm)
    assert (model.grid.dx, model.grid.dy) == (0.5, 1.0)
    whole = np.concatenate(comm.allgather(model.topography))
    np.testing.assert_allclose(whole, heights, rtol=1e-12)
    state = next(iter(model.sweep()))
    assert state.converged


def test_single_precision_scene_solves_the_double_surface_rounded(comm):
    """``solver.precision = "single"``: a single-precision grid and problem carrying the very
    surface of the double scene (made in double, then rounded), solved to the single
    tolerance with the contact set of the double solve; mixed solves a double problem."""
    single = dict(SCENE, solver=dict(SCENE["solver"], precision="single", tolerance=3e-6))
    mixed = dict(SCENE, solver=dict(SCENE["solver"], precision="mixed"))
    models = [build(Scene.from_dict(s, comm), comm) for s in (SCENE, single, mixed)]
    states = [list(m.sweep()) for m in models]
    double_model, single_model, mixed_model = models
    h64 = gather_all(double_model.grid, double_model.topography)
    h32 = gather_all(single_model.grid, single_model.topography)

    assert single_model.grid.precision == "single" and h32.dtype == np.float32
    assert np.array_equal(h32, h64.astype(np.float32))
    assert mixed_model.grid.precision == "double" and mixed_model.solve_options["precision"] \
        == "mixed"
    for ref, one, other in zip(*states):
        assert ref.converged and one.converged and other.converged
        assert (one.precision, other.precision) == ("single", "mixed")
        assert one.kkt_gap <= 3e-6 and other.kkt_gap <= 1e-7
        assert one.contact_fraction == pytest.approx(ref.contact_fraction, rel=2e-3)
        assert other.contact_fraction == ref.contact_fraction
        assert other.mean_gap == pytest.approx(ref.mean_gap, rel=1e-6)


def test_single_precision_run_stores_its_fields_in_32_bits(comm, mpi_tmp_path):
    """A single-precision run's fields are written as float32 datasets (no double copy at
    the write, half the file), with the step's precision; they read back into float64."""
    import h5py  # deferred: the only test here that reads a result file
    from petgap.app import run_scene
    from petgap.io.results import read_field
    single = dict(SCENE, solver=dict(SCENE["solver"], precision="single", tolerance=3e-6))
    scene = Scene.from_dict(single, comm)
    out = mpi_tmp_path / "single.h5"
    run_scene(scene, comm, out)
    model = build(scene, comm)
    with h5py.File(out, "r", driver="mpio", comm=comm) as f:
        dtypes = [f[name].dtype for name in ("topography", "step_0000/gap",
                                               "step_0000/pressure")]
        precision = f["step_0000"].attrs["solution.precision"]
        h = read_field(f, "topography", model.grid)
    assert dtypes == [np.float32] * 3 and precision == "single"
    assert h.dtype == np.float64 and np.array_equal(h, model.topography.astype(np.float64))


def test_a_script_running_a_scene_sees_its_steps(comm, mpi_tmp_path, capfd, monkeypatch):
    """``run_scene`` from a script that set up no logging (``runs/large.py``) still shows
    rank 0 the run's progress and each step's verdict, as ``petgap run`` does: a large
    scene is not silent for an hour.  A script's own logging set-up is kept."""
    import logging
    import warnings
    from petgap.app import run_scene
    logger = logging.getLogger("petgap")
    monkeypatch.setattr(logger, "handlers", [])
    monkeypatch.setattr(logger, "propagate", logger.propagate)   # configure() sets these
    monkeypatch.setattr(logger, "level", logger.level)
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)
    monkeypatch.setattr(logging.getLogger(), "handlers", [])
    run_scene(Scene.from_dict(SCENE, comm), comm, mpi_tmp_path / "silent.h5")
    out = capfd.readouterr().out
    if comm.rank == 0:
        assert "step 0 (" in out and "converged after" in out, out
    else:
        assert out == ""


# ------------------------------------------------------ a series of works of adhesion
SERIES = dict(PROTOCOL, interaction=dict(PROTOCOL["interaction"],
                                         work_of_adhesion=[1e-4, 2e-4, 4e-4]))


def test_a_series_of_works_solves_one_reference_and_each_w_in_turn(comm):
    """``work_of_adhesion = [w1, w2, w3]`` (paper Fig. 3): the references once, then the
    adhesive steps once per w, in order, each w a problem of its own on the shared
    surface and half-space; the strictest w is the one the resolution check judges."""
    scene = Scene.from_dict(SERIES, comm)
    model = build(scene, comm)
    plan = [(s.index, s.chain, s.reference_step, s.work) for s in model.steps]
    problems = [model.problem_of(s) for s in model.steps]
    laws = [model.law_of(s) for s in model.steps]
    assert plan == [(0, "reference", None, None), (1, "reference", None, None),
                    (2, "adhesive", 0, 1e-4), (3, "adhesive", 1, 1e-4),
                    (4, "adhesive", 0, 2e-4), (5, "adhesive", 1, 2e-4),
                    (6, "adhesive", 0, 4e-4), (7, "adhesive", 1, 4e-4)]
    assert [law.work for law in laws[2:]] == [1e-4, 1e-4, 2e-4, 2e-4, 4e-4, 4e-4]
    assert isinstance(laws[0], HardWall) and problems[0] is model.problem
    assert [p.interaction.work for p in problems[2:]] == [1e-4, 1e-4, 2e-4, 2e-4, 4e-4, 4e-4]
    assert problems[2] is problems[3] and problems[4] is problems[5] \
        and problems[2] is not problems[4]
    assert all(p.half_space is model.half_space for p in problems)
    assert all(p.topography is model.topography for p in problems)
    # each w is a chain of its own (started cold), its loads chained within it
    chains = [s.chain for s in model.sweep_steps()]
    assert chains[0] == chains[1] != chains[2]
    assert chains[2] == chains[3] != chains[4] == chains[5] != chains[6] == chains[7]
    assert len({chains[2], chains[4], chains[6]}) == 3
    stickiest = check_resolution(ExponentialAdhesion(4e-4, 1.0), 0.5, 2.0, "off")
    assert model.resolution["message"] == stickiest["message"]
    assert model.resolution["message"] != check_resolution(
        ExponentialAdhesion(1e-4, 1.0), 0.5, 2.0, "off")["message"]


def test_a_series_of_works_needs_the_reference(comm):
    data = dict(SERIES, control={"kind": "load", "values": [0.002]})
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data, comm)
    message = str(info.value)
    assert "control.reference" in message and "work_of_adhesion is a list of 3" in message
    assert "non-adhesive" in message


def test_a_series_of_works_runs_and_stores_each_w(comm, mpi_tmp_path):
    """The run stores each adhesive step with its own w (as petgap-post rebuilds the law),
    at its reference's mean gap; a stickier w pulls harder at the same mean gap."""
    import h5py  # deferred: reads the result file
    from petgap.app import run_scene
    data = dict(SERIES, control={"kind": "load", "values": [0.002],
                                 "reference": "non-adhesive"})
    scene = Scene.from_dict(data, comm)
    out = mpi_tmp_path / "series.h5"
    run_scene(scene, comm, out)
    with h5py.File(out, "r", driver="mpio", comm=comm) as f:
        steps = sorted(k for k in f if k.startswith("step_"))
        works = [f[k].attrs.get("interaction.work_of_adhesion") for k in steps]
        gaps = [f[k].attrs["solution.mean_gap"] for k in steps]
        pressures = [f[k].attrs["solution.mean_pressure"] for k in steps]
        converged = [bool(f[k].attrs["solution.converged"]) for k in steps]
    assert len(steps) == 4 and all(converged)
    assert list(works[1:]) == [1e-4, 2e-4, 4e-4]
    assert gaps[1:] == pytest.approx([gaps[0]] * 3, rel=1e-7)
    assert pressures[0] > pressures[1] > pressures[2] > pressures[3]


def test_fft_planner_by_the_work_ahead(comm):
    """solver.planner = "auto" (the default): estimate for one solve, measure for a sweep,
    saying why; a planner the scene names is kept."""
    from petgap.app.build import fft_planner, make_grid
    auto = {k: v for k, v in SCENE["solver"].items() if k != "planner"}
    one = Scene.from_dict(dict(SCENE, solver=auto, control={"kind": "load", "values": [0.01]}),
                          comm)
    many = Scene.from_dict(dict(SCENE, solver=auto), comm)
    named = Scene.from_dict(dict(SCENE, solver=dict(auto, planner="patient")), comm)
    grid = make_grid(one, comm)
    assert one.solver.planner == "auto"
    assert fft_planner(one) == ("estimate", "auto: one solve ahead; solver.planner = "
                                "\"measure\" for faster transforms")
    assert fft_planner(many) == ("measure", "auto: 2 solves ahead, plans kept as wisdom")
    assert fft_planner(named) == ("patient", "solver.planner")
    assert grid.planner == "estimate"


def test_a_run_holds_no_fields_of_its_finished_steps_while_it_solves(comm, mpi_tmp_path,
                                                                       monkeypatch):
    """While ``run_scene`` solves a step of a series of works of adhesion, no state of a
    step before it is alive: each ``w`` is a chain of its own, cold from the coarse grid,
    so every finished step is written and let go (16 bytes per point a step: at 16384^2
    the paper's protocol fits the machine only so).  Read at the start of every solve."""
    import gc
    import weakref
    from petgap.app import run as run_module
    from petgap.solvers import sweeps
    finished, alive = [], []
    solve, log_solution = sweeps.solve, run_module._log_solution

    def watched_solve(*args, **kwargs):
        gc.collect()
        alive.append(sum(ref() is not None for ref in finished))
        return solve(*args, **kwargs)

    def watched_log(log, step, state):
        finished.append(weakref.ref(state))
        return log_solution(log, step, state)
    monkeypatch.setattr(sweeps, "solve", watched_solve)
    monkeypatch.setattr(run_module, "_log_solution", watched_log)
    series = dict(SERIES, control=dict(SERIES["control"], values=[0.002]))
    run_module.run_scene(Scene.from_dict(series, comm), comm, mpi_tmp_path / "series.h5")
    assert len(alive) == 4 and alive == [0, 0, 0, 0]


def test_a_resumed_run_reads_the_fields_only_of_its_warm_starts(comm):
    """Resuming, the steps complete in the file are read back with their fields only where
    the next step of their chain is still to solve (its warm start); the others give
    their scalars alone, so a resumed series holds no finished step's fields."""
    loads = build(Scene.from_dict(SCENE, comm), comm)          # one chain of two loads
    assert list(loads.warm_starts({0})) == [0]
    assert list(loads.warm_starts({0, 1})) == []
    series = build(Scene.from_dict(dict(SERIES, control=dict(SERIES["control"],
                                                             values=[0.002])), comm), comm)
    assert [series.chain_of(s) for s in series.steps][1:] == [
        (series.steps[1].chain, w) for w in (1e-4, 2e-4, 4e-4)]
    assert list(series.warm_starts({0, 1})) == []               # every chain one step long
