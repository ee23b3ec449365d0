"""Connected components of a distributed pixel set, labelled across slabs and seams.

A component is a 4-connected set of pixels (pixels sharing an edge; pixels that touch
only at a corner belong to different components).  On a periodic cell a component
that leaves one side comes back on the other: its pieces are one component.  The
contact patches (:mod:`.patches`) and the open clusters of the gap through which fluid
can flow (:mod:`.percolation`) are both labelled here.

How it runs in parallel: each rank labels its own slab (:func:`scipy.ndimage.label`),
its labels are numbered after those of the ranks before it, and the pairs of labels
that touch across a slab face (one halo row fetched from the neighbouring rank) or
across the periodic seam are sent to rank 0, which joins them
(:func:`scipy.sparse.csgraph.connected_components`) and numbers the components in a
rank-independent order: by the smallest global pixel index ``i * ny + j`` each one
holds.  Only labels and boundary pairs travel, never the field.  The result is the
same for any number of ranks.

Winding: on a periodic cell a component may *wrap* around the cell, i.e. hold a
closed path that goes once (or more) round the torus along x or y.  A wrapping
component is what carries a net flow through a periodic cell; one that does not
wrap is bounded once the cell is unrolled, however it crosses the seams.  Each pair
of labels that touch across a seam carries the number of cell lengths it crosses
(``+1`` from row ``nx - 1`` to row 0 along x, from column ``ny - 1`` to column 0 along
y).  Rank 0 walks each component from one label, giving every label an offset in
whole cells; a pair whose two labels disagree with the offset the walk gave them
closes a loop round the cell (the classic test of Machta et al. and of Newman and
Ziff for wrapping clusters), and the component wraps along that axis.
"""
from collections import defaultdict
from dataclasses import dataclass
from typing import Optional

import numpy as np
from mpi4py import MPI
from petgap.analysis._slabs import check_fields, fetch_rows, global_shape, local_rows


@dataclass
class Components:
    """The connected components of a pixel set (scalars the same on every rank).

    Attributes
    ----------
    labels : ndarray of int32 (int64 beyond 2^31 - 1 labels), shape ``grid.local_shape``
        This rank's slab: the component of each pixel, ``-1`` outside the set.
        Components are numbered ``0 .. count - 1`` by their first pixel.
    count : int
        Number of components.
    first_pixel : ndarray of int64
        Smallest global index ``i * ny + j`` of each component.
    wraps : ndarray of bool, shape ``(count, 2)``, or None
        Whether each component wraps round the periodic cell along x (column 0) and
        along y (column 1); None unless asked for (``winding=True``).
    """
    labels: np.ndarray
    count: int
    first_pixel: np.ndarray
    wraps: Optional[np.ndarray] = None

    def pixels(self, comm):
        """Number of pixels of each component (collective)."""
        inside = self.labels >= 0
        local = np.bincount(self.labels[inside], minlength=self.count).astype(np.int64)
        return comm.allreduce(local, op=MPI.SUM)

    def touching(self, comm, where):
        """Which components have a pixel where the local boolean slab ``where`` is true
        (collective)."""
        hit = np.zeros(self.count, dtype=np.int64)
        hit[np.unique(self.labels[where & (self.labels >= 0)])] = 1
        return comm.allreduce(hit, op=MPI.SUM) > 0


def label_components(grid, mask, *, periodic=True, winding=False):
    """The :class:`Components` of a distributed pixel set (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        The decomposition (row slabs).
    mask : ndarray of bool, shape ``grid.local_shape``
        This rank's slab of the set.
    periodic : bool
        Join components across the cell's edges (a periodic cell) or not (a map with
        a free boundary).
    winding : bool
        Also find which components wrap round the periodic cell (:attr:`Components.wraps`).
    """
    # deferred: importing SciPy changes warning filters, which `import petgap` must not do
    from scipy import ndimage

    comm = grid.comm
    mask = check_fields(grid, mask=mask)["mask"]
    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)

    labels, nlocal = ndimage.label(mask)        # int32, numbered after the ranks before
    offset = comm.exscan(nlocal, op=MPI.SUM) if comm.size > 1 else 0
    offset = int(offset or 0)
    total = int(comm.allreduce(nlocal, op=MPI.SUM))
    if total >= np.iinfo(np.int32).max:
        labels = labels.astype(np.int64)
    labels[labels > 0] += offset
    pairs = _touching_pairs(grid, labels, periodic)
    # each local label's first global pixel, to number the components independently of ranks
    first = _first_pixels(labels, offset, nlocal, start * ny)
    gathered = comm.gather((pairs, first), root=0)
    verdict = _join(gathered, total, winding) if comm.rank == 0 else None
    mapping, first_pixel, wraps = comm.bcast(verdict, root=0)
    mapping = mapping.astype(labels.dtype)
    np.take(mapping, labels, out=labels)
    return Components(labels=labels, count=len(first_pixel),
                      first_pixel=np.asarray(first_pixel, dtype=np.int64), wraps=wraps)


