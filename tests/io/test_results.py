"""Parallel result files: collective field round trips, provenance, steps, no overwriting."""
import os
import types

import numpy as np
import pytest

from petgap.parallel.grid import Grid
from petgap.io.results import (ResultExistsError, ResultFile, flatten_attrs, read_attrs, read_field,
                         step_name, write_field)

import h5py  # after petgap.io.results, which selects the MPI build  # noqa: E402


def serial_read(comm, path, func):
    """``func(h5py.File)`` on rank 0 alone (after every rank closed the file), result everywhere."""
    comm.Barrier()
    result = None
    if comm.rank == 0:
        with h5py.File(path, "r") as f:
            result = func(f)
    return comm.bcast(result, root=0)


@pytest.mark.parametrize("shape", [(13, 14), (64, 48), (7, 33)])  # decomposable on 1-4 ranks
def test_field_round_trip(comm, mpi_tmp_path, shape):
    grid = Grid(shape, size=(2.0, 1.0), comm=comm, planner="estimate")
    reference = np.random.default_rng(11).standard_normal(shape)
    local = grid.local_part(reference).copy()
    path = mpi_tmp_path / "fields.h5"
    with ResultFile.create(path, comm) as result:
        result.write_field("h", grid, local)
        step = result.begin_step(0)
        result.write_field("g", grid, 2 * local, group=step)
        # a non-contiguous view, as the FFT buffer is
        np.copyto(grid.real, local)
        result.write_field("view", grid, grid.real)
        result.end_step(step)
    # what is on disk is the global array, whatever the number of ranks
    on_disk = serial_read(comm, path, lambda f: (f["h"][...], f["step_0000/g"][...],
                                                 f["view"][...], f["h"].dtype))
    np.testing.assert_array_equal(on_disk[0], reference)
    np.testing.assert_array_equal(on_disk[1], 2 * reference)
    np.testing.assert_array_equal(on_disk[2], reference)
    assert on_disk[3] == np.float64
    # and every rank reads back its own slab
    with ResultFile.open(path, comm) as result:
        np.testing.assert_array_equal(result.read_field("h", grid), local)
        np.testing.assert_array_equal(read_field(result.step(0), "g", grid), 2 * local)
        gathered = grid.gather(result.read_field("view", grid))
    if comm.rank == 0:
        np.testing.assert_array_equal(gathered, reference)


def test_rank_with_empty_slab_takes_part(comm, mpi_tmp_path):
    """A rank without rows must still join the collective write and read (no hang)."""
    nx, ny = 3, 4
    rows = [(0, nx)] + [(nx, nx)] * (comm.size - 1)  # rank 0 holds everything
    start, stop = rows[comm.rank]
    grid = types.SimpleNamespace(shape=(nx, ny), x_slice=slice(start, stop),
                                 local_shape=(stop - start, ny))
    reference = np.arange(nx * ny, dtype=float).reshape(nx, ny)
    path = mpi_tmp_path / "empty.h5"
    with ResultFile.create(path, comm) as result:
        write_field(result.file, "f", grid, reference[start:stop])
    with ResultFile.open(path, comm) as result:
        back = read_field(result.file, "f", grid)
    assert back.shape == (stop - start, ny)
    np.testing.assert_array_equal(back, reference[start:stop])


def test_wrong_shapes_are_refused(comm, mpi_tmp_path):
    grid = Grid((16, 14), comm=comm, planner="estimate")
    other = Grid((8, 14), comm=comm, planner="estimate")
    with ResultFile.create(mpi_tmp_path / "shape.h5", comm) as result:
        with pytest.raises(ValueError, match="local shape"):
            result.write_field("f", grid, np.zeros((1, 1)))
        result.write_field("f", grid, np.zeros(grid.local_shape))
        with pytest.raises(ValueError, match=r"has shape \(16, 14\), the grid is \(8, 14\)"):
            result.read_field("f", other)


def test_provenance_attributes(comm, mpi_tmp_path):
    import petgap
    path = mpi_tmp_path / "prov.h5"
    scene = "[grid]\nnx = 8\n" + "# " + "x" * 100_000 + "\n"  # large texts are fine
    result = ResultFile.create(path, comm, provenance={"scene": scene, "extra": {"a": 1}})
    attrs = result.attrs()
    assert attrs["complete"] is False  # until closed
    result.close()
    attrs = serial_read(comm, path, read_attrs)
    assert attrs["complete"] is True
    assert attrs["petgap_version"] == petgap.__version__
    assert attrs["scene"] == scene
    assert attrs["mpi_size"] == comm.size
    assert attrs["extra.a"] == 1
    for key in ("command_line", "hostname", "hosts", "start_time", "end_time", "hdf5_version"):
        assert key in attrs, key
    assert "pytest" in attrs["command_line"]


def test_refuses_to_overwrite(comm, mpi_tmp_path):
    path = mpi_tmp_path / "exists.h5"
    if comm.rank == 0:
        path.write_bytes(b"precious results")
    comm.Barrier()
    with pytest.raises(ResultExistsError) as info:
        ResultFile.create(path, comm)
    assert str(path) in str(info.value) and "--overwrite" in str(info.value)
    comm.Barrier()
    assert path.read_bytes() == b"precious results"
    with ResultFile.create(path, comm, overwrite=True):
        pass
    assert serial_read(comm, path, lambda f: bool(f.attrs["complete"]))


