"""From solved fields to the paper's quantities: contact area, perimeter, gaps, adhesion.

Every function works on a :class:`~petgap.grid.Grid`'s row slabs, ``(nx_local, ny)``,
and returns global results that are the same on every rank (all functions are
collective).  Nothing is ever gathered on one rank: what crosses a slab boundary
(neighbouring pixels of the perimeter) is fetched as a few halo rows, and
histograms and sums are reduced.

Equation numbers are those of the paper the project implements, "Distribution of gaps
and adhesive interaction between contacting rough surfaces" (``shared/paper/
gap-distribution.md``; Monti, Sanner & Pastewka, Tribology Letters, 2021).

Conventions (GUIDE section 4)
-----------------------------
* Gap ``g >= 0`` (length), pressure ``p`` positive in compression, pixel area
  ``dx dy``, nominal area ``A0 = Lx Ly``, ``N = nx ny`` pixels, periodic in x and y.
* Repulsive contact: zero gap, ``g <= gap_tolerance``, **and** ``p > 0``.  A pixel
  at zero gap under tension (adhesive solutions) is *not* in repulsive contact.
  ``A_rep = dx dy * (number of contact pixels)``, ``c = A_rep / A0``.  The default
  tolerance is ``GAP_ROUND_OFF = 1e-6`` times the mean gap (:func:`resolve_gap_tolerance`):
  a solver that computes the gap as ``d + u - h`` leaves round-off gaps of order its
  tolerance (``~1e-9`` of ``h0``) on contact pixels -- on a 512^2 rough contact solved
  to 1e-8 by Polonsky-Keer, 37 % of the contact pixels -- while physical gaps next to a
  contact edge are many orders larger (``g ~ g0 (s / d_rep)^(3/2)``).
* Perimeter ``P_rep``: length of the marching-squares contour of the contact set
  with crossings placed by the universal square-root / three-halves asymptotics
  of a smooth contact edge (:func:`perimeter`).  ``d_rep = pi A_rep / P_rep``
  (Eq. 2), ``g0 = 4 h0' d_rep / 3`` (Eq. 12).
* Gap distribution: densities are per unit gap and normalised over the
  *non-contacting* pixels (their integral is 1 when no pixel sits at zero gap
  outside repulsive contact); the full distribution of the paper's Eq. 9 for
  ``g > 0`` is ``(1 - c)`` times it.
* Interaction stress ``v'(g) > 0`` is tensile (``v = -w exp(-g / rho)``, Eq. 6);
  attractive forces are negative: ``F_att = -sum_x dx dy v'(g(x)) < 0``, and
  ``1 / kappa_att = -F_att / (h0' E* A_rep) > 0`` (the paper's Fig. 3 convention).
"""
import math
import numbers
from dataclasses import asdict, dataclass

import numpy as np
from mpi4py import MPI

__all__ = ["contact_mask", "resolve_gap_tolerance", "GAP_ROUND_OFF", "perimeter",
           "crossing_fraction", "contact_statistics",
           "gap_distribution", "collapse", "fit_power_law", "resolved_gap", "auto_fit_range",
           "FitRange", "near_contact_area",
           "near_contact_area_eq14", "attractive_force_measured", "attractive_force_eq16",
           "inverse_kappa_att", "fig4_integrand", "PerimeterResult", "ContactStatistics",
           "GapDistribution", "PowerLawFit", "NearContactArea", "AttractiveForce",
           "Eq16Force", "GAMMA_2_3"]

#: ``Gamma(2/3)``: the factor by which the exact integral of Eq. 16 exceeds the printed result.
GAMMA_2_3 = math.gamma(2.0 / 3.0)

#: Angle-correction sweeps of the perimeter's crossing points (see :func:`perimeter`).
PERIMETER_SWEEPS = 3

# Lower bound of the direction cosine used in the crossing correction: keeps the
# correction finite where a (pixel-sized, badly resolved) contour runs along an edge.
_MIN_COSINE = 0.1

_HALO_TAG = 7301


# ====================================================================== helpers
def _global_shape(grid):
    nx, ny = grid.shape
    return int(nx), int(ny)


def _pixel(grid):
    nx, ny = _global_shape(grid)
    dx = getattr(grid, "dx", None)
    dy = getattr(grid, "dy", None)
    if dx is None or dy is None:
        lx, ly = getattr(grid, "Lx", nx), getattr(grid, "Ly", ny)
        dx, dy = lx / nx, ly / ny
    return float(dx), float(dy)


def _local_rows(grid):
    return grid.x_slice.start, grid.x_slice.stop


def _check_fields(grid, **arrays):
    """The arrays as float64 (bool for ``mask``) in this rank's slab shape; else ValueError everywhere.

    ``None`` values are passed through.  Non-finite values are refused as well: a
    NaN in a gap would silently drop out of every count below.
    """
    nloc = _local_rows(grid)[1] - _local_rows(grid)[0]
    shape = (nloc, _global_shape(grid)[1])
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


def _allreduce_sum(comm, values, dtype=np.float64):
    values = np.asarray(values, dtype=dtype)
    total = np.empty_like(values)
    comm.Allreduce(values, total, op=MPI.SUM)
    return total


def _positive(name, value):
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} = {value!r} is not allowed: need a positive finite number")
    return float(value)


def _fetch_rows(grid, fields, rows):
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
    nx, ny = _global_shape(grid)
    start, stop = _local_rows(grid)
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


class _Extended:
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


# =================================================================== contact set
def contact_mask(gap, pressure, gap_tolerance=0.0):
    """Pixels in repulsive contact: zero gap *and* compressive pressure.

    Parameters
    ----------
    gap, pressure : ndarray
        Local slabs (any matching shape).
    gap_tolerance : float
        A gap ``g <= gap_tolerance`` counts as zero.  The default 0 suits
        solvers that put the bound ``g >= 0`` exactly (projected methods do).

    Returns
    -------
    ndarray of bool

    Notes
    -----
    Zero gap alone is not enough: an adhesive solution can hold surfaces together
    at ``g = 0`` under *tension* (``p < 0``), and those pixels are not part of the
    repulsive area ``A_rep`` of the paper; ``p > 0`` alone is not enough either,
    since a non-converged state can carry pressure at open gaps.
    """
    gap = np.asarray(gap)
    pressure = np.asarray(pressure)
    return (gap <= gap_tolerance) & (pressure > 0)


#: Default zero-gap tolerance relative to the mean gap (see :func:`resolve_gap_tolerance`).
GAP_ROUND_OFF = 1e-6


def resolve_gap_tolerance(grid, gap, gap_tolerance=None):
    """The absolute zero-gap tolerance: ``gap_tolerance`` itself, or by default
    ``GAP_ROUND_OFF`` times the global mean gap (collective in that case).

    Why relative to the mean gap: a converged solver leaves gaps of order
    ``tolerance x h0`` on contact pixels (``h0`` ~ mean gap at small contact
    fractions), while the smallest physical gaps of the non-contacting pixels
    next to an edge are ``~ g0 (dx / d_rep)^(3/2)``, typically ``1e-2 dx``; a
    pixel falls below ``1e-6`` of the mean gap by the ``s^(3/2)`` law only with
    probability ``~1e-4`` per edge pixel.  Pass 0 to require exact zeros.
    """
    if gap_tolerance is not None:
        value = float(gap_tolerance)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"gap_tolerance = {gap_tolerance!r}: need a finite number >= 0")
        return value
    nx, ny = _global_shape(grid)
    total = grid.comm.allreduce(float(np.sum(np.asarray(gap, dtype=float))), op=MPI.SUM)
    return GAP_ROUND_OFF * max(total / (nx * ny), 0.0)


# ==================================================================== perimeter
def _solve_depressed_cubic(K):
    """The root ``u in (0, 1]`` of ``K u^3 + u - 1 = 0`` for ``K >= 0`` (vectorised).

    Newton from ``u0 = min(1, K^(-1/3))``, where the (convex, increasing)
    function is non-negative: the iterates then decrease monotonically to the
    root, with no overshoot, for any ``K`` including 0 (root 1) and huge values
    (root ``~ K^(-1/3)``).  Converges to round-off in at most ~6 steps.
    """
    K = np.minimum(np.asarray(K, dtype=float), 1e300)
    with np.errstate(divide="ignore"):
        u = np.minimum(1.0, np.cbrt(1.0 / K))
    for _ in range(60):
        du = (K * u ** 3 + u - 1.0) / (3.0 * K * u * u + 1.0)
        u = u - du
        if np.all(np.abs(du) <= 4e-16 * u):
            break
    return u


