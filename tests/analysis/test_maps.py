"""Block-averaged maps of distributed fields."""
import numpy as np
import pytest

from petgap.analysis import block_map, decimation_factor
from petgap.parallel.grid import Grid


def reference_blocks(field, f):
    nx, ny = field.shape
    out = np.empty((-(-nx // f), -(-ny // f)))
    for a in range(out.shape[0]):
        for b in range(out.shape[1]):
            out[a, b] = field[a * f:(a + 1) * f, b * f:(b + 1) * f].mean()
    return out


@pytest.mark.parametrize("shape, max_pixels, factor", [((37, 23), 10, 4), ((32, 32), 32, 1),
                                                       ((40, 64), 16, 4), ((5, 3), 1, 5)])
def test_block_means_match_a_serial_reference(comm, shape, max_pixels, factor):
    field = np.random.default_rng(3).standard_normal(shape)
    grid = Grid(shape, size=(shape[0] * 0.5, shape[1] * 2.0), comm=comm, planner="estimate",
                wisdom=False)
    assert decimation_factor(shape, max_pixels) == factor
    m = block_map(grid, field[grid.x_slice], max_pixels=max_pixels)
    assert m.factor == factor
    assert m.extent == (0.0, shape[0] * 0.5, 0.0, shape[1] * 2.0)
    if comm.rank == 0:
        np.testing.assert_allclose(m.values, reference_blocks(field, factor), rtol=1e-12,
                                   atol=1e-14)
        assert m.counts.sum() == field.size
        assert m.weighted_mean() == pytest.approx(field.mean(), rel=1e-12, abs=1e-14)
    else:
        assert m.values is None


def test_contact_map_holds_the_contact_fraction(comm):
    mask = np.random.default_rng(5).random((50, 30)) < 0.17
    grid = Grid(mask.shape, comm=comm, planner="estimate", wisdom=False)
    m = block_map(grid, mask[grid.x_slice], max_pixels=7)
    if comm.rank == 0:
        assert m.weighted_mean() == pytest.approx(mask.mean(), rel=1e-13)
        assert np.all((m.values >= 0) & (m.values <= 1))


def test_bad_max_pixels_is_refused():
    with pytest.raises(ValueError, match="max_pixels"):
        decimation_factor((8, 8), 0)
