#!/usr/bin/env python3
"""Benchmark: adhesive contact beside the non-adhesive solve of the same surface (issue 34).

Not a test: it prints a markdown table (docs/benchmarks.md, "Adhesive contact at the hard
wall's pace").  On the GUIDE surface of each size (H = 0.8, lambda_min = 32 a0,
lambda_max = L / 2, rms slope 0.1, seed 7, E* = 1) the non-adhesive state at
P0 = 0.002 E* is solved first (``petgap.solve``), then ``ExponentialAdhesion(w, rho)`` for
each ``--work`` to KKT 1e-8, under ``MeanGap`` at the non-adhesive mean gap and under
``Load(0.002)``, each cold and by each method:

* ``default``: the two-level preconditioner from the coarse-grid start (``petgap.solve``);
* ``two-level``: the two-level preconditioner from the rigid approach (under load, the hard
  wall's state, whose iterations the pairs include) -- ``-petgap_coarse_start 0``;
* ``plain``: the compliance preconditioner alone from the same start --
  ``-petgap_two_level 0 -petgap_coarse_start 0``.

Every solve runs in a process of its own under ``mpirun -n R`` (so that its peak memory is
its own), and the FFT-pair floor of the grid on R ranks (``benchmarks/floor.py``) is measured
between the solves.  A row gives, per solve:

* **its / pairs**: iterations and FFT pairs (the coarse-grid start's included);
* **floor pairs**: the solve's wall time from problem to solution (start included) over the
  mean of the floors measured before and after it: its cost in the machine's transform
  pairs; **x non-adh.**: that over the non-adhesive solve's;
* **cpu x**: rank 0's CPU seconds over the non-adhesive solve's (a shared machine disturbs a
  process's CPU time less than its wall time);
* **B / point**: peak resident memory over the grid's points, summed over the ranks, less
  what the process held before the grid existed;
* **dg**: the largest gap difference over ``h0`` from the first method's state on the first
  rank count (rank independence and the methods' agreement); with ``--tamaas VENV`` also
  Tamaas 2.9's iterations, seconds and its largest gap and pressure differences (over ``h0``
  and ``h0' E*``) on the mean-gap rows of one rank up to ``--tamaas-max`` (Tamaas's
  gap-primal solver has no load control).  Fields are compared up to ``--check-max``.

With ``--free`` the same surface is also a finite map on a free boundary
(``petgap.FreeHalfSpace``: the gap solver on its padded periodic cell), solved by
``petgap.solve`` beside the periodic cell, on every rank of ``COMM_WORLD`` (``mpirun -n 2``):
a row is one ``w`` and control, its cells iterations / FFT pairs of the free map and of the
periodic cell, the outer steps of the free map (the moves of its cell's mean-gap target,
:mod:`petgap.solvers.free_boundary`; a load is one solve), the CPU seconds of both (summed
over the ranks) and ``1/kappa_att`` of both.  Each adhesive solve starts cold; the free
map's mean gap is its own non-adhesive state's.

Usage::

    python benchmarks/adhesive_scaling.py --sizes 512 1024 2048 4096 [--ranks 1 2]
        [--work 0.15 0.3] [--methods default two-level plain] [--range 4]
        [--tamaas /tmp/petgap-tamaas-venv [--tamaas-max 1024]] [--check-max 4096]
    mpirun -n 2 python benchmarks/adhesive_scaling.py --free --sizes 512 1024 2048
"""
import argparse
import re
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from contact import mpirun, run, tamaas_run
from floor import fft_floor

OPTIONS = {"default": {},
           "two-level": {"petgap_coarse_start": 0},
           "plain": {"petgap_two_level": 0, "petgap_coarse_start": 0}}
LOAD = 0.002


