"""The speed/accuracy trade of a scene: ``petgap study``.

``mpirun -n P petgap study SCENE.toml [--output-dir DIR] [--tolerances T ...]
[--resolutions R ...] [--quick] [--max-points N] [--fit-range LO HI]
[--ladders tolerance resolution precision] [--overwrite] [--quiet]``

Solves the scene's first control value on three ladders and measures, against the
most accurate rung of each, what every rung costs and how wrong it is:

*tolerance ladder*
    The scene at its own grid, solver tolerance ``1e-4 .. 1e-10`` (``--tolerances``).
*resolution ladder*
    The same physical problem -- ``Lx``, ``Ly``, ``lambda_min``, ``lambda_max``,
    rms slope, the physical surface itself, ``E*``, load (or mean gap), ``w`` and
    ``rho`` -- at ``lambda_min / a0 = 8 .. 128`` (``--resolutions``), by changing
    ``a0`` and ``nx``, ``ny`` together; at the scene's tolerance.  Rungs whose grid
    would exceed ``--max-points`` (default ``4096^2``) are skipped, and the table
    says so.
*precision ladder*
    The scene at its own grid and tolerance in ``solver.precision`` = single
    (at its tolerance floor, :data:`petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR`, if
    the scene's is tighter), mixed and double (the reference).  Single and mixed
    solve non-adhesive contact on a periodic cell with the pressure solver; for
    other scenes their rungs are skipped, saying why.

Cost: solver wall time, iterations, FFT pairs (elastic operator applications),
and the peak memory of the rung (grid, surface, problem and solve; not the
analysis) per grid point, summed over ranks.  Accuracy: the relative error,
``|q - q_ref| / |q_ref|``, of the contact fraction ``c``, ``d_rep`` (Eq. 2), the
mean gap (load control) or mean pressure (mean-gap control), the exponent and
prefactor of the collapsed gap distribution (Eq. 13) fitted on common bins over
one range of ``x = g / g0`` (``--fit-range``, default 0.001 .. 0.1), and, for
adhesive scenes, ``F_att`` (Eq. 15, measured).  For a scene of the paper's
protocol (``control.reference = "non-adhesive"``) a rung is both solves: the
geometry (``c``, ``d_rep``, mean gap, ``p(g)``) comes from the non-adhesive step,
``F_att`` from the adhesive step at its mean gap; costs are summed.

Rank 0 prints a table and writes ``study.csv``, ``study.json`` and ``study.png``
(relative error against wall time, one panel per quantity, every ladder) into
the output directory, never over existing files unless ``--overwrite``.

One physical surface on every grid
----------------------------------
The same seed does not give the same surface at another pixel size, so the
study makes the scene's own surface once, on the scene's grid, and puts its
band-limited modes on every other grid (:mod:`petgap.surfaces.resampling`):
every rung samples the same continuous surface, and the scene's own grid gets
the very surface ``petgap run`` makes.
"""
import argparse
import ctypes
import dataclasses
import gc
import json
import math
import resource
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from petgap import analysis
from petgap.app.argtypes import number_in, positive_float
from petgap.app.build import build, load_scene, make_grid, make_surface
from petgap.app.study_report import StudyError, check_outputs, format_table, write_outputs
from petgap.io import solver_registry as registry
from petgap.io.solver_registry import SINGLE_TOLERANCE_FLOOR
from petgap.mechanics.interactions import law_class
from petgap.parallel.collective import root_decides
from petgap.parallel.grid import DecompositionError
from petgap.parallel.log import get_logger
from petgap.surfaces.resampling import band_spectrum, resample

#: Solver tolerances of the tolerance ladder (loosest first).
DEFAULT_TOLERANCES = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
#: ``lambda_min / a0`` of the resolution ladder.
DEFAULT_RESOLUTIONS = (8.0, 16.0, 32.0, 64.0, 128.0)
#: The short ladders of ``--quick``.
QUICK_TOLERANCES = (1e-4, 1e-6, 1e-8)
QUICK_RESOLUTIONS = (8.0, 16.0, 32.0)
#: Largest grid of the resolution ladder (points), unless ``--max-points``.
DEFAULT_MAX_POINTS = 4096 ** 2
#: ``x = g / g0`` range of the common power-law fit: where the paper finds Eq. 13
#: (the roll-off at ``1e-3 g0`` or below, the far-field Gaussian from ``0.1 g0``).
DEFAULT_FIT_RANGE = (1e-3, 0.1)
#: Logarithmic bins per decade of the common ``x`` bins.
BINS_PER_DECADE = 10
LADDERS = ("tolerance", "resolution", "precision")
#: Rungs of the precision ladder, least accurate first.
PRECISIONS = ("single", "mixed", "double")


