"""The time-to-go estimate of a solve from its residual's decay, and the best residual the
solvers' stall rules count from."""
import math

import pytest

from petgap.solvers.convergence import BestResidual, ResidualTrend


def test_geometric_decay_is_extrapolated_exactly():
    trend = ResidualTrend(tolerance=1e-8)
    rate = 0.7                                   # residual x 0.5 every 1/0.7 s
    for k in range(10):
        t = 0.5 * k
        trend.add(t, 1e-2 * math.exp(-rate * t))
    # 1e-2 exp(-0.7 t) = 1e-8 at t = ln(1e6) / 0.7; the last point is at 4.5 s
    assert trend.remaining() == pytest.approx(math.log(1e6) / rate - 4.5, rel=1e-9)


def test_no_estimate_without_decay_or_data():
    trend = ResidualTrend(tolerance=1e-8)
    for k in range(3):
        trend.add(k, 1e-3)
    assert trend.remaining() is None             # too few points
    trend.add(3, 2e-3)
    assert trend.remaining() is None             # not falling
    trend.add(4, 0.0)                            # converged: ignored
    assert trend.remaining() is None


def test_only_the_recent_window_counts():
    trend = ResidualTrend(tolerance=1e-9, window=5)
    for k in range(20):     # a decade per 10 s up to 14 s, then a decade per second
        trend.add(k, 10.0 ** (-0.1 * k) if k < 15 else 10.0 ** (-2.5 - (k - 15)))
    # the window holds k = 15..19 only: log10 r = -2.5 - (t - 15) reaches -9 at t = 21.5
    assert trend.remaining() == pytest.approx(2.5, rel=1e-9)
    assert trend.times == [15.0, 16.0, 17.0, 18.0, 19.0]


def test_the_best_residual_counts_only_a_tenth_off():
    """The stall rules' count: a residual is the new best only below ``factor`` times the
    best, so that one wandering at its floor does not renew it."""
    best = BestResidual(0.9)
    assert best.since(0, 1.0) == 0 and best.value == 1.0
    assert best.since(1, 0.95) == 1 and best.value == 1.0     # not a tenth off
    assert best.since(2, 0.5) == 0 and best.at == 2
    assert [best.since(i, 0.46) for i in (3, 4, 5)] == [1, 2, 3]
