"""The single-precision grid: FFTW's float library through the same binding source.

Transforms against numpy.fft (to float32 round-off), the fused elastic convolution and
its sparse forms against the double grid's, double accumulation of the reductions,
buffers of half the size, and the refusals.
"""
import numpy as np
import pytest

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.grid import Grid, weighted_power

SHAPES = [(45, 38), (113, 76), (64, 48), (16, 5)]
EPS = np.finfo(np.float32).eps


def grids(comm, shape, size=None):
    return (Grid(shape, size=size, comm=comm, planner="estimate"),
            Grid(shape, size=size, comm=comm, planner="estimate", precision="single"))


def rel_max(comm, a, b):
    """``max|a - b| / max|b|`` over all ranks (complex or real), in double."""
    a, b = np.asarray(a, np.complex128), np.asarray(b, np.complex128)
    num = comm.allreduce(float(np.abs(a - b).max()), op=max)
    den = comm.allreduce(float(np.abs(b).max()), op=max)
    return num / den


@pytest.mark.parametrize("shape", SHAPES)
def test_forward_matches_numpy(comm, shape):
    double, single = grids(comm, shape, size=(2.0, 3.5))
    assert single.dtype == np.float32 and single.complex_dtype == np.complex64
    assert single.real.dtype == np.float32 and single.fourier.dtype == np.complex64
    glob = np.random.default_rng(7).standard_normal(shape)
    fourier = single.forward(single.local_part(glob).astype(np.float32)).copy()
    reference = np.fft.rfft2(glob).T[single.ky_slice]
    assert rel_max(comm, fourier, reference) < 20 * EPS * np.log2(glob.size)
    single.forward(single.local_part(glob))
    back = single.backward() / single.npoints
    assert rel_max(comm, back, single.local_part(glob)) < 20 * EPS * np.log2(glob.size)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("power", [1, -1])
def test_convolution_matches_the_double_grid(comm, shape, power):
    double, single = grids(comm, shape)
    glob = np.random.default_rng(11).standard_normal(shape)
    ref = Grid.convolve_qpower(_filled(double, glob), 0.5 / double.npoints, power).copy()
    out = Grid.convolve_qpower(_filled(single, glob), 0.5 / single.npoints, power)
    assert out.dtype == np.float32
    assert rel_max(comm, out, ref) < 50 * EPS * np.log2(glob.size)


def _filled(grid, glob):
    grid.real[...] = grid.local_part(glob)
    return grid


