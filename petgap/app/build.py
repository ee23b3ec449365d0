"""From a scene to the objects that are solved: one builder for every caller.

``petgap run``, ``petgap study``, the benchmarks and the tests all turn a
:class:`~petgap.io.scene.Scene` into the same objects the same way, so that a
number measured by one of them is a number of the others::

    scene -> grid -> topography -> half-space (periodic or free) -> problems (hard wall, adhesive)
          -> planned steps (petgap.app.protocol) -> sweep (petgap.solvers.sweeps)

A scene made in code works as one read from a file::

    scene = Scene.from_dict({"grid": {"nx": 256}, "surface": {"hurst": 0.8,
                             "lambda_min": 32, "rms_slope": 0.1},
                             "control": {"kind": "load", "values": [0.01]}})
    model = build(scene, comm)
    states = list(model.sweep())
"""
import contextlib
import dataclasses
import functools
import gc
import math
import resource
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from petgap.app import protocol
from petgap.io import solver_registry as registry
from petgap.io.scene import Scene, SceneError
from petgap.mechanics.free_half_space import FreeHalfSpace
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics import plausibility
from petgap.mechanics.interactions import check_resolution, from_scene
from petgap.mechanics.problem import ContactProblem
from petgap.parallel.grid import Grid, check_decomposition
from petgap.parallel.log import get_logger, timed
from petgap.solvers.sweeps import SweepStep, sweep
from petgap.solvers.options import check_petsc_options
from petgap.surfaces.indenters import KINDS as INDENTERS, indenter
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.statistics import low_pass
from petgap.surfaces.statistics import finite_difference_curvature, finite_difference_slopes
from petgap.surfaces.statistics import statistics as surface_statistics
from petgap.surfaces.topography import load_topography, map_header


#: How much the wrap-around pairs may raise the finite-difference rms slope of a map
#: before its edges count as not matching (a periodic surface: well under 1 %).
SEAM_TOLERANCE = 0.05


def seam_warning(stats, path):
    """The warning for a map solved as periodic whose opposite edges do not match, or "".

    The finite-difference rms slope across the cell's edges exceeds the one inside the
    map by more than :data:`SEAM_TOLERANCE`: the seam is a cliff the periodic images
    put into the surface, which raises ``h0'`` (and with it the KKT scale, ``g0`` and
    ``kappa``) and draws contact to the seam.
    """
    if stats.rms_slope_fd is None or not stats.rms_slope_fd > (1 + SEAM_TOLERANCE) * \
            stats.rms_slope_fd_inner:
        return ""
    return (f"surface from {path}: its opposite edges do not match: rms slope "
            f"{stats.rms_slope:.4g} spectrally and {stats.rms_slope_fd:.4g} by finite "
            f"differences across the edges of the periodic cell, but "
            f"{stats.rms_slope_fd_inner:.4g} inside the map; solved as periodic, the seam "
            f"is a cliff in the surface: solve it on a free boundary (surface.periodic = "
            f"false), remove the trend (surface.detrend = \"height\" or \"curvature\") or "
            f"cut the map so that its edges match")


def used_rms_slope(stats, periodic):
    """The ``h0'`` the solve's scales and the analysis use: spectral on a periodic cell, by
    finite differences inside the map on a free boundary (where the cell's seam is no part
    of the surface; :class:`petgap.mechanics.problem.ContactProblem`)."""
    return stats.rms_slope if periodic or stats.rms_slope_fd_inner is None \
        else stats.rms_slope_fd_inner


def plausibility_findings(scene, rms_slope):
    """What :mod:`petgap.mechanics.plausibility` finds implausible about a scene whose
    surface has the rms slope ``rms_slope``: its slope, and each load it imposes."""
    findings = plausibility.slope_findings(
        rms_slope, None if scene.units.length == "1" else scene.units.length)
    loads = [step.control.value for step in protocol.plan(scene)
             if step.control is not None and step.control.kind == "load"]
    for load in sorted(set(loads), reverse=True)[:1]:    # the largest load speaks for all
        findings += plausibility.load_findings(load, rms_slope,
                                               scene.material.contact_modulus)
    return findings


