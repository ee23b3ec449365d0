"""Peak memory per grid point of generating a self-affine surface.

Measures, on every rank, the peak resident set size (``getrusage`` maxrss) after
creating the :class:`~petgap.parallel.grid.Grid` and after :func:`petgap.surfaces.self_affine.self_affine`,
each minus the peak right after the imports (interpreter, NumPy, MPI, FFTW).
Bytes per point are over the points a rank owns, ``N^2 / P``; the ideal is the
grid's two FFT buffers (a padded real slab and the half-plane Fourier slab,
8 + 8 bytes per point) plus the returned float64 slab (8 bytes per point).

Usage::

    mpirun -n P python benchmarks/surface_memory.py [--n 4096] [--planner estimate]

Prints one table on rank 0.  The surface is H = 0.8, lambda_min = 32 pixels,
lambda_max = n / 2 (the surface of docs/benchmarks.md).
"""
import argparse
import resource
import time

from mpi4py import MPI

from petgap.parallel.grid import Grid
from petgap.surfaces.self_affine import self_affine


def peak_bytes():
    """Peak resident set size of this process so far (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=4096, help="grid is n x n (default 4096)")
    parser.add_argument("--planner", choices=["estimate", "measure", "patient", "exhaustive"],
                        default="measure", help="FFTW planner effort (default measure)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    baseline = peak_bytes()

    grid = Grid((args.n, args.n), comm=comm, planner=args.planner)
    after_grid = peak_bytes()
    comm.Barrier()
    start = time.perf_counter()
    heights = self_affine(grid, 0.8, 32.0, args.n / 2, rms_slope=0.1, seed=1)
    comm.Barrier()
    elapsed = time.perf_counter() - start
    after_surface = peak_bytes()
    points = heights.size
    del heights  # a warm second call: buffers already paged in (not part of the peak above)
    comm.Barrier()
    start = time.perf_counter()
    self_affine(grid, 0.8, 32.0, args.n / 2, rms_slope=0.1, seed=1)
    comm.Barrier()
    warm = time.perf_counter() - start

    rows = comm.gather((comm.rank, points, baseline, after_grid - baseline,
                        after_surface - baseline), root=0)
    if comm.rank == 0:
        mib = 2.0 ** 20
        print(f"self_affine on {args.n} x {args.n}, {comm.size} rank(s), planner {args.planner}: "
              f"{elapsed:.2f} s first call (pages first touched), {warm:.2f} s warm")
        print("rank  points      baseline MiB  grid MiB  grid B/pt  grid+surface MiB  B/pt")
        for rank, pts, base, grid_bytes, total in rows:
            print(f"{rank:4d}  {pts:10d}  {base / mib:12.1f}  {grid_bytes / mib:8.1f}  "
                  f"{grid_bytes / pts:9.2f}  {total / mib:16.1f}  {total / pts:5.2f}")
        total = sum(r[4] for r in rows)
        print(f"all   {args.n ** 2:10d}  {sum(r[2] for r in rows) / mib:12.1f}  "
              f"{sum(r[3] for r in rows) / mib:8.1f}  "
              f"{sum(r[3] for r in rows) / args.n ** 2:9.2f}  {total / mib:16.1f}  "
              f"{total / args.n ** 2:5.2f}")


if __name__ == "__main__":
    main()
