"""A scene with [flow]: ``petgap run`` stores the leak of each step, ``petgap-post`` reads it."""
import json

import numpy as np
import pytest

from petgap.io.results import read_attrs
from petgap.io.scene import Scene, SceneError

import h5py  # after petgap.io.results, which selects the MPI build  # noqa: E402
from conftest import write_shared as write

SCENE = """
[grid]
nx = 64
ny = 48

[surface]
kind = "self-affine"
rms_slope = 0.1
hurst = 0.7
lambda_min = "6 a0"
seed = 5

[control]
kind = "load"
values = [0.002, 0.01, 0.05]

[solver]
planner = "estimate"

[flow]
kind = "reynolds"
viscosity = 2.0
pressure_drop = 3.0
"""


def test_run_and_post_give_the_leak_per_step(comm, mpi_tmp_path, run_cli):
    scene = write(comm, mpi_tmp_path / "leak.toml", SCENE)
    out = mpi_tmp_path / "leak.h5"
    proc = run_cli(["petgap", "run", scene, "--output", out, "--", "-flow_ksp_rtol", "1e-11"],
                   ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("step 0 flow converged") == 1      # the verdict, once
    steps = None
    if comm.rank == 0:
        with h5py.File(out, "r") as f:
            steps = [(read_attrs(f[f"step_{k:04d}"]), f[f"step_{k:04d}"]["flow_pressure"][...],
                      f[f"step_{k:04d}"]["flow_flux_x"].attrs["units"]) for k in range(3)]
    steps = comm.bcast(steps, root=0)
    first, _, units = steps[0]
    assert first["flow.converged"] and first["flow.percolates"]
    assert first["flow.viscosity"] == 2.0 and first["flow.pressure_drop"] == 3.0
    assert first["flow.leak_rate"] > 0 and first["flow.conservation"] < 1e-8
    assert first["flow.transmissivity"] == pytest.approx(
        12 * 2.0 * first["flow.leak_rate"] * 64 / (48 * 3.0), rel=1e-12)
    assert units == "(1)^2 / time"
    rates = [s[0]["flow.leak_rate"] for s in steps]
    assert rates[0] > rates[1] >= rates[2]           # the load closes the gaps
    last, pressure, _ = steps[2]
    if not last["flow.percolates"]:
        assert last["flow.reason"] == "no_percolation" and "percolate" in last["flow.message"]
        assert np.all(np.isnan(pressure))

    post = mpi_tmp_path / "post"
    proc = run_cli(["petgap-post", out, "--output-dir", post], ranks=2)
    assert proc.returncode == 0, proc.stderr
    table = json.loads((post / "gap-analysis.json").read_text()) if comm.rank == 0 else None
    table = comm.bcast(table, root=0)
    rows = table["rows"] if isinstance(table, dict) else table
    assert [r["flow_leak_rate"] for r in rows] == pytest.approx(rates, rel=1e-12)
    assert all(r["flow_percolates"] is not None for r in rows)
    for k in range(3):
        assert (post / f"leak-step{k:04d}-flow.png").exists()
    assert (post / "leak-leakage.png").exists()
    report = (post / "report.html").read_text()
    assert "Flow through the gaps" in report and "transmissivity K" in report


@pytest.mark.parametrize("flow, words", [
    ('kind = "reynolds"\nviscosity = 0', "flow.viscosity = 0: out of range"),
    ('kind = "reynolds"\npressure_drop = -1.0', "flow.pressure_drop = -1.0: out of range"),
    ('kind = "reynolds"\ndirection = "z"', 'flow.direction = "z"'),
    ('kind = "reynolds"\nvelocity = 1.0', "flow.velocity = 1.0: unknown key"),
    ('viscosity = 1.0', 'does not apply with flow.kind = "none"'),
])
def test_bad_flow_sections(comm, flow, words):
    text = SCENE.split("[flow]")[0] + "[flow]\n" + flow + "\n"
    with pytest.raises(SceneError, match=words.replace("(", r"\(")):
        Scene.from_text(text, comm)


def test_flow_refused_where_every_step_is_adhesive(comm):
    text = SCENE + '\n[interaction]\nkind = "exponential"\nwork_of_adhesion = 1e-4\nrange = 1.0\n'
    with pytest.raises(SceneError, match="no thin viscous film"):
        Scene.from_text(text, comm)
    grid = SCENE.replace("ny = 48", "ny = 1").replace('kind = "reynolds"',
                                                      'kind = "reynolds"\ndirection = "y"')
    with pytest.raises(SceneError, match="1 pixel along y"):
        Scene.from_text(grid, comm)


@pytest.mark.parametrize("units, x, bars", [
    (("nm", "GPa"), "$x$ (nm)", ["fluid pressure $p$ (GPa)",
                                 "flux per unit width $|q|$ (nm$^{2}$ / time)"]),
    (("1", "1"), "$x$ (scene units)", ["fluid pressure $p$ (scene units)",
                                       "flux per unit width $|q|$ (scene units)"]),
])
def test_flow_maps_carry_their_units(units, x, bars):
    from petgap.analysis.maps import Map
    from petgap.app.figures import pyplot
    from petgap.app.flow_post import FlowMaps, flow_figure
    values = np.linspace(0.0, 1.0, 12).reshape(4, 3)
    m = Map(values=values, counts=np.ones((4, 3), dtype=np.int64), factor=1,
            extent=(0.0, 40.0, 0.0, 30.0))
    plt = pyplot()
    fig = flow_figure(plt, FlowMaps(pressure=m, flux=m, title="t", units=units))
    maps, colour_bars = fig.axes[:2], fig.axes[2:]
    assert [ax.get_xlabel() for ax in maps] == [x, x]
    assert [ax.get_ylabel() for ax in maps] == [x.replace("$x$", "$y$")] * 2
    assert [ax.get_ylabel() for ax in colour_bars] == bars
    plt.close(fig)
