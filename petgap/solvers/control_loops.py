"""Outer loops that reach one control through solves under another.

* Mean-gap control for TAO's built-ins, which minimise the load-control energy:
  a secant on the multiplier ``log(P0)`` around inexact load solves
  (:func:`solve_mean_gap_by_multiplier`).
* Adhesive load control on the gap: a safeguarded secant on the mean gap around
  warm-started mean-gap solves (:func:`solve_load_by_mean_gap`), so that each step
  reports which branch of a hysteretic interface it landed on.

:func:`solve_as` runs a solver type the registry resolved
(:mod:`petgap.io.solver_registry`) through the loop its control needs; the inner
solves are TAO solves (:func:`petgap.solvers.tao.tao_solve`).
"""
import math

import numpy as np
from mpi4py import MPI

from petgap.io.solver_registry import method
from petgap.mechanics.problem import Load, MeanGap
from petgap.solvers.convergence import Timer
from petgap.solvers.progress import outer_step
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.tao import tao_solve


def solve_as(problem, control, kind, settings, initial=None, monitor=None):
    """Solve a periodic ``problem`` (or a free map by the pressure solver) with type ``kind``.

    ``kind`` is a resolved solver type (never ``"pcg"``:
    :func:`petgap.io.solver_registry.resolve`), run through the loop its control needs
    (:func:`petgap.io.solver_registry.method`): adhesive load control on the gap by
    :func:`solve_load_by_mean_gap`, mean-gap control of a TAO built-in by
    :func:`solve_mean_gap_by_multiplier`, anything else by one :func:`tao_solve`.
    ``initial`` is a warm start (a previous solution).  Collective.
    """
    how = method(kind, control.kind, problem.interaction.adhesive, problem.half_space.periodic)
    loops = {"mean-gap secant": solve_load_by_mean_gap, "multiplier": solve_mean_gap_by_multiplier,
             "direct": tao_solve}
    if how not in loops:
        raise ValueError(f"{kind} reaches {control.kind} control here by {how!r}, which "
                         f"petgap.solvers.dispatch.run runs, not a TAO solve")
    return loops[how](problem, control, kind, settings, initial, monitor)



def solve_mean_gap_by_multiplier(problem, control, kind, settings, initial=None, monitor=None,
                                 max_outer=60):
    """Mean-gap control for gap-space TAO types: secant on log(P0) until mean(g) = g_bar.

    Inexact: each inner load-control solve is only as accurate as the step it
    serves (:func:`_inner_tolerance`).  Why not a fixed inner tolerance well
    below the outer one: TAO's line searches compare energies, whose round-off
    hides the decrease of a step once the KKT residual nears it, so a fixed
    ``tolerance / 100`` may be out of reach and would spend the whole iteration
    budget of a step on its first inner solve, at a guessed ``P0`` that the secant
    would replace anyway.  Every constant here is in the problem's scales (``h0``,
    ``h0' E*``), so the iterations are the same in every unit system.
    """
    timer = Timer()
    target = float(control.mean_gap)
    tolerance = settings.tolerance
    apart = _apart(problem, control, kind, timer)
    if apart is not None:
        return apart
    start_ops = problem.operator_applications
    solution, iterations, history, exhausted = _multiplier_secant(
        problem, target, kind, settings, initial, monitor, max_outer)
    usable = _meets_kkt(solution, tolerance)
    converged = not exhausted and usable and \
        abs((solution.mean_gap - target) / problem.gap_scale) <= tolerance
    reason = "converged_kkt" if converged else "max_iterations" if exhausted else \
        (solution.reason if not usable else "multiplier_not_converged")
    return problem.make_solution(
        solution.gap, solution.pressure, solution.gap <= 0, control, converged=converged,
        reason=reason, solver=f"{kind}+multiplier", iterations=iterations,
        operator_applications=problem.operator_applications - start_ops, wall_time=timer(),
        history=history)


