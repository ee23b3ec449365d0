"""The paper's exponential attraction, ``v(g) = -w exp(-g / rho)`` (Eq. 6).

The contact-mechanics challenge potential (DOI 10.1007/s11249-021-01454-6,
Eq. 6): ``w`` the work of adhesion per unit area, ``rho`` its range.
``v'(g) = (w / rho) exp(-g / rho) > 0`` pulls the surfaces together, strongest
at the wall (``w / rho``); ``v'' = -v' / rho < 0`` everywhere, so the problem is
non-convex for small ``rho``, and the gap solver derives ``v''`` from ``v'`` in
its direction pass (which sums the curvature along the direction) instead of
holding a field of it.
"""
import numpy as np

from petgap.mechanics.interactions import _laws
from petgap.mechanics.interactions.base import AdhesionLaw


class ExponentialAdhesion(AdhesionLaw):
    """``v(g) = -w exp(-g / rho)`` per unit area, with ``work = w`` and ``range = rho``."""

    name, LENGTH, ZONE = "exponential", "rho", "E* rho^2 / w"

    @property
    def curvature_from_stress(self):
        """``rho``: ``v'' = -v' / rho``."""
        return self.range

    def energy(self, gap):
        """``v(g)``."""
        return -self.work * np.exp(-gap / self.range)

    def derivative(self, gap):
        """``v'(g) = (w / rho) exp(-g / rho)``: the attractive stress (positive = tensile)."""
        return (self.work / self.range) * np.exp(-gap / self.range)

    def curvature(self, gap):
        """``v''(g) = -(w / rho^2) exp(-g / rho)``."""
        return -(self.work / self.range ** 2) * np.exp(-gap / self.range)

    @property
    def max_attraction(self):
        """``w / rho``, at the wall."""
        return self.work / self.range

    def process_zone(self, contact_modulus):
        """``E* rho^2 / w`` (:meth:`AdhesionLaw.process_zone` with ``sigma0 = w / rho``)."""
        return contact_modulus * self.range ** 2 / self.work

    def fill_stress(self, gap, vp, vpp=None):
        """``vp = v'(gap)``, one exponential per point (``v''`` is ``-vp / rho``)."""
        _laws.exponential_stress(gap, vp, self.work, self.range)
        return 0
