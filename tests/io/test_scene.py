"""Scene files: defaults, lengths in pixels, and one test per class of validation error.

Every rank parses (rank 0 reads, the result is broadcast) and checks its own copy.
"""
import json
import re
from pathlib import Path

import pytest

from petgap.io.scene import Scene, SceneError, describe_schema

ROOT = Path(__file__).resolve().parents[2]

MINIMAL = """
[grid]
nx = 64
ny = 32
a0 = 0.5

[surface]
hurst = 0.7
lambda_min = "8 a0"
"""


def parse(comm, text, **kwargs):
    return Scene.from_text(text, comm, source="test.toml", **kwargs)


def error_of(comm, text, **kwargs):
    with pytest.raises(SceneError) as info:
        parse(comm, text, **kwargs)
    return str(info.value)


def test_defaults_and_derived_values(comm):
    scene = parse(comm, MINIMAL)
    assert scene.grid.shape == (64, 32) and scene.grid.size == (32.0, 16.0)
    s = scene.surface
    assert s.kind == "self-affine" and s.lambda_min == 4.0  # 8 pixels of 0.5
    assert s.lambda_max == 8.0  # min(Lx, Ly) / 2
    assert s.rms_slope == 0.1 and s.rms_height is None and s.seed == 1
    assert s.path is None and s.dataset is None  # keys of kind = "file"
    assert scene.material.contact_modulus == 1.0
    assert scene.interaction.kind == "hard-wall" and scene.interaction.range is None
    assert scene.control.kind == "none" and scene.control.values is None
    assert scene.solver.tao_type == "pcg" and scene.solver.tolerance == 1e-8
    assert scene.solver.planner == "auto" and scene.solver.petsc_options == ()
    assert scene.output.fields == ("topography", "gap", "pressure") and scene.output.statistics
    assert scene.text == MINIMAL
    json.loads(scene.to_json())  # provenance is plain data


def test_ny_defaults_to_nx(comm):
    scene = parse(comm, "[grid]\nnx = 16\n[surface]\nhurst = 0.5\nlambda_min = 4\n")
    assert scene.grid.shape == (16, 16)


def test_full_scene(comm):
    scene = parse(comm, MINIMAL + """
rms_height = "2 a0"
lambda_max = 12.0
seed = 0
[interaction]
kind = "exponential"
work_of_adhesion = 1e-4
range = "0.5 a0"
[control]
kind = "mean-gap"
values = ["1 a0", 2.5]
[solver]
tao_type = "blmvm"
petsc_options = {"-tao_monitor" = "", tao_max_it = 50, tao_ls_type = "armijo", flag = true}
planner = "estimate"
[output]
fields = ["gap", "displacement"]
statistics = false
""")
    assert scene.surface.rms_height == 1.0 and scene.surface.rms_slope is None
    assert scene.surface.lambda_max == 12.0 and scene.surface.seed == 0
    assert scene.interaction.range == 0.25 and scene.interaction.resolution_check == "warn"
    assert scene.control.values == (0.5, 2.5)
    assert scene.solver.petsc_options == (("tao_monitor", ""), ("tao_max_it", "50"),
                                          ("tao_ls_type", "armijo"), ("flag", "true"))
    assert scene.solver.petsc_args() == ["-tao_monitor", "-tao_max_it", "50", "-tao_ls_type",
                                         "armijo", "-flag", "true"]
    assert scene.output.fields == ("gap", "displacement")


def test_default_scene_file_is_valid(comm):
    scene = Scene.from_file(ROOT / "runs" / "default.toml", comm)
    assert scene.grid.shape == (512, 512)
    assert scene.surface.lambda_min == 32.0 and scene.surface.lambda_max == 256.0
    assert scene.control.kind == "load" and scene.control.values == (0.0015,)
    assert scene.path.endswith("default.toml")


@pytest.mark.parametrize("path", sorted((ROOT / "runs").glob("**/*.toml")),
                         ids=lambda p: p.name)
