"""Spectral statistics of a surface on the distributed Fourier slab.

Statistics are spectral (docs/conventions.md): ``h0 = rms(h - mean)``,
``h0' = sqrt(<|grad h|^2>) = sqrt(sum_q |q|^2 |h_q|^2) / N``,
``h0'' = rms(laplacian h) / 2 = sqrt(sum_q |q|^4 |h_q|^2) / (2 N)``; sums run over
the full plane (half-plane rows weighted by ``grid.hermitian_weight``).  For
an even ``nx`` or ``ny`` the Nyquist modes count with ``|q_x| = pi / dx``
(``|q_y| = pi / dy``): spectral, not finite-difference, derivatives.

The mean is removed exactly, by zeroing the ``q = 0`` coefficient, not by
subtracting its square: a topography far from zero mean (heights read from a
file) keeps its rms height to round-off.  :class:`petgap.mechanics.problem.ContactProblem`
takes its residual scales ``h0`` and ``h0'`` from :func:`statistics`, so a
surface's reported statistics and its problem's scales are the same numbers.
"""
import numbers
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from petgap.parallel.grid import row_blocks, weighted_power


@dataclass(frozen=True)
class SurfaceStatistics:
    """Spectral statistics of a surface, identical on every rank.

    Attributes
    ----------
    mean : float
        Mean height ``<h>``.
    rms_height : float
        ``h0 = sqrt(<(h - <h>)^2>)``.
    rms_slope : float
        ``h0' = sqrt(<|grad h|^2>)``.
    rms_curvature : float
        ``h0'' = sqrt(<(laplacian h)^2>) / 2``.
    rms_slope_fd, rms_slope_fd_inner : float or None
        The rms slope by finite differences across the cell's edges and inside the map
        only (:func:`finite_difference_slopes`), where computed.
    rms_curvature_fd_inner : float or None
        The rms curvature by finite differences inside the map
        (:func:`finite_difference_curvature`), where computed.
    """

    mean: float
    rms_height: float
    rms_slope: float
    rms_curvature: float
    rms_slope_fd: float = None
    rms_slope_fd_inner: float = None
    rms_curvature_fd_inner: float = None


def statistics(grid, h_local):
    """Mean, rms height, rms slope and rms curvature, computed spectrally.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Its scratch buffers are overwritten.
    h_local : ndarray, shape ``grid.local_shape``
        This rank's heights.

    Returns
    -------
    SurfaceStatistics
        The same on every rank (one allreduce of four numbers).
    """
    h_local = check_local_field(grid, h_local, "h_local", dtype=None)   # no copy
    c = grid.forward(h_local)
    if grid.ky_slice.start == 0:
        c[0, 0] = 0.0  # the mean, removed exactly instead of by subtraction
    powers = [weighted_power(c, grid.qx, grid.qy, grid.hermitian_weight, p) for p in (0, 2, 4)]
    sums = np.array([np.sum(h_local, dtype=np.float64)] + powers)
    grid.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    n = grid.npoints
    return SurfaceStatistics(mean=float(sums[0] / n), rms_height=float(np.sqrt(sums[1]) / n),
                             rms_slope=float(np.sqrt(sums[2]) / n),
                             rms_curvature=float(np.sqrt(sums[3]) / (2 * n)))


