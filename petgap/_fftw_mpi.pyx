# cython: language_level=3
"""Thin binding to FFTW 3.3's MPI interface for 2D real-data transforms.

Only what petgap needs is wrapped: the transposed slab distribution of a 2D
real-to-complex transform, one forward (r2c, ``FFTW_MPI_TRANSPOSED_OUT``) and one
backward (c2r, ``FFTW_MPI_TRANSPOSED_IN``) plan on buffers owned by the caller,
the elastic Fourier multiplier fused with the transforms (:class:`ConvolutionPlans`),
wisdom broadcast/gather, and a fused loop over the Fourier slab that would
otherwise cost several NumPy passes.

Layout (FFTW manual, sections 6.4.3 and 6.5): the real array is ``n0 x n1``,
distributed over its first axis in blocks, and padded in its last axis to
``2 (n1 // 2 + 1)`` doubles even for out-of-place transforms.  The transposed
Fourier array is ``(n1 // 2 + 1) x n0`` complex values, distributed over its
first axis.  Transforms are unnormalised: forward then backward multiplies by
``n0 * n1``.
"""
from libc.math cimport sqrt
from libc.string cimport memcpy
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
    int FFTW_FORWARD, FFTW_BACKWARD
    ptrdiff_t FFTW_MPI_DEFAULT_BLOCK
    fftw_plan fftw_plan_many_dft_r2c(int rank, const int *n, int howmany, double *inp,
                                     const int *inembed, int istride, int idist,
                                     fftw_complex *out, const int *onembed, int ostride,
                                     int odist, unsigned flags)
    fftw_plan fftw_plan_many_dft_c2r(int rank, const int *n, int howmany, fftw_complex *inp,
                                     const int *inembed, int istride, int idist, double *out,
                                     const int *onembed, int ostride, int odist, unsigned flags)
    fftw_plan fftw_plan_dft_1d(int n, fftw_complex *inp, fftw_complex *out, int sign,
                               unsigned flags)
    fftw_plan fftw_mpi_plan_many_transpose(ptrdiff_t n0, ptrdiff_t n1, ptrdiff_t howmany,
                                           ptrdiff_t block0, ptrdiff_t block1, double *inp,
                                           double *out, MPI_Comm comm, unsigned flags)
    void *fftw_malloc(size_t n)
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


cdef _check_plan_inputs(cnp.ndarray real, cnp.ndarray fourier, str planner):
    """The checks both plan classes make before FFTW reads the buffers' memory."""
    if planner not in PLANNER_FLAGS:
        raise ValueError(f"planner={planner!r} is not one of {sorted(PLANNER_FLAGS)}")
    if real.dtype != np.float64 or not real.flags.c_contiguous:
        raise TypeError("real buffer must be C-contiguous float64")
    if fourier.dtype != np.complex128 or not fourier.flags.c_contiguous:
        raise TypeError("fourier buffer must be C-contiguous complex128")


cdef inline void _destroy(fftw_plan *plan):
    """Destroy a plan that may never have been made, and forget it."""
    if plan[0] != NULL:
        fftw_destroy_plan(plan[0])
        plan[0] = NULL


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
        _check_plan_inputs(real, fourier, planner)
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
        _destroy(&self.fwd)
        _destroy(&self.bwd)


