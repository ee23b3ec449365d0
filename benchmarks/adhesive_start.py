#!/usr/bin/env python3
"""Benchmark: does the adhesive solve's start decide its iterations?

Not a test: it prints a markdown table for docs/benchmarks.md ("Adhesive contact").
On the benchmark surface (H = 0.8, rms slope 0.1, lambda_min = 32 a0,
lambda_max = L / 2, seed 1) of each size, the paper's protocol: the non-adhesive
solve at P0 = 0.002 E*, then the exponential adhesion (work ``--work``, range
``--range``) at that mean gap with ``pcg-gap``, to KKT 1e-8, started

* cold: the rigid approach, ``g = max(mean gap shift - h, 0)`` (the solver's own
  start without a warm state);
* from the non-adhesive state at the same mean gap (its gap): the state the
  adhesive one differs from by the attraction alone.

A row reads iterations, FFT pairs, seconds, and the residual's history in
decades: the iteration at which the KKT residual first fell below 1e-2, 1e-4,
1e-6 and 1e-8.  Iteration counts do not depend on the machine's load; the
seconds do (the FFT-pair floor, measured before the solves, is printed beside
them).  One rank.

Usage::

    python benchmarks/adhesive_start.py --sizes 512 1024 2048 [--work 0.05] [--range 4]
"""
import argparse
import sys
import time

from floor import fft_floor


def first_below(history, level):
    return next((i + 1 for i, r in enumerate(history) if r < level), None)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--work", type=float, default=0.05)
    parser.add_argument("--range", type=float, default=4.0)
    args = parser.parse_args()

    # the floors first: their mpirun is not started from a process that has MPI running
    floors = {n: fft_floor(n, 1) for n in args.sizes}
    from mpi4py import MPI

    import petgap

    comm = MPI.COMM_SELF
    rows = []
    for n in args.sizes:
        floor = floors[n]
        grid = petgap.Grid((n, n), comm=comm)
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
        hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
        reference = petgap.solve(hard, petgap.Load(0.002))
        adhesive = hard.with_interaction(petgap.ExponentialAdhesion(args.work, args.range))
        control = petgap.MeanGap(reference.mean_gap)
        for label, initial in (("cold (rigid approach)", None),
                               ("the non-adhesive state", reference)):
            history = []
            started = time.perf_counter()
            s = petgap.solve(adhesive, control, initial=initial,
                             monitor=lambda i, r: history.append(r))
            seconds = time.perf_counter() - started
            decades = " / ".join(str(first_below(history, 10.0 ** -k) or "-")
                                 for k in (2, 4, 6, 8))
            rows.append(f"| {n}^2 | {label} | {s.iterations} | {s.operator_applications:g} | "
                        f"{seconds:.2f} | {floor:.4f} | {decades} | "
                        f"{s.contact_fraction:.5f} | {s.mean_pressure:.6g} | {s.reason} |")
    print(f"w = {args.work:g} E* a0, rho = {args.range:g} a0, one rank\n")
    print("| N | start | iterations | FFT pairs | s | FFT floor s | below 1e-2 / 1e-4 / "
          "1e-6 / 1e-8 at | c | P0 (E*) | reason |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
