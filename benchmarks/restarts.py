#!/usr/bin/env python3
"""Benchmark: fine iterations of the pressure solver against its restart rule and coarsening.

Not a test: it prints a markdown table for docs/benchmarks.md ("Restarts").  On the
benchmark surface (H = 0.8, rms slope 0.1, lambda_min = 32 a0, lambda_max = L / 2,
load 0.002 E*, KKT tolerance 1e-8) of each size and seed, ``pcg-pressure`` is solved from
its coarse start, with the preconditioner without the patch interaction
(``interaction_block = 0``) under

* Polonsky and Keer's rule: conjugacy dropped whenever a point enters the contact set
  (``RESTART_FRACTION = 0``);
* the rule petgap keeps for that preconditioner
  (:data:`petgap.solvers.pressure_cg.RESTART_FRACTION`);
* conjugacy never dropped for entering points;

and petgap's solver: the patch interaction in the preconditioner once the set
has settled, Polonsky and Keer's rule in the iterations that apply it and
``RESTART_FRACTION`` in the others; each with the coarse grids 2x coarser per
level (petgap's) and, with ``--factor 4``, 4x.
A cell reads "fine iterations / operator applications of the fine solve (start s)".
Iteration counts do not depend on the machine's load; the seconds do.

Usage::

    python benchmarks/restarts.py --sizes 512 1024 2048 4096 --seeds 1 2 [--factor 2 4]
"""
import argparse
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--factor", type=int, nargs="+", default=[2], choices=[2, 4])
    args = parser.parse_args()

    import petgap
    from petgap.solvers import coarse, pressure_cg
    from petgap.solvers.patch_interaction import BLOCK
    from petgap.solvers.settings import SolverSettings

    petgap_rule = pressure_cg.RESTART_FRACTION
    rules = [("Polonsky-Keer", 0.0, 0), (f"{petgap_rule:g}", petgap_rule, 0),
             ("never", float("inf"), 0), ("petgap (patch interaction)", petgap_rule, BLOCK)]
    comm = None
    lines = []
    for n in args.sizes:
        for seed in args.seeds:
            grid = petgap.Grid((n, n), planner="estimate")
            comm = grid.comm
            h = petgap.self_affine(grid, hurst=0.8, lambda_min=32.0, lambda_max=n / 2,
                                   rms_slope=0.1, seed=seed)
            problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid, 1.0))
            for f in args.factor:
                coarse.FACTOR = f
                cells = []
                for _, fraction, block in rules:
                    pressure_cg.RESTART_FRACTION = fraction
                    started = time.perf_counter()
                    s = pressure_cg.polonsky_keer(problem, petgap.Load(0.002), SolverSettings(
                        tolerance=1e-8, interaction_block=block))
                    wall = time.perf_counter() - started
                    mark = "" if s.converged else f" ({s.reason})"
                    cells.append(f"{s.iterations} / {s.operator_applications} "
                                 f"({s.start_time:.1f} s of {wall:.1f} s){mark}")
                lines.append(f"| {n}^2 | {seed} | {f} | " + " | ".join(cells) + " |")
    if comm.rank == 0:
        print("| N | seed | coarsening | " + " | ".join(name for name, _, _ in rules) + " |")
        print("|---|---|---|" + "---|" * len(rules))
        print("\n".join(lines))


if __name__ == "__main__":
    main()
