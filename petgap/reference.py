"""Analytic reference solutions of frictionless elastic contact, without and with adhesion.

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

Johnson (periodic, two-dimensional, adhesive: the JKR limit)
------------------------------------------------------------
The same rigid sinusoid with adhesion of work ``w`` per unit area in the JKR
limit (interaction range -> 0; Johnson, "The adhesion of two elastic bodies with
slightly wavy surfaces", Int. J. Solids Struct. 32 (1995) 423).  The pressure is
Westergaard's plus the periodic flat-punch (Koiter) term that keeps the
displacement uniform over the contact ``|x| < a``,
``(P0 - p* sin^2(pi a / lambda)) cos(pi x / lambda) / sqrt(sin^2(pi a / lambda) -
sin^2(pi x / lambda))`` (unit mean), which is singular at the edge with the
stress intensity factor ``K = (p* sin^2(pi a / lambda) - P0) sqrt(lambda /
tan(pi a / lambda))``.  The Griffith condition of a crack between a rigid and an
elastic body, ``K^2 / (2 E*) = w`` (the ``E*`` of paper Eq. 4), gives::

    P0 / p* = sin^2(pi a / lambda) - alpha sqrt(tan(pi a / lambda)),
    alpha = sqrt(2 lambda w / (pi^2 E* h_a^2)) = sqrt(2 w E* / (p*^2 lambda))

(Johnson 1995; ``alpha^2`` compares the work of adhesion with the elastic
energy stored in flattening the wave).  The mean gap follows from the
compliance of the periodic punch, which is ``-d g_bar / d P0`` along the
Westergaard solution, ``-(2 h_a / p*) ln sin(pi a / lambda)``::

    g_bar / h_a = cos^2(pi a / lambda) + 2 (P0 / p*) ln sin(pi a / lambda),

the form also used by ContactEngineering's ``Adhesion`` reference solutions
(citing Carbone & Mangialardi, J. Mech. Phys. Solids 52 (2004) 1267).  With
``w = 0`` both reduce to Westergaard's ``P0 = p* s^2`` and
``g_bar = h_a (1 - s^2 + s^2 ln s^2)``.  ``P0(a)`` rises from 0 to a maximum
(jump into full contact under load control) and falls again to ``-inf`` as
``a -> lambda / 2``; its minimum near small ``a`` is the pull-off load.  Under
load control only the rising part between them is stable; under mean-gap
control every ``a`` beyond the maximum of ``g_bar(a)`` is (``g_bar`` decreases
there).  For ``alpha`` above about 0.57 the maximum load is negative: the
surfaces jump into full contact without load (Johnson 1995).

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


# ---------------------------------------------------------------------- Johnson
def johnson_parameter(work, amplitude, wavelength, contact_modulus):
    """Johnson's ``alpha = sqrt(2 lambda w / (pi^2 E* h_a^2))`` of an adhesive wave.

    Parameters
    ----------
    work : float
        Work of adhesion ``w`` (energy per area), ``>= 0``.
    amplitude, wavelength, contact_modulus : float
        ``h_a`` (of ``h = h_a cos(2 pi x / lambda)``), ``lambda``, ``E*``.

    References
    ----------
    Johnson, Int. J. Solids Struct. 32 (1995) 423.
    """
    work = float(work)
    if not work >= 0:
        raise ValueError(f"work of adhesion {work} < 0")
    return math.sqrt(2.0 * wavelength * work / (math.pi ** 2 * contact_modulus * amplitude ** 2))


def _johnson_theta(half_width, wavelength):
    theta = np.pi * np.asarray(half_width, dtype=float) / wavelength
    if np.any((theta < 0) | (theta > 0.5 * np.pi)):
        raise ValueError(f"contact half-width outside [0, lambda / 2 = {0.5 * wavelength}]")
    return theta


def johnson_mean_pressure(half_width, work, amplitude, wavelength, contact_modulus):
    """Mean pressure ``P0 = p* [sin^2(pi a / lambda) - alpha sqrt(tan(pi a / lambda))]``.

    The JKR equilibrium of the adhesive wave with contact half-width ``a``
    (module docstring; Johnson 1995).  ``-inf`` at ``a = lambda / 2``.

    Parameters
    ----------
    half_width : float or array_like
        ``a`` in ``[0, lambda / 2]``.
    work, amplitude, wavelength, contact_modulus : float
        ``w``, ``h_a``, ``lambda``, ``E*``.
    """
    theta = _johnson_theta(half_width, wavelength)
    alpha = johnson_parameter(work, amplitude, wavelength, contact_modulus)
    p_star = westergaard_full_contact_pressure(amplitude, wavelength, contact_modulus)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.tan(np.minimum(theta, 0.5 * np.pi)))
        root = np.where(theta >= 0.5 * np.pi, np.inf, root)
        out = p_star * (np.sin(theta) ** 2 - (alpha * root if alpha > 0 else 0.0))
    return float(out) if np.ndim(out) == 0 else out


def johnson_mean_gap(half_width, work, amplitude, wavelength, contact_modulus):
    """Mean gap ``h_a [cos^2(pi a / lambda) + 2 (P0 / p*) ln sin(pi a / lambda)]`` at equilibrium.

    ``P0`` is :func:`johnson_mean_pressure` at the same ``a``; ``h_a`` at
    ``a = 0`` and 0 at ``a = lambda / 2``.
    """
    theta = _johnson_theta(half_width, wavelength)
    p_star = westergaard_full_contact_pressure(amplitude, wavelength, contact_modulus)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = johnson_mean_pressure(half_width, work, amplitude, wavelength,
                                      contact_modulus) / p_star
        log_sin = np.log(np.sin(theta))
        out = np.cos(theta) ** 2 + 2.0 * ratio * log_sin
        # limits: a -> 0 (the log term vanishes like sqrt(a) ln a) and a -> lambda / 2
        # (it vanishes like (lambda / 2 - a)^(3/2))
        out = np.where(theta <= 0, 1.0, np.where(theta >= 0.5 * np.pi, 0.0, out))
    out = amplitude * out
    return float(out) if np.ndim(out) == 0 else out


def _bisect(func, lo, hi, increasing, iterations=200):
    """Root of a monotone ``func`` on ``[lo, hi]`` (in ``theta``), to round-off."""
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if (func(mid) < 0) == increasing:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 4e-16 * hi:
            break
    return 0.5 * (lo + hi)


def _johnson_extrema(derivative, samples=20001):
    """``theta`` of the sign changes of ``derivative`` on ``(0, pi / 2)``, refined by bisection."""
    theta = np.linspace(0.0, 0.5 * np.pi, samples)[1:-1]
    d = derivative(theta)
    roots = []
    for k in np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]:
        rising = d[k] < 0  # derivative goes from - to +: a minimum
        roots.append((_bisect(derivative, theta[k], theta[k + 1], increasing=rising),
                      "min" if rising else "max"))
    return roots


def johnson_load_limits(work, amplitude, wavelength, contact_modulus):
    """Where load control loses the wave's adhesive contact: ``(a, P0)`` at pull-off and jump-in.

    ``P0(a)`` (:func:`johnson_mean_pressure`) has a minimum at small ``a``
    (pull-off: below it no partial contact carries the load and the surfaces
    separate) and a maximum (jump into full contact).  Between them ``P0``
    increases with ``a``: the branch that is stable under load control.

    Returns
    -------
    dict
        ``a_pull_off``, ``p_pull_off``, ``a_jump_in``, ``p_jump_in``.

    Raises
    ------
    ValueError
        For ``w = 0`` (no extrema: Westergaard) or if the extrema have merged.
    """
    alpha = johnson_parameter(work, amplitude, wavelength, contact_modulus)

    def slope(theta):
        return np.sin(2 * theta) - alpha / (2 * np.cos(theta) ** 2 * np.sqrt(np.tan(theta)))
    found = _johnson_extrema(slope)
    kinds = [k for _, k in found]
    if alpha <= 0 or kinds != ["min", "max"]:
        raise ValueError(f"alpha = {alpha:g}: the load has no pull-off minimum followed by a "
                         f"jump-in maximum (found {kinds})")
    a_off, a_in = (wavelength * t / np.pi for t, _ in found)
    args = (work, amplitude, wavelength, contact_modulus)
    return {"a_pull_off": a_off, "p_pull_off": johnson_mean_pressure(a_off, *args),
            "a_jump_in": a_in, "p_jump_in": johnson_mean_pressure(a_in, *args)}


def johnson_contact_half_width(mean_pressure, work, amplitude, wavelength, contact_modulus):
    """Half-width ``a`` on the load-stable branch (pull-off to jump-in) carrying ``P0``.

    Raises ValueError outside ``[P0 at pull-off, P0 at jump-in]``.
    """
    limits = johnson_load_limits(work, amplitude, wavelength, contact_modulus)
    p0 = float(mean_pressure)
    if not limits["p_pull_off"] <= p0 <= limits["p_jump_in"]:
        raise ValueError(f"mean pressure {p0} outside the load-stable range "
                         f"[{limits['p_pull_off']}, {limits['p_jump_in']}]")
    args = (work, amplitude, wavelength, contact_modulus)
    theta = _bisect(lambda t: johnson_mean_pressure(wavelength * t / np.pi, *args) - p0,
                    np.pi * limits["a_pull_off"] / wavelength,
                    np.pi * limits["a_jump_in"] / wavelength, increasing=True)
    return wavelength * theta / np.pi


def johnson_gap_limit(work, amplitude, wavelength, contact_modulus):
    """``(a, g_bar)`` at the maximum of ``g_bar(a)``: pull-off under mean-gap control.

    For larger ``a`` the mean gap decreases monotonically to 0 at full contact,
    the branch that is stable under mean-gap control; above this mean gap no
    contact holds.
    """
    alpha = johnson_parameter(work, amplitude, wavelength, contact_modulus)

    def slope(theta):
        f = np.sin(theta) ** 2 - alpha * np.sqrt(np.tan(theta))
        df = np.sin(2 * theta) - alpha / (2 * np.cos(theta) ** 2 * np.sqrt(np.tan(theta)))
        return -np.sin(2 * theta) + 2 * df * np.log(np.sin(theta)) + 2 * f / np.tan(theta)
    found = [t for t, kind in _johnson_extrema(slope) if kind == "max"]
    if alpha <= 0 or len(found) != 1:
        raise ValueError(f"alpha = {alpha:g}: the mean gap has no single maximum")
    a = wavelength * found[0] / np.pi
    return a, johnson_mean_gap(a, work, amplitude, wavelength, contact_modulus)


def johnson_half_width_at_mean_gap(mean_gap, work, amplitude, wavelength, contact_modulus):
    """Half-width ``a`` on the gap-stable branch (beyond :func:`johnson_gap_limit`) at ``g_bar``."""
    a_lim, g_lim = johnson_gap_limit(work, amplitude, wavelength, contact_modulus)
    target = float(mean_gap)
    if not 0 <= target <= g_lim:
        raise ValueError(f"mean gap {target} outside the gap-stable range [0, {g_lim}]")
    args = (work, amplitude, wavelength, contact_modulus)
    theta = _bisect(lambda t: johnson_mean_gap(wavelength * t / np.pi, *args) - target,
                    np.pi * a_lim / wavelength, 0.5 * np.pi, increasing=False)
    return wavelength * theta / np.pi
