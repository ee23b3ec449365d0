"""The ``petgap-post`` command: tables and figures of the paper from petgap result files.

Usage::

    mpirun -n P petgap-post RUN.h5[:STEP] [RUN2.h5 ...] [--output-dir DIR] [--bins N]
                            [--reference RUN.h5[:STEP]] [--format png|pdf|svg]
                            [--fit-range LO HI] [--gap-tolerance G] [--overwrite] [--quiet]

(or without ``mpirun``, serially).  Every step group (``step_0000``, ...) of every
file is analysed, or only ``STEP`` (an integer or ``step_NNNN``) where given.
The fields are read collectively, each rank its slab (:func:`petgap.io.results.read_field`),
and analysed with :mod:`petgap.analysis`; rank 0 writes into ``DIR``:

``gap-analysis.csv``, ``gap-analysis.json``
    One row per file/step: contact fraction ``c``, ``A_rep``, ``P_rep`` (and the raw
    pixel-edge length), ``d_rep`` (Eq. 2), ``g0`` (Eq. 12), the fitted exponent and
    power-law range of the collapsed gap distribution (Eq. 13;
    :func:`petgap.analysis.fit_power_law`, a window that looks for ``-1/3``), the
    exponent over the *fit range* (``exponent_fit_range``; see below), the
    near-contact area ``c_n`` at ``g_c = g0``, ``0.18 g0`` and
    ``1e-3 g0`` against Eq. 14, for adhesive runs ``F_att`` measured (Eq. 15, all
    pixels, and its non-contact part) against Eq. 16 as printed and exact
    (``Gamma(2/3)`` times larger), ``1/kappa_att`` from each, and ``kappa_rep``
    (``A_rep h0' E* / F_rep`` with ``F_rep`` the wall reaction ``sum (p + v'(0))``
    over contact pixels).  The JSON file also holds the conventions, the fit-range
    settings, the Fig. 3 references (with the steps each normalises and the
    duplicates drawn through it), the legend label of every series drawn in
    Figs. 2 and 3 (``legends``), and each step's histogram.  Missing values are
    empty in the CSV and ``null`` in the JSON.

    *Fit range.*  With ``--fit-range LO HI`` the exponent is fitted over exactly
    ``LO <= g/g0 <= HI`` for every step.  By default the range is chosen per step
    from its own data (:func:`petgap.analysis.auto_fit_range`): between
    ``3 x_res`` and ``0.1``, where ``x_res = (a0 / (2 d_rep))^(3/2)`` is the gap
    half a pixel from a contact edge by Eq. 12 over ``g0`` (the smallest resolved
    gap; below a few times it ``p(g)`` rolls off), the widest range of at least
    half a decade where ``p(g)`` falls with ``g`` and the local log-log slope
    (least squares over +-0.25 decade) stays within 0.05 of its median, beyond 2
    standard errors of the bin counts; if none qualifies, the flattest
    half-decade, with a warning.  No exponent is assumed: a fixed range such as
    0.01-0.1 lies above the power law at workstation sizes (512^2-2048^2,
    ``lambda_min = 32 a0``; ``docs/fig2.md``).  Columns:
    ``resolved_gap_over_g0``, ``fit_range_source`` (``auto`` or ``--fit-range``),
    ``fit_range_x_min``, ``fit_range_x_max`` (bin centres for ``auto``),
    ``fit_range_bins``, ``fit_range_qualified`` and ``fit_range_slope_deviation``
    (``auto`` only), ``exponent_fit_range``.

``fig2-gap-distribution.FMT``
    Fig. 2: collapsed ``p(g)`` against ``g / g0`` (log-log), one series per
    file/step, with the dashed ``(g/g0)^(-1/3)`` line of Eq. 13.  Each legend
    label states ``lambda_min`` (in ``a0``), and ``lambda_max / lambda_min`` and
    ``L / lambda_max`` where these differ between the series; shared values go
    into the legend title, and labels that would still coincide get
    ``(file:step)``.  Markers as in the paper: the smallest ``lambda_min`` filled,
    the next open (further ones open squares, triangles, ...).
``fig3-adhesion.FMT``
    Fig. 3: adhesive series normalised by ``c`` and ``g0`` of a non-adhesive
    reference step, labelled by ``1/kappa_att``; dotted line at ``rho / g0``.
    The reference is ``--reference`` (then every other step is normalised by
    it) or, for runs of the paper's protocol (``control.reference =
    "non-adhesive"``), each adhesive step's own reference step (step attribute
    ``plan.reference_step``).  Without either, no Fig. 3 is written.  Each
    distinct reference is drawn once: reference steps that are the same solve
    (:func:`solve_identity`: the same scene apart from its ``interaction``,
    ``control`` and ``output`` sections, the same interaction and the same load,
    as when several protocol files of one surface are given, each with its own
    copy of the reference) are one curve, and every adhesive step of those files
    is normalised by it; with ``--reference``, other steps that are the same
    solve as it are not drawn again.
``fig4-integrand.FMT``
    Fig. 4: the normalised integrand of Eq. 16 for ``rho / g0 = 0.01, 0.1, 1``.

The zero-gap tolerance (``--gap-tolerance``, default ``1e-6`` of the mean gap;
:func:`petgap.analysis.resolve_gap_tolerance`) decides which pixels are at zero
gap: solvers leave round-off gaps on contact pixels, and with exact zeros
demanded a Polonsky-Keer solution loses a large share of its contact area.

Attributes read from a result file (first found wins; the step group's own
attributes, then the root's, then the ``topography`` dataset's, then the JSON
of the validated scene in the root attribute ``scene_resolved``):

* ``rms_slope`` / ``statistics.rms_slope`` / ``topography.statistics.rms_slope`` /
  ``surface.rms_slope``: ``h0'``; if none is there, it is computed spectrally
  from the ``topography`` dataset.
* ``contact_modulus`` / ``material.contact_modulus``: ``E*``.
* ``interaction.kind`` (a name of :data:`petgap.mechanics.interactions.LAWS`:
  ``"hard-wall"``, ``"exponential"``, ...), and for an adhesive law its
  parameters, ``interaction.work_of_adhesion`` and ``interaction.range`` (``w``
  and the law's length); the law is rebuilt from them
  (:func:`petgap.mechanics.interactions.from_attributes`) and its own ``v'`` gives
  the attractive force (Eq. 15).  Eq. 16's prediction and Fig. 4's integrand are
  the paper's, for its exponential law, and are given for that law only.
* ``pixel_size`` (``[dx, dy]``), else ``grid.a0`` / ``a0`` (square pixels); the
  grid shape is the datasets' shape.
* optional: ``surface.lambda_min``, ``surface.lambda_max`` (legends);
  ``plan.chain``, ``plan.reference_step`` (Fig. 3 of a protocol run);
  ``solution.control``, ``solution.control_value`` with ``scene_resolved`` (which
  steps of different files are the same solve, for Fig. 3);
  ``solution.contact_fraction``, ``solution.kappa_rep``, ``solution.inv_kappa_att``
  (the solver's own values, tabled next to the analysis' as a cross-check).

Each step group needs the datasets ``gap`` and ``pressure``.  Steps whose
``complete`` attribute is not True are skipped with a warning (or refused, if
asked for by number).

Errors: a missing or unreadable file, a file that is not a petgap result, a
missing step, dataset or attribute, existing outputs (without ``--overwrite``):
``petgap-post: error: <message naming the file, step and item>`` from rank 0,
exit status 2 on every rank.
"""
import os