@pytest.mark.parametrize("shape", SHAPES)
def test_sparse_convolution_matches_the_double_grid(comm, shape):
    double, single = grids(comm, shape)
    rng = np.random.default_rng(5 + comm.rank)
    width = double.padded.shape[1]
    rows = double.local_shape[0]
    flat = np.sort(rng.choice(rows * shape[1], size=max(1, rows * shape[1] // 7),
                              replace=False))
    pidx = (flat // shape[1] * width + flat % shape[1]).astype(np.int32)
    values = rng.standard_normal(len(pidx))
    scale = 2.0 / double.npoints
    gathered = np.empty(len(pidx))
    double.convolve_qpower_sparse(pidx, values, scale, -1, gathered=gathered)
    out32 = np.empty(len(pidx), dtype=np.float32)
    single.convolve_qpower_sparse(pidx, values.astype(np.float32), scale, -1, gathered=out32)
    assert rel_max(comm, out32, gathered) < 50 * EPS * np.log2(double.npoints)
    padded = single.aligned_padded()
    assert padded.dtype == np.float32
    single.convolve_qpower_sparse(pidx, values.astype(np.float32), scale, -1, out=padded)
    double.convolve_qpower_sparse(pidx, values, scale, -1)
    assert rel_max(comm, padded[:, :shape[1]], double.real) < 50 * EPS * np.log2(double.npoints)
    with pytest.raises(TypeError, match="values is float64, the grid's fields are float32"):
        single.convolve_qpower_sparse(pidx, values, scale, -1, gathered=out32)


def test_reductions_are_double(comm):
    double, single = grids(comm, (64, 48))
    glob = np.random.default_rng(2).standard_normal((64, 48))
    c64 = double.forward(double.local_part(glob)).copy()
    c32 = single.forward(single.local_part(glob)).copy()
    for power in (-1, 0, 1, 2, 4):
        a = weighted_power(c64, double.qx, double.qy, double.hermitian_weight, power)
        b = weighted_power(c32, single.qx, single.qy, single.hermitian_weight, power)
        assert isinstance(b, float) and b == pytest.approx(a, rel=1e-6)
    # 1 + 1e-8 repeated: a float32 sum would lose every increment
    local = np.full(single.local_shape, 1e-8, dtype=np.float32)
    assert single.sum(local) == pytest.approx(1e-8 * single.npoints, rel=1e-6)


def test_half_space_on_a_single_grid(comm):
    double, single = grids(comm, (64, 48), size=(3.0, 2.0))
    glob = np.random.default_rng(9).standard_normal((64, 48))
    hs64, hs32 = ElasticHalfSpace(double, 2.0), ElasticHalfSpace(single, 2.0)
    u = double.local_part(glob)
    p64, p32 = hs64.pressure(u), hs32.pressure(u.astype(np.float32))
    assert p32.dtype == np.float32 and rel_max(comm, p32, p64) < 1e-5
    d64, d32 = hs64.displacement(u), hs32.displacement(u.astype(np.float32))
    assert rel_max(comm, d32, d64) < 1e-5
    assert hs32.energy(u.astype(np.float32)) == pytest.approx(hs64.energy(u), rel=1e-6)


def test_buffers_are_half_and_bad_precision_refused(comm):
    double, single = grids(comm, (64, 48))
    assert single._real_storage.nbytes * 2 == double._real_storage.nbytes
    assert single._fourier_storage.nbytes * 2 == double._fourier_storage.nbytes
    assert single.wisdom_path().name.endswith("-single.txt")
    with pytest.raises(ValueError, match="precision = 'half' is not allowed"):
        Grid((64, 48), comm=comm, precision="half")


def test_a_single_topography_is_not_copied_to_double(comm):
    # a problem on a single grid keeps the caller's float32 slab, so a single-precision
    # run holds its topography once, in 4 bytes per point
    from petgap.mechanics.problem import ContactProblem
    from petgap.surfaces.statistics import statistics
    double, single = grids(comm, (64, 48))
    glob = np.random.default_rng(3).standard_normal((64, 48))
    h32 = single.local_part(glob).astype(np.float32)
    problem = ContactProblem(single, h32, ElasticHalfSpace(single, 1.0))
    assert problem.topography is h32
    s32, s64 = statistics(single, h32), statistics(double, double.local_part(glob))
    # the mean and the spectral sums are accumulated in double
    assert s32.mean == pytest.approx(s64.mean, abs=1e-7)
    assert s32.rms_height == pytest.approx(s64.rms_height, rel=1e-6)
    assert s32.rms_slope == pytest.approx(s64.rms_slope, rel=1e-6)


def test_the_single_precision_alias_transforms_in_the_double_grids_buffers(comm):
    """The alias is a single grid of the same decomposition on the first half of the double
    grid's bytes: no buffers of its own, made once, the same numbers as a single grid's;
    the half-space applies it when asked for single precision, counted as an application."""
    double, single = grids(comm, (45, 38), size=(2.0, 3.5))
    alias = double.single_precision_alias()
    assert alias is double.single_precision_alias() and single.single_precision_alias() is single
    assert alias.precision == "single" and alias.local_shape == double.local_shape
    assert alias.x_slice == double.x_slice and alias.ky_slice == double.ky_slice
    for mine, theirs in ((alias.padded, double.padded), (alias.fourier, double.fourier)):
        assert np.shares_memory(mine, theirs)
        assert mine.__array_interface__["data"][0] == theirs.__array_interface__["data"][0]
    assert alias._real_storage.nbytes * 2 == double._real_storage.nbytes
    rng = np.random.default_rng(8 + comm.rank)
    width, rows = double.padded.shape[1], double.local_shape[0]
    flat = np.sort(rng.choice(rows * 38, size=rows * 38 // 5, replace=False))
    pidx = (flat // 38 * width + flat % 38).astype(np.int32)
    values = rng.standard_normal(len(pidx)).astype(np.float32)
    scale = 2.0 / double.npoints
    want, got = np.empty(len(pidx), np.float32), np.empty(len(pidx), np.float32)
    single.convolve_qpower_sparse(pidx, values, scale, -1, gathered=want)
    alias.convolve_qpower_sparse(pidx, values, scale, -1, gathered=got)
    np.testing.assert_array_equal(got, want)
    half_space = ElasticHalfSpace(double, 2.0)
    exact = np.empty(len(pidx))
    half_space.apply_sparse(pidx, values.astype(np.float64), inverse=True, gathered=exact)
    before = half_space.applications
    half_space.apply_sparse(pidx, values, inverse=True, gathered=got, precision="single")
    assert half_space.applications == before + 1
    assert rel_max(comm, got, exact) < 50 * EPS * np.log2(double.npoints)
    half_space.apply_sparse(pidx, values, inverse=True, precision="single")   # to alias.real
    np.testing.assert_array_equal(alias.padded.ravel()[pidx], got)
    with pytest.raises(ValueError, match="precision = 'half' is not allowed"):
        half_space.apply_sparse(pidx, values, precision="half", gathered=got)
