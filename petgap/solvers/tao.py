"""The bridge to PETSc TAO: every solve runs as a TAO solve.

The TAO object is created for every solve with the solution Vec laid out as
the grid's real-space slab, and ``setFromOptions()`` is called last, so the
PETSc options database (``-tao_type``, ``-tao_monitor``, ``-tao_max_it``,
``-tao_view``, ``-log_view``...) has the final word, as every PETSc user expects.
The options of one solve are put in the database by the caller
(:func:`petgap.solvers.dispatch.solve`) for the whole solve; petgap's own options
reach this module only through the :class:`~petgap.solvers.settings.SolverSettings`
read there.

* petgap's own conjugate-gradient solvers run inside a TAO ``python`` type
  (:class:`_PetgapTao`), so that TAO's monitors and views see them;
* TAO's built-ins (``bncg``, ``blmvm``, ``bqnls``, ``gpcg``) minimise the
  load-control energy over the gap in dimensionless variables
  (:class:`DimensionlessGap`) with a matrix-free Hessian (:class:`GapHessian`);
* the outer loops that turn one control into another: mean-gap control for the
  built-ins by a secant on the multiplier
  (:func:`solve_mean_gap_by_multiplier`), adhesive load control by a secant on
  the mean gap (:func:`solve_load_by_mean_gap`).

:func:`solve_as` runs a solver type the registry resolved
(:mod:`petgap.io.solver_registry`) through the loop its control needs.
"""
import difflib
import math
import re

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from petgap.io.solver_registry import PETGAP_TYPES, method
from petgap.mechanics.problem import Load, MeanGap
from petgap.solvers.convergence import Timer
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers.pressure_cg import polonsky_keer
from petgap.solvers.settings import PETGAP_OPTIONS

_REASONS = {v: k for k, v in vars(PETSc.TAO.Reason).items() if not k.startswith("_")}


#: A TAO built-in stops as ``"stalled_round_off"`` when its KKT residual has not fallen
#: below ``TAO_STALL_FACTOR`` times its best for ``TAO_STALL_ITERATIONS`` iterations, or
#: for twice the iterations it took to reach that best if more: its line search then
#: compares energies whose differences are below double round-off, and more iterations
#: do not move it.  The window is wide because a healthy built-in solve can sit on a
#: plateau for a couple of hundred iterations before it falls again.
TAO_STALL_ITERATIONS = 500
TAO_STALL_FACTOR = 0.9

#: Options that set TAO monitors printing the objective.
TAO_MONITORS = ("tao_monitor", "tao_smonitor", "tao_cmonitor", "tao_gmonitor")


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


class _PetgapTao:
    """TAO ``python`` context running one of petgap's own conjugate-gradient solvers."""

    def __init__(self, kind, problem, control, settings, initial, monitor):
        self.kind, self.problem, self.control = kind, problem, control
        self.settings, self.initial, self.monitor = settings, initial, monitor
        self.solution = None

    def solve(self, tao):
        caller_wants = getattr(self.monitor, "wants_objective", False)

        def report(it, residual, objective=None):
            tao.setIterationNumber(it)     # what TAO's default monitor prints
            tao.monitor(its=it, f=0.0 if objective is None else objective, res=residual)
            if self.monitor is not None:
                if caller_wants and objective is not None:
                    self.monitor(it, residual, objective)
                else:
                    self.monitor(it, residual)
        # TAO's monitors print the objective: have the solvers compute it (one extra pass
        # over the contact set or the fields per iteration) only when one is asked for
        report.wants_objective = caller_wants or any(PETSc.Options().hasName(name)
                                                     for name in TAO_MONITORS)
        # -tao_max_it, read by setFromOptions, has the last word on the limit
        settings = self.settings.but(max_iterations=tao.getMaximumIterations())
        if self.kind == "pcg-pressure":
            self.solution = polonsky_keer(
                self.problem, self.control, settings,
                initial_pressure=None if self.initial is None else self.initial.pressure,
                monitor=report)
        else:
            self.solution = gap_cg(
                self.problem, self.control, settings,
                initial_gap=None if self.initial is None else self.initial.gap, monitor=report)
        tao.setIterationNumber(self.solution.iterations)
        tao.setConvergedReason(PETSc.TAO.Reason.CONVERGED_USER if self.solution.converged
                               else PETSc.TAO.Reason.DIVERGED_MAXITS)

    def view(self, tao, viewer):
        viewer.printfASCII(f"petgap preconditioned projected conjugate gradients ({self.kind})\n")


