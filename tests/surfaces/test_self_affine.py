"""Self-affine surfaces and spectral statistics against serial and analytic references.

Every test makes all its collective calls before its first assertion, so a
failure on one rank cannot leave the other waiting in a collective.
"""
import sys
import warnings

import numpy as np
import pytest
from mpi4py import MPI
from scipy import stats

from petgap.parallel.grid import Grid
from petgap.surfaces.self_affine import _fill_spectrum, psd_shape, self_affine
from petgap.surfaces.statistics import SurfaceStatistics, radial_psd, statistics

# Awkward grids: odd and even sizes, non-square, one with few rows per rank.
SHAPES = [(65, 48), (113, 76), (16, 5), (5, 6)]
SIZE = (2.0, 3.0)  # non-square pixels: dx != dy


def make_grid(shape, comm, size=SIZE):
    return Grid(shape, size=size, comm=comm, planner="estimate")


def resolved(grid, pixels=4):
    """A lambda_min of ``pixels`` of the coarser pixel size (4 is just resolved)."""
    return pixels * max(grid.dx, grid.dy)


def gather_all(grid, local):
    """The global field on every rank (small test grids only)."""
    return np.concatenate(grid.comm.allgather(np.asarray(local)), axis=0)


def numpy_statistics(h, lx, ly):
    """Serial reference: real-space mean and rms, full-plane numpy.fft for the derivatives."""
    nx, ny = h.shape
    c = np.fft.fft2(h)
    qx = 2 * np.pi * np.fft.fftfreq(nx, d=lx / nx)
    qy = 2 * np.pi * np.fft.fftfreq(ny, d=ly / ny)
    q2 = qx[:, None] ** 2 + qy[None, :] ** 2
    power = np.abs(c) ** 2
    return SurfaceStatistics(mean=h.mean(), rms_height=h.std(),
                             rms_slope=np.sqrt(np.sum(q2 * power)) / h.size,
                             rms_curvature=np.sqrt(np.sum(q2 ** 2 * power)) / h.size / 2)


def assert_statistics_close(actual, expected, rtol):
    for name in ("rms_height", "rms_slope", "rms_curvature"):
        assert getattr(actual, name) == pytest.approx(getattr(expected, name), rel=rtol), name
    assert actual.mean == pytest.approx(expected.mean, abs=rtol * (abs(expected.mean)
                                                                   + expected.rms_height))


# ------------------------------------------------------------------- spectrum
def test_psd_shape_is_eq5():
    hurst, q1, q2 = 0.7, 2.0, 16.0
    q = np.array([0.0, 0.5, 2.0, 4.0, 16.0, 16.01, 100.0])
    expected = [0.0, 1.0, 1.0, 2.0 ** (-3.4), 8.0 ** (-3.4), 0.0, 0.0]
    np.testing.assert_allclose(psd_shape(q, hurst, q1, q2), expected, rtol=1e-14)
    assert psd_shape(3.0, hurst, q1, q2) == pytest.approx(1.5 ** (-3.4), rel=1e-14)
    with pytest.raises(ValueError, match="hurst"):
        psd_shape(q, 1.2, q1, q2)
    with pytest.raises(ValueError, match="q2"):
        psd_shape(q, hurst, q1, 1.0)


@pytest.mark.parametrize("shape", SHAPES)
def test_rms_slope_is_exact(comm, shape):
    grid = make_grid(shape, comm)
    h = self_affine(grid, 0.8, resolved(grid), 3.0, rms_slope=0.1, seed=3)
    s = statistics(grid, h)
    assert h.shape == grid.local_shape and h.dtype == np.float64
    assert s.rms_slope == pytest.approx(0.1, rel=1e-12)
    assert abs(s.mean) < 1e-14 * s.rms_height


@pytest.mark.parametrize("shape", SHAPES[:2])
def test_rms_height_is_exact(comm, shape):
    grid = make_grid(shape, comm)
    h = self_affine(grid, 0.3, resolved(grid), 1.0, rms_height=2.5, seed=11)
    assert statistics(grid, h).rms_height == pytest.approx(2.5, rel=1e-12)


