#!/usr/bin/env python3
"""Benchmark: how the adhesive gap solver's iterations grow with the grid, per method.

Not a test: it prints markdown tables (issue 34).  On the GUIDE surface of each
size (H = 0.8, lambda_min = 32 a0, lambda_max = L / 2, rms slope 0.1, seed 7,
E* = 1) the non-adhesive state at P0 = 0.002 E* is solved first (``petgap.solve``),
then ``ExponentialAdhesion(work, range)`` to KKT 1e-8, one rank:

* under ``MeanGap`` at the non-adhesive mean gap, from the solver's own cold start
  (the rigid approach), by each method:

  - ``old``: :func:`petgap.solvers.gap_cg.gap_cg` as ``petgap.solve`` runs it;
  - ``keep+PR``: conjugacy kept across projections, Polak-Ribiere+ (``two_level``
    with the coarse term switched off);
  - ``coarse``: the coarse term alone, every projection restarting;
  - ``two-level``: both (``gap_cg(..., two_level=True)``);
  - ``two-level+nested``: two-level, started from the same solve on the grid
    twice as coarse (block means of the topography, recursively down to
    ``--nested-min``, each level to ``--nested-tolerance``): a prototype of a
    start strategy, written here, not in the solver;

* under ``Load(P0)`` (``--load``): ``old`` (``petgap.solve``: a secant on the mean
  gap around mean-gap solves), ``two-level secant`` (the same secant with
  two-level inner solves), and ``two-level direct`` (``gap_cg`` under load
  control, started from the non-adhesive state);

A row reads iterations (inner ones summed, outer count beside them), FFT pairs,
seconds, the seconds over the non-adhesive solve's, per-solve counts (steps whose
projection acted, restarts on a strong release, capped steps; coarse conjugate-
gradient iterations) and the states' agreement: largest gap and pressure
differences from the ``old`` state (over ``h0`` and ``h0' E*``) and the number of
pixels whose contact state differs.  The seconds depend on the machine's load
(two cores shared here); iterations and pairs do not.

Usage::

    python benchmarks/adhesive_scaling.py --sizes 512 1024 2048 [--work 0.05] [--range 4]
        [--methods old keep+PR coarse two-level two-level+nested] [--load]
"""
import argparse
import contextlib
import functools
import sys
import time

import numpy as np

METHODS = ("old", "keep+PR", "coarse", "two-level", "two-level+nested")
LOAD_METHODS = ("old", "two-level secant", "two-level direct")


@contextlib.contextmanager
def patched(module, **values):
    """Set module constants for the duration of a solve."""
    saved = {k: getattr(module, k) for k in values}
    for k, v in values.items():
        setattr(module, k, v)
    try:
        yield
    finally:
        for k, v in saved.items():
            setattr(module, k, v)


