"""Slab helpers shared by the analyses: field checks, global sums, halo rows across ranks."""
import math
import numbers

import numpy as np
from mpi4py import MPI

_HALO_TAG = 7301


def global_shape(grid):
    nx, ny = grid.shape
    return int(nx), int(ny)


def pixel(grid):
    nx, ny = global_shape(grid)
    dx = getattr(grid, "dx", None)
    dy = getattr(grid, "dy", None)
    if dx is None or dy is None:
        lx, ly = getattr(grid, "Lx", nx), getattr(grid, "Ly", ny)
        dx, dy = lx / nx, ly / ny
    return float(dx), float(dy)


def local_rows(grid):
    return grid.x_slice.start, grid.x_slice.stop


def check_fields(grid, **arrays):
    """The arrays as float64 (bool for ``mask``) in this rank's slab shape; else ValueError everywhere.

    ``None`` values are passed through.  Non-finite values are refused as well: a
    NaN in a gap would silently drop out of every count below.
    """
    nloc = local_rows(grid)[1] - local_rows(grid)[0]
    shape = (nloc, global_shape(grid)[1])
    out, problem = {}, None
    for name, value in arrays.items():
        if value is None:
            out[name] = None
            continue
        arr = np.asarray(value, dtype=bool if name == "mask" else np.float64)
        if arr.shape != shape and problem is None:
            problem = f"{name} has shape {arr.shape}, but this rank's slab is {shape}"
        elif arr.dtype != bool and not np.all(np.isfinite(arr)) and problem is None:
            bad = np.count_nonzero(~np.isfinite(arr))
            problem = f"{name} has non-finite values ({bad} of them)"
        out[name] = arr
    problems = grid.comm.allgather(problem)
    for rank, p in enumerate(problems):
        if p is not None:
            raise ValueError(f"on rank {rank} of {grid.comm.size}: {p}")
    return out


def positive(name, value):
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} = {value!r} is not allowed: need a positive finite number")
    return float(value)


def fetch_rows(grid, fields, rows):
    """Global rows ``rows`` (taken modulo ``nx``) of distributed fields, on this rank.

    Collective.  ``fields`` is a list of this rank's ``(nx_local, ny)`` slabs;
    ``rows`` is this rank's list of wanted global row indices (any order,
    repeats allowed; ranks may want different numbers of rows, or none).
    Every rank computes what every other rank wants from the same rule, so the
    only traffic is the rows themselves (point to point, one message per pair
    of ranks that share rows).

    Returns
    -------
    ndarray, shape ``(len(fields), len(rows), ny)``
    """
    comm = grid.comm
    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)
    nf = len(fields)
    rows = np.asarray(rows, dtype=np.int64) % nx

    def pick(sel_rows):
        buf = np.empty((nf, sel_rows.size, ny))
        for k, f in enumerate(fields):
            buf[k] = f[sel_rows - start]
        return buf

    out = np.empty((nf, rows.size, ny))
    if comm.size == 1:
        if rows.size:
            out[...] = pick(rows)
        return out
    slabs = comm.allgather((start, stop))
    wanted = comm.allgather(rows)
    requests, keep = [], []
    for owner, (a, b) in enumerate(slabs):       # receive, grouped by owner
        sel = np.nonzero((rows >= a) & (rows < b))[0]
        if sel.size == 0:
            continue
        if owner == comm.rank:
            out[:, sel, :] = pick(rows[sel])
            continue
        buf = np.empty((nf, sel.size, ny))
        requests.append(comm.Irecv(buf, source=owner, tag=_HALO_TAG))
        keep.append((sel, buf))
    for other, theirs in enumerate(wanted):      # send, in the order the other rank wants
        if other == comm.rank:
            continue
        sel = theirs[(theirs >= start) & (theirs < stop)]
        if sel.size == 0:
            continue
        buf = pick(sel)
        keep.append((None, buf))
        requests.append(comm.Isend(buf, dest=other, tag=_HALO_TAG))
    MPI.Request.Waitall(requests)
    for sel, buf in keep:
        if sel is not None:
            out[:, sel, :] = buf
    return out


class Extended:
    """Rows ``start - halo .. stop + halo - 1`` of a field without copying the slab.

    ``take(e, j)`` reads extended row ``e`` (0 = ``start - halo``), column ``j``,
    from the halo below, the local slab or the halo above.
    """

    def __init__(self, local, below, above):
        self.local, self.below, self.above = local, below, above
        self.halo, self.n = below.shape[0], local.shape[0]

    def take(self, e, j):
        e = np.asarray(e)
        out = np.empty(e.shape)
        lo = e < self.halo
        hi = e >= self.halo + self.n
        mid = ~(lo | hi)
        out[lo] = self.below[e[lo], j[lo]]
        out[mid] = self.local[e[mid] - self.halo, j[mid]]
        out[hi] = self.above[e[hi] - self.halo - self.n, j[hi]]
        return out