def crossing_fraction(p_in, g_out, spacing, contact_modulus, cosine=1.0, p_out=None):
    """Where a smooth contact edge crosses the segment from an inside to an outside pixel.

    The edge asymptotics of any non-adhesive elastic contact (locally a plane-strain
    cylinder: Hertz line contact, ``p = p0 sqrt(1 - x^2/a^2)``, ``p0 = E* a / (2R)``,
    ``g'(x) = sqrt(x^2 - a^2) / R`` outside; Johnson 1985, section 4.2) are, at
    normal distance ``s`` from the edge, with a local intensity ``A`` that is not
    known in advance::

        inside:  p = A s^(1/2),        outside:  g = (4 A / (3 E*)) s^(3/2)

    (check: near ``x = a``, ``p ~ p0 sqrt(2 s / a)`` so ``A = p0 sqrt(2 / a)``, and
    ``g ~ (2 / (3R)) sqrt(2a) s^(3/2) = (4 A / (3 E*)) s^(3/2)``).  Two pixels a
    distance ``d`` apart along a line that meets the edge normal at an angle with
    cosine ``c`` have normal distances ``t d c`` and ``(1 - t) d c``, ``t`` the
    fraction of the way from the inside pixel to the edge.  Eliminating ``A``::

        t = K c^2 (1 - t)^3,    K = (4 p_in d / (3 E* g_out))^2,

    one root in ``[0, 1]`` (with ``u = 1 - t``: ``K c^2 u^3 + u - 1 = 0``).  This is
    the brief's ``alpha y^3 + beta y = d`` with ``y = A^(-2/3)``, solved for the
    fraction instead, which stays well conditioned for any ratio of ``p_in`` to
    ``g_out`` (no cube roots of differences of large numbers, as in Cardano).

    An outside pixel at zero gap (``g_out <= 0``: contact under tension, or the
    exact edge of a non-adhesive state where ``p = 0``) has no three-halves law to
    use; there the edge is put at the zero of the pressure, linearly interpolated
    between ``p_in`` and ``p_out <= 0`` (at the outside pixel if ``p_out = 0``,
    which is also the limit of the formula above as ``g_out -> 0``).

    Parameters
    ----------
    p_in : array_like
        Pressure at the inside pixel (``> 0``; values ``<= 0`` give ``t = 0``).
    g_out : array_like
        Gap at the outside pixel.
    spacing : float or array_like
        Distance ``d`` between the two pixels.
    contact_modulus : float
        ``E*``.
    cosine : float or array_like
        Cosine of the angle between the pixel segment and the edge normal
        (1: the segment is normal to the edge).
    p_out : array_like, optional
        Pressure at the outside pixel, used where ``g_out <= 0`` (default 0).

    Returns
    -------
    ndarray
        ``t`` in ``[0, 1]``.
    """
    p_in = np.maximum(np.asarray(p_in, dtype=float), 0.0)
    g_out = np.asarray(g_out, dtype=float)
    p_in, g_out = np.broadcast_arrays(p_in, g_out)
    p_out = np.zeros_like(p_in) if p_out is None else np.broadcast_to(
        np.minimum(np.asarray(p_out, dtype=float), 0.0), p_in.shape)
    spacing = np.broadcast_to(np.asarray(spacing, dtype=float), p_in.shape)
    cosine = np.broadcast_to(np.asarray(cosine, dtype=float), p_in.shape)
    t = np.empty(p_in.shape)
    open_ = g_out > 0
    if np.any(open_):
        ratio = 4.0 * p_in[open_] * spacing[open_] * cosine[open_] \
            / (3.0 * contact_modulus * g_out[open_])
        ratio = np.minimum(ratio, 1e150)  # t = 1 to round-off long before; no overflow
        t[open_] = 1.0 - _solve_depressed_cubic(ratio * ratio)
    closed = ~open_
    if np.any(closed):
        pi, po = p_in[closed], p_out[closed]
        den = pi - po
        with np.errstate(invalid="ignore", divide="ignore"):
            t[closed] = np.where(den > 0, pi / np.where(den > 0, den, 1.0), 0.5)
    return np.clip(t, 0.0, 1.0)


@dataclass(frozen=True)
class PerimeterResult:
    """The contact perimeter, and the raw pixel-edge measure for comparison.

    Attributes
    ----------
    perimeter : float
        ``P_rep``: length of the marching-squares contour (physical units).
    pixel_edges : int
        Number of pixel edges between a contact and a non-contact pixel.
    pixel_edge_length : float
        Their total length (``dy`` for an edge between x-neighbours, ``dx`` for
        one between y-neighbours).  Over-counts an edge at angle ``theta`` to the
        axes by ``|cos theta| + |sin theta|``: ``4 / pi`` on average over
        directions (a disc), ``sqrt 2`` on a diagonal; it never converges.
    segments : int
        Contour segments (one or two per boundary cell).
    saddles : int
        Ambiguous (saddle) cells, resolved by the cell-centre rule.
    method : str
        ``"asymptotic"`` (fields) or ``"midpoint"`` (binary mask only).
    """

    perimeter: float
    pixel_edges: int
    pixel_edge_length: float
    segments: int
    saddles: int
    method: str


def perimeter(grid, gap=None, pressure=None, contact_modulus=None, mask=None, *,
              gap_tolerance=None, sweeps=PERIMETER_SWEEPS):
    """Contact perimeter ``P_rep`` by marching squares with asymptotic edge crossings.

    Why not count pixel edges: a staircase along an edge at angle ``theta`` is
    ``|cos theta| + |sin theta|`` times longer than the edge, whatever the
    resolution (``4 / pi`` on average over directions).  Marching squares
    (Lorensen & Cline 1987, in 2D) joins crossing points on the cell edges
    between pixel centres into a polygon; its length converges to the true
    perimeter *if* the crossing points converge to the edge faster than the
    cell size.  Placing them at midpoints does not (see below); this function
    places them with the universal asymptotics of a smooth, non-adhesive
    contact edge (:func:`crossing_fraction`): pressure ``p ~ s^(1/2)`` inside,
    gap ``g ~ s^(3/2)`` outside, at normal distance ``s``.

    Algorithm
    ---------
    1. Cells are the squares between four neighbouring pixel centres ``(i, j)``,
       ``(i+1, j)``, ``(i+1, j+1)``, ``(i, j+1)`` (periodic); a cell edge between
       a contact and a non-contact pixel holds one crossing.
    2. Crossing on each such edge from :func:`crossing_fraction` with cosine 1.
    3. Contour segments per cell: two crossings give one segment; four (a
       saddle: diagonal corners alike) give two, joined so that the cell centre
       is *inside* if the mean inside fraction of the four edges exceeds 1/2
       (the cell-centre average of the edge-wise interpolant) and outside
       otherwise, including ties -- so diagonal single contact pixels are kept
       apart (4-connectivity), the rule of the binary-mask fallback.
    4. Angle correction (``sweeps`` times): the direction of the contour at each
       crossing is estimated from the chord between the neighbouring contour
       points (the other ends of the two segments meeting there), the cosine
       between the cell edge and the contour normal is inserted in step 2 and
       steps 2-3 are redone.  Without it, crossings on x- and y-edges of an
       oblique contour are displaced differently (the asymptotics are in the
       *normal* distance) and the polygon zig-zags: the length then stalls at
       a resolution-independent relative error (about +0.2 % on discs); with
       it the error falls as ``(dx / a)^2``.
    5. ``P_rep`` = sum of segment lengths in physical units (``dx``, ``dy``).

    If only a binary ``mask`` is given (no fields), crossings are put at edge
    midpoints and not corrected.  That has a known orientation bias: along a
    straight edge at angle ``theta`` the midpoint polygon zig-zags, over-counting
    by 0 at ``theta = 0`` and ``45`` degrees and by up to about 8 % between (about
    +5.5 % averaged over the directions of a disc, at any resolution).

    Parallel: each rank measures the cells whose lower-left pixel is in its
    slab.  It fetches ``sweeps + 2`` halo rows on each side from the ranks that
    own them (periodic), so the result equals the serial one up to the order of
    summation, on any number of ranks and for contact regions cut by slab or
    periodic boundaries.

    Parameters
    ----------
    grid : petgap.grid.Grid
    gap, pressure : ndarray, shape ``grid.local_shape``, optional
        Local slabs of the solved fields.
    contact_modulus : float, optional
        ``E*``; required with fields.
    mask : ndarray of bool, optional
        Contact set to measure instead of :func:`contact_mask` (with fields:
        crossings still from the fields; without fields: midpoints).
    gap_tolerance : float, optional
        Zero-gap tolerance of the contact set (default: :func:`resolve_gap_tolerance`).
    sweeps : int
        Angle-correction sweeps (0 switches the correction off).

    Returns
    -------
    PerimeterResult
        The same on every rank.
    """
    fields = gap is not None or pressure is not None
    if fields and (gap is None or pressure is None):
        raise ValueError("perimeter needs both gap and pressure (or neither, with a mask)")
    if not fields and mask is None:
        raise ValueError("perimeter needs the gap and pressure fields, or a contact mask")
    if fields:
        contact_modulus = _positive("contact_modulus", contact_modulus)
    if isinstance(sweeps, bool) or not isinstance(sweeps, numbers.Integral) or sweeps < 0:
        raise ValueError(f"sweeps = {sweeps!r} is not allowed: need an integer >= 0")
    checked = _check_fields(grid, gap=gap, pressure=pressure, mask=mask)
    gap, pressure, mask = checked["gap"], checked["pressure"], checked["mask"]
    if mask is None:
        mask = contact_mask(gap, pressure, resolve_gap_tolerance(grid, gap, gap_tolerance))
    method = "asymptotic" if fields else "midpoint"
    sweeps = int(sweeps) if fields else 0

    nx, ny = _global_shape(grid)
    dx, dy = _pixel(grid)
    start, stop = _local_rows(grid)
    nloc = stop - start
    halo = sweeps + 2
    slabs = [mask.astype(np.float64)] + ([gap, pressure] if fields else [])
    rows = np.concatenate([np.arange(start - halo, start), np.arange(stop, stop + halo)]) \
        if nloc else np.empty(0, dtype=np.int64)
    ext = _fetch_rows(grid, slabs, rows)  # (nf, 2 halo, ny): the rows below, then above
    below, above = ext[:, :halo], ext[:, halo:]
    length, counts = 0.0, np.zeros(2)
    ex = ey = 0
    if nloc:
        inside = np.concatenate([below[0] > 0.5, mask, above[0] > 0.5])
        values = (_Extended(gap, below[1], above[1]), _Extended(pressure, below[2], above[2])) \
            if fields else None
        length, counts = _perimeter_block(inside, values, halo, nloc, dx, dy, contact_modulus,
                                          sweeps)
        # raw pixel edges of the owned rows: x-neighbours to the next row, y-neighbours in it
        ex = np.count_nonzero(mask != inside[halo + 1:halo + nloc + 1])
        ey = np.count_nonzero(mask != np.roll(mask, -1, axis=1))
    total = _allreduce_sum(grid.comm, [length, counts[0], counts[1]])
    edges = _allreduce_sum(grid.comm, [ex, ey], dtype=np.int64)
    return PerimeterResult(perimeter=float(total[0]), pixel_edges=int(edges.sum()),
                           pixel_edge_length=float(edges[0] * dy + edges[1] * dx),
                           segments=int(round(total[1])), saddles=int(round(total[2])),
                           method=method)