def coarser(problem):
    """The block-mean problem on a grid twice as coarse (one rank), or None."""
    import petgap
    from mpi4py import MPI
    grid = problem.grid
    nx, ny = grid.shape
    if nx % 2 or ny % 2 or grid.comm.size > 1:
        return None
    cgrid = petgap.Grid((nx // 2, ny // 2), size=(grid.Lx, grid.Ly), comm=MPI.COMM_SELF)
    h = problem.topography.reshape(nx // 2, 2, ny // 2, 2).mean(axis=(1, 3))
    return petgap.ContactProblem(cgrid, h, problem.half_space.on_grid(cgrid),
                                 problem.interaction)


def nested(problem, control, tolerance, minimum, coarse_tolerance, levels):
    """Two-level gap solve started from the same solve on the grid twice as coarse."""
    from petgap.solvers.gap_cg import gap_cg
    from petgap.solvers.settings import SolverSettings
    start = None
    if min(problem.grid.shape) // 2 >= minimum:
        coarse = coarser(problem)
        if coarse is not None:
            c = nested(coarse, control, max(tolerance, coarse_tolerance), minimum,
                       coarse_tolerance, levels)
            start = np.repeat(np.repeat(c.gap, 2, axis=0), 2, axis=1)
    s = gap_cg(problem, control, SolverSettings(tolerance=tolerance, max_iterations=5000),
               initial_gap=start, two_level=True)
    levels.append((problem.grid.shape[0], s.iterations, s.operator_applications))
    return s


def mean_gap_solve(method, problem, control, args):
    """One mean-gap solve by ``method``: (solution, coarse-level log)."""
    import petgap
    import petgap.solvers.gap_cg as gc
    import petgap.solvers.gap_two_level as tl
    from petgap.solvers.settings import SolverSettings
    settings = SolverSettings(tolerance=1e-8, max_iterations=5000)
    levels = []
    if method == "old":
        return petgap.solve(problem, control, max_iterations=5000), levels
    if method == "keep+PR":
        with patched(tl, MIN_SIDE=10 ** 9):
            return gc.gap_cg(problem, control, settings, two_level=True), levels
    if method == "coarse":
        with patched(gc, KEEP_FRACTION=0.0, POLAK_RIBIERE=False):
            return gc.gap_cg(problem, control, settings, two_level=True), levels
    if method == "two-level":
        return gc.gap_cg(problem, control, settings, two_level=True), levels
    if method == "two-level+nested":
        s = nested(problem, control, 1e-8, args.nested_min, args.nested_tolerance, levels)
        return s, levels[:-1]
    raise ValueError(f"method {method!r} is not one of {', '.join(METHODS)}")


def load_solve(method, problem, load, reference):
    """One load-control solve by ``method`` (``reference``: the non-adhesive state)."""
    import petgap
    import petgap.solvers.gap_cg as gc
    import petgap.solvers.tao as tao
    from petgap.solvers.settings import SolverSettings
    if method == "old":
        return petgap.solve(problem, load, max_iterations=5000)
    if method == "two-level secant":
        with patched(tao, gap_cg=functools.partial(gc.gap_cg, two_level=True)):
            return petgap.solve(problem, load, max_iterations=5000)
    if method == "two-level direct":
        return gc.gap_cg(problem, load, SolverSettings(tolerance=1e-8, max_iterations=5000),
                         initial_gap=reference.gap, two_level=True)
    raise ValueError(f"load method {method!r} is not one of {', '.join(LOAD_METHODS)}")


def agreement(problem, s, old):
    """Largest gap and pressure differences over h0 and h0' E*, and differing contact pixels."""
    if old is None or s is old:
        return "-"
    dg = float(np.max(np.abs(s.gap - old.gap))) / problem.gap_scale
    dp = float(np.max(np.abs(s.pressure - old.pressure))) / problem.pressure_scale
    differ = int(np.count_nonzero((s.gap <= 0) != (old.gap <= 0)))
    return f"{dg:.1e} / {dp:.1e} / {differ}"


def counts(s):
    c = getattr(s, "step_counts", None)
    if not c:
        return "-"
    return (f"{c['projected']} / {c['released']} / {c['capped']} / "
            f"{c.get('coarse_iterations', '-')}")


def row(n, label, s, seconds, hard_seconds, problem, old, outer=""):
    return (f"| {n}^2 | {label} | {s.iterations}{outer} | {s.operator_applications:g} | "
            f"{seconds:.2f} | {seconds / hard_seconds:.2f} | {counts(s)} | "
            f"{agreement(problem, s, old)} | {s.mean_pressure:.7g} | {s.reason} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--work", type=float, default=0.05)
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--load", action="store_true", help="also load control")
    parser.add_argument("--load-methods", nargs="+", default=list(LOAD_METHODS),
                        choices=LOAD_METHODS)
    parser.add_argument("--nested-min", type=int, default=256)
    parser.add_argument("--nested-tolerance", type=float, default=1e-3)
    args = parser.parse_args()

    from mpi4py import MPI
    import petgap
    comm = MPI.COMM_SELF
    head = ("| N | method | its | FFT pairs | s | s / non-adhesive s | projected / released / "
            "capped / coarse its | vs old: dg/h0 / dp/(h0'E*) / contact px | P0 (E*) | reason |\n"
            "|---|---|---|---|---|---|---|---|---|---|")
    gap_rows, load_rows = [], []
    for n in args.sizes:
        grid = petgap.Grid((n, n), comm=comm)
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
        hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
        started = time.perf_counter()
        reference = petgap.solve(hard, petgap.Load(0.002))
        hard_seconds = time.perf_counter() - started
        gap_rows.append(f"| {n}^2 | non-adhesive (pcg-pressure) | {reference.iterations} | "
                        f"{reference.operator_applications:g} | {hard_seconds:.2f} | 1 | - | - | "
                        f"{reference.mean_pressure:.7g} | {reference.reason} |")
        adhesive = hard.with_interaction(petgap.ExponentialAdhesion(args.work, args.range))
        control = petgap.MeanGap(reference.mean_gap)
        old = None
        for method in args.methods:
            started = time.perf_counter()
            s, levels = mean_gap_solve(method, adhesive, control, args)
            seconds = time.perf_counter() - started
            old = s if method == "old" else old
            label = method + ("" if not levels else " (coarse levels: " + ", ".join(
                f"{m}^2 {its} its {ops:g} pairs" for m, its, ops in levels) + ")")
            gap_rows.append(row(n, label, s, seconds, hard_seconds, adhesive, old))
            print(gap_rows[-1], file=sys.stderr, flush=True)
        if args.load:
            old = None
            for method in args.load_methods:
                started = time.perf_counter()
                s = load_solve(method, adhesive, petgap.Load(0.002), reference)
                seconds = time.perf_counter() - started
                old = s if method == "old" else old
                outer = f" ({len(s.history)} outer)" if "direct" not in method else ""
                load_rows.append(row(n, method, s, seconds, hard_seconds, adhesive, old, outer))
                print(load_rows[-1], file=sys.stderr, flush=True)
    print(f"GUIDE surface, seed 7; w = {args.work:g} E* a0, rho = {args.range:g} a0, KKT 1e-8, "
          f"one rank.\n\nMean gap at the non-adhesive mean gap (P0 = 0.002 E*):\n")
    print(head)
    print("\n".join(gap_rows))
    if load_rows:
        print("\nLoad control, P0 = 0.002 E*:\n")
        print(head)
        print("\n".join(load_rows))


if __name__ == "__main__":
    main()
