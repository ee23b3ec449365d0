"""Constrained conjugate gradients on the contact pressure (Polonsky & Keer 1999).

Polonsky & Keer, Wear 231 (1999) 206, with the mean-gap variant and the
notation of Rey, Anciaux & Molinari, Comput. Mech. 60 (2017) 69.  The unknown is
the pressure ``p >= 0``; the gap it implies is ``g = K^{-1} p - h + d``.  The
method runs conjugate gradients on the complementary energy restricted to the
contact set ``S = {p > 0}``, projects onto ``p >= 0`` after each step, and
restarts (steepest descent) whenever points that penetrate the surface enter
the contact set.  Each iteration costs two elastic operator applications (two
FFT pairs).

* Load control: ``mean(p) = P0`` is kept by rescaling ``p`` after each step,
  and ``d`` is chosen so that the mean gap over ``S`` vanishes.
* Mean-gap control: ``d = g_bar + mean(h)`` follows from ``mean(g) = g_bar``
  (``K^{-1} p`` has zero mean), no rescaling; ``mean(p)`` is the multiplier.

Preconditioning (petgap's addition)
-----------------------------------
The compliance ``K^{-1}`` (symbol ``2 / (E* |q|)``) restricted to the contact
set has a condition number that grows like ``L / a0``, which is why plain
Polonsky-Keer needs more iterations on finer grids.  Its opposite-order
partner, the stiffness ``K`` (symbol ``E* |q| / 2``) restricted to the same set,
is an almost exact inverse up to edge effects, leaving a condition number that
grows only like ``log^2(L / a0)`` -- operator preconditioning of first-kind
boundary integral equations (Steinbach & Wendland, Adv. Comput. Math. 9 (1998)
191; Hiptmair, Jerez-Hanckes & Urzua for screens).  With
``z = P_S K P_S g`` the iteration count stays nearly flat with resolution at the
price of a third transform pair per iteration (two once the contact set has
settled, see below).

When an iteration changes no point of the contact set (no projection, no
point enters), ``K^{-1} p`` follows ``p`` by the conjugate-gradient recurrence
``u <- s (u - tau r)`` and the next fresh transform is skipped; a fresh
transform is forced every 50 such steps and before any verdict, so round-off
cannot accumulate into the answer.

The contact set is stored as sorted index lists, with the pressure and the
conjugate direction kept on it only (``petgap/_contact_set.pyx``): at a few
percent contact an iteration then streams the slab through memory once (the
gap pass) besides the transforms, instead of half a dozen times.  The
displacement ``u = K^{-1} p`` is the one full field kept between iterations;
the gap ``g = u - h + d`` is recomputed where it is needed.

Convergence is judged at the start of an iteration, on the pair ``(p, g)`` the
iteration starts from, by the gap residual of
:meth:`petgap.contact.ContactProblem.kkt_residuals` (the pressure residual is
zero by construction: ``p >= 0`` and ``p = 0`` off ``S``).
"""
import numpy as np
from mpi4py import MPI

from . import _contact_set as _cs
from .contact import Load, MeanGap, Timer


_EMPTY = np.empty(0)
_EMPTY_INDEX = np.empty(0, dtype=np.int64)


def _sums(comm, *values):
    buf = np.array(values, dtype=float)
    comm.Allreduce(MPI.IN_PLACE, buf, op=MPI.SUM)
    return buf


