"""The ``petgap`` command.

``petgap run SCENE.toml [--output PATH] [--overwrite] [--quiet] [-- PETSC OPTIONS...]``
    Run one scene (see :mod:`petgap.io.scene`) under ``mpirun -n P``.  The result
    goes to ``PATH`` (default ``./<scene stem>.h5``), never over an existing
    file unless ``--overwrite`` is given.  Everything after ``--`` is handed to
    PETSc's options database, after the scene's ``solver.petsc_options``.
``petgap check SCENE.toml``
    Validate a scene and print its resolved values.
``petgap schema``
    Print the scene schema as a markdown table.
``petgap study SCENE.toml [--output-dir DIR] [--tolerances ...] [--resolutions ...] [--quick]``
    Measure the speed/accuracy trade of a scene (see :mod:`petgap.app.study`).

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

from petgap.app import protocol
from petgap.parallel.log import configure, get_logger, report_failure, timed

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
    """The :class:`~petgap.parallel.grid.Grid` of a scene on ``comm``."""
    from petgap.parallel.grid import Grid
    g = scene.grid
    return Grid((g.nx, g.ny), size=g.size, comm=comm, planner=scene.solver.planner)


def make_surface(scene, grid):
    """This rank's slab of the scene's topography."""
    s = scene.surface
    if s.kind == "self-affine":
        from petgap.surfaces import self_affine as surface
        return surface.self_affine(grid, s.hurst, s.lambda_min, s.lambda_max,
                                   rms_slope=s.rms_slope, rms_height=s.rms_height, seed=s.seed)
    if s.kind == "file":
        from petgap.surfaces import topography
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
    scene : petgap.io.scene.Scene
    output : str or Path, optional
        Result file (default ``./<scene stem>.h5``, or ``./scene.h5``).
    petsc_args : sequence of str
        Extra PETSc options (command-line style), applied after
        ``scene.solver.petsc_options``.

    Returns
    -------
    RunResult
    """
    from petgap.io.results import ResultFile, check_free_space, check_output_path
    from petgap.surfaces.statistics import statistics as surface_statistics
    if comm is None:
        from mpi4py import MPI
        comm = MPI.COMM_WORLD
    log = logger or get_logger("run")
    if output is None:
        output = Path(f"{Path(scene.path).stem if scene.path else 'scene'}.h5")
    output = Path(output)
    petsc_args = list(scene.solver.petsc_args()) + list(petsc_args)

    resume = _resume_decision(scene, output, comm, overwrite)
    if not resume:
        check_output_path(output, comm, overwrite)  # before any expensive work
    log.info("%d rank%s; result file %s%s", comm.size, "" if comm.size == 1 else "s", output,
             " (continuing an interrupted run)" if resume else "")
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
    if not resume:
        check_free_space(output, 8 * grid.npoints * ("topography" in scene.output.fields), comm)
        with ResultFile.create(output, comm, overwrite=overwrite, provenance=provenance) as result:
            attrs = {"statistics": stats} if scene.output.statistics else None
            if "topography" in scene.output.fields:
                result.write_field("topography", grid, topography, attrs=attrs)
            elif attrs:
                result.set_attrs(result.root, {"topography": attrs})
            result.close(complete=not protocol.plan(scene))
    steps = _run_steps(scene, grid, topography, stats, output, petsc_args, log, resume)
    if steps is not None:
        with ResultFile.open_for_append(output, comm) as result:
            result.close(complete=True)
    log.info("wrote %s", output)
    return RunResult(output=output, grid=grid, topography=topography, statistics=stats,
                     steps=steps or [])


def _resume_decision(scene, output, comm, overwrite):
    """True if ``output`` is this scene's own interrupted run, to be continued.

    Decided on rank 0 and broadcast.  A complete file, or one made from another
    scene, is left alone (the usual refusal follows unless ``--overwrite``).
    """
    from petgap.io.results import ResultFile
    decision = None
    if comm.rank == 0 and not overwrite and Path(output).exists():
        try:
            import h5py
            with h5py.File(output, "r") as f:
                same = f.attrs.get("scene") == scene.text
                decision = same and not bool(f.attrs.get("complete", False))
        except (OSError, ImportError):
            decision = False
    decision = comm.bcast(decision, root=0)
    if decision:
        with ResultFile.open_for_resume(output, comm) as result:
            result.close(complete=False)
    return bool(decision)


def _petsc_options_dict(args):
    """``["-a", "1", "-b"]`` -> ``{"a": "1", "b": ""}``."""
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