def radial_psd(grid, h_local, nbins=None):
    """Radially averaged power spectral density, identical on every rank.

    ``C(q) = A |h_q|^2 / N^2`` per mode (so ``mean(h^2) = (1 / A) sum_q C(q)``),
    averaged over the full-plane modes whose ``|q|`` falls in each of ``nbins``
    logarithmically spaced bins spanning the smallest non-zero to the largest
    ``|q|`` of the grid.  The ``q = 0`` mode (the mean) is left out, and bins
    that hold no mode (common at small ``q``, where modes are sparse) are
    dropped.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Its scratch buffers are overwritten.
    h_local : ndarray, shape ``grid.local_shape``
    nbins : int, optional
        Number of bins before empty ones are dropped; default about ten per
        decade of ``q``.

    Returns
    -------
    q : ndarray
        Mean ``|q|`` of the modes in each non-empty bin, increasing.
    C : ndarray
        Mean ``C(q)`` over those modes.
    """
    h_local = check_local_field(grid, h_local, "h_local")
    qs = [2 * np.pi / length for length, n in ((grid.Lx, grid.nx), (grid.Ly, grid.ny)) if n > 1]
    if not qs:
        return np.empty(0), np.empty(0)
    q_min = min(qs)
    q_max = np.hypot(2 * np.pi * (grid.nx // 2) / grid.Lx, 2 * np.pi * (grid.ny // 2) / grid.Ly)
    if nbins is None:
        nbins = max(1, int(np.ceil(10 * np.log10(q_max / q_min))))
    elif isinstance(nbins, bool) or not isinstance(nbins, numbers.Integral) or nbins < 1:
        raise ValueError(f"nbins = {nbins!r} is not allowed: need a positive integer or None")
    edges = np.geomspace(q_min, q_max, int(nbins) + 1)
    edges[0], edges[-1] = q_min * (1 - 1e-9), q_max * (1 + 1e-9)

    c = grid.forward(h_local)
    acc = np.zeros((3, int(nbins)))  # mode count, sum of |q|, sum of |h_q|^2
    qx2 = grid.qx ** 2
    for j in range(c.shape[0]):
        q = np.sqrt(qx2 + grid.qy[j] ** 2)
        index = np.searchsorted(edges, q, side="right") - 1
        keep = q > 0
        index, w = index[keep], grid.hermitian_weight[j]
        acc[0] += w * np.bincount(index, minlength=nbins)
        acc[1] += w * np.bincount(index, weights=q[keep], minlength=nbins)
        acc[2] += w * np.bincount(index, weights=np.abs(c[j, keep]) ** 2, minlength=nbins)
    total = np.empty_like(acc)
    grid.comm.Reduce(acc, total, op=MPI.SUM, root=0)  # reduce + bcast: bitwise equal everywhere
    grid.comm.Bcast(total, root=0)
    full = total[0] > 0
    count = total[0, full]
    return total[1, full] / count, grid.area * total[2, full] / (count * grid.npoints ** 2)


def check_local_field(grid, h_local, name, dtype=np.float64):
    """``h_local`` as an array of this rank's slab shape; ValueError on every rank if not.

    Of ``dtype``; with ``dtype=None`` a floating-point array keeps its own (a
    single-precision topography is not copied to double) and any other becomes float64.
    """
    h_local = np.asarray(h_local, dtype=dtype)
    if not np.issubdtype(h_local.dtype, np.floating):
        h_local = h_local.astype(np.float64)
    bad = grid.comm.allgather(None if h_local.shape == grid.local_shape
                              else (h_local.shape, grid.local_shape))
    for rank, problem in enumerate(bad):
        if problem is not None:
            raise ValueError(f"{name} on rank {rank} has shape {problem[0]}, but that rank's slab "
                             f"of the {grid.nx} x {grid.ny} grid is {problem[1]}")
    return h_local


def finite_difference_slopes(grid, h_local):
    """The rms slope by finite differences, across the cell's edges and inside the map only.

    ``(periodic, inner)``: ``sqrt(<(dh/dx)^2> + <(dh/dy)^2>)`` from the forward differences
    of neighbouring pixels, averaged over all ``nx ny`` pairs of each direction with
    the wrap-around pairs (the last row and column against the first) included, and
    over the ``(nx - 1) ny`` and ``nx (ny - 1)`` pairs inside the map only.  On a
    periodic surface the two agree (the wrap-around pairs are like any others); on a
    measured map whose opposite edges do not match, the jump at the seam raises the
    first: the test of whether a map may be solved as periodic.  Collective (one row
    from the next rank); the same on every rank.
    """
    h_local = check_local_field(grid, h_local, "h_local")
    comm, nx, ny = grid.comm, grid.nx, grid.ny
    rows = h_local.shape[0]
    # the first row of the next rank that has rows (cyclically): who holds which rows
    starts = comm.allgather((grid.x_slice.start, rows))
    owners = [r for r, (_, n) in enumerate(starts) if n > 0]
    nxt = prev = None
    if rows:
        k = owners.index(comm.rank)
        nxt, prev = owners[(k + 1) % len(owners)], owners[(k - 1) % len(owners)]
    below = np.empty(ny)
    if rows:
        if len(owners) == 1:
            below[:] = h_local[0]
        else:
            comm.Sendrecv(np.ascontiguousarray(h_local[0]), dest=prev, recvbuf=below, source=nxt)
    sums = np.zeros(4)   # x: inner, seam; y: inner, seam
    if rows:
        # in blocks of rows: no slab-sized temporaries (a run's peak memory is set
        # here otherwise, before the solve)
        for b in row_blocks(rows, ncols=ny):
            i0, i1 = b.start, b.stop
            block = h_local[i0:min(i1 + 1, rows)]      # with the next row, if this rank has it
            sums[0] += np.sum(np.diff(block, axis=0) ** 2)
            sums[2] += np.sum(np.diff(block[:i1 - i0], axis=1) ** 2)
            sums[3] += np.sum((block[:i1 - i0, 0] - block[:i1 - i0, -1]) ** 2)
        last = (below - h_local[-1]) ** 2
        if grid.x_slice.stop == nx:
            sums[1] += np.sum(last)          # the wrap-around pairs of x
        else:
            sums[0] += np.sum(last)
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    ax, ay = grid.dx ** -2, grid.dy ** -2
    periodic = np.sqrt(ax * (sums[0] + sums[1]) / (nx * ny) + ay * (sums[2] + sums[3]) / (nx * ny))
    inner_x = ax * sums[0] / ((nx - 1) * ny) if nx > 1 else 0.0
    inner_y = ay * sums[2] / (nx * (ny - 1)) if ny > 1 else 0.0
    return float(periodic), float(np.sqrt(inner_x + inner_y))


def low_pass(grid, h_local, q_cutoff):
    """The field without its Fourier modes of ``|q| > q_cutoff`` (a sharp spectral cutoff).

    Collective, one transform pair on the grid's buffers (overwritten); returns a new
    ``local_shape`` array.  The mean and every mode up to the cutoff are kept exactly.
    """
    h_local = check_local_field(grid, h_local, "h_local")
    c = grid.forward(h_local)
    c[grid.q_magnitude() > q_cutoff] = 0.0
    return grid.backward() / grid.npoints


def finite_difference_curvature(grid, h_local):
    """The rms curvature by finite differences inside the map: ``sqrt(<(lap h)^2>) / 2``.

    The five-point Laplacian ``(h[i+1,j] + h[i-1,j] - 2 h) / dx^2 + (h[i,j+1] + h[i,j-1] -
    2 h) / dy^2`` at the ``(nx - 2)(ny - 2)`` points whose neighbours all lie inside the
    map (no wrap-around), the convention of :func:`statistics`' spectral ``h0''``; exact
    for quadratic surfaces, so it measures a map's curvature without its seam.
    Collective (a row from each neighbouring rank); the same on every rank; NaN for a
    map narrower than 3 pixels.
    """
    h_local = check_local_field(grid, h_local, "h_local")
    comm, nx, ny = grid.comm, grid.nx, grid.ny
    start, rows = grid.x_slice.start, h_local.shape[0]
    if nx < 3 or ny < 3:
        return float("nan")
    slabs = comm.allgather((start, rows))
    owners = [r for r, (_, n) in enumerate(slabs) if n > 0]
    above = np.full(ny, np.nan)       # global row start - 1
    below = np.full(ny, np.nan)       # global row start + rows
    if rows and len(owners) > 1:
        k = owners.index(comm.rank)
        prev = owners[k - 1] if k > 0 else MPI.PROC_NULL
        nxt = owners[k + 1] if k + 1 < len(owners) else MPI.PROC_NULL
        comm.Sendrecv(np.ascontiguousarray(h_local[-1]), dest=nxt, recvbuf=above, source=prev)
        comm.Sendrecv(np.ascontiguousarray(h_local[0]), dest=prev, recvbuf=below, source=nxt)
    total = 0.0
    first = 1 if start == 0 else 0                    # global rows 1 .. nx - 2 only
    last = rows - 1 if start + rows == nx else rows
    # in blocks of rows, each with its neighbours: no slab-sized temporaries
    for b in row_blocks(rows, ncols=ny):
        i0, i1 = max(b.start, first), min(b.stop, last)
        if i0 >= i1:
            continue
        top = h_local[i0 - 1:i0] if i0 > 0 else above[None, :]
        bottom = h_local[i1:i1 + 1] if i1 < rows else below[None, :]
        ext = np.vstack([top, h_local[i0:i1], bottom])
        centre = ext[1:-1, 1:-1]
        lap = ((ext[2:, 1:-1] + ext[:-2, 1:-1] - 2 * centre) / grid.dx ** 2
               + (ext[1:-1, 2:] + ext[1:-1, :-2] - 2 * centre) / grid.dy ** 2)
        total += float(np.sum(lap ** 2))
    total = comm.allreduce(total, op=MPI.SUM)
    return float(np.sqrt(total / ((nx - 2) * (ny - 2))) / 2)