def load_scene(path, comm=None):
    """A scene file, validated, with what its topography file says filled in.

    :meth:`petgap.io.scene.Scene.from_file` with the reader of topography files
    (:func:`petgap.surfaces.topography.map_header`): a scene of ``surface.kind = "file"``
    may leave out ``grid.nx``, ``grid.ny`` and, if the file knows its physical size,
    the pixel size, which the file then gives.  Collective, like ``from_file``.
    """
    return Scene.from_file(path, comm, read_header=map_header)


def fft_planner(scene, steps=None):
    """The FFTW planner effort of a scene's grids, and why: ``(planner, reason)``.

    ``solver.planner = "auto"`` chooses by the work ahead: a run of one solve
    (``steps``, default the scene's planned steps) takes ``estimate``, which plans at
    once, since ``measure`` times candidate plans for longer than faster transforms
    save over a few dozen of them; a sweep takes ``measure``, whose plans each step
    reuses and which later runs of the size read from the wisdom cache.
    """
    asked = scene.solver.planner
    if asked != "auto":
        return asked, "solver.planner"
    count = len(protocol.plan(scene) if steps is None else steps)
    if count > 1:
        return "measure", f"auto: {count} solves ahead, plans kept as wisdom"
    return "estimate", "auto: one solve ahead; solver.planner = \"measure\" for faster transforms"


def make_grid(scene, comm, precision="double", planner=None):
    """The :class:`~petgap.parallel.grid.Grid` of a scene on ``comm``.

    ``precision`` of its fields (see :func:`build` for when a scene's grid is
    single); ``planner`` overrides the scene's FFTW planner effort
    (:func:`fft_planner`).
    """
    g = scene.grid
    return Grid((g.nx, g.ny), size=g.size, comm=comm,
                planner=fft_planner(scene)[0] if planner is None else planner,
                precision=precision)


def make_surface(scene, grid):
    """This rank's slab of the scene's topography."""
    s = scene.surface
    if s.kind == "self-affine":
        return self_affine(grid, s.hurst, s.lambda_min, s.lambda_max,
                           rms_slope=s.rms_slope, rms_height=s.rms_height, seed=s.seed)
    if s.kind == "file":
        unit = None if scene.units.length == "1" else scene.units.length
        heights = load_topography(grid, s.path, s.dataset, channel=s.channel, unit=unit,
                                  detrend=s.detrend, undefined=s.undefined)
        return heights if s.lambda_cutoff is None else \
            low_pass(grid, heights, 2 * math.pi / s.lambda_cutoff)
    if s.kind in INDENTERS:
        return indenter(grid, s.kind, s.radius)
    raise ValueError(f"surface.kind = {s.kind!r} is not implemented")  # the schema prevents it


def petsc_options_dict(args):
    """``["-a", "1", "-b"]`` -> ``{"a": "1", "b": ""}`` (a negative number is a value)."""
    options, i = {}, 0
    args = list(args)
    while i < len(args):
        name = args[i].lstrip("-")
        if i + 1 < len(args) and not (args[i + 1].startswith("-") and
                                      not _is_number(args[i + 1])):
            options[name] = args[i + 1]
            i += 2
        else:
            options[name] = ""
            i += 1
    return options