def _perimeter_block(inside, values, halo, nloc, dx, dy, modulus, sweeps):
    """Marching squares on an extended block of rows; length of the owned cells' contour.

    ``inside`` is the contact set on the extended rows (bool, ``(nloc + 2 halo,
    ny)``), ``values`` the gap and pressure as :class:`_Extended` (None: midpoint
    crossings).  Rows ``halo .. halo + nloc - 1`` are owned; the block is open at
    its two ends (the halo is wide enough that this does not reach the owned
    cells) and periodic along y.  Only cells on the contour are ever stored.

    Returns ``(length, [segments, saddles])`` of the owned cells.
    """
    fields = values is not None
    M, ny = inside.shape

    # Crossed cell edges, identified by linear index row * ny + col (sorted).
    xcross = inside[:-1] != inside[1:]                     # x-edge (e, j): (e, j)-(e+1, j)
    ycross = inside != np.roll(inside, -1, axis=1)         # y-edge (e, j): (e, j)-(e, j+1)
    xe, xj = np.nonzero(xcross)
    ye, yj = np.nonzero(ycross)
    xlin, ylin = xe * ny + xj, ye * ny + yj

    # Boundary cells (e, j), e in 0..M-2: any of their four edges crossed.
    cell = xcross | np.roll(xcross, -1, axis=1) | ycross[:-1] | ycross[1:]
    ce, cj = np.nonzero(cell)
    cj1 = (cj + 1) % ny
    clin = ce * ny + cj
    nc = ce.size
    if nc == 0:
        return 0.0, np.zeros(2)

    def lookup(table, keys):
        """Position of each key in the sorted ``table``, or -1 if absent."""
        if table.size == 0:
            return np.full(np.shape(keys), -1)
        pos = np.minimum(np.searchsorted(table, keys), table.size - 1)
        return np.where(table[pos] == keys, pos, -1)

    # Edge slots: 0 = x-edge (e, j), 1 = y-edge (e+1, j), 2 = x-edge (e, j+1), 3 = y-edge (e, j)
    slot_edge = np.stack([lookup(xlin, ce * ny + cj), lookup(ylin, (ce + 1) * ny + cj),
                          lookup(xlin, ce * ny + cj1), lookup(ylin, ce * ny + cj)], axis=1)
    crossed = slot_edge >= 0
    corner0 = inside[ce, cj]                                # inside flag of pixel (e, j)
    corner1 = inside[ce + 1, cj]
    corner3 = inside[ce, cj1]
    lower_inside = np.stack([corner0, corner1, corner3, corner0], axis=1)  # slot's lower pixel
    ncross = crossed.sum(axis=1)
    saddle = ncross == 4

    # Which cells the crossing of each edge belongs to (for its tangent): x-edge
    # (e, j) is slot 0 of cell (e, j) and slot 2 of cell (e, j-1); y-edge (e, j)
    # is slot 3 of cell (e, j) and slot 1 of cell (e-1, j).
    x_cells = np.stack([lookup(clin, xlin), lookup(clin, xe * ny + (xj - 1) % ny)], axis=1)
    y_cells = np.stack([lookup(clin, ylin), lookup(clin, (ye - 1) * ny + yj)], axis=1)

    # Data of both pixels of every crossed edge.
    def edge_t(e, j, e2, j2, d, cos):
        """Fraction of the way from pixel (e, j) to (e2, j2) where the contour crosses."""
        first_in = inside[e, j]
        if not fields:
            return np.full(e.size, 0.5)
        ie, ij = np.where(first_in, e, e2), np.where(first_in, j, j2)
        oe, oj = np.where(first_in, e2, e), np.where(first_in, j2, j)
        gap, pressure = values
        t_in = crossing_fraction(pressure.take(ie, ij), gap.take(oe, oj), d, modulus, cos,
                                 p_out=pressure.take(oe, oj))
        return np.where(first_in, t_in, 1.0 - t_in)

    xcos, ycos = np.ones(xe.size), np.ones(ye.size)
    for sweep in range(sweeps + 1):
        tx = edge_t(xe, xj, xe + 1, xj, dx, xcos)
        ty = edge_t(ye, yj, ye, (yj + 1) % ny, dy, ycos)
        # Crossing points in cell coordinates, and the inside fraction of each edge.
        t = np.full((nc, 4), np.nan)
        for s, table in ((0, tx), (1, ty), (2, tx), (3, ty)):
            ok = crossed[:, s]
            t[ok, s] = table[slot_edge[ok, s]]
        px = np.stack([t[:, 0] * dx, np.full(nc, dx), t[:, 2] * dx, np.zeros(nc)], axis=1)
        py = np.stack([np.zeros(nc), t[:, 1] * dy, np.full(nc, dy), t[:, 3] * dy], axis=1)
        # Partner slot of each crossed slot (the other end of its segment).
        partner = np.full((nc, 4), -1)
        two = ncross == 2
        order = np.argsort(~crossed[two], axis=1, kind="stable")
        rows2 = np.nonzero(two)[0]
        partner[rows2, order[:, 0]] = order[:, 1]
        partner[rows2, order[:, 1]] = order[:, 0]
        if np.any(saddle):
            fin = np.where(lower_inside[saddle], t[saddle], 1.0 - t[saddle]).mean(axis=1)
            centre_inside = fin > 0.5
            # corner 0 inside and centre inside: the outside corners 1 and 3 are cut
            # off, segments (0,1) and (2,3); otherwise (0,3) and (1,2).
            cut13 = corner0[saddle] == centre_inside
            partner[saddle] = np.where(cut13[:, None], [1, 0, 3, 2], [3, 2, 1, 0])
        has = partner >= 0
        pidx = np.where(has, partner, 0)
        qx = np.take_along_axis(px, pidx, axis=1)
        qy = np.take_along_axis(py, pidx, axis=1)
        if sweep == sweeps:
            break
        xcos = _edge_cosines(x_cells, (0, 2), qx, qy, has, tx, dx, dy, along_x=True)
        ycos = _edge_cosines(y_cells, (3, 1), qx, qy, has, ty, dx, dy, along_x=False)

    owned = (ce >= halo) & (ce < halo + nloc)
    seg = np.where(has, np.hypot(px - qx, py - qy), 0.0)
    length = 0.5 * float(np.sum(seg[owned]))  # each segment seen from both ends
    nseg = 0.5 * float(np.count_nonzero(has[owned]))
    return length, np.array([nseg, float(np.count_nonzero(saddle & owned))])


