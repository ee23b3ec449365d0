"""Statistics by finite differences inside a map, against closed forms and the spectral ones."""
import numpy as np
import pytest

from petgap.parallel.grid import Grid
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.statistics import (finite_difference_curvature, finite_difference_slopes,
                                        statistics)


def test_curvature_of_a_paraboloid_is_exact(comm):
    """lap(a x^2 + b y^2 + c x y + d x) = 2a + 2b everywhere: h0'' = |a + b|, non-square
    pixels and unequal slabs included."""
    grid = Grid((23, 17), size=(23 * 0.5, 17 * 2.0), comm=comm, planner="estimate",
                wisdom=False)
    x, y = grid.local_positions()
    h = 0.3 * x ** 2 - 0.05 * y ** 2 + 0.02 * x * y + 1.5 * x
    assert finite_difference_curvature(grid, h) == pytest.approx(abs(0.3 - 0.05), rel=1e-9)


def test_finite_differences_agree_with_the_spectrum_on_a_smooth_periodic_surface(comm):
    grid = Grid((128, 96), comm=comm, planner="estimate", wisdom=False)
    h = self_affine(grid, 0.8, 32.0, rms_slope=0.1, seed=4)
    spectral = statistics(grid, h)
    periodic, inner = finite_difference_slopes(grid, h)
    # second differences of wavelengths >= 32 pixels lose at most ~1 % (sinc^2)
    assert finite_difference_curvature(grid, h) == pytest.approx(spectral.rms_curvature,
                                                                 rel=0.05)
    assert periodic == pytest.approx(spectral.rms_slope, rel=0.01)
    assert inner == pytest.approx(periodic, rel=0.02)


def test_too_narrow_a_map_has_no_curvature(comm):
    if comm.size > 2:
        pytest.skip("a 2-column grid has 2 Fourier rows: at most 2 ranks")
    grid = Grid((8, 2), comm=comm, planner="estimate", wisdom=False)
    assert np.isnan(finite_difference_curvature(grid, np.zeros(grid.local_shape)))
