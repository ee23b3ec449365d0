"""Johnson's adhesive wavy contact (periodic, two-dimensional, the JKR limit).

Conventions are those of :mod:`petgap.mechanics.problem`: a rigid surface of height ``h`` is pressed onto
an elastic half-space of contact modulus ``E*``; pressures are positive in compression; the gap is
``g = d + u - h >= 0``.

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
"""
import math

import numpy as np

from petgap.reference_solutions.westergaard import westergaard_full_contact_pressure


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
