"""Preconditioned projected conjugate gradients on the gap.

The unknown is the gap ``g >= 0`` itself (the "gap-primal" of Rey, Anciaux &
Molinari, Comput. Mech. 60 (2017) 69; Bugnicourt, Sainsot, Dureisseix, Gauthier
& Lubrecht, Tribol. Lett. 66 (2018) 29), so an interaction law ``v(g)`` enters
directly.  The gradient per pixel area is ``grad = p_el + v'(g)`` with
``p_el = K (g + h)``; at the solution ``grad + P0 = 0`` where the surfaces are
apart, ``grad + P0 >= 0`` where they touch.

The solver is a small core, :func:`gap_cg` (the iteration and its verdict),
and named parts, each with its reason in its docstring:

* :func:`_start`: the first gap and its elastic pressure;
* :func:`_multiplier`: the free set ``F`` (points off the wall, and points at
  the wall pulled off it), ``P0`` and the residual; with
  :func:`_release_threshold`, the rule that restarts the recurrence when a
  point leaves the wall;
* :func:`_precondition`: ``z = P_F K^{-1} P_F r`` with the mean mode, and with
  ``two_level`` the coarse term of :mod:`petgap.solvers.gap_two_level`;
* :func:`_beta`: the recurrence's ``beta``, Polak-Ribiere+ with ``two_level``;
* :func:`_direction` and :func:`_step_length`: the new direction, the step along
  it, its cap at the interaction's length scale and the non-convex case;
* :func:`_project_mean`: the projection onto ``{g >= 0, mean(g) = g_bar}``;
* :func:`_advance`: the step, then the projection and a restart, or the
  recurrence ``p_el += tau K t``.

The interaction law is asked, never read: it fills ``v'`` (and ``v''`` where it
needs a field of it) by its own kernel, says how the direction pass gets
``v''`` otherwise (``curvature_from_stress``), and gives the length scale a step
is capped at (:mod:`petgap.mechanics.interactions.base`).

With ``two_level`` the preconditioner also sees the contact patches pinning long
waves and the interaction softening them (:mod:`petgap.solvers.gap_two_level`),
and conjugacy is kept across a projection that put at most :data:`KEEP_FRACTION`
of ``F`` at the wall: the few points that reached the wall perturb the subspace
the directions were conjugate in, the step's line minimum still holds along the
new direction, and a restart on every such step would leave the iteration at
steepest descent's pace while the edges settle one pixel at a time.  The
preconditioner then changes with the springs and the free set, so ``beta`` is
Polak-Ribiere+ (zero when the residual turned against the old direction), and a
kept direction loses its mean over ``F`` (points that left ``F`` took their share
of it), keeping the mean gap.

Controls: under mean-gap control directions have zero mean over ``F`` and
``P0 = -mean_F(grad)`` is estimated every iteration; under load control ``P0``
is given and the mean mode is free.  Each iteration applies ``K^{-1}`` (the
preconditioner) and ``K`` (the curvature along the direction): two transform
pairs when the projection does not act, two and a half when it does, and one
more where the coarse term forms its contact springs again
(:mod:`petgap.solvers.gap_two_level`).

Convergence: the largest ``|grad + P0|`` over ``F`` relative to ``h0' E*``
(:meth:`petgap.mechanics.problem.ContactProblem.kkt_residuals`), judged on a
freshly evaluated ``p_el``.  A solve within a hundred times its tolerance (or at
round-off) whose residual has not fallen by a tenth of its best for
:data:`STALL_ITERATIONS` iterations stops, unconverged, as ``"stalled"``: below
round-off more iterations do not reach the tolerance.  The round-off is that of
the residual itself, not of the multiplier's sums: those run over residuals
(:func:`_multiplier`, :func:`_direction`), so it does not grow with the grid.

Memory: the fields ``g``, ``p_el``, ``t`` and ``v'`` besides the FFT buffer (and
the last residual with ``two_level``); a
law whose ``v''`` is not a multiple of its ``v'`` (Lennard-Jones, the squared
exponential) adds one field for ``v''``, filled in the same pass as ``v'``, so
that the direction pass needs no transcendental function of its own.
"""
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from petgap.io import solver_registry as registry
from petgap.mechanics.problem import Load, MeanGap
from petgap.parallel.collective import global_sums
from petgap.parallel.log import GAP_CG_EVENT, event
from petgap.solvers import _kernels as _k
from petgap.solvers.convergence import BestResidual, Timer, judge
from petgap.solvers.gap_start import cold_start
from petgap.solvers.gap_two_level import CoarseTerm, block_for
from petgap.solvers.settings import SolverSettings


