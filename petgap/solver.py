"""Solving a contact problem with PETSc TAO, and sweeps of controls.

The TAO object is created for every solve with the solution Vec laid out as
the grid's real-space slab, and ``setFromOptions()`` is called last, so the
PETSc options database (``-tao_type``, ``-tao_monitor``, ``-tao_max_it``,
``-tao_view``, ``-log_view``...) has the final word, as every PETSc user expects.

Solver types
------------
``pcg`` (default, a TAO ``python`` type)
    petgap's preconditioned projected conjugate gradients, in the formulation
    that suits the problem: on the pressure (``pcg-pressure``,
    :mod:`petgap.polonsky_keer`) for non-adhesive load control, on the gap
    (``pcg-gap``, :mod:`petgap.gap_cg`) otherwise.  Adhesive load control is a
    secant iteration on the mean gap around warm-started mean-gap solves, so
    that each step reports which branch it landed on.
``pcg-pressure``, ``pcg-gap``
    Force one formulation.
``bncg``, ``blmvm``, ``bqnls``, ``gpcg`` (TAO built-ins)
    Bound-constrained minimisation over the gap ``g >= 0`` of the load-control
    energy :meth:`petgap.contact.ContactProblem.objective_gradient`.  Mean-gap
    control wraps them in an exact multiplier update: the mean pressure ``P0``
    is adjusted by a secant iteration on ``log P0`` until the mean gap matches.

Every type stops on the same unit-free KKT test (largest pressure violation
over ``h0' E*`` and gap violation over ``h0`` below ``tolerance``), never on
TAO's unit-dependent gradient norms, and reports ``converged=False`` with
TAO's reason when it stops for any other cause.
"""
import math

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .contact import Load, MeanGap, Timer
from .gap_cg import gap_cg
from .polonsky_keer import polonsky_keer, touching_state

#: Solver types a scene may name.
SOLVER_TYPES = ("pcg", "pcg-pressure", "pcg-gap", "bncg", "blmvm", "bqnls", "gpcg")
PETGAP_TYPES = ("pcg", "pcg-pressure", "pcg-gap")
_REASONS = {v: k for k, v in vars(PETSc.TAO.Reason).items() if not k.startswith("_")}


class _PetgapTao:
    """TAO ``python`` context running one of petgap's own conjugate-gradient solvers."""

    def __init__(self, kind, problem, control, tolerance, initial, monitor):
        self.kind, self.problem, self.control = kind, problem, control
        self.tolerance, self.initial, self.monitor = tolerance, initial, monitor
        self.solution = None

    def solve(self, tao):
        def report(it, residual):
            tao.monitor(its=it, f=0.0, res=residual)
            if self.monitor is not None:
                self.monitor(it, residual)
        maxit = tao.getMaximumIterations()
        if self.kind == "pcg-pressure":
            self.solution = polonsky_keer(
                self.problem, self.control, tolerance=self.tolerance, max_iterations=maxit,
                initial_pressure=None if self.initial is None else self.initial.pressure,
                monitor=report)
        else:
            self.solution = gap_cg(
                self.problem, self.control, tolerance=self.tolerance, max_iterations=maxit,
                initial_gap=None if self.initial is None else self.initial.gap, monitor=report)
        x = tao.getSolution()
        x.getArray()[:] = self.solution.gap.ravel()
        tao.setIterationNumber(self.solution.iterations)
        tao.setConvergedReason(PETSc.TAO.Reason.CONVERGED_USER if self.solution.converged
                               else PETSc.TAO.Reason.DIVERGED_MAXITS)

    def view(self, tao, viewer):
        viewer.printfASCII(f"petgap preconditioned projected conjugate gradients ({self.kind})\n")


