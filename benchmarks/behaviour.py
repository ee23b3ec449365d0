#!/usr/bin/env python3
"""Behaviour record: iterations and fields of a fixed set of solves, for a before/after table.

Not a test: it solves the benchmark surface (H = 0.8, lambda_min = 32 a0,
lambda_max = L / 2, rms slope 0.1, seed 7; E* = 1; unit-free KKT tolerance 1e-8)
under the cases of :data:`CASES` through the public API only (``import petgap``),
prints one markdown row per case and saves each solution's global gap and pressure
to ``<out>/<case>.npz``.  Run it on two versions of petgap (each in its own
environment) and compare the two directories with ``--compare``: a restructuring
that keeps the behaviour shows the same iterations and differences at round-off.

Grids plan their transforms with FFTW's ``estimate`` planner and no wisdom file, so
that the plans (and so the round-off) are the same on every run; ``measure``
planning may pick another algorithm from one run to the next.  Every case builds
its own grid and problem, so that nothing a solver keeps on them carries over from
one case to the next and a case gives the same result alone (``--cases``) or in
the whole set.  The controls that follow from another solution (the mean gap
of a load solution, an indentation depth) are fixed numbers, :data:`DERIVED`, so
that both versions solve exactly the same problems; ``--derive`` recomputes them.

The fingerprint columns are the sums of ``g``, ``g^2``, ``p`` and ``p^2`` over the
global fields (double sums of the gathered arrays), printed with ``%.17g``.
Single-precision cases run to the single-precision tolerance floor (3e-6, that of
``petgap study``) instead of 1e-8, which 32 bits do not resolve.  Compare runs on the
same number of ranks: the sums' order follows the slabs, and a TAO built-in's
iteration count follows the round-off.

Usage (one rank or ``mpirun -n P``)::

    python benchmarks/behaviour.py --out DIR [--cases NAME ...] [--quick] > table.md
    python benchmarks/behaviour.py --compare BEFORE_DIR AFTER_DIR
    python benchmarks/behaviour.py --derive
"""
import argparse
import json
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HURST, LAMBDA_MIN, RMS_SLOPE, SEED = 0.8, 32.0, 0.1, 7
LOAD, TOLERANCE = 0.002, 1e-8
#: The tolerance of a single-precision solve: the floor below which 32 bits stall.
SINGLE_TOLERANCE = 3e-6
WORK, RANGE = 0.05, 4.0

#: Controls taken from other solutions, to 17 digits (``--derive`` prints them again):
#: the mean gap of the hard-wall load solutions at 256^2, 512^2 and 1024^2 (double,
#: one rank), and the indentation depth of the free map (the rms height of the 256^2
#: map, rounded).
DERIVED = {
    "mean_gap_256": 2.1695606167038974,
    "mean_gap_512": 3.1551304584369677,
    "mean_gap_1024": 5.1503434440460127,
    "free_depth_256": 1.35,
}


@dataclass(frozen=True)
class Case:
    """One solve: the surface's side, the body, the interaction, the control and the solver."""
    name: str
    n: int
    control: tuple                 # (kind, value or key of DERIVED)
    solver: str = "pcg"
    precision: str = "double"
    options: dict = field(default_factory=dict)
    adhesive: bool = False
    free: bool = False
    max_iterations: int = 10000


def _cases():
    load = ("load", LOAD)
    cases = [Case(f"load-{n}", n, load) for n in (256, 512, 1024, 2048)]
    cases += [Case(f"load-{n}-{p}", n, load, precision=p)
              for p in ("single", "mixed") for n in (512, 1024)]
    cases += [Case(f"meangap-{n}", n, ("mean-gap", "mean_gap_1024")) for n in (512, 1024)]
    cases += [Case(f"meangap-pressure-{n}", n, ("mean-gap", "mean_gap_1024"),
                   solver="pcg-pressure") for n in (512, 1024)]
    cases += [Case(f"load-512-{label}", 512, load, options={key: value})
              for label, key, value in (("nocoarse", "petgap_coarse_start", "0"),
                                        ("noedge", "petgap_edge_correction", "0"),
                                        ("noblock", "petgap_interaction_block", "0"),
                                        ("searchsingle", "petgap_search_precision", "single"))]
    # on this surface the patch interaction changes nothing at 512^2; it does at 1024^2
    cases += [Case("load-1024-noblock", 1024, load, options={"petgap_interaction_block": "0"})]
    cases += [Case("bncg-load-256", 256, load, solver="bncg", max_iterations=20000)]
    cases += [Case(f"adhesive-meangap-{n}", n, ("mean-gap", f"mean_gap_{n}"), adhesive=True)
              for n in (256, 512)]
    cases += [Case("adhesive-load-256", 256, load, adhesive=True)]
    cases += [Case("free-load-256", 256, load, free=True),
              Case("free-indentation-256", 256, ("indentation", "free_depth_256"), free=True),
              Case("free-adhesive-load-128", 128, load, adhesive=True, free=True)]
    return {case.name: case for case in cases}


