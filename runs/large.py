#!/usr/bin/env python3
"""Run a scene as ``petgap run`` does, and report its peak memory per grid point.

For the large scenes whose memory is a measurement of its own (the bytes per point of
docs/benchmarks.md): the run is :func:`petgap.run_scene` (same provenance, same result
file as ``petgap run``), and at the end the peak resident memory summed over the ranks
is printed, per point above the fixed 91 MB of a process.  ``--bytes-per-point``
replaces ``petgap run``'s estimate of the peak (``petgap.app.build``, used to refuse a
grid that will not fit) when the estimate is known to be too high for a scene.

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
    parser.add_argument("--bytes-per-point", type=int, default=None,
                        help="the memory estimate of every solve, bytes per point")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if args.bytes_per_point is not None:
        for name in ("BYTES_PER_POINT_PRESSURE", "BYTES_PER_POINT_PRESSURE_SINGLE",
                     "BYTES_PER_POINT_SOLVE"):
            setattr(build, name, args.bytes_per_point)
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
