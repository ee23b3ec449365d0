#!/usr/bin/env python3
"""Benchmark: the spectrum of pcg-pressure's preconditioned operator on a contact set.

Not a test: it prints a markdown table for docs/benchmarks.md.  For each grid
size the benchmark surface (H = 0.8, rms slope 0.1, lambda_min = 32 a0,
lambda_max = L / 2, seed 1, P0 = 0.002 E*) is solved by petgap on one process;
on its contact set S the compliance restricted to S, ``A = P_S K^{-1} P_S``,
and the preconditioners ``M_theta = P_S K P_S - theta diag(kappa)``,
``kappa = K 1_S`` (petgap/solvers/edge_correction.py), are built as dense
matrices from the operators' kernels and restricted to the directions of zero
mean on S (those of load control).  The eigenvalues of ``M_theta A`` are what
the conjugate gradients see: the table gives the smallest, the largest and
their ratio, the condition number.  With ``theta = 0`` the smallest is 1 (on
modes away from the edges ``K`` inverts ``K^{-1}``) and the largest sit on
edge pixels.  Dense, so for small grids only (256^2: a few thousand points in
S, half a minute per theta).

Usage::

    python benchmarks/edge_spectrum.py --sizes 64 128 256 --thetas 0 0.3 0.6 0.75
"""
import argparse

import numpy as np
from mpi4py import MPI
from scipy import linalg

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Load
from petgap.parallel.grid import Grid
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine


def kernels(grid):
    """``K^{-1} delta`` and ``K delta`` on the whole grid (one process)."""
    half_space = ElasticHalfSpace(grid, 1.0)
    delta = np.zeros(grid.local_shape)
    delta[0, 0] = 1.0
    return half_space.displacement(delta), half_space.pressure(delta)


def spectrum(n, thetas):
    grid = Grid((n, n), comm=MPI.COMM_SELF, planner="estimate", wisdom=False)
    h = self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    problem = ContactProblem(grid, h, ElasticHalfSpace(grid, 1.0))
    solution = polonsky_keer(problem, Load(0.002),
                             SolverSettings(tolerance=1e-10, edge_correction=0.0))
    rows, cols = np.nonzero(solution.pressure > 0)
    m = len(rows)
    dx, dy = (rows[:, None] - rows[None, :]) % n, (cols[:, None] - cols[None, :]) % n
    compliance, stiffness = kernels(grid)
    a, k = compliance[dx, dy], stiffness[dx, dy]
    kappa = k.sum(axis=1)   # K 1_S on S
    basis = linalg.qr(np.eye(m) - 1.0 / m, mode="economic")[0][:, :m - 1]  # zero mean on S
    a = basis.T @ a @ basis
    rows_out = []
    for theta in thetas:
        preconditioner = basis.T @ (k - theta * np.diag(kappa)) @ basis
        try:
            factor = linalg.cholesky(preconditioner, lower=True)
        except linalg.LinAlgError:
            rows_out.append((n, m, theta, None))
            continue
        values = linalg.eigvalsh(factor.T @ a @ factor)
        rows_out.append((n, m, theta, (values[0], values[-1])))
    return rows_out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--thetas", type=float, nargs="+", default=[0.0, 0.3, 0.6, 0.75])
    args = parser.parse_args()
    print("| N | points in S | theta | smallest | largest | condition number |")
    print("|---|---|---|---|---|---|")
    for n in args.sizes:
        for n_, m, theta, result in spectrum(n, args.thetas):
            if result is None:
                print(f"| {n_}^2 | {m} | {theta:g} | not positive definite | | |", flush=True)
            else:
                low, high = result
                print(f"| {n_}^2 | {m} | {theta:g} | {low:.3f} | {high:.3f} | {high / low:.2f} |",
                      flush=True)


if __name__ == "__main__":
    main()
