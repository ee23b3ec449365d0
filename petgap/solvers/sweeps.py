"""Sweeps: solves in order, each warm-started from the one before.

A sweep follows one branch of a possibly multistable (adhesive) problem by
warm-starting every step from the previous state, and marks each state with
the direction of the step and whether it jumped to another branch, so that
hysteresis (snap-in, pull-off) is recorded rather than averaged away.
"""
import math
from collections.abc import Hashable
from dataclasses import dataclass
from types import SimpleNamespace

from petgap.mechanics.problem import MeanGap
from petgap.solvers.dispatch import solve


@dataclass
class SweepStep:
    """One step of a :func:`sweep` in its general form.

    Attributes
    ----------
    control : Load, MeanGap or callable
        What is imposed; a callable ``control(states)`` gets the scalar results
        of the steps before this one (a list, in sweep order, of objects with the
        attributes of :meth:`~petgap.mechanics.problem.ContactSolution.scalars`:
        ``mean_gap``, ``mean_pressure``, ...) and returns the control,
        for a value that only an earlier step can tell (the paper's protocol
        imposes on each adhesive step the mean gap of its non-adhesive
        reference step).
    problem : petgap.mechanics.problem.ContactProblem, optional
        The problem of this step (default: the sweep's ``problem``), so that
        one sweep can hold hard-wall and adhesive steps.
    chain : hashable, optional
        Steps of one chain warm-start each other and are compared for
        direction and jumps; steps of other chains are not.  Default: one
        chain for the whole sweep.
    state : object, optional
        A state already found (a step of an interrupted run read back from
        its file): not solved again, but annotated and, if it has a ``gap``,
        the warm start of the next step of its chain.  It needs ``control``,
        ``mean_gap`` and ``zero_gap_fraction`` (None allowed).
    """

    control: object = None
    problem: object = None
    chain: Hashable = None
    state: object = None


def sweep(problem, steps, *, initial=None, before=None, **solve_options):
    """Solve steps in order, each warm-started from the previous step of its chain.

    The simple form ``sweep(problem, [Load(p1), Load(p2), ...], tolerance=...)``
    is one chain of controls on one problem.  Each item of ``steps`` may also
    be a :class:`SweepStep` (its own problem, chain, a control computed from
    earlier states, or a state already found), which is how ``petgap run``
    drives a scene's steps (:mod:`petgap.app.run`).

    Yields each state as soon as it is found (or, for a step given with its
    ``state``, that state), in the order of ``steps``, so the caller can store
    it before the next step starts.  Besides the step being solved, the sweep
    holds the state of each chain that has steps to come (their warm start) and
    the scalars of every step (what a later control may ask): a caller that lets
    go of each yielded state before asking for the next keeps a series of chains
    (the works of adhesion of the paper's protocol) at the memory of one solve and
    one warm start.  Each state gets

    * ``direction``: ``"loading"`` when the control pushes the surfaces together
      (larger load, deeper indentation, smaller mean gap) relative to the previous step,
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
      to beat (``tests/solvers/test_adhesion.py`` resolves Johnson's pull-off with
      steps of 0.2, 0.1, 0.07 and 0.03 ``h_a``).

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem or None
        The problem of every step that names none.
    steps : iterable of Load, MeanGap, callable or SweepStep
    initial : petgap.mechanics.problem.ContactSolution, optional
        The state before the first step of every chain: its warm start and
        the reference of its direction.
    before : callable, optional
        ``before(index, control)`` is called before each solve (not for a
        step given with its state); a dict it returns updates the solve
        options of that step only (e.g. its own ``monitor``).
    **solve_options
        Passed to :func:`petgap.solvers.dispatch.solve` for every step.
    """
    steps = [step if isinstance(step, SweepStep) else SweepStep(control=step) for step in steps]
    # the last step of each chain: after it, the chain's state is no warm start, and the
    # sweep lets it go (a series of chains holds no gap and pressure per chain)
    ends = {step.chain: index for index, step in enumerate(steps)}
    states, previous, rates = [], {}, {}
    for index, step in enumerate(steps):
        chain = step.chain
        last = previous.get(chain, initial)
        state = step.state
        if state is None:
            control = step.control(states) if callable(step.control) else step.control
            options = dict(solve_options)
            if before is not None:
                options.update(before(index, control) or {})
            warm = last if getattr(last, "gap", None) is not None else None
            state = solve(step.problem if step.problem is not None else problem, control,
                          initial=warm, **options)
        rates[chain] = annotate_step(state, last, rates.get(chain))
        if ends[chain] > index:
            previous[chain] = state
        else:   # no step of the chain comes: nothing reads its state again
            previous.pop(chain, None)
        # what a later step's control may ask of this one, without its fields: a long
        # sweep holds one state per chain (the warm start), not a gap and a pressure per step
        states.append(SimpleNamespace(**state.scalars()) if hasattr(state, "scalars")
                      else state)
        yield state


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
    # a mean gap pushes by shrinking; a load and an indentation by growing
    pushes = change < 0 if isinstance(solution.control, MeanGap) else change > 0
    solution.direction = "loading" if pushes else "unloading"
    if solution.zero_gap_fraction is None or previous.zero_gap_fraction is None:
        return None
    dc = solution.zero_gap_fraction - previous.zero_gap_fraction
    rate = abs(dc / change) if change != 0 else (math.inf if dc else 0.0)
    solution.jump = bool(last_rate is not None and abs(dc) > 0.01 and rate > 3 * last_rate)
    return rate
