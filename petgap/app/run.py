"""``petgap run``: solve a scene's steps and write them to a result file.

The result goes to one HDF5 file (:mod:`petgap.io.results`): the provenance,
the topography, then one group per step, each written as soon as it is solved,
so that an interrupted run keeps every finished step and the same command
continues it (:func:`run_scene`).  The command line is in :mod:`petgap.app.main`.
"""
import hashlib
import json
import os
import shlex
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from petgap.analysis.of_solution import contact_statistics_of
from petgap.app.build import build, load_scene
from petgap.app.flow_step import FLOW_FIELDS, flow_of_step, write_flow
from petgap.io.results import (OutputPathError, ResultExistsError, ResultFile,
                                check_free_space, existing_result, output_path_error)
from petgap.io.lock import ResultLock, lock_path
from petgap.io.scene import schema_default
from petgap.mechanics import plausibility
from petgap.mechanics.problem import Indentation, Load, MeanGap
from petgap.parallel.collective import root_decides
from petgap.solvers import gap_cg
from petgap.solvers.convergence import ResidualTrend
from petgap.surfaces.measured import length_unit
from petgap.parallel.log import configured, get_logger


@dataclass
class RunResult:
    """What :func:`run_scene` produced (the same on every rank, fields local)."""
    output: Path
    grid: object
    topography: object
    statistics: object
    steps: list
    model: object = None
    #: True if the output was this scene's complete result already, left as it was.
    complete_already: bool = False


def describe_surface(scene):
    """One line describing the scene's surface."""
    s, g = scene.surface, scene.grid
    pixel = f"a0 = {g.a0:g}" if g.dx == g.dy == g.a0 else f"{g.dx:g} x {g.dy:g}"
    size = f"{g.nx} x {g.ny} pixels of {pixel} (L = {g.size[0]:g} x {g.size[1]:g})"
    boundary = "periodic" if s.periodic else "free boundary"
    if s.kind == "file":
        where = f"{s.path}" + (f", dataset {s.dataset}" if s.dataset else "")
        return f"topography from {where}, {size}, {boundary}"
    if s.kind != "self-affine":
        return f"{s.kind} indenter of radius {s.radius:g} ({s.radius / g.a0:g} a0), {size}, {boundary}"
    target = f"rms slope {s.rms_slope:g}" if s.rms_slope is not None \
        else f"rms height {s.rms_height:g}"
    return (f"self-affine surface, H = {s.hurst:g}, lambda_min = {s.lambda_min:g} "
            f"({s.lambda_min / g.a0:g} a0), lambda_max = {s.lambda_max:g} "
            f"({s.lambda_max / g.a0:g} a0), {target}, seed {s.seed}, {size}")


