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
price of one more transform pair per iteration (see "Step length" below).  The
edge effects are the diagonal term ``kappa = K 1_S`` that the zero extension of
``g`` across the contact edge adds to the stiffness; the preconditioner takes a
share of it off,
``z = P_S K P_S g - theta kappa g`` (:mod:`petgap.solvers.edge_correction`,
``edge_correction``), which lowers the edge eigenvalues.  What the local
stiffness cannot see is the far field by which the contact patches press on
each other: on a periodic cell the preconditioner also takes off a model of
that interaction, solved on a grid of blocks of ``interaction_block`` pixels
(:mod:`petgap.solvers.patch_interaction`), which keeps the preconditioned
condition number from growing with the number of patches across the cell.  It
does so under load control; under mean-gap control, at contact fractions beyond
a half, it took more iterations than it saved (docs/benchmarks.md, "The
preconditioner's patch interaction"), and there it is not made.
That term is smooth over whole blocks, and the projection onto ``p >= 0`` that
follows each step is not: while the contact set is still moving it shifts the
pressure of many small patches at once, which the projection then clips, and
on surfaces with patches of a few pixels the set can swing without converging.
So the term enters only in an iteration after one that changed at most
:data:`SETTLED_FRACTION` of ``S`` (:func:`settled_fraction`: less where the blocks are
larger than 32 pixels).  On a set that has settled a step with it is
nearly a Newton step and the residual after it falls (the residual is a
maximum over points and may rise a little after a good step).  Where it rises
by more than :data:`RISE_FACTOR`, the step moved more of the set than it
settled (on large cells, where the far field is strong, a few tenths of a
percent of ``S`` can swing back and forth for dozens of iterations), and the
term is withdrawn until an iteration changes at most :data:`WITHDRAWN_FACTOR`
times the fraction that let it in, so that each withdrawal waits for a more
settled set than the last (docs/benchmarks.md, "The preconditioner's patch
interaction").  Each switch restarts the conjugate gradients, and each
withdrawal is logged.

Restarts (petgap's change to the method)
----------------------------------------
Polonsky and Keer restart the conjugate gradients whenever a point enters
``S``.  Past the first few iterations of a start from a coarser grid, a few
points enter at almost every iteration -- the contact edges move by a pixel
here and there -- so the method degrades to preconditioned steepest descent
while the edges settle.  In an iteration with the patch interaction in the
preconditioner that is what works best: its steepest-descent steps are
nearly Newton steps, and conjugacy kept across changes of ``S`` slows the
final phase to the rate of a condition number several times the true one.
Without it (before the set has settled, under mean-gap control, on a free
boundary, or with ``interaction_block = 0``), steepest descent is slow, and
conjugacy is kept unless more than :data:`RESTART_FRACTION` of ``S`` enters in
one iteration: the few entering points perturb the subspace the directions
were conjugate in, and the step's exact line search still minimises along
the new direction.  A direction that is not a descent direction, ``(g, t) <=
0``, is caught after its transform and replaced by the steepest one.  The
rules are tuning choices: docs/benchmarks.md ("Restarts") has the iteration
counts for both preconditioners under each rule, and
``benchmarks/robustness.py`` checks that every solve of the robustness set
converges.

Step length
-----------
The exact line search ``tau = (g, t) / (t, K^{-1} t)`` needs the direction's
image ``r = K^{-1} t`` only through ``(t, r)``, which by Parseval is
``sum_q 2 |t_q|^2 / (E* |q| N)``: the forward half of the transform
(:meth:`petgap.mechanics.half_space.ElasticHalfSpace.begin_sparse`).  The
inverse half is run only when the iteration changes no point of the contact
set (no projection, no point enters): then ``K^{-1} p`` follows ``p`` by the
conjugate-gradient recurrence ``u <- s (u - tau r)``, and the next fresh
transform of ``u`` is skipped; a fresh transform is forced every 50 such steps
and before any verdict, so round-off cannot accumulate into the answer.  An
iteration that changes the set costs two and a half pairs (``z``, the half of
``r``, the fresh ``u``), one that does not two (``z``, ``r``).  Under load
control the direction is kept at zero mean over ``S`` (the old direction's
mean over the present set is taken off with ``z``'s), so that a step along it
keeps the load and ``(t, r)`` needs no correction for the mean of ``r`` over
``S``.  A half-space without the halves (a free boundary) images the direction
whole.

The contact set is stored as sorted index lists, with the pressure, the
conjugate direction, the gap and the preconditioned gap kept on it only
(:mod:`petgap.solvers.contact_set`, kernels in ``petgap/solvers/_contact_set.pyx``), and the
transforms take their input from those lists and, for ``P_S K P_S g``, give
their output back on them (:meth:`petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse`):
at a few percent contact an iteration then streams the slab through memory
once (the gap pass, which only reads) besides the transforms, instead of half
a dozen times.  The displacement ``u = K^{-1} p`` is the one full field kept
between iterations, in the padded layout the transform writes it in; the gap
``g = u - h + d`` is recomputed where it is needed.

Cold start: from the solution on a grid twice as coarse where the
grid's shape allows (:mod:`petgap.solvers.coarse`, driven by
:func:`coarse_start_pressure`), otherwise, under load control, from a uniform pressure.  The
uniform start's first iteration has a closed form
(:func:`_uniform_first_iteration`: one transform instead of two and a half, and no
set of every point), after which about 60 % of the points are in S on rough
surfaces; the set shrinks from there by some 20 % per iteration, updated in
place, so its peak is one copy of that first set (32 bytes per point of it).
A start nearer the answer built from the geometry alone (the rigid approach
carrying the load) saves a few iterations where it works but does not
converge on some surfaces (see the comment in :func:`polonsky_keer`).

Precision: the solver works in the precision of the problem's grid
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

On a double grid the two transforms that only find the step -- the
preconditioner's ``z`` and the direction's image ``r = K^{-1} t`` -- may run in
single precision (``search_precision="single"``, on the grid's
:meth:`~petgap.parallel.grid.Grid.single_precision_alias`, in its own
buffers, at the price of a single-precision pair).  The
pressure, the displacement ``u = K^{-1} p`` from which every verdict's gap is
taken, and every sum stay double, so the tolerance and the answer are
double's; the rounding changes the path only: the direction and step length
are those of a preconditioner and a line search accurate to about 7 digits,
and the recurrence's update ``tau r`` carries its rounding (relative to the
step, not to ``u``; a verdict is always taken on a fresh transform).  The same
solve on another number of ranks then takes another path within that rounding
and ends within the tolerance's reach of it, not within round-off
(``tests/solvers/test_search_precision.py`` measures it), so double is the
default (:data:`SEARCH_PRECISION`); mixed precision
(:mod:`petgap.solvers.mixed_precision`), whose single stage depends on the
decomposition at that level already, refines with a single search.

Convergence is judged at the start of an iteration, on the pair ``(p, g)`` the
iteration starts from, by the gap residual of
:meth:`petgap.mechanics.problem.ContactProblem.kkt_residuals` (the pressure residual is
zero by construction: ``p >= 0`` and ``p = 0`` off ``S``).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import Indentation, Load, MeanGap
from petgap.parallel.collective import global_sums
from petgap.parallel.log import GAP_PASS_EVENT, SET_UPDATE_EVENT, event, get_logger
from petgap.solvers import _contact_set as _cs
from petgap.solvers import coarse
from petgap.solvers.contact_set import INDEX, ContactSet
from petgap.solvers.convergence import Timer, judge
from petgap.solvers.edge_correction import EDGE_CORRECTION, EdgeCorrection
from petgap.solvers.patch_interaction import BLOCK, patch_interaction
from petgap.solvers.settings import SolverSettings

#: In an iteration without the patch interaction in the preconditioner,
#: conjugacy is dropped (a steepest-descent restart) when more points than this
#: fraction of the contact set enter it; in one with it, whenever a point enters
#: (Polonsky and Keer's own rule, 0).  See "Restarts" in the module docstring.
RESTART_FRACTION = 0.003
#: The patch interaction enters the preconditioner only in an iteration after
#: one that changed at most this fraction of the contact set (points clipped or
#: entering), with blocks of 32 pixels (less with larger ones:
#: :func:`settled_fraction`).  A step with it after which the residual is above
#: ``RISE_FACTOR`` times the residual before it withdraws it, and it enters again only after
#: an iteration that changed at most ``WITHDRAWN_FACTOR`` times the fraction
#: that let it in; see "Preconditioning" in the module docstring.  The residual
#: is a maximum over points, not the energy norm the conjugate gradients
#: lower, so a good step may raise it a little: ``RISE_FACTOR`` allows that.
SETTLED_FRACTION = 0.01
RISE_FACTOR = 1.2
WITHDRAWN_FACTOR = 0.1
#: A single-precision solve stops as ``"stalled_round_off"`` when its residual
#: has not fallen below ``STALL_FACTOR`` times its best for ``STALL_ITERATIONS``
#: iterations (see "Precision" in the module docstring).  Far from the floor
#: the residual falls by about half per iteration, so the rule never fires there.
STALL_ITERATIONS = 20
STALL_FACTOR = 0.9
#: Precision of the preconditioner's transform and of the direction's image on a
#: double grid (see "Precision" in the module docstring): double, so that results
#: depend on the number of ranks by round-off only.
SEARCH_PRECISION = "double"


def settled_fraction(far):
    """The fraction of ``S`` an iteration may change for the patch interaction ``far`` to enter.

    :data:`SETTLED_FRACTION` for blocks of :data:`petgap.solvers.patch_interaction.BLOCK`
    pixels a side or smaller, and that over the ratio of the block's area to theirs for
    larger ones (the 64-pixel blocks of 16384^2): a step with the term shifts the
    pressure of whole blocks, and a larger block moves more of the set per block it
    shifts, so the set must have settled further for the step to be safe.
    """
    if far is None:
        return SETTLED_FRACTION
    return SETTLED_FRACTION * min(1.0, BLOCK * BLOCK / far.block_area)


def polonsky_keer(problem, control, settings=SolverSettings(), *, initial_pressure=None,
                  monitor=None):
    """Solve non-adhesive contact under load or mean-gap control.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
        Must be non-adhesive.
    control : Load or MeanGap
    settings : petgap.solvers.settings.SolverSettings
        Tolerance (of the gap KKT residual ``max|g on S|, max(-g off S)`` over
        ``h0``), iteration limit, start and preconditioner.
    initial_pressure : ndarray, optional
        Warm start (e.g. the previous step of a sweep); copied.
    monitor : callable, optional
        ``monitor(iteration, residual)`` on every rank at every iteration.

    Returns
    -------
    petgap.mechanics.problem.ContactSolution
    """
    if problem.interaction.adhesive:
        raise ValueError("the Polonsky-Keer solver handles non-adhesive contact only; "
                         "use a gap-based solver for adhesion")
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    edge_correction, interaction_block = settings.edge_correction, settings.interaction_block
    search_precision = settings.search_precision
    grid, comm = problem.grid, problem.grid.comm
    h = problem.topography
    dtype = h.dtype   # the grid's precision: every field and set vector in it, sums in double
    timer = Timer()
    refresh_interval = 50  # bound the round-off drift of the u recurrence
    n = grid.npoints
    ny = grid.ny
    load = isinstance(control, Load)
    periodic = problem.half_space.periodic
    if load:
        target = float(control.mean_pressure)
        if target == 0:
            return touching_state(problem, control, timer)
        if not target > 0:
            raise ValueError(f"mean pressure {target} < 0: a non-adhesive interface cannot "
                             f"carry a tensile load; use a positive load or an adhesive interaction")
    elif isinstance(control, MeanGap):
        if not periodic:
            raise ValueError("on a free boundary the mean gap is reached through the "
                             "indentation (solve_mean_gap_by_indentation)")
        target = float(control.mean_gap)
        if not target >= 0:
            raise ValueError(f"mean gap {target} < 0 is impossible with a hard wall (gap >= 0)")
    elif isinstance(control, Indentation):
        if periodic:
            raise ValueError("indentation control needs a free boundary: the periodic "
                             "half-space has no stiffness for the mean, so an approach "
                             "fixes no load; use load or mean-gap control")
        target = float(control.depth)
        if not target >= 0:
            raise ValueError(f"indentation depth {target} < 0: the surfaces do not touch")
        if target == 0:
            return touching_state(problem, control, timer)
    else:
        raise TypeError(f"unknown control {control!r}")

    # The search's two transforms in single precision on a double grid ("Precision" in the
    # module docstring), their inputs and the preconditioner's output on S in `low`, the
    # direction's image r = K^{-1} t in the real FFT buffer in the search's precision.  The
    # alias grid is planned here, while the FFT buffers hold nothing (a start goes there next).
    rounded = search_precision == "single" and dtype == np.float64
    low = np.empty(0, dtype=np.float32)
    # (a free boundary's compliance is applied in double: its image stays double)
    single_image = rounded and problem.half_space.transforms_in_single
    image, image_precision = grid.padded, None
    if rounded:
        alias = grid.single_precision_alias()
        if single_image:
            image, image_precision = alias.padded, "single"
    # the step length by Parseval, the image completed only where needed
    split = problem.half_space.splits_transforms
    start = "warm" if initial_pressure is not None else ""
    if initial_pressure is None and settings.coarse_start:
        initial_pressure, start = coarse_start_pressure(problem, control, settings)
    start_time = timer()
    if initial_pressure is None:
        start = "; ".join(filter(None, [
            start, "uniform pressure" if load else "overlap of the undeformed surfaces"]))
    start_ops = problem.operator_applications
    # The contact set S = {p > 0} as sorted index lists, with p and the
    # conjugate direction t stored on S only (see petgap/solvers/contact_set.py).
    mask = np.zeros(grid.local_shape, dtype=np.uint8)
    padded_width = grid.padded.shape[1]
    # g = u - h + offset; periodic u has zero mean, so a mean gap fixes the offset
    offset = (0.0 if load else problem.mean_height + target if periodic
              else problem.top_height - target)
    if initial_pressure is not None or not load:
        if initial_pressure is not None:
            # in its own precision: the set rounds the values it keeps to the grid's
            # (a coarse start's field lies in the FFT buffer, read here before any transform)
            p = np.asarray(initial_pressure)
        else:
            # Mean-gap or indentation control: pressure where the undeformed
            # surfaces overlap.
            p = (h - offset) * (problem.pressure_scale / problem.gap_scale)
        # S = {p > 0}, with p there: the negative part is dropped on the way in
        # (no pass of its own), and p is rescaled to the load on S alone.
        contact = ContactSet.from_pressure(mask, padded_width, p, dtype=dtype)
        del p   # an overlap's field (mean-gap control) is freed before the iterations' fields
        initial_pressure = None
        if load:
            total = global_sums(comm, contact.p.sum(dtype=np.float64))[0]
            if total > 0:
                contact.p[...] *= target * n / total
            else:
                contact = ContactSet.everywhere(mask, padded_width, target, dtype=dtype)
    else:
        # Load control from a uniform pressure: every point starts in S, which
        # then shrinks to the points that carry the load.  Robust where starts
        # nearer the answer are not: a rigid approach with a local contact
        # stiffness overshoots the long wavelengths (the compliance 2 / (E* q)
        # is large there), so the first displacement makes whole valleys
        # penetrate; their entering pressures, rescaled to the load, then crush
        # the summits, and the set can oscillate at 20-60 % of the points
        # without converging.
        contact = None
    overlap = np.empty(max(1024, n // (100 * comm.size)), dtype=INDEX)
    # u = K^{-1} p, kept in the padded layout so that the transform writes it
    # there directly; its first columns double as scratch for the closed-form
    # first iteration's pressure.
    u = grid.aligned_padded()
    half_space = problem.half_space
    scale, fresh = 1.0, True
    since_fresh = 0
    delta, g_old, shift = 0.0, 1.0, 0.0
    history = []
    converged, reason, it = False, "max_iterations", 0
    first = 0
    watch_stall = dtype == np.float32
    best, best_it = np.inf, 0
    edge = (EdgeCorrection(half_space, mask, edge_correction)
            if settings.preconditioned and edge_correction > 0 else None)
    far = (patch_interaction(half_space, edge_correction, interaction_block)
           if edge is not None and load else None)
    settled = far_used = False   # S changed little in the last iteration; V y applied in it
    # what "little" is (smaller for blocks larger than 32 pixels); the residual V y was used at
    admit, far_from = settled_fraction(far), np.inf
    if contact is None and not periodic:
        contact = ContactSet.everywhere(mask, padded_width, target, dtype=dtype)  # C P0 is not zero
    if contact is None:
        # Its first iteration in closed form (one transform instead of two and a half,
        # and no set of every point); the uniform set itself only where that
        # iteration is also the last.
        scratch = grid.scratch(u)
        first_step = _uniform_first_iteration(problem, mask, padded_width, target, scratch,
                                              tolerance, max_iterations, monitor)
        if first_step is None:
            contact = ContactSet.everywhere(mask, padded_width, target, dtype=dtype)
        else:
            contact, scale, delta, g_old, residual = first_step
            history.append(residual)
            first = 1
    for it in range(first, max_iterations + 1):
        idx, pidx, pS, tS, gS = contact.idx, contact.pidx, contact.p, contact.t, contact.g
        if fresh:
            # u = K^{-1} p from scratch: one transform pair, from S to u
            if scale != 1.0:
                pS *= scale
                scale = 1.0
            half_space.apply_sparse(pidx, pS, inverse=True, out=u)
            since_fresh = 0
        else:
            since_fresh += 1
        with event(GAP_PASS_EVENT):
            sum_g = _cs.gather_gap(u, pidx, h, idx, offset, gS)
        n_contact, sum_g = global_sums(comm, len(idx), sum_g)
        shift = sum_g / n_contact if (load and n_contact > 0) else 0.0
        with event(GAP_PASS_EVENT):
            in_max, g_norm = _cs.shift_and_norms(gS, shift)
            pen_max, n_over = _cs.gap_pass(u, h, mask, offset - shift, overlap)
            if n_over > len(overlap):
                overlap = np.empty(2 * n_over, dtype=INDEX)
                _cs.collect_overlap(u, h, mask, offset - shift, overlap)
        norms = np.array([in_max, pen_max])
        comm.Allreduce(MPI.IN_PLACE, norms, op=MPI.MAX)
        residual = float(norms.max()) / problem.gap_scale

        def objective():
            # the complementary energy (1/2) <p, K^-1 p> - <p, h - offset> of the iterate,
            # from the gap on S, g = K^-1 p - h + offset - shift: (1/2) sum p (g - h + offset
            # + shift) dx dy
            local = float(np.dot(pS, gS - h.ravel()[idx] + offset + shift))
            return 0.5 * grid.pixel_area * global_sums(comm, local)[0]
        verdict = judge(residual, tolerance, fresh, it, max_iterations, history, monitor,
                        objective)
        if verdict == "refresh":
            fresh, scale = True, 1.0
            continue
        if verdict:
            converged, reason = verdict == "converged_kkt", verdict
            break
        if far_used and residual > RISE_FACTOR * far_from:
            admit *= WITHDRAWN_FACTOR
            get_logger("pressure_cg").info(
                "iteration %d: the residual rose from %.3g to %.3g in a step with the patch "
                "interaction in the preconditioner; withdrawn until an iteration changes at "
                "most %.3g of the contact set", it, far_from, residual, admit)
            far_used, settled, delta = False, False, 0.0   # a new preconditioner: restart
        if watch_stall:
            if residual < STALL_FACTOR * best:
                best, best_it = residual, it
            elif it - best_it >= STALL_ITERATIONS:
                reason = "stalled_round_off"
                break
        if n_contact == 0 or (load and n_contact == 1):
            # Mean-gap control with no contact yet, or load control on a single
            # contact point (e.g. warm-started from a one-pixel contact), where no
            # direction has zero mean over S and the step would break down: let the
            # points where the surfaces overlap into S; `scale` restores the load.
            g = u[:, :ny] - h + (offset - shift)
            g.ravel()[idx] = 0.0
            points = np.flatnonzero(g < 0)
            extra = -g.ravel()[points] * (problem.pressure_scale / problem.gap_scale)
            del g, idx, pidx, pS, tS, gS
            contact.merge(points, extra)
            total = global_sums(comm, contact.p.sum(dtype=np.float64))[0]
            scale = target * n / total if load else 1.0
            delta, fresh = 0.0, True
            continue
        # under load control, the kept direction's sum over the present S (its mean is
        # taken off the new one: "Step length" in the module docstring)
        old_t_sum = float(tS.sum(dtype=np.float64)) if load and delta != 0.0 else 0.0
        if settings.preconditioned:
            # z = P_S K P_S g (one pair, from S to S), made zero-mean on S
            # under load control
            zS = contact.z
            if rounded:
                low, g_low, z_low = _in_single(low, gS)
                half_space.apply_sparse(pidx, g_low, inverse=False, gathered=z_low,
                                        precision="single")
                np.copyto(zS, z_low)
            else:
                half_space.apply_sparse(pidx, gS, inverse=False, gathered=zS)
            if edge is None:
                sum_z, kz, g_sq, t_sum = global_sums(comm, *_cs.gap_sums(zS, gS), g_norm,
                                                     old_t_sum)
                gz = kz
            else:
                # z less theta kappa g, if that is still positive on the gap
                sum_z, kz, g_sq, t_sum, sum_kg, sum_kgg = global_sums(
                    comm, *_cs.gap_sums(zS, gS), g_norm, old_t_sum, *edge.sums(gS, idx))
                gz = kz - edge.theta * sum_kgg
                use_far = gz > 0 and far is not None and settled
                if use_far != far_used:
                    delta = 0.0   # a new preconditioner: restart
                far_used = False
                if use_far:
                    # less the patches' interaction V y, where still positive on the gap
                    w, d = far.sums(gS, edge.kappa, idx)
                    y = far.solve(w, d)
                    far_gz, far_z = float(np.dot(w, y)), float(np.dot(d, y))
                    if gz - far_gz > 0:
                        far.subtract(zS, edge.kappa, idx, y)
                        gz -= far_gz
                        sum_z -= far_z
                        far_used, far_from = True, residual
                    else:
                        get_logger("pressure_cg").info(
                            "iteration %d: the patch interaction of the preconditioner is not "
                            "positive on the gap; going on without it", it)
                        far, delta = None, 0.0   # a new preconditioner: restart
                if gz > 0:
                    edge.subtract(zS, gS, idx)
                    sum_z -= edge.theta * sum_kg
                else:
                    get_logger("pressure_cg").info(
                        "iteration %d: the contact-edge correction of the preconditioner is "
                        "not positive on the gap; going on without it", it)
                    edge, far, gz, delta = None, None, kz, 0.0   # a new preconditioner: restart
            zshift = sum_z / n_contact if load else 0.0
            # Pressure per unit penetration given to entering points (below):
            # plain Polonsky-Keer steps along the gap, so its step length tau
            # is a stiffness, the Rayleigh quotient of the compliance's inverse
            # on the gap; here tau is a pure number and the direction a
            # pressure, so the same scale is supplied explicitly, as the
            # Rayleigh quotient (g, K g) / (g, g) of the stiffness on the gap.
            stiffness = kz / g_sq if g_sq > 0 else 0.0
            g_norm = gz
            zS_, zshift_ = zS, zshift
        else:
            g_norm, t_sum = global_sums(comm, g_norm, old_t_sum)
            stiffness = 1.0
            zS_, zshift_ = gS, 0.0
        beta = delta * g_norm / g_old
        g_old = g_norm
        while True:
            # Under load control t has zero mean on S (the old direction's mean on the
            # present S taken off with z's), so that a step along it keeps the load.
            _cs.direction(zS_, zshift_ + beta * t_sum / n_contact, beta, tS)
            if single_image:
                low, t_low, _ = _in_single(low, tS)
            values = t_low if single_image else tS
            if split:
                # The step length needs only (t, K^{-1} t): by Parseval from the forward
                # half of the direction's image r = K^{-1} t, whose inverse half is run
                # below only if the recurrence needs r.
                sum_rt = half_space.begin_sparse(pidx, values, inverse=True,
                                                 precision=image_precision)
                sum_gt, sum_rt = global_sums(comm, _cs.gap_sums(tS, gS)[1], sum_rt)
            else:
                # The image r: one transform pair, from S to the whole slab (the
                # recurrence below needs r everywhere), in the search's precision
                half_space.apply_sparse(pidx, values, inverse=True, precision=image_precision)
                sum_gt, sum_rt = global_sums(comm, *_cs.step_sums(image, pidx, gS, tS))
            if sum_gt > 0 or beta == 0.0:
                break
            # S changed since the last restart, so t need not descend: restart
            beta = 0.0
        if not sum_rt > 0:
            reason = "breakdown"
            break
        tau = sum_gt / sum_rt
        with event(SET_UPDATE_EVENT):
            entering, clipped, sum_p = _cs.update(pS, tS, gS, tau, tau * stiffness)
            added = overlap[:min(n_over, len(overlap))]
            added_p = np.empty(len(added), dtype=dtype)
            sum_p += _cs.overlap_pressures(u, h, added, offset - shift, tau * stiffness, added_p)
        n_overlap, n_clipped, sum_p = global_sums(comm, entering + len(added), clipped, sum_p)
        delta = 0.0 if n_overlap > (0 if far_used else RESTART_FRACTION) * n_contact else 1.0
        settled = n_overlap + n_clipped <= admit * n_contact
        scale = target * n / sum_p if load else 1.0
        if clipped or len(added):
            del idx, pidx, pS, tS, gS  # views of buffers merge may replace
            zS = None
            contact.merge(added, added_p)
        # Same contact set, no projection: u follows p linearly, no transform needed.
        fresh = n_overlap > 0 or n_clipped > 0 or since_fresh >= refresh_interval
        if not fresh:
            if split:
                half_space.finish(precision=image_precision)
            _cs.recurrence(u, image, tau, scale, ny)
            contact.p[...] *= scale
            scale = 1.0
    # kappa and its mask: freed before the result's fields are made.  The result's pressure
    # is a fresh zeroed slab, not kappa's: the pages of its non-contact regions are never
    # written, so they cost neither resident memory nor a first touch (a sweep or the
    # adhesive protocol keeps such results while the next solve runs)
    edge = far = None

    # Residuals are taken on the gap as computed; the stored field (and the
    # scalars derived from it) is its projection onto the contact state found:
    # exactly 0 in contact, >= 0 elsewhere, within the reported kkt_gap h0.
    # The pressure residual is zero by construction (p > 0 on S, 0 off it).
    # The gap is written over u, compacted to the unpadded layout in place (no
    # new slab to allocate and fault in): row i moves to where it starts at or
    # before its old place, so nothing is overwritten before it is read.
    g = grid.scratch(u)
    on, off = _cs.final_gap(u, h, mask, offset - shift, g)
    del u
    residuals = (0.0, comm.allreduce(float(np.max([on, off])), op=MPI.MAX) / problem.gap_scale)
    p = np.zeros(grid.local_shape, dtype=dtype)
    p.ravel()[contact.idx] = contact.p
    contact = mask.view(bool)  # 0 or 1: a valid boolean array, no copy
    return problem.make_solution(
        g, p, contact, control, converged=converged, reason=reason,
        solver="pcg-pressure", iterations=it, wall_time=timer(), history=history,
        operator_applications=problem.operator_applications - start_ops, residuals=residuals,
        start=start, start_time=start_time)


def _in_single(low, values):
    """``values`` rounded to float32 in ``low``, and a float32 vector as long beside them.

    Returns ``(low, rounded, spare)``; ``low`` is replaced by a larger array when
    it holds fewer than two such vectors (the spare takes a gathered result).
    """
    n = len(values)
    if len(low) < 2 * n:
        low = np.empty(2 * n + n // 4, dtype=np.float32)
    rounded, spare = low[:n], low[n:2 * n]
    np.copyto(rounded, values, casting="same_kind")
    return low, rounded, spare


def _uniform_first_iteration(problem, mask, padded_width, target, p, tolerance, max_iterations,
                             monitor):
    """Iteration 0 of a load-controlled cold start from the uniform pressure, in closed form.

    From ``p = P0`` everywhere, ``u = K^{-1} p = 0`` (no q = 0 mode), so the
    iteration's gap (shifted to zero mean over S, here every point) is
    ``g = mean(h) - h``, its preconditioned gap ``z = K g``, its direction
    ``t = z - mean(z)``, the image of that ``r = K^{-1} t = g``, and the step
    ``tau = (g, t) / (r, t) = 1``: the general iteration's two and a half
    transform pairs reduce to one, and its pressure update to ``P0 - t`` projected, with the
    entering pressure of :func:`polonsky_keer` where that clips a penetrating
    point.  The set of every point is never built: the new set (about 60 %
    of the points on rough surfaces) is made from the updated pressure,
    written to ``p`` (a ``local_shape`` array the caller does not need yet).

    Returns ``(contact set, scale restoring the load, delta, g_old, residual)``
    for the iteration loop to carry on from iteration 1, or None when iteration
    0 is also the last (converged, e.g. on a flat surface, or no iteration
    allowed): then the caller runs it the general way.
    """
    grid, comm, h = problem.grid, problem.grid.comm, problem.topography
    padded = grid.padded
    hbar = problem.mean_height
    g_max, g_sq = _cs.uniform_gap(padded, h, hbar)
    g_sq = global_sums(comm, g_sq)[0]
    if not np.isfinite(g_sq):  # decided alike on every rank (a NaN sum is NaN everywhere)
        return None
    residual = comm.allreduce(g_max, op=MPI.MAX) / problem.gap_scale
    if residual <= tolerance or max_iterations < 1:
        return None
    if monitor is not None:
        if getattr(monitor, "wants_objective", False):
            # p = P0 everywhere has u = K^-1 p = 0: F = -<p, h> = -P0 sum(h) dx dy
            monitor(0, residual, -target * grid.pixel_area * global_sums(comm, h.sum())[0])
        else:
            monitor(0, residual)
    problem.half_space.apply_in_buffer(inverse=False)   # z = K g
    sum_z, gz = global_sums(comm, *_cs.uniform_sums(padded, h, hbar))
    zshift = sum_z / grid.npoints
    entry = gz / g_sq  # tau (= 1) times the stiffness's Rayleigh quotient on g
    n_overlap, _, sum_p = global_sums(comm, *_cs.uniform_step(padded, h, hbar, zshift, target,
                                                        entry, p))
    # Only shrinking is expected from here: no spare capacity.
    contact = ContactSet.from_pressure(mask, padded_width, p, spare=1.0, dtype=p.dtype)
    _cs.direction_from_buffer(padded, contact.pidx, zshift, 0.0, contact.t)
    delta = 0.0 if n_overlap > 0 else 1.0
    return contact, target * grid.npoints / sum_p, delta, gz, residual


def coarse_start_pressure(problem, control, settings):
    """A fine-grid pressure to start from: the solution on a coarser grid, prolonged.

    The coarse problem and the transfers are :mod:`petgap.solvers.coarse`'s;
    the coarse solve is this module's own, to ``max(tolerance,
    coarse_tolerance)``.  Returns ``(pressure, a line saying
    how it was found)``, or ``(None, "")`` when the grid is not coarsened (the caller's own
    cold start applies) or the coarse solve produced NaN.  The pressure is the
    fine grid's :meth:`~petgap.parallel.grid.Grid.scratch`, in the grid's
    precision: read it before the next transform.  Collective.
    """
    coarse_problem = coarse.coarse_problem(problem)
    if coarse_problem is None:
        return None, ""
    solution = polonsky_keer(coarse_problem, control, settings.but(
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
    return (coarse.prolong(first_row, problem.grid, pressure, factor, whole,
                           out=problem.grid.scratch()), description)


def full_contact_load(problem):
    """The least mean pressure that closes every gap: ``P_full = -min(K h)``.

    In full contact the gap is zero everywhere, so the displacement is the
    topography less its mean and the pressure ``p = P0 + K h`` (``K`` the
    half-space's stiffness, which has no mean); that state is the solution if and
    only if no pressure is tensile, ``P0 >= -min(K h)``.  One transform pair, made
    once per problem and kept for the steps of a sweep.  Collective.
    """
    def make():
        grid = problem.grid
        np.copyto(grid.real, problem.topography)     # K h in the FFT buffer: no slab copies
        problem.half_space.apply_in_buffer()
        return -grid.comm.allreduce(float(np.min(grid.real, initial=np.inf)), op=MPI.MIN)
    return problem.derived("full_contact_load", make)


def full_contact_state(problem, control, timer=None):
    """The full-contact solution of a non-adhesive problem under load ``control``, or None.

    None unless ``control.mean_pressure >= full_contact_load(problem)``; then no
    iteration is needed (an iterative solver would reach it only in the limit, as
    its contact set grows to every point).  Collective.
    """
    if control.mean_pressure < full_contact_load(problem):
        return None
    grid = problem.grid
    gap = np.zeros(grid.local_shape)
    pressure = problem.elastic_pressure(gap)
    pressure += control.mean_pressure
    return problem.make_solution(gap, pressure, np.ones(grid.local_shape, dtype=bool), control,
                                 converged=True, reason="full_contact", solver="pcg-pressure",
                                 iterations=0, operator_applications=1,
                                 wall_time=timer() if timer is not None else 0.0)


def solve_mean_gap_by_indentation(problem, control, settings=SolverSettings(), *,
                                  initial_pressure=None, monitor=None, max_solves=50):
    """Mean-gap control on a free boundary: the indentation whose solution has the mean gap.

    On a free boundary the displacement has a mean of its own, so a mean gap
    fixes no offset (as it does on a periodic cell); it is found instead as the
    depth ``d`` of an :class:`~petgap.mechanics.problem.Indentation` solve.  The
    mean gap ``m(d) = mean(u) - mean(h) + max(h) - d`` falls with ``d`` at a slope
    between -1 (rigid) and 0, and is convex where the load grows faster than
    the depth (Hertz: ``d^{3/2}``): from the rigid estimate ``u = 0``, which lies
    below the answer since ``u >= 0`` under compression, secant steps through
    the last two solves (the first with slope -1) stay below it and converge
    from one side, each solve warm-started from the last.  Stops when
    ``|m - g_bar| <= tolerance h0``; a solve that fails, or ``max_solves``
    steps, ends it with ``converged=False`` and that reason.

    Returns the last solve's solution with ``control`` set to the mean gap and
    iterations, operator applications and history summed over the solves.
    """
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    g_bar = float(control.mean_gap)
    if not g_bar >= 0:
        raise ValueError(f"mean gap {g_bar} < 0 is impossible with a hard wall (gap >= 0)")
    timer = Timer()
    reach = problem.top_height - problem.mean_height   # mean gap at first touch
    if g_bar >= reach:   # apart: the rigid surface lifted off the touching state
        state = touching_state(problem, control, timer)
        state.gap += g_bar - reach
        state.mean_gap = g_bar
        return state
    start_ops = problem.operator_applications
    depth, previous = reach - g_bar, None
    iterations, history, pressure, solves = 0, [], initial_pressure, 0
    converged, reason = False, "max_solves"
    while solves < max_solves:
        solution = polonsky_keer(problem, Indentation(depth), settings.but(
            max_iterations=max(max_iterations - iterations, 1), coarse_start=pressure is None),
            initial_pressure=pressure, monitor=monitor)
        solves += 1
        iterations += solution.iterations
        history.extend(solution.history)
        excess = solution.mean_gap - g_bar
        if not solution.converged:
            reason = solution.reason
            break
        if abs(excess) <= tolerance * problem.gap_scale:
            converged, reason = True, "converged_kkt"
            break
        slope = -1.0
        if previous is not None and depth != previous[0]:
            slope = min((solution.mean_gap - previous[1]) / (depth - previous[0]), -1e-12)
        previous = (depth, solution.mean_gap)
        depth += excess / -slope
        pressure = solution.pressure
    solution.start = "; ".join(filter(None, [f"{solves} indentation solves to the mean gap, "
                                             f"last depth {solution.control.depth:.6g}",
                                             solution.start]))
    solution.control = control
    solution.converged, solution.reason = converged, reason
    solution.iterations, solution.history = iterations, history
    solution.operator_applications = problem.operator_applications - start_ops
    solution.wall_time = timer()
    return solution


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