def tao_solve(problem, control, kind, settings, initial=None, monitor=None):
    """One TAO solve of ``control`` with type ``kind`` (petgap's own or a built-in).  Collective."""
    grid = problem.grid
    comm = grid.comm
    timer = Timer()
    nloc = grid.local_shape[0] * grid.local_shape[1]
    # petgap's own types keep their fields themselves and return them in the
    # solution: TAO gets an empty solution Vec, not a slab-sized copy of the gap
    # (8 bytes per point at the solve's peak)
    own = kind in PETGAP_TYPES
    x = PETSc.Vec().createMPI((0 if own else nloc, 0 if own else grid.npoints), comm=comm)
    tao = PETSc.TAO().create(comm=comm)
    try:
        tao.setSolution(x)
        tao.setMaximumIterations(settings.max_iterations)
        if own:
            context = _PetgapTao(kind, problem, control, settings, initial, monitor)
            tao.setType(PETSc.TAO.Type.PYTHON)
            tao.setPythonContext(context)
            tao.setFromOptions()
            tao.solve()
            solution = context.solution
            solution.wall_time = timer()
            return solution
        return _gap_tao(problem, control, tao, x, kind, settings, initial, monitor, timer)
    finally:
        tao.destroy()
        x.destroy()


class DimensionlessGap:
    """The load-control energy in the variables TAO works on: ``x = g / h0``, ``F = E / e``.

    Why: TAO's built-ins carry absolute constants -- the first trial step of
    the line search, the active-set estimate of BNCG and BQNLS (``as_tol``,
    ``as_step``: a trial step along the gradient compared with the distance
    to the bound), the bounds on BNCG's scaling (``delta_min``,
    ``delta_max``), the initial scaling of the quasi-Newton Hessians.  Given
    the gap in metres and the energy in joules these constants mean something
    different in every unit system and on every grid, and so would the
    iterations: the same dimensionless problem in two unit systems could
    converge in one and not in the other.

    Here the variable is the gap in units of the rms height ``h0``
    (:attr:`~petgap.mechanics.problem.ContactProblem.gap_scale`), and the energy is
    measured in ``e = k dx dy h0^2``, ``k`` the diagonal of the stiffness
    operator ``K`` (:meth:`~petgap.mechanics.half_space.ElasticHalfSpace.point_stiffness`,
    about ``1.2 E* / a0``).  Then the Hessian ``(K + v''(g)) / k`` has a unit
    diagonal where the interaction's curvature is small: a Jacobi scaling,
    and since ``K`` is a convolution its diagonal is the same ``k`` at every
    point, so the scaling is one number and the bound ``x >= 0`` stays a
    bound.  A unit step along the gradient is then a Newton step for an
    isolated point, and every constant above means the same thing in every
    unit system.  The grid enters only through dimensionless ratios (``h0 /
    a0``, the spectrum of ``K / k``), as it does in the problem itself.

    By the chain rule the gradient is ``dF/dx = (p + v'(g)) / (k h0)``, with
    ``p + v'(g)`` the gradient of the energy per pixel area, a pressure.  The
    KKT residual that decides convergence is computed from that pressure and
    the physical gap, exactly as for the other solvers (unit-free by ``h0' E*``),
    before the gradient is scaled.

    ``-tao_monitor`` and ``-tao_view`` therefore print ``F`` and ``|dF/dx|``,
    pure numbers.  Memory: one scratch array of the physical gap ``h0 x`` (the
    objective and the elastic operator work on lengths); it becomes the
    solution's gap.
    """

    def __init__(self, problem, mean_pressure):
        grid = problem.grid
        self.problem, self.mean_pressure = problem, mean_pressure
        self.length = problem.gap_scale
        self.stiffness = problem.half_space.point_stiffness()  # collective, cached
        self.energy = self.stiffness * grid.pixel_area * self.length ** 2
        self.gap = np.empty(grid.local_shape)

    def physical_gap(self, x):
        """``g = h0 x`` in the scratch array (overwritten by the next evaluation)."""
        return np.multiply(x, self.length, out=self.gap)

    def set_start(self, x, initial):
        """Fill ``x`` with the warm start's gap, or a rigid approach to the highest point."""
        problem = self.problem
        if initial is not None:
            np.maximum(initial.gap, 0.0, out=x)
        else:  # feasible: the highest point touches
            top = problem.grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
            np.subtract(top, problem.topography, out=x)
        x /= self.length

    def evaluate(self, x, grad):
        """``F(x)``, ``grad`` filled with ``dF/dx``, and the unit-free KKT residual at ``x``."""
        problem = self.problem
        g = self.physical_gap(x)
        f = problem.objective_gradient(g, grad, self.mean_pressure)  # grad = p + v'(g)
        residual = self._kkt(g, grad)
        grad *= 1.0 / (self.stiffness * self.length)
        return f / self.energy, residual

    def _kkt(self, g, stress):
        """Largest violation of ``p + v' = 0`` off the wall or ``>= 0`` at it, over ``h0' E*``."""
        local = max(np.max(np.abs(stress[g > 0]), initial=0.0),
                    np.max(-stress[g <= 0], initial=0.0))
        problem = self.problem
        return problem.grid.comm.allreduce(float(local), op=MPI.MAX) / problem.pressure_scale

    def hessian(self, shape):
        """The matrix-free Hessian in ``x``, ``(K + v''(h0 x)) / k``."""
        return GapHessian(self.problem, shape, gap_unit=self.length, energy_unit=self.energy)


