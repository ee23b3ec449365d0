"""The ``petgap`` command.

``petgap run SCENE.toml [--output PATH] [--overwrite] [--quiet] [-- PETSC OPTIONS...]``
    Run one scene (see :mod:`petgap.scene`) under ``mpirun -n P``.  The result
    goes to ``PATH`` (default ``./<scene stem>.h5``), never over an existing
    file unless ``--overwrite`` is given.  Everything after ``--`` is handed to
    PETSc's options database, after the scene's ``solver.petsc_options``.
``petgap check SCENE.toml``
    Validate a scene and print its resolved values.
``petgap schema``
    Print the scene schema as a markdown table.

Errors: an error every rank raises (an invalid scene, an impossible
decomposition, an existing output file, ...) is printed once, by rank 0, as
``petgap: error: <message>``, and every rank exits with status 2.  An exception
raised on some ranks only is printed with its traceback by those ranks, and the
job is aborted (``MPI_Abort``), so that no rank is left waiting forever.
"""
import argparse
import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

from .log import configure, get_logger, report_failure, timed

#: Exit status of a user error (invalid scene, existing output, ...).
EXIT_USAGE = 2


@dataclass
class RunResult:
    """What :func:`run_scene` produced (the same on every rank, fields local)."""
    output: Path
    grid: object
    topography: object
    statistics: object
    steps: list


def make_grid(scene, comm):
    """The :class:`~petgap.grid.Grid` of a scene on ``comm``."""
    from .grid import Grid
    g = scene.grid
    return Grid((g.nx, g.ny), size=g.size, comm=comm, planner=scene.solver.planner)


def make_surface(scene, grid):
    """This rank's slab of the scene's topography."""
    s = scene.surface
    if s.kind == "self-affine":
        from . import surface
        return surface.self_affine(grid, s.hurst, s.lambda_min, s.lambda_max,
                                   rms_slope=s.rms_slope, rms_height=s.rms_height, seed=s.seed)
    if s.kind == "file":
        from . import topography
        return topography.load_topography(grid, s.path, s.dataset)
    raise ValueError(f"surface.kind = {s.kind!r} is not implemented")  # the schema prevents it


def describe_surface(scene):
    """One line describing the scene's surface."""
    s, g = scene.surface, scene.grid
    size = f"{g.nx} x {g.ny} pixels of a0 = {g.a0:g} (L = {g.size[0]:g} x {g.size[1]:g})"
    if s.kind == "file":
        where = f"{s.path}" + (f", dataset {s.dataset}" if s.dataset else "")
        return f"topography from {where}, {size}"
    target = f"rms slope {s.rms_slope:g}" if s.rms_slope is not None \
        else f"rms height {s.rms_height:g}"
    return (f"self-affine surface, H = {s.hurst:g}, lambda_min = {s.lambda_min:g} "
            f"({s.lambda_min / g.a0:g} a0), lambda_max = {s.lambda_max:g} "
            f"({s.lambda_max / g.a0:g} a0), {target}, seed {s.seed}, {size}")


def run_scene(scene, comm=None, output=None, *, overwrite=False, petsc_args=(), logger=None):
    """Run a scene on ``comm`` (default COMM_WORLD) and write its result file.

    Collective.  Steps: refuse an existing ``output`` early (unless
    ``overwrite``), build the grid, the surface and its statistics, create the
    result file with the provenance, write the topography and, for a control
    other than ``"none"``, the sweep (not implemented yet: a warning says so).

    Parameters
    ----------
    scene : petgap.scene.Scene
    output : str or Path, optional
        Result file (default ``./<scene stem>.h5``, or ``./scene.h5``).
    petsc_args : sequence of str
        Extra PETSc options (command-line style), applied after
        ``scene.solver.petsc_options``.

    Returns
    -------
    RunResult
    """
    from .hdf5 import ResultFile, check_output_path
    from .surface import statistics as surface_statistics
    if comm is None:
        from mpi4py import MPI
        comm = MPI.COMM_WORLD
    log = logger or get_logger("run")
    if output is None:
        output = Path(f"{Path(scene.path).stem if scene.path else 'scene'}.h5")
    output = Path(output)
    petsc_args = list(scene.solver.petsc_args()) + list(petsc_args)

    check_output_path(output, comm, overwrite)  # before any expensive work
    log.info("%d rank%s; result file %s", comm.size, "" if comm.size == 1 else "s", output)
    with timed(log, f"planning FFTs ({scene.solver.planner})"):
        grid = make_grid(scene, comm)
    with timed(log, "making the surface"):
        topography = make_surface(scene, grid)
    log.info(describe_surface(scene))
    stats = surface_statistics(grid, topography)
    _log_statistics(log, stats)

    provenance = {"scene": scene.text, "scene_path": str(Path(scene.path).resolve())
                  if scene.path else "", "scene_resolved": scene.to_json(),
                  "petsc_options": shlex.join(petsc_args)}
    steps = []
    with ResultFile.create(output, comm, overwrite=overwrite, provenance=provenance) as result:
        attrs = {"statistics": stats} if scene.output.statistics else None
        if "topography" in scene.output.fields:
            result.write_field("topography", grid, topography, attrs=attrs)
        elif attrs:
            result.set_attrs(result.root, {"topography": attrs})
        result.flush()
        if scene.control.kind != "none":
            # The lead's sweep goes here: for each value, result.begin_step(i, ...),
            # solve (warm-started), result.write_field(..., group=step), then
            # result.end_step(step, attrs={"statistics": ..., "solver": ...}).
            log.warning("the contact solve (control.kind = %r, %d value%s) is not available yet; "
                        "%s holds the surface only", scene.control.kind,
                        len(scene.control.values), "" if len(scene.control.values) == 1 else "s",
                        output)
    log.info("wrote %s", output)
    return RunResult(output=output, grid=grid, topography=topography, statistics=stats,
                     steps=steps)


