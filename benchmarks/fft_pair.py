#!/usr/bin/env python3
"""petgap's FFT transform pair: the floor of an iteration, and the operator against it.

An iteration of the solvers costs a few transform pairs; the pair itself is
therefore the floor the solvers' time is measured against
(``benchmarks/contact.py`` takes its floor from :func:`run_petgap`).  For each
grid size N and rank count P this measures one forward (r2c) plus one
backward (c2r) 2D transform of an N x N field:

* petgap's own pair: ``Grid((N, N), planner="measure")``, ``grid.forward()`` then
  ``grid.backward()`` on the grid's own buffers, timed as a C program
  would (barrier, MPI_Wtime, pair, barrier), median of ``--repeats`` pairs after
  ``--warmup`` untimed pairs, run under ``mpirun -n P``; and, in the same
  process, one application of the elastic operator as the solvers make it
  (``ElasticHalfSpace.apply_in_buffer``: the transforms fused with the Fourier
  multiplier, ``Grid.convolve_qpower``), timed the same way;
* optionally (``--fft-limit PROGRAM``), a C program on FFTW-MPI alone that runs
  as ``PROGRAM N P repeats`` and prints ``median_pair_s=...`` (FFTW_MEASURE,
  transposed layout), to show what the Python binding costs over plain C.

With a C program the order of the two alternates between rounds, so that slow
drifts of a noisy machine hit both alike.  Printed: a markdown table of the
medians over rounds of the per-run medians, and their ratios.

Usage (from the repository root, after ``source scripts/bootstrap.sh``)::

    python benchmarks/fft_pair.py [--sizes 1024 2048] [--ranks 1 2] [--rounds 5] [--fft-limit PROGRAM]

``--worker N`` is the inner measurement (run by the script under mpirun).
"""
import argparse
import os
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np



def worker(n, repeats, warmup):
    """Time petgap's transform pair on an n x n grid; rank 0 prints the median."""
    # Deferred to the worker: the driver process runs no MPI.
    from mpi4py import MPI

    from petgap.mechanics.half_space import ElasticHalfSpace
    from petgap.parallel.grid import Grid
    comm = MPI.COMM_WORLD
    grid = Grid((n, n), comm=comm, planner="measure")
    # Uniform random numbers (after planning, which scribbles on the buffers).
    # Values grow by n^2 per unnormalised pair; 17 pairs stay far from overflow
    # for n <= 8192.
    grid.real[...] = np.random.default_rng(comm.rank).random(grid.local_shape)
    for _ in range(warmup):
        grid.forward()
        grid.backward()
    times = []
    for _ in range(repeats):
        comm.Barrier()
        t0 = MPI.Wtime()
        grid.forward()
        grid.backward()
        comm.Barrier()
        times.append(MPI.Wtime() - t0)
    times.sort()
    half_space = ElasticHalfSpace(grid, 1.0)
    applies = []
    for k in range(warmup + repeats):
        comm.Barrier()
        t0 = MPI.Wtime()
        half_space.apply_in_buffer(inverse=k % 2 == 0)
        comm.Barrier()
        if k >= warmup:
            applies.append(MPI.Wtime() - t0)
    applies.sort()
    if comm.rank == 0:
        print(f"petgap N={n} ranks={comm.size} median_pair_s={times[len(times) // 2]:.6f} "
              f"median_apply_s={applies[len(applies) // 2]:.6f}", flush=True)


def _median_from(output, what, key="median_pair_s"):
    m = re.search(key + r"=([0-9.eE+-]+)", output)
    if not m:
        raise RuntimeError(f"no median in the output of {what}:\n{output}")
    return float(m.group(1))