# ======================================================= one surface, many grids
class SurfaceSource:
    """The scene's surface, for the scene's grid and (band-limited) for any other.

    ``band`` is None when the surface cannot be carried to other grids; then
    ``reason`` says why (a topography file has no ``lambda_min``; a band at the
    Nyquist modes cannot be resampled exactly).
    """

    def __init__(self, scene, comm, log, band=True):
        self.scene = scene
        self.shape = scene.grid.shape
        self.band, self.reason = None, None
        if not band:
            self.reason = "not asked for"
            return
        if scene.surface.kind != "self-affine":
            self.reason = (f"surface.kind = {json.dumps(scene.surface.kind)}: a measured "
                           f"topography has no lambda_min, and resampling it would change it; "
                           f"the resolution ladder needs a self-affine surface")
            return
        grid = make_grid(scene, comm)
        heights = make_surface(scene, grid)
        try:
            self.band = band_spectrum(grid, heights, scene.surface.lambda_min)
        except ValueError as exc:  # deterministic: raised on every rank alike
            self.reason = str(exc)
            return
        finally:
            del grid, heights
        log.info("surface band |q| <= 2 pi / lambda_min: %d x %d half-plane modes kept; "
                 "variance outside the band (round-off): %.2g of the total",
                 self.band.ky + 1, 2 * self.band.kx + 1, self.band.dropped_power)

    def heights(self, scene, grid):
        """The surface on ``grid`` (the scene's own on its grid, else resampled)."""
        if grid.shape == self.shape and math.isclose(grid.Lx, self.scene.grid.size[0]):
            return make_surface(self.scene, grid)
        if self.band is None:
            raise StudyError(f"the surface cannot be put on a {grid.nx} x {grid.ny} grid: "
                             f"{self.reason}")
        return resample(self.band, grid)


# ================================================================== the ladders
@dataclass(frozen=True)
class Rung:
    """One setting of a ladder.

    Attributes
    ----------
    ladder : str
        ``"tolerance"`` or ``"resolution"``.
    value : float
        The tolerance, or the nominal ``lambda_min / a0``.
    scene : petgap.io.scene.Scene or None
        The scene this rung solves (None if skipped).
    nx, ny : int
    a0 : float
    skipped : str or None
        Why the rung is not run.
    """

    ladder: str
    value: float
    scene: object
    nx: int
    ny: int
    a0: float
    skipped: str = None

    @property
    def label(self):
        if self.ladder == "precision":
            return PRECISIONS[int(self.value)]
        if self.ladder == "resolution":
            return f"{self.value:g} a0"
        short = f"{self.value:.0e}"
        return short if float(short) == self.value else f"{self.value:.3e}"

    @property
    def points(self):
        return self.nx * self.ny


def tolerance_ladder(scene, tolerances):
    """Rungs at the scene's grid, one per tolerance, loosest first (the last is the reference)."""
    g = scene.grid
    rungs = []
    for t in sorted(set(float(t) for t in tolerances), reverse=True):
        variant = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, tolerance=t))
        rungs.append(Rung("tolerance", t, variant, g.nx, g.ny, g.a0))
    return rungs


def precision_ladder(scene):
    """Rungs at the scene's grid in single, mixed and double precision (the last is the reference).

    ``value`` is the index into :data:`PRECISIONS`.  Single runs at
    ``max(tolerance, SINGLE_TOLERANCE_FLOOR)``; single and mixed are skipped,
    with the reason, for scenes they do not solve (adhesion, a free boundary,
    solvers other than the pressure solver).
    """
    g, solver = scene.grid, scene.solver
    # what the registry says of the scene in mixed precision (single needs the same), the
    # tolerance left out: single runs at its floor (the paper's protocol has an adhesive
    # interaction: refused with it)
    case = dataclasses.replace(scene.case(), precision="mixed", tolerance=None)
    refused = [r for r in registry.refusals(case) if r.key == "precision"]
    why = f"solver.precision single or mixed {refused[0].detail(registry.api_name)}" \
        if refused else None
    rungs = []
    for i, precision in enumerate(PRECISIONS):
        tolerance = solver.tolerance
        if precision == "single":
            tolerance = max(tolerance, SINGLE_TOLERANCE_FLOOR)
        variant = dataclasses.replace(scene, solver=dataclasses.replace(
            solver, precision=precision, tolerance=tolerance))
        skipped = why if precision != "double" else None
        rungs.append(Rung("precision", float(i), None if skipped else variant, g.nx, g.ny, g.a0,
                          skipped=skipped))
    return rungs


