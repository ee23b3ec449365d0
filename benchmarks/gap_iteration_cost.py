#!/usr/bin/env python3
"""Benchmark: what an adhesive gap-solver iteration costs outside the FFTs (issue 34).

Not a test: it prints a markdown table.  On the GUIDE surface of each size (H = 0.8,
lambda_min = 32 a0, lambda_max = L / 2, rms slope 0.1, seed 7, E* = 1, one rank) the
non-adhesive state at P0 = 0.002 E* (``petgap.solve``), then
``ExponentialAdhesion(work, range)`` under ``MeanGap`` at its mean gap, to KKT 1e-8, by
``gap_cg`` with its defaults (two-level, the coarse-grid start):

* **its / pairs**: the non-adhesive and the adhesive solve's iterations and FFT pairs;
* **cpu s, ratio**: their CPU seconds (``time.process_time``, less sensitive to the
  other jobs on a shared machine than the wall clock), the least over ``--repeat``
  alternating rounds, and the adhesive over the non-adhesive ratio (least over rounds);
* **per iteration**: the adhesive solve started from the non-adhesive state (no
  coarse levels: every iteration is on the fine grid), its wall seconds per iteration,
  split by the PETSc log events into the elastic operator's transforms
  (``petgap:operator``, ``petgap:operatorHalf``), the gap solver's passes over the
  slab (``petgap:gapCG``: the kernels, the law's ``v'`` and the coarse term) and the
  rest (reductions, Python); **passes / it** counts the ``petgap:gapCG`` events per
  iteration; **pair ms** is one transform pair of the grid, for scale.

Usage::

    python benchmarks/gap_iteration_cost.py --sizes 512 1024 2048 [--repeat 3]
        [--work 0.05] [--range 4]
"""
import argparse
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--work", type=float, default=0.05)
    parser.add_argument("--range", type=float, default=4.0)
    args = parser.parse_args()

    from mpi4py import MPI
    from petsc4py import PETSc

    import petgap
    from petgap.parallel.log import GAP_CG_EVENT, OPERATOR_EVENT, OPERATOR_HALF_EVENT, event
    from petgap.solvers.gap_cg import gap_cg
    from petgap.solvers.settings import SolverSettings

    PETSc.Log.begin()
    names = (OPERATOR_EVENT, OPERATOR_HALF_EVENT, GAP_CG_EVENT)

    def logged():
        return {k: event(k).getPerfInfo() for k in names}

    def cpu(solve):
        started = time.process_time()
        result = solve()
        return result, time.process_time() - started

    print("| N | non-adhesive its / pairs | adhesive its / pairs | non-adhesive cpu s | "
          "adhesive cpu s | ratio | per iteration ms: all / transforms / passes / rest | "
          "passes / it | pair ms |\n|---|---|---|---|---|---|---|---|---|")
    settings = SolverSettings(tolerance=1e-8)
    for n in args.sizes:
        grid = petgap.Grid((n, n), comm=MPI.COMM_SELF)
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
        hard = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
        adhesive = hard.with_interaction(petgap.ExponentialAdhesion(args.work, args.range))
        reference = petgap.solve(hard, petgap.Load(0.002))
        control = petgap.MeanGap(reference.mean_gap)
        gap_cg(adhesive, control, settings)  # plans and first touches, untimed
        rounds = []
        for _ in range(args.repeat):
            plain, hard_s = cpu(lambda: petgap.solve(hard, petgap.Load(0.002)))
            sticky, adhesive_s = cpu(lambda: gap_cg(adhesive, control, settings))
            rounds.append((hard_s, adhesive_s))
        before, started = logged(), time.perf_counter()
        warm = gap_cg(adhesive, control, settings, initial_gap=reference.gap)
        wall, after = time.perf_counter() - started, logged()
        spent = {k: after[k]["time"] - before[k]["time"] for k in names}
        passes = after[GAP_CG_EVENT]["count"] - before[GAP_CG_EVENT]["count"]
        transforms = spent[OPERATOR_EVENT] + spent[OPERATOR_HALF_EVENT]
        its = max(warm.iterations, 1)
        pair = (transforms / warm.operator_applications if warm.operator_applications else 0.0)
        split = (wall, transforms, spent[GAP_CG_EVENT], wall - transforms - spent[GAP_CG_EVENT])
        print(f"| {n}^2 | {plain.iterations} / {plain.operator_applications:g} | "
              f"{sticky.iterations} / {sticky.operator_applications:g} | "
              f"{min(r[0] for r in rounds):.2f} | {min(r[1] for r in rounds):.2f} | "
              f"{min(r[1] / r[0] for r in rounds):.2f} | "
              + " / ".join(f"{1e3 * x / its:.1f}" for x in split)
              + f" | {passes / its:.1f} | {1e3 * pair:.1f} |", flush=True)


if __name__ == "__main__":
    main()
