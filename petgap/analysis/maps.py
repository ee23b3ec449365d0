"""Maps for display: a distributed field reduced to at most a screen's worth of pixels.

A 16384^2 field is 2 GiB in double precision and a picture of it has at most a few
million visible pixels, so a map is the field averaged over square blocks of
``factor x factor`` pixels, ``factor = ceil(max(nx, ny) / max_pixels)``: each rank
sums its own rows into the block array and one reduction to the root adds them
up; no rank ever holds the full field.  Block means keep what a map is read for:
the mean of a decimated height or pressure map is the field's mean, and the
decimated contact map holds the contact fraction of each block (its mean,
weighted by block size, is the contact fraction ``c`` exactly).  Blocks at the
far edges are smaller when ``factor`` does not divide the grid; ``counts`` says
how many pixels each block holds.
"""
import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from petgap.analysis._slabs import check_fields, global_shape, local_rows, pixel

#: Largest number of map pixels along either axis, by default.
MAX_PIXELS = 1024


@dataclass
class Map:
    """A block-averaged field, on the root rank (``None`` elsewhere for ``values``/``counts``).

    Attributes
    ----------
    values : ndarray, shape ``(ceil(nx / factor), ceil(ny / factor))``
        Block means; index ``[I, J]`` covers pixels ``I * factor <= i < (I + 1) * factor``
        (and likewise ``j``).
    counts : ndarray of int64, same shape
        Pixels in each block.
    factor : int
        Block edge in pixels (1: the field itself).
    extent : tuple
        ``(0, Lx, 0, Ly)``: the physical extent of the map in length units.
    """
    values: np.ndarray
    counts: np.ndarray
    factor: int
    extent: tuple

    def weighted_mean(self):
        """Mean of the field from the map: ``sum(values * counts) / sum(counts)``."""
        return float(np.sum(self.values * self.counts) / np.sum(self.counts))


def decimation_factor(shape, max_pixels=MAX_PIXELS):
    """Block edge ``ceil(max(nx, ny) / max_pixels)`` (at least 1)."""
    if not (isinstance(max_pixels, int) and max_pixels >= 1):
        raise ValueError(f"max_pixels = {max_pixels!r} is not allowed: need an integer >= 1")
    return max(1, math.ceil(max(shape) / max_pixels))


def block_map(grid, field, *, max_pixels=MAX_PIXELS, root=0):
    """The :class:`Map` of a distributed field (collective; arrays on ``root`` only).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    field : ndarray, shape ``grid.local_shape``
        This rank's rows; booleans (a contact set) are averaged as 0 and 1.
    max_pixels : int
        Upper bound on the map's pixels along either axis.
    """
    comm = grid.comm
    values = check_fields(grid, field=np.asarray(field, dtype=np.float64))["field"]
    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)
    f = decimation_factor((nx, ny), max_pixels)
    bx, by = -(-nx // f), -(-ny // f)
    sums = np.zeros((bx, by))
    if stop > start:
        along_y = np.add.reduceat(values, np.arange(0, ny, f), axis=1)
        np.add.at(sums, np.arange(start, stop) // f, along_y)
    total = np.zeros_like(sums) if comm.rank == root else None
    comm.Reduce(sums, total, op=MPI.SUM, root=root)
    dx, dy = pixel(grid)
    extent = (0.0, nx * dx, 0.0, ny * dy)
    if comm.rank != root:
        return Map(values=None, counts=None, factor=f, extent=extent)
    rows = np.minimum(np.arange(1, bx + 1) * f, nx) - np.arange(bx) * f
    cols = np.minimum(np.arange(1, by + 1) * f, ny) - np.arange(by) * f
    counts = np.outer(rows, cols).astype(np.int64)
    return Map(values=total / counts, counts=counts, factor=f, extent=extent)
