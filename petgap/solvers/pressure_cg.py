"""Constrained conjugate gradients on the contact pressure (Polonsky & Keer 1999).

Polonsky & Keer, Wear 231 (1999) 206, with the mean-gap variant and the
notation of Rey, Anciaux & Molinari, Comput. Mech. 60 (2017) 69.  The unknown is
the pressure ``p >= 0``; the gap it implies is ``g = K^{-1} p - h + d``.  The
method runs conjugate gradients on the complementary energy restricted to the
contact set ``S = {p > 0}``, projects onto ``p >= 0`` after each step, and
restarts (steepest descent) when points that penetrate the surface enter the
contact set.

* Load control: ``mean(p) = P0`` is kept by rescaling ``p`` after each step,
  and ``d`` is chosen so that the mean gap over ``S`` vanishes.
* Mean-gap control: ``d = g_bar + mean(h)`` follows from ``mean(g) = g_bar``
  (``K^{-1} p`` has zero mean), no rescaling; ``mean(p)`` is the multiplier.
* Indentation (a free boundary): ``d`` is the depth.

The solver is a core and the parts it calls:

* :class:`PressureCG` here: the projected, preconditioned iteration, its restart
  rule and its verdict;
* the preconditioner (:mod:`petgap.solvers.preconditioners`): the stiffness
  restricted to ``S``, less the contact-edge term and the patch interaction,
  which keeps the iterations nearly flat in the grid's size;
* the start (:mod:`petgap.solvers.pressure_start`): warm, from a coarser grid,
  uniform, or the overlap of the undeformed surfaces;
* the settings (:class:`petgap.solvers.settings.SolverSettings`), one frozen value.

Restarts (petgap's change to the method)
----------------------------------------
Polonsky and Keer restart the conjugate gradients whenever a point enters
``S``.  Past the first few iterations of a start from a coarser grid, a few
points enter at almost every iteration -- the contact edges move by a pixel
here and there -- so the method degrades to preconditioned steepest descent
while the edges settle.  In an iteration with the patch interaction in the
preconditioner that is what works best: its steepest-descent steps are
nearly Newton steps, and conjugacy kept across changes of ``S`` slows the
final phase.  Without it (before the set has settled, under mean-gap control,
on grids below 1024^2, or with ``interaction_block = 0``), steepest descent is
slow, and conjugacy is kept unless more than :data:`RESTART_FRACTION` of ``S``
enters in one iteration: the few entering points perturb the subspace the
directions were conjugate in, and the step's exact line search still minimises
along the new direction.  A direction that is not a descent direction,
``(g, t) <= 0``, is caught after its transform and replaced by the steepest
one.  docs/design.md gives the measurements behind the rule.

Step length
-----------
The exact line search ``tau = (g, t) / (t, K^{-1} t)`` needs the direction's
image ``r = K^{-1} t`` only through ``(t, r)``, which by Parseval is
``sum_q 2 |t_q|^2 / (E* |q| N)``: the forward half of the transform
(:class:`petgap.solvers.preconditioners.StepTransforms`).  The inverse half is
run only when the iteration changes no point of the contact set (no projection,
no point enters): then ``K^{-1} p`` follows ``p`` by the conjugate-gradient
recurrence ``u <- s (u - tau r)``, and the next fresh transform of ``u`` is
skipped; a fresh transform is forced every :data:`REFRESH_INTERVAL` such steps
and before any verdict, so round-off cannot accumulate into the answer.  An
iteration that changes the set costs two and a half transform pairs (``z``, the
half of ``r``, the fresh ``u``), one that does not two (``z``, ``r``).  Under
load control the direction is kept at zero mean over ``S`` (the old direction's
mean over the present set is taken off with ``z``'s), so that a step along it
keeps the load and ``(t, r)`` needs no correction for the mean of ``r`` over
``S``.

The contact set is stored as sorted index lists, with the pressure, the
conjugate direction, the gap and the preconditioned gap kept on it only
(:mod:`petgap.solvers.contact_set`, kernels in ``petgap/solvers/_contact_set.pyx``),
and the transforms take their input from those lists and, for ``P_S K P_S g``,
give their output back on them
(:meth:`petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse`): at a few
percent contact an iteration then streams the slab through memory once (the gap
pass, which only reads) besides the transforms.  The displacement
``u = K^{-1} p`` is the one full field kept between iterations, in the padded
layout the transform writes it in; the gap ``g = u - h + d`` is recomputed where
it is needed.

Precision
---------
The solver works in the precision of the problem's grid
(:class:`petgap.parallel.grid.Grid` ``precision``): on a single-precision grid
the topography, the displacement, the FFT buffers and the vectors on ``S`` are
32-bit and every sum, norm and step length is accumulated in double (the
kernels' accumulators), so that what single precision costs is the rounding of
the fields, not of the reductions.  The gap ``u - h + d`` is then a difference
of 7-digit numbers: the KKT residual cannot fall much below ``1e-7 max|h| /
h0``, and :mod:`petgap.solvers.mixed_precision` refines such a solve in double.
Near that floor the rounding of ``u`` moves edge points in and out of S at
every iteration and the residual wanders instead of falling, so a
single-precision solve whose residual has not fallen below
:data:`STALL_FACTOR` of its best for :data:`STALL_ITERATIONS` iterations stops,
unconverged, with the reason ``"stalled_round_off"`` rather than run on to
its iteration limit.

On a double grid the two transforms that only find the step may run in single
precision (``settings.search_precision``, :class:`~petgap.solvers.preconditioners.StepTransforms`).
The pressure, the displacement ``u = K^{-1} p`` from which every verdict's gap is
taken, and every sum stay double, so the tolerance and the answer are double's;
the rounding changes the path only.  The same solve on another number of ranks
then takes another path within that rounding and ends within the tolerance's
reach of it, not within round-off (``tests/solvers/test_search_precision.py``
measures it), so double is the default; mixed precision, whose single stage
depends on the decomposition at that level already, refines with a single search.

Convergence is judged at the start of an iteration, on the pair ``(p, g)`` the
iteration starts from, by the gap residual of
:meth:`petgap.mechanics.problem.ContactProblem.kkt_residuals` (the pressure residual is
zero by construction: ``p >= 0`` and ``p = 0`` off ``S``).
"""
import numpy as np
from mpi4py import MPI

