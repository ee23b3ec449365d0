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

Usage::

    python benchmarks/adhesive_scaling.py --sizes 512 1024 2048 4096 [--work 0.05 0.15]
        [--methods plain two-level default] [--range 4]
"""
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--work", type=float, nargs="+", default=[0.05, 0.15])
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--methods", nargs="+", default=list(OPTIONS), choices=list(OPTIONS))
    args = parser.parse_args()

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
