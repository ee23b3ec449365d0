"""Preconditioned projected conjugate gradients on the gap.

The unknown is the gap ``g >= 0`` itself (the "gap-primal" of Rey, Anciaux &
Molinari, Comput. Mech. 60 (2017) 69; Bugnicourt, Sainsot, Dureisseix, Gauthier
& Lubrecht, Tribol. Lett. 66 (2018) 29), so adhesive interactions ``v(g)`` enter
directly.  The gradient per pixel area is ``grad = p_el + v'(g)`` with
``p_el = K (g + h)``; at the solution ``grad + P0 = 0`` where the surfaces are
apart, ``grad + P0 >= 0`` where they touch.

Algorithm
---------
Conjugate gradients on the free set ``F`` (points off the wall, and points at
the wall that are pulled off it), with a projection onto ``g >= 0`` after each
step and a restart whenever the projection acts or a point is released from
the wall with a pull of half the residual or more (see below):

* mean-gap control: directions have zero mean over ``F``; the multiplier
  ``P0 = -mean_F(grad)`` is estimated every iteration and the projection onto
  ``{g >= 0, mean(g) = g_bar}`` (``g = max(y + mu, 0)``) is found by a Newton
  iteration on ``mu`` that converges in a few reductions;
* load control: ``P0`` is given; the mean mode is free.

Preconditioning (petgap's addition): the stiffness ``K`` (symbol
``E* |q| / 2``) restricted to the free set has a condition number growing like
``L / a0``; its opposite-order partner, the compliance ``K^{-1}`` restricted to
the same set, ``z = P_F K^{-1} P_F r``, leaves a condition number that grows
only like ``log^2(L / a0)`` (operator preconditioning, Steinbach & Wendland,
Adv. Comput. Math. 9 (1998) 191).  ``K^{-1}`` has no ``q = 0`` mode; under load
control the preconditioner adds ``c mean_F(r)`` on ``F`` with
``c = h0 / (h0' E*)``, which makes it positive definite on ``F``; one outlier
eigenvalue costs about one iteration whatever ``c`` is.

Each iteration applies ``K^{-1}`` (preconditioner) and ``K`` (curvature along
the direction).  The curvature needs ``K t`` only through ``t.K t``, which by
Parseval the forward half of the transform gives
(:meth:`petgap.mechanics.half_space.ElasticHalfSpace.begin_in_buffer`); the
inverse half is run only when the projection does not act and ``p_el`` follows
by the recurrence ``p_el += tau K t``: two transform pairs then.  Otherwise
``p_el`` is recomputed (a pair) in place of that half: two and a half.  Step
lengths are exact minimisers of the local quadratic model; where the adhesive
curvature makes the model non-convex along the direction, the step is capped at
``rho`` per point and the method restarts, and such steps are counted and
reported.  The same cap (and restart) applies to a
convex adhesive step longer than ``rho`` at some point: the quadratic model of
``exp(-g / rho)`` holds only over changes of ``g`` small against ``rho``, and an
almost vanishing curvature ``t.K t + sum v''(g) t^2`` would otherwise send the
iterate arbitrarily far (seen: a step of 34 rho on a wavy JKR contact that
raised the energy by 3e3 and never recovered).

Why a released point restarts the recurrence: conjugacy holds on a fixed free
set (Polonsky & Keer restart theirs when points enter the contact set).
Points join the wall by the projection, which restarts anyway, but leave it
only when their wall reaction turns tensile beyond the adhesion -- at an
adhesive (JKR-like) contact edge, one pixel row at a time, at the tip of its
crack, when a mean-gap step pulls the surfaces apart.  A released point brings
a residual the old direction knows nothing of; if the recurrence went on,
``beta = (r.z)_k / (r.z)_{k-1}`` would stay at or just above 1, the directions
pile up, the steps shrink, and the edge crawls at about a pixel per seven
iterations.  So the iteration restarts when a point at the wall is pulled off
it by at least half the last residual (``grad + P0 < -r / 2`` at ``g = 0``,
``r`` the last ``max_F |grad + P0|``, ``P0`` estimated over the points off
the wall): a point that will dominate the new residual.  Weaker releases (the
edges of rough contacts, a pixel or two per step) are left to the recurrence:
restarting on every change of ``F`` costs rough surfaces iterations, and lets
round-off decide the path of a sticky solve differently on 1 and 2 ranks
(``test_two_ranks_equal_one_with_adhesion``).  Counting the strong pulls costs
one more pass over the slab, made only when the recurrence would go on with
points at the wall in ``F``: a few percent of the iterations on rough
surfaces, more on Johnson's wave.
Mean-gap control only: load control, which :func:`petgap.solvers.dispatch.solve` gives
this solver for the hard wall alone, has no count of the points off the wall
to compare with, and hard-wall edges have no crack tip to crawl.

This is what lets warm-started mean-gap sweeps of Johnson's wave
(``tests/solvers/test_adhesion.py``) move their edges by tens of pixels per
step in tens of iterations, and unload past pull-off at all, while sweeps on
self-affine surfaces take the iterations and end in the states a restart on
every change of ``F`` would.

Convergence: the largest ``|grad + P0|`` over ``F`` relative to ``h0' E*``
(:meth:`petgap.mechanics.problem.ContactProblem.kkt_residuals`), judged on a freshly
evaluated ``p_el``.
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.problem import Load, MeanGap
from petgap.parallel.collective import global_sums
from petgap.parallel.log import GAP_CG_EVENT, event
from petgap.solvers import _kernels as _k
from petgap.solvers.convergence import Timer, judge
from petgap.solvers.gap_two_level import CoarseTerm, block_for
from petgap.solvers.settings import SolverSettings


def _pass(kernel, *args):
    """``kernel(*args)``, timed in the PETSc log event of the gap solver's passes."""
    with event(GAP_CG_EVENT):
        return kernel(*args)


