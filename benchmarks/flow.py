#!/usr/bin/env python3
"""Benchmark: the Reynolds flow through the gaps, its iterations and cost against N.

Not a test: it prints a markdown table (issue 37).  On the GUIDE surface of each size
(H = 0.8, lambda_min = 32 a0, lambda_max = L / 2, rms slope 0.1, seed 7, E* = 1) the
contact at P0 = 0.002 E* is solved (``petgap.solve``, timed), then the flow through
its gap along x on the periodic cell (``petgap.flow.leakage``, with only the gap and
the grid kept from the contact) with each preconditioner
asked for (``--pcs``: hypre's BoomerAMG, PETSc's GAMG).  A row reads the Krylov
iterations (CG, the relative unpreconditioned residual 1e-10 and the mass balance of
1e-8), the seconds of the flow step (percolation, assembly, solve, fluxes) and of its
KSP solve (set-up included), the peak memory the flow step adds in bytes per point
(the high-water mark of the resident set, reset before the step), the flow factor, and
the contact solve's seconds beside them.

A size whose flow step would not fit is not run: before each size the memory it needs
is projected from the flow step of the largest grid measured so far (bytes per point,
which fall towards a constant as the grid grows, plus the gap and the grid's transform
buffers held beside it, and the contact solve's own peak before it) and compared with the
machine's available memory (``MemAvailable``), so a benchmark never drives a shared
machine into swap or the OOM killer; the row says so.

``--reynoldsflow VENV`` runs ReynoldsFlow 0.1.3 (a throwaway venv with it installed:
``python3 -m venv /tmp/rf && /tmp/rf/bin/pip install ReynoldsFlow==0.1.3``) on the same
gap field (saved by rank 0), periodic along axis 0 with a unit gradient, and prints its
transmissivity (its flux through the unit square, ``K = Q``, g^3 units), seconds and
added peak memory per point beside petgap's.  Its first call compiles Numba kernels:
they are warmed up on a small field first and not counted.

Usage::

    mpirun -n 2 python benchmarks/flow.py --sizes 512 1024 2048 4096 8192 [--pcs hypre gamg]
        [--reynoldsflow /tmp/rf] [--directions x y]
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import petgap
from petgap.flow import leakage

RF_SCRIPT = r"""
import json, sys, time
import numpy as np

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024

from reynoldsflow.transport import compute_total_flux, solve_fluid_problem, warmup_numba_functions
warmup_numba_functions()
small = np.random.default_rng(0).random((32, 32)) + 0.5
solve_fluid_problem(small, boundary_mode="periodic", pressure_gradient=1.0)
gaps = np.load(sys.argv[1])
open("/proc/self/clear_refs", "w").write("5")
base = status("VmRSS:")
start = time.perf_counter()
filtered, p, flux = solve_fluid_problem(gaps, boundary_mode="periodic", pressure_gradient=1.0)
seconds = time.perf_counter() - start
q = 0.0 if flux is None else compute_total_flux(filtered, flux, gaps.shape[0],
                                                boundary_mode="periodic")[0]
print("RF", json.dumps({"K": q, "seconds": seconds,
                        "bytes": status("VmHWM:") - base}))
"""


def memory(key):
    """A line of /proc/self/status in bytes."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    return 0


def available():
    """The machine's available memory in bytes (/proc/meminfo's MemAvailable)."""
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 0


#: Bytes per point of the contact solve at its peak, before the flow step.
CONTACT_BYTES = 100
#: Bytes per point held beside the flow step: the gap and the grid's transform buffers.
HELD_BYTES = 24


def fits(n, per_point, comm):
    """``(fits, needed, available)``: whether ``n^2`` points fit in memory, at the contact
    solve's peak and at the flow step's (``per_point`` bytes each, the largest grid's so
    far, beside what it holds)."""
    needed = n * n * max(CONTACT_BYTES, per_point + HELD_BYTES)
    free = comm.bcast(available() if comm.rank == 0 else None, root=0)
    return needed < free, needed, free


