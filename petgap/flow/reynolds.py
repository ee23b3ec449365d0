"""The steady Reynolds equation on the gap field, in finite volumes on the pixels.

Steady incompressible flow of a Newtonian fluid of viscosity ``mu`` through a thin gap
``g(x, y)`` obeys the Reynolds equation ``div(g^3 grad p) = 0`` with the volume flux per
unit width ``q = -(g^3 / (12 mu)) grad p``.  It is solved here on the pixels of the contact
solution, each pixel one finite volume with the gap constant across it.

Face conductance
----------------
The flux through the face between two pixels of gaps ``g1`` and ``g2`` is that through two
half-pixels in series.  Each half carries ``g^3 / (12 mu)`` times the pressure drop across
it over ``dx / 2``, so the face conducts ``(2 g1^3 g2^3 / (g1^3 + g2^3)) / (12 mu dx)``:
the harmonic mean of ``g^3`` is the exact series conductance of piecewise constant
cells.  (The arithmetic mean of ``g^3`` would let fluid through a face next to a closed
pixel; the cube of the mean gap over- or under-estimates a face between very different
gaps.)  A closed pixel (gap at or below the zero-gap tolerance: contact, or adhesion at
zero gap) has ``g^3 = 0``, so each of its faces conducts nothing.  ReynoldsFlow 0.1.3
uses the same harmonic mean.  Face conductances carry the pixel's aspect,
``dy / dx`` across an x face and ``dx / dy`` across a y face.

Boundaries
----------
* Periodic cell (``periodic=True``): the pressure is ``p = dp (phi - x / L)`` along
  the flow direction with ``phi`` periodic in x and y; the imposed drop ``dp`` across
  the period enters each face along the flow as a source ``dp / n`` (``n`` pixels along
  it).  ``phi`` is fixed to 0 at one pixel of each spanning cluster (its constant is
  free).
* Free map (``periodic=False``): the inlet edge (row 0, or column 0 for flow along y) is
  held at ``p = dp``, the outlet edge (the last row or column) at ``p = 0``, on the map's
  outer faces, half a pixel from the centres of the edge pixels, so that the drop is
  across the map's full length ``L = n dx``; the two other edges are sealed.

Only the clusters that span the map (:mod:`petgap.analysis.percolation`) take part; other
open pixels are sealed pockets or dead ends without flow, and would leave the matrix
singular.  They, the closed pixels and the pinned ones are eliminated: the unknowns are
the open pixels of the spanning clusters alone (:class:`Unknowns`), numbered in the order
of the global pixel index, so each rank owns the contiguous range of its own slab's and
the vectors are the slab's unknowns in place, with no scatter.  (A DMDA would need its own
copy of the slab layout and would keep every closed pixel as an unknown; identity rows for
them would cost memory in the matrix and in every level of the multigrid hierarchy.)
The matrix is assembled straight into PETSc's MPIAIJ format, preallocated exactly and
filled a block of rows at a time (:func:`assemble`), in PETSc's index type (32 bits in
Debian's build).

The linear system is scaled: the unknown is the pressure over ``dp``, the conductances
``g^3`` over the largest ``g^3`` of the map, so the matrix has entries of order one
whatever the units.  It is symmetric positive definite, solved by PETSc's conjugate
gradients with algebraic multigrid (:data:`PC_TYPE`); the options prefix ``flow_`` reaches the solver
(``-flow_ksp_type``, ``-flow_pc_type``, ``-flow_ksp_rtol``, ``-flow_ksp_monitor`` ...).
"""
import time
from contextlib import contextmanager

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from petgap.analysis._slabs import fetch_rows, global_shape, local_rows, pixel