def run_scene(scene, comm=None, output=None, *, overwrite=False, petsc_args=(), logger=None,
              strict=False):
    """Run a scene on ``comm`` (default COMM_WORLD) and write its result file.

    Collective.  Refuses an existing ``output`` early, saying why (unless
    ``overwrite``, or unless it is this scene's own interrupted run, which is
    continued, or its complete result, which is left as it is and returned
    with ``complete_already``), and refuses, ``overwrite`` or not, an output
    that is a directory, a device or a file the run reads; builds the scene (:func:`petgap.app.build.build`), creates the result file
    with the provenance and the topography, and solves the planned steps,
    writing each as soon as it is done.  Its progress and each step's verdict go
    to rank 0 through the ``petgap`` logger, set up to show them if nothing else
    does (:func:`petgap.parallel.log.configured`): a script that runs a large
    scene is not left silent for an hour.

    Parameters
    ----------
    scene : petgap.io.scene.Scene
    output : str or Path, optional
        Result file (default ``./<scene stem>.h5``, or ``./scene.h5``).
    petsc_args : sequence of str
        Extra PETSc options (command-line style), applied after
        ``scene.solver.petsc_options``.
    strict : bool
        A PETSc option petgap does not read is an error (a warning otherwise).

    Returns
    -------
    RunResult
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    configured(comm)
    log = logger or get_logger("run")
    if output is None:
        output = f"{Path(scene.path).stem if scene.path else 'scene'}.h5"
    raw_output, output = output, Path(output)

    state = _output_state(scene, raw_output, comm, overwrite)  # before any expensive work
    if state == "complete":
        log.info("%s is complete, made from this scene; nothing to do (pass --overwrite to "
                 "compute it again)", output)
        return RunResult(output=output, grid=None, topography=None, statistics=None, steps=[],
                         complete_already=True)
    with ResultLock(output, comm):
        # decided again under the lock: another job may have written it meanwhile
        state = _output_state(scene, raw_output, comm, overwrite)
        if state == "complete":
            log.info("%s is complete, made from this scene; nothing to do", output)
            return RunResult(output=output, grid=None, topography=None, statistics=None,
                             steps=[], complete_already=True)
        return _run_locked(scene, comm, output, state == "resume", overwrite, petsc_args,
                           log, strict)


def partial_path(output):
    """Where a new result file is made before it is complete enough to be one:
    ``.<name>.partial`` beside it, renamed to ``output`` once the provenance and the
    topography are written, so that a job killed while creating it never leaves an
    unreadable file at ``output``."""
    output = Path(output)
    return output.with_name(f".{output.name}.partial")


def _run_locked(scene, comm, output, resume, overwrite, petsc_args, log, strict):
    """The run proper, under the result file's lock (see :func:`run_scene`)."""
    log.info("%d rank%s; result file %s%s", comm.size, "" if comm.size == 1 else "s", output,
             " (continuing an interrupted run)" if resume else "")
    model = build(scene, comm, petsc_args=petsc_args, log=log, strict=strict)
    grid, topography = model.grid, model.topography
    log.info(describe_surface(scene))
    stats = model.statistics
    _log_statistics(log, stats)

    provenance = {"scene": scene.text, "scene_path": str(Path(scene.path).resolve())
                  if scene.path else "", "scene_resolved": scene.to_json(),
                  "petsc_options": shlex.join(model.petsc_args)}
    if scene.surface.kind == "file" and not resume:  # what a resume checks the file against
        provenance["surface_sha256"] = root_decides(comm, lambda: file_sha256(scene.surface.path))
    if resume:  # every check passed (in build too): now the file is touched
        with ResultFile.open_for_resume(output, comm) as result:
            result.close(complete=False)
    else:
        check_free_space(output, 8 * grid.npoints * ("topography" in scene.output.fields), comm)
        partial = partial_path(output)
        if root_decides(comm, partial.exists):
            log.warning("%s is the unfinished file of a petgap run killed while creating %s; "
                        "starting again", partial, output)
        with ResultFile.create(partial, comm, overwrite=True, provenance=provenance) as result:
            attrs = {"statistics": stats} if scene.output.statistics else None
            result.write_coordinates(grid, _units(scene)["length"])
            if "topography" in scene.output.fields:
                result.write_field("topography", grid, topography, attrs=attrs,
                                   units=_units(scene))
            elif attrs:
                result.set_attrs(result.root, {"topography": attrs})
            result.close(complete=not model.steps)
        root_decides(comm, lambda: os.replace(partial, output))
    steps = _run_steps(model, output, log, resume)
    if steps is not None:
        with ResultFile.open_for_append(output, comm) as result:
            result.close(complete=True)
    log.info("wrote %s", output)
    return RunResult(output=output, grid=grid, topography=topography, statistics=stats,
                     steps=steps or [], model=model)


def _inputs(scene):
    """The files a run of ``scene`` reads, which its output must never replace."""
    inputs = {"scene file": scene.path}
    if scene.surface.kind == "file":
        inputs["topography file (surface.path)"] = scene.surface.path
    return inputs