def resolution_ladder(scene, resolutions, max_points=DEFAULT_MAX_POINTS):
    """Rungs at fixed physics, ``lambda_min / a0`` = each of ``resolutions``, coarsest first.

    For a ratio ``r``: ``nx = round(r Lx / lambda_min)``, ``a0 = Lx / nx`` (so ``Lx``
    is kept exactly and ``lambda_min / a0`` is ``r`` up to that rounding) and
    ``ny = Ly / a0``.  Every physical length of the scene (``lambda_min``,
    ``lambda_max``, ``rho``, mean gaps) and every other value stays as it is.
    Skipped, with the reason: rungs above ``max_points``, rungs where ``Ly`` is
    no whole number of square pixels, rungs that repeat a grid, and every rung
    of a scene without a self-affine surface.
    """
    g = scene.grid
    lx, ly = g.size
    rungs, seen = [], {}
    for r in sorted(set(float(r) for r in resolutions)):
        if scene.surface.kind != "self-affine":
            rungs.append(Rung("resolution", r, None, 0, 0, math.nan,
                              skipped="the scene's surface is a topography file (no lambda_min)"))
            continue
        lmin = scene.surface.lambda_min
        nx = max(1, int(round(r * lx / lmin)))
        a0 = lx / nx
        ny_exact = ly / a0
        ny = max(1, int(round(ny_exact)))
        skipped = None
        if abs(ny_exact - ny) > 1e-6 * ny_exact:
            skipped = (f"Ly = {ly:g} is {ny_exact:.6g} pixels of a0 = {a0:.6g} (square pixels "
                       f"need a whole number)")
        elif nx * ny > max_points:
            skipped = (f"{nx} x {ny} = {nx * ny} points exceeds --max-points {max_points}")
        elif (nx, ny) in seen:
            skipped = f"same {nx} x {ny} grid as lambda_min / a0 = {seen[(nx, ny)]:g}"
        variant = None
        if skipped is None:
            seen[(nx, ny)] = r
            variant = dataclasses.replace(scene, grid=dataclasses.replace(
                g, nx=nx, ny=ny, a0=a0, dx=a0, dy=a0))
        rungs.append(Rung("resolution", r, variant, nx, ny, a0, skipped=skipped))
    return rungs


# ============================================================ errors and reference
def relative_error(value, reference):
    """``|value - reference| / |reference|``; NaN if either is missing or not finite.

    A zero reference gives 0 for a zero value and infinity otherwise.
    """
    if value is None or reference is None:
        return math.nan
    value, reference = float(value), float(reference)
    if not (math.isfinite(value) and math.isfinite(reference)):
        return math.nan
    if reference == 0.0:
        return 0.0 if value == 0.0 else math.inf
    return abs(value - reference) / abs(reference)


def choose_reference(rows):
    """Index of the most accurate row of a ladder (rows ordered least to most accurate).

    The last converged row that was run; if none converged, the last row run.
    None if no row was run.
    """
    run = [i for i, r in enumerate(rows) if not r.get("skipped")]
    if not run:
        return None
    converged = [i for i in run if rows[i].get("converged")]
    return (converged or run)[-1]


def apply_errors(rows, quantities, reference=None):
    """Set ``err_<q>`` of every row against ``rows[reference]`` (default: :func:`choose_reference`).

    Marks the reference row with ``reference = True``.  Returns the reference index.
    """
    if reference is None:
        reference = choose_reference(rows)
    for i, row in enumerate(rows):
        row["reference"] = i == reference
        for q in quantities:
            row[f"err_{q}"] = math.nan if reference is None or row.get("skipped") else \
                relative_error(row.get(q), rows[reference].get(q))
    return reference