def _apart(problem, control, kind, timer):
    """The undeformed state when the hard wall's highest summit stays clear of the mean gap.

    No contact, no pressure: the rigid surface held ``g_bar`` above its mean height.
    None when there is contact to solve for (or an adhesive interaction).
    """
    target = float(control.mean_gap)
    grid = problem.grid
    top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
    if problem.interaction.adhesive or target < top - problem.mean_height:
        return None
    gap = target + problem.mean_height - problem.topography
    zero = np.zeros(grid.local_shape)
    return problem.make_solution(gap, zero, gap <= 0, control, converged=True,
                                 reason="no_contact", solver=f"{kind}+multiplier",
                                 iterations=0, operator_applications=0, wall_time=timer())


def _multiplier_secant(problem, target, kind, settings, initial, monitor, max_outer):
    """The secant on ``log(P0 / h0' E*)`` of :func:`solve_mean_gap_by_multiplier`.

    Returns the last inner solution, the iterations summed, the history of
    ``(P0, mean gap)`` and whether the iteration limit ended it.
    """
    h0, ps = problem.gap_scale, problem.pressure_scale
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    iterations = 0
    history = []
    # Starting guess: the previous multiplier, or a typical rough-contact pressure.
    pressure = initial.mean_pressure if initial is not None and initial.mean_pressure > 0 \
        else 0.01 * ps
    # The secant works on log(P0 / (h0' E*)), not log(P0): the same numbers, to the
    # last bit, in unit systems that differ by powers of two.  Its slope
    # d g_bar / d log P0 ~ -gamma h0 with gamma ~ 0.5 for rough contact, until measured.
    slope = -0.5 * h0
    inner = tolerance  # P0 is a guess: resolving its state any further is wasted
    points = []
    solution = initial
    for outer in range(max_outer):
        budget = max_iterations - iterations  # the limit is per step, not per inner solve
        if budget < 1:
            return solution, iterations, history, True
        solution = tao_solve(problem, Load(pressure), kind,
                             settings.but(tolerance=inner, max_iterations=budget), solution,
                             monitor)
        iterations += solution.iterations
        error = (solution.mean_gap - target) / h0
        history.append((pressure, solution.mean_gap))
        # Judged on the state, not on the inner solve's own target: an inner solve
        # that stopped short of a tighter inner tolerance (a line search lost in the
        # round-off of the energy) may still leave a state that meets the test, and
        # its mean gap is still the best the secant can have.
        if not _meets_kkt(solution, tolerance) or abs(error) <= tolerance:
            break
        if len(history) >= 3 and history[-1][1] == history[-2][1] == history[-3][1]:
            break  # the inner solves no longer move the mean gap: reported as not converged
        points.append((math.log(pressure / ps), solution.mean_gap))
        if len(points) > 1:
            (l1, g1), (l2, g2) = points[-2], points[-1]
            measured = (g2 - g1) / (l2 - l1) if l2 != l1 else slope
            slope = measured if measured < 0 else -0.5 * h0
        log_p = points[-1][0] + (target - points[-1][1]) / slope
        load = math.exp(min(max(log_p, points[-1][0] - 5.0), points[-1][0] + 5.0))
        pressure = load * ps
        inner = _inner_tolerance(tolerance, error, load, slope / h0)
    return solution, iterations, history, False


def _meets_kkt(solution, tolerance):
    """Whether a state's own unit-free KKT residuals are within ``tolerance``."""
    return solution.kkt_pressure <= tolerance and solution.kkt_gap <= tolerance


def _inner_tolerance(tolerance, error, load, slope, forcing=0.5):
    """KKT tolerance of the next inner solve of the multiplier loop (unit-free).

    Why: a pressure residual ``r h0' E*`` left by an inner solve acts on the
    surfaces apart like an error of that size in ``P0``, which moves the mean
    gap by ``|d g_bar / d log P0| r h0' E* / P0``.  That must stay below a
    fraction ``forcing`` of the mean-gap error the next step is to remove
    (an inexact secant, as inexact Newton methods choose their forcing terms),
    and, near the end, below that fraction of the test ``|g_bar - target| <=
    tolerance h0``; and never above ``tolerance``, which the returned state must
    meet.  Compliant (lightly loaded) contact therefore asks for tighter inner
    solves than stiff contact.  The bound is pessimistic -- a residual bounded
    in the max norm seldom has that size everywhere at once -- which leaves
    margin for the secant.

    Parameters
    ----------
    tolerance : float
        The unit-free tolerance of the whole solve.
    error : float
        Mean-gap error of the last inner solve over ``h0``.
    load : float
        ``P0 / (h0' E*)`` of the next inner solve.
    slope : float
        ``d g_bar / d log P0`` over ``h0`` (negative).
    """
    wanted = forcing * max(abs(error), tolerance) * load / abs(slope)
    return min(tolerance, wanted)


