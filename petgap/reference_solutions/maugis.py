"""Maugis' adhesive sphere: a Dugdale zone of constant attraction around a Hertzian contact.

Conventions are those of :mod:`petgap.mechanics.problem`: a rigid surface of height ``h`` is
pressed onto an elastic half-space of contact modulus ``E*``; forces are positive in
compression (a pull-off force is negative).

A rigid sphere of radius ``R`` (``h = -r^2 / (2 R)``) and an interaction of constant
attractive stress ``sigma0`` up to a gap ``delta``, zero beyond (work of adhesion
``w = sigma0 delta``: :class:`petgap.mechanics.interactions.MaugisDugdaleAdhesion`).  Maugis
(J. Colloid Interface Sci. 150 (1992) 243) solves it in closed form up to one nonlinear
equation.  With ``K = 4 E* / 3``, the contact radius ``a``, the outer radius ``c = m a`` of
the zone where the attraction acts, the force ``P`` and the approach ``Delta`` in units of
the JKR scales::

    A = a (K / (pi w R^2))^(1/3),   P_ = P / (pi w R),   D_ = Delta (K^2 / (pi^2 w^2 R))^(1/3),
    lambda = 2 sigma0 (R / (pi w K^2))^(1/3),

Maugis' equations read (``s = sqrt(m^2 - 1)``, ``arcsec m = arctan s``)::

    (lambda A^2 / 2) (s + (m^2 - 2) arcsec m) + (4 lambda^2 A / 3) (s arcsec m - m + 1) = 1,
    P_ = A^3 - lambda A^2 (s + m^2 arcsec m),
    D_ = A^2 - (4 / 3) A lambda s.

The first fixes ``m`` for each ``A`` (its left side grows with ``m`` from 0 at ``m = 1``);
the others give the force and the approach.  The Tabor-like parameter ``lambda`` spans the
transition: ``lambda -> infinity`` is JKR (pull-off ``P = -1.5 pi w R``), ``lambda -> 0``
DMT (``P = -2 pi w R``).  Under load control the sphere comes off at the least force along
the curve, which for small ``lambda`` is its ``A -> 0`` end (a vanishing contact inside a
finite attractive zone, ``C = m A`` finite).
"""
import math

import numpy as np

#: Bisection steps on ``m``: the bracket shrinks to double precision well before.
_BISECTIONS = 200


def maugis_parameter(sigma0, work, radius, contact_modulus):
    """Maugis' ``lambda = 2 sigma0 (R / (pi w K^2))^(1/3)``, ``K = 4 E* / 3``."""
    sigma0, work, radius, e = _positive(sigma0=sigma0, work=work, radius=radius,
                                        contact_modulus=contact_modulus)
    k = 4.0 * e / 3.0
    return 2.0 * sigma0 * (radius / (math.pi * work * k * k)) ** (1.0 / 3.0)


def _positive(**values):
    for name, value in values.items():
        if not (math.isfinite(float(value)) and float(value) > 0):
            raise ValueError(f"Maugis' sphere needs {name} > 0 and finite, got {value}")
    return tuple(float(v) for v in values.values())


def _zone_equation(m, a, lam):
    s = math.sqrt(m * m - 1.0)
    arcsec = math.atan(s)
    return (0.5 * lam * a * a * (s + (m * m - 2.0) * arcsec)
            + 4.0 * lam * lam * a / 3.0 * (s * arcsec - m + 1.0) - 1.0)


def zone_ratio(contact_radius, lam):
    """``m = c / a`` of Maugis' first equation at the dimensionless contact radius ``A > 0``."""
    a, lam = _positive(contact_radius=contact_radius, lam=lam)
    low, high = 1.0, 2.0
    while _zone_equation(high, a, lam) < 0:
        low, high = high, 2.0 * high
    for _ in range(_BISECTIONS):
        mid = 0.5 * (low + high)
        if mid in (low, high):
            break
        low, high = (mid, high) if _zone_equation(mid, a, lam) < 0 else (low, mid)
    return 0.5 * (low + high)


def maugis_state(contact_radius, lam):
    """``(P_, D_, m)``: the dimensionless force, approach and zone ratio at contact radius ``A``."""
    a = float(contact_radius)
    m = zone_ratio(a, lam)
    s = math.sqrt(m * m - 1.0)
    arcsec = math.atan(s)
    force = a ** 3 - lam * a * a * (s + m * m * arcsec)
    approach = a * a - 4.0 / 3.0 * a * lam * s
    return force, approach, m


def _force_at_vanishing_contact(lam):
    """``P_`` at ``A -> 0``, where ``C = m A`` solves the first equation's limit.

    ``lambda pi C^2 / 4 + (4/3)(pi/2 - 1) lambda^2 C = 1``, and ``P_ = -lambda pi C^2 / 2``.
    """
    b = 4.0 / 3.0 * (0.5 * math.pi - 1.0) * lam * lam
    q = 0.25 * lam * math.pi
    c = (-b + math.sqrt(b * b + 4.0 * q)) / (2.0 * q)
    return -0.5 * lam * math.pi * c * c


def maugis_pull_off(lam):
    """Maugis' pull-off force under load control, ``P / (pi w R)``: the least force of the curve.

    Between ``-2`` (DMT, ``lambda -> 0``) and ``-1.5`` (JKR, ``lambda -> inf``).  The curve
    ``P_(A)`` is scanned over ``A`` and its least value refined by golden sections; the
    ``A -> 0`` end is taken in its closed form.
    """
    (lam,) = _positive(lam=lam)
    grid = np.geomspace(1e-4, 4.0, 400)
    forces = np.array([maugis_state(a, lam)[0] for a in grid])
    k = int(np.argmin(forces))
    best = min(forces[k], _force_at_vanishing_contact(lam))
    if 0 < k < len(grid) - 1:
        lo, hi = grid[k - 1], grid[k + 1]
        ratio = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(100):
            x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
            if maugis_state(x1, lam)[0] < maugis_state(x2, lam)[0]:
                hi = x2
            else:
                lo = x1
        best = min(best, maugis_state(0.5 * (lo + hi), lam)[0])
    return best


def maugis_pull_off_force(work, sigma0, radius, contact_modulus):
    """The pull-off force ``P`` (negative) of a sphere with Maugis-Dugdale adhesion."""
    lam = maugis_parameter(sigma0, work, radius, contact_modulus)
    return maugis_pull_off(lam) * math.pi * work * radius