def quantities_of(scene):
    """The quantities compared for a scene (keys of :data:`petgap.app.study_report.QUANTITIES`)."""
    control = scene.control
    protocol = control.reference == "non-adhesive"
    names = ["c", "d_rep", "mean_pressure" if control.kind == "mean-gap" else "mean_gap",
             "exponent", "prefactor"]
    if law_class(scene.interaction.kind).adhesive or protocol:
        names.append("F_att")
    return names


# ================================================================== measurement
def _status_kib(field):
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _trim_heap():
    """Hand freed heap memory back to the OS (glibc ``malloc_trim``), where there is one.

    Without it, the arrays of an earlier rung, freed but kept by malloc (its
    mmap threshold grows with every large block freed), would be reused by the
    next rung and its peak would not show them.
    """
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


class _PeakMemory:
    """Peak resident memory of a block on this rank, above what was resident at its start.

    Linux's peak counter (VmHWM) is reset at the start through
    ``/proc/self/clear_refs``; where that is refused, the lifetime peak
    (``getrusage``) is used, which undercounts a block smaller than an
    earlier one (``method`` says which).
    """

    def __enter__(self):
        gc.collect()
        _trim_heap()
        self.base = (_status_kib("VmRSS") or 0) * 1024
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            self.method = "VmHWM reset per rung"
        except OSError:
            self.method = "lifetime peak (getrusage)"
        return self

    def __exit__(self, *exc):
        if self.method.startswith("VmHWM"):
            peak = (_status_kib("VmHWM") or 0) * 1024
        else:
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        self.peak = peak
        self.increase = max(peak - self.base, 0)
        return False


def _monitor(log, what, every=10.0):
    start = time.perf_counter()
    last = [start]

    def monitor(iteration, residual):
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            log.info("  %s: iteration %d, KKT residual %.3e, %.0f s", what, iteration, residual,
                     now - start)
    return monitor


def measure_rung(rung, source, comm, log, fit_range=DEFAULT_FIT_RANGE,
                 bins_per_decade=BINS_PER_DECADE):
    """Solve one rung from cold and measure it (collective); returns its table row (a dict).

    The rung's scene is built (:func:`petgap.app.build.build`) for its first
    control value only, and solved as ``petgap run`` would solve those steps.
    """
    scene = rung.scene
    modulus = scene.material.contact_modulus
    interaction = scene.interaction
    protocol = scene.control.reference == "non-adhesive"
    adhesive = law_class(interaction.kind).adhesive
    first = dataclasses.replace(scene, control=dataclasses.replace(
        scene.control, values=tuple(scene.control.values[:1])))
    row = {"ladder": rung.ladder, "rung": rung.label, "value": rung.value, "nx": rung.nx,
           "ny": rung.ny, "a0": rung.a0, "tolerance": scene.solver.tolerance,
           "precision": scene.solver.precision, "skipped": None,
           "lambda_min_a0": (scene.surface.lambda_min / rung.a0
                             if scene.surface.kind == "self-affine" else None)}
    what = f"{rung.ladder} rung {rung.label}"

    with _PeakMemory() as memory:
        start = time.perf_counter()
        # unresolved adhesion is measured, not refused: the study shows what it costs
        model = build(first, comm, surface=lambda grid: source.heights(scene, grid),
                      resolution_check="off" if interaction.resolution_check == "off"
                      else "warn")
        grid, hard = model.grid, model.problem
        if adhesive:
            row["adhesion_resolved"] = bool(model.resolution["resolved"])
        setup = time.perf_counter() - start
        # the geometry from the first step (non-adhesive in the paper's protocol),
        # the adhesive force from the last (the same step otherwise)
        solutions = list(model.sweep(monitor=_monitor(log, what)))
        geometry, force_state = solutions[0], solutions[-1]
    sums = np.array([memory.increase, memory.peak], dtype=float)
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    times = np.array([sum(s.wall_time for s in solutions), setup])
    comm.Allreduce(MPI.IN_PLACE, times, op=MPI.MAX)  # the slowest rank: the same row everywhere
    row.update(
        converged=all(s.converged for s in solutions),
        reason=";".join(s.reason for s in solutions),
        iterations=sum(s.iterations for s in solutions),
        fft_pairs=sum(s.operator_applications for s in solutions),
        wall_time=float(times[0]), setup_time=float(times[1]),
        bytes_per_point=sums[0] / grid.npoints, peak_rss_mib=sums[1] / 2 ** 20,
        memory_method=memory.method,
        kkt_pressure=max(s.kkt_pressure for s in solutions),
        kkt_gap=max(s.kkt_gap for s in solutions),
        rms_height=hard.rms_height, rms_slope=hard.rms_slope)

    # -- accuracy
    gap, pressure = geometry.gap, geometry.pressure
    stats = analysis.contact_statistics(grid, gap, pressure, hard.rms_slope, modulus)
    c, g0 = stats.contact_fraction, stats.g0
    row.update(c=c, d_rep=stats.mean_diameter, g0=g0, mean_gap=geometry.mean_gap,
               mean_pressure=geometry.mean_pressure)
    row.update(_gap_law(grid, gap, pressure, c, g0, fit_range, bins_per_decade))
    if adhesive or protocol:
        force = analysis.attractive_force_measured(grid, force_state.gap, model.interaction,
                                                   pressure=force_state.pressure)
        row.update(F_att=force.force, F_att_noncontact=force.noncontact_force,
                   c_adhesive=force_state.contact_fraction,
                   inv_kappa_att=force_state.inv_kappa_att)
    if not row["converged"]:
        log.warning("%s did not converge (%s); measured as it is", what, row["reason"])
    log.info("%s: %d x %d, a0 = %.4g: %s, %d iterations, %g FFT pairs, %.2f s (+%.2f s setup), "
             "%.0f B/point; c = %.6g, d_rep = %.6g", what, rung.nx, rung.ny, rung.a0,
             "converged" if row["converged"] else "NOT converged", row["iterations"],
             row["fft_pairs"], row["wall_time"], row["setup_time"], row["bytes_per_point"], c,
             stats.mean_diameter)
    del model, grid, hard, solutions, geometry, force_state, gap, pressure
    gc.collect()
    return row


