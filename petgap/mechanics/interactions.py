"""Interactions between the surfaces beyond the hard wall.

The hard wall itself (``g >= 0``) is always a bound on the gap, never a
penalty.  An interaction adds the energy ``sum_x dx dy v(g(x))``.

* :class:`HardWall`: ``v = 0`` (frictionless, non-adhesive contact).
* :class:`ExponentialAdhesion`: ``v(g) = -w exp(-g / rho)`` (paper Eq. 6; the
  contact-mechanics challenge potential), with ``w`` the work of adhesion per
  unit area and ``rho`` its range.  ``v'(g) = (w / rho) exp(-g / rho) > 0``
  pulls the surfaces together; ``v'' < 0`` makes the problem non-convex for
  small ``rho``.
"""
import warnings
from dataclasses import dataclass

import numpy as np


class ResolutionError(ValueError):
    """The grid does not resolve the interaction (raised when the scene asks to refuse)."""


class ResolutionWarning(UserWarning):
    """The grid does not resolve the interaction."""


@dataclass(frozen=True)
class HardWall:
    """No interaction besides the hard wall."""

    adhesive = False

    def energy(self, gap):
        """Interaction energy density ``v(g)`` (zero)."""
        return np.zeros_like(gap)


@dataclass(frozen=True)
class ExponentialAdhesion:
    """``v(g) = -w exp(-g / rho)`` per unit area.

    Parameters
    ----------
    work : float
        Work of adhesion ``w`` (energy per area), positive.
    range : float
        Interaction range ``rho`` (length), positive.
    """

    work: float
    range: float
    adhesive = True

    def __post_init__(self):
        for name in ("work", "range"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"ExponentialAdhesion {name} must be positive and finite, got {value}")

    def energy(self, gap):
        """``v(g)``."""
        return -self.work * np.exp(-gap / self.range)

    def derivative(self, gap):
        """``v'(g) = (w / rho) exp(-g / rho)``: the attractive stress (positive = tensile)."""
        return (self.work / self.range) * np.exp(-gap / self.range)

    def curvature(self, gap):
        """``v''(g) = -(w / rho^2) exp(-g / rho)``."""
        return -(self.work / self.range ** 2) * np.exp(-gap / self.range)


#: Smallest resolved interaction range, in pixels.
MIN_RANGE_PIXELS = 1.0
#: Smallest resolved adhesive process zone, in pixels.
MIN_PROCESS_ZONE_PIXELS = 2.0


def resolution_report(interaction, pixel_size, contact_modulus):
    """How well a grid resolves an adhesive interaction.

    Two lengths must span pixels for the discrete problem to represent the
    continuum one: the range ``rho`` itself (the stress decays over it), and
    the adhesive process zone at a contact edge, where the attractive stress
    acts.  For a cohesive law of strength ``sigma0 = w / rho`` (the largest
    attractive stress of ``v``) the zone length is of order
    ``l_pz = E* w / sigma0^2 = E* rho^2 / w`` (Maugis 1992; Müser, Beilstein J.
    Nanotechnol. 5 (2014) 419, on pixel resolution of adhesive BEM).  With
    ``l_pz`` below a couple of pixels the edge is unresolved and the solution
    depends on the grid (and is prone to lattice trapping).

    Returns
    -------
    dict
        ``range_pixels``, ``process_zone``, ``process_zone_pixels``, ``resolved``
        and a ``message`` that states the numbers and the rule.
    """
    if not interaction.adhesive:
        return {"resolved": True, "message": "hard wall: nothing to resolve"}
    rho, w = interaction.range, interaction.work
    range_px = rho / pixel_size
    zone = contact_modulus * rho ** 2 / w
    zone_px = zone / pixel_size
    problems = []
    if range_px < MIN_RANGE_PIXELS:
        problems.append(f"range rho = {rho:g} is {range_px:.3g} pixels (rule: rho >= "
                        f"{MIN_RANGE_PIXELS:g} a0, a0 = {pixel_size:g})")
    if zone_px < MIN_PROCESS_ZONE_PIXELS:
        problems.append(f"process zone E* rho^2 / w = {zone:.3g} is {zone_px:.3g} pixels (rule: "
                        f">= {MIN_PROCESS_ZONE_PIXELS:g} a0; E* = {contact_modulus:g}, w = {w:g})")
    message = ("interaction not resolved by the grid: " + "; ".join(problems) +
               ". Refine the grid or lengthen rho" if problems else
               f"resolved: rho = {range_px:.3g} a0, process zone = {zone_px:.3g} a0")
    return {"range_pixels": range_px, "process_zone": zone, "process_zone_pixels": zone_px,
            "resolved": not problems, "message": message}


def check_resolution(interaction, pixel_size, contact_modulus, mode="warn"):
    """Warn, refuse or stay silent (``mode``) when the interaction is unresolved.

    Deterministic, so every rank reaches the same verdict and raises together.
    """
    if mode not in ("warn", "error", "off"):
        raise ValueError(f"resolution check mode {mode!r} is not one of warn, error, off")
    report = resolution_report(interaction, pixel_size, contact_modulus)
    if not report["resolved"] and mode == "error":
        raise ResolutionError(report["message"])
    if not report["resolved"] and mode == "warn":
        warnings.warn(report["message"], ResolutionWarning, stacklevel=2)
    return report
