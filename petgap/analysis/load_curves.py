"""Laws of a load sweep: contact area proportional to load, load exponential in the mean gap.

Two results of contact mechanics that a sweep of loads is read against (paper,
doi:10.1007/s11249-021-01454-6, and the work it cites):

* At small contact fractions the repulsive area grows in proportion to the load,
  ``c = kappa_rep P0 / (h0' E*)`` with ``kappa_rep`` about 2 (the paper's
  ``kappa_rep``).  :func:`fit_kappa_rep` fits ``kappa_rep`` as the least-squares
  slope through the origin of ``c`` against ``P0 / (h0' E*)`` over the points with
  ``c <= c_max`` (the law holds only while contacts are sparse).
* The mean pressure falls exponentially with the mean gap at intermediate loads,
  ``P0 ~ exp(-g_mean / (gamma h0))`` with ``h0`` the rms height and ``gamma`` of
  order 0.5 (Persson; Pastewka et al.).  :func:`fit_gap_law` fits ``ln P0``
  linearly against ``g_mean`` and returns ``gamma`` and the prefactor.

Both fits are plain least squares on the points given; they report how many
points they used so that a fit on two points is read as such.
"""
import math
from dataclasses import dataclass

import numpy as np

#: Contact fractions up to which ``c`` is taken as proportional to the load.
KAPPA_C_MAX = 0.1


@dataclass
class KappaFit:
    """``c = kappa * x`` with ``x = P0 / (h0' E*)``, fitted on ``npoints`` points."""
    kappa: float
    npoints: int
    c_max: float


@dataclass
class GapLawFit:
    """``P0 = prefactor * exp(-g_mean / (gamma * h0))``, fitted on ``npoints`` points."""
    gamma: float
    prefactor: float
    npoints: int
    rms_height: float

    def load(self, mean_gap):
        """The fitted law's mean pressure at ``mean_gap``."""
        return self.prefactor * np.exp(-np.asarray(mean_gap) / (self.gamma * self.rms_height))


def fit_kappa_rep(reduced_load, contact_fraction, c_max=KAPPA_C_MAX):
    """Least-squares ``kappa_rep`` through the origin over the points with ``0 < c <= c_max``.

    Parameters
    ----------
    reduced_load : array_like
        ``P0 / (h0' E*)`` of each point.
    contact_fraction : array_like
        ``c`` of each point.
    c_max : float
        Largest ``c`` used.

    Returns
    -------
    KappaFit
        ``kappa = nan`` with ``npoints = 0`` if no point qualifies.
    """
    x = np.asarray(reduced_load, dtype=float)
    c = np.asarray(contact_fraction, dtype=float)
    use = np.isfinite(x) & np.isfinite(c) & (x > 0) & (c > 0) & (c <= c_max)
    if not np.any(use):
        return KappaFit(math.nan, 0, c_max)
    kappa = float(np.sum(x[use] * c[use]) / np.sum(x[use] ** 2))
    return KappaFit(kappa, int(np.count_nonzero(use)), c_max)


def fit_gap_law(mean_gap, load, rms_height):
    """``gamma`` of ``P0 ~ exp(-g_mean / (gamma h0))`` by least squares of ``ln P0`` on ``g_mean``.

    Only points with ``P0 > 0`` and a finite, positive mean gap are used.  Returns a
    :class:`GapLawFit` with ``gamma = nan`` if fewer than two such points have
    different gaps, or if the load does not fall with the gap (no exponential law).
    """
    g = np.asarray(mean_gap, dtype=float)
    p = np.asarray(load, dtype=float)
    if not (math.isfinite(rms_height) and rms_height > 0):
        raise ValueError(f"rms_height = {rms_height!r} is not allowed: need a positive number")
    use = np.isfinite(g) & np.isfinite(p) & (p > 0) & (g > 0)
    if np.count_nonzero(use) < 2 or np.ptp(g[use]) == 0:
        return GapLawFit(math.nan, math.nan, int(np.count_nonzero(use)), rms_height)
    slope, intercept = np.polyfit(g[use], np.log(p[use]), 1)
    if not slope < 0:
        return GapLawFit(math.nan, math.nan, int(np.count_nonzero(use)), rms_height)
    return GapLawFit(float(-1.0 / (slope * rms_height)), float(np.exp(intercept)),
                     int(np.count_nonzero(use)), rms_height)
