"""The parallel layer: one grid owns the communicator, the slab decomposition and the FFT.

Everything above this package asks a :class:`Grid` for its local slices,
wavevectors, transforms and global reductions, and is handed the communicator
through it, never from a module global.

Modules
-------
:mod:`.grid`
    :class:`Grid`: the periodic ``nx x ny`` grid, its FFTW-MPI row slabs, the
    transposed half-plane Fourier layout, FFT buffers and reductions (the
    conventions every other module cites).
:mod:`._fftw_mpi`
    The compiled binding to FFTW-MPI: plans, the fused convolution with
    ``|q|^(+-1)`` and spectral sums.
:mod:`.collective`
    :func:`root_decides`: rank 0 decides, every rank returns or raises alike;
    :func:`global_sums`: any number of sums in one reduction.
:mod:`.dottest`
    :func:`dottest`: ``<A x, y> = <x, A^T y>`` for a distributed operator.
:mod:`.memory`
    :func:`return_freed_memory`: freed fields go back to the system (PETSc's
    SuperLU_DIST turns that off as it loads).
:mod:`.log`
    Rank-aware progress messages, the handling of failures on some ranks, and
    the PETSc log events of petgap's operator and kernels.
"""
from petgap.parallel.collective import global_sums, root_decides
from petgap.parallel.dottest import dottest
from petgap.parallel.grid import DecompositionError, Grid

__all__ = ["Grid", "DecompositionError", "root_decides", "global_sums", "dottest"]