from petgap.io import solver_registry as registry
from petgap.mechanics.problem import Load, MeanGap
from petgap.parallel.collective import global_sums
from petgap.parallel.grid import row_blocks
from petgap.parallel.log import GAP_PASS_EVENT, SET_UPDATE_EVENT, event
from petgap.solvers import _contact_set as _cs
from petgap.solvers.contact_limits import touching_state
from petgap.solvers.contact_set import INDEX
from petgap.solvers.convergence import BestResidual, Timer, judge
from petgap.solvers.preconditioners import StepTransforms, make_preconditioner
from petgap.solvers.pressure_start import choose_start
from petgap.solvers.settings import SolverSettings

#: In an iteration without the patch interaction in the preconditioner,
#: conjugacy is dropped (a steepest-descent restart) when more points than this
#: fraction of the contact set enter it; in one with it, whenever a point enters
#: (Polonsky and Keer's own rule, 0).  See "Restarts" in the module docstring.
RESTART_FRACTION = 0.003
#: A single-precision solve stops as ``"stalled_round_off"`` when its residual
#: has not fallen below ``STALL_FACTOR`` times its best for ``STALL_ITERATIONS``
#: iterations (see "Precision" in the module docstring).  Far from the floor
#: the residual falls by about half per iteration, so the rule never fires there.
STALL_ITERATIONS = 20
STALL_FACTOR = 0.9
#: Fresh transforms of ``u = K^{-1} p`` at least this often, so that the
#: round-off of the recurrence cannot accumulate.
REFRESH_INTERVAL = 50


def polonsky_keer(problem, control, settings=SolverSettings(), *, initial_pressure=None,
                  monitor=None, retarget=None):
    """Solve non-adhesive contact under load, mean-gap or indentation control.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
        Must be non-adhesive.
    control : Load, MeanGap or Indentation
        What :mod:`petgap.io.solver_registry` lets ``pcg-pressure`` take; a mean gap on a
        periodic cell only (on a free boundary it is reached through the indentation:
        :func:`petgap.solvers.indentation.solve_mean_gap_by_indentation`).
    settings : petgap.solvers.settings.SolverSettings
        Tolerance (of the gap KKT residual ``max|g on S|, max(-g off S)`` over
        ``h0``), iteration limit, start and preconditioner.
    initial_pressure : ndarray, optional
        Warm start (e.g. the previous step of a sweep); copied.
    monitor : callable, optional
        ``monitor(iteration, residual)`` on every rank at every iteration.
    retarget : callable, optional
        Under indentation, ``retarget(cg, residual)`` on every iteration that would
        carry on or stop converged: None to hold the depth, or a new offset of
        ``g = u - h + offset``, to which :meth:`PressureCG.move_depth` moves the
        iterate (a move costs an iteration; the solve converges only on an
        iteration the rule holds).  Collective: the rule must answer alike on every
        rank (:class:`petgap.solvers.indentation.DepthForMeanGap`).

    Returns
    -------
    petgap.mechanics.problem.ContactSolution
    """
    timer = Timer()
    load, target, offset = _control_target(problem, control)
    if target == 0 and not isinstance(control, MeanGap):
        return touching_state(problem, control, timer)
    transforms = StepTransforms(problem, settings.search_precision)
    start, description = choose_start(problem, control, settings, initial_pressure, load,
                                      polonsky_keer)
    cg = PressureCG(problem, settings, monitor, load, target, offset, retarget)
    start_time = timer()
    start_ops = problem.operator_applications
    cg.begin(start, transforms)
    cg.iterate()
    return cg.result(control, start=description, start_time=start_time, timer=timer,
                     start_ops=start_ops)


