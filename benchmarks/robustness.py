#!/usr/bin/env python3
"""Benchmark: the robustness set of the pressure solver (``pcg-pressure``).

Not a test (it takes minutes): 126 solves that must all converge, run from the
coarse start and from the cold start (uniform pressure, or the overlap of the
undeformed surfaces under mean-gap control), so 252 in all.  The set:

* 512^2 surfaces, ``H = 0.8`` with ``lambda_min = 32 a0`` and ``H = 0.3`` with
  ``lambda_min = 8 a0``, seeds 1-6 each; 1024^2, ``H = 0.8``, ``lambda_min =
  32 a0``, seeds 1-2 (14 surfaces, ``lambda_max = L / 2``, rms slope 0.1);
* on each, 4 loads ``P0 / E*`` = 0.0005-0.05 (geometric; contact fractions from
  about 1 % to beyond 50 %) and 5 mean gaps 2-0.05 ``h0`` (geometric),
  tolerance 1e-8 on the KKT residual.

It prints a markdown table per surface kind (converged solves, fine iterations
in all, the largest count, the worst KKT residual, the largest difference in
contact fraction between the two starts, the solves in which the
preconditioner's contact-edge correction was dropped as not positive on the
gap, those in which its patch interaction was dropped as not positive, and
those in which the patch interaction was withdrawn at least once because the
residual rose after a step with it) and exits with status 1 if any solve did
not converge.
``--restart-fraction 0`` runs Polonsky and Keer's own restart rule (conjugacy
dropped whenever a point enters the contact set) for comparison with petgap's
(:data:`petgap.solvers.pressure_cg.RESTART_FRACTION`, the rule without the
patch interaction);
``--edge-correction 0`` the plain restricted stiffness as the preconditioner
(:data:`petgap.solvers.edge_correction.EDGE_CORRECTION` is petgap's share of
the contact-edge term taken off it); ``--interaction-block 0`` the
preconditioner without the patch interaction
(:data:`petgap.solvers.patch_interaction.BLOCK` is petgap's block side).

Usage (serially or under ``mpirun -n P``)::

    python benchmarks/robustness.py [--restart-fraction F] [--edge-correction THETA]
        [--interaction-block B] [--quick]
"""
import argparse
import logging
import sys
import time

import numpy as np


def surfaces(quick):
    kinds = [("512^2, H 0.8, 32 a0", 512, 0.8, 32.0, range(1, 7)),
             ("512^2, H 0.3, 8 a0", 512, 0.3, 8.0, range(1, 7)),
             ("1024^2, H 0.8, 32 a0", 1024, 0.8, 32.0, range(1, 3))]
    if quick:
        kinds = [(name, n, hurst, lmin, seeds[:1]) for name, n, hurst, lmin, seeds in kinds]
    return kinds


class Notices(logging.Handler):
    """Counts the solver's notices that name a term of its preconditioner and what befell it."""

    def __init__(self, term, event):
        super().__init__(logging.INFO)
        self.term, self.event, self.count = term, event, 0

    def emit(self, record):
        self.count += self.term in record.msg and self.event in record.msg


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--restart-fraction", type=float, default=None,
                        help="override petgap.solvers.pressure_cg.RESTART_FRACTION")
    parser.add_argument("--edge-correction", type=float, default=None,
                        help="override petgap.solvers.edge_correction.EDGE_CORRECTION")
    parser.add_argument("--interaction-block", type=int, default=None,
                        help="override petgap.solvers.patch_interaction.BLOCK (0: without)")
    parser.add_argument("--quick", action="store_true", help="one seed per surface kind")
    args = parser.parse_args()

    import petgap
    from petgap.solvers import pressure_cg
    from petgap.parallel.log import get_logger
    from petgap.solvers.edge_correction import EDGE_CORRECTION
    from petgap.solvers.patch_interaction import BLOCK
    from petgap.solvers.settings import SolverSettings

    theta = EDGE_CORRECTION if args.edge_correction is None else args.edge_correction
    block = BLOCK if args.interaction_block is None else args.interaction_block
    dropped = Notices("contact-edge correction", "going on without it")
    dropped_far = Notices("patch interaction", "going on without it")
    withdrawn = Notices("patch interaction", "withdrawn until")
    solver_log = get_logger("pressure_cg")
    solver_log.addHandler(dropped)
    solver_log.addHandler(dropped_far)
    solver_log.addHandler(withdrawn)
    solver_log.setLevel(logging.INFO)

    if args.restart_fraction is not None:
        pressure_cg.RESTART_FRACTION = args.restart_fraction
    comm = petgap.Grid((32, 32), planner="estimate").comm
    loads = np.geomspace(0.0005, 0.05, 4)
    gaps = np.geomspace(2.0, 0.05, 5)
    rows, failures, started = [], 0, time.perf_counter()
    for name, n, hurst, lmin, seeds in surfaces(args.quick):
        solves = converged = iterations = worst_its = drops = far_drops = withdrawals = 0
        worst_kkt = worst_dc = 0.0
        for seed in seeds:
            grid = petgap.Grid((n, n), planner="estimate")
            h = petgap.self_affine(grid, hurst=hurst, lambda_min=lmin, lambda_max=n / 2,
                                   rms_slope=0.1, seed=seed)
            problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid, 1.0))
            h0 = problem.gap_scale
            controls = ([petgap.Load(p) for p in loads]
                        + [petgap.MeanGap(g * h0) for g in gaps])
            for control in controls:
                fractions = []
                for coarse_start in (True, False):
                    before, far_before, back = dropped.count, dropped_far.count, withdrawn.count
                    s = pressure_cg.polonsky_keer(problem, control, SolverSettings(
                        tolerance=1e-8, coarse_start=coarse_start, edge_correction=theta,
                        interaction_block=block))
                    solves += 1
                    drops += dropped.count > before
                    far_drops += dropped_far.count > far_before
                    withdrawals += withdrawn.count > back
                    converged += bool(s.converged)
                    iterations += s.iterations
                    worst_its = max(worst_its, s.iterations)
                    worst_kkt = max(worst_kkt, s.kkt_gap)
                    fractions.append(s.contact_fraction)
                    if not s.converged and comm.rank == 0:
                        print(f"NOT CONVERGED: {name}, seed {seed}, {control}, coarse start "
                              f"{coarse_start}: {s.reason} after {s.iterations} iterations",
                              file=sys.stderr)
                worst_dc = max(worst_dc, abs(fractions[0] - fractions[1]))
        failures += solves - converged
        rows.append((name, len(seeds), solves, converged, iterations, worst_its, worst_kkt,
                     worst_dc, drops, far_drops, withdrawals))
    if comm.rank == 0:
        rule = pressure_cg.RESTART_FRACTION
        print(f"restart fraction {rule:g} (without the patch interaction), edge correction "
              f"{theta:g}, interaction block {block}, {comm.size} rank(s), "
              f"{time.perf_counter() - started:.0f} s\n")
        print("| surfaces | seeds | solves | converged | fine iterations | most | worst KKT "
              "| largest c difference between starts | edge correction dropped "
              "| patch interaction dropped | patch interaction withdrawn |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} | {r[6]:.1e} | "
                  f"{r[7]:.1e} | {r[8]} | {r[9]} | {r[10]} |")
        total = [sum(r[k] for r in rows) for k in (2, 3, 4, 8, 9, 10)]
        print(f"| all | | {total[0]} | {total[1]} | {total[2]} | | | | {total[3]} | "
              f"{total[4]} | {total[5]} |")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