#: PETSc options prefix of the flow solve.
OPTIONS_PREFIX = "flow_"
#: Relative residual at which the flow solve stops (``-flow_ksp_rtol`` overrides it).
RTOL = 1e-10
#: The default preconditioner (``-flow_pc_type`` overrides it): hypre's BoomerAMG where
#: PETSc has hypre (Debian's does), which takes fewer iterations and less time than GAMG
#: on the gap fields of rough contacts (docs/benchmarks.md), else PETSc's own GAMG.
PC_TYPE = "hypre" if PETSc.Sys.hasExternalPackage("hypre") else "gamg"
#: BoomerAMG's settings unless given (``-flow_pc_hypre_boomeramg_*``): HMIS coarsening,
#: aggressive on the first level, with extended+i interpolation of at most 4 entries a
#: row, which keep the hierarchy small; docs/design.md has the trade against hypre's own
#: defaults (Falgout coarsening, classical interpolation).
HYPRE_OPTIONS = {"pc_hypre_boomeramg_coarsen_type": "HMIS",
                 "pc_hypre_boomeramg_interp_type": "ext+i",
                 "pc_hypre_boomeramg_P_max": "4",
                 "pc_hypre_boomeramg_agg_nl": "1"}


def harmonic_mean(a, b, out=None):
    """``2 a b / (a + b)``, and 0 where both are 0 (a face between closed pixels)."""
    total = a + b
    if out is None:
        out = np.empty(np.broadcast(a, b).shape)
    out[...] = 0.0
    return np.divide(2.0 * a * b, total, out=out, where=total > 0)


class Faces:
    """The scaled face conductances of this rank's pixels.

    Stored as two arrays of faces, ``x_faces`` (``nloc + 1`` rows: the face above each
    row and below the last) and ``y_faces`` (``ny + 1`` columns: the face left of each
    column and right of the last), so that ``up[i, j]`` (between pixel ``(i, j)`` and
    ``(i - 1, j)``), ``down`` (to ``(i + 1, j)``), ``left`` (to ``(i, j - 1)``) and
    ``right`` (to ``(i, j + 1)``) are views, not copies (global indices, periodic where
    the cell is; pixel aspect included).  On a free map the faces on the map's edges
    across the flow lead to the reservoirs (inlet pressure 1 above or left, outlet 0
    below or right: half a pixel away, so twice the pixel's conductance), and those
    along it are sealed.
    """

    def __init__(self, grid, k, axis, periodic):
        nx, ny = global_shape(grid)
        start, stop = local_rows(grid)
        dx, dy = pixel(grid)
        halo = fetch_rows(grid, [k], [start - 1, stop])[0]
        first, last = start == 0, stop == nx
        self.x_faces = x_faces = np.empty((k.shape[0] + 1, ny))
        harmonic_mean(np.vstack([halo[:1], k]), np.vstack([k, halo[1:]]), out=x_faces)
        x_faces *= dy / dx
        del halo
        self.y_faces = y_faces = np.empty((k.shape[0], ny + 1))
        harmonic_mean(k[:, np.r_[ny - 1, 0:ny]], k[:, np.r_[0:ny, 0]], out=y_faces)
        y_faces *= dx / dy
        #: The faces to the inlet and outlet reservoirs: their direction and pixels.
        self.inlet_side, self.outlet_side = ("up", "down") if axis == 0 else ("left", "right")
        self.inlet = np.zeros(k.shape, dtype=bool)
        self.outlet = np.zeros(k.shape, dtype=bool)
        if periodic:
            return
        if axis == 0:
            self.inlet[0], self.outlet[-1] = first, last
            y_faces[:, 0] = y_faces[:, -1] = 0.0
            if first:
                x_faces[0] = 2.0 * k[0] * (dy / dx)
            if last:
                x_faces[-1] = 2.0 * k[-1] * (dy / dx)
        else:
            self.inlet[:, 0] = self.outlet[:, -1] = True
            y_faces[:, 0], y_faces[:, -1] = 2.0 * k[:, 0] * (dx / dy), 2.0 * k[:, -1] * (dx / dy)
            if first:
                x_faces[0] = 0.0
            if last:
                x_faces[-1] = 0.0

    up = property(lambda self: self.x_faces[:-1])
    down = property(lambda self: self.x_faces[1:])
    left = property(lambda self: self.y_faces[:, :-1])
    right = property(lambda self: self.y_faces[:, 1:])


