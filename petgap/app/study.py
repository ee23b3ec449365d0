"""The speed/accuracy trade of a scene: ``petgap study``.

``mpirun -n P petgap study SCENE.toml [--output-dir DIR] [--tolerances T ...]
[--resolutions R ...] [--quick] [--max-points N] [--fit-range LO HI]
[--ladders tolerance resolution] [--overwrite] [--quiet]``

Solves the scene's first control value on two ladders and measures, against the
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
(relative error against wall time, one panel per quantity, both ladders) into
the output directory, never over existing files unless ``--overwrite``.

One physical surface on every grid
----------------------------------
:func:`petgap.surfaces.self_affine.self_affine` does *not* give the same surface for the same
seed at another pixel size: Fourier row ``n`` draws its ``nx`` amplitudes in
FFT column order from ``Philox(seed, n)``, so the modes with ``q_x >= 0`` (the
first columns) coincide, but those with ``q_x < 0`` sit at columns ``nx - |m|``,
which depend on ``nx``; and the rescaling to the rms slope then differs too
(measured: 64^2 against 128^2 over the same ``L``: the ``q_x >= 0`` modes agree
up to one factor 0.949, the others are unrelated).  The study therefore makes
the scene's own surface once, on the scene's grid, keeps its Fourier modes with
``|q| <= 2 pi / lambda_min`` (:func:`band_spectrum`; everything above is zero
by construction, up to round-off, which is reported), and puts exactly those
modes on every other grid (:func:`resample`): Fourier truncation onto coarser
grids and zero padding onto finer ones.  For a band-limited surface whose band
lies strictly inside each grid's Nyquist range this is exact -- every grid
samples the same continuous surface, with the same rms height, slope and
curvature to round-off -- and the scene's own grid gets the very surface
``petgap run`` makes.  The modes kept are ``O((L / lambda_min)^2)``, independent
of the resolution; they are gathered on every rank (a few kB to a few MB), the
transforms are the grids' distributed FFTW-MPI plans, and no rank ever holds a
global field.
"""
import argparse
import csv
import dataclasses
import gc
import json
import math
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from petgap.app.argtypes import number_in, positive_float

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
#: Output files: ``<stem>.csv``, ``<stem>.json``, ``<stem>.png``.
OUTPUT_STEM = "study"
OUTPUT_SUFFIXES = (".csv", ".json", ".png")
LADDERS = ("tolerance", "resolution")
#: Quantities compared, in table order, and their descriptions.
QUANTITIES = {
    "c": "contact fraction A_rep / A0",
    "d_rep": "mean contact diameter pi A_rep / P_rep (Eq. 2)",
    "mean_gap": "mean gap (load control)",
    "mean_pressure": "mean pressure (mean-gap control)",
    "exponent": "exponent of the collapsed p(g) fitted over the common x = g/g0 range",
    "prefactor": "prefactor of that fit (Eq. 13: 1)",
    "F_att": "attractive force -sum dx dy v'(g) (Eq. 15; adhesive scenes)",
}
TITLES = {"c": "contact fraction c", "d_rep": "mean contact diameter d_rep",
          "mean_gap": "mean gap", "mean_pressure": "mean pressure",
          "exponent": "p(g) exponent (common x range)", "prefactor": "p(g) prefactor",
          "F_att": "attractive force F_att"}
# Relative slack of the band edge |q| <= 2 pi / lambda_min (far below a mode spacing 1/n).
_BAND_SLACK = 1e-9


class StudyError(ValueError):
    """A study that cannot be made as asked (reported as a user error, exit status 2)."""


