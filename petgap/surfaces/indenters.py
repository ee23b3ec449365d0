"""Analytic indenters: the rigid bodies of the classical contact solutions.

Each is a height field ``h`` on the grid with its apex (or face) at height 0 on
the grid's centre pixel ``(nx // 2, ny // 2)`` and ``h < 0`` elsewhere, in the
conventions of :mod:`petgap.parallel.grid` (``h`` towards the elastic body).
Solved on a free boundary (:class:`petgap.mechanics.free_half_space.FreeHalfSpace`)
they give Hertz's and Boussinesq's contacts (Johnson 1985, ch. 3-5), which is
what they are for: checks of the solver and the half-space, and small contacts
to compare a periodic solution with.

``radius`` is ``R``:

``paraboloid``
    ``-r^2 / (2 R)``, Hertz's profile of a sphere of radius ``R``.
``sphere``
    the cap ``sqrt(R^2 - r^2) - R`` for ``r <= R``, and ``-R`` beyond.
``flat-punch``
    0 on the face ``r <= R``, ``-R`` around it (out of reach of indentations
    smaller than ``R``: the punch's sides).
``cylinder``
    ``-x^2 / (2 R)``, a cylinder whose axis runs along ``y`` through the centre
    (a line contact across the map).
"""
import numpy as np

#: The indenters :func:`indenter` makes.
KINDS = ("paraboloid", "sphere", "flat-punch", "cylinder")


def indenter(grid, kind, radius):
    """This rank's slab of the indenter ``kind`` of radius ``radius`` (module docstring)."""
    if kind not in KINDS:
        raise ValueError(f"indenter kind {kind!r} is not one of {', '.join(KINDS)}")
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"indenter radius must be positive and finite, got {radius!r}")
    x, y = grid.local_positions()
    x = x - (grid.nx // 2) * grid.dx
    y = y - (grid.ny // 2) * grid.dy
    if kind == "cylinder":
        return -x ** 2 / (2 * radius)
    r2 = x ** 2 + y ** 2
    if kind == "paraboloid":
        return -r2 / (2 * radius)
    inside = r2 <= radius ** 2
    if kind == "flat-punch":
        return np.where(inside, 0.0, -radius)
    return np.where(inside, np.sqrt(np.maximum(radius ** 2 - r2, 0.0)) - radius, -radius)