os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")  # before h5py is first imported

import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import h5py  # noqa: E402
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

from petgap import analysis  # noqa: E402
from petgap.app.argtypes import positive_float, positive_int, root_parser  # noqa: E402
from petgap.app import flow_post, overview, report  # noqa: E402
from petgap.app.figures import fig2_series, fig3_series, figure2, figure3, figure4  # noqa: E402
from petgap.app.tables import plain, plain_rows, write_csv, write_json  # noqa: E402
from petgap.io.results import (ResultFile, read_attrs, read_field, step_name,  # noqa: E402
                                unreadable)
from petgap.mechanics.interactions import ExponentialAdhesion, LAWS, law_class  # noqa: E402
from petgap.parallel.collective import root_decides  # noqa: E402
from petgap.parallel.grid import DecompositionError, Grid  # noqa: E402
from petgap.parallel.log import configure, report_failure  # noqa: E402
from petgap.surfaces.measured import length_unit  # noqa: E402
from petgap.surfaces.self_affine import psd_shape  # noqa: E402
from petgap.surfaces.statistics import (finite_difference_curvature,  # noqa: E402
                                        finite_difference_slopes, radial_psd, statistics)
from petgap._version import __version__

#: Exit status of a user error.
EXIT_USAGE = 2

TABLE_STEM = "gap-analysis"
FIG2_STEM = "fig2-gap-distribution"
FIG3_STEM = "fig3-adhesion"
FIG4_STEM = "fig4-integrand"
#: Cut-off gaps g_c / g0 of the near-contact-area columns (Eq. 14): at g0, c_n = pi c;
#: at 0.18 g0, c_n = c; at 1e-3 g0 (the roll-off of the paper's data), c_n = 0.031 c.
GC_OVER_G0 = (1.0, 0.18, 1e-3)
#: Gaps below this fraction of g0 are solver round-off rather than physics; if they make
#: up more than ROUND_OFF_WARN of the contact area a warning suggests --gap-tolerance.
ROUND_OFF_GAP = 1e-6
ROUND_OFF_WARN = 0.01

#: Table columns, in order.
COLUMNS = [
    "file", "step", "chain", "reference_step", "nx", "ny", "dx", "dy", "length_unit",
    "pressure_unit", "lambda_min",
    "lambda_max", "interaction",
    "work_of_adhesion", "range", "rms_slope", "rms_slope_source", "contact_modulus",
    "gap_tolerance", "contact_pixels", "c", "A_rep", "P_rep", "P_pixel_edges", "d_rep", "g0",
    "mean_pressure", "kappa_rep", "exponent", "power_law_x_min", "power_law_x_max",
    "power_law_decades", "resolved_gap_over_g0", "fit_range_source", "fit_range_x_min",
    "fit_range_x_max", "fit_range_bins", "fit_range_qualified", "fit_range_slope_deviation",
    "exponent_fit_range",
    "zero_gap_fraction", "cn_g0", "cn_g0_eq14", "cn_018g0", "cn_018g0_eq14", "cn_0001g0",
    "cn_0001g0_eq14",
    "F_att", "F_att_noncontact", "F_att_eq16_printed", "F_att_eq16_exact",
    "inv_kappa_att", "inv_kappa_att_eq16_printed", "inv_kappa_att_eq16_exact",
    "c_solver", "kappa_rep_solver", "inv_kappa_att_solver",
    "mean_gap", "patches", "patch_area_mean", "patch_area_max", "control", "control_value",
    "solver", "converged", "reason", "iterations", "kkt_pressure", "kkt_gap", "wall_time",
] + flow_post.FLOW_COLUMNS
#: Solver status columns and the step attributes they come from.
STATUS = {"control": ("solution.control", str), "control_value": ("solution.control_value", float),
          "solver": ("solution.solver", str), "converged": ("solution.converged", bool),
          "reason": ("solution.reason", str), "iterations": ("solution.iterations", int),
          "kkt_pressure": ("solution.kkt_pressure", float), "kkt_gap": ("solution.kkt_gap", float),
          "wall_time": ("solution.wall_time", float)}
MANIFEST = "figures.json"
PATCH_TABLE = "patches.csv"
PATCH_COLUMNS = ["file", "step", "patch", "pixels", "area", "perimeter_pixel_edges",
                 "first_pixel"]
SURFACE_STEM = "surface-statistics"
SURFACE_COLUMNS = ["file", "nx", "ny", "dx", "dy", "length_unit", "mean", "rms_height", "rms_slope",
                   "rms_curvature", "rms_slope_fd", "rms_slope_fd_inner",
                   "rms_curvature_fd_inner", "kind", "hurst", "lambda_min", "lambda_max"]


class PostError(ValueError):
    """A user error (missing file, step, dataset or attribute); exit status 2."""


# ------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class Input:
    """A result file and optionally one step of it."""
    path: Path
    step: int = None

    @property
    def text(self):
        return str(self.path) if self.step is None else f"{self.path}:{self.step}"


_STEP_SUFFIX = re.compile(r"(.+):(?:step_)?(\d+)")


def parse_input(text):
    """``FILE`` or ``FILE:STEP`` (``STEP`` = ``3`` or ``step_0003``) -> :class:`Input`.

    A path that exists as written is taken as a file even if it ends in ``:<digits>``.
    """
    m = _STEP_SUFFIX.fullmatch(text)
    if m and not Path(text).exists():
        return Input(Path(m.group(1)), int(m.group(2)))
    return Input(Path(text))


def _check_result_file(path):
    """Rank 0: raise PostError unless ``path`` is a readable petgap result file."""
    if not path.exists():
        raise PostError(f"{path}: file not found")
    if not path.is_file():
        raise PostError(f"{path}: not a file")
    try:
        ok = h5py.is_hdf5(str(path))
    except OSError as exc:
        raise PostError(f"{path}: cannot read: {exc}") from None
    if not ok:
        raise PostError(f"{path}: not an HDF5 file (and so not a petgap result file)")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise PostError(f"{path}: {unreadable(exc)}") from None
    with f:
        if "petgap_version" not in f.attrs:
            raise PostError(f"{path}: not a petgap result file (no root attribute "
                            f"'petgap_version')")


# --------------------------------------------------------------- attributes
def _flatten(mapping, prefix=""):
    out = {}
    for k, v in mapping.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


class Attributes:
    """The attribute sources of one step, searched in order."""

    def __init__(self, where, sources):
        self.where = where          # "FILE, step_0000"
        self.sources = sources      # [(label, dict)]

    def find(self, names, what, required=True, kind=float):
        """``(value, "label: name")`` of the first attribute found, else PostError or None."""
        for label, attrs in self.sources:
            for name in names:
                value = attrs.get(name)
                if value is None:
                    continue
                try:
                    return kind(value), f"{label}: {name}"
                except (TypeError, ValueError):
                    raise PostError(f"{self.where}: attribute {name!r} ({label}) = {value!r} "
                                    f"is not a valid {what}") from None
        if required:
            looked = ", ".join(repr(n) for n in names)
            where = ", ".join(label for label, _ in self.sources)
            raise PostError(f"{self.where}: missing attribute {names[0]!r} ({what}); looked for "
                            f"{looked} in the {where}")
        return None, None