def _run(cmd, what, env=None, attempts=2, keys=("median_pair_s",)):
    """Run a measurement; on failure show its output and try once more."""
    for attempt in range(attempts):
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
        if out.returncode == 0:
            values = [_median_from(out.stdout, what, key) for key in keys]
            return values[0] if len(values) == 1 else values
        print(f"# {what} failed (exit {out.returncode}, attempt {attempt + 1}):\n"
              f"{out.stdout}{out.stderr}", file=sys.stderr, flush=True)
    raise RuntimeError(f"{what} failed {attempts} times: {shlex.join(cmd)}")


def run_fft_limit(program, n, ranks, repeats):
    """The median pair of a C FFTW-MPI program (see the module docstring)."""
    return _run([str(program), str(n), str(ranks), str(repeats)], "fft_limit")


def run_petgap(n, ranks, repeats, warmup, wisdom="cached"):
    """Median seconds of petgap's pair and of one operator application, under mpirun.

    ``wisdom="fresh"`` plans from scratch (as a C program without wisdom does).
    """
    cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", sys.executable, str(Path(__file__)),
           "--worker", str(n), "--repeats", str(repeats), "--warmup", str(warmup)]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    keys = ("median_pair_s", "median_apply_s")
    if wisdom == "fresh":
        with tempfile.TemporaryDirectory(prefix="petgap-wisdom-") as empty:
            env["PETGAP_WISDOM_DIR"] = empty
            return _run(cmd, "the petgap worker", env=env, keys=keys)
    return _run(cmd, "the petgap worker", env=env, keys=keys)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--rounds", type=int, default=5, help="alternating runs of each")
    parser.add_argument("--repeats", type=int, default=15, help="timed pairs per run")
    parser.add_argument("--warmup", type=int, default=2, help="untimed pairs per petgap run")
    parser.add_argument("--wisdom", choices=["cached", "fresh"], default="cached",
                        help="petgap's FFTW wisdom: the on-disk cache (as petgap runs), or "
                             "none, planning afresh each run (as a C program does)")
    parser.add_argument("--fft-limit", type=Path, metavar="PROGRAM",
                        help="a C FFTW-MPI program to compare with (module docstring)")
    parser.add_argument("--worker", type=int, metavar="N", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, args.repeats, args.warmup)
        return

    rows = []
    print(f"# {time.strftime('%Y-%m-%d %H:%M')}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f}; {args.rounds} alternating rounds, {args.repeats} pairs per "
          f"run, petgap wisdom {args.wisdom}", file=sys.stderr)
    for n in args.sizes:
        for ranks in args.ranks:
            limit, ours, apply = [], [], []
            for k in range(args.rounds):
                order = (0, 1) if k % 2 == 0 else (1, 0)
                for which in order:
                    if which == 0:
                        if args.fft_limit:
                            limit.append(run_fft_limit(args.fft_limit, n, ranks, args.repeats))
                    else:
                        pair, op = run_petgap(n, ranks, args.repeats, args.warmup,
                                              args.wisdom)
                        ours.append(pair)
                        apply.append(op)
                print(f"# N={n} ranks={ranks} round {k}: "
                      + (f"fft_limit {limit[-1]:.4f} s, " if limit else "")
                      + f"petgap pair {ours[-1]:.4f} s, operator {apply[-1]:.4f} s",
                      file=sys.stderr, flush=True)
            b, c = statistics.median(ours), statistics.median(apply)
            a = statistics.median(limit) if limit else float("nan")
            rows.append((n, ranks, a, b, b / a, c, c / a, min(limit, default=float("nan")),
                         min(ours)))
    print(f"# done {time.strftime('%H:%M')}, load average {os.getloadavg()[0]:.2f}",
          file=sys.stderr)

    print("| N | ranks | fft_limit median s | petgap pair median s | ratio | "
          "operator application median s | ratio | fft_limit best s | petgap pair best s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n, ranks, a, b, r, c, rc, amin, bmin in rows:
        print(f"| {n} | {ranks} | {a:.4f} | {b:.4f} | {r:.2f} | {c:.4f} | {rc:.2f} | "
              f"{amin:.4f} | {bmin:.4f} |")


if __name__ == "__main__":
    main()