# ======================================================= one surface, many grids
@dataclass(frozen=True)
class BandSpectrum:
    """The Fourier modes of a band-limited periodic surface, independent of any grid.

    ``h(x) = sum_q a_q exp(i q.x)`` over ``q = 2 pi (m / Lx, n / Ly)`` with
    ``|m| <= kx``, ``0 <= n <= ky`` (the half plane; ``n < 0`` by Hermitian
    symmetry) and ``|q| <= q_max``; ``a_q`` is the grid's unnormalised
    coefficient over its number of points, ``c_q / N``, which does not depend on
    the grid.  Identical on every rank.

    Attributes
    ----------
    size : (float, float)
        ``(Lx, Ly)``.
    q_max : float
        Band edge (``2 pi / lambda_min``).
    kx, ky : int
        Largest ``|m|`` and ``n`` in the band.
    coefficients : ndarray, complex, shape ``(ky + 1, 2 kx + 1)``
        ``a_q`` at row ``n``, column ``m + kx``; zero outside the band.
    source_shape : (int, int)
        The grid the modes were taken from.
    dropped_power : float
        Fraction of the source's height variance outside the band (round-off
        for a generated self-affine surface; large for a rough measured one).
    """

    size: tuple
    q_max: float
    kx: int
    ky: int
    coefficients: np.ndarray
    source_shape: tuple
    dropped_power: float

    def check_fits(self, shape):
        """Why a grid of ``shape`` (same size) cannot hold the band exactly, or None."""
        nx, ny = shape
        if 2 * self.kx >= nx or 2 * self.ky >= ny:
            return (f"the surface's band |q| <= {self.q_max:.6g} reaches |m| = {self.kx}, "
                    f"n = {self.ky}, at or beyond the Nyquist modes of a {nx} x {ny} grid "
                    f"(need 2 |m| < nx and 2 n < ny, i.e. lambda_min > 2 a0)")
        return None


def band_spectrum(grid, heights, lambda_min):
    """The modes ``|q| <= 2 pi / lambda_min`` of this rank's slab of a surface (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Its FFT buffers are overwritten.
    heights : ndarray, shape ``grid.local_shape``
    lambda_min : float
        Short-wavelength cutoff; the band must lie strictly inside the grid's
        Nyquist range (else ValueError on every rank).

    Returns
    -------
    BandSpectrum
    """
    from mpi4py import MPI
    from petgap.parallel._fftw_mpi import weighted_power
    if not (isinstance(lambda_min, (int, float)) and math.isfinite(lambda_min) and lambda_min > 0):
        raise ValueError(f"lambda_min = {lambda_min!r}: need a positive length")
    q_max = 2 * math.pi / float(lambda_min)
    kx = int(math.floor(q_max * grid.Lx / (2 * math.pi) * (1 + _BAND_SLACK)))
    ky = int(math.floor(q_max * grid.Ly / (2 * math.pi) * (1 + _BAND_SLACK)))
    band = BandSpectrum(size=(grid.Lx, grid.Ly), q_max=q_max, kx=kx, ky=ky,
                        coefficients=None, source_shape=grid.shape, dropped_power=math.nan)
    problem = band.check_fits(grid.shape)
    if problem is not None:
        raise ValueError(f"cannot take the band-limited modes of the surface: {problem}")
    comm = grid.comm
    c = grid.forward(np.asarray(heights, dtype=np.float64))
    total = weighted_power(c, grid.qx, grid.qy, grid.hermitian_weight, 0)
    start = grid.ky_slice.start
    if start == 0:
        total -= abs(c[0, 0]) ** 2  # the mean is not roughness
    rows = range(start, min(grid.ky_slice.stop, ky + 1))
    m = np.arange(-kx, kx + 1)
    local = np.zeros((len(rows), 2 * kx + 1), dtype=complex)
    kept = 0.0
    for i, n in enumerate(rows):
        qy = 2 * math.pi * n / grid.Ly
        qx = 2 * math.pi * m / grid.Lx
        inside = qx ** 2 + qy ** 2 <= (q_max * (1 + _BAND_SLACK)) ** 2
        values = np.where(inside, c[n - start, m % grid.nx], 0.0) / grid.npoints
        local[i] = values
        power = np.abs(values) ** 2
        if n == 0:
            power[kx] = 0.0  # the mean
        kept += grid.hermitian_weight[n - start] * float(power.sum())
    sums = np.array([total / grid.npoints ** 2, kept])
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    parts = comm.allgather(local)
    coefficients = np.concatenate(parts, axis=0)
    dropped = max(sums[0] - sums[1], 0.0) / sums[0] if sums[0] > 0 else 0.0
    return dataclasses.replace(band, coefficients=coefficients, dropped_power=float(dropped))


