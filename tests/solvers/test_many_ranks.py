"""Beyond the two ranks of the suite: 8 and 16 ranks (oversubscribed) against one.

The grid is awkward on purpose: 242 x 180 leaves 16 ranks blocks of 16 real rows and
one of 2, and 12 Fourier rows and one of 1; its coarse start (121 x 90, odd) and the
free boundary's padded cell (484 x 360) split unevenly too, and rows cross between
the map's and the cell's decompositions on every application.  Each run solves, in
one subprocess: the hard wall under load (pressure CG from the coarse start), the
adhesive contact under mean gap (gap CG), and on a free boundary the hard wall under
load, under indentation and under mean gap (the indentation's secant on the depth,
level by level), and an adhesive sphere on a 62 x 60 map under load (on its padded
cell, 124 x 120, in blocks of 8 rows at 16 ranks), and a sticky contact under mean gap on
368 x 240 with the gap solver's coarse system split over the ranks (every coarse grid, for
the test: 46 x 30 nodes in blocks of 3 rows and one of 1 at 16 ranks, its 8-pixel cells
straddling the fine slabs of 23 rows); the fields, iteration counts and scalars must
equal the one-rank solves to round-off (the decompositions only reorder sums).
"""
import json
import sys
import textwrap

import numpy as np
import pytest

SHAPE = (242, 180)

SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    from mpi4py import MPI
    import petgap
    from petgap.solvers import gap_two_level
    from petgap.surfaces.indenters import indenter

    gap_two_level.WHOLE_POINTS = 0   # the coarse system split however small

    out = Path(sys.argv[1])
    comm = MPI.COMM_WORLD
    grid = petgap.Grid(tuple(json.loads(sys.argv[2])), size=(121.0, 90.0), comm=comm,
                       planner="estimate", wisdom=False)
    h = petgap.self_affine(grid, 0.7, 6.0, rms_slope=0.1, seed=5)
    law = petgap.ExponentialAdhesion(2e-4, 1.0)
    sphere_grid = petgap.Grid((62, 60), comm=comm, planner="estimate", wisdom=False)
    sphere = indenter(sphere_grid, "paraboloid", 200.0)
    split_grid = petgap.Grid((368, 240), comm=comm, planner="estimate", wisdom=False)
    rough = petgap.self_affine(split_grid, 0.8, 32.0, 120.0, rms_slope=0.1, seed=7)
    cases = [(petgap.ElasticHalfSpace(grid), h, None, petgap.Load(0.004)),
             (petgap.ElasticHalfSpace(grid), h, law, petgap.MeanGap(0.15)),
             (petgap.FreeHalfSpace(grid), h, None, petgap.Load(0.004)),
             (petgap.FreeHalfSpace(grid), h, None, petgap.Indentation(1.261)),
             (petgap.FreeHalfSpace(grid), h, None, petgap.MeanGap(0.758)),
             (petgap.FreeHalfSpace(sphere_grid), sphere, petgap.ExponentialAdhesion(0.02, 1.0),
              petgap.Load(4.096 / sphere_grid.area)),
             (petgap.ElasticHalfSpace(split_grid), rough, petgap.ExponentialAdhesion(0.3, 4.0),
              petgap.MeanGap(0.5))]
    for k, (body, heights, interaction, control) in enumerate(cases):
        grid = body.grid
        problem = petgap.ContactProblem(grid, heights, body, interaction)
        sol = petgap.solve(problem, control, tolerance=1e-10)
        fields = {"gap": grid.gather(sol.gap), "pressure": grid.gather(sol.pressure)}
        if comm.rank == 0:
            np.savez(out / f"case{k}-{comm.size}.npz", **fields,
                     scalars=json.dumps({key: v if isinstance(v, (bool, str)) else float(v)
                                         for key, v in sol.scalars().items()}))
""")


@pytest.mark.parametrize("ranks", [8, 16])
def test_many_ranks_equal_one(comm, mpi_tmp_path, run_cli, ranks):
    if comm.rank == 0:
        (mpi_tmp_path / "solve.py").write_text(SCRIPT)
    comm.Barrier()
    shape = json.dumps(list(SHAPE))
    one = run_cli([sys.executable, mpi_tmp_path / "solve.py", mpi_tmp_path, shape], ranks=1,
                  timeout=300)
    many = run_cli([sys.executable, mpi_tmp_path / "solve.py", mpi_tmp_path, shape],
                   ranks=ranks, timeout=600)
    assert one.returncode == 0, one.stderr[-3000:]
    assert many.returncode == 0, many.stderr[-3000:]
    for k in range(7):
        one_case = np.load(mpi_tmp_path / f"case{k}-1.npz")
        many_case = np.load(mpi_tmp_path / f"case{k}-{ranks}.npz")
        a, b = (json.loads(str(case["scalars"])) for case in (one_case, many_case))
        assert a["converged"] and b["converged"], (k, a["reason"], b["reason"])
        assert a["iterations"] == b["iterations"], k
        assert a["contact_fraction"] == b["contact_fraction"], k
        for key in ("mean_gap", "mean_pressure", "elastic_energy"):
            assert b[key] == pytest.approx(a[key], rel=1e-11, abs=1e-14), (k, key)
        for field in ("gap", "pressure"):
            x, y = one_case[field], many_case[field]
            assert np.abs(x - y).max() <= 1e-11 * np.abs(x).max(), (k, field)