def worker(args):
    """Runs under mpirun: one solve, its numbers as one JSON line (fields saved if asked)."""
    import resource
    import time

    import numpy as np
    from mpi4py import MPI

    import petgap
    from petgap.surfaces.topography import save_topography_npy

    comm = MPI.COMM_WORLD
    n = args.n
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    grid = petgap.Grid((n, n), comm=comm, planner="estimate")
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
    if args.save_surface:
        save_topography_npy(grid, h, args.save_surface)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    work = args.work[0]   # a worker is given one value
    if work > 0:
        problem = problem.with_interaction(petgap.ExponentialAdhesion(work, args.range))
    control = (petgap.MeanGap(args.mean_gap) if args.mean_gap is not None
               else petgap.Load(LOAD))
    comm.Barrier()
    cpu, wall = time.process_time(), time.perf_counter()
    solution = petgap.solve(problem, control, options=OPTIONS[args.method])
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    out = {k: v for k, v in solution.scalars().items()
           if isinstance(v, (int, float, str, bool))}
    out.update(wall=comm.allreduce(wall, op=MPI.MAX), cpu=cpu,
               bytes_per_point=comm.allreduce((peak - base) * 1024.0) / grid.npoints,
               h0=problem.gap_scale, pressure_scale=problem.pressure_scale,
               step_counts=getattr(solution, "step_counts", {}))
    if args.save_fields:
        gap, pressure = grid.gather(solution.gap), grid.gather(solution.pressure)
        if comm.rank == 0:
            np.save(args.save_fields, np.stack([gap, pressure]))
    if comm.rank == 0:
        print("RESULT " + json.dumps(out), flush=True)


def solve(n, ranks, extra):
    out = run(mpirun(ranks) + [sys.executable, __file__, "--worker", "--n", str(n)] + extra)
    return json.loads(out.split("RESULT ", 1)[1].splitlines()[0])


def largest_differences(a, b, h0, pressure_scale):
    """``max |dg| / h0`` and ``max |dp| / (h0' E*)`` between two saved ``(gap, pressure)``."""
    import numpy as np
    x, y = np.load(a), np.load(b)
    return (float(np.abs(x[0] - y[0]).max()) / h0,
            float(np.abs(x[1] - y[1]).max()) / pressure_scale)


def tamaas_fields(venv, surface, work, rho, mean_gap, tmp):
    """Tamaas 2.9 at ``mean_gap`` (``benchmarks/contact.py``'s adhesive path): its numbers and
    its ``(gap, pressure)`` saved beside petgap's."""
    import numpy as np
    os.environ["TAMAAS_VENV"] = venv
    raw = Path(tmp) / "tamaas-raw.npy"
    result = tamaas_run(surface, LOAD, 1e-8, work, rho, mean_gap, fields=raw)
    pressure, displacement = np.load(raw)
    path = Path(tmp) / "tamaas.npy"
    np.save(path, np.stack([displacement - np.load(surface), pressure]))
    return result, path


def _moves(solution):
    """The free map's outer steps as its start says them: moves of its target, or secant solves."""
    found = re.search(r"moved its target (\d+) times|\((\d+) mean-gap solves\)", solution.start)
    return 0 if found is None else int(found.group(1) or found.group(2))


