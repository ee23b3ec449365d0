"""The progress lines of a long run: step i of n, iteration, residual, time to go."""
import math

from petgap.app.run import _duration, _progress


class Capture:
    def __init__(self):
        self.lines = []

    def info(self, fmt, *args):
        self.lines.append(fmt % args)


def test_progress_line_names_step_iteration_residual_and_eta(monkeypatch):
    clock = [100.0]
    monkeypatch.setattr("petgap.app.run.time.perf_counter", lambda: clock[0])
    log = Capture()
    monitor = _progress(log, index=2, nsteps=8, tolerance=1e-8, every=5.0)
    for k in range(12):
        clock[0] = 100.0 + k
        monitor(k, 1e-2 * math.exp(-math.log(10) * k / 2))   # a decade every 2 s
    # lines at 5 s and 10 s only (at most every 5 s)
    assert len(log.lines) == 2
    last = log.lines[-1]
    assert last.startswith("  step 3 of 8: iteration 10, KKT residual 1.000e-07 (target 1e-08)")
    assert "10.0 s" in last and "about 2 s to go" in last    # one decade left, 2 s


def test_durations_read_at_a_glance():
    assert _duration(42) == "42 s"
    assert _duration(210) == "3.5 min"
    assert _duration(4 * 3600) == "4.0 h"


def test_iterations_count_on_through_the_levels_and_the_sweep_has_its_eta(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr("petgap.app.run.time.perf_counter", lambda: clock[0])
    log = Capture()
    # step 2 of 4; the steps before took 30 s each
    monitor = _progress(log, index=1, nsteps=4, tolerance=1e-8, every=5.0, finished=[30.0, 30.0])
    levels = [(range(10), 1e-1), (range(25), 1e-2)]        # a coarse level, then the fine grid
    shown = []
    for its, first in levels:
        for k in its:
            clock[0] += 1.0
            monitor(k, first * math.exp(-math.log(10) * k / 5))   # a decade every 5 s
            shown.append(k)
    numbers = [int(line.split("iteration ")[1].split(",")[0]) for line in log.lines]
    assert numbers == sorted(numbers) and numbers[-1] == 34       # 10 + 24, never restarted
    last = log.lines[-1]
    # fine level: 1e-2 -> 1e-8 is six decades, 30 s; at iteration 24 (24 s) about 6 s remain;
    # the two steps after it take 30 s each: about 66 s in the sweep
    assert "about 6 s to go in this step, 66 s in the sweep (2 more steps)" in last
    assert "about 0 s" not in "".join(log.lines)


def test_a_step_ending_now_says_so():
    assert _duration(0.2) == "under 1 s"


def test_a_stalled_step_is_logged_with_the_residual_it_reached():
    """A step whose gap solve stalled near its tolerance is logged as not converged, with
    the residual it reached, the stall window and what to do."""
    from types import SimpleNamespace
    from petgap.app import run
    from petgap.solvers import gap_cg

    class Log:
        def __init__(self):
            self.warnings = []

        def info(self, *args):
            pass

        def warning(self, text, *args):
            self.warnings.append(text % args)

    solution = SimpleNamespace(converged=False, reason="stalled", iterations=80,
                               operator_applications=200.0, wall_time=1.0,
                               contact_fraction=0.1, mean_gap=1.0, mean_pressure=0.0,
                               kkt_pressure=1.4e-8, kkt_gap=0.0, jump=False, start="")
    log = Log()
    run._log_solution(log, SimpleNamespace(index=3), solution)
    assert any("step 3 did not converge: stalled" in w for w in log.warnings)
    assert any("stopped falling at 1.40e-08" in w
               and f"{gap_cg.STALL_ITERATIONS} iterations" in w
               and "tolerance above it" in w for w in log.warnings)