class _GapCallbacks:
    """TAO's callbacks for a built-in on :class:`DimensionlessGap`: objective, test, Hessian.

    TAO hands its convergence test a *projected* gradient (zero on active bounds),
    which would hide tension at contact points.  The residual is therefore computed
    inside the objective callback from the full gradient and matched to the accepted
    iterate by a fingerprint of the variables.
    """

    def __init__(self, scaled, x, gradient, tolerance, monitor):
        self.scaled, self.x, self.gradient = scaled, x, gradient
        self.shape = scaled.problem.grid.local_shape
        self.comm = scaled.problem.grid.comm
        self.tolerance, self.monitor = tolerance, monitor
        self.residual, self.key = None, None
        self.best, self.best_at, self.stalled = np.inf, 0, False

    @staticmethod
    def fingerprint(xa):
        return (float(xa.sum()), float(np.vdot(xa, xa)))

    def objective_gradient(self, tao, xv, gv):
        xa = xv.getArray(readonly=True).reshape(self.shape)
        f, self.residual = self.scaled.evaluate(xa, gv.getArray().reshape(self.shape))
        self.key = self.fingerprint(xa)
        return f

    def convergence_test(self, tao):
        xa = self.x.getArray(readonly=True).reshape(self.shape)
        same = self.comm.allreduce(self.fingerprint(xa) == self.key, op=MPI.LAND)
        if not same:  # the last evaluation was not at the accepted point
            _, self.residual = self.scaled.evaluate(
                xa, self.gradient.getArray().reshape(self.shape))
            self.key = self.fingerprint(xa)
        residual = self.residual
        it = tao.getIterationNumber()
        if self.monitor is not None:
            self.monitor(it, residual)
        if not np.isfinite(residual):
            tao.setConvergedReason(PETSc.TAO.Reason.DIVERGED_NAN)
        elif residual <= self.tolerance:
            tao.setConvergedReason(PETSc.TAO.Reason.CONVERGED_USER)
        elif it >= tao.getMaximumIterations():
            tao.setConvergedReason(PETSc.TAO.Reason.DIVERGED_MAXITS)
        elif self._stalls(it, residual):
            self.stalled = True
            tao.setConvergedReason(PETSc.TAO.Reason.DIVERGED_USER)
        else:
            tao.setConvergedReason(PETSc.TAO.Reason.CONTINUE_ITERATING)

    def _stalls(self, it, residual):
        """Whether the residual has stopped falling (:data:`TAO_STALL_ITERATIONS`)."""
        if residual < TAO_STALL_FACTOR * self.best:
            self.best, self.best_at = residual, it
            return False
        return it - self.best_at >= max(TAO_STALL_ITERATIONS, 2 * self.best_at)

    def update_hessian(self, tao, xv, H, P):
        H.getPythonContext().set_point(xv.getArray(readonly=True).reshape(self.shape))


