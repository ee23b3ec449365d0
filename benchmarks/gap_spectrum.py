#!/usr/bin/env python3
"""Benchmark: the spectrum of pcg-gap's preconditioned operator at adhesive states.

Not a test: it prints a markdown table for docs/benchmarks.md.  Why: a sticky
mean-gap solve takes more iterations than a weakly adhesive one even once its
contact set has settled, and the nonlinear solve mixes the search for the set
with the linear convergence on it.  This isolates the second.

For each size and ``w`` the GUIDE surface of ``benchmarks/adhesive_scaling.py``
(H = 0.8, lambda_min = 32 a0, lambda_max = L / 2, rms slope 0.1, seed 7, E* = 1,
one process) is solved under ``ExponentialAdhesion(w, rho)`` at the non-adhesive
state's mean gap (P0 = 0.002 E*) to KKT 1e-8.  At that state, with ``F`` its free
set and ``D = v''(g)``, the gap solver's Hessian on the directions of zero mean
over ``F``,

    A = Pi (K + D) Pi,

is preconditioned as :func:`petgap.solvers.gap_cg._precondition` does: ``K^{-1}``
restricted to ``F``, less the coarse term of :mod:`petgap.solvers.gap_two_level`
with the state's springs (the contact's ``R (1_C K 1_C)`` plus ``R D`` scaled by
the softening ``theta`` the term chooses from its system's smallest eigenvalue,
:func:`petgap.solvers.gap_two_level.softening_for`), on coarse cells of ``--blocks``
pixels.  Conjugate gradients on ``A x = b`` (``b`` random on
``F``) run until the preconditioned residual norm has fallen by 1e-8
("iterations"); the eigenvalues of their Lanczos matrix estimate the extreme
eigenvalues of the preconditioned operator from inside.  For the smallest and the
largest, the Ritz vector is formed and two shares of its squared norm are given:
on waves longer than eight coarse cells ("long"), and on the points within the
law's range of the wall, ``g < rho`` ("band").  "clipped": coarse systems that
were indefinite all the same and were solved with less softening, as the solver
does (:meth:`petgap.solvers.gap_two_level.CoarseTerm.correction`).  ``--margin -inf``
(or any value) sets :data:`petgap.solvers.gap_two_level.MARGIN` for the run.

Usage::

    python benchmarks/gap_spectrum.py --sizes 1024 2048 --work 0.05 0.15 0.3 0.5 \\
        [--blocks 8] [--range 4] [--iterations 60] [--margin 0.1]
"""
import argparse

import numpy as np
from mpi4py import MPI

import petgap
from petgap.solvers import gap_two_level
from petgap.solvers.gap_two_level import CoarseTerm


def hat_restriction(field, block):
    """``R field``: the hat-weighted block means of the coarse term (periodic, ``P^T / b^2``)."""
    n0, n1 = field.shape
    c0, c1 = n0 // block, n1 // block
    w = np.arange(block) / block
    rows = field.reshape(n0, c1, block)
    cols = (rows * (1 - w)).sum(2) + np.roll((rows * w).sum(2), 1, axis=1)
    cells = cols.reshape(c0, block, c1)
    lo = (cells * (1 - w)[None, :, None]).sum(1)
    hi = (cells * w[None, :, None]).sum(1)
    return (lo + np.roll(hi, 1, axis=0)) / block ** 2


def hat_prolongation(coarse, block):
    """``P coarse``: the coarse term's bilinear interpolation onto the fine grid (periodic)."""
    (c0, c1), w = coarse.shape, np.arange(block) / block
    rows = (coarse[:, None, :] * (1 - w)[None, :, None]
            + np.roll(coarse, -1, axis=0)[:, None, :] * w[None, :, None]).reshape(c0 * block, c1)
    return (rows[:, :, None] * (1 - w) + np.roll(rows, -1, axis=1)[:, :, None] * w).reshape(
        c0 * block, c1 * block)