def test_missing_directory(comm, mpi_tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ResultFile.create(mpi_tmp_path / "no" / "such" / "dir.h5", comm)


def test_steps_and_resume(comm, mpi_tmp_path):
    grid = Grid((12, 14), comm=comm, planner="estimate")
    path = mpi_tmp_path / "steps.h5"
    with ResultFile.create(path, comm) as result:
        for i in range(3):
            step = result.begin_step(i, attrs={"load": 0.1 * i})
            result.write_field("gap", grid, np.full(grid.local_shape, float(i)), group=step)
            if i < 2:  # step 2 is "interrupted"
                result.end_step(step, attrs={
                    "statistics": {"contact_fraction": 0.04, "perimeter": 12.5},
                    "solver": {"converged": True, "reason": "CONVERGED_GATOL", "iterations": 17,
                               "history": [1.0, 0.1, 0.01]}})
        assert result.completed_steps() == [0, 1] and result.steps() == [0, 1, 2]

    attrs = serial_read(comm, path, lambda f: read_attrs(f[step_name(1)]))
    assert attrs["complete"] is True and attrs["index"] == 1 and attrs["load"] == 0.1
    assert attrs["solver.reason"] == "CONVERGED_GATOL" and attrs["solver.iterations"] == 17
    assert attrs["solver.converged"] is True and attrs["statistics.perimeter"] == 12.5
    np.testing.assert_array_equal(attrs["solver.history"], [1.0, 0.1, 0.01])

    with ResultFile.open_for_resume(path, comm) as result:
        assert result.completed_steps() == [0, 1]
        with pytest.raises(ValueError, match="complete already"):
            result.begin_step(1)
        step = result.begin_step(2)  # replaces the incomplete one
        assert "gap" not in step
        result.write_field("gap", grid, np.full(grid.local_shape, 2.0), group=step)
        result.end_step(step)
        assert result.completed_steps() == [0, 1, 2]
    attrs = serial_read(comm, path, read_attrs)
    assert attrs["complete"] is True and attrs["resume_count"] == 1


def test_exception_on_every_rank_leaves_file_incomplete(comm, mpi_tmp_path, monkeypatch):
    monkeypatch.setenv("PETGAP_FAILURE_TIMEOUT", "60")
    path = mpi_tmp_path / "failed.h5"
    grid = Grid((8, 14), comm=comm, planner="estimate")
    with pytest.raises(RuntimeError, match="solver exploded"):
        with ResultFile.create(path, comm) as result:
            step = result.begin_step(0)
            result.end_step(step)
            result.begin_step(1)
            raise RuntimeError("solver exploded")
    assert result.file is None  # closed, collectively
    with ResultFile.open(path, comm) as again:
        assert not again.complete and again.completed_steps() == [0]
    with pytest.raises(FileNotFoundError):
        ResultFile.open(mpi_tmp_path / "nothing.h5", comm)
    del grid


def test_flatten_attrs():
    from dataclasses import dataclass

    @dataclass
    class Stats:
        mean: float
        rms: float

    flat = flatten_attrs({"surface": Stats(0.0, 2.0), "solver": {"ok": True, "why": None,
                                                                  "names": ("a", "b")}, "n": 3})
    assert flat == {"surface.mean": 0.0, "surface.rms": 2.0, "solver.ok": np.bool_(True),
                    "solver.names": ["a", "b"], "n": 3}


def test_h5py_is_the_mpi_build():
    assert h5py.get_config().mpi
    assert os.environ.get("H5PY_ALWAYS_USE_MPI")


def test_fields_carry_coordinates_units_and_names(comm, mpi_tmp_path):
    """Dimension scales x, y (pixel positions), units and long_name, root and step alike."""
    grid = Grid((12, 10), size=(6.0, 25.0), comm=comm, planner="estimate", wisdom=False)
    path = mpi_tmp_path / "labelled.h5"
    units = {"length": "nm", "pressure": "GPa"}
    field = np.arange(120, dtype=float).reshape(12, 10)
    with ResultFile.create(path, comm) as out:
        out.write_coordinates(grid, "nm")
        out.write_field("topography", grid, grid.local_part(field), units=units)
        group = out.begin_step(0)
        out.write_coordinates(grid, "nm", group=group)
        out.write_field("pressure", grid, grid.local_part(field), group=group, units=units)
        out.write_field("extra", grid, grid.local_part(field), group=group)
        out.end_step(group)
    if comm.rank != 0:
        return
    with h5py.File(path, "r", driver=None) as f:
        for where, name, unit in (("/", "topography", "nm"), ("/step_0000", "pressure", "GPa")):
            dset = f[where][name]
            assert dset.attrs["units"] == unit
            x, y = dset.dims[0][0], dset.dims[1][0]
            assert x.name == f"{where.rstrip('/')}/x" and y.name == f"{where.rstrip('/')}/y"
            np.testing.assert_array_equal(x[()], np.arange(12) * 0.5)
            np.testing.assert_array_equal(y[()], np.arange(10) * 2.5)
            assert x.attrs["units"] == "nm" and x.attrs["axis"] == "X"
        assert f["step_0000/pressure"].attrs["long_name"].startswith("contact pressure")
        assert "units" not in f["step_0000/extra"].attrs        # not a known field
    xarray = pytest.importorskip("xarray")
    with xarray.open_dataset(path, engine="h5netcdf", group="step_0000") as ds:
        assert ds["pressure"].dims == ("x", "y")
        np.testing.assert_array_equal(ds["pressure"].values, field)
        np.testing.assert_array_equal(ds["y"].values, np.arange(10) * 2.5)
