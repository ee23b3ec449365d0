"""What every interaction law is: the protocol the solvers, the scene and ``petgap-post`` use.

An interaction adds the energy ``sum_x dx dy v(g(x))`` to the elastic one, on
top of the hard wall ``g >= 0`` (always a bound on the gap, never a penalty).
Signs: ``v'(g) > 0`` is an attractive (tensile) stress that pulls the surfaces
together; ``v'' < 0`` makes the problem non-convex.

A law knows itself, so that no caller reads its parameters:

* ``energy``, ``derivative``, ``curvature``: ``v``, ``v'``, ``v''`` of an array
  of gaps (NumPy; for analysis, the objective and tests);
* ``fill_stress(gap, vp, vpp)``: the fused per-point kernel of the gap solver,
  one compiled pass that writes ``v'`` and, where the law needs one, ``v''``;
  ``curvature_from_stress`` says when it needs none: a length ``L`` with
  ``v'' = -v' / L`` (the exponential, ``L = rho``; ``inf`` for ``v'' = 0``),
  which the solver's direction pass applies to ``v'`` itself, so that no
  ``v''`` field is held; a law whose ``v'`` jumps (``jumps``) also counts the
  points that crossed a jump since ``vp`` was last filled, on which the
  solver restarts;
* ``adhesive``, ``work`` (``w = -v(0)``), ``length_scale`` (the gap over which
  ``v'`` changes: what the gap solver caps a step at and what the free
  boundary's reach multiplies), ``max_attraction`` (the largest ``v'``) and
  ``process_zone(E*)`` (``E* w / max_attraction^2``: the cohesive zone at a
  contact edge), from which :mod:`.resolution` judges a grid;
* ``name`` and ``PARAMETERS``: the scene's ``interaction.kind`` and keys, which
  are also the result file's ``interaction.*`` attributes
  (:meth:`attributes`, :meth:`from_attributes`).

A new law is a class deriving from :class:`AdhesionLaw` (a frozen dataclass of
``work`` and ``range``) in a module of its own, plus one line in the registry
(:mod:`petgap.mechanics.interactions`); a compiled kernel in :mod:`._laws` is
for speed only.
"""
import math
from dataclasses import dataclass, fields

import numpy as np


class InteractionLaw:
    """The protocol; :class:`~.hard_wall.HardWall` and :class:`AdhesionLaw` implement it."""

    #: Scene and file name (``interaction.kind``).
    name = None
    adhesive = False
    #: ``(scene / attribute key, dataclass field)`` of each parameter.
    PARAMETERS = ()
    #: ``L`` with ``v'' = -v' / L`` (no ``v''`` field in the gap solver), or None.
    curvature_from_stress = math.inf
    #: Whether ``v'`` jumps somewhere (then ``fill_stress`` counts the crossings).
    jumps = False

    def energy(self, gap):
        """``v(g)``."""
        raise NotImplementedError

    def derivative(self, gap):
        """``v'(g)``: the attractive stress (positive = tensile)."""
        raise NotImplementedError

    def curvature(self, gap):
        """``v''(g)``."""
        raise NotImplementedError

    def fill_stress(self, gap, vp, vpp=None):
        """``vp = v'(gap)`` (and ``vpp = v''(gap)`` if given) in one pass; the gap solver's kernel.

        Returns the number of points whose ``v'`` jumped since ``vp`` was last
        filled (0 for a law without jumps).  This NumPy version serves a smooth
        law without a compiled kernel; the laws of the registry override it
        with their kernels in :mod:`._laws`.
        """
        vp[...] = self.derivative(gap)
        if vpp is not None:
            vpp[...] = self.curvature(gap)
        return 0

    def attributes(self):
        """The law as result-file attributes: ``kind`` and each parameter's key."""
        out = {"kind": self.name}
        out.update((key, getattr(self, attr)) for key, attr in self.PARAMETERS)
        return out

    @classmethod
    def from_attributes(cls, get):
        """The law whose parameters ``get(key)`` returns (keys of :attr:`PARAMETERS`)."""
        return cls(*(get(key) for key, _ in cls.PARAMETERS))


@dataclass(frozen=True)
class AdhesionLaw(InteractionLaw):
    """Base of the adhesive laws: frozen dataclasses of positive, finite parameters.

    Parameters (of every law here)
    ------------------------------
    work : float
        The work of adhesion ``w = -v(0)``, energy per area.
    range : float
        The law's length (``rho``, ``delta``, ``z0``): its ``length_scale``.

    Subclasses (plain classes: the dataclass is inherited) give ``name``,
    ``LENGTH`` (the symbol of ``length_scale`` in messages, e.g. ``"rho"``),
    ``ZONE`` (the process zone's formula in messages), ``energy``,
    ``derivative``, ``curvature``, ``max_attraction`` and, for speed,
    ``fill_stress``.
    """

    work: float
    range: float
    adhesive = True
    PARAMETERS = (("work_of_adhesion", "work"), ("range", "range"))
    LENGTH = "range"
    ZONE = "E* w / sigma0^2"

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{type(self).__name__} {f.name} must be positive and finite, "
                                 f"got {value}")

    @property
    def length_scale(self):
        """The gap over which ``v'`` changes (the law's ``range``)."""
        return self.range

    @property
    def max_attraction(self):
        """The largest attractive stress ``max v'``."""
        raise NotImplementedError

    def process_zone(self, contact_modulus):
        """``E* w / sigma0^2`` with ``sigma0`` the largest attraction: the cohesive zone's length.

        At a contact edge the attraction acts over a zone of this order (Maugis,
        J. Colloid Interface Sci. 150 (1992) 243); unresolved by the grid, the
        edge depends on the pixels (:mod:`.resolution`).
        """
        return contact_modulus * self.work / self.max_attraction ** 2
