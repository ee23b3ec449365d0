"""The sweep driver (petgap.solvers.sweeps): chains, controls from earlier states,
states already found, and the simple form.

Every test makes all its collective calls before its first assertion.
"""
from types import SimpleNamespace

import numpy as np
import pytest

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.problem import ContactProblem, Load, MeanGap
from petgap.parallel.grid import Grid
from petgap.solvers import sweeps as sweep_module
from petgap.solvers.sweeps import SweepStep, sweep
from petgap.surfaces.self_affine import self_affine

OPTIONS = dict(tolerance=1e-8, max_iterations=2000)


@pytest.fixture
def problem(comm):
    grid = Grid((32, 32), comm=comm, planner="estimate", wisdom=False)
    h = self_affine(grid, 0.8, 8.0, 16.0, rms_slope=0.1, seed=2)
    return ContactProblem(grid, h, ElasticHalfSpace(grid, 1.0))


@pytest.fixture
def calls(monkeypatch):
    """Every solve of the sweep: (control, the warm start it got)."""
    seen = []
    real = sweep_module.solve

    def recording(problem, control, initial=None, **kwargs):
        seen.append((control, initial))
        return real(problem, control, initial=initial, **kwargs)
    monkeypatch.setattr(sweep_module, "solve", recording)
    return seen


def test_simple_form_chains_controls(problem, calls):
    loads = [Load(0.002), Load(0.004), Load(0.003)]
    states = list(sweep(problem, loads, **OPTIONS))
    assert [s.control for s in states] == loads
    assert [initial for _, initial in calls] == [None, states[0], states[1]]
    assert [s.direction for s in states] == ["start", "loading", "unloading"]
    assert all(s.converged and s.jump is False for s in states)


def test_chains_warm_start_and_annotate_apart(problem, calls):
    steps = [SweepStep(Load(0.002), chain="a"), SweepStep(Load(0.004), chain="b"),
             SweepStep(Load(0.003), chain="a"), SweepStep(Load(0.002), chain="b")]
    states = list(sweep(problem, steps, **OPTIONS))
    assert [initial for _, initial in calls] == [None, None, states[0], states[1]]
    assert [s.direction for s in states] == ["start", "start", "loading", "unloading"]


def test_control_from_earlier_states(problem):
    steps = [Load(0.003), SweepStep(lambda states: MeanGap(states[0].mean_gap), chain="gap")]
    first, second = sweep(problem, steps, **OPTIONS)
    assert second.control == MeanGap(first.mean_gap)
    assert second.converged
    assert second.mean_pressure == pytest.approx(0.003, rel=1e-5)
    assert second.direction == "start"


def test_a_sweep_holds_no_fields_of_the_steps_behind_it(problem):
    """A step's state lives on in the sweep only as its chain's warm start: once the
    caller lets go of it and the chain has moved on, or has no steps to come, its gap and
    pressure are freed (a protocol of many steps at 16384^2 cannot keep 16 bytes per point
    per step, nor a finished chain's fields through the next chain's solves), while a
    later step's control still reads its scalars."""
    import gc  # deferred: this test only
    import weakref
    steps = [Load(0.002), Load(0.004), Load(0.003),
             SweepStep(lambda states: MeanGap(states[0].mean_gap), chain="gap")]
    alive, refs, scalars = [], [], []
    for state in sweep(problem, steps, **OPTIONS):
        gc.collect()
        alive.append([ref() is not None for ref in refs])
        refs.append(weakref.ref(state))
        scalars.append((state.mean_gap, state.control))
        del state
    # each step's state is held only while it is its chain's warm start: the first chain
    # ends at step 2, so the "gap" chain's solve holds none of its fields
    assert alive == [[], [True], [False, True], [False, False, False]]
    assert scalars[3][1] == MeanGap(scalars[0][0])


def test_per_step_problem_and_before_hook(problem, comm):
    other = ContactProblem(problem.grid, 2.0 * problem.topography, problem.half_space)
    announced, monitored = [], []

    def before(index, control):
        announced.append((index, control))
        return {"monitor": lambda it, res: monitored.append(index)}
    steps = [Load(0.002), SweepStep(Load(0.002), problem=other)]
    a, b = sweep(problem, steps, before=before, **OPTIONS)
    assert announced == [(0, Load(0.002)), (1, Load(0.002))]
    assert set(monitored) == {0, 1}
    assert b.contact_fraction < a.contact_fraction  # twice as rough: less contact


def test_states_found_are_not_solved_again_but_annotated_and_chained(problem, calls):
    loads = [Load(0.002), Load(0.003), Load(0.004)]
    whole = list(sweep(problem, loads, **OPTIONS))
    del calls[:]
    found = [SimpleNamespace(control=s.control, gap=s.gap.copy(), pressure=s.pressure.copy(),
                             mean_gap=s.mean_gap, zero_gap_fraction=s.zero_gap_fraction)
             for s in whole[:2]]
    resumed = list(sweep(problem, [SweepStep(loads[0], state=found[0]),
                                   SweepStep(loads[1], state=found[1]), loads[2]], **OPTIONS))
    # without fields (a file that stores none) the next step starts cold
    bare = SimpleNamespace(control=loads[1], gap=None, mean_gap=whole[1].mean_gap,
                           zero_gap_fraction=None)
    cold = list(sweep(problem, [SweepStep(loads[1], state=bare), loads[2]], **OPTIONS))

    assert resumed[:2] == found
    assert [(c, i) for c, i in calls[:1]] == [(loads[2], found[1])]
    assert [d.direction for d in resumed] == ["start", "loading", "loading"]
    assert resumed[2].mean_gap == pytest.approx(whole[2].mean_gap, rel=1e-12)
    assert np.allclose(resumed[2].gap, whole[2].gap, rtol=0, atol=1e-12 * whole[2].mean_gap)
    assert calls[1] == (loads[2], None)
    assert cold[0].direction == "start" and cold[1].direction == "loading"
    assert cold[1].jump is False  # no zero-gap area to compare with


def test_indentation_sweep_deeper_is_loading(comm):
    """Deeper indentation pushes the surfaces together: loading; shallower: unloading."""
    from petgap.mechanics.free_half_space import FreeHalfSpace
    from petgap.mechanics.problem import Indentation
    from petgap.surfaces.indenters import indenter
    grid = Grid((64, 64), comm=comm, planner="estimate", wisdom=False)
    problem = ContactProblem(grid, indenter(grid, "paraboloid", 200.0), FreeHalfSpace(grid, 1.0))
    states = list(sweep(problem, [Indentation(1.0), Indentation(2.0), Indentation(1.5)],
                        **OPTIONS))
    assert [s.direction for s in states] == ["start", "loading", "unloading"]
    assert all(s.converged for s in states)