@pytest.mark.parametrize("shape", SHAPES + [(7, 9)])
def test_statistics_match_numpy(comm, shape):
    grid = make_grid(shape, comm)
    # a surface, and white noise with an offset (every mode, mean to remove)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (7, 9) cannot resolve 4 pixels: irrelevant here
        surface = self_affine(grid, 0.5, resolved(grid, 2), rms_slope=0.2, seed=1)
    noise = grid.local_part(np.random.default_rng(5).standard_normal(shape) + 3.0)
    pairs = [(statistics(grid, h), numpy_statistics(gather_all(grid, h), grid.Lx, grid.Ly))
             for h in (surface, noise)]
    for actual, expected in pairs:
        assert_statistics_close(actual, expected, rtol=1e-12)


@pytest.mark.parametrize("k, l", [(3, 2), (0, 5), (4, 0), (-3, 15)])  # l = 15: Nyquist row
def test_statistics_single_mode_analytic(comm, k, l):
    grid = make_grid((48, 30), comm)
    x, y = grid.local_positions()
    a, b = 0.3, -1.25
    h = a * np.cos(2 * np.pi * (k * x / grid.Lx + l * y / grid.Ly)) + b
    q = np.hypot(2 * np.pi * k / grid.Lx, 2 * np.pi * l / grid.Ly)
    expected = SurfaceStatistics(mean=b, rms_height=a / np.sqrt(2), rms_slope=a * q / np.sqrt(2),
                                 rms_curvature=a * q ** 2 / (2 * np.sqrt(2)))
    assert_statistics_close(statistics(grid, h), expected, rtol=1e-12)


@pytest.mark.parametrize("hurst", [0.3, 0.8])
def test_psd_log_slope_is_minus_two_one_plus_h(comm, hurst):
    """Fit in the power-law range, away from the roll-off and the cutoff, averaged over 4 seeds.

    Over 25 groups of 4 seeds the fitted slope scattered by 0.3-0.4 % (worst 0.9 %)
    around -2(1 + H), so 2 % is ~5 standard deviations.
    """
    grid = make_grid((512, 512), comm, size=(1.0, 1.0))
    lambda_min, lambda_max = 4 / 512, 64 / 512
    q1, q2 = 2 * np.pi / lambda_max, 2 * np.pi / lambda_min
    spectra = []
    for seed in range(4):
        q, c = radial_psd(grid, self_affine(grid, hurst, lambda_min, lambda_max, rms_slope=0.1,
                                            seed=seed))
        spectra.append(c)
    fit = (q > 1.5 * q1) & (q < 0.8 * q2)
    assert fit.sum() >= 6
    slope = np.polyfit(np.log(q[fit]), np.log(np.mean(spectra, axis=0)[fit]), 1)[0]
    assert slope == pytest.approx(-2 * (1 + hurst), rel=0.02)


def test_radial_psd_normalisation(comm):
    """A unit spike has |h_q| = 1 for every q: C = A / N^2 in every bin, exactly."""
    grid = make_grid((65, 48), comm)
    spike = np.zeros(grid.shape)
    spike[3, 7] = 1.0
    q, c = radial_psd(grid, grid.local_part(spike))
    everywhere = comm.allgather((q, c))
    # white noise of variance s^2: C = s^2 dx dy on average
    noise = grid.local_part(np.random.default_rng(2).standard_normal(grid.shape))
    _, c_noise = radial_psd(grid, noise, nbins=4)

    np.testing.assert_allclose(c, grid.area / grid.npoints ** 2, rtol=1e-12)
    assert np.all(np.diff(q) > 0) and q[0] >= 2 * np.pi / 3.0 * (1 - 1e-12)
    for other_q, other_c in everywhere:  # identical on every rank, bit for bit
        np.testing.assert_array_equal(other_q, q)
        np.testing.assert_array_equal(other_c, c)
    assert np.mean(c_noise) == pytest.approx(grid.pixel_area, rel=0.1)


# --------------------------------------------------------------- Gaussianity
def test_heights_are_gaussian(comm):
    """Skewness and excess kurtosis of the heights, averaged over 4 seeds.

    256^2 pixels, lambda_max = 16 and lambda_min = 4 pixels, H = 0.3: over 100
    seeds one surface's skewness had standard deviation 0.026 and its excess
    kurtosis 0.044 (long wavelengths are few, so single surfaces scatter).  The
    mean of 4 seeds has half that; the bounds below are ~6 of those standard
    deviations.
    """
    grid = make_grid((256, 256), comm, size=(1.0, 1.0))
    skew, kurt = [], []
    for seed in range(4):
        h = self_affine(grid, 0.3, 4 / 256, 16 / 256, rms_height=1.0, seed=seed)
        m2, m3, m4 = (grid.mean(h ** p) for p in (2, 3, 4))
        skew.append(m3 / m2 ** 1.5)
        kurt.append(m4 / m2 ** 2 - 3)
    assert abs(np.mean(skew)) < 0.08
    assert abs(np.mean(kurt)) < 0.13


