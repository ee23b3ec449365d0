"""Hertz's contact of a rigid sphere on an elastic half-space (axisymmetric, isolated).

Conventions are those of :mod:`petgap.mechanics.problem`: a rigid surface of height ``h`` is pressed onto
an elastic half-space of contact modulus ``E*``; pressures are positive in compression; the gap is
``g = d + u - h >= 0``.

A rigid sphere of radius ``R``, ``h(r) = -r^2 / (2 R)``, pressed with force ``F``
(Hertz, J. reine angew. Math. 92, 156 (1882); Johnson 1985, section 4.2, and
section 3.4 for the displacement outside the contact)::

    a = (3 F R / (4 E*))^(1/3),   p0 = 3 F / (2 pi a^2) = 2 a E* / (pi R),
    p(r) = p0 sqrt(1 - r^2 / a^2),  delta = a^2 / R,
    g(r) = r^2 / (2 R) - delta
           + (p0 / (2 a E*)) [(2 a^2 - r^2) arcsin(a / r) + a sqrt(r^2 - a^2)],  r >= a.

``delta`` is the penetration of the sphere measured from first touch.  In a
periodic cell of area ``A0`` the mean pressure is ``F / A0``; the images change
the curvature at the contact only by a relative ``O((a / L)^3)``.
"""
import math

import numpy as np


def _check_hertz(force, radius, contact_modulus):
    force, radius, contact_modulus = float(force), float(radius), float(contact_modulus)
    if not (force >= 0 and radius > 0 and contact_modulus > 0):
        raise ValueError(f"Hertz needs force >= 0, radius > 0 and E* > 0; got "
                         f"{force}, {radius}, {contact_modulus}")
    return force, radius, contact_modulus


def hertz_contact_radius(force, radius, contact_modulus):
    """Contact radius ``a = (3 F R / (4 E*))^(1/3)``.

    Parameters
    ----------
    force : float
        Normal force ``F``.
    radius : float
        Sphere radius ``R`` (``h = -r^2 / (2 R)``).
    contact_modulus : float
        ``E*``.

    References
    ----------
    Johnson, *Contact Mechanics* (1985), section 4.2; Hertz (1882).
    """
    force, radius, contact_modulus = _check_hertz(force, radius, contact_modulus)
    return (3.0 * force * radius / (4.0 * contact_modulus)) ** (1.0 / 3.0)


def hertz_max_pressure(force, radius, contact_modulus):
    """Peak pressure ``p0 = 3 F / (2 pi a^2) = 2 a E* / (pi R)`` (Johnson 1985, section 4.2)."""
    a = hertz_contact_radius(force, radius, contact_modulus)
    return 2.0 * a * contact_modulus / (math.pi * radius)


def hertz_penetration(force, radius, contact_modulus):
    """Penetration ``delta = a^2 / R`` from first touch (Johnson 1985, section 4.2)."""
    a = hertz_contact_radius(force, radius, contact_modulus)
    return a * a / radius


def hertz_pressure(r, force, radius, contact_modulus):
    """Pressure ``p(r) = p0 sqrt(1 - r^2 / a^2)`` for ``r < a``, 0 outside.

    Parameters
    ----------
    r : array_like
        Distance from the axis of the sphere.
    force, radius, contact_modulus : float
        ``F``, ``R``, ``E*``.
    """
    a = hertz_contact_radius(force, radius, contact_modulus)
    p0 = hertz_max_pressure(force, radius, contact_modulus)
    r = np.asarray(r, dtype=float)
    if a == 0:
        return np.zeros_like(r)
    return p0 * np.sqrt(np.maximum(1.0 - (r / a) ** 2, 0.0))


def hertz_gap(r, force, radius, contact_modulus):
    """Gap ``g(r)`` between sphere and half-space (0 in the contact).

    Outside the contact ``g = r^2 / (2 R) - delta + u(r)`` with the Hertz surface
    displacement ``u(r) = (p0 / (2 a E*)) [(2 a^2 - r^2) arcsin(a / r) + a sqrt(r^2 - a^2)]``
    (Johnson 1985, section 3.4, with ``E* = E / (1 - nu^2)`` for a rigid indenter).  It
    is continuous at ``r = a`` and tends to the Boussinesq ``F / (pi E* r)`` far away.
    """
    force, radius, contact_modulus = _check_hertz(force, radius, contact_modulus)
    r = np.abs(np.asarray(r, dtype=float))
    a = hertz_contact_radius(force, radius, contact_modulus)
    if a == 0:
        return r ** 2 / (2 * radius)
    p0 = hertz_max_pressure(force, radius, contact_modulus)
    ro = np.maximum(r, a)
    u = p0 / (2 * a * contact_modulus) * ((2 * a * a - ro ** 2) * np.arcsin(a / ro)
                                          + a * np.sqrt(ro ** 2 - a * a))
    return np.where(r > a, ro ** 2 / (2 * radius) - a * a / radius + u, 0.0)