def _is_number(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


def _run_steps(scene, grid, topography, stats, output, petsc_args, log, resume):
    """Solve the scene's steps in order, writing each as soon as it is done.

    The result file is closed while a step is being solved and reopened to
    write it, so a process killed mid-solve leaves every finished step
    readable; a SIGTERM that arrives while a step is being written is held
    until the write is over.  Steps already complete in the file (a resumed
    run) are read back instead of solved, and warm-start the next ones.
    Returns the list of step summaries, or None if the scene has no steps.
    """
    from petgap.mechanics.problem import ContactProblem, MeanGap
    from petgap.mechanics.half_space import ElasticHalfSpace
    from petgap.io.results import ResultFile, check_free_space
    from petgap.mechanics.interactions import ExponentialAdhesion, check_resolution
    from petgap.solvers.dispatch import annotate_step, solve

    steps = protocol.plan(scene)
    if not steps:
        return None
    comm = grid.comm
    half_space = ElasticHalfSpace(grid, scene.material.contact_modulus)
    problems = {False: ContactProblem(grid, topography, half_space)}
    interaction = scene.interaction
    if interaction.kind == "exponential":
        adhesion = ExponentialAdhesion(interaction.work_of_adhesion, interaction.range)
        report = check_resolution(adhesion, min(grid.dx, grid.dy), scene.material.contact_modulus,
                                  interaction.resolution_check)
        log.info("adhesion: %s", report["message"])
        problems[True] = ContactProblem(grid, topography, half_space, adhesion)
    options = _petsc_options_dict(petsc_args)
    fields = scene.output.fields
    done = {}
    if resume:
        with ResultFile.open(output, comm) as result:
            for index in result.completed_steps():
                done[index] = _read_step(result, index, grid, fields)
            result.close(complete=False)
    previous_in_chain, rates, summaries = {}, {}, []
    for step in steps:
        if step.index in done:
            state = done[step.index]
            rates[step.chain] = annotate_step(state, previous_in_chain.get(step.chain),
                                              rates.get(step.chain))
            previous_in_chain[step.chain] = state
            summaries.append(state.summary)
            log.info("step %d (%s): complete in the file, not recomputed", step.index, step.chain)
            continue
        problem = problems[step.adhesive]
        control = step.control
        if control is None:
            reference = done.get(step.reference_step) or summaries[step.reference_step]
            control = MeanGap(reference.mean_gap if hasattr(reference, "mean_gap")
                              else reference["mean_gap"])
        log.info("step %d (%s): %s = %.6g", step.index, step.chain, control.kind, control.value)
        progress = _progress(log, step.index)
        previous = previous_in_chain.get(step.chain)
        solution = solve(problem, control, solver=scene.solver.tao_type,
                         tolerance=scene.solver.tolerance,
                         max_iterations=scene.solver.max_iterations,
                         initial=previous if hasattr(previous, "gap") and previous.gap is not None
                         else None, options=options, monitor=progress)
        rates[step.chain] = annotate_step(solution, previous, rates.get(step.chain))
        _log_solution(log, step, solution)
        scalars = solution.scalars()
        attrs = {"plan": step.attrs(), "solution": scalars,
                 "interaction": {"kind": "exponential" if step.adhesive else "hard-wall",
                                 "work_of_adhesion": interaction.work_of_adhesion
                                 if step.adhesive else None,
                                 "range": interaction.range if step.adhesive else None},
                 "contact_modulus": scene.material.contact_modulus,
                 "surface": {"rms_height": stats.rms_height, "rms_slope": stats.rms_slope,
                             "rms_curvature": stats.rms_curvature},
                 "pixel_size": [grid.dx, grid.dy]}
        # a full disk is a clean error before the file is touched (see petgap.io.results)
        check_free_space(output, 8 * grid.npoints * len(set(fields) - {"topography"}), comm)
        with _hold_sigterm(), ResultFile.open_for_append(output, comm) as result:
            group = result.begin_step(step.index, attrs=attrs)
            if "gap" in fields:
                result.write_field("gap", grid, solution.gap, group=group)
            if "pressure" in fields:
                result.write_field("pressure", grid, solution.pressure, group=group)
            if "displacement" in fields:
                # u = g - d + h up to the rigid-body constant; stored with zero mean
                u = solution.gap + topography
                u -= grid.mean(u)
                result.write_field("displacement", grid, u, group=group)
            result.end_step(group)
            result.close(complete=False)
        summary = dict(scalars, index=step.index, chain=step.chain)
        solution.summary = summary
        previous_in_chain[step.chain] = solution
        done[step.index] = solution
        summaries.append(summary)
    return summaries


class _SavedState:
    """A completed step read back from the file: enough to warm-start and chain.

    ``zero_gap_fraction`` (what :func:`petgap.solvers.dispatch.annotate_step` compares) is
    the stored attribute, else (a file written before petgap stored it) counted
    from the stored gap, else None: the next step is then not judged for a jump.
    """

    def __init__(self, gap, pressure, attrs, control, zero_gap_fraction=None):
        self.gap, self.pressure, self.control = gap, pressure, control
        self.mean_gap = attrs["solution.mean_gap"]
        self.mean_pressure = attrs["solution.mean_pressure"]
        self.contact_fraction = attrs["solution.contact_fraction"]
        self.zero_gap_fraction = attrs.get("solution.zero_gap_fraction", zero_gap_fraction)
        self.summary = {k[len("solution."):]: v for k, v in attrs.items()
                        if k.startswith("solution.")}


def _read_step(result, index, grid, fields):
    import numpy as np
    from petgap.mechanics.problem import Load, MeanGap
    group = result.step(index)
    attrs = result.attrs(group)
    kind, value = attrs["solution.control"], attrs["solution.control_value"]
    control = Load(value) if kind == "load" else MeanGap(value)
    gap = result.read_field("gap", grid, group=group) if "gap" in group else None
    pressure = result.read_field("pressure", grid, group=group) if "pressure" in group else None
    zero_gap = None
    if "solution.zero_gap_fraction" not in attrs and gap is not None:
        zero_gap = grid.comm.allreduce(int(np.count_nonzero(gap <= 0))) / grid.npoints
    if gap is None or pressure is None:
        gap = pressure = None  # no fields to warm-start from: the next step starts cold
    return _SavedState(gap, pressure, attrs, control, zero_gap)


class _hold_sigterm:
    """Delay SIGTERM until a collective write is over, then act on it."""

    def __enter__(self):
        import signal
        self.pending = False
        self.signal = signal

        def handler(signum, frame):
            self.pending = True
        try:
            self.old = signal.signal(signal.SIGTERM, handler)
        except ValueError:  # not the main thread
            self.old = None
        return self

    def __exit__(self, *exc):
        if self.old is not None:
            self.signal.signal(self.signal.SIGTERM, self.old)
            if self.pending:
                self.signal.raise_signal(self.signal.SIGTERM)
        return False


def _progress(log, index, every=5.0):
    """A solver monitor that logs (rank 0) at most every ``every`` seconds."""
    import time
    last = [time.perf_counter()]
    start = last[0]

    def monitor(iteration, residual):
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            log.info("  step %d: iteration %d, KKT residual %.3e, %.1f s", index, iteration,
                     residual, now - start)
    return monitor


def _log_solution(log, step, solution):
    status = "converged" if solution.converged else f"NOT converged ({solution.reason})"
    log.info("  step %d %s after %d iterations (%d FFT pairs, %.2f s): c = %.5g, mean gap = %.6g, "
             "mean pressure = %.6g, KKT = %.2e/%.2e%s", step.index, status, solution.iterations,
             solution.operator_applications, solution.wall_time, solution.contact_fraction,
             solution.mean_gap, solution.mean_pressure, solution.kkt_pressure, solution.kkt_gap,
             ", jump" if solution.jump else "")
    if solution.start.startswith("coarse"):
        log.info("  step %d started from %s (%.2f s of the above)", step.index,
                 solution.start, solution.start_time)
    if not solution.converged:
        log.warning("step %d did not converge: %s; stored with converged = False",
                    step.index, solution.reason)


def _log_statistics(log, stats):
    log.info("surface statistics:\n"
             "    mean height        <h> = %.6g\n"
             "    rms height          h0 = %.6g\n"
             "    rms slope          h0' = %.6g\n"
             "    rms curvature     h0'' = %.6g",
             stats.mean, stats.rms_height, stats.rms_slope, stats.rms_curvature)


# ------------------------------------------------------------------ commands
def _cmd_run(args, comm, petsc_args):
    from petgap.io.scene import Scene
    scene = Scene.from_file(args.scene, comm)
    output = args.output if args.output is not None else Path(f"{Path(args.scene).stem}.h5")
    run_scene(scene, comm, output, overwrite=args.overwrite, petsc_args=petsc_args)
    return 0


def _cmd_check(args, comm, petsc_args):
    from petgap.io.scene import Scene
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
    from petgap.io.scene import describe_schema
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
    from petgap import __version__
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

    from petgap.app.study import add_parser as add_study_parser
    add_study_parser(sub)
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
