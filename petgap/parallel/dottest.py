"""The dot-product test of a distributed linear operator on a grid's slabs.

For an operator ``A`` and its adjoint ``A^T`` (``A`` itself when symmetric),
``<A x, y> = <x, A^T y>`` holds for every ``x`` and ``y`` up to round-off; a
wrong transpose, a missed Hermitian weight or a rank that sums its halo twice
breaks it at once.  Random slabs drawn per rank make the test exercise the
decomposition as well (as pylops-mpi's ``dottest`` does for its operators).
"""
import numpy as np

from petgap.parallel.collective import global_sums


def dottest(grid, forward, adjoint=None, *, seed=0, rtol=1e-12):
    """Check ``<A x, y> = <x, A^T y>`` on random slabs of ``grid`` (collective).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    forward : callable
        ``forward(x) -> A x``, slab in, slab out (a new array).
    adjoint : callable, optional
        ``adjoint(y) -> A^T y``; default ``forward`` (a symmetric operator).
    seed : int
        Seed of the random slabs (each rank draws its own from ``seed + rank``).
    rtol : float
        Allowed ``|<A x, y> - <x, A^T y>|`` relative to ``||A x|| ||y||``.

    Returns
    -------
    (float, float)
        ``<A x, y>`` and ``<x, A^T y>``, the same on every rank.

    Raises
    ------
    AssertionError
        On every rank alike, when the two differ by more than ``rtol``.
    """
    adjoint = forward if adjoint is None else adjoint
    rng = np.random.default_rng(seed + grid.comm.rank)
    x, y = rng.standard_normal((2,) + grid.local_shape)
    ax, aty = forward(x), adjoint(y)
    lhs, rhs, ax_sq, y_sq = global_sums(grid.comm, np.vdot(ax, y), np.vdot(x, aty),
                                        np.vdot(ax, ax), np.vdot(y, y))
    scale = np.sqrt(ax_sq * y_sq)
    if not abs(lhs - rhs) <= rtol * scale:
        raise AssertionError(f"dot test failed: <A x, y> = {lhs!r}, <x, A^T y> = {rhs!r}, "
                             f"difference {abs(lhs - rhs) / scale:.3e} of ||A x|| ||y|| "
                             f"(allowed {rtol:g})")
    return float(lhs), float(rhs)