def _edge_cosines(edge_cells, slots, qx, qy, has, t, dx, dy, along_x):
    """Cosine between each crossed edge and the contour normal at its crossing.

    The contour direction at a crossing is the chord between the partner points
    of the two cells sharing the edge (second-order accurate); at the open ends
    of the block only one cell may exist, and the one-sided chord is used.
    """
    a, b = edge_cells[:, 0], edge_cells[:, 1]
    sa, sb = slots
    n = a.size
    # point of the crossing itself, in the coordinates of cell a (and of cell b)
    # x-edge: slot 0 of cell a at (t dx, 0), slot 2 of cell b = a shifted by -dy;
    # y-edge: slot 3 of cell a at (0, t dy), slot 1 of cell b = a shifted by -dx.
    if along_x:
        xa, ya = t * dx, np.zeros(n)
        shift = (0.0, dy)     # cell b's origin is (0, -dy) from cell a's
    else:
        xa, ya = np.zeros(n), t * dy
        shift = (dx, 0.0)
    ok_a = (a >= 0)
    ok_b = (b >= 0)
    ok_a[ok_a] &= has[a[ok_a], sa]
    ok_b[ok_b] &= has[b[ok_b], sb]
    # partner points in cell a's coordinates
    pax = np.where(ok_a, qx[np.maximum(a, 0), sa], xa)
    pay = np.where(ok_a, qy[np.maximum(a, 0), sa], ya)
    pbx = np.where(ok_b, qx[np.maximum(b, 0), sb] - shift[0], xa)
    pby = np.where(ok_b, qy[np.maximum(b, 0), sb] - shift[1], ya)
    tx, ty = pax - pbx, pay - pby
    norm = np.hypot(tx, ty)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(ty if along_x else tx) / norm
    cos = np.where(norm > 0, cos, 1.0)
    return np.clip(cos, _MIN_COSINE, 1.0)


# ============================================================ contact statistics
@dataclass(frozen=True)
class ContactStatistics:
    """Contact area, perimeter and the paper's derived lengths (same on every rank).

    Attributes
    ----------
    contact_pixels : int
        Pixels in repulsive contact.
    contact_fraction : float
        ``c = A_rep / A0``.
    contact_area : float
        ``A_rep = dx dy * contact_pixels``.
    perimeter : float
        ``P_rep`` (:func:`perimeter`, asymptotic crossings).
    pixel_edges, pixel_edge_length : int, float
        The raw pixel-edge measure, for comparison (over-counts by ~4/pi).
    mean_diameter : float
        ``d_rep = pi A_rep / P_rep`` (Eq. 2); NaN without contact.
    g0 : float
        ``4 h0' d_rep / 3`` (Eq. 12).
    rms_slope, contact_modulus : float
        ``h0'`` and ``E*`` used.
    mean_pressure : float
        ``sum p dx dy / A0`` (all pixels: with adhesion this includes the tension).
    repulsive_force : float
        ``F_rep = sum over contact pixels of p dx dy``.
    kappa_rep : float
        ``A_rep h0' E* / F_rep`` (paper: ``A_rep = kappa_rep F_rep / (h0' E*)``).
        Equal to :class:`petgap.contact.ContactSolution`'s ``kappa_rep`` for
        non-adhesive solutions, where ``F_rep = P0 A0``.
    kappa : float
        ``A_rep h0' E* / (P0 A0)`` with the total mean pressure ``P0`` (Eq. 3's
        effective ``kappa``; NaN if ``P0 <= 0``).
    """

    contact_pixels: int
    contact_fraction: float
    contact_area: float
    perimeter: float
    pixel_edges: int
    pixel_edge_length: float
    mean_diameter: float
    g0: float
    rms_slope: float
    contact_modulus: float
    mean_pressure: float
    repulsive_force: float
    kappa_rep: float
    kappa: float

    def to_dict(self):
        """The attributes as a plain dict."""
        return asdict(self)


def contact_statistics(grid, gap, pressure, rms_slope, contact_modulus, *, gap_tolerance=None,
                       sweeps=PERIMETER_SWEEPS):
    """``c``, ``A_rep``, ``P_rep``, ``d_rep`` (Eq. 2) and ``g0`` (Eq. 12) of a solved state.

    Parameters
    ----------
    grid : petgap.grid.Grid
    gap, pressure : ndarray, shape ``grid.local_shape``
    rms_slope : float
        ``h0'`` of the topography (spectral, as :func:`petgap.surface.statistics`).
    contact_modulus : float
        ``E*``.
    gap_tolerance : float, optional
        Zero-gap tolerance (default: :func:`resolve_gap_tolerance`).
    sweeps : int
        See :func:`perimeter`.

    Returns
    -------
    ContactStatistics
    """
    rms_slope = _positive("rms_slope", rms_slope)
    contact_modulus = _positive("contact_modulus", contact_modulus)
    checked = _check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    mask = contact_mask(gap, pressure, resolve_gap_tolerance(grid, gap, gap_tolerance))
    per = perimeter(grid, gap, pressure, contact_modulus, mask=mask, sweeps=sweeps)
    local = [np.count_nonzero(mask), float(np.sum(pressure[mask])), float(np.sum(pressure))]
    total = _allreduce_sum(grid.comm, local)
    nx, ny = _global_shape(grid)
    dx, dy = _pixel(grid)
    npix = int(round(total[0]))
    area = npix * dx * dy
    a0 = nx * ny * dx * dy
    f_rep = total[1] * dx * dy
    p_mean = total[2] * dx * dy / a0
    d_rep = math.pi * area / per.perimeter if per.perimeter > 0 else math.nan
    scale = area * rms_slope * contact_modulus
    return ContactStatistics(
        contact_pixels=npix, contact_fraction=npix / (nx * ny), contact_area=area,
        perimeter=per.perimeter, pixel_edges=per.pixel_edges,
        pixel_edge_length=per.pixel_edge_length, mean_diameter=d_rep,
        g0=4.0 * rms_slope * d_rep / 3.0, rms_slope=rms_slope, contact_modulus=contact_modulus,
        mean_pressure=p_mean, repulsive_force=f_rep,
        kappa_rep=scale / f_rep if f_rep > 0 else math.nan,
        kappa=scale / (p_mean * a0) if p_mean > 0 else math.nan)


# ============================================================ gap distribution
@dataclass(frozen=True)
class GapDistribution:
    """Histogram of the gaps of non-contacting pixels on logarithmic bins.

    Attributes
    ----------
    edges : ndarray
        Bin edges (``nbins + 1``, increasing, positive).
    centres : ndarray
        Geometric bin centres ``sqrt(edges[k] edges[k+1])``.
    counts : ndarray of int
        Global pixel counts per bin.
    density : ndarray
        ``counts / (N_nc * width)``: per unit gap, normalised by the number
        ``N_nc = N (1 - c)`` of non-contacting pixels.  The full distribution of
        the paper (Eq. 9, normalised to 1 over all pixels) is ``(1 - c) density``.
    npoints : int
        ``N = nx ny``.
    contact_fraction : float
        ``c``.
    zero_gap_fraction : float
        Fraction of ``A0`` at zero gap (``g <= gap_tolerance``) but not in
        repulsive contact: zero gap under tension in adhesive solutions, or
        edge pixels at ``p = 0`` whose gap is at round-off level.  They cannot
        go on a log axis and are not in the histogram; they are, however, part
        of ``N_nc``.
    below_fraction, above_fraction : float
        Fractions of ``A0`` with ``0 < g < edges[0]`` and ``g > edges[-1]``.
    integral : float
        ``sum(density * width) = 1 - (zero + below + above) / (1 - c)``: 1 for
        a non-adhesive state with the default range.
    """

    edges: np.ndarray
    centres: np.ndarray
    counts: np.ndarray
    density: np.ndarray
    npoints: int
    contact_fraction: float
    zero_gap_fraction: float
    below_fraction: float
    above_fraction: float
    integral: float

    @property
    def widths(self):
        """Bin widths."""
        return np.diff(self.edges)