def step_attributes(result, index):
    """:class:`Attributes` of step ``index`` of an open :class:`petgap.io.results.ResultFile`."""
    name = step_name(index)
    step = (f"{name} attributes", read_attrs(result.file[name]))
    return Attributes(f"{result.path}, {name}", [step] + file_attributes(result).sources)


# ----------------------------------------------------------------- analysis
@dataclass
class StepResult:
    """One analysed step: its table row and its curves (the same on every rank)."""
    row: dict
    distribution: object
    x: np.ndarray
    y: np.ndarray
    adhesive: bool
    meta: dict = field(default_factory=dict)
    patches: object = None
    maps: object = None          # overview.StepMaps on the root rank, else None
    flow_maps: object = None     # flow_post.FlowMaps on the root rank, else None


def analyse_step(result, index, args, grids, comm, log, surface=None):
    """Analyse step ``index`` of an open result file (collective).

    ``surface`` is the file's :class:`petgap.app.overview.SurfaceView` (its topography
    map goes into the step's maps), if the file has a topography.
    """

    f = result.file
    name = step_name(index)
    where = f"{result.path}, {name}"
    group = f[name]
    for dataset in ("gap", "pressure"):
        if dataset not in group:
            raise PostError(f"{where}: dataset {dataset!r} missing (a petgap-post input needs "
                            f"the 'gap' and 'pressure' fields of each step)")
    shape = tuple(int(n) for n in group["gap"].shape)
    if len(shape) != 2 or tuple(group["pressure"].shape) != shape:
        raise PostError(f"{where}: 'gap' {tuple(group['gap'].shape)} and 'pressure' "
                        f"{tuple(group['pressure'].shape)} are not 2D fields of one shape")
    attrs = step_attributes(result, index)
    pixel, _ = attrs.find(["pixel_size"], "pixel size [dx, dy]", required=False,
                          kind=lambda v: tuple(float(x) for x in np.ravel(v)))
    if pixel is None:
        a0, _ = attrs.find(["grid.a0", "a0", "pixel_size"], "pixel size")
        pixel = (a0, a0)
    if len(pixel) != 2 or not all(math.isfinite(v) and v > 0 for v in pixel):
        raise PostError(f"{where}: pixel size {pixel} is not two positive numbers")
    dx, dy = pixel
    modulus, _ = attrs.find(["contact_modulus", "material.contact_modulus"], "contact modulus")
    law = _interaction_law(attrs, where)
    kind, adhesive = law.name, law.adhesive
    w, rho = (law.work, law.length_scale) if adhesive else (None, None)
    paper = isinstance(law, ExponentialAdhesion)  # Eq. 16 and Fig. 4 are its closed forms
    lmin, _ = attrs.find(["surface.lambda_min", "lambda_min"], "lambda_min", required=False)
    lmax, _ = attrs.find(["surface.lambda_max", "lambda_max"], "lambda_max", required=False)

    grid = _grid(grids, shape, dx, dy, comm, where)

    slope, slope_source = attrs.find(["rms_slope", "statistics.rms_slope",
                                      "topography.statistics.rms_slope", "surface.rms_slope"],
                                     "rms slope", required=False)
    if slope is None:
        if "topography" not in f:
            raise PostError(f"{where}: missing attribute 'rms_slope' (rms slope h0'); looked for "
                            f"'rms_slope', 'statistics.rms_slope', "
                            f"'topography.statistics.rms_slope', 'surface.rms_slope', and there "
                            f"is no 'topography' dataset to compute it from")
        if tuple(f["topography"].shape) != shape:
            raise PostError(f"{where}: 'topography' has shape {tuple(f['topography'].shape)}, "
                            f"the step's fields {shape}")
        slope = statistics(grid, read_field(f, "topography", grid)).rms_slope
        slope_source = "computed from the topography dataset"

    gap = read_field(group, "gap", grid)
    pressure = read_field(group, "pressure", grid)

    tol = analysis.resolve_gap_tolerance(grid, gap, args.gap_tolerance)
    periodic, _ = attrs.find(["surface.periodic"], "periodicity", required=False, kind=bool)
    periodic = True if periodic is None else periodic    # files made before the key existed
    stats = analysis.contact_statistics(grid, gap, pressure, slope, modulus, gap_tolerance=tol,
                                        periodic=periodic)
    dist = analysis.gap_distribution(grid, gap, pressure, bins_per_decade=args.bins,
                                     gap_tolerance=tol)
    c, g0 = stats.contact_fraction, stats.g0
    mask = analysis.contact_mask(gap, pressure, tol)
    patches = analysis.contact_patches(grid, mask, periodic=periodic)
    maps = {} if surface is None else {"topography": surface.topography}
    for field_name, values in (("gap", gap), ("pressure", pressure), ("contact", mask)):
        maps[field_name] = analysis.block_map(grid, values, max_pixels=args.map_pixels)
    chain, _ = attrs.find(["plan.chain"], "chain", required=False, kind=str)
    ref_step, _ = attrs.find(["plan.reference_step"], "reference step", required=False, kind=int)
    ref_step = ref_step if ref_step is not None and ref_step >= 0 else None
    solver = {name: attrs.find([f"solution.{name}"], name, required=False)[0]
              for name in ("contact_fraction", "kappa_rep", "inv_kappa_att")}
    row = {k: None for k in COLUMNS}
    row.update(file=str(result.path), step=int(index), chain=chain, reference_step=ref_step,
               c_solver=solver["contact_fraction"], kappa_rep_solver=solver["kappa_rep"],
               inv_kappa_att_solver=solver["inv_kappa_att"] if adhesive else None,
               nx=shape[0], ny=shape[1], dx=dx, dy=dy,
               lambda_min=lmin, lambda_max=lmax, interaction=kind, work_of_adhesion=w,
               range=rho, rms_slope=slope, rms_slope_source=slope_source,
               contact_modulus=modulus, contact_pixels=stats.contact_pixels, c=c,
               A_rep=stats.contact_area, P_rep=stats.perimeter,
               P_pixel_edges=stats.pixel_edge_length, d_rep=stats.mean_diameter, g0=g0,
               mean_pressure=stats.mean_pressure, kappa_rep=stats.kappa_rep,
               zero_gap_fraction=dist.zero_gap_fraction, gap_tolerance=tol,
               mean_gap=grid.mean(gap), patches=patches.count,
               patch_area_mean=float(np.mean(patches.areas)) if patches.count else None,
               patch_area_max=float(np.max(patches.areas)) if patches.count else None)
    for column, (attribute, convert) in STATUS.items():
        row[column] = attrs.find([attribute], column, required=False, kind=convert)[0]
    flow_row, flow_maps = flow_post.analyse_flow(group, attrs, grid, args.map_pixels,
                                                 f"{where}: flow through the gaps")
    row.update(flow_row)
    x = y = np.empty(0)
    usable = 0 < c < 1 and math.isfinite(g0) and g0 > 0
    fit_note = None
    if usable:
        row["resolved_gap_over_g0"] = analysis.resolved_gap(stats.mean_diameter, max(dx, dy))
    if usable and dist.centres.size:
        x, y = analysis.collapse(dist, None, c, g0)
        fit = analysis.fit_power_law(x, y)
        row.update(exponent=fit.exponent, power_law_x_min=fit.x_min,
                   power_law_x_max=fit.x_max, power_law_decades=fit.decades)
        if args.fit_range is None:
            chosen = analysis.auto_fit_range(x, y, dist.counts,
                                             x_resolution=row["resolved_gap_over_g0"])
            lo, hi = chosen.x_min, chosen.x_max
            row.update(fit_range_source="auto", fit_range_qualified=chosen.qualified,
                       fit_range_slope_deviation=chosen.slope_deviation)
            if not chosen.qualified:
                fit_note = chosen.reason
        else:
            lo, hi = args.fit_range
            row["fit_range_source"] = "--fit-range"
        if math.isfinite(lo) and math.isfinite(hi):
            ranged = analysis.fit_power_law(x, y, x_range=(lo, hi))
            row.update(fit_range_x_min=lo, fit_range_x_max=hi, fit_range_bins=ranged.npoints,
                       exponent_fit_range=ranged.exponent)
        if fit_note:
            log.warning("%s: exponent fit range: %s%s", where, fit_note,
                        "" if math.isfinite(lo) else "; pass --fit-range LO HI to fit anyway")
    if usable:
        near = analysis.near_contact_area(grid, gap, pressure,
                                          [r * g0 for r in GC_OVER_G0 + (ROUND_OFF_GAP,)],
                                          c=c, g0=g0, gap_tolerance=tol)
        row.update(cn_g0=near.measured[0], cn_g0_eq14=near.predicted[0],
                   cn_018g0=near.measured[1], cn_018g0_eq14=near.predicted[1],
                   cn_0001g0=near.measured[2], cn_0001g0_eq14=near.predicted[2])
        if near.measured[3] > ROUND_OFF_WARN * c:
            log.warning("%s: %.3g of the area (%.0f %% of the contact area) has gaps below "
                        "%g g0 = %.3g outside contact: round-off gaps of contact pixels? "
                        "--gap-tolerance sets the gap that counts as zero", where, near.measured[3],
                        100 * near.measured[3] / c, ROUND_OFF_GAP, ROUND_OFF_GAP * g0)
    else:
        log.warning("%s: contact fraction %g: no d_rep/g0, so no collapse, fit or c_n", where, c)
    if adhesive:
        force = analysis.attractive_force_measured(grid, gap, law, pressure=pressure,
                                                   gap_tolerance=tol)
        # with adhesion the wall reaction in contact is p + v'(0): F_rep = F - F_att
        f_rep = stats.repulsive_force - force.contact_force
        scale = stats.contact_area * slope * modulus
        row.update(F_att=force.force, F_att_noncontact=force.noncontact_force,
                   inv_kappa_att=analysis.inverse_kappa_att(force.force, slope, modulus,
                                                            stats.contact_area),
                   kappa_rep=scale / f_rep if f_rep > 0 else math.nan)
        if usable:
            by_gap = analysis.attractive_force_by_gap(grid, gap, pressure, law, g0,
                                                      gap_tolerance=tol)
            force_by_gap = {"x": by_gap.x.tolist(), "share": by_gap.share.tolist(),
                            "contact_share": by_gap.contact_share,
                            "outside_share": by_gap.outside_share,
                            "rho_over_g0": rho / g0 if paper else None}
        if usable and paper:
            eq16 = analysis.attractive_force_eq16(w, rho, g0, stats.contact_area)
            row.update(F_att_eq16_printed=eq16.printed, F_att_eq16_exact=eq16.exact,
                       inv_kappa_att_eq16_printed=analysis.inverse_kappa_att(
                           eq16.printed, slope, modulus, stats.contact_area),
                       inv_kappa_att_eq16_exact=analysis.inverse_kappa_att(
                           eq16.exact, slope, modulus, stats.contact_area))
    meta = {"lambda_min_a0": lmin / dx if lmin else None, "rho": rho, "reference_step": ref_step,
            "force_by_gap": force_by_gap if adhesive and usable else None,
            "solve": solve_identity(result, index, attrs, kind, w, rho)}
    # no exponent is told where no range qualified to fit it (the warning above says so)
    finite = [k for k in ("exponent", "exponent_fit_range")
              if row[k] is not None and math.isfinite(row[k])
              and not (fit_note and not math.isfinite(row.get("fit_range_x_min") or math.nan))]
    log.info("%s: c = %.4g, P_rep = %.6g (pixel edges %.6g), d_rep = %.4g, g0 = %.4g%s%s", where,
             c, stats.perimeter, stats.pixel_edge_length, stats.mean_diameter, g0,
             f", exponent {row['exponent']:.3f} over x = {row['power_law_x_min']:.3g} .. "
             f"{row['power_law_x_max']:.3g}" if "exponent" in finite else "",
             f", {row['exponent_fit_range']:.3f} over the {row['fit_range_source']} fit range "
             f"{row['fit_range_x_min']:.3g} .. {row['fit_range_x_max']:.3g}"
             if "exponent_fit_range" in finite else "")
    title = f"{result.path}, {name}: {kind}" + (
        f", {row['control']} = {row['control_value']:.4g}" if row["control"] else "")
    row.update(units_of(attrs))
    if flow_maps is not None:
        flow_maps.units = (row["length_unit"], row["pressure_unit"])
    step_maps = overview.StepMaps(maps, c, title, (row["length_unit"], row["pressure_unit"])) \
        if comm.rank == 0 else None
    return StepResult(row=row, distribution=dist, x=x, y=y, adhesive=adhesive, meta=meta,
                      patches=patches, maps=step_maps, flow_maps=flow_maps)