CASES = _cases()

COLUMNS = ("case", "N", "solver", "precision", "control", "iterations",
           "operator_applications", "converged / reason", "contact fraction", "mean gap",
           "mean pressure", "sum g", "sum g^2", "sum p", "sum p^2", "wall s")


def build(case, comm):
    """The grid and problem of ``case``, made afresh."""
    import petgap
    n = case.n
    double = petgap.Grid((n, n), comm=comm, planner="estimate", wisdom=False)
    heights = petgap.self_affine(double, HURST, LAMBDA_MIN, n / 2, rms_slope=RMS_SLOPE,
                                 seed=SEED)
    grid = double
    if case.precision == "single":    # the same surface, rounded once
        grid = petgap.Grid((n, n), comm=comm, planner="estimate", wisdom=False,
                           precision="single")
        heights = heights.astype(np.float32)
    body = petgap.FreeHalfSpace(grid, 1.0) if case.free else petgap.ElasticHalfSpace(grid, 1.0)
    interaction = petgap.ExponentialAdhesion(work=WORK, range=RANGE) if case.adhesive else None
    return grid, petgap.ContactProblem(grid, heights, body, interaction)


def control_of(case, derived):
    import petgap
    kind, value = case.control
    if isinstance(value, str):
        value = derived[value]
        if value is None:
            raise SystemExit(f"case {case.name}: DERIVED[{case.control[1]!r}] is not set; "
                             f"run --derive and fill it in")
    make = {"load": petgap.Load, "mean-gap": petgap.MeanGap, "indentation": petgap.Indentation}
    return make[kind](float(value))


def run_case(case, comm, derived=DERIVED):
    """Solve ``case``; return (grid, problem, solution, wall seconds)."""
    import petgap
    grid, problem = build(case, comm)
    control = control_of(case, derived)
    tolerance = SINGLE_TOLERANCE if case.precision == "single" else TOLERANCE
    kwargs = {}
    if case.precision != "double":
        kwargs["precision"] = case.precision
    if case.options:
        kwargs["options"] = dict(case.options)
    comm.Barrier()
    start = time.perf_counter()
    solution = petgap.solve(problem, control, solver=case.solver, tolerance=tolerance,
                            max_iterations=case.max_iterations, **kwargs)
    comm.Barrier()
    return grid, problem, solution, time.perf_counter() - start


def fingerprint(gap, pressure):
    g, p = (np.asarray(a, dtype=np.float64) for a in (gap, pressure))
    return float(g.sum()), float((g * g).sum()), float(p.sum()), float((p * p).sum())


def _g(x):
    return "%.17g" % x


def record(case, comm, out):
    """Solve ``case``, save its fields (rank 0) and return its markdown row (rank 0)."""
    grid, problem, s, seconds = run_case(case, comm)
    gap, pressure = grid.gather(s.gap), grid.gather(s.pressure)
    if comm.rank != 0:
        return None
    sums = fingerprint(gap, pressure)
    scalars = {"iterations": int(s.iterations),
               "operator_applications": float(s.operator_applications),
               "converged": bool(s.converged), "reason": str(s.reason),
               "contact_fraction": float(s.contact_fraction), "mean_gap": float(s.mean_gap),
               "mean_pressure": float(s.mean_pressure), "control": s.control.kind,
               "control_value": float(s.control.value), "solver": str(s.solver),
               "precision": str(s.precision), "start": str(s.start), "wall_time": seconds,
               "ranks": comm.size, "gap_scale": float(problem.gap_scale),
               "pressure_scale": float(problem.pressure_scale), "fingerprint": sums}
    np.savez(out / f"{case.name}.npz", gap=gap, pressure=pressure,
             scalars=json.dumps(scalars))
    verdict = f"{'yes' if s.converged else 'NO'} {s.reason}"
    row = (case.name, case.n, s.solver, s.precision, f"{s.control.kind} {_g(s.control.value)}",
           s.iterations, f"{s.operator_applications:g}", verdict, _g(s.contact_fraction),
           _g(s.mean_gap), _g(s.mean_pressure), *map(_g, sums), f"{seconds:.2f}")
    return "| " + " | ".join(map(str, row)) + " |"


def provenance():
    """Where the imported petgap lives and its commit (for the table's header)."""
    import petgap
    where = Path(petgap.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(where), "describe", "--always", "--dirty"],
                                capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return where, commit