def free_rows(args):
    """The ``--free`` table's rows: each size, ``w`` and control, free map beside periodic."""
    from mpi4py import MPI
    import petgap
    comm = MPI.COMM_WORLD

    def run(problem, control):
        comm.Barrier()
        started = time.process_time()
        s = petgap.solve(problem, control)
        return s, comm.allreduce(time.process_time() - started)
    rows = []
    for n in args.sizes:
        grid = petgap.Grid((n, n), comm=comm, planner="estimate")
        h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=7)
        for w in args.work:
            cells = {}
            for body, half in (("free", petgap.FreeHalfSpace(grid)),
                               ("periodic", petgap.ElasticHalfSpace(grid))):
                hard = petgap.ContactProblem(grid, h, half)
                reference, _ = run(hard, petgap.Load(0.002))
                adhesive = hard.with_interaction(petgap.ExponentialAdhesion(w, args.range))
                for control in (petgap.MeanGap(reference.mean_gap), petgap.Load(0.002)):
                    cells[body, control.kind] = run(adhesive, control)
            for kind in ("mean-gap", "load"):
                (free, free_cpu), (periodic, periodic_cpu) = cells["free", kind], \
                    cells["periodic", kind]
                verdict = "".join(f" {s.reason}" for s in (free, periodic) if not s.converged)
                rows.append(f"| {n}^2 | {w:g} | {kind} | {free.iterations} / "
                            f"{free.operator_applications:g} | {_moves(free)} | "
                            f"{periodic.iterations} / {periodic.operator_applications:g} | "
                            f"{free_cpu:.1f} | {periodic_cpu:.1f} | {free.inv_kappa_att:.2f} | "
                            f"{periodic.inv_kappa_att:.2f} |{verdict}")
                if comm.rank == 0:
                    print(rows[-1], file=sys.stderr, flush=True)
    if comm.rank == 0:
        print(f"GUIDE surface, seed 7; rho = {args.range:g} a0, KKT 1e-8, {comm.size} rank(s).\n")
        print("| N | w (E* a0) | control | free | moves | periodic | free CPU s | periodic CPU s "
              "| 1/kappa_att free | periodic |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(rows))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--n", type=int)
    parser.add_argument("--mean-gap", type=float)
    parser.add_argument("--method", default="default", choices=list(OPTIONS))
    parser.add_argument("--save-surface")
    parser.add_argument("--save-fields")
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1])
    parser.add_argument("--work", type=float, nargs="+", default=[0.05, 0.15])
    parser.add_argument("--range", type=float, default=4.0)
    parser.add_argument("--methods", nargs="+", default=["default"], choices=list(OPTIONS))
    parser.add_argument("--tamaas", metavar="VENV",
                        help="also Tamaas 2.9 from this venv (created there if missing)")
    parser.add_argument("--tamaas-max", type=int, default=1024)
    parser.add_argument("--check-max", type=int, default=4096,
                        help="largest size whose fields are compared")
    parser.add_argument("--free", action="store_true",
                        help="the free map beside the periodic cell (module docstring)")
    args = parser.parse_args()
    if args.free:
        return free_rows(args)
    if args.worker:
        return worker(args)

    print(f"GUIDE surface, seed 7; rho = {args.range:g} a0, KKT 1e-8.\n")
    print("| N | ranks | w (E* a0) | control | method | its / pairs | floor pairs | x non-adh. "
          "| cpu x | B / point | 1/kappa_att | dg | Tamaas its / s | Tamaas dg / dp |")
    print("|" + "---|" * 14, flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            surface = Path(tmp) / f"h{n}.npy"
            check = n <= args.check_max
            firsts = {}
            for ranks in args.ranks:
                floors = [fft_floor(n, ranks)]

                def timed(extra, key=None):
                    fields = Path(tmp) / f"{n}-{ranks}-{key}.npy" if check and key else None
                    r = solve(n, ranks, extra + (["--save-fields", str(fields)] if fields else [])
                              + ([] if surface.exists() else ["--save-surface", str(surface)]))
                    floors.append(fft_floor(n, ranks))
                    r["floor_pairs"] = r["wall"] / (0.5 * (floors[-2] + floors[-1]))
                    r["fields"] = fields
                    return r

                hard = timed(["--work", "0"])
                rows = [(0.0, "load", "default", hard)]
                for w, kind, method in ((w, kind, m) for w in args.work
                                        for kind in ("mean-gap", "load") for m in args.methods):
                    extra = ["--work", str(w), "--range", str(args.range), "--method", method]
                    if kind == "mean-gap":
                        extra += ["--mean-gap", repr(hard["mean_gap"])]
                    rows.append((w, kind, method, timed(extra, f"{w}-{kind}-{method}")))
                for w, kind, method, r in rows:
                    first = firsts.setdefault((w, kind), r)
                    dg = ""
                    if r is not first and r["fields"] and first["fields"]:
                        dg = "{:.0e}".format(largest_differences(
                            r["fields"], first["fields"], r["h0"], r["pressure_scale"])[0])
                    t_cols = ["", ""]
                    if (args.tamaas and w > 0 and kind == "mean-gap" and r is first
                            and n <= args.tamaas_max):
                        t, path = tamaas_fields(args.tamaas, surface, w, args.range,
                                                r["mean_gap"], tmp)
                        dgt, dpt = largest_differences(path, r["fields"], r["h0"],
                                                       r["pressure_scale"])
                        t_cols = [f"{t['iterations']} / {t['time']:.1f}", f"{dgt:.0e} / {dpt:.0e}"]
                    verdict = "" if r["converged"] else f" {r['reason']}"
                    print(f"| {n}^2 | {ranks} | {w:g} | {kind} | "
                          + ("non-adhesive" if w == 0 else method)
                          + f" | {r['iterations']} / {r['operator_applications']:g}{verdict} | "
                          f"{r['floor_pairs']:.0f} | {r['floor_pairs'] / hard['floor_pairs']:.1f} | "
                          f"{r['cpu'] / hard['cpu']:.1f} | {r['bytes_per_point']:.0f} | "
                          + (f"{r['inv_kappa_att']:.2f}" if w > 0 else "")
                          + f" | {dg} | " + " | ".join(t_cols) + " |", flush=True)
                    print(f"<!-- N={n} ranks={ranks} w={w:g} {kind} {method}: "
                          f"{json.dumps(r['step_counts'])}; floor "
                          f"{statistics.median(floors):.4g} s -->", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
