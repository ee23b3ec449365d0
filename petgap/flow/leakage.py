"""Leakage through the gaps of a contact: leak rate, transmissivity, flow factor, fields.

:func:`leakage` takes a grid and a gap slab (a fresh solution's, or one read back from a
result file), :func:`leakage_of` a solved problem.  Both find the open clusters that
span the map (:func:`petgap.analysis.open_clusters`), solve the Reynolds equation on
them (:mod:`petgap.flow.reynolds`) and return a :class:`Leakage`.

What is reported
----------------
* ``leak_rate`` ``Q``: the volume of fluid per unit time through the map, across its
  whole width ``W`` (in the scene's units: length^3 / time when ``mu`` is in pressure x
  time).  It is the mean of the fluxes through all cross-sections of the map; their
  spread (``conservation``, relative) measures how well mass is conserved.
* ``transmissivity`` ``K = 12 mu Q L / (W dp)``: the ``g^3`` of the parallel plates that
  leak as much (a length cubed; ``K^(1/3)`` is the hydraulic gap).  Between parallel
  plates at gap ``g`` it is ``g^3``.
* ``flow_factor`` ``K / g_mean^3``: the leak against parallel plates at the mean gap of
  the whole map (contact pixels counted at zero gap), i.e. ``Q`` over
  ``g_mean^3 / (12 mu) dp / L W``.
* the pressure map (``NaN`` where it is undefined: closed pixels and pockets no fluid
  reaches) and the cell-centred volume flux per unit width along x and y;
* the percolation of the open region (:class:`petgap.analysis.Percolation`).

A gap field that does not percolate leaks nothing: ``Q = 0``, with the reason, and no
linear system is solved.
"""
import warnings
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from petgap.analysis._slabs import check_fields, fetch_rows, global_shape, local_rows, pixel, \
    positive
from petgap.analysis.percolation import Percolation, check_direction, open_clusters
from petgap.flow.reynolds import (Faces, KrylovSolve, Unknowns, assemble, face_fluxes,
                                  flux_pieces)
from petgap.solvers.dispatch import petsc_options

#: The largest relative spread of the flux through the cross-sections (the mass balance)
#: a leak rate is returned with; the solve is resumed at a tighter tolerance until then.
CONSERVATION = 1e-8
#: The tightest relative residual asked for: below it round-off decides.
RTOL_FLOOR = 1e-15


@dataclass
class Leakage:
    """The flow through the gaps of one gap field (scalars the same on every rank).

    See the module docstring for what the quantities mean.  ``converged``, ``reason``,
    ``iterations`` and ``residual`` (relative to the right-hand side) are the KSP
    solve's; ``reason`` is ``"no_percolation"`` when nothing was solved because no open
    cluster spans the map, and ``message`` says why in words.
    """
    direction: str
    periodic: bool
    viscosity: float
    pressure_drop: float
    length: float
    width: float
    leak_rate: float
    transmissivity: float
    mean_gap: float
    flow_factor: float
    inflow: float
    outflow: float
    conservation: float
    converged: bool
    reason: str
    message: str
    iterations: int
    residual: float
    solve_time: float
    ksp_type: str
    pc_type: str
    percolation: Percolation = field(repr=False)
    pressure: np.ndarray = field(repr=False)
    flux: tuple = field(repr=False)

    def scalars(self):
        """The scalar results as a flat dict (for tables and result files)."""
        out = {k: getattr(self, k) for k in (
            "direction", "periodic", "viscosity", "pressure_drop", "length", "width",
            "leak_rate", "transmissivity", "mean_gap", "flow_factor", "inflow", "outflow",
            "conservation", "converged", "reason", "message", "iterations", "residual",
            "solve_time", "ksp_type", "pc_type")}
        out.update(self.percolation.scalars())
        return out


