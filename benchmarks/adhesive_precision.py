#!/usr/bin/env python3
"""What single or mixed precision could save an adhesive solve, measured in double.

Not a test: it prints the markdown table of docs/accuracy.md ("Adhesion: double only"),
behind the refusal of single and mixed precision for adhesion
(``petgap.io.solver_registry.ADHESIVE_PRECISION``).  A mixed solve is a single-precision
solve to its floor (:data:`petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR`) and a double
solve from its state to the tolerance (:mod:`petgap.solvers.mixed_precision`).  Its best
case is measured here without a single-precision gap solver:

* **double**: the adhesive solve to 1e-8 from the cold start (``petgap.solve``);
* **K rounding**: what 32 bits do to the gap solver's elastic pressure
  ``p_el = K (g + h)`` at the double solution: the single-precision half-space's
  ``p_el`` of the gap and topography rounded to 32 bits, against the double
  half-space's of the same inputs, its largest difference on the free set over
  ``h0' E*`` (the KKT residual's unit).  A single gap solve's residual cannot fall
  below it;
* **floor**: the single solve's tolerance, three times that rounding and at least
  ``SINGLE_TOLERANCE_FLOOR`` (the pressure solver's rule), or ``--floor``;
* **to floor**: the double solve stopped at that floor, the path a single solve
  would take at best (the rounding it adds only slows it); its iterations count at half
  a double iteration below, as if every pass and transform moved half the bytes;
* **refine**: the double solve to 1e-8 from that state's gap rounded to 32 bits, the
  mixed solve's second half.

``mixed bound`` is ``0.5 x to-floor CPU + refine CPU`` over the double solve's CPU: a
mixed solve cannot do better than that (below 1 it may pay, at or above 1 it cannot).
``dg floor`` is the floor state's largest gap difference from the double solution over
``h0``, ``dc floor`` the points whose contact differs.  Surface: the GUIDE surface of
``benchmarks/adhesive_scaling.py`` (H = 0.8, lambda_min = 32 a0, lambda_max = L / 2,
rms slope 0.1, seed 7, E* = 1), ``ExponentialAdhesion(w, rho)`` under ``MeanGap`` at
the non-adhesive mean gap at P0 = 0.002 E* and under ``Load(0.002)``.  CPU seconds
are rank 0's, measured back to back in one process.

Usage::

    python benchmarks/adhesive_precision.py --sizes 1024 2048 4096 [--work 0.05 0.15] [--floor F]
"""
import argparse
import time

import numpy as np
from mpi4py import MPI

import petgap
from petgap.io.solver_registry import SINGLE_TOLERANCE_FLOOR
from petgap.solvers.mixed_precision import single_precision_twin

LOAD = 0.002
TOLERANCE = 1e-8


def timed(comm, problem, control, **keywords):
    """``(solution, CPU seconds of this rank)`` of one ``petgap.solve``."""
    comm.Barrier()
    started = time.process_time()
    solution = petgap.solve(problem, control, tolerance=keywords.pop("tolerance", TOLERANCE),
                            **keywords)
    return solution, time.process_time() - started


def pressure_rounding(problem, gap, comm):
    """Largest ``|K32 (g + h) - K64 (g + h)|`` on the free set over ``h0' E*``, for the
    gap and topography rounded to 32 bits (module docstring, "K rounding")."""
    twin = single_precision_twin(problem)
    g32 = gap.astype(np.float32)
    single = twin.elastic_pressure(g32).astype(np.float64)
    buf = problem.grid.real
    np.add(g32, twin.topography, out=buf, dtype=np.float64)
    problem.half_space.apply_in_buffer()
    local = float(np.abs(single - buf)[gap > 0].max(initial=0.0))
    return comm.allreduce(local, op=MPI.MAX) / problem.pressure_scale


def rows(n, works, rho, comm, floor_tolerance=None):
    """The table's rows of one size."""
    grid = petgap.Grid((n, n), comm=comm, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
    hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    mean_gap = petgap.solve(hard, petgap.Load(LOAD)).mean_gap
    h0 = hard.gap_scale
    for w in works:
        problem = hard.with_interaction(petgap.ExponentialAdhesion(w, rho))
        for control in (petgap.MeanGap(mean_gap), petgap.Load(LOAD)):
            double, cpu_d = timed(comm, problem, control)
            its_d = double.iterations
            reference_gap = double.gap.copy()
            del double
            rounding = pressure_rounding(problem, reference_gap, comm)
            tolerance = floor_tolerance or max(SINGLE_TOLERANCE_FLOOR, 3 * rounding)
            floor, cpu_f = timed(comm, problem, control, tolerance=tolerance)
            dg = comm.allreduce(float(np.abs(floor.gap - reference_gap).max()), op=MPI.MAX)
            dc = comm.allreduce(int(np.count_nonzero((floor.gap <= 0) != (reference_gap <= 0))))
            floor.gap[...] = floor.gap.astype(np.float32)
            refine, cpu_r = timed(comm, problem, control, initial=floor)
            its_f = floor.iterations
            del floor
            bound = (0.5 * cpu_f + cpu_r) / cpu_d
            verdict = "" if refine.converged else f" {refine.reason}"
            yield (f"| {n}^2 | {w:g} | {control.kind} | {its_d} / {cpu_d:.2f} | {rounding:.1e} | "
                   f"{tolerance:.0e} | "
                   f"{its_f} / {cpu_f:.2f} | {refine.iterations} / {cpu_r:.2f} | {bound:.2f} | "
                   f"{dg / h0:.0e} | {dc} |{verdict}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--work", type=float, nargs="+", default=[0.05, 0.15])
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--floor", type=float,
                        help="the single solve's tolerance (default: from the K rounding)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"GUIDE surface, seed 7; rho = {args.range:g} a0; KKT {TOLERANCE:g}; "
              f"{comm.size} rank(s).\n")
        print("| N | w (E* a0) | control | double its / CPU s | K rounding | floor "
              "| to floor its / CPU s | refine its / CPU s | mixed bound | dg floor / h0 "
              "| dc floor |")
        print("|" + "---|" * 11, flush=True)
    for n in args.sizes:
        for row in rows(n, args.work, args.range, comm, args.floor):
            if comm.rank == 0:
                print(row, flush=True)


if __name__ == "__main__":
    main()
