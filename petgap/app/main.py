"""The ``petgap`` command: one parser, dispatching to its subcommands.

``petgap run SCENE.toml [--output PATH] [--overwrite] [--quiet] [-- PETSC OPTIONS...]``
    Run one scene (see :mod:`petgap.io.scene`) under ``mpirun -n P``.  The result
    goes to ``PATH`` (default ``./<scene stem>.h5``), never over an existing
    file unless ``--overwrite`` is given.  Everything after ``--`` is handed to
    PETSc's options database, after the scene's ``solver.petsc_options``
    (:mod:`petgap.app.run`).
``petgap check SCENE.toml``
    Make every check ``petgap run`` makes before it solves (the scene, its topography
    file, its PETSc options, its size, memory and decomposition on the ranks it runs
    on), and print the resolved values and the estimated peak memory per rank.
``petgap schema``
    Print the scene schema as a markdown table.
``petgap study SCENE.toml [--output-dir DIR] [--tolerances ...] [--resolutions ...] [--quick]``
    Measure the speed/accuracy trade of a scene (see :mod:`petgap.app.study`).

Each subcommand module registers itself (``add_parser``) and is called as
``func(args, comm, petsc_args)``; none imports this one, so the commands do
not depend on each other.

Errors: an error every rank raises (an invalid scene, an impossible
decomposition, an existing output file, ...) is printed once, by rank 0, as
``petgap: error: <message>``, and every rank exits with status 2.  An exception
raised on some ranks only is printed with its traceback by those ranks, and the
job is aborted (``MPI_Abort``), so that no rank is left waiting forever.
"""
import json
import sys

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from petgap.app import run, study
from petgap.app.argtypes import root_parser
from petgap.app.build import (estimated_seconds, load_scene, make_grid, make_surface,
                              plausibility_findings, preflight, seam_warning, statistics_of,
                              used_rms_slope)
from petgap.app.run import _duration
from petgap.mechanics import plausibility
from petgap.io.scene import describe_schema
from petgap.parallel.collective import root_decides
from petgap.parallel.log import configure, report_failure
from petgap.surfaces.topography import MAX_HEIGHT, read_map
from petgap._version import __version__

#: Exit status of a user error (invalid scene, existing output, ...).
EXIT_USAGE = 2


def _check(args, comm, petsc_args):
    """``petgap check``: every check ``petgap run`` makes before it solves, in its order
    (the scene, :func:`petgap.app.build.preflight`, the topography file), and what the
    scene resolves to; then what the run will need (:func:`_needs`)."""
    scene = load_scene(args.scene, comm)
    steps, need = preflight(scene, comm)
    found = root_decides(comm, lambda: check_topography_file(scene, solved=bool(steps))) \
        if scene.surface.kind == "file" else None
    lines = _needs(scene, comm, steps, need)
    if comm.rank == 0:
        for name, section in scene.to_dict().items():
            print(f"[{name}]")
            for k, v in section.items():
                if v is not None:
                    print(f"{k} = {json.dumps(v, ensure_ascii=False)}")
            print()
        if found:
            print(f"# topography: {found}")
        print("\n".join(f"# {line}" for line in lines))
        print(f"# {args.scene}: valid", flush=True)
    return 0


def _needs(scene, comm, steps, need):
    """What a run of ``scene`` will need and meet, as lines (the same on every rank;
    collective): the surface's ``h0`` and ``h0'`` (spectral and by finite differences, and
    which one the solve and the analysis use), the loads that give ``c = 0.01-0.1``, the
    warnings ``run`` gives (a seam, the slope, the loads; with ``checks.plausibility =
    "error"`` they are raised), the peak memory and an estimate of the time."""
    grid = make_grid(scene, comm, planner="estimate")
    stats = statistics_of(grid, make_surface(scene, grid))
    del grid
    periodic = scene.surface.periodic
    slope = used_rms_slope(stats, periodic)
    units = scene.units
    length = "" if units.length == "1" else f" {units.length}"
    pressure = "" if units.pressure == "1" else f" {units.pressure}"
    lines = [f"surface: h0 = {stats.rms_height:.4g}{length}; h0' = {stats.rms_slope:.4g} "
             f"spectral, {stats.rms_slope_fd_inner:.4g} by finite differences inside the map "
             f"({stats.rms_slope_fd:.4g} across the cell's edges); the solve and the analysis "
             f"use the {'spectral' if periodic else 'finite-difference (inside the map)'} "
             f"h0' = {slope:.4g} ({'periodic' if periodic else 'free boundary'})"]
    if steps:
        lo, hi = plausibility.load_range(slope, scene.material.contact_modulus)
        lines.append(f"loads: P0 = {lo:.3g} to {hi:.3g}{pressure} give a contact fraction c = "
                     f"{plausibility.CONTACT_FRACTIONS[0]:g} to "
                     f"{plausibility.CONTACT_FRACTIONS[1]:g} (c = kappa_rep P0 / (h0' E*), "
                     f"kappa_rep ~ {plausibility.KAPPA_REP:g}: the paper's Eq. 3)")
    warnings = plausibility_findings(scene, slope)
    seam = seam_warning(stats, scene.surface.path) if scene.surface.kind == "file" and \
        periodic else ""
    if seam:
        warnings.insert(0, seam)
    if scene.surface.kind == "file" and not periodic:
        warnings.append("free boundary: contact gathers at the map's edges, where nothing "
                        "outside holds the surface up (README, \"Your own measured map\")")
    if scene.checks.plausibility == "error":
        plausibility.report(warnings[1 if seam else 0:], "error", scene.path or "scene")
    lines += [f"warning: {w}" for w in warnings]
    seconds = estimated_seconds(scene, comm.size)
    lines.append(f"memory: about {_in_units(need)} per rank at its peak on {comm.size} "
                 f"rank{'s' if comm.size > 1 else ''} ({len(steps)} step"
                 f"{'' if len(steps) == 1 else 's'} planned)")
    if steps:
        about = lambda t: ("about " if t >= 1 else "") + _duration(t)  # noqa: E731
        lines.append(f"time: {about(seconds)} per step, {about(seconds * len(steps))} "
                     f"for the {len(steps)} on {comm.size} rank{'s' if comm.size > 1 else ''} "
                     f"(an order of magnitude, from docs/benchmarks.md's model of a 2-core "
                     f"workstation; planning FFTW's transforms comes on top)")
    return lines


