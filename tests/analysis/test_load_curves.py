"""Fits of a load sweep: kappa_rep and the exponential mean-gap law."""
import math

import numpy as np
import pytest

from petgap.analysis import fit_gap_law, fit_kappa_rep


def test_kappa_is_recovered_below_c_max_only():
    x = np.array([0.005, 0.01, 0.02, 0.04, 0.2])
    c = 2.1 * x
    c[-1] = 0.3                      # saturating: above c_max, must not count
    fit = fit_kappa_rep(x, c)
    assert fit.kappa == pytest.approx(2.1, rel=1e-12)
    assert fit.npoints == 4


def test_kappa_without_points():
    fit = fit_kappa_rep([0.1], [0.5])
    assert math.isnan(fit.kappa) and fit.npoints == 0


def test_gap_law_recovers_gamma_and_prefactor():
    h0, gamma, p_star = 2.5, 0.43, 0.07
    g = np.linspace(1.0, 4.0, 6)
    p = p_star * np.exp(-g / (gamma * h0))
    fit = fit_gap_law(g, p, h0)
    assert fit.gamma == pytest.approx(gamma, rel=1e-10)
    assert fit.prefactor == pytest.approx(p_star, rel=1e-10)
    assert fit.npoints == 6
    np.testing.assert_allclose(fit.load(g), p, rtol=1e-10)


def test_gap_law_needs_a_falling_load():
    assert math.isnan(fit_gap_law([1.0, 2.0], [0.1, 0.2], 1.0).gamma)
    assert math.isnan(fit_gap_law([1.0], [0.1], 1.0).gamma)
    with pytest.raises(ValueError, match="rms_height"):
        fit_gap_law([1.0, 2.0], [0.2, 0.1], 0.0)
