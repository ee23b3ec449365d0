"""Where the pressure solver starts: warm, from a coarser grid, uniform, or from the overlap.

A start is chosen before the iterations (:func:`choose_start`) and gives them
their first contact set (:meth:`begin`):

* :class:`WarmStart`: a pressure field given (a sweep's previous step, or the
  single-precision stage of a mixed solve); ``S = {p > 0}``, rescaled to the load.
* :class:`CoarseStart`: the same contact solved on a grid twice as coarse
  (:mod:`petgap.solvers.coarse`, recursively) and prolonged; then a warm start.
  Most of a cold solve's iterations find the contact set, which a coarser grid
  finds at a fraction of the cost.
* :class:`UniformStart` (load control without a coarser grid): every point
  carries the mean pressure.  Robust where starts nearer the answer are not: a
  rigid approach with a local contact stiffness overshoots the long wavelengths
  (the compliance ``2 / (E* q)`` is large there), so the first displacement makes
  whole valleys penetrate; their entering pressures, rescaled to the load, then
  crush the summits, and the set can oscillate without converging.  On a periodic
  cell its first iteration has a closed form (:func:`uniform_first_iteration`).
* :class:`OverlapStart` (mean-gap or indentation control without a coarser grid):
  the pressure where the undeformed surfaces overlap.
"""
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from petgap.parallel.collective import global_sums
from petgap.solvers import _contact_set as _cs
from petgap.solvers import coarse
from petgap.solvers.contact_set import ContactSet


class Begun(NamedTuple):
    """The state a start leaves the iterations in."""

    contact: ContactSet
    #: factor that restores the load on the set's pressure at the next fresh transform
    scale: float = 1.0
    #: 0 restarts the conjugate gradients at the first step, 1 keeps the start's direction
    delta: float = 0.0
    #: the last ``(g, z)``, for the first step's ``beta``
    g_old: float = 1.0
    #: residuals of iterations the start made (the closed-form first iteration's)
    history: tuple = ()

    @property
    def first(self):
        """The first iteration the loop runs."""
        return len(self.history)


def _load_set(contact, target, n, comm, mask, padded_width, dtype):
    """``contact`` with its pressure rescaled to mean ``target`` (all points if it has none)."""
    total = global_sums(comm, contact.p.sum(dtype=np.float64))[0]
    if total > 0:
        contact.p[...] *= target * n / total
        return contact
    return ContactSet.everywhere(mask, padded_width, target, dtype=dtype)


class WarmStart:
    """Start from a given pressure field (in its own precision; copied into the set)."""

    def __init__(self, pressure, description="warm"):
        self.pressure, self.description = pressure, description

    def begin(self, cg):
        # S = {p > 0}, with p there: the negative part is dropped on the way in (no pass
        # of its own), and p is rescaled to the load on S alone
        contact = ContactSet.from_pressure(cg.mask, cg.padded_width, np.asarray(self.pressure),
                                           dtype=cg.dtype)
        self.pressure = None   # a start's field is freed before the iterations' fields
        if cg.load:
            contact = _load_set(contact, cg.target, cg.n, cg.comm, cg.mask, cg.padded_width,
                                cg.dtype)
        return Begun(contact)


class CoarseStart(WarmStart):
    """The solution on a coarser grid, prolonged: a warm start made by a coarse solve."""

    @classmethod
    def solve(cls, problem, control, settings, solver):
        """A :class:`CoarseStart`, or ``(None, description)`` where none is made.

        ``solver(problem, control, settings)`` solves the coarse problem (the
        pressure solver itself, to ``max(tolerance, coarse_tolerance)``).  The
        pressure is the fine grid's :meth:`~petgap.parallel.grid.Grid.scratch`, in
        the grid's precision: it is read before the next transform.  Collective.
        """
        pressure, description = coarse_start_pressure(problem, control, settings, solver)
        if pressure is None:
            return None, description
        return cls(pressure, description), description


class OverlapStart:
    """Pressure where the undeformed surfaces overlap at the control's offset."""

    description = "overlap of the undeformed surfaces"

    def begin(self, cg):
        problem = cg.problem
        p = (problem.topography - cg.offset) * (problem.pressure_scale / problem.gap_scale)
        contact = ContactSet.from_pressure(cg.mask, cg.padded_width, p, dtype=cg.dtype)
        del p   # freed before the iterations' fields
        return Begun(contact)


class UniformStart:
    """Every point in ``S`` at the mean pressure; on a periodic cell, its first iteration solved."""

    description = "uniform pressure"

    def begin(self, cg):
        everywhere = ContactSet.everywhere
        if not cg.problem.half_space.periodic:   # C P0 is not zero there: iterate from it
            return Begun(everywhere(cg.mask, cg.padded_width, cg.target, dtype=cg.dtype))
        begun = uniform_first_iteration(cg)
        if begun is None:
            return Begun(everywhere(cg.mask, cg.padded_width, cg.target, dtype=cg.dtype))
        return begun