def _in_units(nbytes):
    """``512 KiB``, ``3.1 MiB``, ``2.5 GiB``."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 2**10:.3g} KiB"


def check_topography_file(scene, solved=True):
    """Everything ``petgap run`` would refuse about a scene's topography file, checked on
    the calling rank by reading it whole (format, channel, shape, data type, undefined and
    out-of-range heights, units, and a flat map if it is ``solved``); a line describing
    it, or ValueError/FileNotFoundError."""
    s, g = scene.surface, scene.grid
    unit = None if scene.units.length == "1" else scene.units.length
    m = read_map(s.path, s.dataset, channel=s.channel, unit=unit, detrend=s.detrend,
                 undefined=s.undefined)
    if m.heights.shape != tuple(g.shape):
        raise ValueError(f"topography {s.path} has shape {m.heights.shape}, but the grid is "
                         f"{tuple(g.shape)} (grid.nx, grid.ny)")
    largest = float(np.max(np.abs(m.heights))) if m.heights.size else 0.0
    if largest > MAX_HEIGHT:
        raise ValueError(f"topography {s.path} holds heights up to {largest:.3g} in magnitude; "
                         f"at most {MAX_HEIGHT:g} is allowed")
    if solved and m.heights.size and np.ptp(m.heights) == 0:
        raise ValueError(f"topography {s.path} is flat (every height is {m.heights.flat[0]:g}): "
                         f"contact of a flat surface has no rough-contact solution")
    size = "" if m.physical_size is None else \
        f", {m.physical_size[0]:g} x {m.physical_size[1]:g} {m.unit or ''} in the file " \
        f"(the scene: {g.size[0]:g} x {g.size[1]:g})"
    return (f"{s.path}: {m.reader}, channel {m.channel}, {m.heights.shape[0]} x "
            f"{m.heights.shape[1]}{size}, heights in {m.unit or 'the scene units'}"
            + (f", {m.undefined} undefined points filled" if m.undefined else ""))


def _schema(args, comm, petsc_args):
    if comm.rank == 0:
        print(describe_schema(), end="", flush=True)
    return 0


def build_parser(rank=0):
    """The argument parser (only ``rank`` 0 prints)."""
    parser = root_parser(rank, prog="petgap",
                         description="Contact, gaps and adhesion of rough elastic surfaces "
                                     "(PETSc/TAO, FFTW-MPI). Run under mpirun -n P.")
    parser.add_argument("--version", action="version", version=f"petgap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run.add_parser(sub)
    check = sub.add_parser("check", help="validate a scene and print its resolved values")
    check.add_argument("scene", metavar="SCENE.toml", help="scene file")
    check.set_defaults(func=_check, quiet=False)
    schema = sub.add_parser("schema", help="print the scene schema as a markdown table")
    schema.set_defaults(func=_schema, quiet=False)
    study.add_parser(sub)
    return parser


def _keep_petsc_options(petsc_args):
    """Keep the command line's PETSc options in force until PETSc finalises at exit.

    Each solve also applies them (:mod:`petgap.app.run`), but some are read only
    when PETSc finalises: ``-log_view`` prints its table then, from the events
    logged since :func:`PETSc.Log.begin` (petgap's operator and kernels among them).
    """
    options = PETSc.Options()
    options.insertString(" ".join(petsc_args))
    if options.hasName("log_view"):
        PETSc.Log.begin()


def main(argv=None):
    """Entry point of the ``petgap`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    petsc_args = []
    if "--" in argv:
        cut = argv.index("--")
        argv, petsc_args = argv[:cut], argv[cut + 1:]
    comm = MPI.COMM_WORLD
    parser = build_parser(comm.rank)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # same argv on every rank: every rank exits alike
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    if petsc_args and args.command != "run":
        if comm.rank == 0:
            print("petgap: error: PETSc options after `--` are only for `petgap run`",
                  file=sys.stderr, flush=True)
        return EXIT_USAGE
    configure(comm, quiet=args.quiet)
    if petsc_args:
        _keep_petsc_options(petsc_args)
    failure_comm = comm.Dup()  # reserved for agreeing on failures
    try:
        status = args.func(args, comm, petsc_args)
    except Exception as exc:
        return report_failure(exc, comm, failure_comm)
    failure_comm.Free()
    return status


if __name__ == "__main__":
    sys.exit(main())
