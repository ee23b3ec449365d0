"""global_sums: one reduction of doubles (or exact integers) for a solver step's sums."""
import numpy as np

from petgap.parallel.collective import global_sums


def test_numbers_and_arrays_are_summed_over_the_ranks(comm):
    r, size = comm.rank, comm.size
    a, b = global_sums(comm, 1.0, r)
    assert (a, b) == (float(size), float(size * (size - 1) // 2))
    local = np.array([[1.0, r], [2.0, 0.5]])
    total = global_sums(comm, local)
    assert total.shape == (2, 2) and total.dtype == np.float64
    np.testing.assert_array_equal(total, [[size, size * (size - 1) / 2], [2 * size, 0.5 * size]])
    assert local[0, 0] == 1.0  # the caller's values are left alone
    counts = global_sums(comm, [2 ** 60, 1], dtype=np.int64)
    assert counts.dtype == np.int64 and counts[0] == size * 2 ** 60  # exact beyond 2^53