def _control_target(problem, control):
    """``(load, target, offset)``: the control's value and the offset of ``g = u - h + offset``.

    Under load the offset follows from the set at every iteration (0 here); on a
    periodic cell ``u`` has zero mean, so a mean gap fixes it; on a free boundary
    the indentation depth does.  What the solver takes is the registry's to say
    (:mod:`petgap.io.solver_registry`); a mean gap on a free boundary is reached
    through the indentation, one level up.
    """
    periodic = problem.half_space.periodic
    registry.check(registry.Case(solver="pcg-pressure", adhesive=problem.interaction.adhesive,
                                 periodic=periodic, **registry.control_words(control)))
    if isinstance(control, MeanGap) and not periodic:
        raise ValueError("on a free boundary the mean gap is reached through the "
                         "indentation (petgap.solvers.indentation)")
    target = float(control.value)
    offset = {"load": 0.0, "mean-gap": problem.mean_height + target,
              "indentation": problem.top_height - target}[control.kind]
    return isinstance(control, Load), target, offset


class PressureCG:
    """The projected, preconditioned conjugate gradients on the pressure (module docstring).

    The state of one solve: the contact set with ``p`` and the direction ``t`` on
    it, the displacement ``u = K^{-1} p`` in the padded layout, and the scalars of
    the recurrence.  :meth:`begin` takes the first set from a start, :meth:`iterate`
    runs to a verdict, :meth:`result` makes the solution.  The preconditioner is an
    object (:mod:`petgap.solvers.preconditioners`) called once per iteration.
    """

    def __init__(self, problem, settings, monitor, load, target, offset, retarget=None):
        grid = problem.grid
        self.problem, self.settings, self.monitor = problem, settings, monitor
        self.grid, self.comm, self.h = grid, grid.comm, problem.topography
        self.dtype = self.h.dtype   # every field and set vector in it, sums in double
        self.load, self.target, self.offset = load, target, offset
        self.n, self.ny = grid.npoints, grid.ny
        self.padded_width = grid.padded.shape[1]
        self.mask = np.zeros(grid.local_shape, dtype=np.uint8)
        self.shift, self.scale = 0.0, 1.0
        self.fresh, self.since_fresh = True, 0
        self.history = []
        self.converged, self.reason, self.it = False, "max_iterations", 0
        self.best = BestResidual(STALL_FACTOR)
        self.retarget = retarget   # polonsky_keer's, or None
        self.punch_scale = None    # move_depth's, found at the first move
        self._u = None

    @property
    def u(self):
        """``u = K^{-1} p`` in the padded layout the transform writes (made when first asked)."""
        if self._u is None:
            self._u = self.grid.aligned_padded()
        return self._u

    def begin(self, start, transforms):
        """Take the first contact set from ``start`` and make the preconditioner."""
        begun = start.begin(self)
        self.contact = begun.contact
        self.overlap = np.empty(max(1024, self.n // (100 * self.comm.size)), dtype=INDEX)
        if self._u is None:   # after a warm start's set, before the preconditioner's fields
            self._u = self.grid.aligned_padded()
        self.transforms = transforms
        self.preconditioner = make_preconditioner(self.problem, self.mask, transforms,
                                                  self.settings, self.load)
        self.scale, self.delta, self.g_old = begun.scale, begun.delta, begun.g_old
        self.history.extend(begun.history)
        self.first = begun.first

    def iterate(self):
        """Iterate to a verdict (stored in ``converged``, ``reason``, ``it``)."""
        for self.it in range(self.first, self.settings.max_iterations + 1):
            if self.fresh:
                self._transform_u()
            else:
                self.since_fresh += 1
            n_contact, g_norm, residual = self._gap_pass()
            verdict = judge(residual, self.settings.tolerance, self.fresh, self.it,
                            self.settings.max_iterations, self.history, self.monitor,
                            self._objective)
            if verdict == "refresh":
                self.fresh, self.scale = True, 1.0
                continue
            if verdict in ("", "converged_kkt") and self.retarget is not None:
                offset = self.retarget(self, residual)
                if offset is not None:
                    self.move_depth(offset)
                    continue
            if verdict:
                self.converged, self.reason = verdict == "converged_kkt", verdict
                return
            if self.preconditioner.withdraws(self.it, residual):
                self.delta = 0.0   # a new preconditioner: restart
            if self._stalled(residual):
                self.reason = "stalled_round_off"
                return
            if n_contact == 0 or (self.load and n_contact == 1):
                self._admit_overlap()
                continue
            if not self._step(n_contact, g_norm, residual):
                self.reason = "breakdown"
                return

    def move_depth(self, offset):
        """Move the offset of ``g = u - h + offset`` to ``offset``, and the pressure with it.

        On a fixed contact set ``S`` an indentation's pressure is affine in the
        depth, with the flat punch on ``S``, ``y = C_SS^{-1} 1_S`` (``C = K^{-1}``), for
        derivative: moved along ``y``, the pressure keeps the gap on ``S`` at zero and
        the iteration keeps its residual.  ``y`` costs a solve; the preconditioner
        applied to ``1_S`` approximates it for one transform pair: the stiffness
        restricted to ``S``, ``P_S K 1_S``, has a punch's shape on each patch (large at
        its edges, small inside it), and the patch interaction shares the force between
        the patches (:meth:`~petgap.solvers.preconditioners.RestrictedStiffness.punch`).
        It is used in ``y``'s place, scaled so that its displacement has unit mean on
        ``S`` (one more pair, at the first move only: the scale barely moves with the
        set).  A pressure scaled with the move instead, whose displacement on ``S``
        is the topography's and far from uniform, leaves a residual several times
        the one the move started from.  A point the move pulls to zero pressure
        leaves ``S``.  The conjugate gradients restart from a fresh ``u``, and the
        residual's rise the move leaves does not withdraw the patch interaction from
        the preconditioner (:meth:`~petgap.solvers.preconditioners.PatchAdmission.moved`).
        Collective.
        """
        contact = self.contact
        shape = contact.z   # scratch until the next preconditioned gap
        self.transforms.stiffness(contact.pidx, np.ones(len(contact.idx), dtype=self.dtype),
                                  shape)
        self.preconditioner.punch(contact, shape)
        if self.punch_scale is None:
            image = np.empty(len(shape), dtype=self.dtype)
            self.problem.half_space.apply_sparse(contact.pidx, shape, inverse=True,
                                                 gathered=image)
            n_contact, total = global_sums(self.comm, len(shape),
                                           float(image.sum(dtype=np.float64)))
            if n_contact > 0 and total > 0:
                self.punch_scale = n_contact / total
        if self.punch_scale is not None:
            # the step's own kernel: p <- max(p - tau shape, 0), no pressure to overlaps
            clipped = _cs.update(contact.p, shape, contact.g,
                                 (offset - self.offset) * self.punch_scale, 0.0)[1]
            if clipped:
                contact.merge(np.empty(0, dtype=INDEX), np.empty(0, dtype=self.dtype))
        self.offset = offset
        self.delta, self.fresh = 0.0, True
        self.preconditioner.moved()

    def _transform_u(self):
        """``u = K^{-1} p`` from scratch: one transform pair, from ``S`` to ``u``."""
        if self.scale != 1.0:
            self.contact.p[...] *= self.scale
            self.scale = 1.0
        self.problem.half_space.apply_sparse(self.contact.pidx, self.contact.p, inverse=True,
                                             out=self.u)
        self.since_fresh = 0

    def _gap_pass(self):
        """The gap on ``S`` and the penetration off it: ``(|S|, (g, g), residual)``.

        Under load the gap is shifted to zero mean on ``S`` (the offset the load
        leaves free); the points that penetrate off ``S`` are listed in ``overlap``.
        """
        contact, u, h = self.contact, self.u, self.h
        with event(GAP_PASS_EVENT):
            sum_g = _cs.gather_gap(u, contact.pidx, h, contact.idx, self.offset, contact.g)
        n_contact, sum_g = global_sums(self.comm, len(contact.idx), sum_g)
        self.shift = sum_g / n_contact if (self.load and n_contact > 0) else 0.0
        with event(GAP_PASS_EVENT):
            in_max, g_norm = _cs.shift_and_norms(contact.g, self.shift)
            pen_max, self.n_over = _cs.gap_pass(u, h, self.mask, self.offset - self.shift,
                                                self.overlap)
            if self.n_over > len(self.overlap):
                self.overlap = np.empty(2 * self.n_over, dtype=INDEX)
                _cs.collect_overlap(u, h, self.mask, self.offset - self.shift, self.overlap)
        norms = np.array([in_max, pen_max])
        self.comm.Allreduce(MPI.IN_PLACE, norms, op=MPI.MAX)
        return n_contact, g_norm, float(norms.max()) / self.problem.gap_scale

    def mean_gap(self, projected=False):
        """The mean over the map of the iterate's gap ``u - h + offset``, or with
        ``projected`` of its projection onto the contact state (0 on ``S``, ``>= 0`` off
        it: what :meth:`result` stores).  Collective; a pass over ``u`` and ``h``."""
        local, offset = 0.0, self.offset - self.shift
        for rows in row_blocks(len(self.h), ncols=self.ny):
            g = self.u[rows, :self.ny] - self.h[rows] + offset
            if projected:
                np.maximum(g, 0.0, out=g)
                g[self.mask[rows].view(bool)] = 0.0
            local += float(g.sum(dtype=np.float64))
        return global_sums(self.comm, local)[0] / self.n

    def _objective(self):
        """The complementary energy ``(1/2) <p, K^-1 p> - <p, h - offset>`` of the iterate.

        From the gap on ``S``, ``g = K^-1 p - h + offset - shift``:
        ``(1/2) sum p (g - h + offset + shift) dx dy``.  Collective.
        """
        contact = self.contact
        local = float(np.dot(contact.p, contact.g - self.h.ravel()[contact.idx] + self.offset
                             + self.shift))
        return 0.5 * self.grid.pixel_area * global_sums(self.comm, local)[0]

    def _stalled(self, residual):
        """A single-precision solve whose residual wanders at its round-off floor."""
        if self.dtype != np.float32:
            return False
        return self.best.since(self.it, residual) >= STALL_ITERATIONS

    def _admit_overlap(self):
        """Let the points where the surfaces overlap into ``S``, at their overlap's pressure.

        Mean-gap control with no contact yet, or load control on a single contact
        point (e.g. warm-started from a one-pixel contact), where no direction has
        zero mean over ``S`` and the step would break down; ``scale`` restores the load.
        """
        problem, contact = self.problem, self.contact
        g = self.u[:, :self.ny] - self.h + (self.offset - self.shift)
        g.ravel()[contact.idx] = 0.0
        points = np.flatnonzero(g < 0)
        extra = -g.ravel()[points] * (problem.pressure_scale / problem.gap_scale)
        del g
        contact.merge(points, extra)
        total = global_sums(self.comm, contact.p.sum(dtype=np.float64))[0]
        self.scale = self.target * self.n / total if self.load else 1.0
        self.delta, self.fresh = 0.0, True

    def _step(self, n_contact, g_norm, residual):
        """One conjugate-gradient step from the gap on ``S``; False on a breakdown."""
        contact = self.contact
        # under load control, the kept direction's sum over the present S (its mean is
        # taken off the new one: "Step length" in the module docstring)
        old_t_sum = (float(contact.t.sum(dtype=np.float64)) if self.load and self.delta != 0.0
                     else 0.0)
        pre = self.preconditioner.apply(contact, n_contact, g_norm, old_t_sum, residual,
                                        self.it)
        if pre.restart:
            self.delta = 0.0
        beta = self.delta * pre.gz / self.g_old
        self.g_old = pre.gz
        sum_gt, sum_rt = self._direction(pre, beta, n_contact)
        if not sum_rt > 0:
            return False
        self._update(sum_gt / sum_rt, pre.stiffness, n_contact)
        return True

    def _direction(self, pre, beta, n_contact):
        """The new direction ``t`` on ``S`` and its step sums ``((g, t), (t, K^{-1} t))``.

        Under load control ``t`` has zero mean on ``S`` (the old direction's mean on
        the present ``S`` taken off with ``z``'s), so that a step along it keeps the
        load.  A kept direction that does not descend, ``(g, t) <= 0`` (``S`` changed
        since the last restart), is replaced by the steepest one.
        """
        contact = self.contact
        while True:
            _cs.direction(pre.z, pre.zshift + beta * pre.t_sum / n_contact, beta, contact.t)
            sum_gt, sum_rt = self.transforms.step_sums(contact.pidx, contact.g, contact.t)
            if sum_gt > 0 or beta == 0.0:
                return sum_gt, sum_rt
            beta = 0.0

    def _update(self, tau, stiffness, n_contact):
        """``p <- max(p - tau t, 0)`` on ``S``, penetrating points in, the load restored.

        Points that penetrate off ``S`` enter with the pressure ``tau`` times the
        stiffness's Rayleigh quotient times their penetration.  Where the set is
        unchanged and nothing was projected, ``u`` follows ``p`` by the recurrence
        ``u <- s (u - tau r)`` and the next fresh transform is skipped.
        """
        contact, overlap = self.contact, self.overlap
        with event(SET_UPDATE_EVENT):
            entering, clipped, sum_p = _cs.update(contact.p, contact.t, contact.g, tau,
                                                  tau * stiffness)
            added = overlap[:min(self.n_over, len(overlap))]
            added_p = np.empty(len(added), dtype=self.dtype)
            sum_p += _cs.overlap_pressures(self.u, self.h, added, self.offset - self.shift,
                                           tau * stiffness, added_p)
        n_overlap, n_clipped, sum_p = global_sums(self.comm, entering + len(added), clipped,
                                                  sum_p)
        self.delta = 0.0 if n_overlap > self._entering_allowed(n_contact) else 1.0
        self.preconditioner.observe_step(n_overlap + n_clipped, n_contact)
        self.scale = self.target * self.n / sum_p if self.load else 1.0
        if clipped or len(added):
            contact.merge(added, added_p)
        self.fresh = (n_overlap > 0 or n_clipped > 0
                      or self.since_fresh >= REFRESH_INTERVAL)
        if not self.fresh:
            self.transforms.finish()
            _cs.recurrence(self.u, self.transforms.image, tau, self.scale, self.ny)
            contact.p[...] *= self.scale
            self.scale = 1.0

    def _entering_allowed(self, n_contact):
        """How many entering points keep conjugacy: none with the patch interaction in use,
        else :data:`RESTART_FRACTION` of ``S`` ("Restarts" in the module docstring)."""
        return (0 if self.preconditioner.patch_used else RESTART_FRACTION) * n_contact

    def result(self, control, *, start, start_time, timer, start_ops):
        """The solution of the contact state found (collective).

        ``start`` and ``start_time`` say how the start was found and what it took,
        ``timer`` the wall time since the solve began, ``start_ops`` the operator
        applications before the iterations.

        Residuals are taken on the gap as computed; the stored field (and the
        scalars derived from it) is its projection onto the contact state found:
        exactly 0 in contact, >= 0 elsewhere, within the reported ``kkt_gap h0``.
        The pressure residual is zero by construction (``p > 0`` on ``S``, 0 off it).
        """
        # kappa and the patch data are freed before the result's fields are made.  The
        # pressure is a fresh zeroed slab: the pages of its non-contact regions are never
        # written, so they cost neither resident memory nor a first touch
        self.preconditioner.release()
        problem, grid = self.problem, self.grid
        # the gap is written over u, compacted to the unpadded layout in place: row i
        # moves to where it starts at or before its old place, so nothing is overwritten
        # before it is read
        g = grid.scratch(self.u)
        on, off = _cs.final_gap(self.u, self.h, self.mask, self.offset - self.shift, g)
        self._u = None
        residual = self.comm.allreduce(float(np.max([on, off])), op=MPI.MAX)
        p = np.zeros(grid.local_shape, dtype=self.dtype)
        p.ravel()[self.contact.idx] = self.contact.p
        contact = self.mask.view(bool)  # 0 or 1: a valid boolean array, no copy
        return problem.make_solution(
            g, p, contact, control, converged=self.converged, reason=self.reason,
            solver="pcg-pressure", iterations=self.it, wall_time=timer(), history=self.history,
            operator_applications=problem.operator_applications - start_ops,
            residuals=(0.0, residual / problem.gap_scale), start=start, start_time=start_time,
            # g = u - h + d with u = C p: on a free boundary d is the rigid body's position
            approach=(float("nan") if problem.half_space.periodic
                      else problem.top_height - (self.offset - self.shift)))
