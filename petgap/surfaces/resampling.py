"""One band-limited surface on grids of any resolution.

:func:`petgap.surfaces.self_affine.self_affine` does *not* give the same
surface for the same seed at another pixel size: Fourier row ``n`` draws its
``nx`` amplitudes in FFT column order from ``Philox(seed, n)``, so the modes
with ``q_x >= 0`` (the first columns) coincide, but those with ``q_x < 0`` sit
at columns ``nx - |m|``, which depend on ``nx``, and the rescaling to the rms
slope then differs too.  To compare grids on one physical surface, make it once,
keep its Fourier modes with ``|q| <= 2 pi / lambda_min`` (:func:`band_spectrum`;
for a generated self-affine surface everything above is zero up to round-off,
which is reported), and put exactly those modes on every other grid
(:func:`resample`): Fourier truncation onto coarser grids and zero padding onto
finer ones.  For a band-limited surface whose band lies strictly inside each
grid's Nyquist range this is exact: every grid samples the same continuous
surface, with the same rms height, slope and curvature to round-off.  The
modes kept are ``O((L / lambda_min)^2)``, independent of the resolution; they
are gathered on every rank (a few kB to a few MB), the transforms are the
grids' distributed FFTW-MPI plans, and no rank ever holds a global field.
"""
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from petgap.parallel.grid import weighted_power

__all__ = ["BandSpectrum", "band_spectrum", "resample"]

# Relative slack of the band edge |q| <= 2 pi / lambda_min (far below a mode spacing 1/n).
_BAND_SLACK = 1e-9


@dataclass(frozen=True)
class BandSpectrum:
    """The Fourier modes of a band-limited periodic surface, independent of any grid.

    ``h(x) = sum_q a_q exp(i q.x)`` over ``q = 2 pi (m / Lx, n / Ly)`` with
    ``|m| <= kx``, ``0 <= n <= ky`` (the half plane; ``n < 0`` by Hermitian
    symmetry) and ``|q| <= q_max``; ``a_q`` is the grid's unnormalised
    coefficient over its number of points, ``c_q / N``, which does not depend on
    the grid.  Identical on every rank.

    Attributes
    ----------
    size : (float, float)
        ``(Lx, Ly)``.
    q_max : float
        Band edge (``2 pi / lambda_min``).
    kx, ky : int
        Largest ``|m|`` and ``n`` in the band.
    coefficients : ndarray, complex, shape ``(ky + 1, 2 kx + 1)``
        ``a_q`` at row ``n``, column ``m + kx``; zero outside the band.
    source_shape : (int, int)
        The grid the modes were taken from.
    dropped_power : float
        Fraction of the source's height variance outside the band (round-off
        for a generated self-affine surface; large for a rough measured one).
    """

    size: tuple
    q_max: float
    kx: int
    ky: int
    coefficients: np.ndarray
    source_shape: tuple
    dropped_power: float

    def check_fits(self, shape):
        """Why a grid of ``shape`` (same size) cannot hold the band exactly, or None."""
        nx, ny = shape
        if 2 * self.kx >= nx or 2 * self.ky >= ny:
            return (f"the surface's band |q| <= {self.q_max:.6g} reaches |m| = {self.kx}, "
                    f"n = {self.ky}, at or beyond the Nyquist modes of a {nx} x {ny} grid "
                    f"(need 2 |m| < nx and 2 n < ny, i.e. lambda_min > 2 a0)")
        return None


def band_spectrum(grid, heights, lambda_min):
    """The modes ``|q| <= 2 pi / lambda_min`` of this rank's slab of a surface (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Its FFT buffers are overwritten.
    heights : ndarray, shape ``grid.local_shape``
    lambda_min : float
        Short-wavelength cutoff; the band must lie strictly inside the grid's
        Nyquist range (else ValueError on every rank).

    Returns
    -------
    BandSpectrum
    """
    if not (isinstance(lambda_min, (int, float)) and math.isfinite(lambda_min) and lambda_min > 0):
        raise ValueError(f"lambda_min = {lambda_min!r}: need a positive length")
    q_max = 2 * math.pi / float(lambda_min)
    kx = int(math.floor(q_max * grid.Lx / (2 * math.pi) * (1 + _BAND_SLACK)))
    ky = int(math.floor(q_max * grid.Ly / (2 * math.pi) * (1 + _BAND_SLACK)))
    band = BandSpectrum(size=(grid.Lx, grid.Ly), q_max=q_max, kx=kx, ky=ky,
                        coefficients=None, source_shape=grid.shape, dropped_power=math.nan)
    problem = band.check_fits(grid.shape)
    if problem is not None:
        raise ValueError(f"cannot take the band-limited modes of the surface: {problem}")
    comm = grid.comm
    c = grid.forward(np.asarray(heights, dtype=np.float64))
    total = weighted_power(c, grid.qx, grid.qy, grid.hermitian_weight, 0)
    start = grid.ky_slice.start
    if start == 0:
        total -= abs(c[0, 0]) ** 2  # the mean is not roughness
    rows = range(start, min(grid.ky_slice.stop, ky + 1))
    m = np.arange(-kx, kx + 1)
    local = np.zeros((len(rows), 2 * kx + 1), dtype=complex)
    kept = 0.0
    for i, n in enumerate(rows):
        qy = 2 * math.pi * n / grid.Ly
        qx = 2 * math.pi * m / grid.Lx
        inside = qx ** 2 + qy ** 2 <= (q_max * (1 + _BAND_SLACK)) ** 2
        values = np.where(inside, c[n - start, m % grid.nx], 0.0) / grid.npoints
        local[i] = values
        power = np.abs(values) ** 2
        if n == 0:
            power[kx] = 0.0  # the mean
        kept += grid.hermitian_weight[n - start] * float(power.sum())
    sums = np.array([total / grid.npoints ** 2, kept])
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    parts = comm.allgather(local)
    coefficients = np.concatenate(parts, axis=0)
    dropped = max(sums[0] - sums[1], 0.0) / sums[0] if sums[0] > 0 else 0.0
    return dataclasses.replace(band, coefficients=coefficients, dropped_power=float(dropped))


def resample(band, grid):
    """This rank's slab of the band-limited surface ``band`` on ``grid`` (collective).

    Puts the band's modes, and nothing else, into the grid's Fourier slab and
    transforms back: Fourier truncation onto a coarser grid, zero padding onto
    a finer one, exact as long as the band lies strictly inside the grid's
    Nyquist range (ValueError otherwise).  The grid must have the band's
    physical size.

    Returns
    -------
    ndarray, shape ``grid.local_shape``
    """
    lx, ly = band.size
    if not (math.isclose(grid.Lx, lx, rel_tol=1e-12) and math.isclose(grid.Ly, ly, rel_tol=1e-12)):
        raise ValueError(f"grid size {grid.Lx:g} x {grid.Ly:g} differs from the surface's "
                         f"{lx:g} x {ly:g}")
    problem = band.check_fits(grid.shape)
    if problem is not None:
        raise ValueError(f"cannot put the surface on this grid: {problem}")
    fourier = grid.fourier
    fourier[...] = 0.0
    start, stop = grid.ky_slice.start, grid.ky_slice.stop
    columns = np.arange(-band.kx, band.kx + 1) % grid.nx
    for n in range(start, min(stop, band.ky + 1)):
        fourier[n - start, columns] = band.coefficients[n]
    # backward is unnormalised: sum_q a_q exp(i q.x) is the surface itself
    return grid.backward().copy()
