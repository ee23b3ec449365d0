"""From solved fields to the paper's quantities: contact area, perimeter, gaps, adhesion.

Modules: :mod:`.contact_geometry` (contact set, perimeter, ``d_rep``, ``g0``),
:mod:`.gap_distribution` (``p(g)``, its collapse onto Eq. 13, power-law fits,
the near-contact area of Eq. 14), :mod:`.adhesion` (the attractive force, Eqs.
15-16, ``1 / kappa_att``), :mod:`.load_curves` (``kappa_rep`` and the exponential mean-gap law
of a load sweep), :mod:`.maps` (fields
block-averaged for display), :mod:`.patches` (the connected contact
patches, their areas and perimeters), :mod:`.components` (connected components across
slabs and seams, and whether they wrap round the cell), :mod:`.percolation` (the open
clusters of the gap and whether they cross the map), :mod:`.of_solution` (the same applied to a problem and
its solution) and :mod:`._slabs` (slab bookkeeping shared by them).

Every function works on a :class:`~petgap.parallel.grid.Grid`'s row slabs, ``(nx_local, ny)``,
and returns global results that are the same on every rank (all functions are
collective).  Nothing is ever gathered on one rank: what crosses a slab boundary
(neighbouring pixels of the perimeter) is fetched as a few halo rows, and
histograms and sums are reduced.

The functions take a grid and field slabs, so that they apply to fields read
back from a result file as well as to a fresh solution; the ``*_of(problem,
solution)`` forms of :mod:`.of_solution` take a solved problem instead.

Equation numbers are those of the paper the project implements, "Distribution of gaps
and adhesive interaction between contacting rough surfaces" (Monti, Sanner &
Pastewka, Tribology Letters, 2021, doi:10.1007/s11249-021-01454-6).

Conventions
-----------
* Gap ``g >= 0`` (length), pressure ``p`` positive in compression, pixel area
  ``dx dy``, nominal area ``A0 = Lx Ly``, ``N = nx ny`` pixels, periodic in x and y.
* Repulsive contact: zero gap, ``g <= gap_tolerance``, **and** ``p > 0``.  A pixel
  at zero gap under tension (adhesive solutions) is *not* in repulsive contact.
  ``A_rep = dx dy * (number of contact pixels)``, ``c = A_rep / A0``.  The default
  tolerance is ``GAP_ROUND_OFF = 1e-6`` times the mean gap (:func:`resolve_gap_tolerance`):
  a solver that computes the gap as ``d + u - h`` leaves round-off gaps of order its
  tolerance (``~1e-9`` of ``h0``) on contact pixels -- on a rough contact, a large share
  of them -- while physical gaps next to a contact edge are many orders larger
  (``g ~ g0 (s / d_rep)^(3/2)``).
* Perimeter ``P_rep``: length of the marching-squares contour of the contact set
  with crossings placed by the universal square-root / three-halves asymptotics
  of a smooth contact edge (:func:`perimeter`).  ``d_rep = pi A_rep / P_rep``
  (Eq. 2), ``g0 = 4 h0' d_rep / 3`` (Eq. 12).
* Gap distribution: densities are per unit gap and normalised over the
  *non-contacting* pixels (their integral is 1 when no pixel sits at zero gap
  outside repulsive contact); the full distribution of the paper's Eq. 9 for
  ``g > 0`` is ``(1 - c)`` times it.
* Interaction stress ``v'(g) > 0`` is tensile (``v = -w exp(-g / rho)``, Eq. 6);
  attractive forces are negative: ``F_att = -sum_x dx dy v'(g(x)) < 0``, and
  ``1 / kappa_att = -F_att / (h0' E* A_rep) > 0`` (the paper's Fig. 3 convention).
"""

from petgap.analysis.contact_geometry import (  # noqa: F401  (the package's API)
    contact_mask, resolve_gap_tolerance, GAP_ROUND_OFF, perimeter, crossing_fraction, contact_statistics, PerimeterResult, ContactStatistics)
from petgap.analysis.gap_distributions import (  # noqa: F401  (the package's API)
    gap_distribution, collapse, fit_power_law, resolved_gap, auto_fit_range, FitRange, near_contact_area, near_contact_area_eq14, GapDistribution, PowerLawFit, NearContactArea,
    BINS_PER_DECADE, DEFAULT_RANGE, FIT_RESOLUTION_FACTOR, FIT_X_MAX, FIT_SLOPE_BAND,
    FIT_SLOPE_WINDOW, FIT_MIN_DECADES, FIT_MIN_COUNT, FIT_SIGMAS)
from petgap.analysis.adhesion import (  # noqa: F401  (the package's API)
    attractive_force_measured, attractive_force_eq16, inverse_kappa_att, fig4_integrand, AttractiveForce, Eq16Force, GAMMA_2_3,
    attractive_force_by_gap, ForceByGap)
from petgap.analysis.patches import contact_patches, Patches  # noqa: F401  (the package's API)
from petgap.analysis.components import label_components, Components  # noqa: F401  (the package's API)
from petgap.analysis.percolation import open_clusters, Percolation  # noqa: F401  (the package's API)
from petgap.analysis.load_curves import fit_kappa_rep, fit_gap_law, KappaFit, GapLawFit, KAPPA_C_MAX  # noqa: F401  (the package's API)
from petgap.analysis.maps import block_map, decimation_factor, Map, MAX_PIXELS  # noqa: F401  (the package's API)
from petgap.analysis.of_solution import (  # noqa: F401  (the package's API)
    contact_statistics_of, gap_distribution_of, attractive_force_of, near_contact_area_of)

__all__ = ["contact_mask", "resolve_gap_tolerance", "GAP_ROUND_OFF", "perimeter",
           "crossing_fraction", "contact_statistics",
           "gap_distribution", "collapse", "fit_power_law", "resolved_gap", "auto_fit_range",
           "FitRange", "near_contact_area",
           "near_contact_area_eq14", "attractive_force_measured", "attractive_force_eq16",
           "inverse_kappa_att", "fig4_integrand", "attractive_force_by_gap", "ForceByGap", "PerimeterResult", "ContactStatistics",
           "GapDistribution", "PowerLawFit", "NearContactArea", "AttractiveForce",
           "Eq16Force", "GAMMA_2_3", "contact_statistics_of", "gap_distribution_of",
           "attractive_force_of", "near_contact_area_of", "contact_patches", "Patches",
           "label_components", "Components", "open_clusters", "Percolation",
           "block_map", "decimation_factor", "Map", "MAX_PIXELS",
           "fit_kappa_rep", "fit_gap_law", "KappaFit", "GapLawFit", "KAPPA_C_MAX", "BINS_PER_DECADE", "DEFAULT_RANGE",
           "FIT_RESOLUTION_FACTOR", "FIT_X_MAX", "FIT_SLOPE_BAND", "FIT_SLOPE_WINDOW",
           "FIT_MIN_DECADES", "FIT_MIN_COUNT", "FIT_SIGMAS"]