def resample(band, grid):
    """This rank's slab of the band-limited surface ``band`` on ``grid`` (collective).

    Puts the band's modes, and nothing else, into the grid's Fourier slab and
    transforms back: Fourier truncation onto a coarser grid, zero padding onto
    a finer one, exact as long as the band lies strictly inside the grid's
    Nyquist range (ValueError otherwise).  The grid must have the band's
    physical size.

    Returns
    -------
    ndarray, shape ``grid.local_shape``
    """
    lx, ly = band.size
    if not (math.isclose(grid.Lx, lx, rel_tol=1e-12) and math.isclose(grid.Ly, ly, rel_tol=1e-12)):
        raise ValueError(f"grid size {grid.Lx:g} x {grid.Ly:g} differs from the surface's "
                         f"{lx:g} x {ly:g}")
    problem = band.check_fits(grid.shape)
    if problem is not None:
        raise ValueError(f"cannot put the surface on this grid: {problem}")
    fourier = grid.fourier
    fourier[...] = 0.0
    start, stop = grid.ky_slice.start, grid.ky_slice.stop
    columns = np.arange(-band.kx, band.kx + 1) % grid.nx
    for n in range(start, min(stop, band.ky + 1)):
        fourier[n - start, columns] = band.coefficients[n]
    # backward is unnormalised: sum_q a_q exp(i q.x) is the surface itself
    return grid.backward().copy()


class SurfaceSource:
    """The scene's surface, for the scene's grid and (band-limited) for any other.

    ``band`` is None when the surface cannot be carried to other grids; then
    ``reason`` says why (a topography file has no ``lambda_min``; a band at the
    Nyquist modes cannot be resampled exactly).
    """

    def __init__(self, scene, comm, log, band=True):
        from petgap.app.run import make_grid, make_surface
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
        from petgap.app.run import make_surface
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
            variant = dataclasses.replace(scene, grid=dataclasses.replace(g, nx=nx, ny=ny, a0=a0))
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
    """The quantities compared for a scene (keys of :data:`QUANTITIES`)."""
    control = scene.control
    protocol = control.reference == "non-adhesive"
    names = ["c", "d_rep", "mean_pressure" if control.kind == "mean-gap" else "mean_gap",
             "exponent", "prefactor"]
    if scene.interaction.kind == "exponential" or protocol:
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
        import ctypes
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
    """Solve one rung from cold and measure it (collective); returns its table row (a dict)."""
    from mpi4py import MPI

    from petgap import analysis
    from petgap.app.run import _petsc_options_dict, make_grid
    from petgap.mechanics.problem import ContactProblem, Load, MeanGap
    from petgap.mechanics.half_space import ElasticHalfSpace
    from petgap.mechanics.interactions import ExponentialAdhesion, check_resolution
    from petgap.solvers.dispatch import solve

    scene = rung.scene
    modulus = scene.material.contact_modulus
    interaction = scene.interaction
    protocol = scene.control.reference == "non-adhesive"
    adhesive = interaction.kind == "exponential"
    value = scene.control.values[0]
    options = _petsc_options_dict(scene.solver.petsc_args())
    solver = dict(solver=scene.solver.tao_type, tolerance=scene.solver.tolerance,
                  max_iterations=scene.solver.max_iterations, options=options)
    row = {"ladder": rung.ladder, "rung": rung.label, "value": rung.value, "nx": rung.nx,
           "ny": rung.ny, "a0": rung.a0, "tolerance": scene.solver.tolerance, "skipped": None,
           "lambda_min_a0": (scene.surface.lambda_min / rung.a0
                             if scene.surface.kind == "self-affine" else None)}
    what = f"{rung.ladder} rung {rung.label}"

    with _PeakMemory() as memory:
        start = time.perf_counter()
        grid = make_grid(scene, comm)
        heights = source.heights(scene, grid)
        half_space = ElasticHalfSpace(grid, modulus)
        hard = ContactProblem(grid, heights, half_space)
        sticky = None
        if adhesive:
            law = ExponentialAdhesion(interaction.work_of_adhesion, interaction.range)
            mode = "off" if interaction.resolution_check == "off" else "warn"
            report = check_resolution(law, min(grid.dx, grid.dy), modulus, mode)
            row["adhesion_resolved"] = bool(report["resolved"])
            sticky = ContactProblem(grid, heights, half_space, law)
        setup = time.perf_counter() - start
        monitor = _monitor(log, what)
        if protocol:
            geometry = solve(hard, Load(value), monitor=monitor, **solver)
            force_state = solve(sticky, MeanGap(geometry.mean_gap), monitor=monitor, **solver)
            solutions = [geometry, force_state]
        else:
            problem = sticky if adhesive else hard
            control = Load(value) if scene.control.kind == "load" else MeanGap(value)
            geometry = force_state = solve(problem, control, monitor=monitor, **solver)
            solutions = [geometry]
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
    fit = {"exponent": math.nan, "prefactor": math.nan, "fit_points": 0,
           "power_law_x_min": math.nan, "power_law_decades": math.nan}
    if 0 < c < 1 and math.isfinite(g0) and g0 > 0:
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
    row.update(fit)
    if adhesive or protocol:
        law = ExponentialAdhesion(interaction.work_of_adhesion, interaction.range)
        force = analysis.attractive_force_measured(grid, force_state.gap, law,
                                                   pressure=force_state.pressure)
        row.update(F_att=force.force, F_att_noncontact=force.noncontact_force,
                   c_adhesive=force_state.contact_fraction,
                   inv_kappa_att=force_state.inv_kappa_att)
    if not row["converged"]:
        log.warning("%s did not converge (%s); measured as it is", what, row["reason"])
    log.info("%s: %d x %d, a0 = %.4g: %s, %d iterations, %d FFT pairs, %.2f s (+%.2f s setup), "
             "%.0f B/point; c = %.6g, d_rep = %.6g", what, rung.nx, rung.ny, rung.a0,
             "converged" if row["converged"] else "NOT converged", row["iterations"],
             row["fft_pairs"], row["wall_time"], row["setup_time"], row["bytes_per_point"], c,
             stats.mean_diameter)
    del grid, heights, hard, sticky, solutions, geometry, force_state, gap, pressure
    gc.collect()
    return row