cdef class ConvolutionPlans:
    """``x <- F^{-1} [scale |q|^power F x]`` in the padded real slab, in one sweep.

    The elastic operators are Fourier multipliers, and applying one with the two
    2D plans of :class:`SlabPlans` streams the Fourier slab through memory three
    more times than needed (the last 1D pass of the forward transform, the
    multiplication, the first 1D pass of the backward transform).  Here the 2D
    transforms are taken apart the way FFTW-MPI builds them (FFTW manual 6.4.3):
    1D r2c transforms along the local rows, a global transpose, 1D transforms
    along the rows of the transposed slab, and the reverse.  The middle stage is
    fused row by row -- forward 1D transform, multiplication, backward 1D
    transform on one row held in cache -- so that the Fourier slab is read and
    written once there instead of three times.  The transposed layout and the
    normalisation are those of :class:`SlabPlans` (unnormalised; the caller's
    ``scale`` folds in ``1 / (n0 n1)``), and the q = 0 mode is set to zero.

    Parameters are those of :class:`SlabPlans` plus the local row counts
    ``local_n0`` (real rows) and ``local_n1`` (transposed Fourier rows), both
    positive (see :func:`local_size_transposed`).  The real buffer is the input
    and the output; the Fourier buffer is scratch.  Planning with an effort
    above ``"estimate"`` overwrites both buffers.
    """
    cdef fftw_plan rows_fwd
    cdef fftw_plan rows_bwd
    cdef fftw_plan transpose_fwd
    cdef fftw_plan transpose_bwd
    cdef fftw_plan line_fwd
    cdef fftw_plan line_bwd
    cdef fftw_complex *line
    cdef double *real_data
    cdef fftw_complex *fourier_data
    cdef Py_ssize_t n0, ln1
    cdef object comm, real, fourier

    def __cinit__(self):
        self.rows_fwd = self.rows_bwd = NULL
        self.transpose_fwd = self.transpose_bwd = NULL
        self.line_fwd = self.line_bwd = NULL
        self.line = NULL

    def __init__(self, MPI.Comm comm, Py_ssize_t n0, Py_ssize_t n1, Py_ssize_t local_n0,
                 Py_ssize_t local_n1, cnp.ndarray real, cnp.ndarray fourier,
                 str planner="measure"):
        _check_plan_inputs(real, fourier, planner)
        if local_n0 <= 0 or local_n1 <= 0:
            raise ValueError("every rank needs at least one real and one Fourier row")
        self.comm, self.real, self.fourier = comm, real, fourier
        self.n0, self.ln1 = n0, local_n1
        cdef unsigned flags = PLANNER_FLAGS[planner]
        cdef int n = <int>n1
        cdef int nky = <int>(n1 // 2 + 1)
        cdef int howmany = <int>local_n0
        cdef int line_length = <int>n0
        cdef MPI_Comm mcomm = comm.ob_mpi
        self.real_data = <double *>cnp.PyArray_DATA(real)
        self.fourier_data = <fftw_complex *>cnp.PyArray_DATA(fourier)
        self.line = <fftw_complex *>fftw_malloc(n0 * sizeof(fftw_complex))
        if self.line == NULL:
            raise MemoryError("no memory for one Fourier row")
        with nogil:
            # real (local_n0, 2 nky) doubles -> fourier (local_n0, nky) complex
            self.rows_fwd = fftw_plan_many_dft_r2c(1, &n, howmany, self.real_data, NULL, 1,
                                                   2 * nky, self.fourier_data, NULL, 1, nky,
                                                   flags)
            # fourier (n0 x nky, by rows) -> real buffer as complex (nky x n0, by rows)
            self.transpose_fwd = fftw_mpi_plan_many_transpose(
                n0, nky, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                <double *>self.fourier_data, self.real_data, mcomm, flags)
            self.line_fwd = fftw_plan_dft_1d(line_length, self.line, self.line, FFTW_FORWARD,
                                             flags)
            self.line_bwd = fftw_plan_dft_1d(line_length, self.line, self.line, FFTW_BACKWARD,
                                             flags)
            self.transpose_bwd = fftw_mpi_plan_many_transpose(
                nky, n0, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                self.real_data, <double *>self.fourier_data, mcomm, flags)
            self.rows_bwd = fftw_plan_many_dft_c2r(1, &n, howmany, self.fourier_data, NULL, 1,
                                                   nky, self.real_data, NULL, 1, 2 * nky,
                                                   flags | FFTW_DESTROY_INPUT)
        if (self.rows_fwd == NULL or self.rows_bwd == NULL or self.transpose_fwd == NULL
                or self.transpose_bwd == NULL or self.line_fwd == NULL or self.line_bwd == NULL):
            raise RuntimeError(f"FFTW-MPI could not plan a {n0} x {n1} convolution")

    def apply(self, const double[::1] qx, const double[::1] qy, double scale, int power):
        """Multiply by ``scale |q|^power`` (``power`` +1 or -1) between the transforms."""
        cdef Py_ssize_t i, j, n0 = self.n0
        cdef double qyj, f
        cdef double *s = <double *>self.line
        cdef fftw_complex *row
        if qx.shape[0] != n0 or qy.shape[0] != self.ln1:
            raise ValueError("wavevector arrays do not match the Fourier slab")
        if power != 1 and power != -1:
            raise ValueError("power must be +1 or -1")
        with nogil:
            fftw_execute(self.rows_fwd)
            fftw_execute(self.transpose_fwd)
            for j in range(self.ln1):
                row = (<fftw_complex *>self.real_data) + j * n0
                memcpy(self.line, row, n0 * sizeof(fftw_complex))
                fftw_execute(self.line_fwd)
                qyj = qy[j] * qy[j]
                if power == 1:
                    for i in range(n0):
                        f = scale * sqrt(qx[i] * qx[i] + qyj)
                        s[2 * i] = s[2 * i] * f
                        s[2 * i + 1] = s[2 * i + 1] * f
                else:
                    for i in range(n0):
                        f = scale / sqrt(qx[i] * qx[i] + qyj)
                        s[2 * i] = s[2 * i] * f
                        s[2 * i + 1] = s[2 * i + 1] * f
                if qyj == 0.0:
                    for i in range(n0):
                        if qx[i] == 0.0:
                            s[2 * i] = 0.0
                            s[2 * i + 1] = 0.0
                fftw_execute(self.line_bwd)
                memcpy(row, self.line, n0 * sizeof(fftw_complex))
            fftw_execute(self.transpose_bwd)
            fftw_execute(self.rows_bwd)

    def __dealloc__(self):
        _destroy(&self.rows_fwd)
        _destroy(&self.rows_bwd)
        _destroy(&self.transpose_fwd)
        _destroy(&self.transpose_bwd)
        _destroy(&self.line_fwd)
        _destroy(&self.line_bwd)
        if self.line != NULL:
            fftw_free(self.line)


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
