"""Is a contact problem inside the model it is solved in?  Checks of valid but implausible input.

A scene or a call can be valid and still ask for something the model does not describe, or
that is a mistake in disguise: heights and pixel size in different units, a load that
flattens the surface, contact patches a few pixels across.  Each check here states the
number, the limit and what to do; the caller warns (once, on rank 0, through the
``petgap`` logger) or, where a scene asks (``checks.plausibility = "error"``), refuses on
every rank.  Every check is a pure function of global numbers, so every rank reaches the
same verdict.

* **The slope.**  The half-space model linearises the surface: its rms slope ``h0'`` must
  be small (beyond :data:`MAX_RMS_SLOPE` the small-slope approximation the elastic
  Green's function rests on fails, and real asperities would deform plastically); a slope
  beyond :data:`ABSURD_RMS_SLOPE` is no surface at all but heights and pixel size in
  different units (a map in nm read with its pixel size in um has slopes 1000 times too
  large).
* **The load.**  Rough contact is proportional, ``c = kappa_rep P0 / (h0' E*)`` with
  ``kappa_rep ~ 2`` (the paper's Eq. 3, doi:10.1007/s11249-021-01454-6), only for
  ``c`` up to about 0.1; beyond :data:`MAX_CONTACT_FRACTION` the contact is no longer
  rough-surface contact in the paper's sense, and beyond ``c = 1`` by that law the load
  flattens the whole surface.  :func:`load_range` gives the loads of ``c`` 0.01-0.1.
* **The contact patches.**  ``d_rep = pi A_rep / P_rep`` (Eq. 2) is the patches' mean
  diameter; below :data:`MIN_PATCH_PIXELS` pixels the perimeter, ``g0`` and the gaps near
  contact edges depend on the grid (the paper resolves ``lambda_min`` with >= 32 pixels).
* **The interaction range** below a pixel is
  :mod:`petgap.mechanics.interactions.resolution`'s check.
"""
import math

from petgap.parallel.log import get_logger

#: The largest rms slope of the small-slope half-space.
MAX_RMS_SLOPE = 0.3
#: An rms slope beyond which the heights and the pixel size are in different units.
ABSURD_RMS_SLOPE = 10.0
#: ``kappa_rep`` of the paper's Eq. 3, for the predicted contact fraction.
KAPPA_REP = 2.0
#: The largest contact fraction (by Eq. 3) a load may aim at before a warning.
MAX_CONTACT_FRACTION = 0.5
#: The contact fractions :func:`load_range` gives the loads of (Eq. 3's range of validity).
CONTACT_FRACTIONS = (0.01, 0.1)
#: The fewest pixels across the mean contact patch (``d_rep``).
MIN_PATCH_PIXELS = 10.0
#: What a caller may do with findings: warn, refuse, or neither.
MODES = ("warn", "error", "off")


class PlausibilityError(ValueError):
    """Implausible input refused (``checks.plausibility = "error"``)."""


def slope_findings(rms_slope, unit=None):
    """What is implausible about an rms slope ``h0'``: a list of sentences (empty if nothing)."""
    if not math.isfinite(rms_slope) or rms_slope <= ABSURD_RMS_SLOPE:
        if math.isfinite(rms_slope) and rms_slope > MAX_RMS_SLOPE:
            return [f"rms slope h0' = {rms_slope:.3g} is beyond the small-slope half-space "
                    f"(h0' <= {MAX_RMS_SLOPE:g}): the elastic model and the paper's laws "
                    f"assume gentle slopes; check the pixel size and the height unit, or "
                    f"smooth the map (surface.lambda_cutoff) if its steepest slopes are noise"]
        return []
    where = f" (lengths in {unit})" if unit else ""
    return [f"rms slope h0' = {rms_slope:.3g} is absurd for a surface (a real one has h0' "
            f"<= {MAX_RMS_SLOPE:g}, and beyond {ABSURD_RMS_SLOPE:g} no surface is that "
            f"steep){where}: the heights and the pixel size are in different units; check "
            f"units.length, the file's unit and grid.a0 / dx / dy"]


