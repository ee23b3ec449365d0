"""How finely single precision resolves the gap: the 32-bit rounding of the displacement.

Not a test: it prints the markdown table behind ``SINGLE_TOLERANCE_FLOOR``
(:mod:`petgap.io.scene`, docs/accuracy.md "Precision").  For each size the
benchmark surface of docs/benchmarks.md (H = 0.8, rms slope 0.1,
lambda_min = 32 a0, lambda_max = L / 2, seed 1, P0 = 0.002 E*) is solved in
double to 1e-8; its pressure, rounded to 32 bits, is then transformed to the
displacement ``u = K^-1 p`` twice -- by the single-precision half-space and by
the double one -- and the difference, the rounding a single-precision solve
carries into its gap ``u - h + d`` at every fresh transform, is reported over
``h0`` (the unit of the KKT residual): its rms, its maximum, and its maximum on
the contact set, beside one unit in the last place of ``max|u|`` in 32 bits.

Usage::

    mpirun -n R python benchmarks/single_rounding.py --sizes 1024 2048 4096
"""
import argparse

import numpy as np
from mpi4py import MPI

from petgap.app.build import build
from petgap.io.scene import Scene
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.grid import Grid


def rounding(n, comm):
    """One row: the rounding of ``u`` in single against double, at the double solution."""
    scene = Scene.from_dict({
        "grid": {"nx": n},
        "surface": {"hurst": 0.8, "lambda_min": 32.0, "lambda_max": n / 2, "rms_slope": 0.1,
                    "seed": 1},
        "material": {"contact_modulus": 1.0}, "interaction": {"kind": "hard-wall"},
        "control": {"kind": "load", "values": [0.002]},
        "solver": {"tao_type": "pcg-pressure", "tolerance": 1e-8}}, comm)
    model = build(scene, comm)
    (solution,) = model.sweep()
    h0 = model.problem.rms_height
    p32 = solution.pressure.astype(np.float32)
    del solution
    u64 = model.half_space.displacement(p32.astype(np.float64))
    grid = model.grid
    single = Grid(grid.shape, size=(grid.Lx, grid.Ly), comm=comm, precision="single")
    u32 = ElasticHalfSpace(single, model.half_space.contact_modulus).displacement(p32)
    error = np.abs(u32 - u64)
    contact = p32 > 0
    local = np.array([error.max(), error[contact].max(initial=0.0), np.abs(u64).max()])
    comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MAX)
    square = comm.allreduce(float(np.sum(error ** 2)))
    largest, on_contact, u_max = local
    return {"n": n, "u_max": u_max / h0, "rms": np.sqrt(square / grid.npoints) / h0,
            "max": largest / h0, "max_contact": on_contact / h0,
            "ulp": float(np.spacing(np.float32(u_max))) / h0}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096])
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    rows = [rounding(n, comm) for n in args.sizes]
    if comm.rank == 0:
        print("| N | ranks | max\\|u\\| / h0 | ulp(max\\|u\\|) / h0 | rms rounding / h0 "
              "| max rounding / h0 | max on the contact set / h0 |")
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['n']}^2 | {comm.size} | {r['u_max']:.2f} | {r['ulp']:.1e} "
                  f"| {r['rms']:.1e} | {r['max']:.1e} | {r['max_contact']:.1e} |")


if __name__ == "__main__":
    main()
