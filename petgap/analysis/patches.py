"""Contact patches: the connected pieces of the contact set, their number, areas and perimeters.

A patch is a 4-connected set of contact pixels (pixels sharing an edge; pixels that
touch only at a corner are separate patches, the same rule as the pixel-edge
perimeter of :func:`petgap.analysis.perimeter`).  On a periodic cell a patch that
leaves one side comes back on the other: its pieces are one patch.  On a
non-periodic map (``periodic=False``: a measured topography solved with a free
boundary) nothing joins across the edge of the map, and the edge of the map is not
part of any perimeter (it is where the data ends, not a contact line).

How it runs in parallel: the patches are labelled across slabs and seams by
:func:`petgap.analysis.components.label_components` (only labels and boundary pairs
travel, never the field) and numbered in a rank-independent order, by the smallest
global pixel index ``i * ny + j`` each patch holds; areas and perimeters are then
summed per patch over all ranks.  The result is the same for any number of ranks.
"""
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petgap.analysis._slabs import check_fields, fetch_rows, global_shape, local_rows, pixel
from petgap.analysis.components import label_components


@dataclass
class Patches:
    """Contact patches of one contact set (the same on every rank).

    Arrays are indexed by patch number, patches ordered by their first pixel in the
    row-major global order (so the order does not depend on the ranks).

    Attributes
    ----------
    count : int
        Number of patches.
    pixels : ndarray of int64
        Contact pixels of each patch.
    areas : ndarray
        ``pixels * dx * dy``.
    perimeters : ndarray
        Pixel-edge length of each patch's boundary: edges between one of its pixels
        and a non-contact pixel, ``dy`` for an edge crossed along x and ``dx`` for one
        crossed along y.  The sum over patches is the ``pixel_edge_length`` of
        :func:`petgap.analysis.perimeter` (periodic cells).  Pixel edges overestimate a
        smooth contour's length (by 4/pi for isotropic shapes); the paper's ``P_rep``
        is the refined contour of :func:`petgap.analysis.perimeter`.
    first_pixel : ndarray of int64
        Smallest global index ``i * ny + j`` of each patch.
    periodic : bool
        Whether patches were joined across the edges of the cell.
    """
    count: int
    pixels: np.ndarray
    areas: np.ndarray
    perimeters: np.ndarray
    first_pixel: np.ndarray
    periodic: bool

    def area_distribution(self, bins_per_decade=5):
        """Histogram of patch areas on logarithmic bins: ``(edges, counts)``.

        The bins start at one pixel's area and are ``bins_per_decade`` per decade up to
        the largest patch; ``counts[k]`` patches have ``edges[k] <= area < edges[k+1]``.
        """
        if self.count == 0:
            return np.empty(0), np.empty(0, dtype=np.int64)
        lo = float(np.min(self.areas))
        hi = float(np.max(self.areas))
        decades = max(np.log10(hi / lo), 1.0 / bins_per_decade)
        nbins = int(np.ceil(decades * bins_per_decade - 1e-9)) + 1
        edges = lo * 10.0 ** (np.arange(nbins + 1) / bins_per_decade)
        counts, _ = np.histogram(self.areas, bins=edges)
        return edges, counts.astype(np.int64)

    def rows(self):
        """One dict per patch (for tables): index, pixels, area, perimeter, first pixel."""
        return [{"patch": k, "pixels": int(self.pixels[k]), "area": float(self.areas[k]),
                 "perimeter_pixel_edges": float(self.perimeters[k]),
                 "first_pixel": int(self.first_pixel[k])} for k in range(self.count)]


def contact_patches(grid, mask, *, periodic=True):
    """The :class:`Patches` of a distributed contact set (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        The decomposition (row slabs) and pixel size.
    mask : ndarray of bool, shape ``grid.local_shape``
        This rank's slab of the contact set, e.g. :func:`petgap.analysis.contact_mask`.
    periodic : bool
        Join patches across the cell's edges (a periodic solution) or not (a map with
        a free boundary).
    """
    comm = grid.comm
    mask = check_fields(grid, mask=mask)["mask"]
    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)
    dx, dy = pixel(grid)

    components = label_components(grid, mask, periodic=periodic)
    count, patch = components.count, components.labels
    pixels = np.bincount(patch[mask], minlength=count).astype(np.int64)

    # pixel edges to a non-contact neighbour, charged to the contact pixel's patch
    rows = [start - 1, stop] if stop > start else []
    halo = fetch_rows(grid, [mask.astype(np.float64)], rows)
    edges = np.zeros(count)
    if stop > start:
        up = halo[0, 0] > 0.5 if (start > 0 or periodic) else mask[0]
        down = halo[0, 1] > 0.5 if (stop < nx or periodic) else mask[-1]
        above = np.concatenate([up[None, :], mask[:-1]])
        beneath = np.concatenate([mask[1:], down[None, :]])
        for neighbour in (above, beneath):          # edges crossed along x: length dy
            cut = mask & ~neighbour
            edges += dy * np.bincount(patch[cut], minlength=count)
        left = np.roll(mask, 1, axis=1)
        right = np.roll(mask, -1, axis=1)
        if not periodic:                            # the map's edge is no contact line
            left[:, 0] = True
            right[:, -1] = True
        for neighbour in (left, right):             # edges crossed along y: length dx
            cut = mask & ~neighbour
            edges += dx * np.bincount(patch[cut], minlength=count)
    pixels = comm.allreduce(pixels, op=MPI.SUM)
    edges = comm.allreduce(edges, op=MPI.SUM)
    return Patches(count=count, pixels=pixels, areas=pixels * dx * dy, perimeters=edges,
                   first_pixel=components.first_pixel, periodic=bool(periodic))
