# cython: language_level=3
"""Thin binding to FFTW 3.3's MPI interface for 2D real-data transforms.

Only what petgap needs is wrapped: the transposed slab distribution of a 2D
real-to-complex transform, one forward (r2c, ``FFTW_MPI_TRANSPOSED_OUT``) and one
backward (c2r, ``FFTW_MPI_TRANSPOSED_IN``) plan on buffers owned by the caller,
wisdom broadcast/gather, and a few fused loops over the Fourier slab that would
otherwise cost several NumPy passes per solver iteration.

Layout (FFTW manual, sections 6.4.3 and 6.5): the real array is ``n0 x n1``,
distributed over its first axis in blocks, and padded in its last axis to
``2 (n1 // 2 + 1)`` doubles even for out-of-place transforms.  The transposed
Fourier array is ``(n1 // 2 + 1) x n0`` complex values, distributed over its
first axis.  Transforms are unnormalised: forward then backward multiplies by
``n0 * n1``.
"""
from libc.math cimport sqrt
from mpi4py.libmpi cimport MPI_Comm
from mpi4py cimport MPI
cimport numpy as cnp
import numpy as np

cnp.import_array()

cdef extern from "fftw3-mpi.h" nogil:
    ctypedef double fftw_complex[2]
    ctypedef struct fftw_plan_s:
        pass
    ctypedef fftw_plan_s *fftw_plan
    unsigned FFTW_ESTIMATE, FFTW_MEASURE, FFTW_PATIENT, FFTW_EXHAUSTIVE
    unsigned FFTW_WISDOM_ONLY, FFTW_DESTROY_INPUT
    unsigned FFTW_MPI_TRANSPOSED_IN, FFTW_MPI_TRANSPOSED_OUT
    void fftw_mpi_init()
    ptrdiff_t fftw_mpi_local_size_2d_transposed(
        ptrdiff_t n0, ptrdiff_t n1, MPI_Comm comm,
        ptrdiff_t *local_n0, ptrdiff_t *local_0_start,
        ptrdiff_t *local_n1, ptrdiff_t *local_1_start)
    fftw_plan fftw_mpi_plan_dft_r2c_2d(ptrdiff_t n0, ptrdiff_t n1, double *inp,
                                       fftw_complex *out, MPI_Comm comm, unsigned flags)
    fftw_plan fftw_mpi_plan_dft_c2r_2d(ptrdiff_t n0, ptrdiff_t n1, fftw_complex *inp,
                                       double *out, MPI_Comm comm, unsigned flags)
    void fftw_execute(const fftw_plan p)
    void fftw_destroy_plan(fftw_plan p)
    void fftw_mpi_broadcast_wisdom(MPI_Comm comm)
    void fftw_mpi_gather_wisdom(MPI_Comm comm)
    char *fftw_export_wisdom_to_string()
    int fftw_import_wisdom_from_string(const char *s)
    void fftw_free(void *p)

fftw_mpi_init()

PLANNER_FLAGS = {"estimate": FFTW_ESTIMATE, "measure": FFTW_MEASURE,
                 "patient": FFTW_PATIENT, "exhaustive": FFTW_EXHAUSTIVE}


def local_size_transposed(MPI.Comm comm, Py_ssize_t n0, Py_ssize_t n1):
    """Slab sizes of an ``n0 x n1`` r2c transform with transposed output.

    Returns
    -------
    tuple of int
        ``(alloc_local, local_n0, local_0_start, local_n1, local_1_start)``;
        ``alloc_local`` counts complex numbers and bounds both the padded real
        slab and the transposed Fourier slab of this rank.
    """
    cdef ptrdiff_t ln0 = 0, l0s = 0, ln1 = 0, l1s = 0, alloc
    alloc = fftw_mpi_local_size_2d_transposed(n0, n1 // 2 + 1, comm.ob_mpi,
                                              &ln0, &l0s, &ln1, &l1s)
    return int(alloc), int(ln0), int(l0s), int(ln1), int(l1s)


def export_wisdom(MPI.Comm comm):
    """Gather the wisdom of all ranks onto rank 0 and return it as text there."""
    fftw_mpi_gather_wisdom(comm.ob_mpi)
    if comm.Get_rank() != 0:
        return None
    cdef char *s = fftw_export_wisdom_to_string()
    if s == NULL:
        return None
    try:
        return (<bytes>s).decode("ascii")
    finally:
        fftw_free(s)


def import_wisdom(MPI.Comm comm, text):
    """Import wisdom text given on rank 0 and broadcast it to every rank.

    Returns True on every rank if rank 0 parsed the text.
    """
    cdef int ok = 0
    if comm.Get_rank() == 0 and text:
        data = text.encode("ascii")
        ok = fftw_import_wisdom_from_string(data)
    ok = comm.bcast(ok, root=0)
    if ok:
        fftw_mpi_broadcast_wisdom(comm.ob_mpi)
    return bool(ok)


