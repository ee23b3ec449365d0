"""The squared exponential, ``v(g) = -w exp(-g^2 / (2 rho^2))``.

The Gaussian-shaped attraction of Tamaas' ``SquaredExponentialAdhesionFunctional``,
here in the form ``-w exp(-g^2 / (2 rho^2))``: ``w`` the work of adhesion, ``rho``
the gap of the largest attraction.  Unlike the exponential it exerts no stress at
the wall, ``v'(0) = 0``, and grows linearly off it:

    v'(g)  = (w / rho^2) g exp(-g^2 / (2 rho^2)),        largest at g = rho: w / (sqrt(e) rho),
    v''(g) = (w / rho^2) (1 - g^2 / rho^2) exp(-g^2 / (2 rho^2)),

convex for ``g < rho`` and non-convex beyond.  The process zone is
``E* w / (max v')^2 = e E* rho^2 / w``.  ``v''`` is not a multiple of ``v'`` (it
changes sign at ``rho``): the gap solver holds it as one more field, filled in the
same pass as ``v'`` from the same exponential.
"""
import math
import numpy as np

from petgap.mechanics.interactions import _laws
from petgap.mechanics.interactions.base import AdhesionLaw


class SquaredExponentialAdhesion(AdhesionLaw):
    """``v(g) = -w exp(-g^2 / (2 rho^2))``: ``work = w``, ``range = rho`` (where ``v'`` peaks)."""

    name, LENGTH, ZONE = "squared-exponential", "rho", "e E* rho^2 / w"
    curvature_from_stress = None

    def _bell(self, gap):
        gap = np.asarray(gap, dtype=float)
        return np.exp(-0.5 * (gap / self.range) ** 2)

    def energy(self, gap):
        """``v(g)``."""
        return -self.work * self._bell(gap)

    def derivative(self, gap):
        """``v'(g) = (w / rho^2) g exp(-g^2 / (2 rho^2))``."""
        return self.work / self.range ** 2 * np.asarray(gap, dtype=float) * self._bell(gap)

    def curvature(self, gap):
        """``v''(g) = (w / rho^2) (1 - g^2 / rho^2) exp(-g^2 / (2 rho^2))``."""
        x2 = (np.asarray(gap, dtype=float) / self.range) ** 2
        return self.work / self.range ** 2 * (1.0 - x2) * self._bell(gap)

    @property
    def max_attraction(self):
        """``w / (sqrt(e) rho)``, at ``g = rho``."""
        return self.work / (math.sqrt(math.e) * self.range)

    def fill_stress(self, gap, vp, vpp=None):
        """``vp = v'(gap)`` and ``vpp = v''(gap)`` in one pass, one exponential per point."""
        _laws.squared_exponential_stress(gap, vp, vpp, self.work, self.range)
        return 0