# ====================================================================== a study
@dataclass
class StudyResult:
    """Rows of both ladders (dicts, the same on every rank) and what they were measured against."""
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
    from petgap.parallel.log import get_logger
    if comm is None:
        from mpi4py import MPI
        comm = MPI.COMM_WORLD
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
    rows, done = {}, {}
    for ladder, rungs in plan.items():
        rows[ladder] = []
        for rung in rungs:
            if rung.skipped:
                log.warning("%s rung %s skipped: %s", ladder, rung.label, rung.skipped)
                rows[ladder].append(_skipped_row(rung))
                continue
            key = (rung.nx, rung.ny, rung.scene.solver.tolerance)
            if key in done:  # the same solve on the other ladder: measured once
                row = dict(done[key][0], ladder=ladder, rung=rung.label, value=rung.value,
                           shared_with=f"{done[key][1]} rung {done[key][0]['rung']}")
                log.info("%s rung %s: the same solve as %s", ladder, rung.label,
                         row["shared_with"])
            else:
                from petgap.parallel.grid import DecompositionError
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


# ====================================================================== outputs
COLUMNS = ["ladder", "rung", "value", "reference", "skipped", "shared_with", "nx", "ny", "a0",
           "lambda_min_a0", "tolerance", "converged", "reason", "iterations", "fft_pairs",
           "wall_time", "setup_time", "bytes_per_point", "peak_rss_mib", "kkt_pressure",
           "kkt_gap", "rms_height", "rms_slope", "adhesion_resolved", "c", "d_rep", "g0",
           "mean_gap", "mean_pressure", "exponent", "prefactor", "fit_points",
           "power_law_x_min", "power_law_decades", "F_att", "F_att_noncontact", "c_adhesive",
           "inv_kappa_att"] + \
          [f"err_{q}" for q in QUANTITIES]


def output_paths(output_dir):
    return [Path(output_dir) / f"{OUTPUT_STEM}{s}" for s in OUTPUT_SUFFIXES]


def check_outputs(output_dir, overwrite, comm):
    """Raise the same StudyError on every rank if the outputs cannot be written (rank 0 decides)."""
    problem = None
    if comm.rank == 0:
        d = Path(output_dir)
        if d.exists() and not d.is_dir():
            problem = f"--output-dir {d} exists and is not a directory"
        elif not overwrite:
            existing = [str(p) for p in output_paths(d) if p.exists()]
            if existing:
                problem = (f"refusing to overwrite existing output {', '.join(existing)}; pass "
                           f"--overwrite or choose another --output-dir")
        if problem is None:
            try:
                d.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                problem = f"cannot create --output-dir {d}: {exc}"
    problem = comm.bcast(problem, root=0)
    if problem:
        raise StudyError(problem)