def _gap_law(grid, gap, pressure, c, g0, fit_range, bins_per_decade):
    """The collapsed gap distribution's power law (Eq. 13) of one state, for a table row.

    Fitted on common bins over ``fit_range`` of ``x = g / g0``, so that rungs compare;
    its extent from all bins.  NaN (and no points) without partial contact.
    """
    fit = {"exponent": math.nan, "prefactor": math.nan, "fit_points": 0,
           "power_law_x_min": math.nan, "power_law_decades": math.nan}
    if not (0 < c < 1 and math.isfinite(g0) and g0 > 0):
        return fit
    lo, hi = fit_range
    nbins = max(1, int(round(bins_per_decade * math.log10(hi / lo))))
    edges = g0 * np.geomspace(lo, hi, nbins + 1)
    common = analysis.gap_distribution(grid, gap, pressure, bins=edges)
    x, y = analysis.collapse(common, None, c, g0)
    fixed = analysis.fit_power_law(x, y, x_range=fit_range)
    full = analysis.gap_distribution(grid, gap, pressure, bins_per_decade=bins_per_decade)
    extent = analysis.fit_power_law(*analysis.collapse(full, None, c, g0)) \
        if full.centres.size else None
    fit.update(exponent=fixed.exponent, prefactor=fixed.prefactor, fit_points=fixed.npoints)
    if extent is not None:
        fit.update(power_law_x_min=extent.x_min, power_law_decades=extent.decades)
    return fit


# ====================================================================== a study
@dataclass
class StudyResult:
    """Rows of the ladders (dicts, the same on every rank) and what they were measured against."""
    scene: object
    quantities: list
    rows: dict            # ladder -> list of row dicts, least to most accurate
    references: dict      # ladder -> index into rows[ladder] or None
    settings: dict
    notes: list


