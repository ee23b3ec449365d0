"""A measured map as a user meets it: its unit taken and kept, plausibility warnings with the
number, the limit and what to do, and ``petgap check`` telling what ``run`` will need."""
import logging
from pathlib import Path

import h5py
import numpy as np
import pytest

import petgap
from conftest import write_shared as write
from petgap.app.build import build, load_scene
from petgap.app.main import main
from petgap.app.run import run_scene
from petgap.io.scene import Scene
from petgap.mechanics.plausibility import PlausibilityError

DATA = Path(__file__).resolve().parent.parent / "data" / "topographies"
TOP = DATA / "top-1.top"       # a 256 x 256 WSxM map of 600 x 600 nm


class Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


@pytest.fixture
def warnings_of():
    """The warnings logged by petgap on this rank during the test."""
    handler = Records()
    logger = logging.getLogger("petgap")
    logger.addHandler(handler)
    yield handler.messages
    logger.removeHandler(handler)


def scene_text(extra="", values="[0.002]", kind="load"):
    return (f'[surface]\nkind = "file"\npath = "{TOP}"\n{extra}\n'
            f'[control]\nkind = "{kind}"\nvalues = {values}\n'
            f'[solver]\nplanner = "estimate"\n')


def test_without_units_the_files_unit_is_the_scenes_and_the_results(comm, mpi_tmp_path):
    path = write(comm, mpi_tmp_path / "map.toml", scene_text(kind="none", values="[]")
                 .replace("values = []\n", ""))
    scene = load_scene(path, comm)
    assert scene.units.length == "nm" and scene.grid.a0 == pytest.approx(600 / 256)
    run_scene(scene, comm, mpi_tmp_path / "map.h5")
    with h5py.File(mpi_tmp_path / "map.h5", "r") as f:
        assert f["topography"].attrs["units"] == "nm" and f["x"].attrs["units"] == "nm"


def test_a_unit_spelt_micron_is_converted_and_labelled_um(comm, mpi_tmp_path):
    path = write(comm, mpi_tmp_path / "map.toml",
                 scene_text('[units]\nlength = "micron"\n', kind="none").replace(
                     "values = [0.002]\n", ""))
    scene = load_scene(path, comm)
    assert scene.grid.a0 == pytest.approx(0.6 / 256)
    run_scene(scene, comm, mpi_tmp_path / "map.h5")
    with h5py.File(mpi_tmp_path / "map.h5", "r") as f:
        assert f["x"].attrs["units"] == "um"


def test_implausible_scenes_warn_with_number_limit_and_remedy(comm, warnings_of):
    data = {"grid": {"nx": 32}, "surface": {"hurst": 0.8, "lambda_min": 8, "rms_slope": 0.77},
            "control": {"kind": "load", "values": [0.001, 5.0]},
            "solver": {"planner": "estimate"}}
    build(Scene.from_dict(data), comm)
    said = " | ".join(warnings_of)
    if comm.rank == 0:      # once, on rank 0
        assert "rms slope h0' = 0.77 is beyond the small-slope half-space (h0' <= 0.3)" in said
        assert "load P0 = 5 gives a contact fraction" in said and "beyond full contact" in said
        assert "loads 0.00385 to 0.0385 give c = 0.01 to 0.1" in said
        assert len(warnings_of) == 2
    else:
        assert warnings_of == []
    strict = Scene.from_dict({**data, "checks": {"plausibility": "error"}})
    with pytest.raises(PlausibilityError, match="rms slope h0' = 0.77"):
        build(strict, comm)


def test_a_map_read_in_the_wrong_unit_has_an_absurd_slope(comm, mpi_tmp_path, warnings_of):
    # a0 given in um, heights in nm: slopes 1000 times too steep
    path = write(comm, mpi_tmp_path / "map.toml",
                 scene_text('[grid]\na0 = 0.00234375\n', kind="none").replace(
                     "values = [0.002]\n", ""))
    build(load_scene(path, comm), comm)
    if comm.rank == 0:
        assert any("is absurd for a surface" in w and "(lengths in nm)" in w
                   and "units.length" in w for w in warnings_of), warnings_of


