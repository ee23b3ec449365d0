"""The pruned padded convolution (``PaddedConvolutionPlans``) against NumPy's full transform of
the padded cell, on awkward shapes, cells, precisions and rank counts."""
import numpy as np
import pytest

from petgap.parallel.grid import Grid

SHAPES_AND_CELLS = [((12, 10), None), ((9, 7), None), ((7, 12), (11, 15)), ((16, 5), (21, 5)),
                    ((6, 9), (6, 9)), ((12, 4), None)]
TOLERANCE = {"double": 1e-13, "single": 3e-6}


def _symbol(cell, seed=3):
    """A random real symbol on the cell's r2c half plane, even in ``kx``: ``(cx, cy // 2 + 1)``."""
    cx, cy = cell
    half = np.random.default_rng(seed).random((cx // 2 + 1, cy // 2 + 1)) + 0.5
    kx = np.arange(cx)
    return half[np.minimum(kx, cx - kx)]


def _reference(p, symbol, cell):
    """``k * p`` on the map by NumPy: the whole padded cell, transformed and cut."""
    nx, ny = p.shape
    padded = np.zeros(cell)
    padded[:nx, :ny] = p
    return np.fft.irfft2(np.fft.rfft2(padded) * symbol, s=cell)[:nx, :ny]


def _plans(grid, cell, symbol, square=None):
    cx, cy = (2 * grid.nx, 2 * grid.ny) if cell is None else cell
    plans = grid.zero_padded_plans(cell, planner="estimate", square=square)
    plans.set_kernel(np.ascontiguousarray(symbol[:cx // 2 + 1, plans.kernel_ky].T) / (cx * cy))
    return plans


@pytest.mark.parametrize("square", [None, False, True])
@pytest.mark.parametrize("precision", ["double", "single"])
@pytest.mark.parametrize("shape, cell", SHAPES_AND_CELLS)
def test_pruned_equals_the_full_padded_transform(comm, shape, cell, precision, square):
    """Whole, sparse, gathered and split (begin / end) applications equal the full cell's
    transform to round-off, and the form of a begin is ``(p, k * p)``, on any rank count;
    square transposes (one rank) move padding that no stage reads (NaN before the first
    use)."""
    if square and comm.size > 1:
        pytest.skip("square transposes are for one rank")
    grid = Grid(shape, comm=comm, planner="estimate", wisdom=False, precision=precision)
    full_cell = (2 * shape[0], 2 * shape[1]) if cell is None else cell
    symbol = _symbol(full_cell)
    plans = _plans(grid, cell, symbol, square)
    if square is not None:
        assert plans.square == square
    plans.rows[...] = np.nan
    p = np.random.default_rng(1).standard_normal(shape)   # the same on every rank
    p[np.random.default_rng(2).random(shape) < 0.4] = 0.0
    expected = _reference(p, symbol, full_cell)[grid.x_slice]
    tol = TOLERANCE[precision] * np.abs(expected).max()
    local = p[grid.x_slice].astype(grid.dtype)

    out = np.full(grid.local_shape, np.nan, dtype=grid.dtype)
    plans.apply(local, out)
    np.testing.assert_allclose(out, expected, rtol=0, atol=tol)

    # on the points of a padded slab, as the solvers give them
    padded = np.zeros(grid.padded.shape, dtype=grid.dtype)
    padded[:, :shape[1]] = local
    pidx = np.flatnonzero(padded).astype(np.int32)
    values = padded.ravel()[pidx]
    target = np.full(grid.padded.shape, 7.0, dtype=grid.dtype)
    plans.apply_sparse(pidx, values, out=target)
    np.testing.assert_allclose(target[:, :shape[1]], expected, rtol=0, atol=tol)
    assert np.all(target[:, shape[1]:] == 7.0)   # the padding columns left as they were
    gathered = np.empty(len(pidx), dtype=grid.dtype)
    plans.apply_sparse(pidx, values, gathered=gathered)
    np.testing.assert_allclose(gathered, expected.ravel()[np.flatnonzero(local)], rtol=0, atol=tol)

    form = grid.comm.allreduce(plans.begin_sparse(pidx, values))
    global_form = float(np.vdot(p, _reference(p, symbol, full_cell)))
    assert form == pytest.approx(global_form, rel=TOLERANCE[precision] * 10)
    target[...] = 0.0
    plans.end(target)
    np.testing.assert_allclose(target[:, :shape[1]], expected, rtol=0, atol=tol)
    with pytest.raises(RuntimeError, match="no half-made"):
        plans.end(target)


def test_bad_indices_raise_on_their_rank_without_a_hang(comm):
    """Unsorted indices, or one off the map's columns: a ValueError after the collective
    stages ran on every rank."""
    grid = Grid((8, 6), comm=comm, planner="estimate", wisdom=False)
    plans = _plans(grid, None, _symbol((16, 12)))
    width = grid.padded.shape[1]
    bad = np.array([width + 1, 1] if comm.rank == 0 else [0], dtype=np.int32)
    off_map = np.array([grid.ny] if comm.rank == 0 else [0], dtype=np.int32)
    for pidx in (bad, off_map):
        values = np.ones(len(pidx))
        failed = False
        try:
            plans.apply_sparse(pidx, values, gathered=np.empty(len(pidx)))
        except ValueError as exc:
            failed = "sorted ascending" in str(exc)
        assert comm.allgather(failed) == [True] + [False] * (comm.size - 1)


def test_cell_smaller_than_the_map_is_refused(comm):
    grid = Grid((8, 6), comm=comm, planner="estimate", wisdom=False)
    with pytest.raises(ValueError, match="does not hold a 8 x 6 map"):
        grid.zero_padded_plans((7, 12))


def test_square_transposes_refused_on_more_ranks(comm):
    """``square=True`` on more than one rank: a ValueError naming it, on every rank; the
    default rule takes square transposes where they fit, on one rank only."""
    grid = Grid((12, 10), comm=comm, planner="estimate", wisdom=False)
    if comm.size > 1:
        with pytest.raises(ValueError, match=f"square=True needs one rank, not {comm.size}"):
            grid.zero_padded_plans(planner="estimate", square=True)
    plans = grid.zero_padded_plans(planner="estimate")
    assert plans.square == (comm.size == 1)
    assert (plans.row_stride, plans.line_stride) == ((12, 12) if comm.size == 1 else (10, 12))
    # a 16 x 5 map's lines are 5: the square would be more than SQUARE_GROWTH its buffer
    assert not Grid((16, 5), comm=comm, planner="estimate", wisdom=False).zero_padded_plans(
        planner="estimate").square
