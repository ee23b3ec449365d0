"""The slab decomposition and FFTW-MPI transforms against numpy.fft on awkward grids."""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.parallel.grid import DecompositionError, Grid

SHAPES = [(65, 48), (113, 76), (7, 9), (16, 5), (4, 64)]


@pytest.mark.parametrize("shape", SHAPES)
def test_forward_matches_numpy(comm, shape):
    grid = Grid(shape, size=(2.0, 3.5), comm=comm, planner="estimate")
    glob = np.random.default_rng(7).standard_normal(shape)
    fourier = grid.forward(grid.local_part(glob)).copy()
    reference = np.fft.rfft2(glob).T[grid.ky_slice]
    np.testing.assert_allclose(fourier, reference, rtol=0, atol=1e-12 * np.abs(reference).max())


@pytest.mark.parametrize("shape", SHAPES)
def test_backward_inverts_forward(comm, shape):
    grid = Grid(shape, comm=comm, planner="estimate")
    glob = np.random.default_rng(3).standard_normal(shape)
    grid.forward(grid.local_part(glob))
    back = grid.backward() / grid.npoints
    np.testing.assert_allclose(back, grid.local_part(glob), atol=1e-13)


def test_slabs_tile_the_grid(comm):
    grid = Grid((113, 76), comm=comm, planner="estimate")
    rows = comm.allgather((grid.x_slice.start, grid.x_slice.stop))
    krows = comm.allgather((grid.ky_slice.start, grid.ky_slice.stop))
    assert rows[0][0] == 0 and rows[-1][1] == 113
    assert krows[0][0] == 0 and krows[-1][1] == 76 // 2 + 1
    assert all(a[1] == b[0] for a, b in zip(rows, rows[1:]))
    assert all(a[1] == b[0] for a, b in zip(krows, krows[1:]))


def test_wavevectors(comm):
    grid = Grid((6, 8), size=(3.0, 4.0), comm=comm, planner="estimate")
    np.testing.assert_allclose(grid.qx, 2 * np.pi * np.array([0, 1, 2, 3, -2, -1]) / 3.0)
    n = np.arange(grid.ky_slice.start, grid.ky_slice.stop)
    np.testing.assert_allclose(grid.qy, 2 * np.pi * n / 4.0)
    weights = np.where((n == 0) | (n == 4), 1, 2)
    np.testing.assert_array_equal(grid.hermitian_weight, weights)
    # Parseval through the Hermitian weights
    glob = np.random.default_rng(0).standard_normal((6, 8))
    f = grid.forward(grid.local_part(glob))
    assert np.isclose(grid.fourier_sum(np.abs(f) ** 2) / grid.npoints, np.sum(glob ** 2))


def test_undecomposable_grid_raises_on_every_rank(comm):
    too_few = comm.size + 1 if comm.size == 1 else 1  # 1 row cannot feed 2 ranks
    if comm.size == 1:
        pytest.skip("any grid decomposes on one rank")
    with pytest.raises(DecompositionError, match="cannot be split over"):
        Grid((too_few, 16), comm=comm, planner="estimate")
    with pytest.raises(DecompositionError, match="Fourier rows"):
        Grid((16, 1), comm=comm, planner="estimate")


def test_bad_shapes(comm):
    with pytest.raises(ValueError, match="positive"):
        Grid((0, 4), comm=comm)
    with pytest.raises(ValueError, match="two integers"):
        Grid((4.5, 4), comm=comm)
    with pytest.raises(ValueError, match="size must be positive"):
        Grid((4, 4), size=(1.0, -1.0), comm=comm)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_scratch_is_a_contiguous_slab_on_the_real_fft_buffer(comm, precision):
    grid = Grid((30, 21), comm=comm, planner="estimate", precision=precision)
    scratch = grid.scratch()
    assert scratch.shape == grid.local_shape and scratch.dtype == grid.dtype
    assert scratch.flags.c_contiguous and np.shares_memory(scratch, grid.padded)
    # it starts where the buffer does and ends within the padded slab
    assert scratch.__array_interface__["data"][0] == grid.padded.__array_interface__["data"][0]
    assert scratch.size <= grid.padded.size
    # the same view of another padded array (a field a solver keeps in the padded layout)
    other = grid.aligned_padded()
    view = grid.scratch(other)
    assert view.shape == grid.local_shape and view.flags.c_contiguous
    assert view.__array_interface__["data"][0] == other.__array_interface__["data"][0]


def test_serial_grid_on_comm_self(comm):
    """A COMM_SELF grid is a complete serial reference inside an MPI job."""
    grid = Grid((9, 10), comm=MPI.COMM_SELF, planner="estimate")
    assert grid.local_shape == (9, 10) and grid.fourier_local_shape == (6, 9)


def test_wisdom_is_read_again_only_when_the_file_changed(comm, mpi_tmp_path, monkeypatch):
    """Each level of a coarse start makes a grid: the cached wisdom file is parsed
    once per process and set of ranks, and again once a planning run rewrote it."""
    import pathlib
    monkeypatch.setenv("PETGAP_WISDOM_DIR", str(mpi_tmp_path))
    reads = []
    read_text = pathlib.Path.read_text
    monkeypatch.setattr(pathlib.Path, "read_text",
                        lambda self, *a, **k: reads.append(self.name) or read_text(self, *a, **k))
    Grid((40, 36), comm=comm, planner="measure")          # plans, writes the file
    for _ in range(3):
        Grid((20, 18), comm=comm, planner="estimate")
    first = len(reads)
    Grid((44, 36), comm=comm, planner="measure")          # another size: the file is rewritten
    Grid((20, 18), comm=comm, planner="estimate")
    # rank 0 reads, then broadcasts what it read
    assert comm.allgather((first, len(reads))) == [(1, 2)] + [(0, 0)] * (comm.size - 1)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_a_multiplier_that_does_not_fit_the_slab_is_refused(comm, precision):
    """Wavevectors, row multiplicities and the power are checked before any transform runs."""
    grid = Grid((24, 18), comm=comm, planner="estimate", precision=precision)
    plans, qx, qy, w = grid._convolution, grid.qx, grid.qy, grid.hermitian_weight
    pidx = np.zeros(1, dtype=np.int32)
    values = np.ones(1, dtype=grid.dtype)
    calls = {"apply": lambda qx, qy, w, p: plans.apply(qx, qy, 1.0, p),
             "apply_sparse": lambda qx, qy, w, p: plans.apply_sparse(pidx, values, qx, qy, 1.0, p),
             "begin": lambda qx, qy, w, p: plans.begin(qx, qy, w, 1.0, p),
             "begin_sparse": lambda qx, qy, w, p: plans.begin_sparse(pidx, values, qx, qy, w,
                                                                      1.0, p)}
    for name, call in calls.items():
        with pytest.raises(ValueError, match="wavevector arrays do not match"):
            call(qx[:-1], qy, w, 1)
        with pytest.raises(ValueError, match="wavevector arrays do not match"):
            call(qx, np.append(qy, 0.0), w, 1)
        with pytest.raises(ValueError, match="power must be"):
            call(qx, qy, w, 2)
        if name.startswith("begin"):
            with pytest.raises(ValueError, match="wrow does not match"):
                call(qx, qy, np.append(w, 1.0), 1)
        call(qx, qy, w, -1)   # the same arrays, fitting, are taken