def test_the_python_route_warns_too(comm, warnings_of):
    x = np.arange(64) / 64
    wave = 0.05 * np.cos(2 * np.pi * x)[:, None] * np.cos(2 * np.pi * x)[None, :]
    r = petgap.contact(wave, 1 / 64, load=1.0, contact_modulus=1.0)
    assert r.contact_fraction > 0.5
    if comm.rank == 0:
        assert any("gives a contact fraction" in w and "beyond full contact" in w
                   for w in warnings_of), warnings_of
    else:
        assert warnings_of == []


def test_small_patches_are_flagged_after_the_solve(comm, warnings_of):
    rng = np.random.default_rng(6)
    rough = rng.standard_normal((64, 64)) * 0.02        # white noise: patches of a pixel
    petgap.contact(rough, 1.0, load=0.001)
    if comm.rank == 0:
        assert any("contact patches are" in w and "resolved: d_rep >= 10 pixels" in w
                   for w in warnings_of), warnings_of


def test_check_tells_what_run_will_need(comm, mpi_tmp_path, capsys):
    path = write(comm, mpi_tmp_path / "map.toml", scene_text(values="[5.0]"))
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    if comm.rank != 0:
        return
    assert 'length = "nm"' in out
    assert "# surface: h0 = 3.153 nm; h0' = 0.3671 spectral, 0.166 by finite differences " \
           "inside the map" in out
    assert "use the finite-difference (inside the map) h0' = 0.166 (free boundary)" in out
    assert "# loads: P0 = 0.00083 to 0.0083 give a contact fraction c = 0.01 to 0.1" in out
    assert "# warning: load P0 = 5 gives a contact fraction" in out
    assert "# memory: about" in out and "# time: " in out and " per step" in out


def test_check_refuses_implausible_input_when_the_scene_says_so(comm, mpi_tmp_path, capsys):
    path = write(comm, mpi_tmp_path / "map.toml",
                 scene_text('[checks]\nplausibility = "error"\n', values="[5.0]"))
    assert main(["check", str(path)]) == 2
    if comm.rank == 0:
        assert "load P0 = 5 gives a contact fraction" in capsys.readouterr().err


def test_pressure_maps_clip_a_hot_pixel_and_axes_carry_units():
    from petgap.app.overview import PRESSURE_PERCENTILE, _pressure_scale, unit_label
    values = np.full((50, 50), 0.01)
    values[:25] = 0.0
    values[3, 40] = 100.0                      # one hot pixel
    kwargs, label = _pressure_scale(values, "pressure $p$")
    assert kwargs == {"vmin": 0.0, "vmax": pytest.approx(0.01)}
    assert f"clipped at its {PRESSURE_PERCENTILE:g}th percentile (max 100)" in label
    assert unit_label("$x$", "um") == "$x$ (um)"
    assert unit_label("PSD", "nm", 4) == "PSD (nm$^{4}$)"
    assert unit_label("$x$", "1") == "$x$ (scene units)"


def test_post_tables_carry_the_files_unit(comm, mpi_tmp_path):
    from petgap.app.post import main as post_main
    path = write(comm, mpi_tmp_path / "map.toml", scene_text(kind="none").replace(
        "values = [0.002]\n", ""))
    run_scene(load_scene(path, comm), comm, mpi_tmp_path / "map.h5")
    assert post_main([str(mpi_tmp_path / "map.h5"), "-o", str(mpi_tmp_path / "post")]) == 0
    if comm.rank == 0:
        table = (mpi_tmp_path / "post" / "surface-statistics.csv").read_text().splitlines()
        header, row = table[0].split(","), table[1].split(",")
        assert row[header.index("length_unit")] == "nm"