def solve_load_by_mean_gap(problem, control, kind, settings, initial=None, monitor=None,
                           max_outer=60):
    """Adhesive load control: find the mean gap whose multiplier is the load.

    A safeguarded secant (regula falsi once the root is bracketed) on
    ``P(g_bar) - P0`` with warm-started mean-gap solves of type ``kind``
    (:class:`_LoadSecant`).  ``P(g_bar)`` of an adhesive interface need not be
    monotone; the branch found is the one connected to the starting gap (the
    previous step of a sweep, else the non-adhesive solution at the same load,
    :func:`_branch_start`), and is reported in ``history``.  Full contact
    (``g_bar = 0``) carries every load that leaves no wall reaction tensile
    (:func:`_carried_in_full_contact`).
    """
    timer = Timer()
    target = float(control.mean_pressure)
    tolerance, max_iterations = settings.tolerance, settings.max_iterations
    start_ops = problem.operator_applications
    gap_guess, state, iterations = _branch_start(problem, target, settings, initial)
    secant = _LoadSecant(problem, target, state)
    solution, history, negative_curvature, exhausted = state, [], 0, False
    outer_exhausted = False
    for outer in range(max_outer + 1):
        budget = max_iterations - iterations  # the limit is per step, seed included
        if budget < 1:
            exhausted = True  # (the state is then a trial or the hard-wall seed)
            break
        if outer == max_outer:
            outer_exhausted = True
            break
        solution = tao_solve(problem, MeanGap(max(gap_guess, 0.0)), kind,
                             settings.but(max_iterations=budget), secant.on_branch, monitor)
        iterations += solution.iterations
        negative_curvature += solution.negative_curvature_steps
        f = solution.mean_pressure - target
        history.append((solution.mean_gap, solution.mean_pressure))
        outer_step("adhesive load by the mean gap", outer + 1, max_outer, timer,
                   f"load off by {abs(f) / problem.pressure_scale:.3e} h0' E* (target "
                   f"{tolerance:.0e}) after {solution.iterations} iterations"
                   + ("" if solution.converged else f", not converged ({solution.reason})"))
        if not solution.converged or abs(f) <= tolerance * problem.pressure_scale:
            break
        if solution.mean_gap == 0.0 and _carried_in_full_contact(problem, solution, target):
            break
        gap_guess = secant.next_gap(solution, f)
        if gap_guess is None:
            break  # pull-off: the branch ends without carrying the load
    converged = not exhausted and solution.converged and \
        abs(solution.mean_pressure - target) <= tolerance * problem.pressure_scale
    reason = "converged_kkt" if converged else "max_iterations" if exhausted else \
        "max_outer_iterations" if outer_exhausted else \
        (solution.reason if not solution.converged else "load_not_reached")
    result = problem.make_solution(
        solution.gap, solution.pressure, solution.gap <= 0, control, converged=converged,
        reason=reason, solver=f"{kind}+mean-gap-secant", iterations=iterations,
        operator_applications=problem.operator_applications - start_ops, wall_time=timer(),
        history=history)
    result.negative_curvature_steps = negative_curvature  # of all inner solves
    return result


def _branch_start(problem, target, settings, initial):
    """The mean gap to try first, the state it is on, and the iterations that cost.

    A sweep's previous step; else the same surface against a hard wall at the same
    load (at least ``1e-3 h0' E*``), whose operator applications count as this
    solve's (the half-space is shared).
    """
    if initial is not None:
        return initial.mean_gap, initial, 0
    hard = problem.with_interaction(None)
    seed = polonsky_keer(hard, Load(max(target, 1e-3 * problem.pressure_scale)),
                         settings.but(tolerance=max(settings.tolerance, 1e-6)))
    return seed.mean_gap, seed, seed.iterations


