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
  (:class:`DimensionlessGap`) with a matrix-free Hessian (:class:`GapHessian`).

The outer loops that turn one control into another are
:mod:`petgap.solvers.control_loops`; the options a run may give are checked by
:mod:`petgap.solvers.options`.
"""
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from petgap.io.solver_registry import PETGAP_TYPES
from petgap.solvers.convergence import BestResidual, Timer
from petgap.solvers.gap_cg import gap_cg
from petgap.solvers.pressure_cg import polonsky_keer

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
        self.best, self.stalled = BestResidual(TAO_STALL_FACTOR), False

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
        since = self.best.since(it, residual)
        return since >= max(TAO_STALL_ITERATIONS, 2 * self.best.at)

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
