"""Distributed topography files: round trips, and errors raised on every rank alike.

Files are written by rank 0 alone (as a user or another program would) before a
barrier; then every rank loads and asserts on its own slab.  An error test that
raised on one rank only would hang the other in the loader's collectives, so
these tests also check that no rank is left behind.
"""
import os

import numpy as np
import pytest

os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")
import h5py  # noqa: E402

from petgap.parallel.grid import Grid  # noqa: E402
from petgap.surfaces.topography import load_topography, save_topography_npy  # noqa: E402

SHAPE = (65, 48)


@pytest.fixture
def grid(comm):
    return Grid(SHAPE, size=(2.0, 3.0), comm=comm, planner="estimate")


def on_root(comm, write):
    """Run ``write()`` on rank 0 only, then let every rank see the file."""
    if comm.rank == 0:
        write()
    comm.Barrier()


def field(shape=SHAPE, seed=0):
    return np.random.default_rng(seed).standard_normal(shape)


def write_h5(path, **datasets):
    with h5py.File(path, "w") as f:  # serial driver: written by one process
        for name, data in datasets.items():
            f.create_dataset(name, data=data)


# -------------------------------------------------------------- round trips
@pytest.mark.parametrize("shape", [(65, 48), (113, 76), (4, 7)])
def test_npy_round_trip(comm, mpi_tmp_path, shape):
    grid = Grid(shape, comm=comm, planner="estimate")
    heights = field(shape, seed=1)
    path = mpi_tmp_path / "h.npy"
    save_topography_npy(grid, grid.local_part(heights), path)
    comm.Barrier()
    loaded = load_topography(grid, path)
    np.testing.assert_array_equal(np.load(path), heights)  # a plain .npy, readable anywhere
    np.testing.assert_array_equal(loaded, grid.local_part(heights))
    assert loaded.dtype == np.float64 and loaded.flags.c_contiguous


def test_npy_float32_and_fortran_order(comm, grid, mpi_tmp_path):
    heights = field(seed=2)
    on_root(comm, lambda: (np.save(mpi_tmp_path / "f32.npy", heights.astype(np.float32)),
                           np.save(mpi_tmp_path / "fortran.npy", np.asfortranarray(heights))))
    single = load_topography(grid, mpi_tmp_path / "f32.npy")
    fortran = load_topography(grid, mpi_tmp_path / "fortran.npy")
    np.testing.assert_array_equal(single, grid.local_part(heights.astype(np.float32)))
    np.testing.assert_array_equal(fortran, grid.local_part(heights))


@pytest.mark.parametrize("suffix", [".h5", ".hdf5", ".H5"])
def test_hdf5_round_trip(comm, grid, mpi_tmp_path, suffix):
    heights = field(seed=3)
    path = mpi_tmp_path / f"h{suffix}"
    on_root(comm, lambda: write_h5(path, topography=heights, x=np.arange(65.0),
                                   other=2 * heights))
    by_default = load_topography(grid, path)
    by_name = load_topography(grid, path, dataset="other")
    np.testing.assert_array_equal(by_default, grid.local_part(heights))
    np.testing.assert_array_equal(by_name, grid.local_part(2 * heights))


def test_hdf5_only_2d_dataset_and_groups(comm, grid, mpi_tmp_path):
    heights = field(seed=4)
    path = mpi_tmp_path / "scan.h5"

    def write():
        with h5py.File(path, "w") as f:
            f.create_dataset("scan/heights", data=heights.astype(np.float32))
            f.create_dataset("scan/x", data=np.arange(65.0))
    on_root(comm, write)
    only = load_topography(grid, path)
    named = load_topography(grid, path, dataset="/scan/heights")
    expected = grid.local_part(heights.astype(np.float32))
    np.testing.assert_array_equal(only, expected)
    np.testing.assert_array_equal(named, expected)