def _output_state(scene, output, comm, overwrite):
    """What to do with ``output``: ``"new"`` (create it), ``"resume"`` or ``"complete"``.

    Decided on rank 0, raised on every rank.  A path that can never be a result
    (a directory, a device, an input of the run) is refused, ``overwrite`` or
    not, and so are a lock or unfinished-file path that is a directory and a new
    result at a symbolic link (which the new file would replace).  An existing file is, without ``overwrite``: this scene's unfinished
    run (continued), this scene's complete result (nothing to do), or refused
    with the reason -- not a readable result, or the result of another scene,
    named by its first differing key.
    """
    def decide():
        exists = Path(output).exists()
        output_path_error(output, overwrite=overwrite or exists, inputs=_inputs(scene))
        _check_sidecars(output)
        if overwrite or not exists:
            _refuse_link(output)
            return "new"
        attrs = existing_result(output)
        difference = scene_difference(attrs, scene)
        if difference:
            raise ResultExistsError(
                f"refusing to overwrite {output}: it holds the result of a different scene "
                f"({difference}); pass --overwrite to replace it, or choose another --output")
        complete = bool(attrs.get("complete", False))
        stored = attrs.get("surface_sha256")
        if not complete and stored is not None and scene.surface.kind == "file":
            now = file_sha256(scene.surface.path)
            if now != stored:
                raise ResultExistsError(
                    f"refusing to continue {output}: the topography file {scene.surface.path} "
                    f"(surface.path) changed since its finished steps were made (sha256 "
                    f"{stored[:12]}... in the result, {now[:12]}... now); restore the file, "
                    f"or pass --overwrite to start again")
        return "complete" if complete else "resume"
    return root_decides(comm, decide)


def _check_sidecars(output):
    """Refuse, naming it, a lock file or unfinished-result path of ``output`` that is a
    directory or anything else a file cannot replace."""
    for sidecar, role in ((lock_path(output), f"keeps the lock of {output}"),
                          (partial_path(output), f"makes {output} before renaming it")):
        if sidecar.exists() and not sidecar.is_file():
            kind = "a directory" if sidecar.is_dir() else "not a regular file"
            raise OutputPathError(f"{sidecar} is {kind}, where petgap {role}; remove or "
                                  f"rename it, or choose another --output")


def _refuse_link(output):
    """A new result is made beside ``output`` and renamed onto it: a symbolic link there
    would be replaced by the file, its target left as it was.  Refused, naming both."""
    if Path(output).is_symlink():
        target = os.readlink(output)
        gone = "" if Path(output).exists() else ", which does not exist"
        raise OutputPathError(f"output path {output} is a symbolic link to {target}{gone}; a "
                              f"new result would replace the link, not write its target: give "
                              f"the target itself (or another path) as --output")