#: With ``two_level``, conjugacy is kept across a projection that put at most this
#: fraction of the free set at the wall (module docstring); otherwise every
#: projection restarts the recurrence.
KEEP_FRACTION = 1.0
#: With ``two_level``, ``beta`` is Polak-Ribiere+ (module docstring).
POLAK_RIBIERE = True
#: Iterations a load-controlled solve stays past pull-off before it says so (:func:`_pulled_off`).
PULL_OFF_ITERATIONS = 3
#: A solve stops as ``"stalled"`` when its residual, once its best is within
#: ``STALL_NEAR`` times the tolerance or below ``ROUND_OFF``, has not fallen below
#: ``STALL_FACTOR`` times that best for ``STALL_ITERATIONS`` iterations (:func:`_stalled`).
#: Near the tolerance a healthy solve beats its best within a few iterations; one that
#: sits for fifty has met the floor of round-off and would otherwise run on to its
#: iteration limit.  Far from it a state may wander for a hundred iterations and more on
#: its way (a jump into full contact), which is no stall.
STALL_ITERATIONS = 50
STALL_FACTOR = 0.9
STALL_NEAR = 100.0
ROUND_OFF = 1e-12


def _pass(kernel, *args):
    """``kernel(*args)``, timed in the PETSc log event of the gap solver's passes."""
    with event(GAP_CG_EVENT):
        return kernel(*args)


class _Fields:
    """This rank's fields of one solve, and what the parts need of the problem and the law.

    ``vp`` caches ``v'(g)`` once per iteration (the hard wall has none: ``vp`` is
    then ``pel``, never read); ``vpp`` is ``v''(g)`` for a law that needs the
    field, else None and the direction pass takes ``v'' = -v' / divisor``.
    """

    def __init__(self, problem, load, target, two_level=False):
        grid = problem.grid
        law = problem.interaction
        self.problem, self.grid, self.comm, self.law = problem, grid, grid.comm, law
        self.h, self.padded, self.half_space = problem.topography, grid.padded, problem.half_space
        self.load, self.target = load, target
        self.adhesive = bool(law.adhesive)
        self.g = np.empty(grid.local_shape)
        self.pel = np.empty(grid.local_shape)
        self.t = np.zeros(grid.local_shape)
        self.vp = np.empty(grid.local_shape) if self.adhesive else self.pel
        divisor = law.curvature_from_stress if self.adhesive else 1.0
        self.vpp = np.empty(grid.local_shape) if divisor is None else None
        self.divisor = 1.0 if divisor is None else divisor  # not read with a v'' field
        # the step cap and the step along a direction without curvature: an adhesive
        # law's length scale; the hard wall has no length, and takes one length unit
        # there (round-off, or a rigid mode under load control)
        self.cap = law.length_scale if self.adhesive else 1.0
        # points whose v' jumped (a law with jumps counts them; see _multiplier)
        self.jumps, self.crossed = bool(law.jumps), 0
        # the mean mode's compliance under load control (_precondition); with the coarse
        # term the springs set its stiffness, and it need only exceed every wave's
        block = block_for(grid.shape) if two_level else 0
        modulus = self.half_space.contact_modulus
        self.mean_mode = (max(grid.Lx, grid.Ly) / modulus if block and load
                          else problem.gap_scale / problem.pressure_scale)
        self.coarse = (CoarseTerm(grid, modulus, block, self.mean_mode if load else 0.0)
                       if block else None)
        self.two_level = bool(two_level)
        self.keep = KEEP_FRACTION if two_level else 0.0
        self.r_old = np.zeros(grid.local_shape) if two_level else None  # the last residual

    def fill_stress(self):
        """``v'`` (and ``v''``) at the current gap, by the law's kernel."""
        if self.adhesive:
            self.crossed = _pass(self.law.fill_stress, self.g, self.vp, self.vpp)

    def load_gap(self):
        """The FFT buffer = ``g + h``, the field ``K`` maps to ``p_el``."""
        np.add(self.g, self.h, out=self.padded[:, :self.grid.ny])

    def fresh_pressure(self):
        """``p_el = K (g + h)`` from the FFT buffer (one transform pair)."""
        self.half_space.apply_in_buffer(inverse=False)
        _pass(_k.copy_from, self.pel, self.padded)