cdef class SlabPlans:
    """Forward r2c and backward c2r FFTW-MPI plans on two caller-owned buffers.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator of the slab decomposition (kept alive by this object).
    n0, n1 : int
        Logical real-space shape; ``n0`` is the distributed axis.
    real : ndarray of float64, C-contiguous, at least ``2 * alloc_local`` values
        Padded real slab; plans read and write it in place of any copy.
    fourier : ndarray of complex128, C-contiguous, at least ``alloc_local`` values
        Transposed Fourier slab.
    planner : {"estimate", "measure", "patient", "exhaustive"}
        FFTW planner effort.  Measuring overwrites both buffers.
    """
    cdef fftw_plan fwd
    cdef fftw_plan bwd
    cdef object comm, real, fourier

    def __cinit__(self):
        self.fwd = NULL
        self.bwd = NULL

    def __init__(self, MPI.Comm comm, Py_ssize_t n0, Py_ssize_t n1,
                 cnp.ndarray real, cnp.ndarray fourier, str planner="measure"):
        if planner not in PLANNER_FLAGS:
            raise ValueError(f"planner={planner!r} is not one of {sorted(PLANNER_FLAGS)}")
        if real.dtype != np.float64 or not real.flags.c_contiguous:
            raise TypeError("real buffer must be C-contiguous float64")
        if fourier.dtype != np.complex128 or not fourier.flags.c_contiguous:
            raise TypeError("fourier buffer must be C-contiguous complex128")
        self.comm, self.real, self.fourier = comm, real, fourier
        cdef unsigned flags = PLANNER_FLAGS[planner]
        cdef double *r = <double *>cnp.PyArray_DATA(real)
        cdef fftw_complex *c = <fftw_complex *>cnp.PyArray_DATA(fourier)
        cdef MPI_Comm mcomm = comm.ob_mpi
        with nogil:
            self.fwd = fftw_mpi_plan_dft_r2c_2d(n0, n1, r, c, mcomm,
                                                flags | FFTW_MPI_TRANSPOSED_OUT)
            self.bwd = fftw_mpi_plan_dft_c2r_2d(n0, n1, c, r, mcomm,
                                                flags | FFTW_MPI_TRANSPOSED_IN)
        if self.fwd == NULL or self.bwd == NULL:
            raise RuntimeError(f"FFTW-MPI could not plan a {n0} x {n1} transform")

    def forward(self):
        """Real slab -> Fourier slab (unnormalised, ``exp(-i q.x)``)."""
        with nogil:
            fftw_execute(self.fwd)

    def backward(self):
        """Fourier slab -> real slab (unnormalised, ``exp(+i q.x)``); destroys the Fourier slab."""
        with nogil:
            fftw_execute(self.bwd)

    def __dealloc__(self):
        if self.fwd != NULL:
            fftw_destroy_plan(self.fwd)
        if self.bwd != NULL:
            fftw_destroy_plan(self.bwd)


def multiply_by_qpower(double complex[:, ::1] c, const double[::1] qx,
                       const double[::1] qy, double scale, int power):
    """``c[j, i] *= scale * |q|**power`` in place, with ``|q| = hypot(qx[i], qy[j])``.

    ``power`` is +1 (stiffness) or -1 (compliance).  Where ``|q| = 0`` the
    result is set to zero: the q = 0 mode is never touched by an elastic
    operator (it is the rigid-body mode, fixed by the control).  The inner loop
    is branch-free so that the compiler vectorises the square roots.
    """
    cdef Py_ssize_t i, j, nj = c.shape[0], ni = c.shape[1]
    cdef double qyj, f
    cdef double *row
    if qx.shape[0] != ni or qy.shape[0] != nj:
        raise ValueError("wavevector arrays do not match the Fourier slab")
    if power != 1 and power != -1:
        raise ValueError("power must be +1 or -1")
    with nogil:
        for j in range(nj):
            qyj = qy[j] * qy[j]
            row = <double *>&c[j, 0]
            if power == 1:
                for i in range(ni):
                    f = scale * sqrt(qx[i] * qx[i] + qyj)
                    row[2 * i] = row[2 * i] * f
                    row[2 * i + 1] = row[2 * i + 1] * f
            else:
                for i in range(ni):
                    f = scale / sqrt(qx[i] * qx[i] + qyj)
                    row[2 * i] = row[2 * i] * f
                    row[2 * i + 1] = row[2 * i + 1] * f
            if qyj == 0.0:
                for i in range(ni):
                    if qx[i] == 0.0:
                        c[j, i] = 0.0


def weighted_power(const double complex[:, ::1] c, const double[::1] qx,
                   const double[::1] qy, const double[::1] wrow, int power):
    """``sum_j wrow[j] sum_i |c[j, i]|**2 |q|**power`` over this rank's Fourier slab.

    ``wrow`` holds the Hermitian multiplicity of each half-plane row (1 for
    ``ky = 0`` and the Nyquist row of an even ``ny``, 2 otherwise), so that the
    sum over the half plane equals the sum over the full plane.  Terms with
    ``|q| = 0`` contribute only when ``power == 0``.
    """
    cdef Py_ssize_t i, j, nj = c.shape[0], ni = c.shape[1]
    cdef double q2, a, rowsum, total = 0.0, qyj
    if power not in (-1, 0, 1, 2, 4):
        raise ValueError(f"power={power} is not one of -1, 0, 1, 2, 4")
    if qx.shape[0] != ni or qy.shape[0] != nj or wrow.shape[0] != nj:
        raise ValueError("wavevector or weight arrays do not match the Fourier slab")
    with nogil:
        for j in range(nj):
            qyj = qy[j] * qy[j]
            rowsum = 0.0
            for i in range(ni):
                a = c[j, i].real * c[j, i].real + c[j, i].imag * c[j, i].imag
                if power == 0:
                    rowsum = rowsum + a
                else:
                    q2 = qx[i] * qx[i] + qyj
                    if q2 > 0.0:
                        if power == 1:
                            rowsum = rowsum + a * sqrt(q2)
                        elif power == 2:
                            rowsum = rowsum + a * q2
                        elif power == 4:
                            rowsum = rowsum + a * q2 * q2
                        elif power == -1:
                            rowsum = rowsum + a / sqrt(q2)
            total = total + wrow[j] * rowsum
    return total