def table(args):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    names = args.cases or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise SystemExit(f"unknown case(s) {', '.join(unknown)}; the cases are: "
                         f"{', '.join(CASES)}")
    chosen = [CASES[n] for n in names if not (args.quick and CASES[n].n > 512)]
    out = Path(args.out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        where, commit = provenance()
        print(f"petgap at {where} ({commit}), {comm.size} rank(s); surface H = {HURST}, "
              f"lambda_min = {LAMBDA_MIN:g}, lambda_max = N/2, rms slope {RMS_SLOPE}, seed "
              f"{SEED}; E* = 1; KKT {TOLERANCE:g} (single {SINGLE_TOLERANCE:g}); adhesion "
              f"w = {WORK}, rho = {RANGE:g}\n")
        print("| " + " | ".join(COLUMNS) + " |")
        print("|" + "---|" * len(COLUMNS), flush=True)
    begin = time.perf_counter()
    for case in chosen:
        row = record(case, comm, out)
        if row is not None:
            print(row, flush=True)
    if comm.rank == 0:
        print(f"\n{len(chosen)} cases in {time.perf_counter() - begin:.1f} s", flush=True)


def derive(args):
    """Print :data:`DERIVED` as this petgap computes it."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    derived = {}
    for n in (256, 512, 1024):
        _, _, s, _ = run_case(CASES[f"load-{n}"], comm)
        derived[f"mean_gap_{n}"] = float(s.mean_gap)
    _, problem = build(CASES["free-load-256"], comm)
    derived["free_depth_256"] = float(np.round(problem.gap_scale, 2))
    if comm.rank == 0:
        for key, value in derived.items():
            print(f"    \"{key}\": {value!r},")


def _load(directory, name):
    with np.load(Path(directory) / f"{name}.npz") as data:
        return data["gap"], data["pressure"], json.loads(str(data["scalars"]))


def compare(before_dir, after_dir):
    """Per case: before/after iterations and the largest field differences in residual units.

    The differences are over the before run's scales (``h0`` and ``h0' E*`` of its
    problem), on the global fields in double.  Returns 0 when every case of BEFORE is
    in AFTER with the same iterations, operator applications and verdict, 1 otherwise.
    """
    before_dir, after_dir = Path(before_dir), Path(after_dir)
    stems = {p.stem for p in before_dir.glob("*.npz")}
    names = [name for name in CASES if name in stems] + sorted(stems - set(CASES))
    columns = ("case", "iterations before", "after", "applications before", "after",
               "verdict before", "after", "max abs dg / h0", "max abs dp / h0'E*",
               "contact fraction before", "after")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    missing, changed, restarted, largest = [], [], [], [0.0, 0.0]
    for name in names:
        if not (after_dir / f"{name}.npz").exists():
            missing.append(name)
            continue
        g0, p0, s0 = _load(before_dir, name)
        g1, p1, s1 = _load(after_dir, name)
        if g0.shape != g1.shape:
            dg = dp = float("nan")
        else:
            dg = float(np.max(np.abs(g1.astype(np.float64) - g0))) / s0["gap_scale"]
            dp = float(np.max(np.abs(p1.astype(np.float64) - p0))) / s0["pressure_scale"]
        largest = [max(largest[0], dg), max(largest[1], dp)]
        verdicts = [("yes " if s["converged"] else "NO ") + s["reason"] for s in (s0, s1)]
        if (s0["iterations"], s0["operator_applications"], verdicts[0]) != \
                (s1["iterations"], s1["operator_applications"], verdicts[1]):
            changed.append(name)
        if s0["start"] != s1["start"]:
            restarted.append(name)
        print("| " + " | ".join(map(str, (
            name, s0["iterations"], s1["iterations"], f"{s0['operator_applications']:g}",
            f"{s1['operator_applications']:g}", *verdicts, f"{dg:.3g}", f"{dp:.3g}",
            _g(s0["contact_fraction"]), _g(s1["contact_fraction"])))) + " |")
    compared = len(names) - len(missing)
    print(f"\n{compared} cases compared; largest abs dg / h0 {largest[0]:.3g}, abs dp / h0'E* "
          f"{largest[1]:.3g}")
    print("iterations, applications and verdicts: " + (
        f"different in {', '.join(changed)}" if changed else "the same in every compared case"))
    if restarted:
        print(f"the start's description differs in: {', '.join(restarted)}")
    if missing:
        print(f"not in {after_dir}: {', '.join(missing)}")
    return 1 if changed or missing else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", help="directory for <case>.npz (made if missing)")
    parser.add_argument("--cases", nargs="+", metavar="NAME",
                        help=f"a subset of the cases: {', '.join(CASES)}")
    parser.add_argument("--quick", action="store_true", help="only the cases with N <= 512")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE_DIR", "AFTER_DIR"),
                        help="compare two --out directories (no MPI, no petgap needed)")
    parser.add_argument("--derive", action="store_true",
                        help="print DERIVED (the controls taken from other solutions)")
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    if args.derive:
        return derive(args)
    if not args.out:
        parser.error("--out DIR is required (or --compare / --derive)")
    return table(args)


if __name__ == "__main__":
    sys.exit(main())
