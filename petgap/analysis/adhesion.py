"""The attractive force: measured (Eq. 15), predicted by Eq. 16, 1/kappa_att and the Fig. 4 integrand.

Conventions: :mod:`petgap.analysis`.
"""
import math
from dataclasses import dataclass

import numpy as np

from petgap.parallel.collective import global_sums
from petgap.analysis._slabs import check_fields, global_shape, pixel, positive
from petgap.analysis.contact_geometry import contact_mask, resolve_gap_tolerance


#: ``Gamma(2/3)``: the factor by which the exact integral of Eq. 16 exceeds the printed result.
GAMMA_2_3 = math.gamma(2.0 / 3.0)


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
    grid : petgap.parallel.grid.Grid
    gap : ndarray, shape ``grid.local_shape``
    v_prime : callable or object with ``derivative``
        ``v'(g)`` (e.g. :class:`petgap.mechanics.interactions.ExponentialAdhesion`), the
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
    checked = check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    stress = np.asarray(derivative(gap), dtype=float)
    if pressure is not None:
        contact = contact_mask(gap, pressure, resolve_gap_tolerance(grid, gap, gap_tolerance))
        local = [float(np.sum(stress)), float(np.sum(stress[contact]))]
    else:
        local = [float(np.sum(stress)), math.nan]
    total = global_sums(grid.comm, local)
    dx, dy = pixel(grid)
    nx, ny = global_shape(grid)
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
    w, rho, g0 = positive("w", w), positive("rho", rho), positive("g0", g0)
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
    return -float(force) / (positive("rms_slope", rms_slope)
                            * positive("contact_modulus", contact_modulus) * contact_area)


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


@dataclass(frozen=True)
class ForceByGap:
    """Where the measured attractive force comes from, by gap (Fig. 4 from data).

    Attributes
    ----------
    x : ndarray
        Geometric bin centres of ``g / g0`` (logarithmic bins).
    share : ndarray
        Share of ``F_att`` per unit ``ln(g / g0)`` in each bin: the measured
        counterpart of :func:`fig4_integrand` (``x f``).  Its integral over
        ``ln x`` is the non-contact share of ``F_att``, at most 1.
    contact_share : float
        The share of ``F_att`` from pixels in repulsive contact (``g = 0``, not on
        the log axis), which Eq. 16 leaves out.
    outside_share : float
        The share from non-contact pixels with ``g / g0`` outside the bins.
    """
    x: np.ndarray
    share: np.ndarray
    contact_share: float
    outside_share: float


def attractive_force_by_gap(grid, gap, pressure, v_prime, g0, *, bins_per_decade=10,
                            x_range=(1e-5, 1e2), gap_tolerance=None):
    """The measured ``F_att`` resolved by ``x = g / g0``, per unit ``ln x`` (collective).

    Each non-contact pixel adds ``-dx dy v'(g)`` to the bin of its ``g / g0``;
    the bins are divided by ``F_att`` and by their width in ``ln x``.  Pixels in
    repulsive contact (:func:`contact_mask`) are counted apart.  The result is the
    same on every rank.
    """
    derivative = getattr(v_prime, "derivative", v_prime)
    g0 = positive("g0", g0)
    checked = check_fields(grid, gap=gap, pressure=pressure)
    gap, pressure = checked["gap"], checked["pressure"]
    contact = contact_mask(gap, pressure, resolve_gap_tolerance(grid, gap, gap_tolerance))
    stress = np.asarray(derivative(gap), dtype=float)
    lo, hi = (float(v) for v in x_range)
    nbins = int(round(bins_per_decade * math.log10(hi / lo)))
    edges = np.geomspace(lo, hi, nbins + 1)
    x = gap[~contact] / g0
    sums, _ = np.histogram(x, bins=edges, weights=stress[~contact])
    local = np.concatenate([sums, [float(np.sum(stress[contact])), float(np.sum(stress))]])
    total = global_sums(grid.comm, *local)
    bins, in_contact, everything = np.asarray(total[:nbins]), total[nbins], total[nbins + 1]
    if everything == 0:
        raise ValueError("the interaction stress is zero everywhere: no attractive force")
    share = bins / everything / np.diff(np.log(edges))
    outside = (everything - in_contact - float(np.sum(bins))) / everything
    return ForceByGap(x=np.sqrt(edges[:-1] * edges[1:]), share=share,
                      contact_share=in_contact / everything, outside_share=outside)