def _clean(value):
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def all_rows(study):
    return [row for ladder in study.rows for row in study.rows[ladder]]


def write_outputs(study, output_dir, argv=None):
    """Write ``study.csv``, ``study.json`` and ``study.png`` (call on one rank)."""
    csv_path, json_path, png_path = output_paths(output_dir)
    rows = [{k: _clean(r.get(k)) for k in COLUMNS} for r in all_rows(study)]
    with open(csv_path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if v is None else v for k, v in row.items()})
    from petgap import __version__
    scene = study.scene
    doc = {"petgap_version": __version__,
           "command_line": " ".join(argv if argv is not None else sys.argv),
           "scene_path": scene.path, "scene": scene.text, "scene_resolved": scene.to_dict(),
           "settings": study.settings, "quantities": {q: QUANTITIES[q] for q in study.quantities},
           "references": {ladder: (None if i is None else study.rows[ladder][i]["rung"])
                          for ladder, i in study.references.items()},
           "notes": study.notes,
           "conventions": {
               "error": "|q - q_ref| / |q_ref| against the ladder's reference rung (the most "
                        "accurate converged one)",
               "wall_time": "solver wall time, s (slowest rank; summed over the solves of a "
                            "rung)",
               "setup_time": "grid (FFT planning), surface and problem, s",
               "fft_pairs": "elastic operator applications (one forward + one inverse FFT each)",
               "bytes_per_point": "peak resident memory of grid + surface + problem + solve "
                                  "above the resident memory before them, summed over ranks, "
                                  "over nx ny",
               "exponent, prefactor": "least-squares fit of log y on log x of the collapsed "
                                      "p(g) (Eq. 13) on common log bins over the fit range",
               "power_law_x_min, power_law_decades": "extent of the power law found by "
                                                     "petgap.analysis.fit_power_law (no error)",
               "F_att_noncontact, c_adhesive, inv_kappa_att": "adhesive state: the part of "
                                                              "F_att from pixels outside "
                                                              "repulsive contact, its contact "
                                                              "fraction and 1/kappa_att (no "
                                                              "error)"},
           "rows": rows}
    with open(json_path, "w") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")
    figure(study, png_path)
    return [csv_path, json_path, png_path]


