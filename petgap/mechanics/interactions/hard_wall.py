"""The hard wall alone: ``v = 0`` (frictionless, non-adhesive contact)."""
from dataclasses import dataclass

import numpy as np

from petgap.mechanics.interactions.base import InteractionLaw


@dataclass(frozen=True)
class HardWall(InteractionLaw):
    """No interaction besides the hard wall."""

    name = "hard-wall"
    adhesive = False
    #: No length: nothing to resolve, no step to cap, nothing for a free boundary to clear.
    length_scale = 0.0
    max_attraction = 0.0
    work = 0.0

    def energy(self, gap):
        """Interaction energy density ``v(g)`` (zero)."""
        return np.zeros_like(gap)

    def derivative(self, gap):
        """``v'(g)`` (zero)."""
        return np.zeros_like(gap)

    def curvature(self, gap):
        """``v''(g)`` (zero)."""
        return np.zeros_like(gap)

    def attributes(self):
        """``kind = "hard-wall"``, and no parameters (stored as None, as a reader expects)."""
        return {"kind": self.name, "work_of_adhesion": None, "range": None}