def _interaction_law(attrs, where):
    """The interaction law a step was solved with, rebuilt from its attributes (registry)."""
    kind, _ = attrs.find(["interaction.kind", "interaction"], "interaction kind", kind=str)
    if kind not in LAWS:
        raise PostError(f"{where}: interaction.kind = {kind!r} is not known to petgap-post "
                        f"({', '.join(LAWS)})")

    def parameter(key):
        return attrs.find([f"interaction.{key}", key], f"interaction {key}")[0]

    try:
        return law_class(kind).from_attributes(parameter)
    except PostError:
        raise
    except ValueError as exc:  # a parameter the law refuses
        raise PostError(f"{where}: interaction.kind = {kind!r}: {exc}") from None


def solve_identity(result, index, attrs, kind, w, rho):
    """What identifies the solve that produced a step, across files (see :func:`fig3_groups`).

    Two steps are the same solve if their files' validated scenes agree in everything
    but the ``interaction``, ``control`` and ``output`` sections (grid, surface with its
    seed, material, solver), the interaction applied to the step agrees, and the step's
    own control (``solution.control`` and ``solution.control_value``: the load of a
    non-adhesive reference) agrees.  Without the scene or the step's control attributes
    a step is only itself: ``("file", resolved path, index)``.
    """
    scene = dict(next((d for label, d in attrs.sources if label == "scene_resolved"), {}))
    control, _ = attrs.find(["solution.control"], "control kind", required=False, kind=str)
    value, _ = attrs.find(["solution.control_value"], "control value", required=False)
    if not scene or control is None or value is None:
        try:
            path = str(Path(result.path).resolve())
        except OSError:
            path = str(result.path)
        return ("file", path, int(index))
    shared = {k: v for k, v in scene.items()
              if not k.startswith(("interaction.", "control.", "output."))}
    return ("solve", json.dumps(shared, sort_keys=True, default=str), kind, w, rho, control,
            float(value))


