"""Maugis-Dugdale: a constant attraction ``sigma0 = w / delta`` over gaps ``0 <= g < delta``.

``v(g) = -w (1 - g / delta)`` for ``g < delta`` and ``0`` beyond: Dugdale's
cohesive zone, with which Maugis (J. Colloid Interface Sci. 150 (1992) 243)
spans the JKR-DMT transition by one parameter,
``lambda = 2 sigma0 (R / (pi w K^2))^(1/3)`` with ``K = 4 E* / 3``
(:mod:`petgap.reference_solutions.maugis`).

The law is not smooth: ``v'`` jumps from ``w / delta`` to ``0`` at ``delta``.
How the gap solver handles it, without smoothing:

* ``v'' = 0`` everywhere but at ``delta`` (``curvature_from_stress = inf``):
  the solver's quadratic model along a direction is the elastic energy plus
  the linear ``v`` each point has where it stands;
* the kink at ``delta`` is concave (the slope drops), so that linear model
  lies above the true energy on either side of it: a step from the model
  never does worse than the model predicts, and no minimiser has a point at
  the kink itself (a local minimum of a function with a concave kink is not at
  the kink), so the KKT conditions with ``v'`` as defined here hold at the
  solution;
* steps are capped at ``delta`` per point (the law's length scale, as for
  every adhesive law): no step carries a point across more than the width of
  the attraction;
* the conjugate gradients restart whenever a point crossed ``delta``
  (``jumps``; the kernel counts the crossings as it fills ``v'``): the jump
  changes that point's gradient by ``w / delta``, which the old direction knows
  nothing of, and without the restart a receding cohesive zone (at pull-off)
  shrinks by a ring of pixels per iteration.
"""
import numpy as np

from petgap.mechanics.interactions import _laws
from petgap.mechanics.interactions.base import AdhesionLaw


class MaugisDugdaleAdhesion(AdhesionLaw):
    """``v(g) = -w (1 - g / delta)`` below ``delta``, 0 beyond; ``work = w``, ``range = delta``."""

    name, LENGTH, ZONE = "maugis-dugdale", "delta", "E* delta^2 / w"
    #: ``v'' = 0`` (``-v' / inf``) away from ``delta``: no field of it.
    curvature_from_stress = np.inf
    jumps = True

    def energy(self, gap):
        """``v(g)``."""
        return np.where(gap < self.range, -self.work * (1.0 - gap / self.range), 0.0)

    def derivative(self, gap):
        """``v'(g) = w / delta`` below ``delta``, ``0`` from ``delta`` on."""
        return np.where(gap < self.range, self.work / self.range, 0.0)

    def curvature(self, gap):
        """``v''(g) = 0`` (away from ``delta``, where ``v'`` jumps)."""
        return np.zeros_like(np.asarray(gap, dtype=float))

    @property
    def max_attraction(self):
        """``sigma0 = w / delta``."""
        return self.work / self.range

    def fill_stress(self, gap, vp, vpp=None):
        """``vp = v'(gap)``; returns how many points crossed ``delta`` since the last fill."""
        return _laws.maugis_dugdale_stress(gap, vp, self.work, self.range)
