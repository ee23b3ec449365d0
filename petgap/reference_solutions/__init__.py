"""Analytic reference solutions of frictionless elastic contact, without and with adhesion.

Tests and users compare the numerical solutions against these closed forms (as
ContactMechanics' ``ReferenceSolutions``).  Conventions are those of
:mod:`petgap.mechanics.problem`: a rigid surface of height ``h`` is pressed onto an
elastic half-space of contact modulus ``E*`` (paper Eq. 4); contact occurs at
the maxima of ``h``; pressures are positive in compression; the gap is
``g = d + u - h >= 0``.

One module per solution: :mod:`.westergaard`, :mod:`.johnson`, :mod:`.hertz`, :mod:`.maugis`.
"""
from petgap.reference_solutions.westergaard import (  # noqa: F401
    westergaard_full_contact_pressure,
    westergaard_contact_half_width,
    westergaard_pressure,
    westergaard_gap,
    westergaard_mean_gap,
    westergaard_mean_pressure,
    westergaard_elastic_energy)
from petgap.reference_solutions.hertz import (  # noqa: F401
    hertz_contact_radius,
    hertz_max_pressure,
    hertz_penetration,
    hertz_pressure,
    hertz_gap)
from petgap.reference_solutions.johnson import (  # noqa: F401
    johnson_parameter,
    johnson_mean_pressure,
    johnson_mean_gap,
    johnson_load_limits,
    johnson_contact_half_width,
    johnson_gap_limit,
    johnson_half_width_at_mean_gap)
from petgap.reference_solutions.maugis import (  # noqa: F401
    maugis_parameter,
    maugis_state,
    maugis_pull_off,
    maugis_pull_off_force)

__all__ = ["westergaard_full_contact_pressure", "westergaard_contact_half_width",
           "westergaard_pressure", "westergaard_gap", "westergaard_mean_gap",
           "westergaard_mean_pressure", "westergaard_elastic_energy",
           "hertz_contact_radius", "hertz_max_pressure", "hertz_penetration", "hertz_pressure",
           "hertz_gap", "johnson_parameter", "johnson_mean_pressure", "johnson_mean_gap",
           "johnson_load_limits", "johnson_contact_half_width", "johnson_gap_limit",
           "johnson_half_width_at_mean_gap", "maugis_parameter", "maugis_state",
           "maugis_pull_off", "maugis_pull_off_force"]