def predicted_contact_fraction(mean_pressure, rms_slope, contact_modulus):
    """``c = kappa_rep P0 / (h0' E*)`` (Eq. 3 with :data:`KAPPA_REP`)."""
    return KAPPA_REP * mean_pressure / (rms_slope * contact_modulus)


def load_range(rms_slope, contact_modulus):
    """The mean pressures that give :data:`CONTACT_FRACTIONS` by Eq. 3: ``(lo, hi)``."""
    return tuple(c * rms_slope * contact_modulus / KAPPA_REP for c in CONTACT_FRACTIONS)


def load_findings(mean_pressure, rms_slope, contact_modulus):
    """What is implausible about a mean pressure ``P0`` on a surface of rms slope ``h0'``."""
    if not (mean_pressure > 0 and rms_slope > 0 and contact_modulus > 0):
        return []
    c = predicted_contact_fraction(mean_pressure, rms_slope, contact_modulus)
    if c <= MAX_CONTACT_FRACTION:
        return []
    lo, hi = load_range(rms_slope, contact_modulus)
    full = rms_slope * contact_modulus / KAPPA_REP
    beyond = (f", beyond full contact (P0 = h0' E* / kappa_rep = {full:.3g} flattens the "
              f"surface by that law)" if c >= 1 else "")
    return [f"load P0 = {mean_pressure:.4g} gives a contact fraction c = kappa_rep P0 / "
            f"(h0' E*) = {c:.3g} (kappa_rep = {KAPPA_REP:g}, h0' = {rms_slope:.3g}, E* = "
            f"{contact_modulus:.4g}){beyond}; rough contact lies below c = "
            f"{MAX_CONTACT_FRACTION:g} and the paper's laws below 0.1: loads {lo:.3g} to "
            f"{hi:.3g} give c = {CONTACT_FRACTIONS[0]:g} to {CONTACT_FRACTIONS[1]:g} (is the "
            f"load in the unit of E*?)"]


def patch_findings(mean_diameter, pixel_size):
    """What is implausible about contact patches of mean diameter ``d_rep`` on pixels of
    ``pixel_size`` (the larger side)."""
    if not (math.isfinite(mean_diameter) and mean_diameter > 0):
        return []
    pixels = mean_diameter / pixel_size
    if pixels >= MIN_PATCH_PIXELS:
        return []
    return [f"contact patches are {pixels:.3g} pixels across (d_rep = {mean_diameter:.4g}, "
            f"pixel {pixel_size:.4g}; resolved: d_rep >= {MIN_PATCH_PIXELS:g} pixels): P_rep, "
            f"d_rep, g0 and the gaps near contact depend on the grid; use a finer map "
            f"(smaller pixels) or smooth away the wavelengths below ~{MIN_PATCH_PIXELS:g} "
            f"pixels (surface.lambda_cutoff)"]


def report(findings, mode="warn", what="", log=None, comm=None):
    """Warn about ``findings`` (on rank 0 of ``comm`` only), raise them (on every rank), or
    neither (``mode``).

    Collective in effect: every rank holds the same findings and acts alike.
    """
    if mode not in MODES:
        raise ValueError(f"checks.plausibility = {mode!r} is not allowed; allowed: "
                         f"{', '.join(MODES)}")
    if not findings or mode == "off":
        return findings
    lead = f"{what}: " if what else ""
    if mode == "error":
        raise PlausibilityError(lead + "; ".join(findings) + " (checks.plausibility = "
                                "\"error\" refuses this; \"warn\" runs it with a warning)")
    if comm is not None and comm.rank != 0:
        return findings
    for finding in findings:
        (log or get_logger("plausibility")).warning("%s%s", lead, finding)
    return findings