def test_fourier_amplitudes_are_complex_gaussian(comm):
    """Random amplitudes, not only random phases: Re and Im of c_q / sqrt(C(q)) are normal.

    Kolmogorov-Smirnov on ~13000 values; the seed is fixed, so the test is
    deterministic, and p > 1e-3 rejects e.g. a random-phase generator (fixed
    |c_q|, arcsine-distributed parts), whose KS distance is ~0.05, p ~ 1e-28.
    """
    grid = make_grid((256, 256), comm, size=(1.0, 1.0))
    lambda_min, lambda_max = 4 / 256, 32 / 256
    h = self_affine(grid, 0.8, lambda_min, lambda_max, rms_height=1.0, seed=4)
    c = grid.forward(h)
    shape = np.sqrt(psd_shape(grid.q_magnitude(), 0.8, 2 * np.pi / lambda_max,
                              2 * np.pi / lambda_min))
    use = (shape > 0) & (grid.hermitian_weight[:, None] == 2)  # q and -q independent pairs
    z = c[use] / shape[use]
    parts = np.concatenate(comm.allgather(np.concatenate([z.real, z.imag])))
    assert parts.size > 10000
    parts /= np.sqrt(np.mean(parts ** 2))
    assert stats.kstest(parts, "norm").pvalue > 1e-3


# ------------------------------------------------------ decomposition, symmetry
# lambda_min = 2 pixels: every Fourier row, up to the Nyquist row, carries power, so
# every rank's part of the random stream matters (with 4 pixels rank 1 holds only zeros).
@pytest.mark.filterwarnings("ignore:lambda_min")
@pytest.mark.parametrize("shape", SHAPES)
def test_same_surface_on_one_and_two_ranks(comm, shape):
    grid = make_grid(shape, comm)
    serial = make_grid(shape, MPI.COMM_SELF)
    kwargs = dict(hurst=0.7, lambda_min=resolved(grid, 2), lambda_max=3.0, rms_slope=0.1,
                  seed=2 ** 40 + 17)
    h = self_affine(grid, **kwargs)
    reference = self_affine(serial, **kwargs)[grid.x_slice]
    np.testing.assert_allclose(h, reference, rtol=0, atol=1e-13 * np.abs(reference).max())


@pytest.mark.filterwarnings("ignore:lambda_min")
@pytest.mark.parametrize("shape", SHAPES)
def test_a_single_precision_grid_gets_the_same_surface(comm, shape):
    """Drawn and filtered in double, rounded once: the double grid's surface to float32
    round-off, at the same rms slope, on any number of ranks."""
    single = Grid(shape, size=SIZE, comm=comm, planner="estimate", precision="single")
    double = make_grid(shape, MPI.COMM_SELF)
    kwargs = dict(hurst=0.7, lambda_min=resolved(double, 2), lambda_max=3.0, rms_slope=0.1,
                  seed=5)
    h = self_affine(single, **kwargs)
    reference = self_affine(double, **kwargs)
    slope = statistics(single, h).rms_slope
    assert h.dtype == np.float32 and h.shape == single.local_shape
    np.testing.assert_allclose(h, reference[single.x_slice], rtol=0,
                               atol=2e-6 * np.abs(reference).max())
    assert slope == pytest.approx(0.1, rel=2e-6)


THREE_RANK_SCRIPT = """
import sys
import warnings
from mpi4py import MPI
from petgap.parallel.grid import Grid
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.topography import save_topography_npy
warnings.simplefilter("ignore")  # lambda_min = 2 pixels, on purpose
for shape in {shapes!r}:
    grid = Grid(shape, size={size!r}, comm=MPI.COMM_WORLD, planner="estimate")
    h = self_affine(grid, lambda_min=2 * max(grid.dx, grid.dy), **{kwargs!r})
    save_topography_npy(grid, h, f"{{sys.argv[1]}}/surface-{{shape[0]}}x{{shape[1]}}.npy")
"""


