"""Interaction laws between the surfaces, and the registry that names them.

Each law is one object that knows itself (:mod:`.base` states the protocol):
its energy and derivatives, the gap solver's fused kernel, whether it is
adhesive, its length scale and resolution, its scene name and parameters and its
result-file attributes.  The registry, :data:`LAWS`, maps ``interaction.kind``
(of a scene and of a result file) to the class: a new law is one module and one
line here.

* :class:`HardWall`: ``v = 0``.
* :class:`ExponentialAdhesion`: ``-w exp(-g / rho)`` (the paper's Eq. 6).
* :class:`MaugisDugdaleAdhesion`: ``-w (1 - g / delta)`` below ``delta`` (Dugdale's
  constant stress ``w / delta``; the JKR-DMT transition).
* :class:`LennardJones93Adhesion`: 9-3 Lennard-Jones with the wall at its minimum.
* :class:`SquaredExponentialAdhesion`: ``-w exp(-g^2 / (2 rho^2))``.
"""
from petgap.mechanics.interactions.base import AdhesionLaw, InteractionLaw
from petgap.mechanics.interactions.exponential import ExponentialAdhesion
from petgap.mechanics.interactions.hard_wall import HardWall
from petgap.mechanics.interactions.lennard_jones import LennardJones93Adhesion
from petgap.mechanics.interactions.maugis_dugdale import MaugisDugdaleAdhesion
from petgap.mechanics.interactions.resolution import (ResolutionError, ResolutionWarning,
                                                      check_resolution, resolution_report)
from petgap.mechanics.interactions.squared_exponential import SquaredExponentialAdhesion

#: ``interaction.kind`` -> law class: the one table of the laws there are.
LAWS = {law.name: law for law in (
    HardWall,
    ExponentialAdhesion,
    MaugisDugdaleAdhesion,
    LennardJones93Adhesion,
    SquaredExponentialAdhesion,
)}


def law_class(kind):
    """The class of ``interaction.kind`` ``kind``; ValueError naming the kinds there are."""
    try:
        return LAWS[kind]
    except (KeyError, TypeError):
        raise ValueError(f"interaction.kind = {kind!r} is not known; allowed: "
                         f"{', '.join(LAWS)}") from None


def from_attributes(kind, get):
    """The law of a result file's ``interaction.kind`` and ``get(key)`` of its parameters."""
    return law_class(kind).from_attributes(get)


def from_scene(section, work=None):
    """The law of a scene's validated ``[interaction]`` section.

    ``work``: which of the section's works of adhesion (a scene may list several, a
    series of adhesive steps); by default its first.
    """
    def get(key):
        value = getattr(section, key)
        if key == "work_of_adhesion" and isinstance(value, tuple):
            return value[0] if work is None else work
        return value
    return from_attributes(section.kind, get)


__all__ = ["InteractionLaw", "AdhesionLaw", "HardWall", "ExponentialAdhesion",
           "MaugisDugdaleAdhesion", "LennardJones93Adhesion", "SquaredExponentialAdhesion",
           "LAWS", "law_class", "from_attributes", "from_scene", "ResolutionError",
           "ResolutionWarning", "check_resolution", "resolution_report"]