def solve(problem, control, *, solver="pcg", tolerance=1e-8, max_iterations=10000,
          initial=None, options=None, monitor=None):
    """Solve one contact problem.

    Parameters
    ----------
    problem : petgap.contact.ContactProblem
    control : petgap.contact.Load or petgap.contact.MeanGap
    solver : str
        One of :data:`SOLVER_TYPES`; ``-tao_type`` in the options overrides it.
    tolerance : float
        Unit-free KKT tolerance.
    max_iterations : int
        Iteration limit of the whole solve, summed over the inner solves of the
        outer loops (adhesive load control, mean-gap control with TAO
        built-ins), so that a sweep step never costs more (``-tao_max_it``
        overrides it for each TAO solve).
    initial : petgap.contact.ContactSolution, optional
        Warm start: the previous state of a sweep.
    options : dict, optional
        PETSc options (without the leading dash) set for this solve only.
    monitor : callable, optional
        ``monitor(iteration, residual)``, called on every rank.

    Returns
    -------
    petgap.contact.ContactSolution
    """
    if solver not in SOLVER_TYPES:
        raise ValueError(f"solver {solver!r} is not one of {', '.join(SOLVER_TYPES)}")
    if not (isinstance(tolerance, float) or isinstance(tolerance, int)) or not 0 < tolerance < 1:
        raise ValueError(f"tolerance must be in (0, 1), got {tolerance!r}")
    with _options(options):
        tao_type = PETSc.Options().getString("tao_type", solver)
    if tao_type == "python":
        tao_type = "pcg"
    if tao_type not in SOLVER_TYPES:
        raise ValueError(f"-tao_type {tao_type} is not supported; use one of {', '.join(SOLVER_TYPES)}")
    adhesive = problem.interaction.adhesive
    if isinstance(control, Load) and not adhesive and control.mean_pressure == 0:
        return touching_state(problem, control)  # nothing to solve, for any solver
    if tao_type == "pcg":
        tao_type = "pcg-pressure" if (isinstance(control, Load) and not adhesive) else "pcg-gap"
    if tao_type == "pcg-pressure" and adhesive:
        raise ValueError("solver 'pcg-pressure' (Polonsky-Keer on the pressure) is for "
                         "non-adhesive contact; use pcg or pcg-gap for adhesion")
    if isinstance(control, Load) and adhesive and tao_type == "pcg-gap":
        return _solve_load_by_mean_gap(problem, control, tolerance, max_iterations, initial,
                                       options, monitor)
    if isinstance(control, MeanGap) and tao_type not in PETGAP_TYPES:
        return _solve_mean_gap_by_multiplier(problem, control, tao_type, tolerance,
                                             max_iterations, initial, options, monitor)
    return _tao_solve(problem, control, tao_type, tolerance, max_iterations, initial, options,
                      monitor)


def sweep(problem, controls, **kwargs):
    """Solve a list of controls in order, each warm-started from the previous one.

    Yields each :class:`~petgap.contact.ContactSolution` as soon as it is done,
    so the caller can store it before the next step starts.  Each solution gets

    * ``direction``: ``"loading"`` when the control pushes the surfaces together
      (larger load, smaller mean gap) relative to the previous step,
      ``"unloading"`` when it pulls them apart, ``"start"`` for the first;
    * ``jump``: True when the area at zero gap (``zero_gap_fraction``: repulsive
      and tensile contact alike) changed faster (per unit control) than 3 times
      the previous step did *and* by more than 1 % of the cell -- the signature
      of an instability (snap-in, pull-off) where the warm start left one branch
      of an adhesive, multistable problem for another.  A sweep that reverses
      direction therefore exposes hysteresis: the same control value may carry
      different states on loading and unloading, and which one was found is
      recorded, never averaged away.

      Why not the repulsive area (``contact_fraction``): near the end of a
      JKR-like branch under mean-gap control the surfaces are still stuck, but
      all in tension, so the repulsive area is already zero and pull-off leaves
      it unchanged.  Being a comparison of rates, the test needs a step onto the
      instability not much longer than the steps before it: near the end of a
      branch the area changes like ``sqrt(g_end - g_bar)``, ever faster, and a
      step that ends just short of pull-off sets a high rate for the next one
      to beat (``tests/test_adhesion.py`` resolves Johnson's pull-off with
      steps of 0.2, 0.1, 0.07 and 0.03 ``h_a``).
    """
    previous = kwargs.pop("initial", None)
    last_rate = None
    for control in controls:
        solution = solve(problem, control, initial=previous, **kwargs)
        last_rate = annotate_step(solution, previous, last_rate)
        previous = solution
        yield solution


