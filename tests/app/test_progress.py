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