def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def flow_row(grid, gap, pc, direction, comm):
    """One flow step: iterations, seconds, added peak bytes per point (summed over ranks)."""
    comm.Barrier()
    reset_peak()
    base = memory("VmRSS:")
    started = time.perf_counter()
    result = leakage(grid, gap, direction=direction, options={"flow_pc_type": pc})
    seconds = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
    added = comm.allreduce(memory("VmHWM:") - base, op=MPI.SUM)
    return result, seconds, added / grid.npoints


def reynoldsflow(venv, gap, workdir):
    path = Path(workdir) / "gap.npy"
    np.save(path, gap)
    script = Path(workdir) / "rf.py"
    script.write_text(RF_SCRIPT)
    done = subprocess.run([str(Path(venv) / "bin" / "python"), str(script), str(path)],
                          capture_output=True, text=True, timeout=7200)
    lines = [t for t in done.stdout.splitlines() if t.startswith("RF ")]
    if done.returncode != 0 or not lines:
        return {"error": done.stderr[-500:]}
    return json.loads(lines[0][3:])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048, 4096])
    parser.add_argument("--large", action="store_true", help="add 8192^2")
    parser.add_argument("--pcs", nargs="+", default=["hypre", "gamg"])
    parser.add_argument("--reynoldsflow", metavar="VENV")
    parser.add_argument("--directions", nargs="+", default=["x"], choices=["x", "y"],
                        help="flow directions (a row each; y rows read 'pc, y')")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    sizes = args.sizes + ([8192] if args.large else [])
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    say(f"{comm.size} rank(s)\n")
    say("| N | contact solve / s | pc | iterations | flow step / s | KSP / s | "
        "flow B/pt | flow factor | c | ReynoldsFlow K / petgap K | ReynoldsFlow / s | "
        "ReynoldsFlow B/pt |")
    say("|---|---|---|---|---|---|---|---|---|---|---|---|")
    largest = 0.0
    for n in sizes:
        ok, needed, free = fits(n, largest, comm)
        if not ok:
            say(f"| {n}^2 | not run: needs about {needed / 2**30:.1f} GiB "
                f"({largest:.0f} B/pt for the flow step, {HELD_BYTES} held beside it), "
                f"{free / 2**30:.1f} GiB available |", flush=True)
            continue
        grid = petgap.Grid((n, n), comm=comm)
        h = petgap.self_affine(grid, 0.8, 32.0, lambda_max=n / 2, rms_slope=0.1, seed=7)
        problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
        started = time.perf_counter()
        solution = petgap.solve(problem, petgap.Load(0.002))
        contact = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
        gap, fraction = solution.gap, solution.contact_fraction
        del problem, solution, h
        rf = None
        if args.reynoldsflow:
            whole = grid.gather(gap)
            if comm.rank == 0:
                with tempfile.TemporaryDirectory() as workdir:
                    rf = reynoldsflow(args.reynoldsflow, whole, workdir)
            del whole
        for pc, direction in [(pc, d) for pc in args.pcs for d in args.directions]:
            result, seconds, per_point = flow_row(grid, gap, pc, direction, comm)
            largest = per_point
            extra = " - | - | - |"
            if rf is not None and "K" in rf and direction == "x":
                extra = (f" {rf['K'] / result.transmissivity:.6f} | {rf['seconds']:.2f} | "
                         f"{rf['bytes'] / grid.npoints:.0f} |")
            elif rf is not None and "K" not in rf:
                extra = f" error: {rf['error'][-80:]!r} | - | - |"
            label = result.pc_type + ("" if direction == "x" else f", {direction}")
            say(f"| {n}^2 | {contact:.2f} | {label} | {result.iterations} | "
                f"{seconds:.2f} | {result.solve_time:.2f} | {per_point:.0f} | "
                f"{result.flow_factor:.5f} | {fraction:.4f} |{extra}",
                flush=True)
        del gap, grid


if __name__ == "__main__":
    sys.exit(main())