#: Default number of logarithmic bins per decade of gap.
BINS_PER_DECADE = 10

#: Default lower end of the bins relative to the largest gap (gaps below this are
#: round-off of the bound, not resolved physics; they are counted in ``below_fraction``).
DEFAULT_RANGE = 1e-10


def gap_distribution(grid, gap, pressure, bins=None, gmin=None, gmax=None, *,
                     bins_per_decade=BINS_PER_DECADE, gap_tolerance=None):
    """The distribution ``p(g)`` of the non-contacting pixels on logarithmic bins (Fig. 2).

    Collective: each rank histograms its slab on the same bins and the counts
    are summed (integers, so the result does not depend on the decomposition).

    Parameters
    ----------
    grid : petgap.grid.Grid
    gap, pressure : ndarray, shape ``grid.local_shape``
    bins : int or array_like, optional
        Number of logarithmic bins between ``gmin`` and ``gmax``, or the bin
        edges themselves (positive, increasing; ``gmin``/``gmax`` then unused).
        Default: ``bins_per_decade`` per decade, at least one bin.
    gmin, gmax : float, optional
        Range of the bins.  Default: the smallest positive gap of a
        non-contacting pixel (but not below ``1e-10`` times the largest gap)
        and the largest gap.
    bins_per_decade : int
    gap_tolerance : float, optional
        Gaps ``<= gap_tolerance`` count as zero: in contact if ``p > 0``
        (:func:`contact_mask`), in ``zero_gap_fraction`` otherwise.  Default:
        :func:`resolve_gap_tolerance` (``1e-6`` of the mean gap).  With 0,
        contact pixels whose gap is solver round-off (``~1e-9 h0``) show up as
        a spike at the left end of the histogram.

    Returns
    -------
    GapDistribution
        Empty arrays if no pixel has a positive gap.
    """
    checked = _check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    comm = grid.comm
    gap_tolerance = resolve_gap_tolerance(grid, gap, gap_tolerance)
    contact = contact_mask(gap, pressure, gap_tolerance)
    positive = ~contact & (gap > gap_tolerance)
    g = gap[positive]
    counts0 = _allreduce_sum(comm, [np.count_nonzero(contact), g.size], dtype=np.int64)
    nx, ny = _global_shape(grid)
    n = nx * ny
    n_contact, n_pos = int(counts0[0]), int(counts0[1])
    n_nc = n - n_contact
    n_zero = n_nc - n_pos
    lo = comm.allreduce(float(g.min()) if g.size else math.inf, op=MPI.MIN)
    hi = comm.allreduce(float(g.max()) if g.size else -math.inf, op=MPI.MAX)

    edges = _log_edges(bins, gmin, gmax, lo, hi, bins_per_decade)
    if edges is None:
        empty = np.empty(0)
        return GapDistribution(edges=empty, centres=empty, counts=np.empty(0, dtype=np.int64),
                               density=empty, npoints=n, contact_fraction=n_contact / n,
                               zero_gap_fraction=n_zero / n, below_fraction=0.0,
                               above_fraction=0.0, integral=0.0)
    local_counts, _ = np.histogram(g, bins=edges)
    local = np.concatenate([local_counts, [np.count_nonzero(g < edges[0]),
                                           np.count_nonzero(g > edges[-1])]])
    total = _allreduce_sum(comm, local, dtype=np.int64)
    counts, below, above = total[:-2], int(total[-2]), int(total[-1])
    widths = np.diff(edges)
    density = counts / (n_nc * widths) if n_nc > 0 else np.full(widths.shape, np.nan)
    return GapDistribution(edges=edges, centres=np.sqrt(edges[:-1] * edges[1:]), counts=counts,
                           density=density, npoints=n, contact_fraction=n_contact / n,
                           zero_gap_fraction=n_zero / n, below_fraction=below / n,
                           above_fraction=above / n,
                           integral=float(np.sum(density * widths)) if n_nc > 0 else math.nan)


def _log_edges(bins, gmin, gmax, lo, hi, bins_per_decade):
    """Logarithmic bin edges, identical on every rank (from global extremes)."""
    if bins is not None and np.ndim(bins) == 1:
        edges = np.asarray(bins, dtype=float)
        if edges.size < 2 or not np.all(edges > 0) or not np.all(np.diff(edges) > 0) \
                or not np.all(np.isfinite(edges)):
            raise ValueError("bin edges must be at least two positive, finite, increasing numbers")
        return edges
    if not math.isfinite(lo):  # no positive gap anywhere
        if gmin is None or gmax is None:
            return None
    gmax = hi if gmax is None else _positive("gmax", gmax)
    gmin = max(lo, DEFAULT_RANGE * gmax) if gmin is None else _positive("gmin", gmin)
    if not gmin < gmax:
        if gmin == gmax:  # one distinct gap value: a bin around it
            gmin, gmax = gmin / 1.01, gmax * 1.01
        else:
            raise ValueError(f"gmin = {gmin!r} is not below gmax = {gmax!r}")
    if bins is None:
        if isinstance(bins_per_decade, bool) or not isinstance(bins_per_decade, numbers.Integral) \
                or bins_per_decade < 1:
            raise ValueError(f"bins_per_decade = {bins_per_decade!r}: need a positive integer")
        bins = max(1, int(math.ceil(bins_per_decade * math.log10(gmax / gmin) - 1e-9)))
    elif isinstance(bins, bool) or not isinstance(bins, numbers.Integral) or bins < 1:
        raise ValueError(f"bins = {bins!r} is not allowed: need a positive integer or edges")
    edges = np.geomspace(gmin, gmax, int(bins) + 1)
    edges[0], edges[-1] = gmin, gmax  # exact ends: the extremes themselves are inside
    return edges


def collapse(density, centres, c, g0):
    """The data collapse of Fig. 2: ``x = g / g0`` and ``y`` with Eq. 13 as ``y = x^(-1/3)``.

    Eq. 13 is the near-edge part of the distribution normalised over *all*
    pixels, ``p_n(g) = (2 pi c / (3 g0)) (g0 / g)^(1/3)``.  The paper plots the
    distribution "normalised to the non-contacting fractional area 1 - c", i.e.
    with integral ``1 - c`` over ``g > 0`` -- that is ``p(g) = (1 - c) density``
    with ``density`` as returned by :func:`gap_distribution` (integral 1) --
    "divided by the prefactor of Eq. 13"::

        y = (1 - c) density / (2 pi c / (3 g0)) = 3 g0 (1 - c) density / (2 pi c),

    so that Eq. 13 reads ``y = x^(-1/3)``.  (Dividing ``density`` itself by the
    prefactor would shift the curve up by ``1 / (1 - c)``, 4 % at ``c = 0.04``.)

    Parameters
    ----------
    density : array_like or GapDistribution
        Density normalised over the non-contacting pixels (a
        :class:`GapDistribution` supplies ``centres`` too).
    centres : array_like or None
        Bin centres (gaps).
    c : float
        Contact fraction ``c``.
    g0 : float
        ``4 h0' d_rep / 3`` (Eq. 12).

    Returns
    -------
    x, y : ndarray
    """
    if isinstance(density, GapDistribution):
        density, centres = density.density, density.centres
    c = float(c)
    g0 = _positive("g0", g0)
    if not 0 < c < 1:
        raise ValueError(f"c = {c!r}: the collapse needs a contact fraction 0 < c < 1")
    density = np.asarray(density, dtype=float)
    x = np.asarray(centres, dtype=float) / g0
    return x, 3.0 * g0 * (1.0 - c) * density / (2.0 * math.pi * c)


@dataclass(frozen=True)
class PowerLawFit:
    """Where ``y ~ x^exponent`` holds and the exponent fitted there.

    Attributes
    ----------
    exponent : float
        Least-squares slope of ``log y`` against ``log x`` over the window
        (NaN if no window of ``min_points`` points qualifies).
    prefactor : float
        ``exp(intercept)`` of that fit.
    x_min, x_max : float
        First and last ``x`` of the window (NaN if none).
    decades : float
        ``log10(x_max / x_min)``.
    npoints : int
        Points in the window.
    start, stop : int
        Index range of the window in the input arrays (``stop`` exclusive).
    """

    exponent: float
    prefactor: float
    x_min: float
    x_max: float
    decades: float
    npoints: int
    start: int
    stop: int