def check_options(scene, petsc_args=(), strict=False, log=None):
    """Check the scene's ``solver.petsc_options`` and the command line's PETSc options.

    A malformed value of an option petgap reads (``-tao_max_it notanumber``)
    or an unsupported ``-tao_type`` is a :class:`~petgap.io.scene.SceneError`
    naming the option, its value, where it was given and what is allowed.  An
    option petgap does not read (a misspelling: ``-tao_monitr``) is a warning
    naming it, or with ``strict`` an error.  Pure and the same on every rank.
    """
    sources = (("solver.petsc_options", dict(scene.solver.petsc_options)),
               ("the command line after --", petsc_options_dict(petsc_args)))
    errors, unknown = [], []
    for where, options in sources:
        bad, strange = check_petsc_options(options)
        errors += [f"PETSc option -{name} {value!r} ({where}): {problem}; allowed: {allowed}"
                   for name, value, problem, allowed in bad]
        tao_type = options.get("tao_type")
        refusal = None if tao_type is None else registry.choice_refusal(
            "tao_type", registry.ALIASES.get(tao_type, tao_type), registry.SOLVER_NAMES)
        if refusal is not None:
            errors.append(f"PETSc option -tao_type {tao_type!r} ({where}): is not a solver "
                          f"petgap runs; allowed: {', '.join(registry.SOLVER_NAMES)}")
        unknown += [(f"-{name} ({where})", f" (did you mean -{close}?)" if close else "")
                    for name, close in strange]
    if unknown and strict:
        errors += [f"PETSc option {u}: petgap does not read it{hint}; allowed with --strict: "
                   f"the options petgap reads (petgap.solvers.options.KNOWN_OPTIONS)"
                   for u, hint in unknown]
    if errors:
        raise SceneError(errors[0] if len(errors) == 1 else
                         f"{len(errors)} errors:\n" + "\n".join(f"  - {e}" for e in errors),
                         errors)
    for u, hint in unknown:
        (log or get_logger("build")).warning(
            "PETSc option %s is not read by petgap and is ignored%s; petgap run --strict "
            "makes this an error", u, hint)


#: Peak bytes per grid point of a run, for the estimate before anything is allocated:
#: the pressure solver (the registry's ``pcg-pressure`` on a periodic cell) in double or
#: mixed precision, and in single; every other solve (adhesion, the solvers on the gap);
#: a surface-only run (the FFT buffers and the topography).  Each lies above the
#: measured peak of a whole run (docs/benchmarks.md, "Memory per point"), with a margin
#: for small grids, whose fixed costs weigh more, and for TAO's solvers, which hold more
#: fields than the pressure solver.
BYTES_PER_POINT_PRESSURE = 56
BYTES_PER_POINT_PRESSURE_SINGLE = 36
BYTES_PER_POINT_SOLVE = 80
BYTES_PER_POINT_SURFACE = 40
#: The same for a free boundary: the hard wall adds the pruned transform's buffer and
#: kernel and the free coarse levels (74-89 bytes per point in all, docs/benchmarks.md,
#: "Free boundary beside periodic"); adhesion solves on the cell, four times the map's
#: points.
BYTES_PER_POINT_FREE = 110
BYTES_PER_POINT_FREE_ADHESIVE = 4 * BYTES_PER_POINT_SOLVE + BYTES_PER_POINT_FREE
#: The same for a run with a ``[flow]`` step: the flow step's own peak, about 310 bytes
#: per point from 1024^2 on (docs/benchmarks.md, "Flow through the gaps"; more on
#: smaller grids, whose multigrid has fixed costs), plus the contact's problem, solution
#: and transform buffers held beside it; that peak, not the contact solve's, is the run's.
BYTES_PER_POINT_FLOW = 400
#: The most points of a rank's (padded) slab: the kernels index it with 32-bit integers.
MAX_SLAB_POINTS = 2**31 - 1


def _meminfo_available():
    """MemAvailable of /proc/meminfo in bytes, or None where there is none."""
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _address_space_left():
    """Bytes this process may still map under RLIMIT_AS (``ulimit -v``), or None if unlimited."""
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit == resource.RLIM_INFINITY:
        return None
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmSize:"):
                return limit - int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return limit


def _gib(nbytes):
    return f"{nbytes / 2**30:.3g} GiB"


