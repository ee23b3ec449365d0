#!/usr/bin/env python3
"""Benchmark: what one iteration of the gap solver's coarse system costs (issue 34).

Not a test: it prints a markdown table.  For each fine size ``N`` the coarse term of the
gap solver's preconditioner (:class:`petgap.solvers.gap_two_level.CoarseTerm`, cells of
``block_for(N)`` pixels) is made on the ranks of ``COMM_WORLD``, given springs shaped like
a sticky state's (contact springs on a fifth of the coarse nodes, a softening on the rest
strong enough that the softening's scale comes into play) and a random right-hand side,
and its correction is computed ``--repeat`` times.  A row gives:

* the coarse grid and how it is held: split over the ranks, or whole on every rank;
* **pair ms**: one transform pair of the coarse grid by its own FFTW plans (the floor
  of an inner iteration);
* **inner its**: the conjugate-gradient iterations of one correction (to
  ``INNER_TOLERANCE``);
* **inner ms**: the wall time of one of them (the least over the repeats), and that over
  the pair;
* **Lanczos ms**: one step of the smallest eigenvalue's estimate (made at each respring).

``--whole-points P`` sets the largest coarse grid solved whole on every rank
(``gap_two_level.WHOLE_POINTS``) for the run: 0 splits every coarse grid the ranks allow.

Usage::

    mpirun -n R python benchmarks/coarse_system.py --sizes 2048 4096 8192 [--repeat 3]
        [--whole-points P]
"""
import argparse
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[2048, 4096, 8192])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--whole-points", type=int, default=None)
    args = parser.parse_args()

    import numpy as np
    from mpi4py import MPI

    from petgap.parallel.grid import Grid
    from petgap.solvers import gap_two_level
    from petgap.solvers.gap_two_level import LANCZOS_STEPS, CoarseTerm, block_for

    if args.whole_points is not None:
        gap_two_level.WHOLE_POINTS = args.whole_points
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print("| N | ranks | coarse grid | held | pair ms | inner its | inner ms | inner / pair "
              "| Lanczos ms |\n|---|---|---|---|---|---|---|---|---|", flush=True)
    for n in args.sizes:
        grid = Grid((n, n), comm=comm)
        term = CoarseTerm(grid, 1.0, block_for(grid.shape))
        cgrid, rows = term.cgrid, term.cgrid.x_slice
        rng = np.random.default_rng(5)
        shape = term.coarse_shape
        contact = np.where(rng.random(shape) < 0.2, rng.uniform(1.0, 5.0, shape), 0.0)
        free = np.where(contact > 0, 0.0, -20.0 * rng.uniform(0.5, 1.0, shape))
        term.contact = contact[rows]
        started = time.perf_counter()
        term.form_springs(free[rows], estimate=True)
        lanczos = (time.perf_counter() - started) / LANCZOS_STEPS
        term.rhs = rng.standard_normal(shape)[rows]

        def pair():
            cgrid.forward()
            cgrid.backward()
        pair()
        comm.Barrier()
        started = time.perf_counter()
        for _ in range(20):
            pair()
        pair_s = comm.allreduce(time.perf_counter() - started, op=MPI.MAX) / 20
        best, its = np.inf, 0
        for _ in range(args.repeat):
            before = term.inner_iterations
            comm.Barrier()
            started = time.perf_counter()
            term.correction()
            spent = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
            its = term.inner_iterations - before
            best = min(best, spent / its)
        lanczos = comm.allreduce(lanczos, op=MPI.MAX)
        if comm.rank == 0:
            held = "split" if term.split else ("whole" if comm.size > 1 else "one rank")
            print(f"| {n}^2 | {comm.size} | {shape[0]}^2 | {held} | {1e3 * pair_s:.2f} | {its} | "
                  f"{1e3 * best:.2f} | {best / pair_s:.2f} | {1e3 * lanczos:.2f} |", flush=True)
        del term, grid


if __name__ == "__main__":
    main()
