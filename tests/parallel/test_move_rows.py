"""move_rows: rows held by one decomposition, delivered to the ranks of another."""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.parallel.collective import move_rows


def _slab(n, size, rank):
    """Rows ``lo <= row < hi`` of an uneven split of ``n`` rows over ``size`` ranks."""
    cuts = [round(n * k ** 1.3 / size ** 1.3) for k in range(size + 1)]
    return cuts[rank], cuts[rank + 1]


def _assemble(pieces, lo, hi, width):
    out = np.zeros((hi - lo, width))
    for row, piece in pieces:
        assert lo <= row and row + len(piece) <= hi
        out[row - lo:row - lo + len(piece)] += piece
    return out


@pytest.mark.parametrize("wanted_shift", [0, 3])
def test_each_rank_gets_exactly_the_rows_it_asks_for(comm, wanted_shift):
    n, width = 23, 5
    field = np.arange(n * width, dtype=float).reshape(n, width) ** 1.5
    first, stop = _slab(n, comm.size, comm.rank)
    # wanted: another split, shifted and clipped to the field (possibly empty)
    lo, hi = _slab(n, comm.size, comm.size - 1 - comm.rank)
    lo, hi = min(lo + wanted_shift, n), min(hi + wanted_shift, n)
    pieces = move_rows(comm, field[first:stop], first, lo, hi)
    np.testing.assert_array_equal(_assemble(pieces, lo, hi, width), field[lo:hi])


def test_one_rank_hands_back_views_without_a_message():
    field = np.random.default_rng(1).random((10, 4)).astype(np.float32)
    pieces = move_rows(MPI.COMM_SELF, field[2:9], 2, 4, 12)
    assert len(pieces) == 1
    row, piece = pieces[0]
    assert row == 4 and np.shares_memory(piece, field)
    np.testing.assert_array_equal(piece, field[4:9])
    assert move_rows(MPI.COMM_SELF, field[2:9], 2, 9, 12) == []