#: Pixels of the slab assembled, or whose fluxes are summed, at a time: bounds the
#: temporaries of the assembly (about 100 bytes per pixel of a block) and of the balance
#: check beside the multigrid hierarchy whatever the grid.
BLOCK_PIXELS = 1 << 16


class Unknowns:
    """The numbering of the pixels that are unknowns of the reduced system.

    Only the open pixels of the spanning clusters, less the pinned ones, are unknowns: a
    closed pixel, a sealed pocket or a dead end carries no flow, and an identity row for
    each would only add to the matrix and the multigrid hierarchy.  They are numbered in
    the order of their global pixel index ``i * ny + j``, so each rank owns a contiguous
    range (its slab's) and the numbering does not depend on the number of ranks.
    ``index`` is the slab of their numbers (``-1`` for the others), in PETSc's index
    type; ``above`` and ``below`` are its halo rows (``-1`` beyond a free map's edge).
    """

    def __init__(self, grid, active, periodic):
        comm = grid.comm
        nx = global_shape(grid)[0]
        start, stop = local_rows(grid)
        self.count = int(np.count_nonzero(active))
        self.start = int(comm.exscan(self.count, op=MPI.SUM) or 0) if comm.size > 1 else 0
        self.total = int(comm.allreduce(self.count, op=MPI.SUM))
        self.index = np.full(active.shape, -1, dtype=PETSc.IntType)
        self.index[active] = np.arange(self.start, self.start + self.count, dtype=PETSc.IntType)
        halo = fetch_rows(grid, [self.index], [start - 1, stop])[0].astype(PETSc.IntType)
        if not periodic:
            halo[0] = -1 if start == 0 else halo[0]
            halo[1] = -1 if stop == nx else halo[1]
        self.above, self.below = halo[0], halo[1]


def assemble(grid, faces, unknowns, axis, periodic):
    """The matrix and right-hand side of the scaled system over ``unknowns`` (collective).

    Straight into PETSc's MPIAIJ matrix on each rank's range of unknowns: the exact
    preallocation first, then the entries a block of rows at a time
    (``MatSetValues`` through ``setValuesIJV``), so no full-size copy of the matrix is
    ever held outside PETSc.  A pinned neighbour's unknown is 0: it adds its face to the
    diagonal and no column, as do the reservoirs' faces (the inlet's value 1 goes to the
    right-hand side).
    """
    n, first = unknowns.count, unknowns.start
    counts = [np.empty(n, dtype=PETSc.IntType) for _ in range(2)]
    for rows, cols, vals, valid in _blocks(faces, unknowns, periodic):
        mine = valid & (cols >= first) & (cols < first + n)
        counts[0][rows] = np.count_nonzero(mine, axis=1)
        counts[1][rows] = np.count_nonzero(valid & ~mine, axis=1)
    matrix = PETSc.Mat().createAIJ(size=((n, unknowns.total), (n, unknowns.total)),
                                   nnz=tuple(counts), comm=grid.comm)
    del counts
    matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    for rows, cols, vals, valid in _blocks(faces, unknowns, periodic):
        indptr = np.zeros(len(rows) + 1, dtype=PETSc.IntType)
        np.cumsum(np.count_nonzero(valid, axis=1), out=indptr[1:])
        matrix.setValuesIJV(indptr, cols[valid], vals[valid], addv=PETSc.InsertMode.ADD_VALUES,
                            rowmap=(rows + first).astype(PETSc.IntType))
    matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    matrix.setOption(PETSc.Mat.Option.SPD, True)
    matrix.assemble()
    active = unknowns.index >= 0
    if periodic:      # the drop across the period: p = dp (phi - x / L)
        ahead, behind = (faces.down, faces.up) if axis == 0 else (faces.right, faces.left)
        rhs = (behind[active] - ahead[active]) / global_shape(grid)[axis]
    else:             # the inlet reservoir at 1 behind its faces
        rhs = np.zeros(n)
        inlet = faces.inlet[active]
        rhs[inlet] = getattr(faces, faces.inlet_side)[active][inlet]
    return matrix, rhs


