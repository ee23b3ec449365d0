"""The coarse grid of the pressure solver's start: a blurred copy of the problem.

Why: from a uniform pressure, Polonsky-Keer spends its first iterations on a
contact set of most of the points, which shrinks slowly, each iteration
costing more than a late one; and a start nearer the answer built from the
geometry alone (a rigid approach) is unstable (see
:mod:`petgap.solvers.pressure_start`).  The
answer of the same contact on a grid ``f`` times coarser -- the topography
averaged over ``f x f`` blocks, the same cell, modulus and control -- is such a
start, and costs ``1/f^2`` per iteration.  ``f = 2``: a start twice as coarse
leaves the fine solve fewer contact edges to move than one four times as
coarse, and the levels below cost less than the first in all.  Its pressure,
repeated over each block, starts the fine solve with the set already at the
contact fraction of the answer, which spares the fine solve its first
iterations on a set of most of the points (docs/design.md, "The coarse-grid
start").  The coarse problem is solved
the same way (:func:`petgap.solvers.pressure_start.coarse_start_pressure` drives it), so
large grids descend through several levels (1024^2: 512^2, 256^2, ..., 32^2).
The coarse problem is made for the start and dropped after it (the later
steps of a sweep start warm), so that it never adds to the fine solve's peak
memory; its transforms are planned with FFTW's "estimate", so that a first
run of a size does not spend longer planning the levels than solving on them.
On a periodic cell the coarse levels are single precision whatever the
fine grid's: a start is solved to :data:`COARSE_TOLERANCE`, far above what
32 bits resolve (:data:`petgap.io.solver_registry.SINGLE_TOLERANCE_FLOOR`), and in
single its transforms move half the bytes.  The fine solve takes the
prolonged pressure in its own precision.

This module holds the coarse problem and the transfers between the grids
only; it does not solve, so the solver may import it without a cycle.

Conventions
-----------
* Restriction is the block mean (it keeps the mean height, so a mean-gap
  control means the same on both grids); prolongation repeats each coarse
  value over its block (it keeps the mean pressure, so a load control does).
* The decision to coarsen depends on the grid's shape only (both sides
  divisible by ``f``, the coarse sides at least :data:`MIN_SIDE`), never on
  the number of ranks, so that results do not depend on it beyond round-off.
  Blocks of rows may straddle two ranks' slabs: rows are moved between the
  two decompositions with one ``Alltoallv`` each way (:func:`petgap.parallel.collective.move_rows`).
* Coarse grids of at most :data:`WHOLE_POINTS` points are solved whole on
  every rank (a grid on ``MPI.COMM_SELF``, the same arithmetic everywhere):
  spread over ranks, their transforms and reductions would cost the
  messages' latency and little else, and a slab decomposition stops at one
  row per rank.  The finer levels stay distributed.
* The coarse solve is a start, not a result: its tolerance is
  ``max(tolerance, COARSE_TOLERANCE)`` (``-petgap_coarse_tolerance``
  sets another) and a coarse solve that did not
  converge still gives its pressure (a NaN gives none: the caller then starts
  from the uniform pressure).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import ContactProblem
from petgap.parallel.collective import move_rows
from petgap.parallel.log import get_logger
from petgap.parallel.grid import DecompositionError, Grid

#: Smallest side of a coarse grid, in points (below it the uniform start is cheap).
MIN_SIDE = 32
#: Block size of a coarsening level (see the module docstring for why 2).
FACTOR = 2
#: Coarse solves stop here (or at the fine tolerance if that is looser).  The
#: prolonged start misses the fine grid's shortest wavelengths, so its residual
#: there is a few 1e-3 however closely the coarse problem was solved; below
#: 1e-3 the coarse iterations buy the fine solve nothing, and at 1e-2 the fine
#: solve takes a few more (docs/benchmarks.md, "The coarse-grid start").
COARSE_TOLERANCE = 1e-3
#: Coarse grids of at most this many points are solved whole on every rank.
WHOLE_POINTS = 256 * 256
#: Fine rows :func:`prolong` writes at a time.
PROLONG_CHUNK = 128
#: Blocks from a free map's edge that :func:`edge_profile` shapes (the third's shares
#: differ from its mean by 5 %, and shaping it too started the 1024^2 benchmark map no
#: better than two).
EDGE_BLOCKS = 2


def coarsening_factor(shape):
    """The block size ``f`` (:data:`FACTOR`) for a grid of this shape, or None.

    Depends on the shape alone, so every rank count decides alike.
    """
    nx, ny = shape
    f = FACTOR
    if nx % f == 0 and ny % f == 0 and min(nx, ny) // f >= MIN_SIDE:
        return f
    return None


def coarse_problem(problem, precision=None, scales=None):
    """The block-averaged problem on the coarse grid, or None if the shape has none
    (or the body cannot live on it: :meth:`admits`).

    Collective.  Made anew on every call (the caller drops it after the start);
    about ``1/f^2`` of the fine problem's memory.  ``precision``: the coarse
    grid's; by default single on a periodic cell (the pressure solver's start, see
    the module docstring; the free half-space is double only), else the grid's.
    ``scales``: the coarse problem's KKT scales
    (:class:`~petgap.mechanics.problem.Scales`); by default its own topography's.
    """
    grid = problem.grid
    f = coarsening_factor(grid.shape)
    if f is None:
        return None
    if precision is None:
        precision = "single" if problem.half_space.periodic else grid.precision
    shape = (grid.nx // f, grid.ny // f)
    if not problem.half_space.admits(shape):
        return None   # e.g. the padded cell of a map with an odd side
    whole = grid.comm.size > 1 and shape[0] * shape[1] <= WHOLE_POINTS
    try:
        cgrid = Grid(shape, size=(grid.Lx, grid.Ly), comm=MPI.COMM_SELF if whole else grid.comm,
                     planner="estimate", wisdom=grid.wisdom, precision=precision)
    except DecompositionError:
        return None  # too few coarse rows for this many ranks: no coarse start
    # where the set-up time goes, level by level
    get_logger("coarse").info("coarse grid %dx%d (%s%s) for the start: FFTs planned in %.2f s "
                              "(%s)", cgrid.nx, cgrid.ny, precision,
                              ", whole on every rank from here down" if whole else "",
                              cgrid.planning_time,
                              cgrid.planner)
    h = restrict(grid, cgrid, problem.topography, f).astype(cgrid.dtype, copy=False)
    return ContactProblem(cgrid, h, problem.half_space.on_grid(cgrid),
                          problem.interaction, scales=scales)


def is_whole(grid, coarse):
    """Whether ``coarse`` is solved whole on every rank of the fine ``grid``'s ranks."""
    return coarse.comm.size < grid.comm.size


