#!/usr/bin/env python3
"""Run a scene too large for ``petgap run``'s memory estimate, and record its peak memory.

``petgap run`` refuses a grid whose estimated peak (``BYTES_PER_POINT_SOLVE`` = 90 bytes per
point, the conservative figure of docs/benchmarks.md) exceeds the memory available;
16384^2 (2.7e8 points) needs 24 GB by that figure, beside 23 GB here.  A one-rank run of
2048^2 measured 59 bytes per point above the process's fixed 91 MB (sampled RSS), so this
driver runs the scene exactly as ``petgap run`` does (:func:`petgap.run_scene`, same
provenance, same result file) with the estimate set to ``--bytes-per-point`` (default 64),
and prints the peak RSS per point at the end.

Usage (one rank; under mpirun for more)::

    python runs/large.py runs/fig2_H08_lmin32_r256.toml out/fig2/fig2_H08_lmin32_r256.h5
"""
import argparse
import resource
import sys

from mpi4py import MPI

import petgap
from petgap.app import build


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("output")
    parser.add_argument("--bytes-per-point", type=int, default=64)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    build.BYTES_PER_POINT_SOLVE = args.bytes_per_point
    scene = petgap.load_scene(args.scene, comm)
    petgap.run_scene(scene, comm, args.output)
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    if comm.rank == 0:
        points = scene.grid.nx * scene.grid.ny
        print(f"peak RSS {peak / 2**30:.2f} GiB over {comm.size} rank(s): "
              f"{(peak - 91e6 * comm.size) / points:.1f} bytes per point above 91 MB per rank",
              file=sys.stderr)


if __name__ == "__main__":
    main()