def annotate_step(solution, previous, last_rate):
    """Set ``solution.direction`` and ``solution.jump`` relative to ``previous`` (see :func:`sweep`).

    Returns the rate of change of the area at zero gap per unit control, for
    the next step's comparison (None when there is no previous step to compare
    with: the first step of a sweep has no reference and is never a jump; nor
    is a step after a state whose ``zero_gap_fraction`` is None, a step read
    back from a result file that stores neither it nor the gap).
    """
    solution.direction, solution.jump = "start", False
    if previous is None or previous.control.kind != solution.control.kind:
        return None
    change = solution.control.value - previous.control.value
    pushes = change > 0 if isinstance(solution.control, Load) else change < 0
    solution.direction = "loading" if pushes else "unloading"
    if solution.zero_gap_fraction is None or previous.zero_gap_fraction is None:
        return None
    dc = solution.zero_gap_fraction - previous.zero_gap_fraction
    rate = abs(dc / change) if change != 0 else (math.inf if dc else 0.0)
    solution.jump = bool(last_rate is not None and abs(dc) > 0.01 and rate > 3 * last_rate)
    return rate


# --------------------------------------------------------------------- TAO
def _tao_solve(problem, control, tao_type, tolerance, max_iterations, initial, options, monitor):
    grid = problem.grid
    comm = grid.comm
    timer = Timer()
    nloc = grid.local_shape[0] * grid.local_shape[1]
    x = PETSc.Vec().createMPI((nloc, grid.npoints), comm=comm)
    tao = PETSc.TAO().create(comm=comm)
    try:
        tao.setSolution(x)
        tao.setMaximumIterations(max_iterations)
        if tao_type in PETGAP_TYPES:
            context = _PetgapTao(tao_type, problem, control, tolerance, initial, monitor)
            tao.setType(PETSc.TAO.Type.PYTHON)
            tao.setPythonContext(context)
            with _options(options):
                tao.setFromOptions()
            tao.solve()
            solution = context.solution
            solution.wall_time = timer()
            return solution
        return _gap_tao(problem, control, tao, x, tao_type, tolerance, initial, options,
                        monitor, timer)
    finally:
        tao.destroy()
        x.destroy()


def _gap_tao(problem, control, tao, x, tao_type, tolerance, initial, options, monitor, timer):
    grid = problem.grid
    shape = grid.local_shape
    mean_pressure = float(control.mean_pressure)
    if mean_pressure < 0 and not problem.interaction.adhesive:
        raise ValueError(f"mean pressure {mean_pressure} < 0: a non-adhesive interface cannot "
                         f"carry a tensile load")
    area = grid.pixel_area
    gradient = x.duplicate()
    lower = x.duplicate()
    upper = x.duplicate()
    lower.set(0.0)
    upper.set(PETSc.INFINITY)
    start_ops = problem.operator_applications
    gap = x.getArray().reshape(shape)
    if initial is not None:
        gap[...] = np.maximum(initial.gap, 0.0)
    else:
        # Rigid approach to the highest point: a feasible start.
        top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
        gap[...] = top - problem.topography
    # TAO hands its convergence test a *projected* gradient (zero on active
    # bounds), which would hide tension at contact points.  The residual is
    # therefore computed inside the objective callback from the full gradient
    # and matched to the accepted iterate by a fingerprint of the gap field.
    cache = {}

    def kkt(g, grad):
        local = max(np.max(np.abs(grad[g > 0]), initial=0.0),
                    np.max(-grad[g <= 0], initial=0.0)) / area
        return grid.comm.allreduce(float(local), op=MPI.MAX) / problem.pressure_scale

    def fingerprint(g):
        return (float(g.sum()), float(np.vdot(g, g)))

    def objective_gradient(tao, xv, gv):
        g = xv.getArray(readonly=True).reshape(shape)
        grad = gv.getArray().reshape(shape)
        f = problem.objective_gradient(g, grad, mean_pressure)
        grad *= area
        cache["key"], cache["residual"] = fingerprint(g), kkt(g, grad)
        return f

    def convergence_test(tao):
        g = x.getArray(readonly=True).reshape(shape)
        same = grid.comm.allreduce(fingerprint(g) == cache.get("key"), op=MPI.LAND)
        if not same:  # the last evaluation was not at the accepted point
            grad = gradient.getArray().reshape(shape)
            problem.objective_gradient(g, grad, mean_pressure)
            grad *= area
            cache["key"], cache["residual"] = fingerprint(g), kkt(g, grad)
        residual = cache["residual"]
        it = tao.getIterationNumber()
        if monitor is not None:
            monitor(it, residual)
        if not np.isfinite(residual):
            tao.setConvergedReason(PETSc.TAO.Reason.DIVERGED_NAN)
        elif residual <= tolerance:
            tao.setConvergedReason(PETSc.TAO.Reason.CONVERGED_USER)
        elif it >= tao.getMaximumIterations():
            tao.setConvergedReason(PETSc.TAO.Reason.DIVERGED_MAXITS)
        else:
            tao.setConvergedReason(PETSc.TAO.Reason.CONTINUE_ITERATING)

    hessian = PETSc.Mat().createPython(((x.getLocalSize(), x.getSize()),) * 2,
                                       GapHessian(problem, shape), comm=grid.comm)
    hessian.setUp()

    def update_hessian(tao, xv, H, P):
        H.getPythonContext().set_point(xv.getArray(readonly=True).reshape(shape))

    try:
        tao.setType(tao_type)
        tao.setObjectiveGradient(objective_gradient, gradient)
        tao.setHessian(update_hessian, hessian)
        tao.setVariableBounds((lower, upper))
        tao.setConvergenceTest(convergence_test)
        tao.setTolerances(gatol=0.0, grtol=0.0, gttol=0.0)
        ksp = tao.getKSP()
        if ksp is not None and ksp.handle:
            ksp.getPC().setType("none")  # matrix-free Hessian: no entries to factor
        with _options(options):
            tao.setFromOptions()
        tao.solve()
        reason_code = tao.getConvergedReason()
        reason = _REASONS.get(reason_code, str(reason_code)).lower()
        converged = reason_code == PETSc.TAO.Reason.CONVERGED_USER
        g = x.getArray(readonly=True).reshape(shape).copy()
        pressure = problem.elastic_pressure(g) + mean_pressure
        return problem.make_solution(
            g, pressure, g <= 0, control, converged=converged,
            reason="converged_kkt" if converged else reason, solver=tao_type,
            iterations=tao.getIterationNumber(),
            operator_applications=problem.operator_applications - start_ops,
            wall_time=timer())
    finally:
        for v in (gradient, lower, upper, hessian):
            v.destroy()