@pytest.mark.filterwarnings("ignore:lambda_min")
def test_same_surface_on_three_ranks(comm, mpi_tmp_path, run_cli):
    shapes = [(65, 48), (113, 76)]
    kwargs = dict(hurst=0.4, rms_height=1.0, seed=9)
    script = mpi_tmp_path / "three_ranks.py"
    if comm.rank == 0:
        script.write_text(THREE_RANK_SCRIPT.format(shapes=shapes, size=SIZE, kwargs=kwargs))
    comm.Barrier()
    result = run_cli([sys.executable, script, mpi_tmp_path], ranks=3)
    assert result.returncode == 0, result.stderr
    for shape in shapes:
        serial = make_grid(shape, MPI.COMM_SELF)
        reference = self_affine(serial, lambda_min=resolved(serial, 2), **kwargs)
        three = np.load(mpi_tmp_path / f"surface-{shape[0]}x{shape[1]}.npy")
        np.testing.assert_allclose(three, reference, rtol=0, atol=1e-13 * np.abs(reference).max())


@pytest.mark.parametrize("shape", [(65, 48), (64, 48), (65, 49), (16, 5)])
def test_spectrum_is_hermitian(comm, shape):
    """The generated coefficients survive c2r then r2c: no imaginary residue was dropped.

    If a self-conjugate row (ky = 0, or the Nyquist row of an even ny) broke
    c[m] = conj(c[-m]), the real field would only carry its Hermitian part and the
    forward transform would not give the coefficients back.
    """
    grid = make_grid(shape, comm)
    coefficients = _fill_spectrum(grid, 0.8, resolved(grid, 2), 2.0, seed=6).copy()
    h = grid.backward() / grid.npoints
    back = grid.forward(h).copy()
    largest = comm.allreduce(float(np.abs(coefficients).max()), op=MPI.MAX)
    full = np.fft.ifft2(np.fft.fft2(gather_all(grid, h)))
    np.testing.assert_allclose(back, coefficients, rtol=0, atol=1e-12 * largest)
    # and the full-plane inverse of the gathered field's spectrum is real
    assert np.abs(full.imag).max() < 1e-14 * np.abs(full.real).max()


def test_power_only_inside_the_band(comm):
    grid = make_grid((113, 76), comm)
    lambda_min, lambda_max = resolved(grid, 6), 1.0
    h = self_affine(grid, 0.8, lambda_min, lambda_max, rms_slope=0.1, seed=0)
    c = np.abs(grid.forward(h))
    q = grid.q_magnitude()
    outside = (q == 0) | (q > 2 * np.pi / lambda_min * (1 + 1e-9))
    largest = comm.allreduce(float(c.max()), op=MPI.MAX)  # rank 1 may hold only outside rows
    assert c[outside].max(initial=0) < 1e-12 * largest
    assert c[~outside].min(initial=np.inf) > 1e-6 * largest


@pytest.mark.filterwarnings("ignore:lambda_min")
def test_cutoff_on_a_harmonic_keeps_it(comm):
    """lambda_min = L / 13: the band is m^2 + n^2 <= 13^2 in integers, whatever the round-off.

    L = 0.1 is chosen because 2 pi 13 / L rounds above 2 pi / (L / 13).
    """
    grid = make_grid((32, 32), comm, size=(0.1, 0.1))
    h = self_affine(grid, 0.5, 0.1 / 13, 0.1, rms_height=1.0, seed=8)
    c = np.abs(grid.forward(h))
    largest = comm.allreduce(float(c.max()), op=MPI.MAX)
    m = np.fft.fftfreq(32, d=1 / 32).astype(int)
    n = np.arange(grid.ky_slice.start, grid.ky_slice.stop)
    radius2 = m[None, :] ** 2 + n[:, None] ** 2
    band = (radius2 > 0) & (radius2 <= 13 ** 2)
    assert c[band].min(initial=np.inf) > 1e-6 * largest
    assert c[~band].max(initial=0) < 1e-12 * largest


