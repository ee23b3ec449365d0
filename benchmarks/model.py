#!/usr/bin/env python3
"""A performance model of a petgap solve, fitted here, used to plan cluster runs.

One iteration of the default solver (``pcg-pressure``) costs ``k`` FFT pairs (``k`` about
2.4-2.6: ``docs/benchmarks.md``) plus passes over the contact set and the slab, and a few
reductions.  The model:

* **FFT pair** on ``P`` ranks of an ``n x n`` grid (``N = n^2`` points)::

      T_pair(N, P) = c N log2(N) / (P e)  +  4 V_off(N, P) C / B_net  +  4 (P - 1) l

  The first term is the transforms and the on-node transposes: ``c`` (seconds per point
  and level) is fitted to one-rank pairs at the sizes given, ``e`` is the efficiency of two
  ranks sharing this machine's memory, ``T_1 / (2 T_2)`` at the largest size (a stand-in
  for the ranks of a node sharing its memory bandwidth: transforms of large grids are
  bandwidth-bound).  The second is the four all-to-all transposes' traffic off the node:
  ``V_off = 8 N (P - 1) / P^2 x (P - C) / (P - 1)`` bytes leave a rank per transpose for
  other nodes (the half-spectrum, 16-byte complex values, ``N / 2`` of them, in ``P``
  pieces), ``C`` ranks per node share the node's network bandwidth ``B_net``.  The last is
  the messages' latency ``l``.  ``B_net`` and ``l`` cannot be measured on one machine:
  ``--network-gbs`` and ``--latency-us`` give them (defaults: a 100 Gb/s InfiniBand node).
* **Iteration**: ``t_it = k T_pair + r N / P`` (``r``: the solver's own passes per point,
  from a measured one-rank solve's time per iteration beside its floor).
* **Iterations** of the GUIDE surface grow like ``a + b log2(n)^2`` (fitted to the measured
  counts given with ``--iterations``, the defaults being docs/benchmarks.md's).
* **Memory per rank**: ``91 MB + 40 B x N / P`` (docs/benchmarks.md, "Memory per point":
  a whole double run's peak).

``--check-slurm`` reads ``runs/slurm/petgap.sbatch`` (nodes, ranks per node, memory per CPU,
time limit) and says whether the paper's 65536^2 solve fits in it by the model.

Usage::

    python benchmarks/model.py [--sizes 1024 2048 4096] [--solve-size 2048]
        [--network-gbs 12.5] [--latency-us 2] [--cores-per-node 64] [--check-slurm]
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Bytes per point and fixed bytes per rank of a whole non-adhesive run (docs/benchmarks.md,
#: "Memory per point": 43.4-45.1 measured at 4096^2-16384^2 on one rank, rounded up).
BYTES_PER_POINT, FIXED_BYTES = 46.0, 91e6
#: Iterations of the GUIDE surface at 512^2-16384^2 (docs/benchmarks.md, "Non-adhesive rough
#: contact" and "16384^2 on this machine").
ITERATIONS = {512: 13, 1024: 13, 2048: 14, 4096: 15, 8192: 18, 16384: 22}


def solve_worker(n):
    """Time one pcg-pressure solve of the GUIDE surface on one rank; print JSON."""
    from mpi4py import MPI
    import petgap
    grid = petgap.Grid((n, n), comm=MPI.COMM_WORLD)
    h = petgap.self_affine(grid, 0.8, 32.0, n / 2, rms_slope=0.1, seed=1)
    problem = petgap.ContactProblem(grid, h, petgap.ElasticHalfSpace(grid))
    petgap.solve(problem, petgap.Load(0.002), tolerance=1e-2)      # plans, first touch
    t = time.perf_counter()
    s = petgap.solve(problem, petgap.Load(0.002), tolerance=1e-8)
    dt = time.perf_counter() - t - s.start_time
    print("SOLVE " + json.dumps({"iterations": s.iterations, "time": dt,
                                 "pairs": s.operator_applications}), flush=True)


def fit(sizes, solve_size):
    """Fit c and e from floors on 1 and 2 ranks, and r from one solve."""
    from floor import fft_floor
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    one = {n: fft_floor(n, 1) for n in sizes}
    two = {n: fft_floor(n, 2) for n in sizes}
    work = np.array([n * n * math.log2(n * n) for n in sizes])
    c = float(np.dot(work, [one[n] for n in sizes]) / np.dot(work, work))
    largest = max(sizes)
    efficiency = one[largest] / (2 * two[largest])
    proc = subprocess.run(["mpirun", "-n", "1", sys.executable, __file__, "--solve-worker",
                           str(solve_size)], capture_output=True, text=True, env=env,
                          timeout=3600)
    solve = json.loads(proc.stdout.split("SOLVE ", 1)[1].splitlines()[0])
    per_it = solve["time"] / solve["iterations"]
    pairs = solve["pairs"] / solve["iterations"]
    floor = one[solve_size] if solve_size in one else fft_floor(solve_size, 1)
    r = max(per_it - pairs * floor, 0.0) / solve_size ** 2
    return {"c": c, "efficiency": efficiency, "r": r, "floors_1": one, "floors_2": two,
            "solve": solve, "pairs_per_it": pairs}


def iterations_model(measured):
    """``(a, b)`` of iterations = a + b log2(n)^2, least squares."""
    x = np.array([math.log2(n) ** 2 for n in measured])
    y = np.array(list(measured.values()), dtype=float)
    b, a = np.polyfit(x, y, 1)
    return float(a), float(b)


def pair_time(n, ranks, cores_per_node, model, network_bw, network_latency):
    """Model seconds of one FFT pair of n^2 on ``ranks`` ranks, ``cores_per_node`` per node."""
    N = float(n) * n
    if ranks == 1:
        return model["c"] * N * math.log2(N)
    compute = model["c"] * N * math.log2(N) / (ranks * model["efficiency"])
    local = min(cores_per_node, ranks)
    off_node = 8.0 * N * (ranks - local) / ranks ** 2     # bytes per rank per transpose
    latency = (ranks - 1) * network_latency if ranks > local else 0.0
    return compute + 4 * (off_node * local / network_bw + latency)


def predict(n, nodes, cores_per_node, model, its_ab, network_bw, network_latency):
    ranks = nodes * cores_per_node
    its = its_ab[0] + its_ab[1] * math.log2(n) ** 2
    t_pair = pair_time(n, ranks, cores_per_node, model, network_bw, network_latency)
    t_it = model["pairs_per_it"] * t_pair + model["r"] * n * n / ranks
    memory = FIXED_BYTES + BYTES_PER_POINT * n * n / ranks
    return {"ranks": ranks, "iterations": its, "pair_s": t_pair, "solve_s": its * t_it,
            "memory_per_rank": memory}


def slurm_settings(path):
    text = Path(path).read_text()
    get = lambda key: re.search(rf"^#SBATCH --{key}=(\S+)", text, re.M).group(1)  # noqa: E731
    hours, minutes, seconds = (int(v) for v in get("time").split(":"))
    memory = get("mem-per-cpu")
    scale = {"G": 1e9 * 1.073741824, "M": 1e6 * 1.048576}[memory[-1]]
    return {"nodes": int(get("nodes")), "per_node": int(get("ntasks-per-node")),
            "time_s": hours * 3600 + minutes * 60 + seconds,
            "memory": float(memory[:-1]) * scale}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--solve-worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096])
    parser.add_argument("--solve-size", type=int, default=2048)
    parser.add_argument("--network-gbs", type=float, default=12.5,
                        help="network bandwidth per node, GB/s (default: 100 Gb/s)")
    parser.add_argument("--latency-us", type=float, default=2.0,
                        help="network message latency, microseconds")
    parser.add_argument("--cores-per-node", type=int, default=64)
    parser.add_argument("--iterations", default=json.dumps(ITERATIONS),
                        help="measured iterations by grid side, JSON")
    parser.add_argument("--check-slurm", action="store_true")
    args = parser.parse_args()
    if args.solve_worker:
        return solve_worker(args.solve_worker)
    model = fit(args.sizes, args.solve_size)
    its_ab = iterations_model({int(k): v for k, v in json.loads(args.iterations).items()})
    bw, lat = args.network_gbs * 1e9, args.latency_us * 1e-6
    print("fitted on this machine:")
    floors_1 = ", ".join(f"{n}^2 {1e3 * model['floors_1'][n]:.1f} ms" for n in args.sizes)
    floors_2 = ", ".join(f"{n}^2 {1e3 * model['floors_2'][n]:.1f} ms" for n in args.sizes)
    print(f"  c = {model['c']:.3e} s per point and level (1-rank FFT pairs: {floors_1})")
    print(f"  e = {model['efficiency']:.2f}, two ranks' efficiency at {max(args.sizes)}^2 "
          f"(2-rank pairs: {floors_2})")
    print(f"  solver passes r = {model['r']:.2e} s per point per iteration, "
          f"{model['pairs_per_it']:.2f} FFT pairs per iteration "
          f"({args.solve_size}^2 solve: {model['solve']['iterations']} iterations, "
          f"{model['solve']['time']:.2f} s)")
    print(f"  iterations = {its_ab[0]:.1f} + {its_ab[1]:.3f} log2(n)^2")
    print("\nchecked against this machine (model vs measured floor pair, 1 and 2 ranks):")
    for n in args.sizes:
        print(f"  {n}^2: {1e3 * pair_time(n, 1, 2, model, bw, lat):.1f} vs "
              f"{1e3 * model['floors_1'][n]:.1f} ms, {1e3 * pair_time(n, 2, 2, model, bw, lat):.1f} "
              f"vs {1e3 * model['floors_2'][n]:.1f} ms")
    measured = model["solve"]
    n = args.solve_size
    its = measured["iterations"]
    t = its * (model["pairs_per_it"] * pair_time(n, 1, 2, model, bw, lat) + model["r"] * n * n)
    print(f"  {n}^2 solve on one rank: model {t:.2f} s vs {measured['time']:.2f} s measured "
          f"(its {its} iterations; r is fitted to it)")
    print(f"\n65536^2 (the paper's largest), {args.cores_per_node} ranks per node, network "
          f"{args.network_gbs:g} GB/s and {args.latency_us:g} us per node:")
    print("| nodes | ranks | iterations | FFT pair s | solve h | memory per rank GB |")
    print("|---|---|---|---|---|---|")
    for nodes in (2, 4, 8, 16, 32, 64):
        p = predict(65536, nodes, args.cores_per_node, model, its_ab, bw, lat)
        print(f"| {nodes} | {p['ranks']} | {p['iterations']:.0f} | {p['pair_s']:.2f} | "
              f"{p['solve_s'] / 3600:.2f} | {p['memory_per_rank'] / 1e9:.2f} |")
    if args.check_slurm:
        s = slurm_settings(HERE.parent / "runs" / "slurm" / "petgap.sbatch")
        p = predict(65536, s["nodes"], s["per_node"], model, its_ab, bw, lat)
        fits_time = p["solve_s"] < s["time_s"]
        fits_memory = p["memory_per_rank"] < s["memory"]
        print(f"\nruns/slurm/petgap.sbatch: {s['nodes']} nodes x {s['per_node']} ranks, "
              f"--time {s['time_s'] / 3600:.1f} h, --mem-per-cpu {s['memory'] / 1e9:.2f} GB: "
              f"model {p['solve_s'] / 3600:.2f} h ({'fits' if fits_time else 'DOES NOT FIT'}), "
              f"{p['memory_per_rank'] / 1e9:.2f} GB per rank "
              f"({'fits' if fits_memory else 'DOES NOT FIT'})")


if __name__ == "__main__":
    main()
