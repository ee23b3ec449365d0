#!/usr/bin/env python3
"""Benchmark: the extreme eigenvalues of pcg-pressure's preconditioned operator on large grids.

Not a test: it prints a markdown table for docs/benchmarks.md.  For each grid
size the benchmark surface (H = 0.8, rms slope 0.1, lambda_min = 32 a0,
lambda_max = L / 2, seed 1, P0 = 0.002 E*) is solved by petgap on one process;
on its contact set S, the compliance restricted to S, ``A = P_S K^{-1} P_S``,
is preconditioned by the restricted stiffness less its edge term,
``M = P_S K P_S - theta diag(kappa)`` (petgap/solvers/edge_correction.py), and
by ``M`` less the patch interaction (petgap/solvers/patch_interaction.py), on the
directions of zero mean on S (those of load control).  Where
``benchmarks/edge_spectrum.py`` builds dense matrices (256^2 at most), here
conjugate gradients on ``A x = P h`` (the topography on S) with each
preconditioner run ``--iterations`` steps, and the eigenvalues of their Lanczos
matrix, built from the step lengths and the ``beta``s, estimate the extreme
eigenvalues of the preconditioned operator from inside (they converge to them
from the middle of the spectrum as the iterations grow).  "rate" is the
geometric mean of the fall of the preconditioned residual norm per iteration.

Usage::

    python benchmarks/patch_spectrum.py --sizes 1024 2048 4096 [--iterations 25]
"""
import argparse

import numpy as np
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Load
from petgap.parallel.grid import Grid
from petgap.solvers.edge_correction import EDGE_CORRECTION, EdgeCorrection
from petgap.solvers.patch_interaction import patch_interaction
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import SolverSettings
from petgap.surfaces.self_affine import self_affine


def lanczos_extremes(n, iterations, interaction):
    grid = Grid((n, n), comm=MPI.COMM_SELF)
    h = self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    half_space = ElasticHalfSpace(grid, 1.0)
    problem = ContactProblem(grid, h, half_space)
    solution = polonsky_keer(problem, Load(0.002), SolverSettings(tolerance=1e-8))
    mask = (solution.pressure > 0).astype(np.uint8)
    idx = np.flatnonzero(mask).astype(np.int32)
    del solution
    edge = EdgeCorrection(half_space, mask, EDGE_CORRECTION)
    edge.update()
    far = patch_interaction(half_space, EDGE_CORRECTION) if interaction else None

    def zero_mean(v):
        return v - v.mean()

    def compliance(v):
        field = np.zeros(grid.local_shape)
        field.ravel()[idx] = zero_mean(v)
        return zero_mean(half_space.displacement(field).ravel()[idx])

    def precondition(g):
        field = np.zeros(grid.local_shape)
        field.ravel()[idx] = g
        z = half_space.pressure(field).ravel()[idx]
        edge.subtract(z, g, idx)
        if far is not None:
            w, d = far.sums(g, edge.kappa, idx)
            far.subtract(z, edge.kappa, idx, far.solve(w, d))
        return zero_mean(z)

    r = zero_mean(-h.ravel()[idx].astype(float))
    z = precondition(r)
    p = z.copy()
    rz = first = float(r @ z)
    alphas, betas = [], []
    for _ in range(iterations):
        ap = compliance(p)
        alpha = rz / float(p @ ap)
        r -= alpha * ap
        z = precondition(r)
        rz, rz_old = float(r @ z), rz
        beta = rz / rz_old
        p = z + beta * p
        alphas.append(alpha)
        betas.append(beta)
    t = np.zeros((iterations, iterations))
    for k in range(iterations):
        t[k, k] = 1 / alphas[k] + (betas[k - 1] / alphas[k - 1] if k else 0.0)
        if k + 1 < iterations:
            t[k, k + 1] = t[k + 1, k] = np.sqrt(betas[k]) / alphas[k]
    values = np.linalg.eigvalsh(t)
    rate = (rz / first) ** (0.5 / iterations)
    return len(idx), values[0], values[-1], rate


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096])
    parser.add_argument("--iterations", type=int, default=25)
    args = parser.parse_args()
    print("| N | points in S | preconditioner | smallest | largest | condition number | rate |")
    print("|---|---|---|---|---|---|---|")
    for n in args.sizes:
        for interaction in (False, True):
            m, low, high, rate = lanczos_extremes(n, args.iterations, interaction)
            name = "M less patch interaction" if interaction else "M"
            print(f"| {n}^2 | {m} | {name} | {low:.3f} | {high:.3f} | {high / low:.2f} | "
                  f"{rate:.2f} |", flush=True)


if __name__ == "__main__":
    main()