def _project_mean(grid, g, target, h, padded, comm):
    """``g = max(g + mu, 0)`` off the wall with ``mean(g) = target``; loads ``g + h`` too.

    Points exactly at the wall stay there (the projection onto the current
    face; see :func:`petgap.solvers._kernels.shifted_positive_sums`).  Newton on the
    convex, increasing, piecewise-linear ``mean(max(g + mu, 0))`` converges in
    a few steps, one reduction each.

    Wall points pulled off by their gradient are not lifted here either: lifted
    by ``mu`` (several ``rho`` for a typical step), a released edge point loads
    the next one like a crack tip, and re-evaluating the release after each
    lift opened the whole contact of Johnson's wave, which then lost the
    contact that unloading must hold at ``1.3 h_a`` (hysteresis).  Points leave
    the wall through the conjugate gradients' free set instead, whose
    recurrence restarts when they are pulled off hard (module docstring).
    """
    n = grid.npoints
    mu = target - grid.mean(g)
    # start to the right of the root: the mean of max(., 0) is at least the mean
    s, count = global_sums(comm, *_pass(_k.shifted_positive_sums, g, mu))
    for _ in range(100):
        excess = s / n - target
        if abs(excess) <= 1e-14 * max(abs(target), 1e-300) or count == 0:
            break
        mu -= excess * n / count
        s_new, count = global_sums(comm, *_pass(_k.shifted_positive_sums, g, mu))
        if s_new / n - target >= excess and excess > 0:  # no progress: converged to round-off
            s = s_new
            break
        s = s_new
    _pass(_k.project_and_load, g, mu, h, padded)


#: With the coarse term, conjugacy is kept across a projection that put at most this
#: fraction of the free set at the wall (module docstring of
#: :mod:`petgap.solvers.gap_two_level`); without it, every projection restarts.
KEEP_FRACTION = 1.0
#: With the coarse term, ``beta`` is Polak-Ribiere+ rather than the ratio of ``r.z``.
POLAK_RIBIERE = True


