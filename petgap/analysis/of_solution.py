"""The analysis functions applied to a solved problem: ``f_of(problem, solution)``.

The functions of :mod:`petgap.analysis` take a grid and field slabs, so that
they apply to fields read back from a result file as well as to fresh ones.
For a solution in hand, these take the :class:`~petgap.mechanics.problem.ContactProblem`
and its :class:`~petgap.mechanics.problem.ContactSolution` instead, and pass on
the grid, the gap and pressure slabs, the rms slope ``h0'``, the contact modulus
``E*`` and the interaction the problem already holds, so none of them can be
passed inconsistently.  All are collective and return the same value on every rank.
"""
from petgap.analysis.adhesion import AttractiveForce, attractive_force_measured
from petgap.analysis.contact_geometry import PERIMETER_SWEEPS, contact_statistics
from petgap.analysis.gap_distributions import BINS_PER_DECADE, gap_distribution, near_contact_area


def contact_statistics_of(problem, solution, *, gap_tolerance=None, sweeps=PERIMETER_SWEEPS):
    """:func:`~petgap.analysis.contact_statistics` of a solution: ``c``, ``P_rep``, ``d_rep``, ``g0``.

    Uses the problem's spectral rms slope ``h0'`` and its half-space's ``E*``.

    Returns
    -------
    petgap.analysis.ContactStatistics
    """
    return contact_statistics(problem.grid, solution.gap, solution.pressure, problem.rms_slope,
                              problem.half_space.contact_modulus, gap_tolerance=gap_tolerance,
                              sweeps=sweeps, periodic=problem.half_space.periodic)


def gap_distribution_of(problem, solution, bins=None, gmin=None, gmax=None, *,
                        bins_per_decade=BINS_PER_DECADE, gap_tolerance=None):
    """:func:`~petgap.analysis.gap_distribution` of a solution (arguments as there).

    Returns
    -------
    petgap.analysis.GapDistribution
    """
    return gap_distribution(problem.grid, solution.gap, solution.pressure, bins, gmin, gmax,
                            bins_per_decade=bins_per_decade, gap_tolerance=gap_tolerance)


def attractive_force_of(problem, solution, *, gap_tolerance=None):
    """:func:`~petgap.analysis.attractive_force_measured` of a solution (Eq. 15), split by contact.

    The interaction stress ``v'(g)`` is the problem's own.  A hard wall exerts
    no attractive force: all parts are then zero.

    Returns
    -------
    petgap.analysis.AttractiveForce
    """
    if not problem.interaction.adhesive:
        return AttractiveForce(force=0.0, per_area=0.0, contact_force=0.0, noncontact_force=0.0)
    return attractive_force_measured(problem.grid, solution.gap, problem.interaction,
                                     solution.pressure, gap_tolerance=gap_tolerance)


def near_contact_area_of(problem, solution, gc, g0=None, *, gap_tolerance=None):
    """:func:`~petgap.analysis.near_contact_area` of a solution against Eq. 14.

    ``g0`` (from :func:`contact_statistics_of`) is needed for the prediction;
    the contact fraction is the measured one.

    Returns
    -------
    petgap.analysis.NearContactArea
    """
    return near_contact_area(problem.grid, solution.gap, solution.pressure, gc, g0=g0,
                             gap_tolerance=gap_tolerance)