def _solve_mean_gap_by_multiplier(problem, control, tao_type, tolerance, max_iterations,
                                  initial, options, monitor, max_outer=60):
    """Mean-gap control for gap-space TAO types: secant on log(P0) until mean(g) = g_bar."""
    timer = Timer()
    target = float(control.mean_gap)
    if not target >= 0:
        raise ValueError(f"mean gap {target} < 0 is impossible with a hard wall (gap >= 0)")
    h0 = problem.gap_scale
    grid = problem.grid
    top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
    if not problem.interaction.adhesive and target >= top - problem.mean_height:
        # the rigid surface's highest summit stays clear: no contact, no pressure
        gap = target + problem.mean_height - problem.topography
        zero = np.zeros(grid.local_shape)
        return problem.make_solution(gap, zero, gap <= 0, control, converged=True,
                                     reason="no_contact", solver=f"{tao_type}+multiplier",
                                     iterations=0, operator_applications=0, wall_time=timer())
    # Inner solves must resolve the mean gap finer than the outer test asks.
    tolerance_inner = tolerance * 1e-2
    start_ops = problem.operator_applications
    iterations = 0
    history = []
    # Starting guess: the previous multiplier, or a typical rough-contact pressure.
    pressure = initial.mean_pressure if initial is not None and initial.mean_pressure > 0 \
        else 0.01 * problem.pressure_scale
    points = []
    solution = initial
    exhausted = False
    for outer in range(max_outer):
        budget = max_iterations - iterations  # the limit is per step, not per inner solve
        if budget < 1:
            exhausted = True
            break
        solution = _tao_solve(problem, Load(pressure), tao_type, tolerance_inner, budget,
                              solution, options, monitor)
        iterations += solution.iterations
        error = (solution.mean_gap - target) / h0
        history.append((pressure, solution.mean_gap))
        if not solution.converged or abs(error) <= tolerance:
            break
        if len(history) >= 3 and history[-1][1] == history[-2][1] == history[-3][1]:
            break  # the inner solves no longer move the mean gap: reported as not converged
        points.append((math.log(pressure), solution.mean_gap))
        if len(points) == 1:
            # mean gap ~ -gamma h0 log P with gamma ~ 0.5 for rough contact
            log_p = points[0][0] + (points[0][1] - target) / (0.5 * h0)
        else:
            (l1, g1), (l2, g2) = points[-2], points[-1]
            slope = (g2 - g1) / (l2 - l1) if l2 != l1 else -0.5 * h0
            if not slope < 0:
                slope = -0.5 * h0
            log_p = l2 + (target - g2) / slope
        pressure = math.exp(min(max(log_p, points[-1][0] - 5.0), points[-1][0] + 5.0))
    converged = not exhausted and solution.converged and \
        abs((solution.mean_gap - target) / h0) <= tolerance
    reason = "converged_kkt" if converged else "max_iterations" if exhausted else \
        (solution.reason if not solution.converged else "multiplier_not_converged")
    result = problem.make_solution(
        solution.gap, solution.pressure, solution.gap <= 0, control, converged=converged,
        reason=reason, solver=f"{tao_type}+multiplier", iterations=iterations,
        operator_applications=problem.operator_applications - start_ops, wall_time=timer(),
        history=history)
    return result