def run_study(scene, comm=None, *, tolerances=DEFAULT_TOLERANCES, resolutions=DEFAULT_RESOLUTIONS,
              max_points=DEFAULT_MAX_POINTS, fit_range=DEFAULT_FIT_RANGE, ladders=LADDERS,
              log=None):
    """Run the study of ``scene`` on ``comm`` (collective); see the module docstring.

    Returns
    -------
    StudyResult
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    log = log or get_logger("study")
    check_scene(scene)
    quantities = quantities_of(scene)
    notes = []
    source = SurfaceSource(scene, comm, log, band="resolution" in ladders)
    if source.band is None and "resolution" in ladders:
        notes.append(f"resolution ladder not run: {source.reason}")
        log.warning("resolution ladder not run: %s", source.reason)
    plan = {}
    if "tolerance" in ladders:
        plan["tolerance"] = tolerance_ladder(scene, tolerances)
    if "resolution" in ladders:
        rungs = resolution_ladder(scene, resolutions, max_points)
        if source.band is None:
            rungs = [dataclasses.replace(r, scene=None, skipped=r.skipped or source.reason)
                     for r in rungs]
        else:
            rungs = [_fits(r, source.band) for r in rungs]
        plan["resolution"] = rungs
    if "precision" in ladders:
        plan["precision"] = precision_ladder(scene)
    rows, done = {}, {}
    for ladder, rungs in plan.items():
        rows[ladder] = []
        for rung in rungs:
            if rung.skipped:
                log.warning("%s rung %s skipped: %s", ladder, rung.label, rung.skipped)
                rows[ladder].append(_skipped_row(rung))
                continue
            key = (rung.nx, rung.ny, rung.scene.solver.tolerance, rung.scene.solver.precision)
            if key in done:  # the same solve on the other ladder: measured once
                row = dict(done[key][0], ladder=ladder, rung=rung.label, value=rung.value,
                           shared_with=f"{done[key][1]} rung {done[key][0]['rung']}")
                log.info("%s rung %s: the same solve as %s", ladder, rung.label,
                         row["shared_with"])
            else:
                try:
                    row = measure_rung(rung, source, comm, log, fit_range)
                except DecompositionError as exc:  # raised on every rank alike
                    rung = dataclasses.replace(rung, skipped=str(exc))
                    log.warning("%s rung %s skipped: %s", ladder, rung.label, exc)
                    rows[ladder].append(_skipped_row(rung))
                    continue
                row["shared_with"] = None
                done[key] = (row, ladder)
            rows[ladder].append(row)
    references = {ladder: apply_errors(r, quantities) for ladder, r in rows.items()}
    for ladder, index in references.items():
        if index is not None and not rows[ladder][index]["converged"]:
            notes.append(f"{ladder} ladder: no rung converged; errors are against the most "
                         f"accurate rung run, {rows[ladder][index]['rung']}")
            log.warning(notes[-1])
    settings = {"tolerances": sorted(set(tolerances), reverse=True),
                "resolutions": sorted(set(resolutions)), "max_points": max_points,
                "fit_range": list(fit_range), "bins_per_decade": BINS_PER_DECADE,
                "ladders": list(ladders), "ranks": comm.size,
                "control": {"kind": scene.control.kind, "value": scene.control.values[0],
                            "reference": scene.control.reference},
                "surface_band": None if source.band is None else {
                    "q_max": source.band.q_max, "kx": source.band.kx, "ky": source.band.ky,
                    "source_shape": list(source.band.source_shape),
                    "dropped_power": source.band.dropped_power}}
    return StudyResult(scene=scene, quantities=quantities, rows=rows, references=references,
                       settings=settings, notes=notes)


def _fits(rung, band):
    if rung.skipped:
        return rung
    problem = band.check_fits((rung.nx, rung.ny))
    return dataclasses.replace(rung, scene=None, skipped=problem) if problem else rung


def _skipped_row(rung):
    return {"ladder": rung.ladder, "rung": rung.label, "value": rung.value,
            "nx": rung.nx or None, "ny": rung.ny or None,
            "a0": rung.a0 if math.isfinite(rung.a0) else None, "skipped": rung.skipped,
            "converged": None}


def check_scene(scene):
    """StudyError unless the scene has something to solve."""
    if scene.control.kind == "none":
        raise StudyError("the scene has control.kind = \"none\": a study needs a load or a mean "
                         "gap to solve (its first control value is used)")


# ========================================================================== CLI
_tolerance = number_in(0.0, 0.1, what="a tolerance in (0, 0.1]")
_resolution = number_in(2.0, 1e6, what="a lambda_min / a0 above 2 (the band must lie inside "
                                       "the Nyquist modes)")


def _points(text):
    """``16777216``, ``4096^2`` or ``4096x4096``."""
    t = text.strip().lower()
    try:
        if "^2" in t:
            value = int(t.replace("^2", "")) ** 2
        elif "x" in t:
            a, b = t.split("x")
            value = int(a) * int(b)
        else:
            value = int(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of points (e.g. 16777216, "
                                         f"4096^2 or 4096x4096)") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} is not a positive number of points")
    return value


def add_parser(subparsers):
    """Register ``petgap study`` on the ``petgap`` command's subparsers."""
    p = subparsers.add_parser(
        "study", help="measure the speed/accuracy trade of a scene (tolerance and resolution)",
        description="Solve the scene's first control value on a tolerance ladder (at its grid) "
                    "and a resolution ladder (lambda_min / a0 at fixed physics and the same "
                    "physical surface), and tabulate cost against the relative error of c, "
                    "d_rep, the mean gap (or pressure), the p(g) exponent and prefactor, and "
                    "F_att. Run under mpirun -n P.")
    p.add_argument("scene", metavar="SCENE.toml", help="scene file")
    p.add_argument("-o", "--output-dir", type=Path, metavar="DIR",
                   help="where study.csv, study.json and study.png go "
                        "(default: ./<scene stem>-study)")
    p.add_argument("--tolerances", type=_tolerance, nargs="+", metavar="T",
                   help="solver tolerances of the tolerance ladder, each in (0, 0.1] (default "
                        + " ".join(f"{t:g}" for t in DEFAULT_TOLERANCES) + ")")
    p.add_argument("--resolutions", type=_resolution, nargs="+", metavar="R",
                   help="lambda_min / a0 of the resolution ladder, each > 2 (default "
                        + " ".join(f"{r:g}" for r in DEFAULT_RESOLUTIONS) + ")")
    p.add_argument("--quick", action="store_true",
                   help="short ladders: tolerances " + " ".join(f"{t:g}" for t in QUICK_TOLERANCES)
                        + ", resolutions " + " ".join(f"{r:g}" for r in QUICK_RESOLUTIONS)
                        + " (explicit --tolerances / --resolutions still win)")
    p.add_argument("--max-points", type=_points, default=DEFAULT_MAX_POINTS, metavar="N",
                   help="skip resolution rungs with more grid points (default 4096^2; "
                        "accepts 16777216, 4096^2 or 4096x4096)")
    p.add_argument("--fit-range", type=positive_float, nargs=2, default=DEFAULT_FIT_RANGE,
                   metavar=("LO", "HI"),
                   help="x = g/g0 range of the common power-law fit (default 0.001 0.1, "
                        "where the paper finds Eq. 13)")
    p.add_argument("--ladders", nargs="+", choices=LADDERS, default=list(LADDERS),
                   help="which ladders to run (default all three)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print only the table, warnings and errors")
    p.set_defaults(func=command)
    return p


