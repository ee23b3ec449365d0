#!/usr/bin/env python3
"""Benchmark: free-boundary against periodic contact on the same map, beside Tamaas' DC-FFT.

For each size ``n``, a self-affine surface (H = 0.8, lambda_min = 32 a0, lambda_max = L/2,
h0' = 0.1, seed 1: docs/benchmarks.md's) is solved under the load P0 = 0.002 E* to KKT 1e-8 by petgap's ``pcg``
twice: on the periodic cell, and as a finite map on a free boundary
(:class:`petgap.mechanics.free_half_space.FreeHalfSpace`: Hockney's zero padding, a
``2n x 2n`` transform pair per compliance application).  Printed per size and rank count:
iterations, applications of the elastic operator, wall time of the solve (coarse start
included), time per iteration, the FFTW-MPI pair floor of ``n^2`` and ``(2n)^2`` measured
in the same run (benchmarks/fft_floor.c), the solve in floor pairs of its own grid (``n^2``
periodic, ``(2n)^2`` free), and the peak memory per map point (peak RSS less the RSS before
the grid, summed over ranks; each boundary solved in a process of its own).

With ``--tamaas`` the free map is also solved by Tamaas 2.9's ``PolonskyKeerRey`` with its
non-periodic ``dcfft`` operator (one process, in its own venv as in benchmarks/contact.py),
to the same load and its own tolerance 1e-8, with the contact fraction of both.

Usage::

    python benchmarks/free_boundary.py --sizes 256 512 1024 2048 --ranks 1 2 [--tamaas]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

LOAD, TOLERANCE = 0.002, 1e-8

TAMAAS_DCFFT = r'''
import json, sys, time
import numpy as np
import tamaas as tm
path, load, tol = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
h = np.load(path); n = h.shape[0]
model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [float(n), float(n)], [n, n])
model.E = 1.0; model.nu = 0.0
tm.ModelFactory.registerNonPeriodic(model, "dcfft")
solver = tm.PolonskyKeerRey(model, h, tol)
solver.setIntegralOperator("dcfft")
solver.max_iter = 100000
t = time.perf_counter(); solver.solve(load); dt = time.perf_counter() - t
p = np.array(model.traction).reshape(n, n)
print("TAMAAS " + json.dumps({"time": dt, "contact_fraction": float((p > 0).mean()),
                              "mean_pressure": float(p.mean()), "error": float(solver.computeError())}))
'''


def worker(n, path, boundary):
    """Solve the map on COMM_WORLD periodic or free; print one JSON line (rank 0)."""
    import resource
    from mpi4py import MPI
    import petgap
    comm = MPI.COMM_WORLD
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    grid = petgap.Grid((n, n), comm=comm)
    h = petgap.load_topography(grid, path)
    body = petgap.ElasticHalfSpace(grid) if boundary == "periodic" else petgap.FreeHalfSpace(grid)
    problem = petgap.ContactProblem(grid, h, body)
    comm.Barrier()
    t = time.perf_counter()
    s = petgap.solve(problem, petgap.Load(LOAD), tolerance=TOLERANCE)
    comm.Barrier()
    dt = time.perf_counter() - t
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024
    if comm.rank == 0:
        print("RESULT " + json.dumps({
            "iterations": s.iterations, "applications": s.operator_applications, "time": dt,
            "converged": s.converged, "c": s.contact_fraction, "bytes": peak / n ** 2}),
            flush=True)


def make_surface(n, path):
    import numpy as np
    from mpi4py import MPI
    import petgap
    grid = petgap.Grid((n, n), comm=MPI.COMM_SELF, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    np.save(path, h)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--n", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--map", help=argparse.SUPPRESS)
    parser.add_argument("--boundary", help=argparse.SUPPRESS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--tamaas", action="store_true")
    args = parser.parse_args()
    if args.worker:
        return worker(args.n, args.map, args.boundary)
    from floor import fft_floor
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    work = Path(tempfile.mkdtemp(prefix="petgap-free-bench-"))
    print(f"load {LOAD} E*, KKT {TOLERANCE}; H = 0.8, lambda_min = 32 a0, lambda_max = L/2, "
          f"h0' = 0.1; times in s, pairs = solve time / floor pair of that grid")
    header = ("n", "ranks", "boundary", "iterations", "applications", "time s", "ms/it",
              "floor n^2", "floor (2n)^2", "floor pairs", "B/pt", "c")
    print(" | ".join(header))
    for n in args.sizes:
        path = work / f"map{n}.npy"
        make_surface(n, path)
        for ranks in args.ranks:
            small, large = fft_floor(n, ranks), fft_floor(2 * n, ranks)
            for boundary in ("periodic", "free"):
                proc = subprocess.run(["mpirun", "-n", str(ranks), "--oversubscribe",
                                       sys.executable, __file__, "--worker", "--n", str(n),
                                       "--map", str(path), "--boundary", boundary],
                                      capture_output=True, text=True, env=env, timeout=7200)
                if "RESULT " not in proc.stdout:
                    print(proc.stdout[-2000:], proc.stderr[-2000:])
                    continue
                r = json.loads(proc.stdout.split("RESULT ", 1)[1].splitlines()[0])
                floor = small if boundary == "periodic" else large
                print(" | ".join(str(v) for v in (
                    n, ranks, boundary, r["iterations"], r["applications"], f"{r['time']:.3f}",
                    f"{1e3 * r['time'] / max(r['iterations'], 1):.2f}", f"{small * 1e3:.2f} ms",
                    f"{large * 1e3:.2f} ms", f"{r['time'] / floor:.0f}", f"{r['bytes']:.0f}",
                    f"{r['c']:.4f}")), flush=True)
        if args.tamaas:
            from contact import tamaas_python
            proc = subprocess.run([str(tamaas_python()), "-c", TAMAAS_DCFFT, str(path), str(LOAD),
                                   str(TOLERANCE)], capture_output=True, text=True, timeout=14400)
            text = proc.stdout + proc.stderr
            if "TAMAAS " not in text:
                print(f"{n} | 1 | Tamaas dcfft failed: {text[-1500:]}")
                continue
            t = json.loads(text.split("TAMAAS ", 1)[1].splitlines()[0])
            print(f"{n} | 1 | Tamaas dcfft | - | - | {t['time']:.3f} | - | - | - | "
                  f"{t['time'] / fft_floor(2 * n, 1):.0f} | - | {t['contact_fraction']:.4f}",
                  flush=True)


if __name__ == "__main__":
    main()