def test_every_scene_in_runs_is_valid(comm, path):
    """The scenes the docs point to (runs/, runs/slurm/) parse and name the grid their header says."""
    scene = Scene.from_file(path, comm)
    header = path.read_text().split("\n[", 1)[0]
    sizes = {(int(a), int(b)) for a, b in re.findall(r"(\d+) x (\d+)", header)}
    assert not sizes or scene.grid.shape in sizes, (sizes, scene.grid.shape)


def test_unknown_key_suggests_nearest(comm):
    msg = error_of(comm, MINIMAL + "lamda_max = 3\n")
    assert "surface.lamda_max = 3" in msg and "did you mean surface.lambda_max?" in msg
    assert "allowed" in msg


def test_key_in_wrong_section_names_its_section(comm):
    msg = error_of(comm, MINIMAL.replace("a0 = 0.5", "a0 = 0.5\nhurst = 0.3"))
    assert "grid.hurst = 0.3" in msg and "surface.hurst" in msg


def test_unknown_section_suggests_nearest(comm):
    msg = error_of(comm, MINIMAL + "[solvr]\ntolerance = 1e-6\n")
    assert "[solvr]" in msg and "did you mean [solver]?" in msg


def test_top_level_key(comm):
    msg = error_of(comm, "nx = 4\n" + MINIMAL)
    assert "nx = 4" in msg and "grid.nx" in msg


SURFACE = '[surface]\nhurst = 0.7\nlambda_min = "8 a0"\n'


@pytest.mark.parametrize("text, shown", [
    ("[grid]\nnx = 64.0\n" + SURFACE, "grid.nx = 64.0"),
    ("[grid]\nnx = true\n" + SURFACE, "grid.nx = true"),
    ('[grid]\nnx = 64\na0 = "1"\n' + SURFACE, 'grid.a0 = "1"'),
    ("[grid]\nnx = 64\n" + SURFACE + "[output]\nfields = \"gap\"\n", 'output.fields = "gap"'),
    ("[grid]\nnx = 64\n" + SURFACE + "[solver]\npetsc_options = 3\n", "solver.petsc_options = 3"),
    ("[grid]\nnx = 64\n" + SURFACE + "[material]\ncontact_modulus = nan\n",
     "material.contact_modulus = nan"),
    ("grid = 3\n" + SURFACE, "grid = 3"),
])
def test_wrong_type(comm, text, shown):
    msg = error_of(comm, text)
    assert shown in msg and "allowed: " in msg


@pytest.mark.parametrize("text, shown, allowed", [
    ("[grid]\nnx = 0\n" + SURFACE, "grid.nx = 0", "an integer >= 1"),
    ("[grid]\nnx = 64\n" + SURFACE.replace("0.7", "1.0"), "surface.hurst = 1.0", "in (0, 1)"),
    ("[grid]\nnx = 64\n" + SURFACE + "seed = -3\n", "surface.seed = -3", ">= 0"),
    ("[grid]\nnx = 64\n" + SURFACE + "[solver]\ntolerance = 0.5\n", "solver.tolerance = 0.5",
     "in (0, 0.1]"),
    ("[grid]\nnx = 64\n" + SURFACE + "[material]\ncontact_modulus = -1\n",
     "material.contact_modulus = -1", "> 0"),
])
def test_out_of_range(comm, text, shown, allowed):
    msg = error_of(comm, text)
    assert f"{shown}: out of range; allowed: " in msg and allowed in msg


def test_bad_choice_suggests(comm):
    msg = error_of(comm, MINIMAL + '[solver]\ntao_type = "blmv"\n')
    assert 'solver.tao_type = "blmv"' in msg and 'did you mean "blmvm"' in msg
    assert '"bncg"' in msg  # the choices are listed


def test_bad_list_entry(comm):
    msg = error_of(comm, MINIMAL + '[output]\nfields = ["gap", "stress"]\n')
    assert "output.fields" in msg and '"stress"' in msg and '"displacement"' in msg


