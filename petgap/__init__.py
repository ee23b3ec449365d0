"""petgap: gap distributions and adhesion between rough elastic surfaces.

MPI-parallel contact mechanics of a rigid rough surface pressed onto an elastic
half-space, with or without adhesion, on FFTW-MPI slabs with PETSc TAO solvers;
and the analysis of the paper it implements: Monti, Sanner & Pastewka,
"Distribution of gaps and adhesive interaction between contacting rough
surfaces", Tribology Letters (2021), doi:10.1007/s11249-021-01454-6.

Example
-------
Serially, or the same script on every rank of ``mpirun -n P``::

    import petgap

    grid = petgap.Grid((128, 128), size=(1.0, 1.0), planner="estimate")
    heights = petgap.self_affine(grid, hurst=0.8, lambda_min=8 * grid.dx, rms_slope=0.1,
                                 seed=1)  # this rank's rows of the surface
    problem = petgap.ContactProblem(grid, heights, petgap.ElasticHalfSpace(grid, 1.0))
    solution = petgap.solve(problem, petgap.Load(0.01 * problem.pressure_scale))
    stats = petgap.contact_statistics_of(problem, solution)
    print(solution.converged, solution.contact_fraction, stats.mean_diameter, stats.g0)

or in one call, from a global height array that every rank holds:
``petgap.contact(heights, pixel_size, load=...)``.  ``docs/tutorial.md`` walks
from a surface to a figure.

The public API
--------------
The package is laid out along the data flow of a run, each subpackage
importing only from those before it:

``petgap.parallel``
    :class:`Grid` (owns the communicator, the slab decomposition and the FFT).
``petgap.surfaces``
    :func:`self_affine`, :func:`statistics`, :func:`radial_psd`,
    :func:`load_topography`, :func:`save_topography_npy`, :func:`read_measured` (an
    instrument's file, with its size, unit and periodicity).
``petgap.io``
    :class:`Scene` (a run described by a TOML file), :class:`SceneError`.
``petgap.mechanics``
    :class:`ElasticHalfSpace` (periodic), :class:`FreeHalfSpace` (no images),
    the interaction laws :class:`HardWall`, :class:`ExponentialAdhesion`,
    :class:`MaugisDugdaleAdhesion`, :class:`LennardJones93Adhesion`,
    :class:`SquaredExponentialAdhesion`, the controls :class:`Load`,
    :class:`MeanGap` and :class:`Indentation`, :class:`ContactProblem`,
    :class:`ContactSolution`.
``petgap.solvers``
    :func:`solve`, :func:`sweep`.
``petgap.analysis``
    :func:`contact_statistics_of`, :func:`gap_distribution_of`,
    :func:`attractive_force_of`, :func:`near_contact_area_of` on a problem and
    its solution; :func:`contact_statistics`, :func:`gap_distribution`,
    :func:`collapse`, :func:`fit_power_law`, :func:`attractive_force_measured`,
    :func:`contact_patches` (patch count, areas, perimeters), :func:`block_map`
    (a field block-averaged for display), :func:`fit_kappa_rep` and
    :func:`fit_gap_law` (the laws of a load sweep),
    ... on a grid and field slabs (:mod:`petgap.analysis` has them all).
``petgap.flow``
    :func:`leakage_of` (leak rate, transmissivity, flow factor, percolation, pressure and
    flux maps of a solved contact, by the Reynolds equation on its gap), :func:`leakage`
    (the same on a grid and a gap slab), :class:`Leakage`.
``petgap.reference_solutions``
    Westergaard, Hertz and Johnson closed forms (the module itself).
``petgap.app``
    :func:`load_scene` (a scene file, with what its topography file says filled in),
    :func:`run_scene` (what ``petgap run`` does), :func:`contact` (the one-call
    solve, returning a :class:`ContactResult`).

Fields are always a rank's slab of rows, shape ``grid.local_shape``, except
where a function says it takes or returns a global array; scalars are global
and the same on every rank; every function that communicates is collective.

Importing petgap loads its modules (and NumPy, mpi4py, petsc4py and the
FFTW-MPI binding, which initialise MPI, PETSc and FFTW-MPI as they load) and
does one thing more: it lets the C library return freed fields to the system,
which a library PETSc loads turns off (:mod:`petgap.parallel.memory`).  PETSc
options for a solve go in ``solve(..., options={...})``; to hand PETSc a script's
command line instead, call ``petsc4py.init(sys.argv)`` before ``import petgap``.
"""
from petgap._version import __version__  # noqa: E402

from petgap import analysis, reference_solutions  # noqa: E402
from petgap.analysis import (  # noqa: E402
    attractive_force_eq16, attractive_force_measured, attractive_force_of, collapse,
    contact_statistics, contact_statistics_of, fit_power_law, gap_distribution,
    gap_distribution_of, inverse_kappa_att, near_contact_area, near_contact_area_of,
    contact_patches, block_map, fit_kappa_rep, fit_gap_law)
from petgap.flow import Leakage, leakage, leakage_of  # noqa: E402
from petgap.app import ContactResult, run_scene  # noqa: E402
from petgap.app.build import load_scene  # noqa: E402
from petgap.app.contact import contact  # noqa: E402  (petgap.app keeps the module's name)
from petgap.io import Scene, SceneError  # noqa: E402
from petgap.mechanics import (  # noqa: E402
    ContactProblem, ContactSolution, ElasticHalfSpace, ExponentialAdhesion, FreeHalfSpace,
    HardWall, Indentation, LennardJones93Adhesion, Load, MaugisDugdaleAdhesion, MeanGap,
    SquaredExponentialAdhesion)
from petgap.parallel import Grid  # noqa: E402
from petgap.solvers import solve, sweep  # noqa: E402
from petgap.surfaces import (load_topography, radial_psd, read_measured,  # noqa: E402
                             save_topography_npy)
from petgap.surfaces.statistics import statistics  # noqa: E402  (petgap.surfaces keeps the module)
from petgap.surfaces.self_affine import self_affine  # noqa: E402  (the module's name)
from petgap.parallel.memory import return_freed_memory  # noqa: E402

return_freed_memory()

__all__ = [
    "__version__",
    # parallel
    "Grid",
    # surfaces
    "self_affine", "statistics", "radial_psd", "load_topography", "save_topography_npy",
    "read_measured",
    # io
    "Scene", "SceneError",
    # mechanics
    "ElasticHalfSpace", "FreeHalfSpace", "HardWall", "ExponentialAdhesion",
    "MaugisDugdaleAdhesion", "LennardJones93Adhesion", "SquaredExponentialAdhesion", "Load",
    "MeanGap", "Indentation",
    "ContactProblem", "ContactSolution",
    # solvers
    "solve", "sweep",
    # analysis
    "analysis", "contact_statistics_of", "gap_distribution_of", "attractive_force_of",
    "near_contact_area_of", "contact_statistics", "gap_distribution", "collapse",
    "fit_power_law", "near_contact_area", "attractive_force_measured",
    "attractive_force_eq16", "inverse_kappa_att", "contact_patches", "block_map",
    "fit_kappa_rep", "fit_gap_law",
    # flow
    "leakage", "leakage_of", "Leakage",
    # reference solutions
    "reference_solutions",
    # app
    "load_scene", "run_scene", "contact", "ContactResult",
]