@dataclass
class _State:
    """The scalars the iteration carries: multipliers, free-set counts, the recurrence."""
    lam: float = 0.0          # P0
    lam_f: float = 0.0        # P0 as estimated over the points off the wall (free-set test)
    lam_free: float = 0.0     # P0 as estimated over F (the reported multiplier, load control)
    n_open: int = 0
    n_free: int = 0
    beta_ok: bool = False     # whether the recurrence may go on (False: steepest descent)
    rz_old: float = 1.0
    fresh: bool = True        # p_el freshly evaluated, not by recurrence
    since_fresh: int = 0
    negative_curvature: int = 0
    projected: int = 0        # steps whose projection acted
    released: int = 0         # restarts on a strong release (_release_threshold)
    capped: int = 0           # steps capped at the law's length scale
    apart: int = 0            # consecutive iterations past pull-off (_pulled_off)
    cross: tuple = ()         # with two_level: sum_F z r_old, sum_F r_old, sum_F t (_beta)
    best: BestResidual = field(default_factory=lambda: BestResidual(STALL_FACTOR))  # _stalled


def _project_mean(grid, g, target, h, padded, comm, positive=None):
    """``g = max(g + mu, 0)`` off the wall with ``mean(g) = target``; loads ``g + h`` too.

    Points exactly at the wall stay there (the projection onto the current
    face; see :func:`petgap.solvers._kernels.shifted_positive_sums`).  Newton on the
    convex, increasing, piecewise-linear ``mean(max(g + mu, 0))`` converges in
    a few steps, one reduction each.  ``positive``: its data at ``mu = 0``
    (reduced), where a step that kept the mean has them from its own pass
    (:func:`petgap.solvers._kernels.gcg_step`); the shift then starts there.

    Wall points pulled off by their gradient are not lifted here either: lifted
    by ``mu`` (several interaction lengths for a typical step), a released edge
    point loads the next one like a crack tip, and re-evaluating the release
    after each lift opens the whole contact of an adhesive wave, which then
    loses the contact that unloading must hold (hysteresis).  Points leave the
    wall through the conjugate gradients' free set instead, whose recurrence
    restarts when they are pulled off hard (:func:`_release_threshold`).
    """
    n = grid.npoints
    if positive is None:
        mu = target - grid.mean(g)
        # start to the right of the root: the mean of max(., 0) is at least the mean
        s, count = global_sums(comm, *_pass(_k.shifted_positive_sums, g, mu))
    else:
        mu, (s, count) = 0.0, positive
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


def _start(f, initial_gap):
    """The first gap (a warm start made feasible, or the surfaces just touching) and ``p_el``.

    Under load control a cold start lifts the surface onto its highest point
    (no penetration, no contact yet); under mean-gap control the start is
    projected onto the prescribed mean.
    """
    g, h, comm = f.g, f.h, f.comm
    if initial_gap is not None:
        np.maximum(initial_gap, 0.0, out=g)
    else:
        np.negative(h, out=g)
    if f.load:
        if initial_gap is None:
            top = comm.allreduce(float(h.max()), op=MPI.MAX)
            g += top
        np.maximum(g, 0.0, out=g)
        f.load_gap()
    else:
        _project_mean(f.grid, g, f.target, h, f.padded, comm)
    f.fresh_pressure()


