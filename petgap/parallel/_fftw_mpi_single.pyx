# cython: language_level=3
"""The single-precision twin of :mod:`petgap.parallel._fftw_mpi`: the same binding on FFTW's
``fftwf_*`` functions, for ``float32`` real and ``complex64`` Fourier buffers.

The Cython names are the double module's (``fftw_plan``, ``fftw_execute``, ...), bound
here to the single-precision C names, and the classes and functions come from the
same source (``_fftw_body.pxi``): only the element type ``real_t`` differs.
Wavevectors, multipliers and every sum are double in both.  FFTW keeps the wisdom of
each precision apart, so :func:`export_wisdom` and :func:`import_wisdom` here carry
single-precision wisdom only.
"""
from mpi4py.libmpi cimport MPI_Comm

cdef extern from "fftw3-mpi.h" nogil:
    ctypedef float fftw_complex "fftwf_complex" [2]
    ctypedef struct fftw_plan_s "fftwf_plan_s":
        pass
    ctypedef fftw_plan_s *fftw_plan "fftwf_plan"
    unsigned FFTW_ESTIMATE, FFTW_MEASURE, FFTW_PATIENT, FFTW_EXHAUSTIVE
    unsigned FFTW_WISDOM_ONLY, FFTW_DESTROY_INPUT
    unsigned FFTW_MPI_TRANSPOSED_IN, FFTW_MPI_TRANSPOSED_OUT
    void fftw_mpi_init "fftwf_mpi_init"()
    ptrdiff_t fftw_mpi_local_size_2d_transposed "fftwf_mpi_local_size_2d_transposed"(
        ptrdiff_t n0, ptrdiff_t n1, MPI_Comm comm,
        ptrdiff_t *local_n0, ptrdiff_t *local_0_start,
        ptrdiff_t *local_n1, ptrdiff_t *local_1_start)
    fftw_plan fftw_mpi_plan_dft_r2c_2d "fftwf_mpi_plan_dft_r2c_2d"(
        ptrdiff_t n0, ptrdiff_t n1, float *inp, fftw_complex *out, MPI_Comm comm,
        unsigned flags)
    fftw_plan fftw_mpi_plan_dft_c2r_2d "fftwf_mpi_plan_dft_c2r_2d"(
        ptrdiff_t n0, ptrdiff_t n1, fftw_complex *inp, float *out, MPI_Comm comm,
        unsigned flags)
    int FFTW_FORWARD, FFTW_BACKWARD
    ptrdiff_t FFTW_MPI_DEFAULT_BLOCK
    fftw_plan fftw_plan_many_dft_r2c "fftwf_plan_many_dft_r2c"(
        int rank, const int *n, int howmany, float *inp, const int *inembed, int istride,
        int idist, fftw_complex *out, const int *onembed, int ostride, int odist,
        unsigned flags)
    fftw_plan fftw_plan_many_dft_c2r "fftwf_plan_many_dft_c2r"(
        int rank, const int *n, int howmany, fftw_complex *inp, const int *inembed,
        int istride, int idist, float *out, const int *onembed, int ostride, int odist,
        unsigned flags)
    fftw_plan fftw_plan_many_dft "fftwf_plan_many_dft"(
        int rank, const int *n, int howmany, fftw_complex *inp, const int *inembed,
        int istride, int idist, fftw_complex *out, const int *onembed, int ostride,
        int odist, int sign, unsigned flags)
    fftw_plan fftw_mpi_plan_many_transpose "fftwf_mpi_plan_many_transpose"(
        ptrdiff_t n0, ptrdiff_t n1, ptrdiff_t howmany, ptrdiff_t block0, ptrdiff_t block1,
        float *inp, float *out, MPI_Comm comm, unsigned flags)
    void *fftw_malloc "fftwf_malloc"(size_t n)
    void fftw_execute "fftwf_execute"(const fftw_plan p)
    void fftw_execute_dft "fftwf_execute_dft"(const fftw_plan p, fftw_complex *inp,
                                              fftw_complex *out)
    void fftw_execute_dft_r2c "fftwf_execute_dft_r2c"(const fftw_plan p, float *inp,
                                                      fftw_complex *out)
    void fftw_execute_dft_c2r "fftwf_execute_dft_c2r"(const fftw_plan p, fftw_complex *inp,
                                                      float *out)
    void fftw_destroy_plan "fftwf_destroy_plan"(fftw_plan p)
    void fftw_mpi_broadcast_wisdom "fftwf_mpi_broadcast_wisdom"(MPI_Comm comm)
    void fftw_mpi_gather_wisdom "fftwf_mpi_gather_wisdom"(MPI_Comm comm)
    char *fftw_export_wisdom_to_string "fftwf_export_wisdom_to_string"()
    int fftw_import_wisdom_from_string "fftwf_import_wisdom_from_string"(const char *s)
    void fftw_free "fftwf_free"(void *p)
    int fftw_alignment_of "fftwf_alignment_of"(float *p)

ctypedef float real_t
ctypedef float complex complex_t

include "_fftw_body.pxi"

#: dtypes of the real and Fourier buffers this module's plans take.
REAL_DTYPE = np.float32
COMPLEX_DTYPE = np.complex64