def _blocks(faces, unknowns, periodic):
    """Blocks of rows of the matrix: ``(rows, cols, vals, valid)``, ``rows`` the local
    numbers of the block's unknowns, ``cols`` and ``vals`` ``(len(rows), 5)`` (diagonal,
    up, down, left, right), ``valid`` where the entry exists (a neighbour that is an
    unknown behind an open face; the diagonal always).  Entries are added, so the two
    faces of a period two pixels long add up in one column."""
    index = unknowns.index
    nloc, ny = index.shape
    step = max(1, BLOCK_PIXELS // max(ny, 1))
    for a in range(0, nloc, step):
        b = min(a + step, nloc)
        here = index[a:b]
        active = here >= 0
        up = index[a - 1:b - 1] if a > 0 else np.vstack([unknowns.above[None, :], index[:b - 1]])
        down = index[a + 1:b + 1] if b < nloc else np.vstack([index[a + 1:b], unknowns.below[None, :]])
        left, right = np.roll(here, 1, axis=1), np.roll(here, -1, axis=1)
        if not periodic:
            left[:, 0] = right[:, -1] = -1
        t = [faces.up[a:b], faces.down[a:b], faces.left[a:b], faces.right[a:b]]
        cols = np.stack([here, up, down, left, right], axis=-1)[active]
        vals = np.stack([sum(t)] + [-f for f in t], axis=-1)[active]
        valid = (cols >= 0) & (vals != 0)
        valid[:, 0] = True
        yield here[active] - unknowns.start, cols, vals, valid


class KrylovSolve:
    """``matrix u = rhs`` by CG and algebraic multigrid, resumable at a tighter tolerance.

    The options database is read (prefix ``flow_``) after the defaults are set, so
    ``-flow_ksp_type``, ``-flow_pc_type``, ``-flow_ksp_rtol``, the BoomerAMG options of
    :data:`HYPRE_OPTIONS` and the rest override them.  ``monitor(iteration,
    residual_norm)`` is called at every iteration.  The residual is the unpreconditioned
    one: it is the mass imbalance of the pixels.  The solver owns ``matrix`` and destroys
    it with itself; ``run`` gives the solution on the slab (0 where no unknown is).
    """

    def __init__(self, grid, matrix, rhs, unknowns, monitor=None):
        self.unknowns = unknowns
        self.matrix = matrix
        self.ksp = ksp = PETSc.KSP().create(comm=grid.comm)
        ksp.setOptionsPrefix(OPTIONS_PREFIX)
        ksp.setOperators(matrix)
        ksp.setType("cg")
        ksp.getPC().setType(PC_TYPE)
        if PC_TYPE == "hypre":
            ksp.getPC().setHYPREType("boomeramg")
        ksp.setTolerances(rtol=RTOL, atol=0.0, max_it=10000)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        with _defaults(HYPRE_OPTIONS):
            ksp.setFromOptions()
        if monitor is not None:
            ksp.setMonitor(lambda _, iteration, norm: monitor(iteration, norm))
        self.x, self.b = matrix.createVecs()
        self.b.getArray()[:] = rhs
        self.x.set(0.0)
        self.iterations, self.time = 0, 0.0

    @property
    def rtol(self):
        return self.ksp.getTolerances()[0]

    def run(self, rtol=None):
        """Solve (on from the last solution when ``rtol`` tightens it); the solution slab."""
        if rtol is not None:
            self.ksp.setTolerances(rtol=rtol)
            self.ksp.setInitialGuessNonzero(True)
        started = time.perf_counter()
        self.ksp.solve(self.b, self.x)
        self.time += time.perf_counter() - started
        self.iterations += self.ksp.getIterationNumber()
        u = np.zeros(self.unknowns.index.shape)
        u[self.unknowns.index >= 0] = self.x.getArray()
        return u

    @property
    def converged(self):
        return self.ksp.getConvergedReason() > 0

    def status(self):
        """What the solve did, for the result (iterations summed over the runs)."""
        reason = self.ksp.getConvergedReason()
        return {"converged": bool(reason > 0), "reason": _reason_name(reason),
                "iterations": int(self.iterations),
                "residual": float(self.ksp.getResidualNorm()) / max(self.b.norm(), 1e-300),
                "solve_time": self.time, "ksp_type": self.ksp.getType(),
                "pc_type": self.ksp.getPC().getType()}

    def destroy(self):
        for obj in (self.x, self.b, self.ksp, self.matrix):
            obj.destroy()


@contextmanager
def _defaults(options):
    """``options`` (without the prefix) in PETSc's database where the user set none."""
    database = PETSc.Options()
    added = [OPTIONS_PREFIX + k for k in options if not database.hasName(OPTIONS_PREFIX + k)]
    for name in added:
        database.setValue(name, options[name[len(OPTIONS_PREFIX):]])
    try:
        yield
    finally:
        for name in added:
            database.delValue(name)


def _reason_name(reason):
    names = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
    return names.get(reason, str(reason)).lower()


def face_fluxes(grid, faces, u, axis, periodic):
    """The scaled flux (per unit drop) through the faces: ``(down, right, inlet)``.

    ``down[i, j]`` flows from pixel ``(i, j)`` to ``(i + 1, j)`` (or into the outlet
    reservoir), ``right[i, j]`` to ``(i, j + 1)``; ``inlet[i, j]`` into the pixel from the
    inlet reservoir (free map; zero elsewhere).  Collective.
    """
    (_, down, right, inlet), = flux_pieces(grid, faces, u, axis, periodic, rows=len(u))
    return down, right, inlet


def flux_pieces(grid, faces, u, axis, periodic, rows=None):
    """:func:`face_fluxes` a piece of ``rows`` rows at a time (by default the rows of
    :data:`BLOCK_PIXELS` pixels): ``(first_row, down, right, inlet)`` per piece, local
    rows.  What a sum over the fluxes needs, without the whole fields beside the
    solver's hierarchy.  Collective (every rank iterates to the end).
    """
    nx, ny = global_shape(grid)
    stop = local_rows(grid)[1]
    halo = fetch_rows(grid, [u], [stop])[0, 0]
    drive = (1.0 / (nx, ny)[axis]) if periodic else 0.0
    n = len(u)
    rows = max(BLOCK_PIXELS // max(ny, 1) if rows is None else rows, 1)
    for lo in range(0, max(n, 1), rows):
        hi = min(lo + rows, n)
        piece = u[lo:hi]
        below = np.vstack([u[lo + 1:hi + 1], halo[None, :]]) if hi == n else u[lo + 1:hi + 1]
        right = np.roll(piece, -1, axis=1)
        if not periodic:              # the outlet reservoir is at 0
            below = np.where(faces.outlet[lo:hi], 0.0, below) if axis == 0 else below
            right = np.where(faces.outlet[lo:hi], 0.0, right) if axis == 1 else right
        down = faces.down[lo:hi] * (piece - below + (drive if axis == 0 else 0.0))
        across = faces.right[lo:hi] * (piece - right + (drive if axis == 1 else 0.0))
        inlet = np.where(faces.inlet[lo:hi],
                         getattr(faces, faces.inlet_side)[lo:hi] * (1.0 - piece), 0.0)
        yield lo, down, across, inlet