def _gap_tao(problem, control, tao, x, kind, settings, initial, monitor, timer):
    """Run a TAO built-in on the dimensionless load-control energy (:class:`DimensionlessGap`)."""
    grid = problem.grid
    shape = grid.local_shape
    mean_pressure = float(control.mean_pressure)
    scaled = DimensionlessGap(problem, mean_pressure)
    gradient = x.duplicate()
    lower = x.duplicate()
    upper = x.duplicate()
    lower.set(0.0)
    upper.set(PETSc.INFINITY)
    start_ops = problem.operator_applications
    scaled.set_start(x.getArray().reshape(shape), initial)
    calls = _GapCallbacks(scaled, x, gradient, settings.tolerance, monitor)
    hessian = PETSc.Mat().createPython(((x.getLocalSize(), x.getSize()),) * 2,
                                       scaled.hessian(shape), comm=grid.comm)
    hessian.setUp()
    try:
        tao.setType(kind)
        tao.setObjectiveGradient(calls.objective_gradient, gradient)
        tao.setHessian(calls.update_hessian, hessian)
        tao.setVariableBounds((lower, upper))
        tao.setConvergenceTest(calls.convergence_test)
        tao.setTolerances(gatol=0.0, grtol=0.0, gttol=0.0)
        ksp = tao.getKSP()
        if ksp is not None and ksp.handle:
            ksp.getPC().setType("none")  # matrix-free Hessian: no entries to factor
        tao.setFromOptions()
        tao.solve()
        reason_code = tao.getConvergedReason()
        reason = ("stalled_round_off" if calls.stalled
                  else _REASONS.get(reason_code, str(reason_code)).lower())
        converged = reason_code == PETSc.TAO.Reason.CONVERGED_USER
        g = scaled.physical_gap(x.getArray(readonly=True).reshape(shape))  # the scratch, kept
        pressure = problem.elastic_pressure(g) + mean_pressure
        return problem.make_solution(
            g, pressure, g <= 0, control, converged=converged,
            reason="converged_kkt" if converged else reason, solver=kind,
            iterations=tao.getIterationNumber(),
            operator_applications=problem.operator_applications - start_ops,
            wall_time=timer())
    finally:
        for v in (gradient, lower, upper, hessian):
            v.destroy()


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
    for outer in range(max_outer):
        budget = max_iterations - iterations  # the limit is per step, seed included
        if budget < 1:
            exhausted = True  # (the state is then a trial or the hard-wall seed)
            break
        solution = tao_solve(problem, MeanGap(max(gap_guess, 0.0)), kind,
                             settings.but(max_iterations=budget), secant.on_branch, monitor)
        iterations += solution.iterations
        negative_curvature += solution.negative_curvature_steps
        f = solution.mean_pressure - target
        history.append((solution.mean_gap, solution.mean_pressure))
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


