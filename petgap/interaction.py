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
from dataclasses import dataclass

import numpy as np


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