def restrict(grid, coarse, field, f):
    """The block means of ``field`` (this rank's fine slab) on this rank's coarse slab.

    A ``coarse`` grid solved whole on every rank (:func:`is_whole`) gets every row.
    Summed by ``f^2`` strided slices into the coarse rows (NumPy walks a
    reshaped short axis slowly).  On one rank the partial rows are the coarse
    slab itself, without a second coarse field to add them into.
    """
    m = field.shape[0]
    x0 = grid.x_slice.start
    first, last = x0 // f, (x0 + m - 1) // f
    partial = np.zeros((last - first + 1, grid.ny // f))  # coarse rows first..last, in part
    for i0 in range(f):
        b0 = (x0 + i0) // f - first   # local rows i0, i0 + f, ... lie in blocks b0, b0 + 1, ...
        count = len(range(i0, m, f))
        for j in range(f):
            partial[b0:b0 + count] += field[i0::f, j::f]
    if grid.comm.size == 1:
        partial /= f * f
        return partial
    lo, hi = coarse.x_slice.start, coarse.x_slice.stop
    out = np.zeros(coarse.local_shape)
    for row, piece in move_rows(grid.comm, partial, first, lo, hi):
        out[row - lo:row - lo + len(piece)] += piece  # a straddling block: two parts
    out /= f * f
    return out


def prolong(first_row, grid, field, f, whole=False, out=None):
    """``field`` (this rank's coarse slab) repeated over each block, on this rank's fine slab.

    ``first_row`` is the global coarse row the slab starts at (the coarse grid's
    ``x_slice.start``): all that is needed of the coarse grid, which the caller
    may then free before the fine field is made.  ``whole``: ``field`` is the
    whole coarse field, the same on every rank (:func:`is_whole`), and each
    rank takes its rows without messages; so does a single rank, reading the
    field where it is rather than a copy of it.  Written by ``f^2`` strided
    assignments into the result: no fine-slab temporaries besides it.  ``out``:
    a contiguous array of the fine slab's shape to write into (e.g.
    :meth:`petgap.parallel.grid.Grid.scratch`), converting to its dtype; by
    default a new one of ``field``'s dtype.
    """
    m = grid.local_shape[0]
    x0 = grid.x_slice.start
    lo, hi = x0 // f, (x0 + m - 1) // f + 1
    if whole or grid.comm.size == 1:
        rows = field[lo:hi]
    else:
        rows = np.empty((hi - lo, field.shape[1]), dtype=field.dtype)
        for row, piece in move_rows(grid.comm, field, first_row, lo, hi):
            rows[row - lo:row - lo + len(piece)] = piece
    if out is None:
        out = np.empty(grid.local_shape, dtype=field.dtype)
    # by chunks of rows, so that the strided writes fault in fresh pages at the pace of
    # contiguous ones (first touching the whole slab strided costs several times more)
    for a in range(0, m, PROLONG_CHUNK):
        part = out[a:a + PROLONG_CHUNK]
        for i0 in range(f):
            b0 = (x0 + a + i0) // f - lo   # rows i0, i0 + f, ... repeat rows b0, b0 + 1, ...
            count = len(range(i0, len(part), f))
            for j in range(f):
                part[i0::f, j::f] = rows[b0:b0 + count]
    return out


def prolong_pressure(problem, first_row, field, f, whole=False, out=None):
    """A coarse level's pressure on ``problem``'s grid: :func:`prolong`, and on a free map
    the edges' profile (:func:`edge_profile`).  What both pressure starts prolong."""
    pressure = prolong(first_row, problem.grid, field, f, whole, out)
    if not problem.half_space.periodic:
        edge_profile(problem.grid, pressure, f)
    return pressure


def edge_shares(n, f, blocks=EDGE_BLOCKS):
    """Weights of a free map's fine pixels along one side of ``n``, for :func:`edge_profile`.

    The pixel at ``m`` pixels from the nearer edge, in block ``k = m // f``, gets
    ``f (sqrt(m + 1) - sqrt(m)) / (sqrt(f (k + 1)) - sqrt(f k))``: its share of
    the block's integral of ``s^(-1/2)``, ``s`` the distance to the edge.  The
    shares of a block sum to ``f``; pixels farther in get 1.
    """
    w = np.ones(n)
    for m in range(min(f * blocks, n // 2)):
        k = m // f
        share = f * (np.sqrt(m + 1) - np.sqrt(m)) / (np.sqrt(f * (k + 1)) - np.sqrt(f * k))
        w[m] = w[n - 1 - m] = share
    return w


def edge_profile(grid, field, f):
    """Give a prolonged pressure on a free map the square-root profile of the map's edges.

    Why: on a free boundary no pressure acts outside the map, so a contact patch
    that the map's edge cuts ends there as a flat punch does, its pressure rising
    like ``s^(-1/2)`` towards the edge (``s`` the distance to it).  Repeated over
    its block, a coarse edge pixel's pressure leaves the outermost fine pixel too
    low and the next too high (the converged fine field has 1.33-1.54 times the
    block's mean in the outer one), and the fine solve's start has its largest
    residual there.  Each of the :data:`EDGE_BLOCKS` blocks nearest an edge shares
    its value out in proportion to the profile's integral over its pixels
    (:func:`edge_shares`, the product of the two sides' at a corner): block means,
    hence the load, are kept, and a block out of contact stays at zero.  In place on
    this rank's slab (``field``, of the grid's local shape); depends on global
    indices only, so not on the decomposition.
    """
    band = f * EDGE_BLOCKS
    wy = edge_shares(grid.ny, f)
    field[:, :band] *= wy[:band]
    field[:, -band:] *= wy[-band:]
    wx = edge_shares(grid.nx, f)[grid.x_slice]
    rows = np.flatnonzero(wx != 1.0)
    field[rows] *= wx[rows, None]
    return field


def extrapolated(values, ratio):
    """A quantity on the next finer grid from its values on the levels, finest first.

    ``values[0]`` plus the last step over ``ratio``: a quantity that converges with the
    grid at an order whose steps shrink about ``ratio``-fold per level.  ``values[0]``
    itself where there is only one level, or where three levels give two steps that do
    not shrink in the same direction (the levels then say nothing of the next step).
    """
    if len(values) < 2:
        return values[0]
    last = values[0] - values[1]
    if len(values) > 2:
        below = values[1] - values[2]
        if last * below <= 0 or abs(below) <= abs(last):
            return values[0]
    return values[0] + last / ratio
