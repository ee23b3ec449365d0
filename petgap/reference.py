"""Analytic reference solutions of frictionless, non-adhesive elastic contact.

Tests and users compare the numerical solutions against these closed forms (as
ContactMechanics' ``ReferenceSolutions``).  Conventions are those of
:mod:`petgap.contact`: a rigid surface of height ``h`` is pressed onto an
elastic half-space of contact modulus ``E*`` (paper Eq. 4); contact occurs at
the maxima of ``h``; pressures are positive in compression; the gap is
``g = d + u - h >= 0``.

Westergaard (periodic, two-dimensional)
---------------------------------------
A rigid sinusoid ``h(x) = h_a cos(2 pi x / lambda)`` (uniform along ``y``) under
the mean pressure ``P0`` (Westergaard, J. Appl. Mech. 6, A49 (1939); Johnson,
*Contact Mechanics*, Cambridge University Press 1985, section 13.2).  With the
full-contact pressure ``p* = pi E* h_a / lambda`` and ``s^2 = P0 / p*``:

* contact half-width ``a``:  ``sin^2(pi a / lambda) = s^2``;
* pressure (``|x| < a``, ``x`` measured from a maximum of ``h``)::

      p(x) = (2 P0 / s^2) cos(pi x / lambda) sqrt(s^2 - sin^2(pi x / lambda));

* gap (``a <= |x| <= lambda / 2``, ``t = |sin(pi x / lambda)|``)::

      g(x) = 2 h_a [t sqrt(t^2 - s^2) - s^2 ln((t + sqrt(t^2 - s^2)) / s)];

  the gap slope ``g'(x) = (4 pi h_a / lambda) cos(pi x / lambda)
  sqrt(sin^2(pi x / lambda) - s^2)`` outside the contact is the analytic
  continuation of the pressure profile;
* mean gap (spatial average of ``g``)::

      g_bar = h_a (1 - s^2 + s^2 ln s^2),

  from ``d g_bar / d P0 = -(h_a / p*) ln(p* / P0)``, the load-displacement
  relation of the wavy surface (Johnson 1985, section 13.2); ``g_bar = h_a`` at
  first touch and 0 at full contact;
* elastic energy per unit nominal area, from ``d E_el / d g_bar = -P0 A0``::

      E_el / A0 = (h_a p* / 4) s^4 (1 - 2 ln s^2).

The gap and mean-gap expressions were derived here and checked against the
displacement of the exact pressure computed by a 2^18-point FFT (agreement to
1e-7 h_a, the quadrature error of the square-root edge).

Hertz (axisymmetric, isolated)
------------------------------
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


# ------------------------------------------------------------------ Westergaard
def _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus):
    p_star = westergaard_full_contact_pressure(amplitude, wavelength, contact_modulus)
    mean_pressure = float(mean_pressure)
    if not 0 <= mean_pressure <= p_star:
        raise ValueError(f"mean pressure {mean_pressure} outside [0, p* = {p_star}]: the "
                         f"Westergaard partial-contact solution needs 0 <= P0 <= p*")
    return mean_pressure / p_star, p_star


def westergaard_full_contact_pressure(amplitude, wavelength, contact_modulus):
    """Mean pressure ``p* = pi E* h_a / lambda`` that closes the gap everywhere.

    Parameters
    ----------
    amplitude : float
        ``h_a``, amplitude of ``h(x) = h_a cos(2 pi x / lambda)``.
    wavelength : float
        ``lambda``.
    contact_modulus : float
        ``E*``.

    References
    ----------
    Johnson, *Contact Mechanics* (1985), section 13.2; Westergaard (1939).
    """
    return math.pi * contact_modulus * amplitude / wavelength


def westergaard_contact_half_width(mean_pressure, amplitude, wavelength, contact_modulus):
    """Contact half-width ``a`` with ``sin^2(pi a / lambda) = P0 / p*``.

    Parameters
    ----------
    mean_pressure : float
        ``P0`` in ``[0, p*]``.
    amplitude, wavelength, contact_modulus : float
        ``h_a``, ``lambda``, ``E*``.

    Returns
    -------
    float
        ``a``; ``lambda / 2`` at full contact.
    """
    s2, _ = _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus)
    return wavelength / math.pi * math.asin(math.sqrt(s2))


def _wrapped(x, wavelength):
    """``x`` mapped to ``[-lambda/2, lambda/2)``, the period centred on the maximum of h."""
    x = np.asarray(x, dtype=float)
    return x - wavelength * np.floor(x / wavelength + 0.5)


def westergaard_pressure(x, mean_pressure, amplitude, wavelength, contact_modulus):
    """Contact pressure ``p(x)`` of the Westergaard solution.

    Parameters
    ----------
    x : array_like
        Positions; ``x = 0`` is a maximum of ``h`` (the solution is periodic).
    mean_pressure : float
        ``P0`` in ``[0, p*]``.
    amplitude, wavelength, contact_modulus : float
        ``h_a``, ``lambda``, ``E*``.

    Returns
    -------
    ndarray
        ``(2 P0 / s^2) cos(pi x / lambda) sqrt(s^2 - sin^2(pi x / lambda))`` in the
        contact, 0 outside (``s^2 = P0 / p*``).

    References
    ----------
    Johnson, *Contact Mechanics* (1985), section 13.2; Westergaard (1939).
    """
    s2, _ = _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus)
    psi = np.pi * _wrapped(x, wavelength) / wavelength
    if s2 == 0:
        return np.zeros_like(psi)
    inside = np.maximum(s2 - np.sin(psi) ** 2, 0.0)
    return (2 * mean_pressure / s2) * np.cos(psi) * np.sqrt(inside)


def westergaard_gap(x, mean_pressure, amplitude, wavelength, contact_modulus):
    """Gap ``g(x)`` of the Westergaard solution (0 in the contact).

    Parameters
    ----------
    x : array_like
        Positions; ``x = 0`` is a maximum of ``h``.
    mean_pressure : float
        ``P0`` in ``[0, p*]``.
    amplitude, wavelength, contact_modulus : float
        ``h_a``, ``lambda``, ``E*``.

    Returns
    -------
    ndarray
        ``2 h_a [t sqrt(t^2 - s^2) - s^2 ln((t + sqrt(t^2 - s^2)) / s)]`` with
        ``t = |sin(pi x / lambda)|`` outside the contact; at zero load the
        undeformed gap ``h_a (1 - cos(2 pi x / lambda))``.
    """
    s2, _ = _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus)
    t = np.abs(np.sin(np.pi * _wrapped(x, wavelength) / wavelength))
    if s2 == 0:
        return 2 * amplitude * t ** 2
    root = np.sqrt(np.maximum(t ** 2 - s2, 0.0))
    s = math.sqrt(s2)
    outside = t * root - s2 * np.log(np.maximum(t + root, s) / s)
    return 2 * amplitude * np.where(t ** 2 > s2, outside, 0.0)


def westergaard_mean_gap(mean_pressure, amplitude, wavelength, contact_modulus):
    """Mean gap ``g_bar = h_a (1 - s^2 + s^2 ln s^2)`` at the mean pressure ``P0``.

    Parameters
    ----------
    mean_pressure : float
        ``P0`` in ``[0, p*]``; ``s^2 = P0 / p*``.
    amplitude, wavelength, contact_modulus : float
        ``h_a``, ``lambda``, ``E*``.

    Returns
    -------
    float
        The spatial mean of :func:`westergaard_gap`; ``h_a`` at first touch, 0 at
        full contact.
    """
    s2, _ = _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus)
    if s2 == 0:
        return float(amplitude)
    return amplitude * (1.0 - s2 + s2 * math.log(s2))


def westergaard_mean_pressure(mean_gap, amplitude, wavelength, contact_modulus):
    """Inverse of :func:`westergaard_mean_gap`: the ``P0`` at which ``g_bar = mean_gap``.

    ``g_bar(P0)`` decreases strictly from ``h_a`` to 0 on ``[0, p*]``; it is
    inverted by bisection on ``s^2`` to round-off.

    Parameters
    ----------
    mean_gap : float
        In ``[0, h_a]``.
    amplitude, wavelength, contact_modulus : float
        ``h_a``, ``lambda``, ``E*``.
    """
    p_star = westergaard_full_contact_pressure(amplitude, wavelength, contact_modulus)
    target = float(mean_gap) / amplitude
    if not 0 <= target <= 1:
        raise ValueError(f"mean gap {mean_gap} outside [0, h_a = {amplitude}]")
    lo, hi = 0.0, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        value = 1.0 - mid + mid * math.log(mid) if mid > 0 else 1.0
        if value > target:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 4e-16 * hi:
            break
    return 0.5 * (lo + hi) * p_star


def westergaard_elastic_energy(mean_pressure, amplitude, wavelength, contact_modulus):
    """Elastic energy per unit nominal area, ``(h_a p* / 4) s^4 (1 - 2 ln s^2)``.

    Follows from ``d(E_el / A0) / d g_bar = -P0`` and :func:`westergaard_mean_gap`;
    at full contact it is ``pi E* h_a^2 / (4 lambda)``, the energy of the
    displacement ``h_a cos(2 pi x / lambda)``.
    """
    s2, p_star = _westergaard_s2(mean_pressure, amplitude, wavelength, contact_modulus)
    if s2 == 0:
        return 0.0
    return 0.25 * amplitude * p_star * s2 ** 2 * (1.0 - 2.0 * math.log(s2))


# ------------------------------------------------------------------------ Hertz
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