def check_size(scene, comm, solve=True):
    """Refuse a grid that cannot run on ``comm``, before anything is allocated (collective).

    A :class:`~petgap.io.scene.SceneError` naming ``grid.nx``/``grid.ny`` if a
    rank's slab exceeds the kernels' 32-bit index range, or if the estimated
    peak memory of a rank (:data:`BYTES_PER_POINT_PRESSURE` or
    :data:`BYTES_PER_POINT_PRESSURE_SINGLE` where the registry resolves the
    scene's solver to the pressure solver (:meth:`~petgap.io.scene.Scene.case`),
    :data:`BYTES_PER_POINT_SOLVE` for other solves, on a free boundary
    :data:`BYTES_PER_POINT_FREE` or :data:`BYTES_PER_POINT_FREE_ADHESIVE`, or
    :data:`BYTES_PER_POINT_SURFACE` per point of its slab; at least
    :data:`BYTES_PER_POINT_FLOW` with a ``[flow]`` step) exceeds what it
    has: its share of the node's MemAvailable or what its address-space
    limit (``ulimit -v``) leaves.  The message gives the estimate, both
    limits and what to do.  Every rank looks at its own node and limits; the
    worst rank's verdict is every rank's.
    """
    nx, ny, size = scene.grid.nx, scene.grid.ny, comm.size
    rows = -(-nx // size)
    row_points = 2 * (ny // 2 + 1)  # the padded real slab of the r2c transform
    if rows * row_points > MAX_SLAB_POINTS:
        most_rows = MAX_SLAB_POINTS // row_points
        fix = (f"run on at least {-(-nx // most_rows)} ranks, or use a smaller grid"
               if most_rows >= 1 else "use a smaller grid.ny")
        raise SceneError(
            f"grid.nx = {nx}, grid.ny = {ny}: a rank's slab of {rows} x {ny} points on {size} "
            f"rank{'s' if size > 1 else ''} is beyond the {MAX_SLAB_POINTS} points petgap's "
            f"kernels can index; allowed: at most {most_rows} rows of {ny} per rank: {fix}")
    per_point = BYTES_PER_POINT_SOLVE if solve else BYTES_PER_POINT_SURFACE
    if solve and scene.case().kind == "pcg-pressure":
        per_point = (BYTES_PER_POINT_PRESSURE_SINGLE if scene.solver.precision == "single"
                     else BYTES_PER_POINT_PRESSURE)
    if solve and not scene.surface.periodic:
        per_point = (BYTES_PER_POINT_FREE if scene.interaction.kind == "hard-wall"
                     else BYTES_PER_POINT_FREE_ADHESIVE)
    if solve and scene.flow.kind != "none":
        per_point = max(per_point, BYTES_PER_POINT_FLOW)
    need = rows * ny * per_point
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    on_node = node.size
    node.Free()
    available = _meminfo_available()
    share = None if available is None else available // on_node
    left = _address_space_left()
    limits = [x for x in (share, left) if x is not None]
    short = bool(limits) and need > min(limits)
    verdicts = comm.allgather((short, need, share, left, on_node))
    worst = [v for v in verdicts if v[0]]
    if not worst:
        return need
    _, need, share, left, on_node = worst[0]
    have = []
    if share is not None:
        have.append(f"MemAvailable {_gib(share * on_node)} on its node shared by {on_node} "
                    f"rank{'s' if on_node > 1 else ''} ({_gib(share)} each)")
    if left is not None:
        have.append(f"{_gib(left)} of address space left under its limit (ulimit -v)")
    ranks = math.ceil(size * need / max(1, min(x for x in (share, left) if x is not None)))
    raise SceneError(
        f"grid.nx = {nx}, grid.ny = {ny}: a run {'solving' if solve else 'making'} this "
        f"grid needs about {_gib(need)} per rank on {size} rank{'s' if size > 1 else ''} "
        f"({per_point} bytes per point of a {rows} x {ny} slab), more than a rank has: "
        f"{'; '.join(have)}; use more ranks (about {ranks}, on more nodes), a smaller grid, "
        f"or raise the limit")


#: The time model of ``petgap check`` (docs/benchmarks.md, "A model for cluster runs"):
#: seconds per point and level of an FFT pair, FFT pairs and seconds per point of an
#: iteration of the pressure solver, and its iterations ``a + b log2(n)^2`` on a periodic
#: cell, all fitted on a 2-core workstation (``benchmarks/model.py``).
SECONDS_PER_POINT_LEVEL = 6.2e-10
PAIRS_PER_ITERATION = 2.4
SECONDS_PER_POINT_ITERATION = 1.0e-9
ITERATIONS = (5.4, 0.077)
#: The coarse start's share on top of the fine iterations (docs/design.md, "The coarse-grid
#: start": its levels cost about a third of the fine solve).
START_FACTOR = 1.3
#: How much dearer a step is than the periodic pressure solve of the same grid: on a free
#: boundary (README: 4-7 times), with adhesion (the gap solver's iterations at about
#: seven times the pressure solver's time on the benchmark surface at 512^2), and under load
#: control with adhesion (a secant on the mean gap: a few gap solves).
FREE_FACTOR = 5.5
ADHESIVE_FACTOR = 7.0
ADHESIVE_LOAD_FACTOR = 3.0
#: The efficiency of each further rank (two ranks sharing this machine's memory: 0.41).
RANK_EFFICIENCY = 0.5


def estimated_seconds(scene, ranks):
    """An order-of-magnitude estimate of one step's solve time on ``ranks`` ranks (see the
    constants above), or 0 for a scene without steps."""
    steps = protocol.plan(scene)
    if not steps:
        return 0.0
    points = scene.grid.nx * scene.grid.ny
    n = math.sqrt(points)
    iterations = ITERATIONS[0] + ITERATIONS[1] * math.log2(n) ** 2
    per_iteration = (PAIRS_PER_ITERATION * SECONDS_PER_POINT_LEVEL * math.log2(points)
                     + SECONDS_PER_POINT_ITERATION) * points
    seconds = START_FACTOR * iterations * per_iteration
    if not scene.surface.periodic:
        seconds *= FREE_FACTOR
    if any(step.adhesive for step in steps):
        seconds *= ADHESIVE_FACTOR * (ADHESIVE_LOAD_FACTOR if scene.control.kind == "load"
                                      else 1.0)
    return seconds / (1 + (ranks - 1) * RANK_EFFICIENCY)


def _is_number(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


def preflight(scene, comm, *, petsc_args=(), strict=False, resolution_check=None, log=None):
    """Every check of a scene that needs neither its grid nor its surface (collective), in
    the order :func:`build` makes them: the PETSc options (:func:`check_options`), the
    planned steps, the size and peak memory (:func:`check_size`), the decomposition of the
    grid over ``comm`` and the adhesive interaction's resolution, where the scene (or
    ``resolution_check``) makes an unresolved one an error.  ``petgap check`` runs it as
    ``petgap run`` does.

    Returns ``(steps, bytes)``: the planned steps and the estimated peak memory per rank.
    """
    check_options(scene, petsc_args, strict=strict, log=log)
    steps = protocol.plan(scene)
    need = check_size(scene, comm, solve=bool(steps))
    check_decomposition(comm, scene.grid.nx, scene.grid.ny)
    interaction = scene.interaction
    mode = interaction.resolution_check if resolution_check is None else resolution_check
    law = from_scene(interaction)
    if steps and law.adhesive and mode == "error":
        g = scene.grid
        check_resolution(stickiest(interaction),
                         min(g.size[0] / g.nx, g.size[1] / g.ny),  # as the Grid does
                         scene.material.contact_modulus, "error")
    return steps, need


def stickiest(interaction):
    """The law of a scene's ``[interaction]`` at its largest work of adhesion: the one whose
    process zone is the smallest, which the grid must resolve for every step to."""
    return from_scene(interaction, work=max(interaction.work_of_adhesion))


def statistics_of(grid, topography):
    """Mean, rms height, slope and curvature of a surface, spectral and by finite
    differences (across the cell's edges and inside the map); collective."""
    stats = surface_statistics(grid, topography)
    periodic, inner = finite_difference_slopes(grid, topography)
    curvature = finite_difference_curvature(grid, topography)
    return dataclasses.replace(stats, rms_slope_fd=periodic, rms_slope_fd_inner=inner,
                               rms_curvature_fd_inner=curvature)


@dataclass
class Model:
    """What a scene builds to: the same on every rank, fields local.

    Attributes
    ----------
    scene : petgap.io.scene.Scene
    grid : petgap.parallel.grid.Grid
    topography : ndarray
        This rank's slab of the rigid surface.
    half_space : petgap.mechanics.half_space.ElasticHalfSpace or None
    problem : petgap.mechanics.problem.ContactProblem or None
        The hard-wall problem.
    adhesive_problem : petgap.mechanics.problem.ContactProblem or None
        The problem with the scene's adhesive interaction, if it has one.
    interaction : petgap.mechanics.interactions.AdhesionLaw or None
        The scene's adhesive law (:func:`petgap.mechanics.interactions.from_scene`).
    resolution : dict or None
        :func:`~petgap.mechanics.interactions.check_resolution`'s report on
        the adhesive interaction.
    steps : list of petgap.app.protocol.Step
        The planned solves, in order (empty for ``control.kind = "none"``:
        then no half-space and no problem are made, so that a surface-only
        run needs nothing of them, not even a rough surface).
    petsc_args : list of str
        The scene's ``solver.petsc_options`` and then the caller's, command-line style.
    options : dict
        The same as a PETSc options dict for :func:`petgap.solvers.dispatch.solve`.
    """

    scene: object
    grid: object
    topography: object
    half_space: object = None
    problem: object = None
    adhesive_problem: object = None
    series: dict = field(default_factory=dict)
    interaction: object = None
    resolution: dict = None
    steps: list = field(default_factory=list)
    petsc_args: list = field(default_factory=list)
    options: dict = field(default_factory=dict)

    @functools.cached_property
    def statistics(self):
        """Mean, rms height, slope and curvature of the surface (collective on first use)."""
        return statistics_of(self.grid, self.topography)

    @property
    def solve_options(self):
        """Keyword arguments of :func:`petgap.solvers.dispatch.solve` from the scene's solver section."""
        s = self.scene.solver
        return dict(solver=s.tao_type, tolerance=s.tolerance, max_iterations=s.max_iterations,
                    options=self.options, precision=s.precision)

    def law_of(self, step):
        """The interaction law a planned step solves with: its problem's (the hard wall, the
        scene's law, or that law at the step's own work of adhesion in a series)."""
        return self.problem_of(step).interaction

    def problem_of(self, step):
        """The problem a planned step solves."""
        if not step.adhesive:
            return self.problem
        if step.work is None:
            return self.adhesive_problem
        if step.work not in self.series:   # the surface and half-space shared
            law = from_scene(self.scene.interaction, work=step.work)
            self.series[step.work] = self.adhesive_problem.with_interaction(law)
        return self.series[step.work]

    def sweep_steps(self, states=None):
        """The planned steps as :class:`~petgap.solvers.sweeps.SweepStep` s.

        ``states`` maps step indices to states already found (a resumed run):
        those steps are not solved again.
        """
        states = states or {}
        return [SweepStep(control=protocol.control_of(step), problem=self.problem_of(step),
                          chain=self.chain_of(step), state=states.get(step.index))
                for step in self.steps]

    @staticmethod
    def chain_of(step):
        """The sweep chain of a planned step: the steps that warm-start each other.

        Each ``w`` of a series starts its own chain, cold from the coarse-grid start: a
        warm start from a much less sticky state must grow every patch to its new size,
        edge pixel by edge pixel (188 iterations from ``w = 0.08`` to ``0.2`` at 8192^2,
        against 22-31 for the cold steps of the same run).
        """
        return step.chain if step.work is None else (step.chain, step.work)

    def warm_starts(self, done):
        """The indices among ``done`` (steps complete in a resumed file) whose fields the
        next steps start from: the last done step of each chain, if the chain goes on."""
        last = {}
        for step in self.steps:
            chain = self.chain_of(step)
            if step.index in done:
                last[chain] = step.index
            elif chain in last:
                yield last.pop(chain)

    def sweep(self, states=None, **solve_options):
        """:func:`~petgap.solvers.sweeps.sweep` over the planned steps (a generator, collective).

        ``solve_options`` override :attr:`solve_options` (e.g. a ``monitor``,
        or ``before``).
        """
        return sweep(None, self.sweep_steps(states), **{**self.solve_options, **solve_options})


def build(scene, comm=None, *, petsc_args=(), surface=None, resolution_check=None, log=None,
          strict=False):
    """Build a scene's grid, surface, problems and steps on ``comm`` (collective).

    Parameters
    ----------
    scene : petgap.io.scene.Scene
    comm : mpi4py.MPI.Comm, optional
        Default ``COMM_WORLD``.
    petsc_args : sequence of str
        PETSc options (command-line style) after the scene's own.
    surface : callable, optional
        ``surface(grid)`` returns this rank's heights (default: the scene's
        surface, :func:`make_surface`); ``petgap study`` puts one physical
        surface on grids of other resolutions this way.
    resolution_check : str, optional
        ``"warn"``, ``"error"`` or ``"off"`` for an unresolved adhesive
        interaction (default: the scene's ``interaction.resolution_check``).
    log : logging.Logger, optional
        Where the FFT planning and surface making are timed (default: not logged).
    strict : bool
        An unknown PETSc option is an error, not a warning (:func:`check_options`).

    Returns
    -------
    Model
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    steps, _ = preflight(scene, comm, petsc_args=petsc_args, strict=strict,
                         resolution_check=resolution_check, log=log)
    if steps and registry.grid_precision(scene.solver.precision) == "single":
        # The surface is made in double and rounded: the same surface as a double
        # run's (its random numbers are drawn in double), so that the two compare.
        with _timed(log, "making the surface (in double, then rounded to single)"):
            scratch = make_grid(scene, comm, planner="estimate")
            heights = surface(scratch) if surface is not None else make_surface(scene, scratch)
            del scratch   # its buffers go before the rounded copy is made
            gc.collect()  # (the grid's plans and buffers may sit in a reference cycle)
            topography = heights.astype(np.float32)
            del heights
        planner, why = fft_planner(scene, steps)
        with _timed(log, f"planning FFTs ({planner}, single precision; {why})"):
            grid = make_grid(scene, comm, precision="single", planner=planner)
    else:
        planner, why = fft_planner(scene, steps)
        with _timed(log, f"planning FFTs ({planner}; {why})"):
            grid = make_grid(scene, comm, planner=planner)
        with _timed(log, "making the surface"):
            topography = surface(grid) if surface is not None else make_surface(scene, grid)
    args = list(scene.solver.petsc_args()) + list(petsc_args)
    model = Model(scene=scene, grid=grid, topography=topography, steps=steps,
                  petsc_args=args, options=petsc_options_dict(args))
    if scene.surface.kind == "file" and scene.surface.periodic:
        seam = seam_warning(model.statistics, scene.surface.path)
        if seam:
            log.warning(seam)
    plausibility.report(
        plausibility_findings(scene, used_rms_slope(model.statistics, scene.surface.periodic)),
        scene.checks.plausibility, scene.path or "scene", log, comm)
    if not model.steps:
        return model
    modulus = scene.material.contact_modulus
    if scene.surface.periodic:
        model.half_space = ElasticHalfSpace(grid, modulus)
    else:
        with _timed(log, f"free boundary: planning the {2 * grid.nx}x{2 * grid.ny} padded "
                         f"cell's FFTs and transforming its kernel"):
            model.half_space = FreeHalfSpace(grid, modulus)
    try:
        model.problem = ContactProblem(grid, topography, model.half_space)
    except ValueError as err:   # a flat map: say which file it came from
        if scene.surface.kind == "file":
            raise ValueError(f"topography {scene.surface.path}: {err}") from None
        raise
    interaction = scene.interaction
    law = from_scene(interaction)
    if law.adhesive:
        mode = interaction.resolution_check if resolution_check is None else resolution_check
        model.resolution = check_resolution(stickiest(interaction), min(grid.dx, grid.dy),
                                            modulus, mode)
        model.interaction = law
        model.adhesive_problem = ContactProblem(grid, topography, model.half_space, law)
    return model


def _timed(log, what):
    return timed(log, what) if log is not None else contextlib.nullcontext()