def test_bad_length_string(comm):
    msg = error_of(comm, MINIMAL.replace('"8 a0"', '"8 pixels"'))
    assert 'surface.lambda_min = "8 pixels"' in msg and '"32 a0"' in msg


def test_required_key(comm):
    msg = error_of(comm, MINIMAL.replace("hurst = 0.7\n", ""))
    assert "surface.hurst is missing" in msg


def test_key_of_another_kind(comm):
    msg = error_of(comm, MINIMAL + '[interaction]\nwork_of_adhesion = 1.0\n')
    assert "interaction.work_of_adhesion = 1.0" in msg and 'interaction.kind = "hard-wall"' in msg
    assert 'only with interaction.kind = "exponential"' in msg


def test_required_with_kind(comm):
    msg = error_of(comm, MINIMAL + '[interaction]\nkind = "exponential"\nrange = 1\n')
    assert "interaction.work_of_adhesion is missing" in msg


def test_rms_slope_and_height_exclusive(comm):
    msg = error_of(comm, MINIMAL + "rms_slope = 0.2\nrms_height = 3\n")
    assert "surface.rms_slope = 0.2" in msg and "rms_height" in msg and "exactly one" in msg


def test_cross_checks(comm):
    msg = error_of(comm, MINIMAL + 'lambda_max = "4 a0"\n')
    assert "surface.lambda_max = 2.0" in msg and "lambda_min < lambda_max" in msg
    msg = error_of(comm, MINIMAL.replace('"8 a0"', '"1 a0"'))
    assert "surface.lambda_min" in msg and "Nyquist" in msg
    msg = error_of(comm, MINIMAL + '[control]\nkind = "load"\nvalues = [0.01, -0.01]\n')
    assert "control.values" in msg and "hard-wall" in msg
    msg = error_of(comm, MINIMAL + '[control]\nkind = "load"\nvalues = 0.01\n'
                   'reference = "non-adhesive"\n')
    assert "control.reference" in msg and "exponential" in msg
    msg = error_of(comm, MINIMAL + '[control]\nkind = "mean-gap"\nvalues = [1.0, 0]\n')
    assert "control.values = [1.0, 0]" in msg and "item 1 (0)" in msg


def test_single_precision_tolerance_floor(comm):
    """A single solve asked below what 32 bits resolve is refused, naming the floor and
    the way out; at the floor it is accepted."""
    from petgap.io.scene import SINGLE_TOLERANCE_FLOOR
    below = SINGLE_TOLERANCE_FLOOR / 2
    msg = error_of(comm, MINIMAL + f'[solver]\nprecision = "single"\ntolerance = {below!r}\n')
    assert f"solver.tolerance = {below!r}" in msg, msg
    assert f">= {SINGLE_TOLERANCE_FLOOR:g}" in msg and '"mixed"' in msg
    scene = parse(comm, MINIMAL + f'[solver]\nprecision = "single"\n'
                  f'tolerance = {SINGLE_TOLERANCE_FLOOR!r}\n')
    assert scene.solver.tolerance == SINGLE_TOLERANCE_FLOOR
    # mixed refines in double: any tolerance
    assert parse(comm, MINIMAL + '[solver]\nprecision = "mixed"\ntolerance = 1e-10\n'
                 ).solver.precision == "mixed"


def test_adhesive_load_may_be_tensile(comm):
    scene = parse(comm, MINIMAL + '[interaction]\nkind = "exponential"\nwork_of_adhesion = 1e-3\n'
                  'range = "2 a0"\n[control]\nkind = "load"\nvalues = [-1e-4, 0, 1e-3]\n'
                  'reference = "non-adhesive"\n')
    assert scene.control.values == (-1e-4, 0.0, 1e-3)
    assert scene.control.reference == "non-adhesive"


def test_all_errors_reported_at_once(comm):
    msg = error_of(comm, "[grid]\nnx = -1\n[surface]\nhurst = 2\nlambda_min = 4\n"
                   "[output]\nstatistics = 1\n")
    assert msg.startswith("test.toml: 3 errors")
    for key in ("grid.nx = -1", "surface.hurst = 2", "output.statistics = 1"):
        assert key in msg