# ------------------------------------------------------------------- errors
def _bad_files(tmp):
    """name -> (writer, expected exception, fragments of its message)."""
    heights = field(seed=5)
    nonfinite = heights.copy()
    nonfinite[40, 7] = np.nan   # rank 1's rows on 2 ranks
    nonfinite[50, 1] = np.inf
    nonfinite[60, 0] = -np.inf
    early = heights.copy()
    early[2, 3] = np.nan        # rank 0's rows
    early[64, 47] = np.nan
    return {
        "missing.npy": (None, FileNotFoundError, ["does not exist"]),
        "notes.txt": (lambda p: p.write_text("measured on a Tuesday\nno heights here\n"),
                      ValueError, ["notes.txt", "SurfaceTopography does not recognise its format"]),
        "cube.npy": (lambda p: np.save(p, np.zeros((65, 48, 2))), ValueError,
                     ["3D with shape (65, 48, 2)", "must be 2D"]),
        "cube.h5": (lambda p: write_h5(p, topography=np.zeros((65, 48, 2))), ValueError,
                    ["cube.h5:topography is 3D"]),
        "small.npy": (lambda p: np.save(p, np.zeros((64, 48))), ValueError,
                      ["shape (64, 48), but the grid is (65, 48)"]),
        "transposed.h5": (lambda p: write_h5(p, topography=heights.T), ValueError,
                          ["shape (48, 65), but the grid is (65, 48)"]),
        "integer.npy": (lambda p: np.save(p, np.zeros(SHAPE, dtype=np.int64)), ValueError,
                        ["int64", "not floating point"]),
        "integer.h5": (lambda p: write_h5(p, topography=np.zeros(SHAPE, dtype=np.int32)),
                       ValueError, ["int32", "not floating point"]),
        "complex.npy": (lambda p: np.save(p, np.zeros(SHAPE, dtype=complex)), ValueError,
                        ["complex128", "not floating point"]),
        "nonfinite.npy": (lambda p: np.save(p, nonfinite), ValueError,
                          ["3 non-finite values", "(i, j) = (40, 7)"]),
        "nonfinite.h5": (lambda p: write_h5(p, topography=nonfinite), ValueError,
                         ["3 non-finite values", "(i, j) = (40, 7)"]),
        "early.npy": (lambda p: np.save(p, early), ValueError,
                      ["2 non-finite values", "(i, j) = (2, 3)"]),
        "huge.npy": (lambda p: np.save(p, np.full(SHAPE, 3e300)), ValueError,
                     ["heights up to 3e+300", "at most 1e+100", "unit"]),
        "garbage.npy": (lambda p: p.write_bytes(b"not a numpy file"), ValueError,
                        ["cannot read", "as a .npy file"]),
        "garbage.h5": (lambda p: p.write_bytes(b"not an HDF5 file"), ValueError,
                       ["cannot read", "as an HDF5 file"]),
        "two.h5": (lambda p: write_h5(p, a=heights, b=heights), ValueError,
                   ["no dataset 'topography' and 2 2D datasets", "a (65, 48)", "dataset="]),
        "none.h5": (lambda p: write_h5(p, x=np.arange(3.0)), ValueError,
                    ["no 2D datasets", "x (3,)"]),
    }


BAD = sorted(_bad_files(None))


@pytest.mark.parametrize("name", BAD)
def test_bad_file_raises_on_every_rank(comm, grid, mpi_tmp_path, name):
    writer, error, fragments = _bad_files(mpi_tmp_path)[name]
    path = mpi_tmp_path / name
    if writer is not None:
        on_root(comm, lambda: writer(path))
    with pytest.raises(error) as info:
        load_topography(grid, path)
    for fragment in fragments:
        assert fragment in str(info.value)


def test_bad_dataset_choice(comm, grid, mpi_tmp_path):
    on_root(comm, lambda: (write_h5(mpi_tmp_path / "h.h5", topography=field()),
                           np.save(mpi_tmp_path / "h.npy", field())))
    with pytest.raises(ValueError, match=r"no dataset 'nope'; datasets: topography \(65, 48\)"):
        load_topography(grid, mpi_tmp_path / "h.h5", dataset="nope")
    with pytest.raises(ValueError, match="datasets exist only in HDF5 files"):
        load_topography(grid, mpi_tmp_path / "h.npy", dataset="topography")


def test_directory_is_not_a_topography(comm, grid, mpi_tmp_path):
    with pytest.raises(ValueError, match="is not a file"):
        load_topography(grid, mpi_tmp_path)


def test_save_errors_on_every_rank(comm, grid, mpi_tmp_path):
    local = grid.local_part(field())
    with pytest.raises(ValueError, match="must end in .npy"):
        save_topography_npy(grid, local, mpi_tmp_path / "h.h5")
    with pytest.raises(OSError, match="could not write"):
        save_topography_npy(grid, local, mpi_tmp_path / "no" / "such" / "dir.npy")
    with pytest.raises(ValueError, match="h_local on rank"):
        save_topography_npy(grid, local[:-1] if comm.rank == comm.size - 1 else local,
                            mpi_tmp_path / "h.npy")