def figure(study, path):
    """Relative error against solver wall time, one panel per quantity, both ladders."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401  (matplotlib.ticker below)
    quantities = study.quantities
    ncols = 3
    nrows = int(math.ceil(len(quantities) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.4 * nrows), squeeze=False)
    styles = {"tolerance": ("o", "C0"), "resolution": ("s", "C3")}
    floor = 1e-12
    for ax, q in zip(axes.flat, quantities):
        for ladder, rows in study.rows.items():
            marker, colour = styles[ladder]
            ref = study.references.get(ladder)
            pts = [(r["wall_time"], r[f"err_{q}"], r["rung"]) for i, r in enumerate(rows)
                   if not r.get("skipped") and i != ref and r.get("wall_time")
                   and r.get(f"err_{q}") is not None and math.isfinite(r[f"err_{q}"])]
            if not pts:
                continue
            t = np.array([p[0] for p in pts])
            e = np.array([p[1] for p in pts])
            shown = np.maximum(e, floor)
            reflabel = rows[ref]["rung"] if ref is not None else "-"
            ax.loglog(t, shown, "-", color=colour, lw=0.8, alpha=0.6)
            ax.loglog(t[e >= floor], shown[e >= floor], marker, color=colour, ls="none",
                      label=f"{ladder} (ref. {reflabel})")
            if np.any(e < floor):
                ax.loglog(t[e < floor], shown[e < floor], "v", color=colour, ls="none",
                          label=f"{ladder}: error < {floor:g}")
            for ti, si, ei, label in zip(t, shown, e, [p[2] for p in pts]):
                if ei < floor:
                    continue  # at the floor: the legend says so, labels would pile up
                ax.annotate(label, (ti, si), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
        lo, hi = ax.get_xlim()
        if hi < 10 * lo:  # at least a decade, so that the log axis has labelled ticks
            mid = math.sqrt(lo * hi)
            ax.set_xlim(mid / math.sqrt(10), mid * math.sqrt(10))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(TITLES[q], fontsize=9)
        ax.set_xlabel("solver wall time [s]", fontsize=8)
        ax.set_ylabel("relative error", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(quantities):]:
        ax.axis("off")
    name = Path(study.scene.path).name if study.scene.path else "scene"
    fig.suptitle(f"petgap study: {name} (errors against each ladder's most accurate rung; "
                 f"below {floor:g} drawn at {floor:g})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _fmt(value, spec):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, spec)


def format_table(study):
    """The printed table (a string)."""
    lines = []
    head = (f"{'rung':>9} {'grid':>11} {'conv':>4} {'its':>5} {'FFT':>6} {'wall s':>8} "
            f"{'B/pt':>6} " + " ".join(f"{'err ' + q:>12}" for q in study.quantities))
    for ladder, rows in study.rows.items():
        ref = study.references.get(ladder)
        scene = study.scene.grid
        title = (f"{ladder} ladder" + (f" at {scene.nx} x {scene.ny}, a0 = {scene.a0:g}"
                                        if ladder == "tolerance" else
                                        f" at tolerance {study.scene.solver.tolerance:g}"))
        if ref is not None:
            r = rows[ref]
            values = ", ".join(f"{q} = {_fmt(r.get(q), '.6g')}" for q in study.quantities)
            title += f"; reference {r['rung']}: {values}"
        lines.append(title)
        lines.append(head)
        for i, r in enumerate(rows):
            if r.get("skipped"):
                grid = f"{r['nx']}x{r['ny']}" if r.get("nx") else "-"
                lines.append(f"{r['rung']:>9} {grid:>11} skipped: {r['skipped']}")
                continue
            errs = " ".join(f"{'ref' if i == ref else _fmt(r.get('err_' + q), '.2e'):>12}"
                            for q in study.quantities)
            lines.append(f"{r['rung']:>9} {str(r['nx']) + 'x' + str(r['ny']):>11} "
                         f"{'yes' if r['converged'] else 'NO':>4} {r['iterations']:>5d} "
                         f"{r['fft_pairs']:>6d} {r['wall_time']:>8.2f} "
                         f"{_fmt(r['bytes_per_point'], '.0f'):>6} {errs}")
        lines.append("")
    for note in study.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines).rstrip() + "\n"


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
                   help="which ladders to run (default both)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print only the table, warnings and errors")
    p.set_defaults(func=command)
    return p


def command(args, comm, petsc_args=()):
    """``petgap study``: run the study and write its outputs (collective); exit status."""
    from petgap.parallel.log import get_logger
    from petgap.io.scene import Scene
    if not args.fit_range[0] < args.fit_range[1]:
        raise StudyError(f"--fit-range {args.fit_range[0]:g} {args.fit_range[1]:g}: need LO < HI")
    tolerances = args.tolerances or (QUICK_TOLERANCES if args.quick else DEFAULT_TOLERANCES)
    resolutions = args.resolutions or (QUICK_RESOLUTIONS if args.quick else DEFAULT_RESOLUTIONS)
    output_dir = args.output_dir if args.output_dir is not None else \
        Path(f"{Path(args.scene).stem}-study")
    scene = Scene.from_file(args.scene, comm)
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
            return f"cannot write the study outputs in {output_dir}: {exc}"
        log.info("wrote %s", ", ".join(str(p) for p in written))
        return None
    problem = _on_root(comm, write)
    if problem:
        raise StudyError(problem)
    return 0


def _on_root(comm, func, poll=0.02):
    """``func()`` on rank 0 while the others sleep-poll (not spin); its result on every rank.

    Open MPI's blocking collectives busy-wait; on a machine with as many cores
    as ranks that would starve rank 0 while it draws the figure.  ``func``
    must not raise (return the problem instead).
    """
    result = func() if comm.rank == 0 else None
    request = comm.Ibarrier()
    while not request.Test():
        time.sleep(poll)
    return comm.bcast(result, root=0)