def file_sha256(path):
    """The SHA-256 of a file's content, hex (read in 1 MiB blocks)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def scene_difference(attrs, scene):
    """How the scene stored in a result file's root ``attrs`` differs from ``scene``, or "".

    Compared on the resolved values (comments and layout of the TOML text do
    not count); the first differing key is named with both values.  A file
    without resolved values is compared on the text.
    """
    where = scene.path or "the scene given"
    stored = attrs.get("scene_resolved")
    if stored is None:
        return "" if attrs.get("scene") == scene.text else \
            f"the scene text in the file is not that of {where}"
    try:
        old = json.loads(stored)
    except ValueError:
        return f"the file's scene_resolved attribute is not JSON, so not that of {where}"
    new = json.loads(scene.to_json())
    for section in list(new) + [s for s in old if s not in new]:
        a, b = old.get(section, {}), new.get(section, {})
        for key in list(b) + [k for k in a if k not in b]:
            if key not in a and b.get(key) == schema_default(section, key):
                continue        # a key newer than the file, at its default: nothing changed
            if a.get(key) != b.get(key):
                return (f"{section}.{key} = {json.dumps(a.get(key))} in the file, "
                        f"{json.dumps(b.get(key))} in {where}")
    return ""


def _units(scene):
    """The scene's units of lengths and pressures, as result files label fields: a length
    unit petgap converts in its one spelling ("um" for micron, um and \u00b5m), any other
    as the scene gives it."""
    try:
        length = length_unit(scene.units.length)
    except ValueError:
        length = scene.units.length
    return {"length": length, "pressure": scene.units.pressure}


def _run_steps(model, output, log, resume):
    """Solve the scene's steps in order, writing each as soon as it is done.

    The sweep itself is :meth:`petgap.app.build.Model.sweep`.  The result file
    is closed while a step is being solved and reopened to write it, so a
    process killed mid-solve leaves every finished step readable; a SIGTERM
    that arrives while a step is being written is held until the write is
    over.  Steps already complete in the file (a resumed run) are read back
    instead of solved, and warm-start the next ones.  Returns the list of step
    summaries, or None if the scene has no steps.
    """
    if not model.steps:
        return None
    scene, grid, comm = model.scene, model.grid, model.grid.comm
    if model.resolution is not None:
        log.info("adhesion: %s", model.resolution["message"])
    fields = scene.output.fields
    done = {}
    if resume:
        with ResultFile.open(output, comm) as result:
            complete = list(result.completed_steps())
            warm = set(model.warm_starts(set(complete)))
            for index in complete:   # the fields only of the steps a later one starts from
                done[index] = _read_step(result, index, grid, fields, index in warm)
            result.close(complete=False)

    def before(index, control):
        step = model.steps[index]
        log.info("step %d (%s, %d of %d): %s = %.6g", step.index, step.chain, step.index + 1,
                 len(model.steps), control.kind, control.value)
        return {"monitor": _progress(log, step.index, len(model.steps),
                                     scene.solver.tolerance, finished=wall_times)}

    wall_times = []

    summaries, patches_told = [], False
    # next() rather than zip: zip's reused result tuple would hold each state's fields
    # through the next step's solve (8 bytes per point a field)
    states = model.sweep(done, before=before)
    for step in model.steps:
        state = next(states)
        if step.index in done:
            summaries.append(state.summary)
            log.info("step %d (%s): complete in the file, not recomputed", step.index, step.chain)
            continue
        _log_solution(log, step, state)
        wall_times.append(state.wall_time)
        flow = flow_of_step(model, step, state, log)
        summary = _write_step(model, output, step, state, flow)
        state.summary = summary
        summaries.append(summary)
        if not patches_told:   # once a run: the first step with small patches speaks for all
            patches_told = bool(_check_patches(model, step, state, log))
        del state, flow   # not held through the next step's solve (the sweep keeps warm starts)
    return summaries


def _check_patches(model, step, state, log):
    """Warn (or refuse, after the step is written) if the step's contact patches are a few
    pixels across (:func:`petgap.mechanics.plausibility.patch_findings`); the findings."""
    grid = model.grid
    stats = contact_statistics_of(model.problem_of(step), state)
    return plausibility.report(
        plausibility.patch_findings(stats.mean_diameter, max(grid.dx, grid.dy)),
        model.scene.checks.plausibility, f"step {step.index}", log, grid.comm)


def _write_step(model, output, step, solution, flow=None):
    """Write one solved step, and its flow if it has one, into the result file
    (collective); returns its summary."""
    scene, grid, comm = model.scene, model.grid, model.grid.comm
    stats, fields = model.statistics, scene.output.fields
    scalars = solution.scalars()
    law = model.law_of(step)
    attrs = {"plan": step.attrs(), "solution": scalars,
             # the law applied to this step, as petgap-post rebuilds it
             "interaction": law.attributes(),
             "contact_modulus": scene.material.contact_modulus,
             # the h0' of the solve's scales and of the analysis (finite differences inside
             # the map on a free boundary; see petgap.mechanics.problem.ContactProblem)
             "rms_slope": model.problem.rms_slope,
             "surface": {"rms_height": stats.rms_height, "rms_slope": stats.rms_slope,
                         "rms_curvature": stats.rms_curvature},
             "pixel_size": [grid.dx, grid.dy]}
    # a full disk is a clean error before the file is touched (see petgap.io.results)
    nfields = len(set(fields) - {"topography"}) + (len(FLOW_FIELDS) if flow else 0)
    check_free_space(output, 8 * grid.npoints * nfields, comm)
    with _hold_sigterm(), ResultFile.open_for_append(output, comm) as result:
        group = result.begin_step(step.index, attrs=attrs)
        units = _units(scene)
        result.write_coordinates(grid, _units(scene)["length"], group=group)
        if "gap" in fields:
            result.write_field("gap", grid, solution.gap, group=group, units=units)
        if "pressure" in fields:
            result.write_field("pressure", grid, solution.pressure, group=group, units=units)
        if "displacement" in fields:
            # u = g - d + h up to the rigid-body constant; stored with zero mean
            u = solution.gap + model.topography
            u -= grid.mean(u)
            result.write_field("displacement", grid, u, group=group, units=units)
        write_flow(result, grid, group, flow, units)
        result.end_step(group)
        result.close(complete=False)
    return dict(scalars, index=step.index, chain=step.chain)


class _SavedState:
    """A completed step read back from the file: enough to warm-start and chain.

    ``zero_gap_fraction`` (what :func:`petgap.solvers.sweeps.annotate_step` compares) is
    the stored attribute, else (a file without it) counted from the stored
    gap, else None: the next step is then not judged for a jump.
    """

    def __init__(self, gap, pressure, attrs, control, zero_gap_fraction=None):
        self.gap, self.pressure, self.control = gap, pressure, control
        self.mean_gap = attrs["solution.mean_gap"]
        self.mean_pressure = attrs["solution.mean_pressure"]
        self.contact_fraction = attrs["solution.contact_fraction"]
        self.zero_gap_fraction = attrs.get("solution.zero_gap_fraction", zero_gap_fraction)
        self.summary = {k[len("solution."):]: v for k, v in attrs.items()
                        if k.startswith("solution.")}


def _read_step(result, index, grid, fields, warm=True):
    """A complete step of a resumed run, as a :class:`_SavedState` (collective); its
    fields only if ``warm`` (the next step of its chain starts from them)."""
    group = result.step(index)
    attrs = result.attrs(group)
    kind, value = attrs["solution.control"], attrs["solution.control_value"]
    control = {"load": Load, "mean-gap": MeanGap, "indentation": Indentation}[kind](value)
    counted = "solution.zero_gap_fraction" not in attrs   # an older file: count it
    gap = (result.read_field("gap", grid, group=group)
           if "gap" in group and (warm or counted) else None)
    zero_gap = None
    if counted and gap is not None:
        zero_gap = grid.comm.allreduce(int(np.count_nonzero(gap <= 0))) / grid.npoints
    pressure = (result.read_field("pressure", grid, group=group)
                if warm and gap is not None and "pressure" in group else None)
    if pressure is None:
        gap = None  # no fields to warm-start from: the next step starts cold
    return _SavedState(gap, pressure, attrs, control, zero_gap)


class _hold_sigterm:
    """Delay SIGTERM until a collective write is over, then act on it."""

    def __enter__(self):
        self.pending = False

        def handler(signum, frame):
            self.pending = True
        try:
            self.old = signal.signal(signal.SIGTERM, handler)
        except ValueError:  # not the main thread
            self.old = None
        return self

    def __exit__(self, *exc):
        if self.old is not None:
            signal.signal(signal.SIGTERM, self.old)
            if self.pending:
                signal.raise_signal(signal.SIGTERM)
        return False


def _progress(log, index, nsteps, tolerance, every=5.0, finished=()):
    """A solver monitor that logs (rank 0) at most every ``every`` seconds: the step of
    the sweep, the iteration, the KKT residual against its target, the time so far and
    estimates of the time left, in the step (from the residual's decay,
    :class:`petgap.solvers.convergence.ResidualTrend`) and in the sweep (the steps after
    this one at the mean time of ``finished``, the wall times of the steps solved before
    it, or at this step's own).

    The iterations count on through the levels of a coarse start (a level's solver
    counts from 0 again), so that a line never shows fewer than the one before; the
    residual's trend starts afresh with each level, whose residuals are another grid's."""
    start = time.perf_counter()
    state = {"last": start, "previous": -1, "offset": 0, "trend": ResidualTrend(tolerance)}

    def monitor(iteration, residual):
        now = time.perf_counter()
        if iteration < state["previous"]:      # the next level of the start, or the fine grid
            state["offset"] += state["previous"] + 1
            state["trend"] = ResidualTrend(tolerance)
        state["previous"] = iteration
        state["trend"].add(now - start, residual)
        if now - state["last"] < every:
            return
        state["last"] = now
        left = state["trend"].remaining()
        log.info("  step %d of %d: iteration %d, KKT residual %.3e (target %.0e), %.1f s%s",
                 index + 1, nsteps, iteration + state["offset"], residual, tolerance,
                 now - start, _time_left(left, now - start, nsteps - index - 1, finished))
    return monitor


def _time_left(left, elapsed, after, finished):
    """The progress line's estimate of the time left: in the step, and in the sweep."""
    if left is None:
        return ""
    text = f", about {_duration(left)} to go"
    if after:
        per_step = sum(finished) / len(finished) if finished else elapsed + left
        text += f" in this step, {_duration(left + after * per_step)} in the sweep " \
                f"({after} more step{'s' if after > 1 else ''})"
    return text


def _duration(seconds):
    """``under 1 s``, ``42 s``, ``3.5 min`` or ``1.2 h``."""
    if seconds < 1:
        return "under 1 s"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def _log_solution(log, step, solution):
    status = "converged" if solution.converged else f"NOT converged ({solution.reason})"
    log.info("  step %d %s after %d iterations (%g FFT pairs, %.2f s): c = %.5g, mean gap = %.6g, "
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
    if solution.reason == "stalled":
        log.warning("step %d: the KKT residual stopped falling at %.2e, above the tolerance "
                    "(%d iterations without a tenth off its best); ask for a tolerance above "
                    "it", step.index, max(solution.kkt_pressure, solution.kkt_gap),
                    gap_cg.STALL_ITERATIONS)
    if solution.reason == "stalled_round_off":
        log.warning("step %d: the KKT residual stopped falling at %.2e, above the tolerance, "
                    "where round-off decides the steps; ask for a tolerance above it, or "
                    "solver.tao_type = \"pcg\" (single precision: precision = \"mixed\")",
                    step.index, max(solution.kkt_pressure, solution.kkt_gap))


def _log_statistics(log, stats):
    log.info("surface statistics:\n"
             "    mean height        <h> = %.6g\n"
             "    rms height          h0 = %.6g\n"
             "    rms slope          h0' = %.6g\n"
             "    rms curvature     h0'' = %.6g%s",
             stats.mean, stats.rms_height, stats.rms_slope, stats.rms_curvature,
             "" if stats.rms_slope_fd is None else
             "\n    by finite differences: rms slope %.6g across the cell's edges, %.6g "
             "inside the map; rms curvature %.6g inside the map"
             % (stats.rms_slope_fd, stats.rms_slope_fd_inner, stats.rms_curvature_fd_inner))


# ----------------------------------------------------------------------- CLI
def add_parser(subparsers):
    """Register ``petgap run`` on the ``petgap`` command's subparsers."""
    run = subparsers.add_parser("run", help="run a scene",
                                description="Run a scene. Options after `--` go to PETSc "
                                            "(e.g. -- -tao_monitor -log_view).")
    run.add_argument("scene", metavar="SCENE.toml", help="scene file")
    run.add_argument("-o", "--output", metavar="PATH",  # a str: a trailing slash is kept
                     help="result file (default: ./<scene stem>.h5)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace an existing result file")
    run.add_argument("-q", "--quiet", action="store_true",
                     help="print only warnings and errors")
    run.add_argument("--strict", action="store_true",
                     help="a PETSc option petgap does not read is an error, not a warning")
    run.set_defaults(func=command)
    return run


def command(args, comm, petsc_args):
    """``petgap run``: run the scene file and write its result (collective); exit status."""
    scene = load_scene(args.scene, comm)
    output = args.output if args.output is not None else f"{Path(args.scene).stem}.h5"
    run_scene(scene, comm, output, overwrite=args.overwrite, petsc_args=petsc_args,
              strict=args.strict)
    return 0