def _release_threshold(f, s, history):
    """``P0_open + r / 2``: a point at the wall pulled off it beyond this restarts the recurrence.

    Conjugacy holds on a fixed free set (Polonsky & Keer restart theirs when
    points enter the contact set).  Points join the wall by the projection,
    which restarts anyway, but leave it only when their wall reaction turns
    tensile beyond the adhesion: at an adhesive (JKR-like) contact edge, one
    pixel row at a time, at the tip of its crack, when a mean-gap step pulls
    the surfaces apart.  A released point brings a residual the old direction
    knows nothing of; if the recurrence went on, ``beta`` would stay at or just
    above 1, the directions pile up, the steps shrink, and the edge crawls a
    pixel per several iterations.  So the iteration restarts when a point at
    the wall is pulled off it by at least half the last residual
    (``grad + P0 < -r / 2`` at ``g = 0``, ``P0`` estimated over the points off
    the wall): a point that will dominate the new residual.  Weaker releases
    (the edges of rough contacts, a pixel or two per step) are left to the
    recurrence: restarting on every change of ``F`` costs rough surfaces
    iterations, and lets round-off decide the path of a sticky solve
    differently on different rank counts.  The strong pulls are counted in
    the free set's pass (:func:`petgap.solvers._kernels.gcg_free_sums`) and
    reduced with its sums; the count decides only when the recurrence would go
    on with points at the wall in ``F``.

    Mean-gap control only: load control, which :func:`petgap.solvers.dispatch.solve`
    gives this solver for the hard wall alone, has no count of the points off
    the wall to compare with, and hard-wall edges have no crack tip to crawl
    (infinite there, and before the first residual: no point counts).
    """
    if f.load or not history:
        return np.inf
    return s.lam_f + 0.5 * history[-1] * f.problem.pressure_scale


def _multiplier(f, s, history):
    """The free set's sums: ``P0`` (mean-gap control), whether to restart, and the residual.

    ``F`` holds the points off the wall and the points at the wall that the
    gradient pulls off it (``grad + P0_open < 0``, with ``P0_open`` estimated over
    the points off the wall alone, so that the test does not depend on the
    points it decides).  Under mean-gap control ``P0 = -mean_F(grad)``, the
    multiplier of the mean constraint; the residual is ``max_F |grad + P0|``
    over ``h0' E*``.

    The recurrence restarts when a point crossed a jump of ``v'`` (a law with
    ``jumps``, e.g. Maugis-Dugdale at ``delta``): its gradient changed by the
    jump, which the old direction knows nothing of, as for a point released
    from the wall (:func:`_release_threshold`).  Both counts ride on the free
    set's pass and reduction.

    The sums run over ``grad + P0_last`` (the last estimates), so that they add up
    residuals, not gradients.  ``P0`` is the mean of some ``N`` gradients that all lie
    near ``-P0``: summed as they are, the rounding of the running sum grows like
    ``N eps |P0|``, and that error enters every residual as a constant over ``F``.
    The mean constraint keeps the iteration from removing a constant; its
    compliance image, a long wave in the free set's shape, pollutes every direction,
    and a sticky solve (``|P0|`` large) then stalls at a residual that grows with the
    grid (docs/design.md, the gap solver).  Summed as residuals, the rounding shrinks
    with them.
    """
    comm = f.comm
    if not f.load:
        s_open, s.n_open = global_sums(comm, *_pass(_k.gcg_open_sums, f.pel, f.g, f.vp,
                                                    f.adhesive, s.lam_f))
        s.lam_f = s.lam_f - s_open / s.n_open if s.n_open > 0 else 0.0
    s_free, n_free, gmax, gmin, strong = _pass(_k.gcg_free_sums, f.pel, f.g, f.vp, f.adhesive,
                                               s.lam_f, _release_threshold(f, s, history), s.lam)
    s_free, s.n_free, crossed, strong = global_sums(comm, s_free, n_free, f.crossed, strong)
    s.beta_ok = s.beta_ok and crossed == 0
    if s.beta_ok and not f.load and s.n_free > s.n_open:
        s.beta_ok = bool(strong == 0)
        s.released += not s.beta_ok
    ext = np.array([gmax, -gmin])
    comm.Allreduce(MPI.IN_PLACE, ext, op=MPI.MAX)
    shift = s.lam
    if not f.load:
        s.lam = shift - s_free / s.n_free if s.n_free > 0 else s.lam_f
    s.lam_free = shift - s_free / s.n_free if s.n_free > 0 else s.lam
    if s.n_free > 0:
        return max(ext[0] + s.lam, ext[1] - s.lam) / f.problem.pressure_scale
    return 0.0


