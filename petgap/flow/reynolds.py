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
singular.  Their rows, and those of closed pixels, are the identity, so the matrix is
laid out over petgap's own row slabs, each rank owning the rows ``i * ny + j`` of its
pixels: the vectors are the slabs themselves, with no scatter.  (A DMDA would need
its own copy of the slab layout; an AIJ matrix over the slab's rows takes the FFTW-MPI
decomposition as it is, uneven blocks included.)

The linear system is scaled: the unknown is the pressure over ``dp``, the conductances
``g^3`` over the largest ``g^3`` of the map, so the matrix has entries of order one
whatever the units.  It is symmetric positive definite, solved by PETSc's conjugate
gradients with algebraic multigrid (:data:`PC_TYPE`); the options prefix ``flow_`` reaches the solver
(``-flow_ksp_type``, ``-flow_pc_type``, ``-flow_ksp_rtol``, ``-flow_ksp_monitor`` ...).
"""
import time

import numpy as np
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


def harmonic_mean(a, b):
    """``2 a b / (a + b)``, and 0 where both are 0 (a face between closed pixels)."""
    total = a + b
    return np.divide(2.0 * a * b, total, out=np.zeros(np.broadcast(a, b).shape), where=total > 0)


class Faces:
    """The scaled face conductances of this rank's pixels.

    ``up[i, j]`` conducts between pixel ``(i, j)`` and ``(i - 1, j)``, ``down`` to
    ``(i + 1, j)``, ``left`` to ``(i, j - 1)``, ``right`` to ``(i, j + 1)`` (global
    indices, periodic where the cell is), pixel aspect included.  On a free map the
    faces on the map's edges across the flow lead to the reservoirs (inlet pressure 1
    above or left, outlet 0 below or right: half a pixel away, so twice the pixel's
    conductance), and those along it are sealed.
    """

    def __init__(self, grid, k, axis, periodic):
        nx, ny = global_shape(grid)
        start, stop = local_rows(grid)
        dx, dy = pixel(grid)
        halo = fetch_rows(grid, [k], [start - 1, stop])[0]
        first, last = start == 0, stop == nx
        above, below = halo[0], halo[1]
        ext = np.vstack([above, k, below])
        x_faces = harmonic_mean(ext[:-1], ext[1:]) * (dy / dx)
        y_faces = harmonic_mean(k, np.roll(k, -1, axis=1)) * (dx / dy)   # (i, j) to (i, j+1)
        self.up, self.down = x_faces[:-1].copy(), x_faces[1:].copy()
        self.right, self.left = y_faces, np.roll(y_faces, 1, axis=1)
        #: The faces to the inlet and outlet reservoirs: their direction and pixels.
        self.inlet_side, self.outlet_side = ("up", "down") if axis == 0 else ("left", "right")
        self.inlet = np.zeros(k.shape, dtype=bool)
        self.outlet = np.zeros(k.shape, dtype=bool)
        if periodic:
            return
        if axis == 0:
            self.inlet[0], self.outlet[-1] = first, last
            self.left[:, 0] = self.right[:, -1] = 0.0
        else:
            self.inlet[:, 0] = self.outlet[:, -1] = True
            self.up[0] = 0.0 if first else self.up[0]
            self.down[-1] = 0.0 if last else self.down[-1]
        for side, where in ((self.inlet_side, self.inlet), (self.outlet_side, self.outlet)):
            getattr(self, side)[where] = 2.0 * k[where] * (dy / dx if axis == 0 else dx / dy)

    def reservoir(self, side):
        """The pixels whose face on ``side`` leads to a reservoir (bool slab)."""
        if side == self.inlet_side:
            return self.inlet
        if side == self.outlet_side:
            return self.outlet
        return np.zeros(self.inlet.shape, dtype=bool)

    def diagonal(self):
        return self.up + self.down + self.left + self.right


def assemble(grid, faces, axis, periodic, pinned):
    """The matrix and right-hand side of the scaled system (collective).

    ``pinned`` (global pixel indices, the same on every rank) are the pixels whose
    unknown is fixed at 0; pixels with no conducting face get identity rows as well.
    """
    # deferred: importing SciPy changes warning filters, which `import petgap` must not do
    from scipy.sparse import coo_matrix

    nx, ny = global_shape(grid)
    start, stop = local_rows(grid)
    nloc = stop - start
    i = np.arange(start, stop)[:, None]
    j = np.arange(ny)[None, :]
    index = np.broadcast_to(i * ny + j, (nloc, ny))
    diag = faces.diagonal()
    pinned = np.asarray(pinned, dtype=np.int64)
    fixed = np.isin(index, pinned) | (diag == 0)
    neighbours = {"up": ((i - 1) % nx) * ny + j, "down": ((i + 1) % nx) * ny + j,
                  "left": i * ny + (j - 1) % ny, "right": i * ny + (j + 1) % ny}
    rows, cols, vals = [index[~fixed]], [index[~fixed]], [diag[~fixed]]
    rows.append(index[fixed])
    cols.append(index[fixed])
    vals.append(np.ones(np.count_nonzero(fixed)))
    for name, where in neighbours.items():
        t = getattr(faces, name)
        link = (t > 0) & ~fixed & ~faces.reservoir(name)
        col = np.broadcast_to(where, (nloc, ny))[link]
        keep = ~np.isin(col, pinned)   # a pinned neighbour's unknown is 0: no column
        rows.append(index[link][keep])
        cols.append(col[keep])
        vals.append(-t[link][keep])
    rows, cols, vals = (np.concatenate(a) for a in (rows, cols, vals))
    csr = coo_matrix((vals, (rows - start * ny, cols)), shape=(nloc * ny, nx * ny)).tocsr()
    csr.sum_duplicates()
    csr.sort_indices()
    matrix = PETSc.Mat().createAIJ(size=((nloc * ny, nx * ny), (nloc * ny, nx * ny)),
                                   csr=(csr.indptr.astype(PETSc.IntType),
                                        csr.indices.astype(PETSc.IntType), csr.data),
                                   comm=grid.comm)
    matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    matrix.setOption(PETSc.Mat.Option.SPD, True)
    matrix.assemble()
    rhs = np.where(faces.inlet & ~fixed, getattr(faces, faces.inlet_side), 0.0)
    if periodic:      # the drop across the period: p = dp (phi - x / L)
        n = (nx, ny)[axis]
        ahead, behind = (faces.down, faces.up) if axis == 0 else (faces.right, faces.left)
        rhs = np.where(fixed, 0.0, (behind - ahead) / n)
    return matrix, rhs


class KrylovSolve:
    """``matrix u = rhs`` by CG and algebraic multigrid, resumable at a tighter tolerance.

    The options database is read (prefix ``flow_``) after the defaults are set, so
    ``-flow_ksp_type``, ``-flow_pc_type``, ``-flow_ksp_rtol`` and the rest override them.
    ``monitor(iteration, residual_norm)`` is called at every iteration.  The residual is
    the unpreconditioned one: it is the mass imbalance of the pixels.
    """

    def __init__(self, grid, matrix, rhs, monitor=None):
        self.shape = rhs.shape
        self.ksp = ksp = PETSc.KSP().create(comm=grid.comm)
        ksp.setOptionsPrefix(OPTIONS_PREFIX)
        ksp.setOperators(matrix)
        ksp.setType("cg")
        ksp.getPC().setType(PC_TYPE)
        if PC_TYPE == "hypre":
            ksp.getPC().setHYPREType("boomeramg")
        ksp.setTolerances(rtol=RTOL, atol=0.0, max_it=10000)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setFromOptions()
        if monitor is not None:
            ksp.setMonitor(lambda _, iteration, norm: monitor(iteration, norm))
        self.x, self.b = matrix.createVecs()
        self.b.getArray()[:] = rhs.ravel()
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
        return self.x.getArray().reshape(self.shape).copy()

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
        for obj in (self.x, self.b, self.ksp):
            obj.destroy()


def _reason_name(reason):
    names = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
    return names.get(reason, str(reason)).lower()


def face_fluxes(grid, faces, u, axis, periodic):
    """The scaled flux (per unit drop) through the faces: ``(down, right, inlet)``.

    ``down[i, j]`` flows from pixel ``(i, j)`` to ``(i + 1, j)`` (or into the outlet
    reservoir), ``right[i, j]`` to ``(i, j + 1)``; ``inlet[i, j]`` into the pixel from the
    inlet reservoir (free map; zero elsewhere).
    """
    nx, ny = global_shape(grid)
    stop = local_rows(grid)[1]
    halo = fetch_rows(grid, [u], [stop])[0, 0]
    below = np.vstack([u[1:], halo[None, :]])
    right = np.roll(u, -1, axis=1)
    if not periodic:              # the outlet reservoir is at 0
        below = np.where(faces.outlet, 0.0, below) if axis == 0 else below
        right = np.where(faces.outlet, 0.0, right) if axis == 1 else right
    drive = (1.0 / (nx, ny)[axis]) if periodic else 0.0
    down = faces.down * (u - below + (drive if axis == 0 else 0.0))
    across = faces.right * (u - right + (drive if axis == 1 else 0.0))
    inlet = np.where(faces.inlet, getattr(faces, faces.inlet_side) * (1.0 - u), 0.0)
    return down, across, inlet