def units_of(attrs):
    """``{"length_unit": ..., "pressure_unit": ...}`` of a result file (its scene's
    ``units``; "1", the scene's own units, in files without them)."""
    length, _ = attrs.find(["units.length"], "length unit", required=False, kind=str)
    pressure, _ = attrs.find(["units.pressure"], "pressure unit", required=False, kind=str)
    try:
        length = length_unit(length) if length and length != "1" else length
    except ValueError:
        pass    # a unit petgap does not convert: labelled as the scene gives it
    return {"length_unit": length or "1", "pressure_unit": pressure or "1"}


def file_attributes(result):
    """:class:`Attributes` of a result file itself (root, topography dataset, scene)."""
    f = result.file
    sources = [("root attributes", read_attrs(f))]
    if "topography" in f:
        sources.append(("topography dataset attributes", read_attrs(f["topography"])))
    scene = sources[0][1].get("scene_resolved")
    if scene:
        try:
            sources.append(("scene_resolved", _flatten(json.loads(scene))))
        except (TypeError, ValueError):
            raise PostError(f"{result.path}: root attribute 'scene_resolved' is not valid JSON") \
                from None
    return Attributes(str(result.path), sources)


def analyse_surface(result, args, grids, comm):
    """Statistics, PSD and topography map of a file's ``topography`` (collective), or None.

    The PSD model is Eq. 5 of the paper for a generated self-affine surface, with
    ``C0`` set so that the model summed over the grid's modes gives the measured
    rms height (the normalisation of :func:`petgap.surfaces.statistics.radial_psd`,
    ``mean(h^2) = (1 / A0) sum_q C(q)``).
    """
    f = result.file
    if "topography" not in f:
        return None
    shape = tuple(int(n) for n in f["topography"].shape)
    if len(shape) != 2:
        raise PostError(f"{result.path}: 'topography' {shape} is not a 2D field")
    attrs = file_attributes(result)
    dx, _ = attrs.find(["grid.dx", "grid.a0", "a0"], "pixel size")
    dy, _ = attrs.find(["grid.dy", "grid.a0", "a0"], "pixel size")
    grid = _grid(grids, shape, dx, dy, comm, str(result.path))
    heights = read_field(f, "topography", grid)
    stats = statistics(grid, heights)
    slope_fd, slope_fd_inner = finite_difference_slopes(grid, heights)
    curvature_fd = finite_difference_curvature(grid, heights)
    q, psd = radial_psd(grid, heights)
    kind, _ = attrs.find(["surface.kind"], "surface kind", required=False, kind=str)
    model, label = None, ""
    if kind == "self-affine":
        hurst, _ = attrs.find(["surface.hurst"], "Hurst exponent")
        lmin, _ = attrs.find(["surface.lambda_min"], "lambda_min")
        lmax, _ = attrs.find(["surface.lambda_max"], "lambda_max", required=False)
        lmax = min(grid.Lx, grid.Ly) if lmax is None else lmax
        q1, q2 = 2 * math.pi / lmax, 2 * math.pi / lmin
        qm = grid.q_magnitude()
        modes = float(np.sum(grid.hermitian_weight[:, None] * psd_shape(qm, hurst, q1, q2)))
        modes = comm.allreduce(modes)
        c0 = grid.area * stats.rms_height ** 2 / modes if modes > 0 else math.nan
        model = c0 * psd_shape(q, hurst, q1, q2)
        label = (f"Eq. 5: H = {hurst:g}, $\\lambda_{{min}}$ = {lmin:g}, "
                 f"$\\lambda_{{max}}$ = {lmax:g}")
    topo_map = analysis.block_map(grid, heights, max_pixels=args.map_pixels)
    spectrum = {"q": q.tolist(), "C": psd.tolist(),
                "model": None if model is None else model.tolist()}
    row = {"file": str(result.path), "nx": shape[0], "ny": shape[1], "dx": dx, "dy": dy,
           "mean": stats.mean, "rms_height": stats.rms_height, "rms_slope": stats.rms_slope,
           "rms_curvature": stats.rms_curvature, "rms_slope_fd": slope_fd,
           "rms_slope_fd_inner": slope_fd_inner, "rms_curvature_fd_inner": curvature_fd,
           "kind": kind,
           "hurst": attrs.find(["surface.hurst"], "Hurst exponent", required=False)[0],
           "lambda_min": attrs.find(["surface.lambda_min"], "lambda_min", required=False)[0],
           "lambda_max": attrs.find(["surface.lambda_max"], "lambda_max", required=False)[0],
           "psd": spectrum, "length_unit": units_of(attrs)["length_unit"]}
    return overview.SurfaceView(statistics=stats, q=q, psd=psd, model=model, model_label=label,
                                topography=topo_map, row=row, length_unit=row["length_unit"])


def _grid(grids, shape, dx, dy, comm, where):
    key = (shape, dx, dy)
    if key not in grids:
        grids.clear()  # one grid at a time: its FFT buffers are 16 bytes per point
        try:
            grids[key] = Grid(shape, size=(shape[0] * dx, shape[1] * dy), comm=comm,
                              planner="estimate", wisdom=False)
        except DecompositionError as exc:
            raise PostError(f"{where}: {exc}") from None
    return grids[key]


#: Root attributes of a result file shown in the report (provenance).
PROVENANCE = ("petgap_version", "command_line", "scene_path", "start_time", "end_time",
              "mpi_size", "hostname", "complete", "petsc_options", "scene")


def analyse_inputs(inputs, args, comm, log, surfaces=None, provenance=None):
    """Analyse every step asked for (collective); returns a list of StepResult.

    If ``surfaces`` is a dict, each file's :class:`petgap.app.overview.SurfaceView`
    (or None without a topography) is stored in it under the file's path; a file
    without steps (a surface-only run) is then analysed for its surface alone.
    """
    out, grids = [], {}
    for item in inputs:
        root_decides(comm, lambda: _check_result_file(item.path))
        with ResultFile.open(item.path, comm) as result:
            surface = None
            if surfaces is not None:
                surface = analyse_surface(result, args, grids, comm)
                surfaces[str(item.path)] = surface
            if provenance is not None:
                root = read_attrs(result.file)
                provenance[str(item.path)] = {k: plain(root.get(k)) for k in PROVENANCE}
            if not result.complete:
                log.warning("%s was not closed after a successful run (root attribute "
                            "'complete' is not True); using its complete steps", item.path)
            steps = result.steps()
            done = set(result.completed_steps())
            if item.step is not None:
                if item.step not in steps:
                    raise PostError(f"{item.path}: no step {item.step} (group "
                                    f"'step_{item.step:04d}'); the file has steps {steps}")
                if item.step not in done:
                    raise PostError(f"{item.path}: step {item.step} is incomplete "
                                    f"(interrupted run); its fields may be missing or partial")
                chosen = [item.step]
            else:
                if not steps and surface is not None:
                    log.info("%s: no step groups (a surface-only run): its surface only",
                             item.path)
                elif not steps:
                    raise PostError(f"{item.path}: no step groups ('step_0000', ...): a "
                                    f"surface-only run (control.kind = \"none\")?")
                skipped = [s for s in steps if s not in done]
                if skipped:
                    log.warning("%s: skipping incomplete step(s) %s", item.path, skipped)
                chosen = [s for s in steps if s in done]
            for index in chosen:
                out.append(analyse_step(result, index, args, grids, comm, log, surface))
    return out