def _pulled_off(f, s):
    """Whether a tensile load has pulled the surfaces apart for good (load control).

    The mean mode of the gap carries no elastic stress (``K`` has no ``q = 0``
    term), so with every point off the wall its gradient is ``mean(v') + P0``.
    Once every point is farther from the wall than the law's length scale and the
    strongest attraction left, ``max v'(g)``, is weaker than the tension
    ``-P0``, that gradient pushes the surfaces apart, the gaps grow, the
    attraction fades, and no equilibrium lies ahead: the load is beyond pull-off
    of the branch the solve was on.  Held for :data:`PULL_OFF_ITERATIONS`
    iterations, so that a momentary excursion of an iterate is not taken for it.
    Collective; a few passes, made only under a tensile load.
    """
    if not (f.load and f.adhesive and s.lam < 0):
        return False
    local = np.array([float(f.g.min()) if f.g.size else np.inf,
                      -float(f.vp.max()) if f.g.size else np.inf])
    f.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MIN)
    beyond = local[0] > f.cap and -local[1] < -s.lam
    s.apart = s.apart + 1 if beyond else 0
    return s.apart >= PULL_OFF_ITERATIONS


def _precondition(f, s):
    """``z = P_F K^{-1} P_F r`` (one transform pair); returns ``(z shift, r.z)``.

    The stiffness ``K`` (symbol ``E* |q| / 2``) restricted to the free set has
    a condition number growing like ``L / a0``; its opposite-order partner, the
    compliance ``K^{-1}`` restricted to the same set, leaves one that grows only
    like ``log^2(L / a0)`` (operator preconditioning, Steinbach & Wendland, Adv.
    Comput. Math. 9 (1998) 191).  ``K^{-1}`` has no ``q = 0`` mode.  Under load
    control the preconditioner adds ``c mean_F(r)`` on ``F`` with
    ``c = h0 / (h0' E*)`` (the problem's gap over pressure scale), which makes it
    positive definite on ``F``: one outlier eigenvalue, about one iteration
    whatever ``c`` is.  Under mean-gap control ``z`` is shifted to zero mean over
    ``F`` instead, keeping the mean gap.  With the coarse term (``two_level``),
    ``c`` is the compliance of the cell's longest wave and the coarse springs
    stiffen the mean mode as the contact does (:mod:`petgap.solvers.gap_two_level`).
    """
    n = f.grid.npoints
    if f.coarse is not None:
        with event(GAP_CG_EVENT):
            f.coarse.write_residual(f, s)
    else:
        _pass(_k.gcg_write_residual, f.pel, f.g, f.vp, f.adhesive, s.lam_f, s.lam, f.padded)
    f.half_space.apply_in_buffer(inverse=True)
    coarse = (None, 0, 0)
    if f.coarse is not None:
        with event(GAP_CG_EVENT):
            coarse = (f.coarse.correction(), f.coarse.x0, f.coarse.block)
    # with two_level, the sums _beta needs and the coarse correction ride on the same pass
    sums = global_sums(f.comm, *_pass(_k.gcg_precond_sums, f.padded, f.pel, f.g, f.vp,
                                      f.adhesive, s.lam_f, s.lam, f.r_old, f.t, *coarse))
    (sum_z, rz, sum_r), s.cross = sums[:3], sums[3:]
    if f.load:
        # z += c mean(r) on F, i.e. a shift of -c sum_r / n
        return -f.mean_mode * sum_r / n, rz + f.mean_mode * sum_r * sum_r / n
    return sum_z / s.n_free, rz


def _beta(f, s, rz, zshift):
    """``beta`` of the recurrence and the direction's shift (``z`` in the FFT buffer).

    Without ``two_level``: the ratio of ``r.z``.  With it (module docstring):
    Polak-Ribiere+, ``max(0, (r.z - r_old.z) / (r.z)_old)`` over ``F``, and under
    mean-gap control the shift also takes the old direction's mean over ``F`` off;
    the sums come from :func:`_precondition`'s pass.
    """
    if f.r_old is None:
        return (rz / s.rz_old if s.beta_ok else 0.0), zshift
    cross, sum_old, sum_t = s.cross
    if not s.beta_ok:
        beta = 0.0
    elif POLAK_RIBIERE:
        beta = max(0.0, (rz - cross + zshift * sum_old) / s.rz_old)
    else:
        beta = rz / s.rz_old
    if not f.load:
        zshift -= beta * sum_t / s.n_free
    return beta, zshift


