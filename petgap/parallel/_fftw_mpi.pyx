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
from mpi4py.libmpi cimport MPI_Comm

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
    fftw_plan fftw_plan_many_dft(int rank, const int *n, int howmany, fftw_complex *inp,
                                 const int *inembed, int istride, int idist, fftw_complex *out,
                                 const int *onembed, int ostride, int odist, int sign,
                                 unsigned flags)
    fftw_plan fftw_mpi_plan_many_transpose(ptrdiff_t n0, ptrdiff_t n1, ptrdiff_t howmany,
                                           ptrdiff_t block0, ptrdiff_t block1, double *inp,
                                           double *out, MPI_Comm comm, unsigned flags)
    void *fftw_malloc(size_t n)
    void fftw_execute(const fftw_plan p)
    void fftw_execute_dft(const fftw_plan p, fftw_complex *inp, fftw_complex *out)
    void fftw_execute_dft_r2c(const fftw_plan p, double *inp, fftw_complex *out)
    void fftw_execute_dft_c2r(const fftw_plan p, fftw_complex *inp, double *out)
    void fftw_destroy_plan(fftw_plan p)
    void fftw_mpi_broadcast_wisdom(MPI_Comm comm)
    void fftw_mpi_gather_wisdom(MPI_Comm comm)
    char *fftw_export_wisdom_to_string()
    int fftw_import_wisdom_from_string(const char *s)
    void fftw_free(void *p)
    int fftw_alignment_of(double *p)

ctypedef double real_t
ctypedef double complex complex_t

include "_fftw_body.pxi"

#: dtypes of the real and Fourier buffers this module's plans take.
REAL_DTYPE = np.float64
COMPLEX_DTYPE = np.complex128
