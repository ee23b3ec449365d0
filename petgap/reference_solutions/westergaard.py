"""Westergaard's periodic wavy contact (two-dimensional, non-adhesive).

Conventions are those of :mod:`petgap.mechanics.problem`: a rigid surface of height ``h`` is pressed onto
an elastic half-space of contact modulus ``E*``; pressures are positive in compression; the gap is
``g = d + u - h >= 0``.

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
"""
import math

import numpy as np


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