# ------------------------------------------------------------------ outputs
def output_paths(args):
    """The files this run may write (Fig. 3 only if there is something to normalise)."""
    d = args.output_dir
    return [d / f"{TABLE_STEM}.csv", d / f"{TABLE_STEM}.json",
            d / f"{FIG2_STEM}.{args.format}", d / f"{FIG3_STEM}.{args.format}",
            d / f"{FIG4_STEM}.{args.format}", d / MANIFEST, d / PATCH_TABLE,
            d / f"{SURFACE_STEM}.csv", d / f"{SURFACE_STEM}.json", d / report.REPORT]


def check_outputs(args):
    """Rank 0: PostError if an output exists (without --overwrite) or cannot be made."""
    d = args.output_dir
    if d.exists() and not d.is_dir():
        raise PostError(f"--output-dir {d} exists and is not a directory")
    if not args.overwrite:
        existing = [str(p) for p in output_paths(args) if p.exists()]
        if existing:
            raise PostError(f"refusing to overwrite existing output {', '.join(existing)}; "
                            f"pass --overwrite or choose another --output-dir")
    d.mkdir(parents=True, exist_ok=True)


SURFACE_CONVENTIONS = {
    "rms_height, rms_slope, rms_curvature": "spectral (petgap.surfaces.statistics), the mean "
                                            "removed; h0'' = sqrt(<(laplacian h)^2>) / 2",
    "rms_slope_fd, rms_slope_fd_inner": "by forward differences, with the wrap-around pairs "
                                        "and inside the map only (their gap: the seam)",
    "rms_curvature_fd_inner": "five-point Laplacian at the points whose neighbours lie "
                              "inside the map",
    "psd": "C(q) = A0 |h_q|^2 / N^2, radially averaged on logarithmic bins "
           "(petgap.surfaces.statistics.radial_psd); model: Eq. 5 with C0 from the rms height",
}


def write_tables(results, args, groups, fig2, fig3, sweeps=None):
    """The CSV and JSON tables; ``fig2``, ``fig3`` are the drawn series (:func:`fig2_series`,
    :func:`fig3_series`), recorded with their legend labels."""
    rows = plain_rows([r.row for r in results], COLUMNS)
    write_csv(args.output_dir / f"{TABLE_STEM}.csv", rows, COLUMNS)
    doc = {
        "petgap_version": __version__,
        "command_line": " ".join(sys.argv),
        "conventions": {
            "c": "A_rep / A0, repulsive contact = zero gap and p > 0",
            "P_rep": "marching squares, crossings from the edge asymptotics p ~ s^1/2, "
                     "g ~ s^3/2 (petgap.analysis.perimeter)",
            "P_pixel_edges": "raw pixel-edge length (over-counts by ~4/pi)",
            "d_rep": "pi A_rep / P_rep (Eq. 2)", "g0": "4 h0' d_rep / 3 (Eq. 12)",
            "collapse": "x = g/g0, y = 3 g0 (1-c) density / (2 pi c); Eq. 13: y = x^(-1/3)",
            "power_law": "longest run of bins with local slope within 0.1 of -1/3 and y within "
                         "a factor 2 of x^(-1/3) (petgap.analysis.fit_power_law)",
            "resolved_gap_over_g0": "(max(dx, dy) / (2 d_rep))^(3/2): the gap half a pixel "
                                    "from a contact edge by Eq. 12, over g0 "
                                    "(petgap.analysis.resolved_gap)",
            "fit_range": fit_range_rule(),
            "exponent_fit_range": "least-squares slope of log y on log x over the bins with "
                                  "fit_range_x_min <= x <= fit_range_x_max",
            "cn": "fraction of A0 with 0 < g < g_c; eq14 = pi c (g_c/g0)^(2/3)",
            "F_att": "-sum dx dy v'(g) over all pixels (< 0 attractive); F_att_noncontact: "
                     "pixels not in repulsive contact",
            "F_att_eq16_printed": "-(2 pi/3) w A_rep / (g0^2 rho)^(1/3), as printed",
            "F_att_eq16_exact": "the integral of Eq. 16 exactly: Gamma(2/3) x printed",
            "inv_kappa_att": "-F_att / (h0' E* A_rep)",
            "kappa_rep": "A_rep h0' E* / F_rep, F_rep = repulsive (wall) force in contact",
            "fig3_references": "each distinct non-adhesive reference once: steps of the same "
                               "scene (apart from interaction, control, output), the same "
                               "interaction and the same load are one solve; the others are "
                               "listed as duplicates",
        },
        "fit_range": {"option": None if args.fit_range is None else list(args.fit_range),
                      "auto": {"resolution_factor": analysis.FIT_RESOLUTION_FACTOR,
                               "x_max": analysis.FIT_X_MAX,
                               "slope_band": analysis.FIT_SLOPE_BAND,
                               "slope_window_decades": analysis.FIT_SLOPE_WINDOW,
                               "min_decades": analysis.FIT_MIN_DECADES,
                               "min_count": analysis.FIT_MIN_COUNT,
                               "sigmas": analysis.FIT_SIGMAS}},
        "fig3_references": [{"file": g.reference.row["file"], "step": g.reference.row["step"],
                             "c": plain(g.reference.row["c"]),
                             "g0": plain(g.reference.row["g0"]),
                             "normalised_steps": [[m.row["file"], m.row["step"]]
                                                  for m in g.members],
                             "duplicates": [[d.row["file"], d.row["step"]]
                                            for d in g.duplicates]}
                            for g in groups],
        "legends": {"fig2": [{"file": s.result.row["file"], "step": s.result.row["step"],
                              "label": s.label} for s in fig2.series],
                    "fig2_title": fig2.title,
                    "fig3": [{"file": s.result.row["file"], "step": s.result.row["step"],
                              "reference": s.is_reference, "label": s.label} for s in fig3]},
        "rows": rows,
        "sweeps": {path: fits.to_dict() for path, fits in (sweeps or {}).items()},
        "force_by_gap": [dict(file=r.row["file"], step=r.row["step"],
                              **{k: plain(v) if not isinstance(v, list) else v
                                 for k, v in r.meta["force_by_gap"].items()})
                         for r in results if r.meta.get("force_by_gap")],
        "distributions": [{"file": r.row["file"], "step": r.row["step"],
                           "edges": r.distribution.edges.tolist(),
                           "counts": r.distribution.counts.tolist(),
                           "density": [plain(v) for v in r.distribution.density],
                           "zero_gap_fraction": r.distribution.zero_gap_fraction,
                           "integral": plain(r.distribution.integral)} for r in results],
    }
    write_json(args.output_dir / f"{TABLE_STEM}.json", doc)