def test_malformed_toml_gives_line(comm):
    msg = error_of(comm, "[grid]\nnx = 64\nny = \n")
    assert "not valid TOML" in msg and "line 3" in msg


def test_missing_file(comm, mpi_tmp_path):
    path = mpi_tmp_path / "nowhere.toml"
    with pytest.raises(SceneError, match="scene file .*nowhere.toml not found"):
        Scene.from_file(path, comm)


def test_file_surface_path_relative_to_scene(comm, mpi_tmp_path):
    if comm.rank == 0:
        (mpi_tmp_path / "data").mkdir()
        (mpi_tmp_path / "data" / "topo.h5").write_bytes(b"")
        (mpi_tmp_path / "scene.toml").write_text(
            '[grid]\nnx = 8\n[surface]\nkind = "file"\npath = "data/topo.h5"\ndataset = "h"\n')
        (mpi_tmp_path / "bad.toml").write_text(
            '[grid]\nnx = 8\n[surface]\nkind = "file"\npath = "data/missing.h5"\n')
    comm.Barrier()
    scene = Scene.from_file(mpi_tmp_path / "scene.toml", comm)
    assert Path(scene.surface.path) == (mpi_tmp_path / "data" / "topo.h5").resolve()
    assert scene.surface.dataset == "h" and scene.surface.hurst is None
    with pytest.raises(SceneError, match=r'surface.path = "data/missing.h5": no such file'):
        Scene.from_file(mpi_tmp_path / "bad.toml", comm)


def test_every_rank_gets_rank_zeros_verdict(comm):
    """Only rank 0's text counts, so all ranks raise together (or none does)."""
    text = MINIMAL if comm.rank != 0 else MINIMAL.replace("0.7", "7.0")
    with pytest.raises(SceneError, match="surface.hurst = 7.0"):
        parse(comm, text)
    text = MINIMAL if comm.rank == 0 else "garbage ["
    assert parse(comm, text).surface.hurst == 0.7


def test_scene_is_frozen(comm):
    scene = parse(comm, MINIMAL)
    with pytest.raises(AttributeError):
        scene.grid.nx = 3


def test_describe_schema_lists_every_key():
    table = describe_schema()
    for key in ("grid.nx", "grid.a0", "surface.hurst", "surface.lambda_max", "surface.path",
                "interaction.range", "control.values", "control.reference", "solver.tao_type",
                "solver.petsc_options", "output.fields"):
        assert f"`{key}`" in table
    assert "min(Lx, Ly) / 2" in table
    assert all(line.count("|") - line.count("\\|") == 6 for line in table.splitlines())


@pytest.mark.parametrize("text, shown", [
    ("[grid]\nnx = 9223372036854775807\n",
     "grid.nx = 9223372036854775807: is beyond the index range"),
    ("[grid]\nnx = 64\nny = 2147483648\n", "grid.ny = 2147483648: is beyond the index range"),
    ("[grid]\nnx = 64\na0 = 1e-320\n",
     "grid.a0 = 1e-320: is so small that the largest wavevector 2 pi / a0 overflows"),
    ("[grid]\nnx = 64\na0 = 1e307\n", "grid.a0 = 1e+307: is so large that the system size"),
    ("[grid]\nnx = 64\n[surface]\nhurst = 0.7\nlambda_min = 1e-320\n",
     "surface.lambda_min = 1e-320: is so small that the wavevector 2 pi / lambda_min"),
])
def test_absurd_grids_name_their_key(comm, text, shown):
    """Sizes beyond the kernels' index range and pixel sizes whose wavevectors or system
    size overflow are scene errors naming the key, not errors deep in the run."""
    if "[surface]" not in text:
        text += '[surface]\nhurst = 0.7\nlambda_min = "8 a0"\n'
    message = error_of(comm, text)
    assert shown in message and "allowed:" in message
    assert message.count("\n") == 0  # one error, not its consequences
