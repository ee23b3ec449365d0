"""Self-affine random surfaces, generated on the distributed Fourier slab.

A surface is never assembled on one rank: it is drawn, filtered and rescaled on
each rank's own rows of the transposed Fourier half plane, and transformed to
the real-space slab with the :class:`~petgap.parallel.grid.Grid`'s FFTW-MPI plans.  That is
what lets a 65536^2 surface (paper section 7) be generated at all; serial
generators run out of memory far below that.

Conventions
-----------
* Heights and lengths are in the physical units of the grid (pixel sizes
  ``grid.dx``, ``grid.dy``); wavelengths ``lambda`` map to wavevector
  magnitudes ``q = 2 pi / lambda``.
* Fourier coefficients follow :mod:`petgap.parallel.grid`: ``h_q = sum_x h(x)
  exp(-i q.x)`` (unnormalised), ``N = nx * ny`` points, area ``A = Lx * Ly``.
* Power spectral density, continuum convention: ``C(q) = A |h_q|^2 / N^2``,
  so that ``mean(h^2) = (1 / A) sum_q C(q)``, which tends to
  ``int d^2q / (2 pi)^2 C(q)`` as the grid is refined.  The spectrum generated is
  Eq. 5 of the paper (Jacobs, Junge & Pastewka, Surf. Topogr. 5, 013001 (2017);
  Ramisetti et al., J. Phys.: Condens. Matter 23, 215004 (2011)): a plateau
  ``C0`` for ``0 < q <= q1 = 2 pi / lambda_max``, ``C0 (q / q1)^(-2(1+H))`` up to
  ``q2 = 2 pi / lambda_min`` and zero above.  ``C0`` is not an input: the surface
  is rescaled to a target rms slope or rms height instead, because that is the
  quantity the contact results are expressed in.
* The ``q = 0`` coefficient is zero: generated surfaces have mean height zero.
* The surface is rescaled to a spectral rms slope or height, as
  :mod:`petgap.surfaces.statistics` measures them.
* Randomness (as Dedalus' ``fill_random``, but counter-based so nothing global is
  ever drawn): global Fourier row ``n`` (``q_y = 2 pi n / Ly``) takes its ``nx``
  complex amplitudes from ``Philox(key=(seed, n))``.  The surface is therefore a
  function of ``(seed, grid shape and size, spectrum, target)`` only, identical
  on any number of ranks to round-off.  Changing how rows are drawn changes
  every surface ever generated from a seed: treat the stream as part of the
  file format.  (Philox is stable; ``Generator.standard_normal`` is not promised
  to be across NumPy versions, NEP 19 — ``test_stream_is_pinned`` would notice.)
"""
import numbers
import warnings

import numpy as np
from mpi4py import MPI

from petgap.parallel.grid import weighted_power

#: Shortest wavelength, in pixels, that counts as resolved; below it a warning is issued.
RESOLVED_PIXELS = 4.0

# Modes within this relative distance of q2 = 2 pi / lambda_min are kept: with
# lambda_min = L / k the k-th harmonic then belongs to the spectrum whatever the
# last bit of 2 pi k / L is.  Far below any mode spacing (relative 1 / n).
_CUTOFF_SLACK = 1e-12


# --------------------------------------------------------------------- spectrum
def psd_shape(q, hurst, q1, q2):
    """Shape of the self-affine PSD, Eq. 5 of the paper with ``C0 = 1``.

    Parameters
    ----------
    q : array_like
        Wavevector magnitudes ``|q| >= 0``.
    hurst : float
        Hurst exponent ``H``, ``0 < H < 1``.
    q1, q2 : float
        Roll-off ``2 pi / lambda_max`` and short-wavelength cutoff
        ``2 pi / lambda_min``, ``0 < q1 <= q2``.

    Returns
    -------
    ndarray or float
        ``1`` for ``0 < q <= q1`` (roll-off plateau), ``(q / q1)^(-2(1+H))`` for
        ``q1 < q <= q2``, ``0`` above ``q2`` and ``0`` at ``q = 0`` (the mean
        height is not part of the roughness).  A float for scalar ``q``.
    """
    hurst = _check_real("hurst", hurst, lambda v: 0 < v < 1, "0 < hurst < 1")
    q1 = _check_real("q1", q1, lambda v: v > 0, "a positive finite number")
    q2 = _check_real("q2", q2, lambda v: v >= q1, f"a finite number >= q1 = {q1!r}")
    q = np.asarray(q, dtype=float)
    with np.errstate(divide="ignore"):
        power_law = (q / q1) ** (-2.0 * (1.0 + hurst))
    shape = np.where(q <= q1, 1.0, np.where(q <= q2, power_law, 0.0))
    shape = np.where(q > 0, shape, 0.0)
    return float(shape) if shape.ndim == 0 else shape