def fit_range_rule():
    """The rule of the default exponent fit range, in words (``--help``, JSON conventions)."""
    a = analysis
    return (f"the widest range of x = g/g0, at least {a.FIT_MIN_DECADES:g} decade, between "
            f"{a.FIT_RESOLUTION_FACTOR:g} x_res and {a.FIT_X_MAX:g} (x_res = "
            f"(a0 / (2 d_rep))^(3/2): the gap half a pixel from a contact edge by Eq. 12, "
            f"the smallest resolved gap; column resolved_gap_over_g0), over bins of at least "
            f"{a.FIT_MIN_COUNT} pixels, where p(g) falls with g and the local log-log slope "
            f"(least squares over +-{a.FIT_SLOPE_WINDOW:g} decade) stays within "
            f"{a.FIT_SLOPE_BAND:g} of its median, plus {a.FIT_SIGMAS:g} standard errors from the "
            f"bin counts (petgap.analysis.auto_fit_range); if no range qualifies, the flattest "
            f"{a.FIT_MIN_DECADES:g} decade (fit_range_qualified false, and a warning). The "
            f"range used is recorded in the columns fit_range_source, fit_range_x_min, "
            f"fit_range_x_max and fit_range_bins")


# ---------------------------------------------------------------------- main
def build_parser(rank=0):
    """The argument parser of ``petgap-post`` (only ``rank`` 0 prints)."""
    p = root_parser(rank, prog="petgap-post",
                    description="Gap distributions, contact perimeter and adhesion (the paper's "
                                "Eqs. 2, 12-16 and Figs. 2-4) from petgap result files. "
                                "MPI-aware: run as mpirun -n P petgap-post ... or serially.")
    p.add_argument("inputs", nargs="+", metavar="RUN.h5[:STEP]",
                   help="result files; FILE:STEP (3 or step_0003) picks one step, otherwise "
                        "all complete steps are analysed")
    p.add_argument("-o", "--output-dir", type=Path, default=Path("."), metavar="DIR",
                   help="where tables and figures go (created if missing; default: .)")
    p.add_argument("--bins", type=positive_int, default=10, metavar="N",
                   help="logarithmic gap bins per decade (default 10)")
    p.add_argument("--reference", type=parse_input, metavar="RUN.h5[:STEP]",
                   help="non-adhesive step whose c and g0 normalise Fig. 3 (default step: the "
                        "first complete one)")
    p.add_argument("--format", choices=("png", "pdf", "svg"), default="png",
                   help="figure file format (default png)")
    p.add_argument("--fit-range", nargs=2, type=positive_float, default=None,
                   metavar=("LO", "HI"),
                   help="x = g/g0 range of the exponent fit of Eq. 13 (column "
                        "exponent_fit_range); given, exactly this range for every step. "
                        "Default: chosen per step from its data: "
                        + fit_range_rule().replace("%", "%%"))
    p.add_argument("--gap-tolerance", type=float, default=None, metavar="G",
                   help="gaps <= G (length units) count as zero gap: contact where p > 0, "
                        "'zero gap' (not in the histogram) elsewhere (default: 1e-6 x the "
                        "mean gap, above the solver's round-off; 0 demands exact zeros)")
    p.add_argument("--map-pixels", type=positive_int, default=overview.FIGURE_MAP_PIXELS,
                   metavar="N", help="largest number of pixels per axis of the maps; bigger "
                   "fields are block-averaged (default %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("-q", "--quiet", action="store_true", help="print only warnings and errors")
    return p


def main(argv=None):
    """Entry point of ``petgap-post``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    comm = MPI.COMM_WORLD
    parser = build_parser(comm.rank)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # same argv everywhere: every rank exits alike
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    problem = None
    if args.fit_range is not None and not args.fit_range[0] < args.fit_range[1]:
        problem = "--fit-range LO HI needs LO < HI"
    elif args.gap_tolerance is not None and not (math.isfinite(args.gap_tolerance)
                                                 and args.gap_tolerance >= 0):
        problem = f"--gap-tolerance {args.gap_tolerance} must be a finite number >= 0"
    if problem:
        if comm.rank == 0:
            print(f"petgap-post: error: {problem}", file=sys.stderr, flush=True)
        return EXIT_USAGE
    log = configure(comm, quiet=args.quiet).getChild("post")
    inputs = [parse_input(t) for t in args.inputs]
    failure_comm = comm.Dup()
    try:
        status = _run(args, inputs, comm, log)
    except Exception as exc:
        return report_failure(exc, comm, failure_comm, program="petgap-post")
    failure_comm.Free()
    return status


def _find_reference(results, item, comm):
    """The already analysed step ``item`` refers to (its first step if none is named), or None.

    Rank 0 compares the resolved paths, so that every rank picks the same step.
    """
    def same(a, b):
        try:
            return Path(a).resolve() == Path(b).resolve()
        except OSError:
            return False

    def decide():
        matches = [i for i, r in enumerate(results) if same(r.row["file"], item.path)
                   and (item.step is None or r.row["step"] == item.step)]
        return min(matches, key=lambda i: results[i].row["step"]) if matches else None
    index = root_decides(comm, decide)
    return None if index is None else results[index]


def _usable(r):
    c, g0 = r.row["c"], r.row["g0"]
    return 0 < c < 1 and g0 is not None and math.isfinite(g0) and g0 > 0


@dataclass
class Fig3Group:
    """A reference step of Fig. 3, the steps normalised by it, and the other steps that are
    the same solve as the reference (drawn once, through ``reference``)."""
    reference: StepResult
    members: list = field(default_factory=list)
    duplicates: list = field(default_factory=list)


def _same_step(a, b):
    return a.row["file"] == b.row["file"] and a.row["step"] == b.row["step"]


def fig3_groups(results, reference, log=None):
    """The :class:`Fig3Group` list of Fig. 3 (see the module docstring).

    With ``reference`` every other step is normalised by it, except steps that are
    the same solve (:func:`solve_identity`), which are duplicates of it.  Without it
    each step that names a reference step of its own file (``plan.reference_step``)
    is normalised by that step, and reference steps that are the same solve --
    several protocol files of one surface and load, each with its own copy of the
    non-adhesive reference -- form one group, drawn once, with the first of them as
    its reference.
    """
    if reference is not None:
        group = Fig3Group(reference)
        for r in results:
            if _same_step(r, reference):
                continue
            if r.meta["solve"] == reference.meta["solve"]:
                group.duplicates.append(r)
            else:
                group.members.append(r)
        groups = [group]
    else:
        by_step = {(r.row["file"], r.row["step"]): r for r in results}
        by_solve = {}
        for r in results:
            ref = by_step.get((r.row["file"], r.meta["reference_step"]))
            if r.meta["reference_step"] is None or ref is None or not _usable(ref):
                continue
            group = by_solve.setdefault(ref.meta["solve"], Fig3Group(ref))
            if not _same_step(ref, group.reference) and \
                    not any(_same_step(ref, d) for d in group.duplicates):
                group.duplicates.append(ref)
            group.members.append(r)
        groups = list(by_solve.values())
    for group in groups:
        ref = group.reference
        for d in group.duplicates:
            if d.row["contact_pixels"] != ref.row["contact_pixels"] and log is not None:
                log.warning("%s:%s is the same solve as the Fig. 3 reference %s:%s (same scene "
                            "and load) but has %s contact pixels against %s; drawing the "
                            "reference only", d.row["file"], d.row["step"], ref.row["file"],
                            ref.row["step"], d.row["contact_pixels"], ref.row["contact_pixels"])
    return groups


def output_stems(paths):
    """File-name stems of the per-input outputs: the input's stem, made unique in order."""
    stems, used = {}, set()
    for path in paths:
        key = str(path)
        if key in stems:
            continue
        stem, n = Path(path).stem, 1
        while (stem if n == 1 else f"{stem}-{n}") in used:
            n += 1
        stems[key] = stem if n == 1 else f"{stem}-{n}"
        used.add(stems[key])
    return stems


def _run(args, inputs, comm, log):
    root_decides(comm, lambda: check_outputs(args))
    surfaces, provenance = {}, {}
    results = analyse_inputs(inputs, args, comm, log, surfaces, provenance)
    if not results and not any(surfaces.values()):
        raise PostError("no complete step to analyse in " + ", ".join(i.text for i in inputs))
    reference = None
    if args.reference is not None:
        reference = _find_reference(results, args.reference, comm)
        if reference is None:
            reference = analyse_inputs([args.reference], args, comm, log)[0]
        if reference.adhesive:
            log.warning("--reference %s is adhesive; Fig. 3 normalises by its c and g0 anyway",
                        args.reference.text)
        if not _usable(reference):
            raise PostError(f"--reference {args.reference.text}: contact fraction "
                            f"{reference.row['c']:g} gives no g0 to normalise by")
    groups = fig3_groups(results, reference, log)
    if not groups and results:
        log.info("no Fig. 3: no --reference, and no adhesive step names a reference step")
    fig2, fig3 = fig2_series(results), fig3_series(groups)
    stems = output_stems([i.path for i in inputs])
    sweeps = {}
    for path in stems:
        steps = [r.row for r in results if r.row["file"] == path]
        if steps:
            view = surfaces.get(path)
            sweeps[path] = overview.sweep_fits(
                steps, None if view is None else view.statistics.rms_height)

    def write():
        d, fmt = args.output_dir, args.format
        figures = []

        def add(name, title, kind, file=None, step=None):
            figures.append({"file": name, "title": title, "kind": kind, "input": file,
                            "step": step})
        paths = []
        if results:
            write_tables(results, args, groups, fig2, fig3, sweeps)
            paths += [d / f"{TABLE_STEM}.csv", d / f"{TABLE_STEM}.json"]
            figure2(fig2, results, d / f"{FIG2_STEM}.{fmt}")
            add(f"{FIG2_STEM}.{fmt}", "Gap distributions collapsed onto Eq. 13 (Fig. 2)", "fig2")
            if groups:
                figure3(fig3, d / f"{FIG3_STEM}.{fmt}")
                add(f"{FIG3_STEM}.{fmt}", "Adhesive gap distributions (Fig. 3)", "fig3")
        figure4(d / f"{FIG4_STEM}.{fmt}",
                [(f"{Path(r.row['file']).name}:{r.row['step']}", r.meta["force_by_gap"])
                 for r in results if r.meta.get("force_by_gap")])
        add(f"{FIG4_STEM}.{fmt}", "Integrand of Eq. 16 (Fig. 4)", "fig4")
        for path, stem in stems.items():
            view = surfaces.get(path)
            if view is not None:
                name = f"{stem}-psd.{fmt}"
                overview.draw_psd(view, d / name, f"{path}: topography")
                add(name, f"{path}: power spectrum of the topography", "psd", path)
            steps = [r for r in results if r.row["file"] == path]
            if view is not None and not steps:
                name = f"{stem}-topography.{fmt}"
                overview.draw_maps(overview.StepMaps({"topography": view.topography}, math.nan,
                                                     f"{path}: topography",
                                                     (view.length_unit, "1")), d / name)
                add(name, f"{path}: topography", "maps", path)
            for r in steps:
                base = f"{stem}-step{r.row['step']:04d}-maps"
                overview.draw_maps(r.maps, d / f"{base}.{fmt}")
                r.maps.save(d / f"{base}.npz")
                add(f"{base}.{fmt}", r.maps.title, "maps", path, r.row["step"])
                if r.flow_maps is not None:
                    name = f"{stem}-step{r.row['step']:04d}-flow.{fmt}"
                    flow_post.draw_flow_maps(r.flow_maps, d / name)
                    add(name, r.flow_maps.title, "flow-maps", path, r.row["step"])
            flowing = flow_post.flow_rows([r.row for r in steps])
            if len(flowing) >= 2:
                name = f"{stem}-leakage.{fmt}"
                flow_post.draw_leakage_curve(flowing, d / name,
                                             f"{path}: leakage of {len(flowing)} steps")
                add(name, f"{path}: transmissivity against load and mean gap, percolation",
                    "leakage", path)
            if len(steps) >= 2:
                name = f"{stem}-sweep.{fmt}"
                overview.draw_sweep([r.row for r in steps], sweeps[path], d / name,
                                    f"{path}: sweep of {len(steps)} steps")
                add(name, f"{path}: contact area, mean gap and adhesion against load",
                    "sweep", path)
            if steps:
                name = f"{stem}-patches.{fmt}"
                overview.draw_patches([(f"step {r.row['step']}", r.patches) for r in steps],
                                      d / name, f"{path}: contact patch areas",
                                      steps[0].row["length_unit"])
                add(name, f"{path}: contact patch-area distributions", "patches", path)
        if results:
            patch_rows = [dict(file=r.row["file"], step=r.row["step"], **row)
                          for r in results for row in r.patches.rows()]
            write_csv(d / PATCH_TABLE, plain_rows(patch_rows, PATCH_COLUMNS), PATCH_COLUMNS)
            paths.append(d / PATCH_TABLE)
        surface_rows = plain_rows([v.row for v in surfaces.values() if v is not None],
                                  SURFACE_COLUMNS)
        if surface_rows:
            write_csv(d / f"{SURFACE_STEM}.csv", surface_rows, SURFACE_COLUMNS)
            write_json(d / f"{SURFACE_STEM}.json", {"petgap_version": __version__,
                                                    "conventions": SURFACE_CONVENTIONS,
                                                    "rows": surface_rows,
                                                    "psd": {v.row["file"]: v.row["psd"]
                                                            for v in surfaces.values()
                                                            if v is not None}})
            paths += [d / f"{SURFACE_STEM}.csv", d / f"{SURFACE_STEM}.json"]
        write_json(d / MANIFEST, {"petgap_version": __version__, "figures": figures})
        paths += [d / f["file"] for f in figures] + [d / MANIFEST]
        report.write_report(d, inputs=[i.path for i in inputs], figures=figures,
                            rows=[r.row for r in results], surfaces=surface_rows,
                            sweeps={k: v.to_dict() for k, v in sweeps.items()},
                            command_line=" ".join(sys.argv), provenance=provenance)
        paths.append(d / report.REPORT)
        return [str(p) for p in paths]

    written = root_decides(comm, write)
    log.info("wrote %s", ", ".join(written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