def _direction(f, s, zshift, beta):
    """The new direction ``t`` (from ``z`` in the FFT buffer) and ``(t.K t + sum v''(g) t^2,
    slope, max |t|)`` along it.

    ``t = -(z - zshift) + beta t`` on ``F``, 0 elsewhere; the pass that writes it
    also sums the slope and the interaction's curvature along it.  The step
    needs ``K t`` only through ``t.K t``, which by Parseval the forward half of
    the transform gives
    (:meth:`petgap.mechanics.half_space.ElasticHalfSpace.begin_in_buffer`); the
    inverse half runs later only if ``p_el`` follows by the recurrence (a whole
    pair where the half-space has no halves).  The slope sums ``(grad + P0) t`` under
    either control: under mean-gap control ``t`` has no mean over ``F`` and ``P0``
    adds nothing to it, but ``grad t`` alone would be ``-P0 t`` to within the
    residual, a sum that cancels to round-off of ``P0`` (as in :func:`_multiplier`).
    """
    curv, slope, tmax = _pass(_k.gcg_direction, f.padded, f.pel, f.g, f.vp, f.vpp, f.adhesive,
                              f.t, s.lam_f, zshift, beta, s.lam, f.divisor)
    if f.half_space.splits_transforms:
        curv += f.half_space.begin_in_buffer(inverse=False)
    else:
        f.half_space.apply_in_buffer(inverse=False)
        curv += _pass(_k.gcg_image_sum, f.padded, f.t)
    curv, slope = global_sums(f.comm, curv, slope)
    return curv, slope, f.comm.allreduce(tmax, op=MPI.MAX)


def _step_length(f, s, curv, slope, tmax):
    """The step ``tau`` along ``t``, and whether it was capped (a cap restarts the recurrence).

    Steps are exact minimisers of the local quadratic model.  Where the
    interaction's curvature makes the model non-convex along the direction,
    the step moves the farthest-moving point by the law's length scale, and is
    counted (``negative_curvature_steps``).  A convex adhesive step that would
    move some point farther than that length is capped the same way: the
    quadratic model of ``v`` holds only over changes of ``g`` small against the
    length over which ``v'`` changes, and an almost vanishing curvature
    ``t.K t + sum v''(g) t^2`` would otherwise send the iterate arbitrarily far,
    raising the energy beyond recovery.  For a law whose ``v'`` jumps
    (Maugis-Dugdale) the cap also keeps a point from crossing the jump more than
    once per step.
    """
    if curv > 0:
        tau = -slope / curv
        if f.adhesive and tau * tmax > f.cap:  # beyond the quadratic model's reach
            s.capped += 1
            return f.cap / tmax, True
        return tau, False
    s.negative_curvature += 1
    return (f.cap / tmax if tmax > 0 else 0.0), False


def _advance(f, s, tau, restart, refresh_interval):
    """``g += tau t``, then either project and restart, or follow ``p_el`` by the recurrence.

    The projection acts (points went below the wall), the step was capped or
    non-convex (``restart``), or ``p_el`` has followed by recurrence for
    ``refresh_interval`` steps: then ``g`` is projected (the mean too, under
    mean-gap control), ``p_el`` evaluated afresh, and the recurrence restarts
    unless only the refresh was due (with ``two_level``, also when the projection put at
    most :data:`KEEP_FRACTION` of ``F`` at the wall).  Otherwise the inverse half of the
    transform begun by :func:`_direction` completes ``K t`` and
    ``p_el += tau K t``.
    """
    negative, *positive = global_sums(f.comm, *_pass(_k.gcg_step, f.g, f.t, tau))
    s.projected += bool(negative > 0)
    if negative > 0 or restart or s.since_fresh >= refresh_interval:
        if f.load:  # g = max(g, 0), g + h into the FFT buffer in the same pass
            _pass(_k.project_and_load, f.g, 0.0, f.h, f.padded)
        else:
            _project_mean(f.grid, f.g, f.target, f.h, f.padded, f.comm, positive)
        f.fresh_pressure()
        s.fresh, s.since_fresh = True, 0
        s.beta_ok = negative <= f.keep * s.n_free and not restart
    else:
        if f.half_space.splits_transforms:
            f.half_space.finish()
        _pass(_k.axpy, f.pel, f.padded, tau)
        s.fresh = False
        s.since_fresh += 1
        s.beta_ok = True


