"""Lennard-Jones 9-3 with the hard wall at its minimum.

The 9-3 wall potential (ContactEngineering's Adhesion package, ``LJ93``:
``eps (2/15 (sigma/z)^9 - (sigma/z)^3)``) written with its equilibrium
distance ``z0 = sigma (2/5)^(1/6)`` and its depth ``w`` (the work of adhesion):

    V(z) = (w / 2) ((z0 / z)^9 - 3 (z0 / z)^3),   V(z0) = -w,  V'(z0) = 0.

The gap is measured from the minimum, ``g = z - z0``, and the hard wall stands
there: ``v(g) = V(z0 + g)`` for ``g >= 0``.  So ``v(0) = -w`` and ``v'(0) = 0``:
in contact the surfaces sit at their equilibrium distance, the wall reaction
takes the place of the repulsive branch ``z < z0`` (which the hard wall cuts
off, and which a gap grid could not resolve: it stiffens as ``z^-10``), and the
attractive branch is kept exactly.  With ``s = z0 / (z0 + g)``:

    v'(g)  = (9 w / (2 z0)) (s^4 - s^10)          >= 0,
    v''(g) = (9 w / (2 z0^2)) (10 s^11 - 4 s^5),

convex near the wall (``v''(0) = 27 w / z0^2``), non-convex beyond the
inflection at ``s^6 = 2/5`` (``g = 0.165 z0``), where the attraction is largest,
``(27 / 10) (2/5)^(2/3) w / z0 = 1.466 w / z0``.  The tail falls as ``g^-4``:
the longest-ranged of the laws here.  ``z0`` is the length scale (the step cap
of the gap solver, what the free boundary's reach multiplies).

``v''`` is not a multiple of ``v'``: the gap solver holds it as one more field,
filled in the same pass as ``v'`` (no transcendental function: powers of ``s``).
"""
import numpy as np

from petgap.mechanics.interactions import _laws
from petgap.mechanics.interactions.base import AdhesionLaw


class LennardJones93Adhesion(AdhesionLaw):
    """9-3 Lennard-Jones, the wall at its minimum: ``work = w`` (its depth), ``range = z0``.

    ``v(g) = (w / 2) (s^9 - 3 s^3)`` with ``s = z0 / (z0 + g)``, ``z0`` the
    equilibrium distance.
    """

    name, LENGTH = "lennard-jones-9-3", "z0"
    curvature_from_stress = None

    def _s(self, gap):
        return self.range / (self.range + np.asarray(gap, dtype=float))

    def energy(self, gap):
        """``v(g)``."""
        s3 = self._s(gap) ** 3
        return 0.5 * self.work * (s3 ** 3 - 3.0 * s3)

    def derivative(self, gap):
        """``v'(g) = (9 w / (2 z0)) (s^4 - s^10)``."""
        s = self._s(gap)
        return 4.5 * self.work / self.range * (s ** 4 - s ** 10)

    def curvature(self, gap):
        """``v''(g) = (9 w / (2 z0^2)) (10 s^11 - 4 s^5)``."""
        s = self._s(gap)
        return 4.5 * self.work / self.range ** 2 * (10.0 * s ** 11 - 4.0 * s ** 5)

    @property
    def max_attraction(self):
        """``(27 / 10) (2/5)^(2/3) w / z0``, at ``s^6 = 2/5``."""
        return 2.7 * 0.4 ** (2.0 / 3.0) * self.work / self.range

    def fill_stress(self, gap, vp, vpp=None):
        """``vp = v'(gap)`` and ``vpp = v''(gap)`` in one pass."""
        _laws.lennard_jones_stress(gap, vp, vpp, self.work, self.range)
        return 0