@pytest.mark.filterwarnings("ignore:lambda_min")
def test_stream_is_pinned(comm):
    """The same seed gives the same surface across versions (values from petgap 0.1.0).

    If this fails, every surface generated from a seed has changed — NumPy's
    normal sampler or the row keying — and that needs a release note.
    """
    grid = make_grid((8, 6), comm, size=(8.0, 6.0))
    h = gather_all(grid, self_affine(grid, 0.5, 2.0, 6.0, rms_height=1.0, seed=123))
    np.testing.assert_allclose(h[[0, 3, 7], [0, 4, 5]],
                               [0.9440797179466939, -0.433747501362626, -1.4776892082371549],
                               rtol=1e-12)


def test_seed_is_what_matters(comm):
    grid = make_grid((65, 48), comm)
    kwargs = dict(hurst=0.8, lambda_min=resolved(grid), rms_slope=0.1)
    a, b = self_affine(grid, seed=1, **kwargs), self_affine(grid, seed=1, **kwargs)
    other = self_affine(grid, seed=2, **kwargs)
    difference = grid.comm.allreduce(float(np.abs(a - other).max()), op=MPI.MAX)
    np.testing.assert_array_equal(a, b)
    assert difference > 1e-3


def test_default_lambda_max_is_smaller_side(comm):
    grid = make_grid((65, 48), comm)
    kwargs = dict(hurst=0.8, lambda_min=resolved(grid), rms_slope=0.1, seed=4)
    np.testing.assert_array_equal(self_affine(grid, **kwargs),
                                  self_affine(grid, lambda_max=2.0, **kwargs))


# --------------------------------------------------------------- arguments
GOOD = dict(hurst=0.8, lambda_min=8.0, lambda_max=None, rms_slope=0.1, seed=0)
BAD = [
    (dict(hurst=0.0), "hurst = 0.0"), (dict(hurst=1.0), "hurst = 1.0"),
    (dict(hurst=float("nan")), "hurst = nan"), (dict(hurst="0.5"), "hurst = '0.5'"),
    (dict(lambda_min=0.0), "lambda_min = 0.0"), (dict(lambda_min=-2.0), "lambda_min = -2.0"),
    (dict(lambda_min=np.inf), "lambda_min = inf"), (dict(lambda_max=-1.0), "lambda_max = -1.0"),
    (dict(lambda_min=20.0, lambda_max=10.0), "lambda_min = 20.0 is larger than lambda_max"),
    (dict(rms_slope=None), "exactly one of rms_slope, rms_height"),
    (dict(rms_height=1.0), "exactly one of rms_slope, rms_height"),
    (dict(rms_slope=0.0), "rms_slope = 0.0"), (dict(rms_slope=np.nan), "rms_slope = nan"),
    (dict(rms_slope=None, rms_height=-1.0), "rms_height = -1.0"),
    (dict(seed=-1), "seed = -1"), (dict(seed=2 ** 63), "seed = 9223372036854775808"),
    (dict(seed=1.5), "seed = 1.5"), (dict(seed=True), "seed = True"),
]


@pytest.mark.parametrize("bad, message", BAD, ids=[m.split(" ")[0] + "-" + str(i)
                                                   for i, (_, m) in enumerate(BAD)])
def test_bad_arguments_name_themselves(comm, bad, message):
    grid = make_grid((32, 32), comm, size=(32.0, 32.0))
    with pytest.raises(ValueError) as info:
        self_affine(grid, **{**GOOD, **bad})
    assert message in str(info.value)
    assert "need" in str(info.value) or "give" in str(info.value)


def test_no_mode_in_band_raises(comm):
    grid = make_grid((32, 32), comm, size=(32.0, 32.0))
    with pytest.raises(ValueError, match="lambda_min = 100.0 is longer than every wavelength"):
        self_affine(grid, 0.8, 100.0, 200.0, rms_slope=0.1)


def test_unresolved_lambda_min_warns(comm):
    grid = make_grid((32, 32), comm, size=(16.0, 16.0))  # pixel 0.5
    with pytest.warns(UserWarning, match=r"lambda_min = 1 is 2 pixels .* below 4 pixels"):
        self_affine(grid, 0.8, 1.0, rms_slope=0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        self_affine(grid, 0.8, 2.0, rms_slope=0.1)  # 4 pixels: resolved, silent


def test_statistics_rejects_wrong_slab(comm):
    grid = make_grid((32, 32), comm)
    with pytest.raises(ValueError, match="h_local on rank 0 has shape"):
        statistics(grid, np.zeros((grid.local_shape[0] + (comm.rank == 0), 32)))