def leakage(grid, gap, *, viscosity=1.0, pressure_drop=1.0, direction="x", periodic=True,
            gap_tolerance=None, mean_gap=None, options=None, monitor=None):
    """The :class:`Leakage` of a distributed gap field (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    gap : ndarray, shape ``grid.local_shape``
        This rank's slab of the gap.
    viscosity, pressure_drop : float
        ``mu > 0`` and the drop ``dp > 0`` imposed along ``direction``: across the period
        of a periodic cell, from the inlet edge to the outlet edge of a free map.
    direction : {"x", "y"}
    periodic : bool
        A periodic cell, or a free map (inlet and outlet edges, the other two sealed).
    gap_tolerance : float, optional
        Gaps at or below it are closed (default :func:`petgap.analysis.resolve_gap_tolerance`).
    mean_gap : float, optional
        The mean gap the flow factor refers to (default: the mean of ``gap``).
    options : dict, optional
        PETSc options for this solve (``{"flow_pc_type": "hypre"}``).
    monitor : callable, optional
        ``monitor(iteration, residual_norm)`` at every Krylov iteration.
    """
    axis = check_direction(grid, direction)
    viscosity = positive("viscosity", viscosity)
    pressure_drop = positive("pressure_drop", pressure_drop)
    gap = check_fields(grid, gap=gap)["gap"]
    comm = grid.comm
    nx, ny = global_shape(grid)
    dx, dy = pixel(grid)
    if mean_gap is None:
        mean_gap = comm.allreduce(float(np.sum(gap)), op=MPI.SUM) / (nx * ny)
    percolation = open_clusters(grid, gap, direction=direction, periodic=periodic,
                                gap_tolerance=gap_tolerance)
    geometry = dict(direction=direction, periodic=bool(periodic), viscosity=viscosity,
                    pressure_drop=pressure_drop, length=(nx * dx, ny * dy)[axis],
                    width=(nx * dx, ny * dy)[1 - axis], mean_gap=float(mean_gap),
                    percolation=percolation)
    if not percolation.percolates:
        return _no_leak(grid, geometry)
    labels = percolation.components.labels
    keep = np.isin(labels, np.nonzero(percolation.spanning)[0])
    cubes = np.where(keep, gap, 0.0)
    cubes **= 3
    scale = comm.allreduce(float(cubes.max(initial=0.0)), op=MPI.MAX)
    cubes /= scale
    faces = Faces(grid, cubes, axis, periodic)
    del cubes
    active = keep.copy()
    if periodic:      # each wrapping cluster's constant is fixed at its first pixel
        _unpin(grid, active, percolation.components.first_pixel[percolation.spanning])
    unknowns = Unknowns(grid, active, periodic)
    del active
    matrix, rhs = assemble(grid, faces, unknowns, axis, periodic)
    with petsc_options(options):
        solver = KrylovSolve(grid, matrix, rhs, unknowns, monitor)
    del rhs
    try:
        u, sections, spread = _balanced(grid, solver, faces, axis, periodic)
        status = solver.status()
    finally:
        solver.destroy()
        del solver, unknowns
    # the flux fields only now, with the matrix and its hierarchy gone (the memory's peak)
    down, across, inlet = face_fluxes(grid, faces, u, axis, periodic)
    del faces
    # physical flux per unit scaled flux: dp g^3 / (12 mu), g^3 in units of `scale`
    unit = pressure_drop * scale / (12.0 * viscosity)
    leak = unit * float(np.mean(sections))
    transmissivity = 12.0 * viscosity * leak * geometry["length"] / (
        geometry["width"] * pressure_drop)
    return Leakage(**geometry, leak_rate=leak, transmissivity=transmissivity,
                   flow_factor=_flow_factor(transmissivity, mean_gap),
                   inflow=unit * float(sections[0]), outflow=unit * float(sections[-1]),
                   conservation=spread, message="", **status,
                   pressure=_pressure(grid, u, keep, percolation, axis, periodic, pressure_drop),
                   flux=_cell_flux(grid, down, across, inlet, axis, periodic, unit))


def leakage_of(problem, solution, *, viscosity=1.0, pressure_drop=1.0, direction="x",
               gap_tolerance=None, options=None, monitor=None):
    """:func:`leakage` of a solved contact (collective): its grid, gap, mean gap and boundary.

    A periodic problem gives a periodic cell, a free boundary a free map.  An adhesive
    problem is warned about: where the gap is below the interaction's range the surfaces
    interact across it, and the film is not the thin viscous film the Reynolds equation
    describes.
    """
    interaction = problem.interaction
    if interaction.adhesive:
        rng = interaction.length_scale
        gap = np.asarray(solution.gap)
        near = problem.grid.comm.allreduce(int(np.count_nonzero((gap > 0) & (gap < rng))),
                                           op=MPI.SUM) / problem.grid.npoints
        warnings.warn(f"leakage of an adhesive contact: {100 * near:.3g} % of the map has an "
                      f"open gap below the interaction range {rng:g}, where the surfaces "
                      f"attract across a film the Reynolds equation does not describe; use the "
                      f"non-adhesive solution at the same load for the leakage", stacklevel=2)
    return leakage(problem.grid, solution.gap, viscosity=viscosity,
                   pressure_drop=pressure_drop, direction=direction,
                   periodic=problem.half_space.periodic, gap_tolerance=gap_tolerance,
                   mean_gap=solution.mean_gap, options=options, monitor=monitor)


def _balanced(grid, solver, faces, axis, periodic):
    """Solve until the flux through the cross-sections agrees to :data:`CONSERVATION`.

    The solver's relative residual bounds the pixels' mass imbalance against the
    right-hand side, which the reservoirs' or the drive's faces set; where narrow
    constrictions carry a flux far below that, the imbalance is a larger share of the
    leak.  So the sections are compared after the solve, and the solve resumed at a
    tolerance tightened by the shortfall until they agree (or round-off is reached).
    Returns the solution slab, the sections and their spread.
    """
    rtol = None
    while True:
        u = solver.run(rtol)
        pieces = flux_pieces(grid, faces, u, axis, periodic)
        sections = _sections(grid, pieces, axis, periodic)
        spread = float(np.ptp(sections)) / max(abs(float(np.mean(sections))), 1e-300)
        if spread <= CONSERVATION or not solver.converged or solver.rtol <= RTOL_FLOOR:
            return u, sections, spread
        rtol = max(solver.rtol * 0.1 * CONSERVATION / spread, RTOL_FLOOR)