def self_affine(grid, hurst, lambda_min, lambda_max=None, *, rms_slope=None,
                rms_height=None, seed=0):
    """This rank's slab of a periodic, Gaussian, self-affine random surface.

    Fourier filtering done where the data live: every rank draws complex
    Gaussian amplitudes for its own Fourier rows, multiplies them by
    ``sqrt(C(|q|))`` (:func:`psd_shape`), rescales to the target and transforms
    back.  No rank ever holds the global field, and the result does not depend
    on the number of ranks (see the module docstring for the random stream).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Grid, decomposition and FFT.  Its scratch buffers ``real`` and
        ``fourier`` are overwritten.
    hurst : float
        Hurst exponent ``H``, ``0 < H < 1``.
    lambda_min : float
        Short-wavelength cutoff in grid length units; modes with
        ``|q| > 2 pi / lambda_min`` are zero.  Below 4 pixels a warning is issued
        (on every rank, so that ``-W error`` stops all ranks alike): such
        wavelengths are not resolved.
    lambda_max : float, optional
        Roll-off wavelength, ``lambda_min <= lambda_max``; defaults to
        ``min(Lx, Ly)``.  Longer than the box is allowed (no plateau is left).
    rms_slope, rms_height : float
        Exactly one: the spectral rms slope ``h0'`` or rms height ``h0`` the
        surface is scaled to (exact to round-off).
    seed : int
        ``0 <= seed < 2**63``; keys the counter-based random stream.

    Returns
    -------
    ndarray of the grid's real dtype, shape ``grid.local_shape``
        Heights on this rank's rows ``grid.x_slice``; zero mean.  On a
        single-precision grid the amplitudes are drawn and filtered in double
        and rounded once into the grid's buffer, so the surface is the one a
        double grid gives, to single-precision round-off.

    Raises
    ------
    ValueError
        For an invalid argument (naming it, its value and what is allowed), or
        if no Fourier mode of the grid lies in ``0 < |q| <= 2 pi / lambda_min``.

    Notes
    -----
    Memory: nothing beyond the grid's FFT buffers (16 bytes per point) and the
    returned slab (8 bytes per point), 24 bytes per point in all, as
    ``benchmarks/surface_memory.py`` measures; half of each on a
    single-precision grid.
    """
    hurst = _check_real("hurst", hurst, lambda v: 0 < v < 1, "0 < hurst < 1")
    lambda_min = _check_positive("lambda_min", lambda_min)
    if lambda_max is None:
        lambda_max, origin = min(grid.Lx, grid.Ly), " (the default, min(Lx, Ly))"
    else:
        lambda_max, origin = _check_positive("lambda_max", lambda_max), ""
    if lambda_min > lambda_max:
        raise ValueError(f"lambda_min = {lambda_min!r} is larger than lambda_max = "
                         f"{lambda_max!r}{origin}; need lambda_min <= lambda_max")
    if (rms_slope is None) == (rms_height is None):
        raise ValueError(f"give exactly one of rms_slope, rms_height; got rms_slope={rms_slope!r}, "
                         f"rms_height={rms_height!r}")
    if rms_slope is not None:
        target, power = _check_positive("rms_slope", rms_slope), 2
    else:
        target, power = _check_positive("rms_height", rms_height), 0
    seed = _check_seed(seed)

    pixel = max(grid.dx, grid.dy)
    if lambda_min < RESOLVED_PIXELS * pixel:
        warnings.warn(f"lambda_min = {lambda_min:g} is {lambda_min / pixel:.3g} pixels (pixel size "
                      f"{pixel:g}): wavelengths below {RESOLVED_PIXELS:g} pixels are not resolved",
                      UserWarning, stacklevel=2)

    fourier = _fill_spectrum(grid, hurst, lambda_min, lambda_max, seed)
    total = grid.comm.allreduce(weighted_power(fourier, grid.qx, grid.qy, grid.hermitian_weight,
                                               power), op=MPI.SUM)
    if not total > 0:
        raise ValueError(f"no Fourier mode of the {grid.nx} x {grid.ny} grid (size {grid.Lx:g} x "
                         f"{grid.Ly:g}) has 0 < |q| <= 2 pi / lambda_min: lambda_min = "
                         f"{lambda_min!r} is longer than every wavelength the grid holds")
    current = np.sqrt(total) / grid.npoints
    real = grid.backward()
    # One pass: the rescaling to the target and the 1 / N of the inverse FFT,
    # straight into the array we return (grid.real is shared scratch).
    heights = np.empty(grid.local_shape, dtype=grid.dtype)
    np.multiply(real, target / (current * grid.npoints), out=heights)
    return heights