def _solve_load_by_mean_gap(problem, control, tolerance, max_iterations, initial, options,
                            monitor, max_outer=60):
    """Adhesive load control: find the mean gap whose multiplier is the load.

    A safeguarded secant (regula falsi once the root is bracketed) on
    ``P(g_bar) - P0`` with warm-started mean-gap solves.  ``P(g_bar)`` of an
    adhesive interface need not be monotone; the branch found is the one
    connected to the starting gap (the previous step of a sweep, else the
    non-adhesive solution at the same load), and is reported in ``history``.
    Every trial is warm-started from the last state on that branch; a trial in
    which every contact has let go of the wall is not followed (adhesion is
    hysteretic: a separated warm start never finds the contact again) but
    bisected back towards the branch, down to ``1e-3 h0`` of mean gap: if the
    branch ends there without carrying the load, that is pull-off, and the
    separated state is returned with ``converged=False``.  Full contact
    (``g_bar = 0``) carries every load that leaves no wall reaction tensile.
    """
    from .contact import ContactProblem
    timer = Timer()
    target = float(control.mean_pressure)
    h0 = problem.gap_scale
    start_ops = problem.operator_applications
    iterations = 0
    if initial is not None:
        gap_guess, state = initial.mean_gap, initial
    else:
        hard = ContactProblem.__new__(ContactProblem)
        hard.__dict__.update(problem.__dict__)
        from .interaction import HardWall
        hard.interaction = HardWall()
        seed = polonsky_keer(hard, Load(max(target, 1e-3 * problem.pressure_scale)),
                             tolerance=max(tolerance, 1e-6), max_iterations=max_iterations)
        problem.operator_applications = hard.operator_applications
        iterations += seed.iterations
        gap_guess, state = seed.mean_gap, seed
    points, history = [], []
    lo = hi = None  # brackets: (gap, P - P0) with opposite signs
    solution = on_branch = state
    negative_curvature = 0

    def touching(s):
        return problem.grid.comm.allreduce(int(np.count_nonzero(s.gap <= 0))) > 0
    guard = touching(state)
    release = None  # smallest mean gap tried at which every contact let go
    exhausted = False
    for outer in range(max_outer):
        budget = max_iterations - iterations  # the limit is per step, seed included
        if budget < 1:
            exhausted = True  # (the state is then a trial or the hard-wall seed)
            break
        solution = _tao_solve(problem, MeanGap(max(gap_guess, 0.0)), "pcg-gap", tolerance,
                              budget, on_branch, options, monitor)
        iterations += solution.iterations
        negative_curvature += solution.negative_curvature_steps
        f = solution.mean_pressure - target
        history.append((solution.mean_gap, solution.mean_pressure))
        if not solution.converged or abs(f) <= tolerance * problem.pressure_scale:
            break
        if solution.mean_gap == 0.0:
            # Full contact (every gap at the wall): the mean gap cannot resolve the
            # load any further, and this state carries every P0 at which no wall
            # reaction is tensile, p_el + P0 + v'(0) >= 0 (adhesive jump-in).
            p_el = solution.pressure - solution.mean_pressure
            least = -problem.grid.comm.allreduce(
                float(np.min(p_el + problem.interaction.derivative(0.0))), op=MPI.MIN)
            if target >= least:
                solution.pressure = p_el + target
                solution.mean_pressure = problem.grid.mean(solution.pressure)
                break
        if guard and not touching(solution):
            # off the branch (overshoot, or past its end): bisect back towards it
            release = solution.mean_gap if release is None else min(release, solution.mean_gap)
            if release - on_branch.mean_gap <= 1e-3 * h0:
                break  # pull-off: the branch ends without carrying the load
            gap_guess = 0.5 * (on_branch.mean_gap + release)
            continue
        on_branch = solution
        points.append((solution.mean_gap, f))
        if f > 0:
            lo = (solution.mean_gap, f) if lo is None or solution.mean_gap > lo[0] else lo
        else:
            hi = (solution.mean_gap, f) if hi is None or solution.mean_gap < hi[0] else hi
        if len(points) == 1:
            # stiffness estimate of rough contact: dP/dg ~ -P / (0.5 h0)
            slope = -max(abs(solution.mean_pressure), 1e-3 * problem.pressure_scale) / (0.5 * h0)
        else:
            (g1, f1), (g2, f2) = points[-2], points[-1]
            slope = (f2 - f1) / (g2 - g1) if g2 != g1 else -problem.pressure_scale / h0
        step = -f / slope if slope < 0 else (0.5 * h0 if f > 0 else -0.5 * h0)
        gap_guess = solution.mean_gap + max(min(step, h0), -h0)
        if lo is not None and hi is not None and not (min(lo[0], hi[0]) < gap_guess < max(lo[0], hi[0])):
            # regula falsi inside the bracket
            gap_guess = lo[0] - lo[1] * (hi[0] - lo[0]) / (hi[1] - lo[1])
        if release is not None:
            gap_guess = min(gap_guess, 0.5 * (solution.mean_gap + release))
    converged = not exhausted and solution.converged and \
        abs(solution.mean_pressure - target) <= tolerance * problem.pressure_scale
    reason = "converged_kkt" if converged else "max_iterations" if exhausted else \
        (solution.reason if not solution.converged else "load_not_reached")
    result = problem.make_solution(
        solution.gap, solution.pressure, solution.gap <= 0, control, converged=converged,
        reason=reason, solver="pcg-gap+mean-gap-secant", iterations=iterations,
        operator_applications=problem.operator_applications - start_ops, wall_time=timer(),
        history=history)
    result.negative_curvature_steps = negative_curvature  # of all inner solves
    return result