def _unpin(grid, active, pinned):
    """Take the pixels ``pinned`` (global indices, the same on every rank) out of ``active``."""
    ny = global_shape(grid)[1]
    start, stop = local_rows(grid)
    mine = pinned[(pinned >= start * ny) & (pinned < stop * ny)] - start * ny
    active.reshape(-1)[mine] = False


def _flow_factor(transmissivity, mean_gap):
    return transmissivity / mean_gap ** 3 if mean_gap > 0 else 0.0


def _no_leak(grid, geometry):
    """The :class:`Leakage` of a field that does not percolate: nothing flows."""
    zero = np.zeros(grid.local_shape)
    percolation = geometry["percolation"]
    pressure = _pressure(grid, zero, zero > 0, percolation, check_direction(
        grid, geometry["direction"]), geometry["periodic"], geometry["pressure_drop"])
    return Leakage(**geometry, leak_rate=0.0, transmissivity=0.0, flow_factor=0.0, inflow=0.0,
                   outflow=0.0, conservation=0.0, converged=True, reason="no_percolation",
                   message=percolation.reason(), iterations=0, residual=0.0, solve_time=0.0,
                   ksp_type="", pc_type="", pressure=pressure, flux=(zero, zero.copy()))


def _sections(grid, pieces, axis, periodic):
    """The scaled flux through each cross-section of the map along the flow, in order
    (free map: the inlet first, the outlet last; periodic: the seam last), summed over the
    flux ``pieces`` (:func:`~petgap.flow.reynolds.flux_pieces`) of this rank's rows."""
    comm = grid.comm
    inflow, columns, rows = 0.0, 0.0, []
    for _, down, across, inlet in pieces:
        inflow += float(np.sum(inlet))
        columns = columns + np.sum(across, axis=0)
        rows.append(np.sum(down, axis=1))
    inflow = comm.allreduce(inflow, op=MPI.SUM)
    if axis == 1:
        columns = comm.allreduce(columns, op=MPI.SUM)
        return columns if periodic else np.concatenate([[inflow], columns])
    rows = np.concatenate(comm.allgather(np.concatenate(rows)))
    return rows if periodic else np.concatenate([[inflow], rows])


def _cell_flux(grid, down, across, inlet, axis, periodic, unit):
    """The cell-centred volume flux per unit width along x and y: the mean of the fluxes
    through a pixel's two faces along each axis, over the face's width."""
    dx, dy = pixel(grid)
    start = local_rows(grid)[0]
    above = fetch_rows(grid, [down], [start - 1])[0, 0]
    if not periodic and start == 0:
        above = inlet[0] if axis == 0 else np.zeros_like(above)
    into_x = np.vstack([above[None, :], down[:-1]])
    into_y = np.roll(across, 1, axis=1)
    if not periodic:
        into_y[:, 0] = inlet[:, 0] if axis == 1 else 0.0
    return (unit * 0.5 * (into_x + down) / dy, unit * 0.5 * (into_y + across) / dx)


def _pressure(grid, u, keep, percolation, axis, periodic, pressure_drop):
    """The pressure map: ``dp`` at the inlet to 0 at the outlet; on a periodic cell the
    mean drop ``dp x / L`` put back, shifted to mean ``dp / 2`` over the flowing pixels.
    ``NaN`` where no pressure is defined (closed pixels, sealed pockets); on a free map
    a dead end takes the pressure of the reservoir it opens to."""
    comm = grid.comm
    pressure = np.full(u.shape, np.nan)
    if periodic:
        nx, ny = global_shape(grid)
        start, stop = local_rows(grid)
        position = (np.arange(start, stop)[:, None] + 0.5) / nx if axis == 0 else \
            (np.arange(ny)[None, :] + 0.5) / ny
        total = u - position
        count = comm.allreduce(int(np.count_nonzero(keep)), op=MPI.SUM)
        if count == 0:
            return pressure
        mean = comm.allreduce(float(np.sum(np.where(keep, total, 0.0))), op=MPI.SUM) / count
        pressure[keep] = pressure_drop * (total - mean + 0.5)[keep]
        return pressure
    labels = percolation.components.labels
    pressure[np.isin(labels, np.nonzero(percolation.at_inlet)[0])] = pressure_drop
    pressure[np.isin(labels, np.nonzero(percolation.at_outlet)[0])] = 0.0
    pressure[keep] = pressure_drop * u[keep]
    return pressure