def fit_power_law(x, y, *, expected=-1.0 / 3.0, amplitude=1.0, slope_tolerance=0.1,
                  factor=2.0, window=None, min_points=3, x_range=None):
    """Fitted exponent and the range of ``x`` over which ``y = amplitude x^expected`` holds.

    Definition of the range (for the collapsed Fig. 2 data, ``expected = -1/3``,
    ``amplitude = 1``): a point ``k`` *conforms* if

    * its local log-slope -- the least-squares slope of ``log y`` on ``log x``
      over the ``window`` points centred on it (fewer at the ends of a run of
      valid points) -- is within ``slope_tolerance`` of ``expected``, and
    * ``y_k`` is within a factor ``factor`` of the prediction ``amplitude x_k^expected``.

    The range is the longest run of consecutive conforming points (points with
    ``y <= 0`` or non-finite values break runs; ties go to the run spanning more
    decades, then the first).  The exponent is then fitted over that run.  The
    fit is not independent of the window choice (its points have slopes near
    ``expected`` by construction): for an unbiased exponent over a fixed range,
    pass ``x_range=(lo, hi)``, which fits all valid points with ``lo <= x <= hi``
    and reports that range instead.

    Parameters
    ----------
    x, y : array_like
    expected, amplitude : float
        The law tested.
    slope_tolerance : float
        Allowed deviation of the local slope.
    factor : float
        Allowed ratio to the prediction (``> 1``).
    window : int, optional
        Points in the local-slope fit (``>= 2``).  Default: the points of about
        one decade of ``x`` (11 for 10 bins per decade).  Narrower windows turn
        the Poisson noise of sparsely filled bins into slope noise larger than
        any sensible tolerance (at 5 points, +-15 % scatter gives +-0.2).
    min_points : int
        Shortest acceptable run.
    x_range : (float, float), optional
        Fit over this range instead of searching a window.

    Returns
    -------
    PowerLawFit
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y must be 1D arrays of one length, got {x.shape} and {y.shape}")
    valid = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx = np.where(valid, np.log(np.where(valid, x, 1.0)), np.nan)
    ly = np.where(valid, np.log(np.where(valid, y, 1.0)), np.nan)
    nothing = PowerLawFit(math.nan, math.nan, math.nan, math.nan, math.nan, 0, 0, 0)

    if x_range is not None:
        lo, hi = (float(v) for v in x_range)
        sel = np.nonzero(valid & (x >= lo) & (x <= hi))[0]
        if sel.size < 2:
            return nothing
        slope, icept = np.polyfit(lx[sel], ly[sel], 1)
        return PowerLawFit(float(slope), float(np.exp(icept)), lo, hi, math.log10(hi / lo),
                           int(sel.size), int(sel[0]), int(sel[-1]) + 1)

    if window is None:
        steps = np.diff(lx[valid]) / math.log(10.0)
        steps = steps[steps > 0]
        per_decade = 1.0 / float(np.median(steps)) if steps.size else 1.0
        window = 2 * int(round(per_decade / 2.0)) + 1
    half = max(1, int(window) // 2)
    n = x.size
    # runs of consecutive valid points
    slopes = np.full(n, np.nan)
    for k in np.nonzero(valid)[0]:
        a, b = k, k
        while a > 0 and valid[a - 1] and k - a < half:
            a -= 1
        while b < n - 1 and valid[b + 1] and b - k < half:
            b += 1
        if b - a >= 1:
            slopes[k] = np.polyfit(lx[a:b + 1], ly[a:b + 1], 1)[0]
    with np.errstate(invalid="ignore"):
        near = np.abs(ly - (math.log(amplitude) + expected * lx)) <= math.log(factor)
        good = valid & near & (np.abs(slopes - expected) <= slope_tolerance)
    best = None
    k = 0
    while k < n:
        if not good[k]:
            k += 1
            continue
        m = k
        while m + 1 < n and good[m + 1]:
            m += 1
        key = (m - k + 1, lx[m] - lx[k])
        if best is None or key > best[0]:
            best = (key, k, m + 1)
        k = m + 1
    if best is None or best[0][0] < max(2, min_points):
        return nothing
    _, a, b = best
    slope, icept = np.polyfit(lx[a:b], ly[a:b], 1)
    return PowerLawFit(float(slope), float(np.exp(icept)), float(x[a]), float(x[b - 1]),
                       float(math.log10(x[b - 1] / x[a])), int(b - a), int(a), int(b))


# ============================================================ fit range (Eq. 13)
#: Defaults of :func:`auto_fit_range`, the data-driven range of petgap-post's exponent fit.
#: Lower bound: this many times the smallest resolved gap (:func:`resolved_gap`).  In the
#: runs of ``docs/fig2.md`` the local slope of ``p(g)`` settles only at 2-3 times it.
FIT_RESOLUTION_FACTOR = 3.0
#: Upper bound in ``x = g / g0``: Eq. 13 is a small-gap law; above ``~0.1 g0`` the
#: far-from-contact (Gaussian) part of ``p(g)`` takes over (paper, section 5).
FIT_X_MAX = 0.1
#: Largest deviation of a local log-log slope from the range's median slope (beyond noise).
FIT_SLOPE_BAND = 0.05
#: Local slopes are fitted over the bins within this many decades either side.
FIT_SLOPE_WINDOW = 0.25
#: Narrowest range searched, in decades of ``x`` (unless the bounds leave less).
FIT_MIN_DECADES = 0.5
#: Bins with fewer pixels (Poisson noise above 30 %) are not used.
FIT_MIN_COUNT = 10
#: Statistical allowance: a local slope may deviate by this many of its standard errors
#: (from the bins' Poisson counts) beyond ``FIT_SLOPE_BAND``.
FIT_SIGMAS = 2.0


def resolved_gap(mean_diameter, pixel):
    """The smallest gap the grid resolves next to a contact edge, in units of ``g0``.

    By Eq. 12 the gap at lateral distance ``s`` from an edge is
    ``g0 (s / d_rep)^(3/2)``; the first pixel outside an edge lies on average half a
    pixel from it, so gaps below ``x_res = (pixel / (2 d_rep))^(3/2)`` (in ``g / g0``)
    are not resolved: there ``p(g)`` levels off instead of following Eq. 13 (the
    paper's roll-off, "inversely proportional to the resolution").

    Parameters
    ----------
    mean_diameter : float
        ``d_rep`` (Eq. 2).
    pixel : float
        Pixel size (the larger of ``dx``, ``dy`` for non-square pixels).
    """
    return (_positive("pixel", pixel) / (2.0 * _positive("mean_diameter", mean_diameter))) ** 1.5


@dataclass(frozen=True)
class FitRange:
    """The range of ``x = g / g0`` chosen by :func:`auto_fit_range`.

    Attributes
    ----------
    x_min, x_max : float
        First and last bin centre of the range (NaN if none was found).
    bound_min, bound_max : float
        The bounds searched: ``resolution_factor x_res`` and ``x_max``.
    slope_deviation : float
        Largest deviation of a local log-log slope in the range from their median.
    slope_error : float
        Largest standard error of those local slopes, from the bins' Poisson
        counts (0 without counts).
    npoints : int
        Bins in the range.
    start, stop : int
        Index range of the bins in the input arrays (``stop`` exclusive).
    qualified : bool
        Whether the range meets the criterion of :func:`auto_fit_range` (False: the
        flattest range of the minimum width was taken instead, or there was none).
    reason : str
        How the range was chosen, or why there is none.
    """

    x_min: float
    x_max: float
    bound_min: float
    bound_max: float
    slope_deviation: float
    slope_error: float
    npoints: int
    start: int
    stop: int
    qualified: bool
    reason: str


def _local_slopes(t, v, weights, half_width):
    """Least-squares slope of ``v`` on ``t`` over the points within ``half_width`` of each
    point, and its standard error (weights: inverse variances of ``v``; None: no error)."""
    n = t.size
    slopes, errors = np.full(n, np.nan), np.zeros(n)
    for k in range(n):
        sel = np.abs(t - t[k]) <= half_width * (1 + 1e-9)
        if np.count_nonzero(sel) < 2:
            continue
        w = np.ones(np.count_nonzero(sel)) if weights is None else weights[sel]
        tt, vv = t[sel], v[sel]
        tm = np.sum(w * tt) / np.sum(w)
        sxx = np.sum(w * (tt - tm) ** 2)
        slopes[k] = np.sum(w * (tt - tm) * vv) / sxx
        errors[k] = 0.0 if weights is None else 1.0 / math.sqrt(sxx)
    return slopes, errors


def auto_fit_range(x, y, counts=None, *, x_resolution, resolution_factor=FIT_RESOLUTION_FACTOR,
                   x_max=FIT_X_MAX, slope_band=FIT_SLOPE_BAND, slope_window=FIT_SLOPE_WINDOW,
                   min_decades=FIT_MIN_DECADES, min_count=FIT_MIN_COUNT, sigmas=FIT_SIGMAS):
    """The range of ``x`` where the local slope of ``log y`` against ``log x`` is constant.

    The default range of petgap-post's exponent fit (Eq. 13).  No exponent is
    assumed (unlike :func:`fit_power_law`'s own window, which looks for ``-1/3``),
    so a fit over this range tests the exponent rather than confirming it.

    Rule
    ----
    1. *Bounds*: ``resolution_factor * x_resolution <= x <= x_max``.  Below a few
       times the smallest resolved gap (:func:`resolved_gap`) ``p(g)`` rolls off
       to a constant; above ``~0.1 g0`` the far-from-contact part of ``p(g)``
       takes over.  Only bins with positive ``y`` and, when ``counts`` are given,
       at least ``min_count`` pixels are used: the longest run (in decades) of
       consecutive such bins inside the bounds.
    2. *Local slopes*: at each bin of the run, the least-squares slope of
       ``log y`` on ``log x`` over the bins of the run within ``slope_window``
       decades either side, weighted by the counts (the Poisson variance of
       ``log y`` is ``1 / count``), with its standard error ``sigma_k``.
    3. *Choice*: a window of consecutive bins *qualifies* if the median of its
       local slopes is negative -- ``p(g)`` falls with ``g`` near contact edges,
       while the far-from-contact part rises towards its Gaussian peak -- and
       every local slope in it lies within ``slope_band + sigmas * sigma_k`` of
       that median: the slope is constant to ``+-slope_band`` beyond noise.  Of
       the qualifying windows spanning at least ``min_decades`` (or the whole
       run, if it is shorter) the widest is taken (ties: the smaller largest
       deviation).  If none qualifies, the flattest of the narrowest windows
       with a negative median slope is taken, with ``qualified = False``.

    On exact data the range ends about two bins inside a sharp change of slope
    (the local slopes there mix both sides); with noisy data the allowance
    ``sigmas * sigma_k`` lets it reach further where the change is within the
    noise.

    Parameters
    ----------
    x, y : array_like
        Collapsed data (:func:`collapse`): ``x = g / g0`` ascending.
    counts : array_like, optional
        Pixels per bin (``GapDistribution.counts``); without them every bin
        counts equally and no noise allowance is made.
    x_resolution : float
        Smallest resolved gap over ``g0`` (:func:`resolved_gap`).
    resolution_factor, x_max, slope_band, slope_window, min_decades, min_count, sigmas
        See the rule; defaults: the ``FIT_*`` constants of this module.

    Returns
    -------
    FitRange
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y must be 1D arrays of one length, got {x.shape} and {y.shape}")
    if counts is not None:
        counts = np.asarray(counts, dtype=float)
        if counts.shape != x.shape:
            raise ValueError(f"counts has shape {counts.shape}, x {x.shape}")
    bound_min = float(resolution_factor) * _positive("x_resolution", x_resolution)
    bound_max = _positive("x_max", x_max)

    def nothing(reason):
        return FitRange(math.nan, math.nan, bound_min, bound_max, math.nan, math.nan, 0, 0, 0,
                        False, reason)

    if not bound_min < bound_max:
        return nothing(f"no range: the resolution bound {bound_min:.3g} g0 "
                       f"({resolution_factor:g} x the smallest resolved gap) is not below "
                       f"{bound_max:g} g0")
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        if counts is not None:
            ok &= counts >= min_count
        ok &= (x >= bound_min) & (x <= bound_max)
    # the longest run (in decades) of consecutive usable bins inside the bounds
    run = None
    k, n = 0, x.size
    while k < n:
        if not ok[k]:
            k += 1
            continue
        m = k
        while m + 1 < n and ok[m + 1]:
            m += 1
        key = (math.log10(x[m] / x[k]), m - k)
        if run is None or key > run[0]:
            run = (key, k, m + 1)
        k = m + 1
    if run is None or run[2] - run[1] < 3:
        return nothing(f"no range: fewer than 3 bins with at least {min_count} pixels between "
                       f"{bound_min:.3g} and {bound_max:g} g0")
    _, r0, r1 = run
    decades = np.log10(x[r0:r1])
    weights = None if counts is None else counts[r0:r1]
    t = np.log(x[r0:r1])
    # at least the neighbouring bins, however coarse the bins
    half = max(float(slope_window) * math.log(10.0), float(np.max(np.diff(t))) * (1 + 1e-6))
    slopes, errors = _local_slopes(t, np.log(y[r0:r1]), weights, half)
    m = r1 - r0
    need = min(float(min_decades), decades[-1] - decades[0]) - 1e-9
    allowed = slope_band + sigmas * errors
    qualified, fallback = None, None
    for a in range(m - 2):
        for b in range(a + 3, m + 1):        # window a .. b - 1 of the run, at least 3 bins
            span = decades[b - 1] - decades[a]
            if span < need:
                continue
            s, e = slopes[a:b], allowed[a:b]
            middle = float(np.median(s))
            deviation = np.abs(s - middle)
            worst = float(np.max(deviation))
            if not middle < 0:                # p(g) rising with g: the far-from-contact part
                continue
            if np.all(deviation <= e):
                key = (span, -worst)
                if qualified is None or key > qualified[0]:
                    qualified = (key, a, b, worst)
            key = (-(b - a), -float(np.max(deviation - (e - slope_band))))
            if fallback is None or key > fallback[0]:
                fallback = (key, a, b, worst)
    if qualified is not None:
        _, a, b, worst = qualified
        reason = (f"widest range in {bound_min:.3g} .. {bound_max:g} g0 whose local slope stays "
                  f"within {slope_band:g} (+ {sigmas:g} sigma) of its median")
    elif fallback is None:
        return nothing(f"no range: p(g) does not decrease with g anywhere in {bound_min:.3g} .. "
                       f"{bound_max:g} g0")
    else:
        _, a, b, worst = fallback
        reason = (f"no range in {bound_min:.3g} .. {bound_max:g} g0 has a local slope constant "
                  f"to {slope_band:g}: the flattest {decades[b - 1] - decades[a]:.2g} decades")
    return FitRange(float(x[r0 + a]), float(x[r0 + b - 1]), bound_min, bound_max, worst,
                    float(np.max(errors[a:b])), b - a, r0 + a, r0 + b,
                    qualified is not None, reason)


# ========================================================= near-contact area
@dataclass(frozen=True)
class NearContactArea:
    """``c_n(g_c)``: the fraction of ``A0`` with ``0 < g < g_c``, measured and from Eq. 14.

    Attributes
    ----------
    gc : ndarray
        Cut-off gaps.
    measured : ndarray
        Fraction of all pixels that are not in repulsive contact and have
        ``gap_tolerance < g < g_c``.
    predicted : ndarray
        Eq. 14: ``pi c (g_c / g0)^(2/3)`` (NaN if ``g0`` is not given).
    ratio : ndarray
        ``measured / predicted``.
    contact_fraction : float
        ``c`` used in the prediction.
    """

    gc: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    ratio: np.ndarray
    contact_fraction: float


def near_contact_area_eq14(gc, c, g0):
    """Eq. 14: ``c_n(g_c) = pi c (g_c / g0)^(2/3)`` (so ``c_n = pi c`` at ``g_c = g0`` and
    ``c_n = c`` at ``g_c = pi^(-3/2) g0 ~ 0.18 g0``)."""
    return math.pi * float(c) * (np.asarray(gc, dtype=float) / float(g0)) ** (2.0 / 3.0)


def near_contact_area(grid, gap, pressure, gc, c=None, g0=None, *, gap_tolerance=None):
    """Measured near-contact area ``c_n(g_c)`` against Eq. 14.

    Parameters
    ----------
    grid : petgap.grid.Grid
    gap, pressure : ndarray, shape ``grid.local_shape``
    gc : float or array_like
        Cut-off gaps ``g_c``.
    c : float, optional
        Contact fraction for the prediction (default: measured here).
    g0 : float, optional
        ``4 h0' d_rep / 3``; without it no prediction is made.
    gap_tolerance : float, optional
        Zero-gap tolerance (default: :func:`resolve_gap_tolerance`).

    Returns
    -------
    NearContactArea
        Collective; identical on every rank (integer counts are reduced).
    """
    checked = _check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    gc = np.atleast_1d(np.asarray(gc, dtype=float))
    gap_tolerance = resolve_gap_tolerance(grid, gap, gap_tolerance)
    contact = contact_mask(gap, pressure, gap_tolerance)
    g = np.sort(gap[~contact & (gap > gap_tolerance)])
    local = np.concatenate([[np.count_nonzero(contact)], np.searchsorted(g, gc, side="left")])
    total = _allreduce_sum(grid.comm, local, dtype=np.int64)
    nx, ny = _global_shape(grid)
    n = nx * ny
    c = total[0] / n if c is None else float(c)
    measured = total[1:] / n
    predicted = near_contact_area_eq14(gc, c, g0) if g0 is not None else np.full(gc.shape, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = measured / predicted
    return NearContactArea(gc=gc, measured=measured, predicted=predicted, ratio=ratio,
                           contact_fraction=c)


# ===================================================================== adhesion
@dataclass(frozen=True)
class AttractiveForce:
    """The attractive force of a solved adhesive state (negative: attraction).

    Attributes
    ----------
    force : float
        ``F_att = -sum over all pixels of dx dy v'(g)`` (Eq. 15).
    per_area : float
        ``F_att / A0``.
    contact_force : float
        The part from pixels in repulsive contact (``c A0 v'(0)``-like; NaN
        without the pressure field).
    noncontact_force : float
        The part from the other pixels: what Eq. 16 models with ``p_n``
        (NaN without the pressure field).
    """

    force: float
    per_area: float
    contact_force: float
    noncontact_force: float


def attractive_force_measured(grid, gap, v_prime, pressure=None, *, gap_tolerance=None):
    """``F_att`` as the pixel sum of the interaction stress (Eq. 15), sign: attraction < 0.

    Eq. 15, ``F_att / A0 = int dg p(g) dv/dg``, with the measured distribution
    ``p(g) = (1 / N) sum_x delta(g - g(x))`` (all pixels, the contact's
    ``c delta(g)`` included) is exactly the pixel sum; no histogram is needed.
    The paper writes ``dv/dg`` (positive for ``v = -w exp(-g / rho)``) yet calls
    ``F_att < 0``; here the sign is explicit: ``F_att = -sum dx dy v'(g)``.

    Parameters
    ----------
    grid : petgap.grid.Grid
    gap : ndarray, shape ``grid.local_shape``
    v_prime : callable or object with ``derivative``
        ``v'(g)`` (e.g. :class:`petgap.interaction.ExponentialAdhesion`), the
        tensile interaction stress.
    pressure : ndarray, optional
        With it the force is also split into contact and non-contact parts.
    gap_tolerance : float, optional
        Zero-gap tolerance (default: :func:`resolve_gap_tolerance`).

    Returns
    -------
    AttractiveForce
    """
    derivative = getattr(v_prime, "derivative", v_prime)
    if not callable(derivative):
        raise ValueError("v_prime must be a function of the gap or have a derivative method")
    checked = _check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    stress = np.asarray(derivative(gap), dtype=float)
    if pressure is not None:
        contact = contact_mask(gap, pressure, resolve_gap_tolerance(grid, gap, gap_tolerance))
        local = [float(np.sum(stress)), float(np.sum(stress[contact]))]
    else:
        local = [float(np.sum(stress)), math.nan]
    total = _allreduce_sum(grid.comm, local)
    dx, dy = _pixel(grid)
    nx, ny = _global_shape(grid)
    force = -dx * dy * total[0]
    contact_force = -dx * dy * total[1]
    return AttractiveForce(force=force, per_area=force / (nx * ny * dx * dy),
                           contact_force=contact_force,
                           noncontact_force=force - contact_force)


@dataclass(frozen=True)
class Eq16Force:
    """Eq. 16's prediction of ``F_att`` for ``v = -w exp(-g / rho)`` (negative).

    Attributes
    ----------
    printed : float
        As printed in the paper: ``-(2 pi / 3) w A_rep / (g0^2 rho)^(1/3)``.
    exact : float
        The integral of Eq. 16 evaluated exactly::

            (2 pi / 3) int_0^inf (dg / g0) (g0 / g)^(1/3) (w / rho) exp(-g / rho)
              = (2 pi / 3) (w / rho) g0^(-2/3) rho^(2/3) Gamma(2/3)
              = (2 pi / 3) Gamma(2/3) w / (g0^2 rho)^(1/3),

        i.e. ``Gamma(2/3) = 1.3541...`` times the printed result, which drops
        that factor.  (Tested against numerical quadrature.)
    ratio : float
        ``exact / printed = Gamma(2/3)``.
    """

    printed: float
    exact: float
    ratio: float


def attractive_force_eq16(w, rho, g0, contact_area):
    """``F_att`` from Eq. 16, as printed and exactly (see :class:`Eq16Force`).

    Parameters
    ----------
    w : float
        Work of adhesion (``v(g) = -w exp(-g / rho)``, Eq. 6).
    rho : float
        Interaction range.
    g0 : float
        ``4 h0' d_rep / 3``.
    contact_area : float
        ``A_rep``.
    """
    w, rho, g0 = _positive("w", w), _positive("rho", rho), _positive("g0", g0)
    contact_area = float(contact_area)
    printed = -(2.0 * math.pi / 3.0) * w * contact_area / (g0 * g0 * rho) ** (1.0 / 3.0)
    return Eq16Force(printed=printed, exact=GAMMA_2_3 * printed, ratio=GAMMA_2_3)


def inverse_kappa_att(force, rms_slope, contact_modulus, contact_area):
    """``1 / kappa_att = -F_att / (h0' E* A_rep)``: positive for attraction (Fig. 3).

    The paper's text writes ``F_att / (h0' E* A_rep)``, which with its own
    ``F_att < 0`` would be negative; Fig. 3 labels ``1 / kappa_att > 0`` and
    Eq. 3 needs ``1 / kappa = 1 / kappa_rep - 1 / kappa_att`` to *increase*
    ``kappa`` with adhesion, hence the minus sign.
    """
    if not contact_area > 0:
        return math.nan
    return -float(force) / (_positive("rms_slope", rms_slope)
                            * _positive("contact_modulus", contact_modulus) * contact_area)


def fig4_integrand(x, rho_over_g0, per_log=True):
    """Normalised integrand of Eq. 16 against ``x = g / g0`` (Fig. 4).

    In ``x``, Eq. 16 is ``F_att / A_rep = -(2 pi / 3) (w / rho) int dx x^(-1/3) exp(-x / r)``
    with ``r = rho / g0``.  Normalised to unit integral over ``x`` (the exact
    value ``r^(2/3) Gamma(2/3)``) the integrand is::

        f(x; r) = x^(-1/3) exp(-x / r) / (r^(2/3) Gamma(2/3)).

    On the log axis of the figure the contribution per unit ``ln x`` is what
    shows where the force comes from: ``x f(x; r)``, peaked at ``x = 2 r / 3``
    (so for ``rho <= 0.1 g0`` the force comes from ``g / g0 < 0.1``, where the
    power law holds -- the paper's conclusion).

    Parameters
    ----------
    x : array_like
        ``g / g0 > 0``.
    rho_over_g0 : float or array_like
        One or more ``r = rho / g0``.
    per_log : bool
        Return ``x f`` (default; integrates to 1 over ``ln x``) or ``f``.

    Returns
    -------
    ndarray, shape ``(len(rho_over_g0), len(x))`` (or ``x``'s shape for a scalar ``r``)
    """
    x = np.asarray(x, dtype=float)
    r = np.asarray(rho_over_g0, dtype=float)
    if np.any(r <= 0) or np.any(x <= 0):
        raise ValueError("fig4_integrand needs x = g / g0 > 0 and rho / g0 > 0")
    rr = r[..., None] if r.ndim else r
    f = x ** (-1.0 / 3.0) * np.exp(-x / rr) / (rr ** (2.0 / 3.0) * GAMMA_2_3)
    return x * f if per_log else f