class GapHessian:
    """Matrix-free Hessian of the gap energy, a PETSc ``python`` Mat context.

    ``H v = dx dy (K v + v''(g) v)``: the half-space stiffness plus, for an
    adhesive interaction, its curvature at the current gap (set by TAO through
    :meth:`set_point`).  Symmetric; positive definite on zero-mean fields for
    the hard wall.

    With ``gap_unit`` ``l`` and ``energy_unit`` ``e`` it is the Hessian in the
    variables ``x = g / l`` of the energy ``E / e``: ``(dx dy l^2 / e) (K v +
    v''(l x) v)``, and :meth:`set_point` takes ``x`` (the scaling of
    :class:`DimensionlessGap`).  The defaults give the physical Hessian.
    """

    def __init__(self, problem, shape, gap_unit=1.0, energy_unit=1.0):
        self.problem, self.shape = problem, shape
        self.gap_unit = float(gap_unit)
        self.factor = problem.grid.pixel_area * self.gap_unit ** 2 / energy_unit
        self.curvature = None

    def set_point(self, x):
        interaction = self.problem.interaction
        self.curvature = interaction.curvature(self.gap_unit * x) if interaction.adhesive \
            else None

    def mult(self, mat, xv, yv):
        problem = self.problem
        v = xv.getArray(readonly=True).reshape(self.shape)
        y = yv.getArray().reshape(self.shape)
        problem.half_space.pressure(v, out=y)
        if self.curvature is not None:
            y += self.curvature * v
        y *= self.factor

    def multTranspose(self, mat, xv, yv):
        self.mult(mat, xv, yv)


# ------------------------------------------------------------- option checking
#: The PETSc options a petgap run reads, with the kind of value each takes:
#: ``"int"``, ``"real"``, ``"bool"`` (a bare flag is true), ``"word"`` (any
#: text, checked elsewhere: ``tao_type``), ``"viewer"`` (an optional viewer
#: spec such as ``ascii:file.txt``), ``"flag"`` (no value), ``"precision"``
#: (``single`` or ``double``).  PETSc's database
#: cannot say which options were read (petsc4py wraps no "used" query, and
#: petgap pushes and pops its options around every solve), so they are checked
#: against this list before anything runs: a misspelt name is found before
#: the run rather than ignored, and a malformed value is named instead of
#: ending in PETSc's error code.
KNOWN_OPTIONS = {
    # TAO, read by TaoSetFromOptions for every type (petgap's own run as TAO "python")
    "tao_type": "word", "tao_max_it": "int", "tao_max_funcs": "int",
    "tao_gatol": "real", "tao_grtol": "real", "tao_gttol": "real", "tao_catol": "real",
    "tao_crtol": "real", "tao_fmin": "real", "tao_steptol": "real", "tao_trust0": "real",
    "tao_monitor": "viewer", "tao_smonitor": "viewer", "tao_cmonitor": "viewer",
    "tao_gmonitor": "viewer", "tao_xmonitor": "viewer", "tao_monitor_cancel": "bool",
    "tao_view": "viewer", "tao_converged_reason": "viewer", "tao_view_solution": "viewer",
    "tao_view_gradient": "viewer", "tao_view_stepdirection": "viewer",
    "tao_view_ls_residual": "viewer", "tao_recycle_history": "bool", "tao_mf_hessian": "bool",
    "tao_fd_gradient": "bool", "tao_fd_hessian": "bool", "tao_subset_type": "word",
    "tao_ls_type": "word",
    # petgap's own (the settings of petgap.solvers.settings.read_settings)
    **{name: kind for name, (_, kind) in PETGAP_OPTIONS.items()},
    # PETSc at large (profiling, debugging), read at initialisation or finalisation
    "log_view": "viewer", "log_view_memory": "bool", "log_all": "bool", "log_trace": "viewer",
    "log_exclude": "word", "options_left": "bool", "options_view": "viewer",
    "options_monitor": "viewer", "memory_view": "bool", "malloc_debug": "bool",
    "malloc_dump": "bool", "malloc_view": "bool", "info": "viewer", "help": "flag",
    "on_error_abort": "flag", "fp_trap": "bool", "no_signal_handler": "bool",
    "check_pointer_intensity": "int", "objects_dump": "flag",
}