def command(args, comm, petsc_args=()):
    """``petgap study``: run the study and write its outputs (collective); exit status."""
    if not args.fit_range[0] < args.fit_range[1]:
        raise StudyError(f"--fit-range {args.fit_range[0]:g} {args.fit_range[1]:g}: need LO < HI")
    tolerances = args.tolerances or (QUICK_TOLERANCES if args.quick else DEFAULT_TOLERANCES)
    resolutions = args.resolutions or (QUICK_RESOLUTIONS if args.quick else DEFAULT_RESOLUTIONS)
    output_dir = args.output_dir if args.output_dir is not None else \
        Path(f"{Path(args.scene).stem}-study")
    scene = load_scene(args.scene, comm)
    check_scene(scene)
    check_outputs(output_dir, args.overwrite, comm)  # before any expensive work
    log = get_logger("study")
    log.info("study of %s on %d rank%s: %s", args.scene, comm.size, "" if comm.size == 1 else "s",
             ", ".join(f"{ladder} ladder" for ladder in args.ladders))
    study = run_study(scene, comm, tolerances=tolerances, resolutions=resolutions,
                      max_points=args.max_points, fit_range=tuple(args.fit_range),
                      ladders=tuple(dict.fromkeys(args.ladders)), log=log)
    def write():
        print(format_table(study), end="", flush=True)
        try:
            written = write_outputs(study, output_dir)
        except OSError as exc:
            raise StudyError(f"cannot write the study outputs in {output_dir}: {exc}") from None
        log.info("wrote %s", ", ".join(str(p) for p in written))
    # the other ranks sleep while rank 0 draws (Open MPI's broadcast would spin)
    root_decides(comm, write, poll=0.02)
    return 0