def state(n, work, rho):
    """The converged adhesive mean-gap state on the GUIDE surface: ``(problem, gap,
    the solve's iterations)``."""
    grid = petgap.Grid((n, n), comm=MPI.COMM_SELF, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    reference = petgap.solve(problem, petgap.Load(0.002))
    adhesive = problem.with_interaction(petgap.ExponentialAdhesion(work, rho))
    solution = petgap.solve(adhesive, petgap.MeanGap(reference.mean_gap))
    if not solution.converged:
        raise RuntimeError(f"{n}^2, w = {work}: the adhesive solve did not converge "
                           f"({solution.reason})")
    return adhesive, solution.gap.copy(), solution.iterations


def spectrum(problem, gap, block, rho, iterations):
    """Lanczos estimates of the preconditioned operator's extremes at ``gap`` (module docstring)."""
    grid, half_space, law = problem.grid, problem.half_space, problem.interaction
    n0, n1 = grid.shape
    buffer = grid.padded
    free = gap > 0
    n_free = float(free.sum())
    curvature = np.where(free, law.curvature(gap), 0.0)

    def stiffness(field):
        buffer[:, :n1] = field
        half_space.apply_in_buffer(inverse=False)
        return buffer[:, :n1].copy()

    def on_free(field):
        field = np.where(free, field, 0.0)
        return np.where(free, field - field.sum() / n_free, 0.0)

    term = CoarseTerm(grid, half_space.contact_modulus, block)
    contact = (~free).astype(float)
    term.contact = hat_restriction(contact * stiffness(contact), block)
    term.form_springs(hat_restriction(curvature, block), estimate=True)

    def precondition(r):
        r = np.where(free, r, 0.0)
        buffer[:, :n1] = r
        half_space.apply_in_buffer(inverse=True)
        term.rhs = hat_restriction(r, block)
        return on_free(buffer[:, :n1] - hat_prolongation(term.correction(), block))

    def operator(t):
        return on_free(stiffness(t) + curvature * t)

    r = on_free(np.random.default_rng(1).standard_normal((n0, n1)))
    z = precondition(r)
    p = z.copy()
    rz = first = float(np.vdot(r, z))
    vectors, alphas, betas = [z / np.sqrt(rz)], [], []
    for k in range(iterations):
        ap = operator(p)
        alpha = rz / float(np.vdot(p, ap))
        r -= alpha * ap
        z = precondition(r)
        rz, rz_old = float(np.vdot(r, z)), rz
        beta = rz / rz_old
        alphas.append(alpha)
        betas.append(beta)
        if np.sqrt(rz / first) < 1e-8:
            break
        vectors.append((-1) ** (k + 1) * z / np.sqrt(rz))
        p = z + beta * p
    m = len(alphas)
    lanczos = np.zeros((m, m))
    for k in range(m):
        lanczos[k, k] = 1 / alphas[k] + (betas[k - 1] / alphas[k - 1] if k else 0.0)
        if k + 1 < m:
            lanczos[k, k + 1] = lanczos[k + 1, k] = np.sqrt(betas[k]) / alphas[k]
    values, ritz = np.linalg.eigh(lanczos)
    # wavelengths above 8 coarse cells: frequencies below 1 / (8 block) cycles per pixel
    long_waves = np.hypot(np.fft.fftfreq(n0)[:, None], np.fft.fftfreq(n1)[None, :]) \
        < 1.0 / (8 * block)
    band = free & (gap < rho)
    shares = []
    for which in (0, -1):
        x = sum(ritz[k, which] * vectors[k] for k in range(min(m, len(vectors))))
        power = np.abs(np.fft.fft2(x)) ** 2
        shares.append((float(power[long_waves].sum() / power.sum()),
                       float((x[band] ** 2).sum() / (x ** 2).sum())))
    converged = np.sqrt(rz / first) < 1e-8
    return dict(iterations=m if converged else f"> {m}", low=values[0], high=values[-1],
                shares=shares, clipped=term.clipped, softening=term.softening,
                band=float(band.mean()),
                contact=float(1 - free.mean()))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--work", type=float, nargs="+", default=[0.05, 0.15, 0.3, 0.5])
    parser.add_argument("--blocks", type=int, nargs="+", default=[gap_two_level.BLOCK])
    parser.add_argument("--margin", type=float, default=gap_two_level.MARGIN)
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--iterations", type=int, default=60)
    args = parser.parse_args()
    gap_two_level.MARGIN = args.margin
    print("| N | w (E* a0) | solve its | contact | band | block | iterations | smallest | "
          "largest | condition number | smallest: long / band | largest: long / band | "
          "theta | clipped |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        for work in args.work:
            problem, gap, its = state(n, work, args.range)
            for block in args.blocks:
                s = spectrum(problem, gap, block, args.range, args.iterations)
                (long_low, band_low), (long_high, band_high) = s["shares"]
                print(f"| {n}^2 | {work} | {its} | {s['contact']:.3f} | {s['band']:.3f} | "
                      f"{block} | {s['iterations']} | {s['low']:.3f} | {s['high']:.2f} | "
                      f"{s['high'] / s['low']:.1f} | {long_low:.2f} / {band_low:.2f} | "
                      f"{long_high:.2f} / {band_high:.2f} | {s['softening']:.2f} | {s['clipped']} |",
                      flush=True)


if __name__ == "__main__":
    main()