def choose_start(problem, control, settings, initial_pressure, load, solver):
    """The start of a pressure solve, and a line saying how it was found.

    A given pressure is a warm start; else a coarse start where
    ``settings.coarse_start`` and the grid allow; else uniform (load) or the
    overlap (mean gap, indentation).  ``solver`` solves the coarse problem.
    """
    if initial_pressure is not None:
        return WarmStart(initial_pressure), "warm"
    description = ""
    if settings.coarse_start:
        start, description = CoarseStart.solve(problem, control, settings, solver)
        if start is not None:
            return start, description
    cold = UniformStart() if load else OverlapStart()
    return cold, "; ".join(filter(None, [description, cold.description]))


def uniform_first_iteration(cg):
    """Iteration 0 of a load-controlled cold start from the uniform pressure, in closed form.

    From ``p = P0`` everywhere, ``u = K^{-1} p = 0`` (no q = 0 mode), so the
    iteration's gap (shifted to zero mean over S, here every point) is
    ``g = mean(h) - h``, its preconditioned gap ``z = K g``, its direction
    ``t = z - mean(z)``, the image of that ``r = K^{-1} t = g``, and the step
    ``tau = (g, t) / (r, t) = 1``: the general iteration's two and a half
    transform pairs reduce to one, and its pressure update to ``P0 - t`` projected,
    with the entering pressure of the general iteration where that clips a
    penetrating point.  The set of every point is never built: the new set is made
    from the updated pressure, written to the scratch columns of ``cg.u`` (not
    needed yet).  Only shrinking is expected from there, so the set gets no spare
    capacity.

    Returns the :class:`Begun` state for the iteration loop to carry on from
    iteration 1, or None when iteration 0 is also the last (converged, e.g. on a
    flat surface, or no iteration allowed): then the caller runs it the general way.
    """
    problem = cg.problem
    grid, comm, h = problem.grid, problem.grid.comm, problem.topography
    padded = grid.padded
    hbar = problem.mean_height
    g_max, g_sq = _cs.uniform_gap(padded, h, hbar)
    g_sq = global_sums(comm, g_sq)[0]
    if not np.isfinite(g_sq):  # decided alike on every rank (a NaN sum is NaN everywhere)
        return None
    residual = comm.allreduce(g_max, op=MPI.MAX) / problem.gap_scale
    if residual <= cg.settings.tolerance or cg.settings.max_iterations < 1:
        return None
    if cg.monitor is not None:
        if getattr(cg.monitor, "wants_objective", False):
            # p = P0 everywhere has u = K^-1 p = 0: F = -<p, h> = -P0 sum(h) dx dy
            cg.monitor(0, residual, -cg.target * grid.pixel_area * global_sums(comm, h.sum())[0])
        else:
            cg.monitor(0, residual)
    problem.half_space.apply_in_buffer(inverse=False)   # z = K g
    sum_z, gz = global_sums(comm, *_cs.uniform_sums(padded, h, hbar))
    zshift = sum_z / grid.npoints
    entry = gz / g_sq  # tau (= 1) times the stiffness's Rayleigh quotient on g
    p = grid.scratch(cg.u)
    n_overlap, _, sum_p = global_sums(comm, *_cs.uniform_step(padded, h, hbar, zshift, cg.target,
                                                              entry, p))
    contact = ContactSet.from_pressure(cg.mask, cg.padded_width, p, spare=1.0, dtype=p.dtype)
    _cs.direction_from_buffer(padded, contact.pidx, zshift, 0.0, contact.t)
    return Begun(contact, cg.target * grid.npoints / sum_p, 0.0 if n_overlap > 0 else 1.0, gz,
                 (residual,))


def coarse_start_pressure(problem, control, settings, solver):
    """A fine-grid pressure to start from: the solution on a coarser grid, prolonged.

    The coarse problem and the transfers are :mod:`petgap.solvers.coarse`'s;
    ``solver(problem, control, settings)`` solves it to ``max(tolerance,
    coarse_tolerance)`` from its own coarse start.  Returns ``(pressure, a line
    saying how it was found)``, or ``(None, "")`` when the grid is not coarsened,
    or ``(None, why)`` when the coarse solve produced NaN.  The pressure is the fine
    grid's :meth:`~petgap.parallel.grid.Grid.scratch`, in the grid's precision: read
    it before the next transform.  On a free map the pressure near the edges takes
    their profile (:func:`petgap.solvers.coarse.prolong_pressure`).  Collective.
    """
    coarse_problem = coarse.coarse_problem(problem)
    if coarse_problem is None:
        return None, ""
    solution = solver(coarse_problem, control, settings.but(
        tolerance=max(settings.tolerance, settings.coarse_tolerance), coarse_start=True,
        search_precision="double", preconditioned=True))
    pressure = solution.pressure
    finite = problem.grid.comm.allreduce(bool(np.isfinite(pressure).all()), op=MPI.LAND)
    cgrid = coarse_problem.grid
    description = (f"coarse {cgrid.nx}x{cgrid.ny}: {solution.iterations} "
                   f"iterations, {solution.reason}"
                   + (f"; {solution.start}" if solution.start.startswith("coarse") else ""))
    if not finite:
        return None, description + " (NaN: not used)"
    factor = problem.grid.nx // cgrid.nx
    first_row = cgrid.x_slice.start
    whole = coarse.is_whole(problem.grid, cgrid)
    # the coarse problem, grid and solution go before the fine iterations make their fields
    del solution, coarse_problem, cgrid
    return (coarse.prolong_pressure(problem, first_row, pressure, factor, whole,
                                    out=problem.grid.scratch()), description)