def _carried_in_full_contact(problem, solution, target):
    """Whether full contact carries the load ``target``; if so ``solution`` is set to it.

    With every gap at the wall the mean gap cannot resolve the load any further, and
    this state carries every ``P0`` at which no wall reaction is tensile,
    ``p_el + P0 + v'(0) >= 0`` (adhesive jump-in).
    """
    p_el = solution.pressure - solution.mean_pressure
    least = -problem.grid.comm.allreduce(
        float(np.min(p_el + problem.interaction.derivative(0.0))), op=MPI.MIN)
    if target < least:
        return False
    solution.pressure = p_el + target
    solution.mean_pressure = problem.grid.mean(solution.pressure)
    return True


class _LoadSecant:
    """The safeguarded secant of :func:`solve_load_by_mean_gap` on ``P(g_bar) - P0``.

    Keeps the last state on the branch (the warm start of every trial), the points on
    it, the bracket of the root once found, and the smallest mean gap at which every
    contact let go.  A trial in which every contact has let go of the wall is not
    followed (adhesion is hysteretic: a separated warm start never finds the contact
    again) but bisected back towards the branch, down to ``1e-3 h0`` of mean gap: if
    the branch ends there without carrying the load, that is pull-off, and the
    separated state is returned with ``converged=False``.
    """

    def __init__(self, problem, target, state):
        self.problem, self.target = problem, target
        self.on_branch = state
        self.points = []
        self.lo = self.hi = None  # brackets: (gap, P - P0) with opposite signs
        self.guard = self.touching(state)
        self.release = None  # smallest mean gap tried at which every contact let go

    def touching(self, state):
        return self.problem.grid.comm.allreduce(int(np.count_nonzero(state.gap <= 0))) > 0

    def next_gap(self, solution, f):
        """The next mean gap to try after ``solution`` (``f = P - P0``), or None at pull-off."""
        h0 = self.problem.gap_scale
        if self.guard and not self.touching(solution):
            # off the branch (overshoot, or past its end): bisect back towards it
            self.release = solution.mean_gap if self.release is None \
                else min(self.release, solution.mean_gap)
            if self.release - self.on_branch.mean_gap <= 1e-3 * h0:
                return None
            return 0.5 * (self.on_branch.mean_gap + self.release)
        self.on_branch = solution
        self.points.append((solution.mean_gap, f))
        if f > 0:
            self.lo = (solution.mean_gap, f) if self.lo is None or solution.mean_gap > \
                self.lo[0] else self.lo
        else:
            self.hi = (solution.mean_gap, f) if self.hi is None or solution.mean_gap < \
                self.hi[0] else self.hi
        gap_guess = solution.mean_gap + max(min(self._step(solution, f), h0), -h0)
        lo, hi = self.lo, self.hi
        if lo is not None and hi is not None and \
                not (min(lo[0], hi[0]) < gap_guess < max(lo[0], hi[0])):
            # regula falsi inside the bracket
            gap_guess = lo[0] - lo[1] * (hi[0] - lo[0]) / (hi[1] - lo[1])
        if self.release is not None:
            gap_guess = min(gap_guess, 0.5 * (solution.mean_gap + self.release))
        return gap_guess

    def _step(self, solution, f):
        """The secant's step in mean gap, before the safeguards."""
        problem, h0 = self.problem, self.problem.gap_scale
        if len(self.points) == 1:
            # stiffness estimate of rough contact: dP/dg ~ -P / (0.5 h0)
            slope = -max(abs(solution.mean_pressure), 1e-3 * problem.pressure_scale) / (0.5 * h0)
        else:
            (g1, f1), (g2, f2) = self.points[-2], self.points[-1]
            slope = (f2 - f1) / (g2 - g1) if g2 != g1 else -problem.pressure_scale / h0
        return -f / slope if slope < 0 else (0.5 * h0 if f > 0 else -0.5 * h0)