def _touching_pairs(grid, labels, periodic):
    """Rows ``(a, b, sx, sy)``: local labels ``a`` and ``b`` touch across the slab face below
    or the seam, ``b`` lying ``(sx, sy)`` cells on from ``a``."""
    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)
    pairs = []
    want_below = stop < nx or periodic
    below = fetch_rows(grid, [labels], [stop] if (want_below and stop > start) else [])
    if below.shape[1]:
        mine, theirs = labels[-1], below[0, 0].astype(np.int64)
        touch = (mine > 0) & (theirs > 0)
        across = 1 if stop == nx else 0          # row nx - 1 to row 0: one cell on along x
        pairs.append(np.stack([mine[touch], theirs[touch], np.full(touch.sum(), across),
                               np.zeros(touch.sum(), dtype=np.int64)], axis=1))
    if periodic and ny > 1 and labels.size:
        touch = (labels[:, -1] > 0) & (labels[:, 0] > 0)
        pairs.append(np.stack([labels[touch, -1], labels[touch, 0],
                               np.zeros(touch.sum(), dtype=np.int64),
                               np.ones(touch.sum(), dtype=np.int64)], axis=1))
    if not pairs:
        return np.empty((0, 4), dtype=np.int64)
    return np.unique(np.concatenate(pairs).astype(np.int64), axis=0)


def _first_pixels(labels, offset, count, base):
    """The smallest global pixel index of each of this rank's labels ``offset + 1 ..
    offset + count``, found a block of rows at a time (no slab-sized index array)."""
    # deferred: importing SciPy changes warning filters, which `import petgap` must not do
    from scipy import ndimage

    nloc, ny = labels.shape
    first = np.full(count, -1, dtype=np.int64)
    step = max(1, (1 << 16) // max(ny, 1))
    for a in range(0, nloc, step):
        block = labels[a:a + step]
        ids = np.unique(block[block > 0]) - offset
        ids = ids[first[ids - 1] < 0]           # rows in order: a label's first block holds it
        if ids.size:
            index = base + a * ny + np.arange(block.size, dtype=np.int64).reshape(block.shape)
            first[ids - 1] = ndimage.minimum(index, block, ids + offset)
    return first


def _join(gathered, total, winding):
    """Rank 0: the global numbering of the local labels, each component's first pixel and,
    if asked, which components wrap."""
    # deferred: importing SciPy changes warning filters, which `import petgap` must not do
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pairs = np.concatenate([p for p, _ in gathered])
    pairs[:, :2] -= 1
    all_first = np.concatenate([f for _, f in gathered])
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(total, total))
    ncomp, comp = connected_components(graph, directed=False)
    comp_first = np.full(ncomp, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(comp_first, comp, all_first)
    order = np.argsort(comp_first, kind="stable")
    rank_of = np.empty(ncomp, dtype=np.int64)
    rank_of[order] = np.arange(ncomp)
    mapping = np.concatenate([[-1], rank_of[comp]]).astype(np.int64)
    wraps = None
    if winding:
        wraps = _wrapping_axes(pairs, comp, rank_of, ncomp)
    return mapping, comp_first[order], wraps


def _wrapping_axes(pairs, comp, rank_of, ncomp):
    """Walk each component's label graph giving labels offsets in whole cells; a pair that
    contradicts them closes a loop round the cell along the axes where they differ."""
    neighbours = defaultdict(list)
    for a, b, sx, sy in pairs.tolist():
        neighbours[a].append((b, sx, sy))
        neighbours[b].append((a, -sx, -sy))
    offset = {}
    wraps = np.zeros((ncomp, 2), dtype=bool)
    for root in neighbours:
        if root in offset:
            continue
        offset[root] = (0, 0)
        todo = [root]
        while todo:
            v = todo.pop()
            ox, oy = offset[v]
            for w, sx, sy in neighbours[v]:
                want = (ox + sx, oy + sy)
                have = offset.setdefault(w, want)
                if have is want:
                    todo.append(w)
                elif have != want:
                    c = rank_of[comp[v]]
                    wraps[c, 0] |= have[0] != want[0]
                    wraps[c, 1] |= have[1] != want[1]
    return wraps