def gap_cg(problem, control, settings=SolverSettings(), *, initial_gap=None, monitor=None,
           refresh_interval=50, two_level=False):
    """Solve hard-wall or adhesive contact on the gap, under load or mean-gap control.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
    control : Load or MeanGap
    settings : petgap.solvers.settings.SolverSettings
        Tolerance (of the largest KKT stress violation over ``h0' E*``) and
        iteration limit.
    initial_gap : ndarray, optional
        Warm start (copied and made feasible).
    monitor : callable, optional
        ``monitor(iteration, residual)`` on every rank.
    refresh_interval : int
        Recompute ``p_el`` from scratch at least this often.
    two_level : bool
        Add the coarse term to the preconditioner (:mod:`petgap.solvers.gap_two_level`)
        and keep conjugacy across projections.

    Returns
    -------
    petgap.mechanics.problem.ContactSolution
        ``history`` holds the residuals; ``reason`` says why it stopped.
    """
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    grid, comm = problem.grid, problem.grid.comm
    h = problem.topography
    half_space = problem.half_space
    padded = grid.padded
    timer = Timer()
    n = grid.npoints
    interaction = problem.interaction
    w = interaction.work if interaction.adhesive else 0.0
    rho = interaction.range if interaction.adhesive else 1.0
    load = isinstance(control, Load)
    if load:
        lam = float(control.mean_pressure)
    elif isinstance(control, MeanGap):
        target = float(control.mean_gap)
        if not target >= 0:
            raise ValueError(f"mean gap {target} < 0 is impossible with a hard wall (gap >= 0)")
    else:
        raise TypeError(f"unknown control {control!r}")
    if load and not interaction.adhesive and lam < 0:
        raise ValueError(f"mean pressure {lam} < 0: a non-adhesive interface cannot carry a "
                         f"tensile load")
    start_ops = problem.operator_applications
    mean_mode = problem.gap_scale / problem.pressure_scale  # c of the module docstring
    if not load and target == 0.0:
        return _full_contact(problem, control, timer)

    g = np.empty(grid.local_shape)
    if initial_gap is not None:
        g[...] = np.maximum(initial_gap, 0.0)
    else:
        g[...] = -h
    if load:
        if initial_gap is None:
            top = comm.allreduce(float(h.max()), op=MPI.MAX)
            g += top
        np.maximum(g, 0.0, out=g)
        np.add(g, h, out=padded[:, :grid.ny])
    else:
        _project_mean(grid, g, target, h, padded, comm)
    pel = np.empty(grid.local_shape)
    t = np.zeros(grid.local_shape)
    adh = bool(interaction.adhesive)
    # v'(g), cached once per iteration (one exponential per point); unused for the hard wall
    vp = np.empty(grid.local_shape) if adh else pel

    def fresh_pressure():
        half_space.apply_in_buffer(inverse=False)
        _pass(_k.copy_from, pel, padded)

    fresh_pressure()
    fresh, since_fresh = True, 0
    beta_ok, rz_old = False, 1.0
    block = block_for(grid.shape) if two_level else 0
    if block and load:
        # the springs set the mean mode's stiffness: its compliance need only exceed every
        # wave's (gap_two_level docstring)
        mean_mode = max(grid.Lx, grid.Ly) / half_space.contact_modulus
    coarse = CoarseTerm(grid, half_space.contact_modulus, block,
                        mean_mode if load else 0.0) if block else None
    keep = KEEP_FRACTION if two_level else 0.0
    r_old = np.zeros(grid.local_shape) if two_level else None
    split = half_space.splits_transforms
    history = []
    negative_curvature = 0
    counts = dict(capped=0, projected=0, released=0, refreshed=0)
    converged, reason, it = False, "max_iterations", 0
    lam_f = lam if load else 0.0
    for it in range(max_iterations + 1):
        if adh:
            _pass(_k.gcg_interaction, g, vp, w, rho)
        if not load:
            s_open, n_open = global_sums(comm, *_pass(_k.gcg_open_sums, pel, g, vp, adh))
            lam_f = -s_open / n_open if n_open > 0 else 0.0
        s_free, n_free, gmax, gmin = _pass(_k.gcg_free_sums, pel, g, vp, adh, lam_f)
        s_free, n_free = global_sums(comm, s_free, n_free)
        if beta_ok and not load and n_free > n_open:
            # points at the wall joined F: restart if one is pulled off it by half the
            # last residual or more (module docstring).  One more pass, in the few
            # iterations that would go on with points at the wall in F.
            pull = 0.5 * history[-1] * problem.pressure_scale
            strong = _pass(_k.gcg_free_sums, pel, g, vp, adh, lam_f + pull)[1]
            beta_ok = comm.allreduce(strong, op=MPI.SUM) == n_open
            counts["released"] += not beta_ok
        ext = np.array([gmax, -gmin])
        comm.Allreduce(MPI.IN_PLACE, ext, op=MPI.MAX)
        if not load:
            lam = -s_free / n_free if n_free > 0 else lam_f
        if n_free > 0:
            residual = max(ext[0] + lam, ext[1] - lam) / problem.pressure_scale
        else:
            residual = 0.0
        def objective():
            # elastic + interaction energy + P0 A mean(g) (the load's work; constant
            # under mean-gap control): (1/2) sum pel (g + h) + sum v(g) + P0 sum g, x dx dy
            local = 0.5 * float(np.sum(pel * (g + h)))
            if adh:
                local += float(np.sum(interaction.energy(g)))
            if load:
                local += lam * float(np.sum(g))
            return grid.pixel_area * global_sums(comm, local)[0]
        verdict = judge(residual, tolerance, fresh, it, max_iterations, history, monitor,
                        objective)
        if verdict == "refresh":
            np.add(g, h, out=padded[:, :grid.ny])
            fresh_pressure()
            fresh, since_fresh = True, 0
            continue
        if verdict:
            converged, reason = verdict == "converged_kkt", verdict
            break

        # preconditioned residual z = P_F K^{-1} P_F r (one pair)
        _pass(_k.gcg_write_residual, pel, g, vp, adh, lam_f, lam, padded)
        if coarse is not None:
            coarse.set_springs(g, vp, adh, rho)
            coarse.restrict(padded)
        half_space.apply_in_buffer(inverse=True)
        if coarse is not None:
            coarse.correct(padded)
        sum_z, rz, sum_r = global_sums(
            comm, *_pass(_k.gcg_precond_sums, padded, pel, g, vp, adh, lam_f, lam))
        if load:
            # mean mode: z += c mean(r) on F, i.e. a shift of -c sum_r / n
            zshift = -mean_mode * sum_r / n
            rz += mean_mode * sum_r * sum_r / n
        else:
            zshift = sum_z / n_free
        if r_old is not None:
            # the preconditioner changes with the springs and the free set: Polak-Ribiere+;
            # points that left F take their share of the old direction's mean with them
            cross, sum_old, sum_t = global_sums(comm, *_pass(
                _k.gcg_cross_sums, padded, r_old, t, pel, g, vp, adh, lam_f, lam))
            if POLAK_RIBIERE:
                beta = max(0.0, (rz - cross + zshift * sum_old) / rz_old) if beta_ok else 0.0
            else:
                beta = rz / rz_old if beta_ok else 0.0
            if not load:
                zshift -= beta * sum_t / n_free
        else:
            beta = rz / rz_old if beta_ok else 0.0
        rz_old = rz
        _pass(_k.gcg_direction, padded, pel, g, vp, adh, t, lam_f, zshift, beta)

        # curvature along t: t.K t by Parseval from the forward half of K t, whose inverse
        # half runs below only if p_el follows by the recurrence (a whole pair where the
        # half-space has no halves)
        if split:
            form = half_space.begin_in_buffer(inverse=False)
            curv, slope, tmax, reach = _pass(_k.gcg_curvature, None, t, pel, g, vp, adh,
                                             lam if load else 0.0, rho)
            curv += form
        else:
            half_space.apply_in_buffer(inverse=False)
            curv, slope, tmax, reach = _pass(_k.gcg_curvature, padded, t, pel, g, vp, adh,
                                             lam if load else 0.0, rho)
        curv, slope = global_sums(comm, curv, slope)
        tmax = comm.allreduce(tmax, op=MPI.MAX)
        if not slope < 0:
            # not a descent direction (round-off or non-convexity): restart
            beta_ok = False
            if not fresh or (two_level and beta != 0.0):
                # a kept conjugacy can leave a fresh state on an ascent direction
                if not fresh:
                    np.add(g, h, out=padded[:, :grid.ny])
                    fresh_pressure()
                    fresh, since_fresh = True, 0
                continue
            reason = "no_descent_direction"
            break
        capped = False
        if curv > 0:
            tau = -slope / curv
            if w > 0 and tau * tmax > rho:  # beyond the quadratic model's reach
                tau, capped = rho / tmax, True
        else:
            negative_curvature += 1
            tau = rho / tmax if tmax > 0 else 0.0
        negative = comm.allreduce(_pass(_k.gcg_step, g, t, tau), op=MPI.SUM)
        counts["capped"] += capped
        counts["projected"] += negative > 0
        counts["refreshed"] += since_fresh >= refresh_interval
        if negative > 0 or curv <= 0 or capped or since_fresh >= refresh_interval:
            # the projection acts: new free set, fresh elastic pressure, restart
            if load:
                np.maximum(g, 0.0, out=g)
                np.add(g, h, out=padded[:, :grid.ny])
            else:
                _project_mean(grid, g, target, h, padded, comm)
            fresh_pressure()
            fresh, since_fresh = True, 0
            beta_ok = negative <= keep * n_free and curv > 0 and not capped
        else:
            if split:
                half_space.finish()
            _pass(_k.axpy, pel, padded, tau)
            fresh = False
            since_fresh += 1
            beta_ok = True

    pel += lam  # the total pressure, in place (no extra full-size array)
    pressure = pel
    contact = g <= 0
    solution = problem.make_solution(
        g, pressure, contact, control, converged=converged, reason=reason, solver="pcg-gap",
        iterations=it, operator_applications=problem.operator_applications - start_ops,
        wall_time=timer(), history=history)
    solution.negative_curvature_steps = negative_curvature
    solution.step_counts = dict(counts, negative_curvature=negative_curvature)
    if coarse is not None:
        solution.step_counts.update(coarse_iterations=coarse.inner_iterations,
                                    coarse_clipped=coarse.clipped)
    return solution


def _full_contact(problem, control, timer):
    """Mean gap 0: the only feasible gap is ``g = 0``; no iteration can improve on it.

    The mean pressure is then any ``P0`` that leaves no wall reaction tensile,
    ``p_el + P0 + v'(0) >= 0`` with ``p_el = K h``; the least such ``P0`` (the
    load that just closes the last gap) is reported.
    """
    grid = problem.grid
    gap = np.zeros(grid.local_shape)
    p_el = problem.elastic_pressure(gap)
    wall = problem.interaction.derivative(0.0) if problem.interaction.adhesive else 0.0
    least = -grid.comm.allreduce(float(np.min(p_el)) + wall, op=MPI.MIN)
    solution = problem.make_solution(
        gap, p_el + least, gap <= 0, control, converged=True, reason="full_contact",
        solver="pcg-gap", iterations=0, operator_applications=1, wall_time=timer())
    return solution