def _restarted(f, s, beta):
    """After a direction that does not descend: whether the iteration goes on, restarted.

    Round-off or non-convexity on a recurrence, or (with ``two_level``) a
    direction kept across a projection: steepest descent from a fresh ``p_el``
    goes on.  A steepest-descent direction on a fresh ``p_el`` that does not
    descend ends the solve.
    """
    s.beta_ok = False
    if s.fresh and not (f.two_level and beta != 0.0):
        return False
    if not s.fresh:
        f.load_gap()
        f.fresh_pressure()
        s.fresh, s.since_fresh = True, 0
    return True


def _objective(f, s):
    """Elastic + interaction energy + ``P0 A mean(g)`` (the load's work; constant under mean gap).

    ``(1/2) sum p_el (g + h) + sum v(g) + P0 sum g``, times ``dx dy``: for
    monitors that ask for what the solver minimises (collective).
    """
    local = 0.5 * float(np.sum(f.pel * (f.g + f.h)))
    if f.adhesive:
        local += float(np.sum(f.law.energy(f.g)))
    if f.load:
        local += s.lam * float(np.sum(f.g))
    return f.grid.pixel_area * global_sums(f.comm, local)[0]


def _control(problem, control):
    """``(load, P0, mean gap)`` of a control, refused as the registry says
    (:mod:`petgap.io.solver_registry`: a hard wall carries no tension)."""
    registry.check(registry.Case(solver="pcg-gap", adhesive=problem.interaction.adhesive,
                                 periodic=problem.half_space.periodic,
                                 **registry.control_words(control)))
    if isinstance(control, Load):
        return True, float(control.mean_pressure), None
    if isinstance(control, MeanGap):
        return False, 0.0, float(control.mean_gap)
    raise TypeError(f"unknown control {control!r}")


def _stalled(s, it, residual, tolerance):
    """Whether the residual has stopped falling near the tolerance (:data:`STALL_ITERATIONS`).

    The same on every rank: the residual is a global maximum.
    """
    since = s.best.since(it, residual)
    near = s.best.value <= max(STALL_NEAR * tolerance, ROUND_OFF)
    return near and since >= STALL_ITERATIONS


def _retargeted(f, s, retarget, residual):
    """Whether ``retarget`` moved the mean-gap constraint; if so, ``g`` is on the new one.

    The extension point of a caller whose mean gap is a function of the state (a free
    map's mean gap on its padded cell, :mod:`petgap.solvers.free_boundary`): it is
    asked on every iteration, and a converged verdict stands only where it answers
    None.  It may also change ``g`` in place (a predictor of the moved state).  A moved
    constraint projects ``g`` onto it, evaluates ``p_el`` afresh and restarts the
    recurrence: the old directions were conjugate on the old constraint.
    """
    moved = retarget(f.g, residual)
    if moved is None:
        return False
    f.target = float(moved)
    _project_mean(f.grid, f.g, f.target, f.h, f.padded, f.comm)
    f.fresh_pressure()
    s.fresh, s.since_fresh, s.beta_ok = True, 0, False
    s.best = BestResidual(STALL_FACTOR)   # a new constraint: its residual starts afresh
    return True