#: Prefixes of the options of one TAO type, its line search and its inner
#: solvers (read only when that type runs, and too many to list).
KNOWN_PREFIXES = ("tao_ls_", "tao_bncg_", "tao_blmvm_", "tao_bqnls_", "tao_bqnk_", "tao_bnk_",
                  "tao_gpcg_", "tao_bnls_", "tao_bntr_", "tao_bntl_", "tao_view_",
                  "tao_monitor_", "tao_draw_", "tao_ksp_", "tao_pc_", "tao_mat_lmvm_",
                  "tao_bqnls_mat_lmvm_")

_TRUE_FALSE = ("true", "false", "yes", "no", "on", "off", "1", "0")
_SPECIAL = ("petsc_default", "default", "petsc_decide", "decide", "petsc_determine",
            "determine")
_INT = re.compile(r"^[-+]?\d+$")


def option_problem(name, value):
    """What is wrong with the value of the known option ``name``, or None.

    Parses as PETSc will (integers, also ``1e3``; reals; booleans
    ``true/false/yes/no/on/off/1/0``, a bare flag is true; PETSc's
    ``DEFAULT``/``DECIDE`` names) and returns ``(problem, allowed)``.
    """
    kind = KNOWN_OPTIONS.get(name)
    text = "" if value is None else str(value).strip()
    if kind == "int":
        if text == "":
            return "has no value", "an integer, e.g. 100"
        if _INT.match(text) or text.lower() in _SPECIAL:
            return None
        try:
            x = float(text)
        except ValueError:
            return "is not an integer", "an integer, e.g. 100"
        if math.isfinite(x) and x == int(x):
            return None
        return "is not an integer", "an integer, e.g. 100"
    if kind == "real":
        if text == "":
            return "has no value", "a real number, e.g. 1e-8"
        if text.lower() in _SPECIAL:
            return None
        try:
            x = float(text)
        except ValueError:
            return "is not a number", "a real number, e.g. 1e-8"
        return None if not math.isnan(x) else ("is not a number", "a real number, e.g. 1e-8")
    if kind == "bool":
        if text == "" or text.lower() in _TRUE_FALSE:
            return None
        return "is not a boolean", "true or false (yes/no, on/off, 1/0), or no value (true)"
    if kind == "flag" and text:
        return "takes no value", "the bare option"
    if kind == "precision" and text not in ("single", "double"):
        return "is not a precision", "single or double"
    return None


def check_petsc_options(options):
    """Check PETSc options ``{name: value}`` (names without the dash).

    Returns ``(errors, unknown)``: ``errors`` a list of ``(name, value, problem,
    allowed)`` for malformed values of known options, ``unknown`` a list of
    ``(name, suggestion or None)`` for names petgap does not read (see
    :data:`KNOWN_OPTIONS` and :data:`KNOWN_PREFIXES`).
    """
    errors, unknown = [], []
    for raw, value in dict(options or {}).items():
        name = str(raw).lstrip("-")
        if name in KNOWN_OPTIONS:
            problem = option_problem(name, value)
            if problem is not None:
                errors.append((name, value, *problem))
        elif not name.startswith(KNOWN_PREFIXES):
            close = difflib.get_close_matches(name, list(KNOWN_OPTIONS), n=1, cutoff=0.75)
            unknown.append((name, close[0] if close else None))
    return errors, unknown
