#!/usr/bin/env python3
"""Benchmark: the adhesive gap solver's iterations against the grid, per start and preconditioner.

Not a test: it prints a markdown table (docs/benchmarks.md, "Adhesive contact at the hard
wall's pace").  On the GUIDE surface of each size (H = 0.8, lambda_min = 32 a0,
lambda_max = L / 2, rms slope 0.1, seed 7, E* = 1) the non-adhesive state at
P0 = 0.002 E* is solved first (``petgap.solve``), then ``ExponentialAdhesion(w, rho)`` for
each ``--work`` to KKT 1e-8, one rank, under ``MeanGap`` at the non-adhesive mean gap and
under ``Load(0.002)``, by each method:

* ``plain``: the compliance preconditioner alone, from the rigid approach (or, under load,
  the hard wall's state) -- ``-petgap_two_level 0 -petgap_coarse_start 0``;
* ``two-level``: the two-level preconditioner from the same start
  (``-petgap_coarse_start 0``);
* ``default``: the two-level preconditioner from the coarse-grid start (``petgap.solve``).

A cell reads iterations / FFT pairs (CPU seconds of the adhesive solve over the
non-adhesive solve's).  CPU seconds, not wall time: the machine this ran on is shared, and
a process's CPU time is less disturbed by the others than its wall time.  The states of
the methods agree to the tolerance's reach (checked here: largest gap difference over h0
printed per row).

With ``--free`` the same surface is also a finite map on a free boundary
(``petgap.FreeHalfSpace``: the gap solver on its padded periodic cell), solved by
``petgap.solve`` beside the periodic cell, on every rank of ``COMM_WORLD`` (``mpirun -n 2``):
a row is one ``w`` and control, its cells iterations / FFT pairs of the free map and of the
periodic cell, the outer steps of the free map (the moves of its cell's mean-gap target,
:mod:`petgap.solvers.free_boundary`; a load is one solve), the CPU seconds of both (summed
over the ranks) and ``1/kappa_att`` of both.  Each adhesive solve starts cold; the free
map's mean gap is its own non-adhesive state's.

Usage::

    python benchmarks/adhesive_scaling.py --sizes 512 1024 2048 4096 [--work 0.05 0.15]
        [--methods plain two-level default] [--range 4]
    mpirun -n 2 python benchmarks/adhesive_scaling.py --free --sizes 512 1024 2048
"""
import re
import argparse
import sys
import time

import numpy as np

OPTIONS = {"plain": {"petgap_two_level": 0, "petgap_coarse_start": 0},
           "two-level": {"petgap_coarse_start": 0},
           "default": {}}


def cpu(function):
    started = time.process_time()
    out = function()
    return out, time.process_time() - started


def _moves(solution):
    """The free map's outer steps as its start says them: moves of its target, or secant solves."""
    found = re.search(r"moved its target (\d+) times|\((\d+) mean-gap solves\)", solution.start)
    return 0 if found is None else int(found.group(1) or found.group(2))


def free_rows(args):
    """The ``--free`` table's rows: each size, ``w`` and control, free map beside periodic."""
    from mpi4py import MPI
    import petgap
    comm = MPI.COMM_WORLD

    def run(problem, control):
        comm.Barrier()
        s, seconds = cpu(lambda: petgap.solve(problem, control))
        return s, comm.allreduce(seconds)
    rows = []
    for n in args.sizes:
        grid = petgap.Grid((n, n), comm=comm, planner="estimate")
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
        for w in args.work:
            cells = {}
            for body, half in (("free", petgap.FreeHalfSpace(grid)),
                               ("periodic", petgap.ElasticHalfSpace(grid))):
                hard = petgap.ContactProblem(grid, h, half)
                reference, _ = run(hard, petgap.Load(0.002))
                adhesive = hard.with_interaction(petgap.ExponentialAdhesion(w, args.range))
                for control in (petgap.MeanGap(reference.mean_gap), petgap.Load(0.002)):
                    cells[body, control.kind] = run(adhesive, control)
            for kind in ("mean-gap", "load"):
                (free, free_cpu), (periodic, periodic_cpu) = cells["free", kind], \
                    cells["periodic", kind]
                verdict = "".join(f" {s.reason}" for s in (free, periodic) if not s.converged)
                rows.append(f"| {n}^2 | {w:g} | {kind} | {free.iterations} / "
                            f"{free.operator_applications:g} | {_moves(free)} | "
                            f"{periodic.iterations} / {periodic.operator_applications:g} | "
                            f"{free_cpu:.1f} | {periodic_cpu:.1f} | {free.inv_kappa_att:.2f} | "
                            f"{periodic.inv_kappa_att:.2f} |{verdict}")
                if comm.rank == 0:
                    print(rows[-1], file=sys.stderr, flush=True)
    if comm.rank == 0:
        print(f"GUIDE surface, seed 7; rho = {args.range:g} a0, KKT 1e-8, {comm.size} rank(s).\n")
        print("| N | w (E* a0) | control | free | moves | periodic | free CPU s | periodic CPU s "
              "| 1/kappa_att free | periodic |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(rows))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--work", type=float, nargs="+", default=[0.05, 0.15])
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--methods", nargs="+", default=list(OPTIONS), choices=list(OPTIONS))
    parser.add_argument("--free", action="store_true",
                        help="the free map beside the periodic cell (module docstring)")
    args = parser.parse_args()
    if args.free:
        return free_rows(args)

    from mpi4py import MPI
    import petgap
    rows = []
    for n in args.sizes:
        grid = petgap.Grid((n, n), comm=MPI.COMM_SELF, planner="estimate")
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
        hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
        reference, hard_cpu = cpu(lambda: petgap.solve(hard, petgap.Load(0.002)))
        for w in args.work:
            adhesive = hard.with_interaction(petgap.ExponentialAdhesion(w, args.range))
            for control in (petgap.MeanGap(reference.mean_gap), petgap.Load(0.002)):
                cells, first = [], None
                for method in args.methods:
                    s, seconds = cpu(lambda: petgap.solve(adhesive, control,
                                                          options=OPTIONS[method]))
                    first = s if first is None else first
                    dg = float(np.max(np.abs(s.gap - first.gap))) / adhesive.gap_scale
                    cells.append(f"{s.iterations} / {s.operator_applications:g} "
                                 f"({seconds / hard_cpu:.1f})"
                                 + ("" if s.converged else f" {s.reason}")
                                 + ("" if s is first else f" [dg {dg:.0e}]"))
                rows.append(f"| {n}^2 | {w:g} | {control.kind} | "
                            f"{reference.iterations} / {reference.operator_applications:g} | "
                            + " | ".join(cells) + f" | {s.inv_kappa_att:.2f} |")
                print(rows[-1], file=sys.stderr, flush=True)
    print(f"GUIDE surface, seed 7; rho = {args.range:g} a0, KKT 1e-8, one rank.\n")
    print("| N | w (E* a0) | control | non-adhesive | " + " | ".join(args.methods)
          + " | 1/kappa_att |")
    print("|---|---|---|---|" + "---|" * len(args.methods) + "---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