def gap_cg(problem, control, settings=SolverSettings(), *, initial_gap=None, monitor=None,
           refresh_interval=50, two_level=None, retarget=None):
    """Solve hard-wall or adhesive contact on the gap, under load or mean-gap control.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
    control : Load or MeanGap
    settings : petgap.solvers.settings.SolverSettings
        Tolerance (of the largest KKT stress violation over ``h0' E*``) and
        iteration limit.
    initial_gap : ndarray, optional
        Warm start (copied and made feasible); without it the start is
        :func:`petgap.solvers.gap_start.cold_start`'s (a coarse-grid solve, the
        hard wall's state for adhesive load control, or the rigid approach).
    monitor : callable, optional
        ``monitor(iteration, residual)`` on every rank.
    refresh_interval : int
        Recompute ``p_el`` from scratch at least this often.
    two_level : bool, optional
        The coarse term in the preconditioner, conjugacy kept across projections and
        Polak-Ribiere+ (module docstring); ``settings.two_level`` by default.
    retarget : callable, optional
        Mean-gap control only: ``retarget(g, residual)`` returns a new mean gap to
        hold from here on, or None (:func:`_retargeted`).

    Returns
    -------
    petgap.mechanics.problem.ContactSolution
        ``history`` holds the residuals; ``reason`` says why it stopped.
    """
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    two_level = settings.two_level if two_level is None else two_level
    timer = Timer()
    load, lam, target = _control(problem, control)
    if retarget is not None and load:
        raise ValueError("gap_cg: retarget moves a mean-gap constraint; load control has none")
    start_ops = problem.operator_applications
    if not load and target == 0.0:
        return _full_contact(problem, control, timer)
    start = ""
    if initial_gap is None:
        def level(coarse_problem, coarse_control, coarse_settings):
            return gap_cg(coarse_problem, coarse_control, coarse_settings,
                          refresh_interval=refresh_interval, two_level=two_level)
        initial_gap, start = cold_start(problem, control, settings, level)
    start_time = timer()
    f = _Fields(problem, load, target, two_level)
    s = _State(lam=lam, lam_f=lam if load else 0.0)
    _start(f, initial_gap)
    initial_gap = None   # a cold start's field: not held through the solve
    history = []
    converged, reason, it = False, "max_iterations", 0
    for it in range(max_iterations + 1):
        f.fill_stress()
        residual = _multiplier(f, s, history)
        verdict = judge(residual, tolerance, s.fresh, it, max_iterations, history, monitor,
                        lambda: _objective(f, s))
        if verdict == "refresh":
            f.load_gap()
            f.fresh_pressure()
            s.fresh, s.since_fresh = True, 0
            continue
        if retarget is not None and verdict in ("", "converged_kkt") \
                and _retargeted(f, s, retarget, residual):
            continue
        if verdict:
            converged, reason = verdict == "converged_kkt", verdict
            break
        if _stalled(s, it, residual, tolerance):
            reason = "stalled"
            break
        if _pulled_off(f, s):
            reason = "load_not_reached"  # every contact let go: beyond pull-off
            break
        zshift, rz = _precondition(f, s)
        beta, zshift = _beta(f, s, rz, zshift)
        s.rz_old = rz
        curv, slope, tmax = _direction(f, s, zshift, beta)
        if not slope < 0:
            if _restarted(f, s, beta):
                continue
            reason = "no_descent_direction"
            break
        tau, capped = _step_length(f, s, curv, slope, tmax)
        _advance(f, s, tau, capped or curv <= 0, refresh_interval)

    # the total pressure, in place (no extra full-size array); an adhesive load-controlled
    # state reports the free set's multiplier, the load it carries, as under mean-gap
    # control: it balances the forces exactly (F_rep + F_att = A0 P0 to round-off),
    # differs from the load by at most the KKT residual once converged, and shows the
    # miss of a state past pull-off (the hard wall reports the load it was given)
    f.pel += s.lam_free if f.load and f.adhesive else s.lam
    solution = problem.make_solution(
        f.g, f.pel, f.g <= 0, control, converged=converged, reason=reason, solver="pcg-gap",
        iterations=it, operator_applications=problem.operator_applications - start_ops,
        wall_time=timer(), history=history, start=start, start_time=start_time)
    solution.negative_curvature_steps = s.negative_curvature
    solution.step_counts = dict(projected=s.projected, released=s.released, capped=s.capped,
                                negative_curvature=s.negative_curvature)
    if f.coarse is not None:
        solution.step_counts.update(coarse_iterations=f.coarse.inner_iterations,
                                    coarse_clipped=f.coarse.clipped,
                                    coarse_lanczos_steps=f.coarse.lanczos_steps)
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
    wall = float(problem.interaction.derivative(0.0))
    least = -grid.comm.allreduce(float(np.min(p_el)) + wall, op=MPI.MIN)
    solution = problem.make_solution(
        gap, p_el + least, gap <= 0, control, converged=True, reason="full_contact",
        solver="pcg-gap", iterations=0, operator_applications=1, wall_time=timer())
    return solution