class GapHessian:
    """Matrix-free Hessian of the gap energy, a PETSc ``python`` Mat context.

    ``H v = dx dy (K v + v''(g) v)``: the half-space stiffness plus, for an
    adhesive interaction, its curvature at the current gap (set by TAO through
    :meth:`set_point`).  Symmetric; positive definite on zero-mean fields for
    the hard wall.
    """

    def __init__(self, problem, shape):
        self.problem, self.shape = problem, shape
        self.curvature = None

    def set_point(self, gap):
        interaction = self.problem.interaction
        self.curvature = interaction.curvature(gap).copy() if interaction.adhesive else None

    def mult(self, mat, xv, yv):
        problem = self.problem
        v = xv.getArray(readonly=True).reshape(self.shape)
        y = yv.getArray().reshape(self.shape)
        problem.operator_applications += 1
        problem.half_space.pressure(v, out=y)
        if self.curvature is not None:
            y += self.curvature * v
        y *= problem.grid.pixel_area

    def multTranspose(self, mat, xv, yv):
        self.mult(mat, xv, yv)


class _options:
    """Push PETSc options for the duration of a ``with`` block, then restore them."""

    def __init__(self, options):
        self.options = {str(k).lstrip("-"): ("" if v is None else str(v))
                        for k, v in (options or {}).items()}
        self.saved = {}

    def __enter__(self):
        db = PETSc.Options()
        for key, value in self.options.items():
            self.saved[key] = db.getString(key, None) if db.hasName(key) else None
            db.setValue(key, value)
        return db

    def __exit__(self, *exc):
        db = PETSc.Options()
        for key, old in self.saved.items():
            if old is None:
                db.delValue(key)
            else:
                db.setValue(key, old)
        return False
