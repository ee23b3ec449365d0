"""Percolation of the open gap: does a path of non-contact pixels cross the map?

The open region is the set of pixels whose gap exceeds the zero-gap tolerance
(:func:`petgap.analysis.resolve_gap_tolerance`): pixels in contact, and pixels held at
zero gap under adhesive tension, are closed.  Its 4-connected clusters are labelled
across slabs and seams (:func:`petgap.analysis.components.label_components`); fluid
passes from one pixel to the next only through a shared edge, so pixels that touch at a
corner are not connected (the same rule as the contact patches).

A cluster *spans* the map in the flow direction when

* on a free map (inlet and outlet edges, sealed sides): it holds a pixel of the inlet
  edge and one of the outlet edge (row 0 and row ``nx - 1`` for flow along x, column 0
  and ``ny - 1`` along y);
* on a periodic cell: it wraps round the cell along the flow direction (a cluster that
  crosses the seam without closing a loop round the cell is bounded once the cell is
  unrolled, and carries no net flow).

Only spanning clusters carry a leak; the others are dead ends or sealed pockets.  The
open region *percolates* when some cluster spans.
"""
from dataclasses import dataclass

import numpy as np

from petgap.analysis._slabs import check_fields, global_shape, local_rows
from petgap.analysis.components import Components, label_components
from petgap.analysis.contact_geometry import resolve_gap_tolerance

#: The flow directions and the axis of the slab arrays each one runs along.
DIRECTIONS = {"x": 0, "y": 1}


@dataclass
class Percolation:
    """The open clusters of a gap field and whether they cross the map (same on every rank).

    Attributes
    ----------
    direction : str
        ``"x"`` or ``"y"``, the flow direction the spanning refers to.
    periodic : bool
        Periodic cell (spanning = wrapping) or free map (spanning = inlet to outlet).
    open_fraction : float
        Fraction of the pixels that are open (``1 -`` the closed fraction).
    clusters : int
        Number of open clusters.
    cluster_pixels : ndarray of int64
        Pixels of each cluster (clusters ordered by their first pixel).
    spanning : ndarray of bool
        Whether each cluster spans the map in the flow direction.
    at_inlet, at_outlet : ndarray of bool
        Whether each cluster touches the inlet / outlet edge (free map; all False on a
        periodic cell, which has neither).
    largest_fraction : float
        Pixels of the largest open cluster over all pixels of the map.
    spanning_fraction : float
        Pixels of the spanning clusters over all pixels (the backbone and its dead ends).
    gap_tolerance : float
        The absolute gap at or below which a pixel counts as closed.
    components : petgap.analysis.components.Components
        The labels (this rank's slab, ``-1`` on closed pixels).
    """
    direction: str
    periodic: bool
    open_fraction: float
    clusters: int
    cluster_pixels: np.ndarray
    spanning: np.ndarray
    at_inlet: np.ndarray
    at_outlet: np.ndarray
    largest_fraction: float
    spanning_fraction: float
    gap_tolerance: float
    components: Components

    @property
    def percolates(self):
        """Whether some open cluster spans the map in the flow direction."""
        return bool(np.any(self.spanning))

    def reason(self):
        """Why no fluid crosses the map ("" when it percolates), in words."""
        if self.percolates:
            return ""
        if self.open_fraction == 0:
            return "the whole map is closed (every pixel in contact or at zero gap)"
        what = "wraps round the periodic cell" if self.periodic else \
            "joins the inlet edge to the outlet edge"
        return (f"no open cluster {what} along {self.direction}: the open region "
                f"({100 * self.open_fraction:.3g} % of the map, {self.clusters} clusters, the "
                f"largest {100 * self.largest_fraction:.3g} %) does not percolate")

    def scalars(self):
        """The scalar results as a flat dict (for tables and result files)."""
        return {"percolates": self.percolates, "open_fraction": self.open_fraction,
                "open_clusters": self.clusters, "largest_cluster_fraction": self.largest_fraction,
                "spanning_fraction": self.spanning_fraction,
                "spanning_clusters": int(np.count_nonzero(self.spanning))}


def check_direction(grid, direction):
    """The axis of ``direction``; ValueError (on every rank alike) for an unknown direction or
    a map with fewer than two pixels along it, where no pressure gradient fits."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction = {direction!r} is not allowed: need one of "
                         f"{', '.join(map(repr, DIRECTIONS))}")
    axis = DIRECTIONS[direction]
    n = global_shape(grid)[axis]
    if n < 2:
        raise ValueError(f"direction = {direction!r}: the map has {n} pixel along {direction} "
                         f"(shape {global_shape(grid)}), too few for a pressure drop; allowed: a "
                         f"direction with at least 2 pixels")
    return axis


def open_clusters(grid, gap, *, direction="x", periodic=True, gap_tolerance=None):
    """The :class:`Percolation` of a distributed gap field (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    gap : ndarray, shape ``grid.local_shape``
        This rank's slab of the gap.
    direction : {"x", "y"}
        The flow direction.
    periodic : bool
        A periodic cell, or a free map with inlet and outlet edges across ``direction``.
    gap_tolerance : float, optional
        Gaps at or below it are closed (default: :func:`petgap.analysis.resolve_gap_tolerance`).
    """
    axis = check_direction(grid, direction)
    gap = check_fields(grid, gap=gap)["gap"]
    tolerance = resolve_gap_tolerance(grid, gap, gap_tolerance)
    is_open = gap > tolerance
    components = label_components(grid, is_open, periodic=periodic, winding=periodic)
    comm = grid.comm
    nx, ny = global_shape(grid)
    pixels = components.pixels(comm)
    nopen = int(np.sum(pixels))
    if periodic:
        spanning = components.wraps[:, axis].copy()
        at_inlet = at_outlet = np.zeros(components.count, dtype=bool)
    else:
        start, stop = local_rows(grid)
        inlet, outlet = (np.zeros(is_open.shape, dtype=bool) for _ in range(2))
        if axis == 0:
            inlet[:1] = start == 0
            outlet[-1:] = stop == nx
        else:
            inlet[:, 0] = outlet[:, -1] = True
        at_inlet = components.touching(comm, inlet)
        at_outlet = components.touching(comm, outlet)
        spanning = at_inlet & at_outlet
    return Percolation(direction=direction, periodic=bool(periodic),
                       open_fraction=nopen / (nx * ny), clusters=components.count,
                       cluster_pixels=pixels, spanning=spanning, at_inlet=at_inlet,
                       at_outlet=at_outlet,
                       largest_fraction=float(pixels.max(initial=0)) / (nx * ny),
                       spanning_fraction=float(pixels[spanning].sum()) / (nx * ny),
                       gap_tolerance=tolerance, components=components)
