"""Gap distributions, their collapse onto Eq. 13, power-law fits and the near-contact area (Eq. 14).

Conventions: :mod:`petgap.analysis`.
"""
import math
import numbers
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from petgap.parallel.collective import global_sums
from petgap.analysis._slabs import check_fields, global_shape, positive
from petgap.analysis.contact_geometry import contact_mask, resolve_gap_tolerance


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
    grid : petgap.parallel.grid.Grid
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
    checked = check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    comm = grid.comm
    gap_tolerance = resolve_gap_tolerance(grid, gap, gap_tolerance)
    contact = contact_mask(gap, pressure, gap_tolerance)
    positive = ~contact & (gap > gap_tolerance)
    g = gap[positive]
    counts0 = global_sums(comm, [np.count_nonzero(contact), g.size], dtype=np.int64)
    nx, ny = global_shape(grid)
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
    total = global_sums(comm, local, dtype=np.int64)
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
    gmax = hi if gmax is None else positive("gmax", gmax)
    gmin = max(lo, DEFAULT_RANGE * gmax) if gmin is None else positive("gmin", gmin)
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
    g0 = positive("g0", g0)
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
    return (positive("pixel", pixel) / (2.0 * positive("mean_diameter", mean_diameter))) ** 1.5


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
    bound_min = float(resolution_factor) * positive("x_resolution", x_resolution)
    bound_max = positive("x_max", x_max)

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
    grid : petgap.parallel.grid.Grid
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
    checked = check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    gc = np.atleast_1d(np.asarray(gc, dtype=float))
    gap_tolerance = resolve_gap_tolerance(grid, gap, gap_tolerance)
    contact = contact_mask(gap, pressure, gap_tolerance)
    g = np.sort(gap[~contact & (gap > gap_tolerance)])
    local = np.concatenate([[np.count_nonzero(contact)], np.searchsorted(g, gc, side="left")])
    total = global_sums(grid.comm, local, dtype=np.int64)
    nx, ny = global_shape(grid)
    n = nx * ny
    c = total[0] / n if c is None else float(c)
    measured = total[1:] / n
    predicted = near_contact_area_eq14(gc, c, g0) if g0 is not None else np.full(gc.shape, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = measured / predicted
    return NearContactArea(gc=gc, measured=measured, predicted=predicted, ratio=ratio,
                           contact_fraction=c)


