#!/usr/bin/env python3
"""Benchmark: free-boundary against periodic contact on the same map, beside Tamaas' DC-FFT.

For each size ``n``, a self-affine surface (H = 0.8, lambda_min = 32 a0, lambda_max = L/2,
h0' = 0.1, seed 1: docs/benchmarks.md's) is solved under the load P0 = 0.002 E* to KKT 1e-8
by petgap's ``pcg`` twice: on the periodic cell, and as a finite map on a free boundary
(:class:`petgap.mechanics.free_half_space.FreeHalfSpace`: Hockney's zero padding by the
pruned transform).  Printed per size and rank count: iterations, applications of the
elastic operator, wall time of the solve (coarse start included), time per iteration, the
FFTW-MPI pair floor of ``n^2`` and ``(2n)^2`` measured in the same run
(benchmarks/fft_floor.c), the free operator's pruned pair (``C p`` of a whole field,
median of 5, into a field of its own as the solvers apply it; wall and CPU) in ms and
in ``n^2`` floor pairs, the free solve's wall time, CPU time
(summed over the ranks: on a shared machine it moves less with the other jobs than the
wall time) and iterations over the periodic one's, and the peak memory per map point (peak RSS less the RSS before the
grid, summed over ranks; each boundary solved in a process of its own).

``--shape NXxNY`` and ``--pixel DXxDY`` solve one non-square map with non-unit pixels
instead of the square sizes (no floor then).  ``--controls`` adds mean-gap control to the
load solve's mean gap on both boundaries, and on the free map indentation to its depth,
with their iterations and times (in each boundary's process, after its memory is taken);
a free control's ratios are over the periodic solve of the same control: the cell's
mean-gap solve, and for indentation (which a periodic cell does not have: an approach
fixes no load there) its load solve.

With ``--tamaas`` the free map is also solved by Tamaas 2.9's ``PolonskyKeerRey`` with its
non-periodic ``dcfft`` operator (one process, in its own venv as in benchmarks/contact.py),
to the same load and its own tolerance 1e-8, with the contact fraction of both and their
fields compared: the points in contact in one solution only (over the points in contact
in petgap's), and the largest pressure difference over petgap's largest pressure.

Usage::

    python benchmarks/free_boundary.py --sizes 1024 2048 4096 --ranks 1 [--controls] [--tamaas]
    python benchmarks/free_boundary.py --shape 2048x1536 --pixel 1.0x0.75 --ranks 1
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
np.save(path + ".tamaas.npy", p)
print("TAMAAS " + json.dumps({"time": dt, "contact_fraction": float((p > 0).mean()),
                              "mean_pressure": float(p.mean()), "error": float(solver.computeError())}))
'''


def _timed(comm, func):
    """``(func(), wall seconds, CPU seconds summed over the ranks)``."""
    comm.Barrier()
    t, cpu = time.perf_counter(), time.process_time()
    result = func()
    cpu = time.process_time() - cpu
    comm.Barrier()
    return result, time.perf_counter() - t, comm.allreduce(cpu)


def worker(shape, size, path, boundary, controls, save=False):
    """Solve the map on COMM_WORLD periodic or free; print one JSON line (rank 0)."""
    import resource
    import numpy as np
    from mpi4py import MPI
    import petgap
    comm = MPI.COMM_WORLD
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    grid = petgap.Grid(shape, size=size, comm=comm)
    h = petgap.load_topography(grid, path)
    body = petgap.ElasticHalfSpace(grid) if boundary == "periodic" else petgap.FreeHalfSpace(grid)
    problem = petgap.ContactProblem(grid, h, body)
    s, dt, cpu = _timed(comm, lambda: petgap.solve(problem, petgap.Load(LOAD),
                                                   tolerance=TOLERANCE))
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024
    result = {"iterations": s.iterations, "applications": s.operator_applications, "time": dt,
              "cpu": cpu, "converged": s.converged, "c": s.contact_fraction,
              "bytes": peak / grid.npoints}
    if save:   # the pressure field, for the comparison with Tamaas'
        pressure = grid.gather(s.pressure)
        if comm.rank == 0:
            np.save(path + ".free.npy", pressure)
    if boundary == "free":
        # into a field of its own, as the solvers apply it: a new result each time would
        # add the first touch of its pages (8 B/pt), which grows with the machine's load
        field = np.random.default_rng(comm.rank).random(grid.local_shape)
        out = np.empty_like(field)
        pairs = [_timed(comm, lambda: body.displacement(field, out)) for _ in range(6)]
        result["pair"] = float(np.median([wall for _, wall, _ in pairs[1:]]))
        result["pair_cpu"] = float(np.median([cpu for _, _, cpu in pairs[1:]]))
    if controls:
        # each control at the load solve's own state: the mean gap it found, and on the
        # free map the depth too (a periodic cell has no indentation: an approach fixes
        # no load there)
        steps = [("mean-gap", petgap.MeanGap(s.mean_gap))]
        if boundary == "free":
            u = body.displacement(s.pressure)
            depth = problem.top_height - grid.sum(s.gap + h - u) / grid.npoints
            steps.insert(0, ("indentation", petgap.Indentation(depth)))
        for name, control in steps:
            c, t, cpu = _timed(comm, lambda: petgap.solve(problem, control, tolerance=TOLERANCE))
            result[name] = {"iterations": c.iterations, "time": t, "cpu": cpu,
                            "converged": c.converged, "load": c.mean_pressure}
    if comm.rank == 0:
        print("RESULT " + json.dumps(result), flush=True)


def make_surface(shape, size, path):
    import numpy as np
    from mpi4py import MPI
    import petgap
    grid = petgap.Grid(shape, size=size, comm=MPI.COMM_SELF, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 32.0 * grid.dx, grid.Lx / 2, rms_slope=0.1, seed=1)
    np.save(path, h)


def _compare(path):
    """Contact sets and pressures of petgap's free solve and Tamaas' of the map, in words."""
    import numpy as np
    ours, theirs = np.load(path + ".free.npy"), np.load(path + ".tamaas.npy")
    a, b = ours > 0, theirs > 0
    return (f"{np.count_nonzero(a & ~b)} points in contact in petgap's only, "
            f"{np.count_nonzero(b & ~a)} in Tamaas' only (of {np.count_nonzero(a)}); "
            f"max |p - p_Tamaas| = {np.abs(ours - theirs).max() / ours.max():.2e} max p")


def _pair(text):
    a, b = text.lower().split("x")
    return a, b


def _run(ranks, shape, size, path, boundary, controls, env, save=False):
    command = ["mpirun", "-n", str(ranks), "--oversubscribe", sys.executable, __file__,
               "--worker", "--shape", "x".join(map(str, shape)),
               "--pixel", "x".join(str(size[i] / shape[i]) for i in range(2)), "--map", str(path),
               "--boundary", boundary] + (["--controls"] if controls else []) \
        + (["--save"] if save else [])
    proc = subprocess.run(command, capture_output=True, text=True, env=env, timeout=14400)
    if "RESULT " not in proc.stdout:
        print(proc.stdout[-2000:], proc.stderr[-2000:])
        return None
    return json.loads(proc.stdout.split("RESULT ", 1)[1].splitlines()[0])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--map", help=argparse.SUPPRESS)
    parser.add_argument("--boundary", help=argparse.SUPPRESS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--shape", type=_pair, help="one NXxNY map instead of --sizes")
    parser.add_argument("--pixel", type=_pair, default=("1", "1"), help="DXxDY (with --shape)")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1])
    parser.add_argument("--controls", action="store_true",
                        help="also indentation and mean gap on the free map")
    parser.add_argument("--tamaas", action="store_true")
    parser.add_argument("--save", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.shape is not None:
        shapes = [tuple(int(v) for v in args.shape)]
    else:
        shapes = [(n, n) for n in args.sizes]
    pixel = tuple(float(v) for v in args.pixel)
    if args.worker:
        shape = shapes[0]
        return worker(shape, (shape[0] * pixel[0], shape[1] * pixel[1]), args.map, args.boundary,
                      args.controls, args.save)
    from floor import fft_floor
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    work = Path(tempfile.mkdtemp(prefix="petgap-free-bench-"))
    print(f"load {LOAD} E*, KKT {TOLERANCE}; H = 0.8, lambda_min = 32 dx, lambda_max = Lx/2, "
          f"h0' = 0.1, pixels {pixel[0]:g} x {pixel[1]:g}; times in s; floor pairs of FFTW-MPI; "
          f"pair: the free operator's pruned pair")
    header = ("map", "ranks", "boundary", "iterations", "applications", "solve s", "CPU s",
              "ms/it", "floor n^2", "floor (2n)^2", "pair", "pair / floor n^2", "time ratio",
              "CPU ratio", "iteration ratio", "B/pt", "c")
    print(" | ".join(header))
    for shape in shapes:
        size = (shape[0] * pixel[0], shape[1] * pixel[1])
        name = f"{shape[0]}x{shape[1]}" if shape[0] != shape[1] else f"{shape[0]}^2"
        path = work / f"map{shape[0]}x{shape[1]}.npy"
        make_surface(shape, size, path)
        for ranks in args.ranks:
            square = shape[0] == shape[1]
            small = fft_floor(shape[0], ranks) if square else None
            # beyond 8192^2 FFTW's measuring planner takes longer than the solves
            large = fft_floor(2 * shape[0], ranks) if square and shape[0] <= 4096 else None
            periodic = _run(ranks, shape, size, path, "periodic", args.controls, env)
            free = _run(ranks, shape, size, path, "free", args.controls, env,
                        save=args.tamaas and ranks == 1)
            for boundary, r in (("periodic", periodic), ("free", free)):
                if r is None:
                    continue
                ms = lambda v: "-" if v is None else f"{v * 1e3:.1f} ms"
                pair = r.get("pair")
                ratios = ("-", "-", "-")
                if boundary == "free" and periodic is not None:
                    ratios = (f"{r['time'] / periodic['time']:.2f}",
                              f"{r['cpu'] / periodic['cpu']:.2f}",
                              f"{r['iterations'] / periodic['iterations']:.2f}")
                print(" | ".join(str(v) for v in (
                    name, ranks, boundary, r["iterations"], r["applications"],
                    f"{r['time']:.3f}", f"{r['cpu']:.3f}",
                    f"{1e3 * r['time'] / max(r['iterations'], 1):.1f}",
                    ms(small), ms(large),
                    ms(pair) + (f" (CPU {r['pair_cpu'] * 1e3:.1f})" if pair is not None else ""),
                    "-" if pair is None or small is None else f"{pair / small:.2f}",
                    *ratios, f"{r['bytes']:.0f}", f"{r['c']:.4f}")), flush=True)
                for control in ("indentation", "mean-gap"):
                    if control not in r:
                        continue
                    c = r[control]
                    # the free control over the periodic solve of the same control where
                    # the cell has it, else (indentation) over its load solve
                    base = None
                    if boundary == "free" and periodic is not None:
                        base = periodic.get(control, periodic)
                    ratios = "- | - | -"
                    if base is not None:
                        ratios = (f"{c['time'] / base['time']:.2f} | {c['cpu'] / base['cpu']:.2f}"
                                  f" | {c['iterations'] / base['iterations']:.2f}")
                    print(f"{name} | {ranks} | {boundary}, {control} | {c['iterations']} | - | "
                          f"{c['time']:.3f} | {c['cpu']:.3f} | "
                          f"{1e3 * c['time'] / max(c['iterations'], 1):.1f} | - | - | - | - | "
                          f"{ratios} | - | P0 {c['load']:.6f}", flush=True)
        if args.tamaas and shape[0] == shape[1]:
            from contact import tamaas_python
            proc = subprocess.run([str(tamaas_python()), "-c", TAMAAS_DCFFT, str(path), str(LOAD),
                                   str(TOLERANCE)], capture_output=True, text=True, timeout=14400)
            text = proc.stdout + proc.stderr
            if "TAMAAS " not in text:
                print(f"{name} | 1 | Tamaas dcfft failed: {text[-1500:]}")
                continue
            t = json.loads(text.split("TAMAAS ", 1)[1].splitlines()[0])
            print(f"{name} | 1 | Tamaas dcfft | - | - | {t['time']:.3f} | - | - | - | - | - | - |"
                  f" {t['time'] / free['time'] if free else float('nan'):.1f} (Tamaas / free) | "
                  f"- | - | - | {t['contact_fraction']:.4f}", flush=True)
            print(f"{name}: Tamaas' fields against petgap's free solve: "
                  + _compare(str(path)),
                  flush=True)


if __name__ == "__main__":
    main()
