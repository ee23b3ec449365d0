#!/usr/bin/env python3
"""Benchmark: the gap solver's coarse system solved to each relative residual (issue 34).

Not a test: it prints a markdown table (docs/design.md, the two-level preconditioner).  On
the GUIDE surface of each size (H = 0.8, lambda_min = 32 a0, lambda_max = L / 2, rms slope
0.1, seed 7, E* = 1, one rank) the non-adhesive state at P0 = 0.002 E* first, then
``ExponentialAdhesion(w, rho)`` to KKT 1e-8 by ``petgap.solve`` (the coarse-grid start and
the two-level preconditioner), under ``MeanGap`` at the non-adhesive mean gap or, with
``--load``, under ``Load(0.002)``, once for each ``--tolerances`` value of
``petgap.solvers.gap_two_level.INNER_TOLERANCE``.  A cell is the outer iterations / the
coarse system's inner iterations (the coarse-grid start's levels included), its Lanczos
steps in brackets (both runs of the recurrence, the levels included), and the solve's
wall seconds; every solve runs in a process of its own.

Usage::

    python benchmarks/coarse_tolerance.py --sizes 4096 --work 0.3 0.5 \\
        [--tolerances 1e-6 1e-4 1e-3 1e-2] [--load] [--range 4]
"""
import argparse
import json
import subprocess
import sys


def worker(n, work, rho, tolerance, load):
    """One solve in this process; its numbers as one JSON line."""
    import time

    from mpi4py import MPI

    import petgap
    from petgap.solvers import gap_two_level

    gap_two_level.INNER_TOLERANCE = tolerance
    grid = petgap.Grid((n, n), comm=MPI.COMM_SELF)
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
    hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    adhesive = hard.with_interaction(petgap.ExponentialAdhesion(work, rho))
    control = petgap.Load(0.002)
    if not load:
        control = petgap.MeanGap(petgap.solve(hard, control).mean_gap)
    started = time.perf_counter()
    solution = petgap.solve(adhesive, control, tolerance=1e-8)
    print(json.dumps(dict(its=solution.iterations, reason=solution.reason,
                          inner=solution.step_counts["coarse_iterations"],
                          lanczos=solution.step_counts["coarse_lanczos_steps"],
                          seconds=time.perf_counter() - started)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4096])
    parser.add_argument("--work", type=float, nargs="+", default=[0.3, 0.5])
    parser.add_argument("--tolerances", type=float, nargs="+", default=[1e-6, 1e-4, 1e-3, 1e-2])
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--load", action="store_true")
    parser.add_argument("--worker", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        n, work, rho, tolerance, load = args.worker
        worker(int(n), float(work), float(rho), float(tolerance), load == "1")
        return
    control = "load" if args.load else "mean gap"
    print(f"| N, w ({control}) | " + " | ".join(f"{t:g}" for t in args.tolerances) + " |")
    print("|---|" + "---|" * len(args.tolerances))
    for n in args.sizes:
        for work in args.work:
            cells = []
            for tolerance in args.tolerances:
                out = subprocess.run(
                    [sys.executable, __file__, "--worker", str(n), str(work), str(args.range),
                     repr(tolerance), "1" if args.load else "0"],
                    capture_output=True, text=True, check=True).stdout
                r = json.loads(out.strip().splitlines()[-1])
                verdict = "" if r["reason"] == "converged_kkt" else f" ({r['reason']})"
                cells.append(f"{r['its']} / {r['inner']} ({r['lanczos']}), "
                             f"{r['seconds']:.1f} s{verdict}")
            print(f"| {n}^2, {work:g} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