def polonsky_keer(problem, control, *, tolerance=1e-8, max_iterations=10000,
                  initial_pressure=None, monitor=None, preconditioned=True,
                  cold_start="uniform"):
    """Solve non-adhesive contact under load or mean-gap control.

    Parameters
    ----------
    problem : petgap.contact.ContactProblem
        Must be non-adhesive.
    control : Load or MeanGap
    tolerance : float
        Target for the gap KKT residual ``max|g on S|, max(-g off S)`` over ``h0``.
    max_iterations : int
    initial_pressure : ndarray, optional
        Warm start (e.g. the previous step of a sweep); copied.
    monitor : callable, optional
        ``monitor(iteration, residual)`` on every rank at every iteration.
    preconditioned : bool
        Precondition the conjugate gradients with the stiffness restricted to
        the contact set, ``z = P_S K P_S g`` (see the module docstring).
    cold_start : {"uniform", "rigid"}
        Load control without ``initial_pressure``: a uniform pressure (every
        point in the initial contact set), or :func:`_rigid_pressure`.  The
        rigid start needs fewer iterations and less memory at 512^2-4096^2,
        but on the GUIDE surface at 8192^2 it stalled (residual about 2.5 after
        670 iterations) where the uniform start converges in 154, so it is not
        the default until that is understood.

    Returns
    -------
    petgap.contact.ContactSolution
    """
    if problem.interaction.adhesive:
        raise ValueError("the Polonsky-Keer solver handles non-adhesive contact only; "
                         "use a gap-based solver for adhesion")
    grid, comm = problem.grid, problem.grid.comm
    h = problem.topography
    timer = Timer()
    refresh_interval = 50  # bound the round-off drift of the u recurrence
    n = grid.npoints
    load = isinstance(control, Load)
    if load:
        target = float(control.mean_pressure)
        if target == 0:
            return touching_state(problem, control, timer)
        if not target > 0:
            raise ValueError(f"mean pressure {target} < 0: a non-adhesive interface cannot "
                             f"carry a tensile load; use a positive load or an adhesive interaction")
    elif isinstance(control, MeanGap):
        target = float(control.mean_gap)
        if not target >= 0:
            raise ValueError(f"mean gap {target} < 0 is impossible with a hard wall (gap >= 0)")
    else:
        raise TypeError(f"unknown control {control!r}")

    start_ops = problem.operator_applications
    if initial_pressure is not None:
        p = np.maximum(np.asarray(initial_pressure, dtype=float), 0.0)
    elif load and cold_start == "rigid":
        p = _rigid_pressure(problem, target)
    elif load:
        p = np.full(grid.local_shape, target)
    else:
        # Rigid approach: pressure where the undeformed surfaces overlap.
        overlap = h - problem.mean_height - target
        p = np.maximum(overlap, 0.0) * (problem.pressure_scale / problem.gap_scale)
    if load:
        p *= target / grid.mean(p) if grid.mean(p) > 0 else 1.0
        if grid.mean(p) <= 0:
            p[...] = target
    offset = problem.mean_height + target if not load else 0.0

    # The contact set S = {p > 0} as sorted index lists, with p and the
    # conjugate direction t stored on S only (see petgap/_contact_set.pyx).
    mask = np.zeros(grid.local_shape, dtype=np.uint8)
    padded = grid._padded
    padded_width = padded.shape[1]
    start = np.flatnonzero(p > 0)
    idx, pidx, pS, tS = _cs.merge(_EMPTY_INDEX, _EMPTY, _EMPTY, start, p.ravel()[start], mask,
                                  padded_width)
    del p, start
    gS, zS = np.empty_like(pS), np.empty_like(pS)
    overlap = np.empty(max(1024, n // (100 * comm.size)), dtype=np.int64)
    u = np.empty(grid.local_shape)
    half_space = problem.half_space
    scale, fresh = 1.0, True
    since_fresh = 0
    delta, g_old, shift = 0.0, 1.0, 0.0
    history = []
    converged, reason, it = False, "max_iterations", 0
    for it in range(max_iterations + 1):
        if len(gS) != len(pS):
            gS, zS = np.empty_like(pS), np.empty_like(pS)
        if fresh:
            # u = K^{-1} p from scratch: one transform pair
            if scale != 1.0:
                pS *= scale
                scale = 1.0
            _cs.fill(padded, pidx, pS, 1.0)
            half_space.apply_in_buffer(inverse=True)
            problem.operator_applications += 1
            src, sidx = padded, pidx
            since_fresh = 0
        else:
            src, sidx = u, idx
            since_fresh += 1
        n_contact, sum_g = _sums(comm, len(idx), _cs.gather_gap(src, sidx, h, idx, offset, gS))
        shift = sum_g / n_contact if (load and n_contact > 0) else 0.0
        in_max, g_norm = _cs.shift_and_norms(gS, shift)
        pen_max, n_over = _cs.gap_pass(src, h, mask, u, fresh, offset - shift, padded,
                                       preconditioned, overlap)
        if n_over > len(overlap):
            overlap = np.empty(2 * n_over, dtype=np.int64)
            _cs.collect_overlap(u, h, mask, offset - shift, overlap)
        norms = np.array([in_max, pen_max])
        comm.Allreduce(MPI.IN_PLACE, norms, op=MPI.MAX)
        residual = float(norms.max()) / problem.gap_scale
        if not np.isfinite(residual):
            reason = "diverged_nan"
            break
        if residual <= tolerance and not fresh:
            # Verdicts are only given on a freshly evaluated displacement.
            fresh, scale = True, 1.0
            continue
        history.append(residual)
        if monitor is not None:
            monitor(it, residual)
        if residual <= tolerance:
            converged, reason = True, "converged_kkt"
            break
        if it >= max_iterations:
            break
        if n_contact == 0 or (load and n_contact == 1):
            # Mean-gap control with no contact yet, or load control on a single
            # contact point (e.g. warm-started from a one-pixel contact), where no
            # direction has zero mean over S and the step would break down: let the
            # points where the surfaces overlap into S; `scale` restores the load.
            g = u - h + (offset - shift)
            g.ravel()[idx] = 0.0
            points = np.flatnonzero(g < 0)
            extra = -g.ravel()[points] * (problem.pressure_scale / problem.gap_scale)
            idx, pidx, pS, tS = _cs.merge(idx, pS, tS, points, extra, mask, padded_width)
            del g
            scale = target * n / _sums(comm, pS.sum())[0] if load else 1.0
            delta, fresh = 0.0, True
            continue
        if preconditioned:
            # z = P_S K P_S g (one pair; gap_pass left P_S g in the buffer),
            # made zero-mean on S under load control
            half_space.apply_in_buffer(inverse=False)
            problem.operator_applications += 1
            sum_z, g_norm = _sums(comm, *_cs.gather_sums(padded, pidx, gS, zS))
            zshift = sum_z / n_contact if load else 0.0
            _cs.direction(zS, zshift, delta * g_norm / g_old, tS)
        else:
            g_norm = _sums(comm, g_norm)[0]
            _cs.direction(gS, 0.0, delta * g_norm / g_old, tS)
        g_old = g_norm
        # The image r = K^{-1} t of the direction: one transform pair
        _cs.fill(padded, pidx, tS, 1.0)
        half_space.apply_in_buffer(inverse=True)
        problem.operator_applications += 1
        sum_r, sum_gt, sum_rt, sum_t = _sums(comm, *_cs.step_sums(padded, pidx, gS, tS))
        if load:
            sum_rt -= sum_r / n_contact * sum_t  # r minus its mean over S
        if not sum_rt > 0:
            reason = "breakdown"
            break
        tau = sum_gt / sum_rt
        entering, clipped, sum_p = _cs.update(pS, tS, gS, tau)
        added = overlap[:min(n_over, len(overlap))]
        added_p = np.empty(len(added))
        sum_p += _cs.overlap_pressures(u, h, added, offset - shift, tau, added_p)
        n_overlap, n_clipped, sum_p = _sums(comm, entering + len(added), clipped, sum_p)
        delta = 0.0 if n_overlap > 0 else 1.0
        scale = target * n / sum_p if load else 1.0
        if clipped or len(added):
            idx, pidx, pS, tS = _cs.merge(idx, pS, tS, added, added_p, mask, padded_width)
        # Same contact set, no projection: u follows p linearly, no transform needed.
        fresh = n_overlap > 0 or n_clipped > 0 or since_fresh >= refresh_interval
        if not fresh:
            _cs.recurrence(u, padded, tau, scale)
            pS *= scale
            scale = 1.0

    # Residuals are taken on the gap as computed; the stored field (and the
    # scalars derived from it) is its projection onto the contact state found:
    # exactly 0 in contact, >= 0 elsewhere, within the reported kkt_gap h0.
    g = u
    g -= h
    g += offset - shift
    p = np.zeros(grid.local_shape)
    p.ravel()[idx] = pS
    contact = mask.astype(bool)
    residuals = problem.kkt_residuals(g, p, contact)
    g[contact] = 0.0
    np.maximum(g, 0.0, out=g)
    return problem.make_solution(
        g, p, contact, control, converged=converged, reason=reason,
        solver="pcg-pressure", iterations=it, wall_time=timer(), history=history,
        operator_applications=problem.operator_applications - start_ops, residuals=residuals)


def _rigid_pressure(problem, target):
    """A cold start for load control: the rigid approach that carries the load.

    ``p = k max(h - d, 0)`` with the contact stiffness ``k = h0' E* / h0`` of
    the control's unit-free measures, and the level ``d`` found by Newton's
    method so that ``mean(p) = target``.  It puts the initial contact set
    near the summits that will carry the load, instead of everywhere as a
    uniform pressure would: the first iterations then work on a contact set
    of the order of the final one, which keeps the index lists (and the peak
    memory) small.  Newton from below on the convex, decreasing, piecewise
    linear ``mean(max(h - d, 0))`` increases monotonically to the root.
    """
    grid, comm, h = problem.grid, problem.grid.comm, problem.topography
    k = problem.pressure_scale / problem.gap_scale
    wanted = target / k * grid.npoints
    level = comm.allreduce(float(h.min()) if h.size else np.inf, op=MPI.MIN)
    total, count = _sums(comm, *_cs.overlap_sums(h, level))
    if total <= wanted:
        # Even full overlap carries less: the whole surface is in contact.
        level = float(problem.mean_height) - target / k
    for _ in range(100):
        if count == 0 or total <= wanted * (1 + 1e-12):
            break
        level += (total - wanted) / count
        total, count = _sums(comm, *_cs.overlap_sums(h, level))
    p = np.maximum(h - level, 0.0)
    p *= k
    return p


def touching_state(problem, control, timer=None):
    """Zero load: the surfaces touch at the highest point and carry nothing."""
    grid = problem.grid
    top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
    gap = top - problem.topography
    pressure = np.zeros(grid.local_shape)
    return problem.make_solution(gap, pressure, pressure > 0, control, converged=True,
                                 reason="zero_load", solver="pcg-pressure", iterations=0,
                                 operator_applications=0,
                                 wall_time=timer() if timer is not None else 0.0)