def _fill_spectrum(grid, hurst, lambda_min, lambda_max, seed):
    """Fill ``grid.fourier`` with this rank's filtered random coefficients (unscaled).

    Row ``n`` draws ``2 nx`` standard normals (real and imaginary parts) from
    ``Philox(key=(seed, n))``.  The self-conjugate rows ``n = 0`` and (``ny``
    even) ``n = ny / 2`` stand for themselves only: there ``c[m] = conj(c[-m])``
    is imposed by mirroring ``m = 1 .. (nx - 1) // 2`` and the self-conjugate
    entries are made real (``sqrt(2) Re``, keeping ``E|c|^2`` equal for all
    modes), so that the c2r transform is exactly the inverse of r2c.  Rows with
    ``q_y > q2`` are zeroed without drawing (each row has its own stream, so
    this changes nothing else).  Work is row by row: no temporary is larger
    than one row.

    Returns
    -------
    ndarray
        ``grid.fourier``.
    """
    nx, ny = grid.nx, grid.ny
    q1 = 2 * np.pi / lambda_max
    q2 = 2 * np.pi / lambda_min * (1 + _CUTOFF_SLACK)
    qx2 = grid.qx ** 2
    fourier = grid.fourier
    half = (nx - 1) // 2
    # a single-precision buffer's rows are drawn and filtered in a double row first
    drawn = None if fourier.dtype == np.complex128 else np.empty(nx, dtype=np.complex128)
    for j, n in enumerate(range(grid.ky_slice.start, grid.ky_slice.stop)):
        if grid.qy[j] > q2:  # the whole row is above the cutoff: nothing to draw
            fourier[j] = 0.0
            continue
        row = fourier[j] if drawn is None else drawn
        rng = np.random.Generator(np.random.Philox(key=np.array([seed, n], dtype=np.uint64)))
        rng.standard_normal(out=row.view(np.float64))
        if n == 0 or (ny % 2 == 0 and n == ny // 2):
            if half > 0:
                row[nx - half:] = np.conj(row[half:0:-1])
            row[0] = np.sqrt(2.0) * row[0].real
            if nx % 2 == 0:
                row[nx // 2] = np.sqrt(2.0) * row[nx // 2].real
        row *= np.sqrt(psd_shape(np.sqrt(qx2 + grid.qy[j] ** 2), hurst, q1, q2))
        if drawn is not None:
            fourier[j] = drawn
    return fourier  # q = 0 is zero already: psd_shape(0) = 0


# ------------------------------------------------------------------ validation
def _check_real(name, value, allowed, description):
    """``float(value)`` if it is a real number with ``allowed(value)``, else ValueError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} = {value!r} is not allowed: need a real number, {description}")
    value = float(value)
    if not (np.isfinite(value) and allowed(value)):
        raise ValueError(f"{name} = {value!r} is not allowed: need {description}")
    return value


def _check_positive(name, value):
    return _check_real(name, value, lambda v: v > 0, "a positive finite number")


def _check_seed(seed):
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= seed < 2 ** 63:
        raise ValueError(f"seed = {seed!r} is not allowed: need an integer with 0 <= seed < 2**63")
    return int(seed)