def _log_statistics(log, stats):
    log.info("surface statistics:\n"
             "    mean height        <h> = %.6g\n"
             "    rms height          h0 = %.6g\n"
             "    rms slope          h0' = %.6g\n"
             "    rms curvature     h0'' = %.6g",
             stats.mean, stats.rms_height, stats.rms_slope, stats.rms_curvature)


# ------------------------------------------------------------------ commands
def _cmd_run(args, comm, petsc_args):
    from .scene import Scene
    scene = Scene.from_file(args.scene, comm)
    output = args.output if args.output is not None else Path(f"{Path(args.scene).stem}.h5")
    run_scene(scene, comm, output, overwrite=args.overwrite, petsc_args=petsc_args)
    return 0


def _cmd_check(args, comm, petsc_args):
    from .scene import Scene
    scene = Scene.from_file(args.scene, comm)
    if comm.rank == 0:
        for name, section in scene.to_dict().items():
            print(f"[{name}]")
            for k, v in section.items():
                if v is not None:
                    print(f"{k} = {json.dumps(v)}")
            print()
        print(f"# {args.scene}: valid", flush=True)
    return 0


def _cmd_schema(args, comm, petsc_args):
    from .scene import describe_schema
    if comm.rank == 0:
        print(describe_schema(), end="", flush=True)
    return 0


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser that lets only rank 0 print (usage, help, errors)."""

    rank = 0

    def _print_message(self, message, file=None):
        if self.rank == 0:
            super()._print_message(message, file)


def build_parser(rank=0):
    """The argument parser (only ``rank`` 0 prints)."""
    _Parser.rank = rank
    parser = _Parser(prog="petgap", description="Contact, gaps and adhesion of rough elastic "
                     "surfaces (PETSc/TAO, FFTW-MPI). Run under mpirun -n P.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"petgap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="run a scene",
                         description="Run a scene. Options after `--` go to PETSc "
                                     "(e.g. -- -tao_monitor -log_view).")
    run.add_argument("scene", metavar="SCENE.toml", help="scene file")
    run.add_argument("-o", "--output", type=Path, metavar="PATH",
                     help="result file (default: ./<scene stem>.h5)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace an existing result file")
    run.add_argument("-q", "--quiet", action="store_true",
                     help="print only warnings and errors")
    run.set_defaults(func=_cmd_run)

    check = sub.add_parser("check", help="validate a scene and print its resolved values")
    check.add_argument("scene", metavar="SCENE.toml", help="scene file")
    check.set_defaults(func=_cmd_check, quiet=False)

    schema = sub.add_parser("schema", help="print the scene schema as a markdown table")
    schema.set_defaults(func=_cmd_schema, quiet=False)
    return parser


def main(argv=None):
    """Entry point of the ``petgap`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    petsc_args = []
    if "--" in argv:
        cut = argv.index("--")
        argv, petsc_args = argv[:cut], argv[cut + 1:]
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    parser = build_parser(comm.rank)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # same argv on every rank: every rank exits alike
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    if petsc_args and args.command != "run":
        if comm.rank == 0:
            print(f"petgap: error: PETSc options after `--` are only for `petgap run`",
                  file=sys.stderr, flush=True)
        return EXIT_USAGE
    configure(comm, quiet=args.quiet)
    failure_comm = comm.Dup()  # reserved for agreeing on failures
    try:
        status = args.func(args, comm, petsc_args)
    except Exception as exc:
        return report_failure(exc, comm, failure_comm)
    failure_comm.Free()
    return status


if __name__ == "__main__":
    sys.exit(main())
