# The precision-independent body of petgap's FFTW-MPI binding, included by
# _fftw_mpi.pyx (double: real_t = double, FFTW's fftw_* functions) and by
# _fftw_mpi_single.pyx (single: real_t = float, the same Cython names bound to
# FFTW's fftwf_* functions), so that both precisions run the same source.
# Wavevectors, multipliers and every sum stay in double in both.  Each module
# cimports MPI_Comm and declares FFTW's functions and real_t/complex_t before
# including this, and defines REAL_DTYPE/COMPLEX_DTYPE after it.
from libc.math cimport sqrt
from libc.string cimport memcpy, memset
from mpi4py cimport MPI
cimport numpy as cnp
import numpy as np

cnp.import_array()

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
    return local_size_lines(comm, n0, n1 // 2 + 1)


def padded_line_count(Py_ssize_t cy):
    """The Fourier lines of a ``cy``-long padded row in :class:`PaddedConvolutionPlans`:
    ``cy // 2`` for an even ``cy`` (the Nyquist column packed into the ``ky = 0`` line),
    ``cy // 2 + 1`` for an odd one (no Nyquist column)."""
    return cy // 2 if cy % 2 == 0 else cy // 2 + 1


def local_size_lines(MPI.Comm comm, Py_ssize_t n0, Py_ssize_t nlines):
    """Slab sizes of ``n0`` rows of ``nlines`` complex values transposed to ``nlines`` lines
    of ``n0`` (FFTW-MPI's default blocks): ``(alloc_local, local_n0, local_0_start,
    local_n1, local_1_start)``, as for :func:`local_size_transposed` (an r2c row of
    ``n1`` reals has ``n1 // 2 + 1`` such values)."""
    cdef ptrdiff_t ln0 = 0, l0s = 0, ln1 = 0, l1s = 0, alloc
    alloc = fftw_mpi_local_size_2d_transposed(n0, nlines, comm.ob_mpi, &ln0, &l0s, &ln1, &l1s)
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
    if real.dtype != REAL_DTYPE or not real.flags.c_contiguous:
        raise TypeError(f"real buffer must be C-contiguous {np.dtype(REAL_DTYPE).name}")
    if fourier.dtype != COMPLEX_DTYPE or not fourier.flags.c_contiguous:
        raise TypeError(f"fourier buffer must be C-contiguous {np.dtype(COMPLEX_DTYPE).name}")


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
    real : ndarray of the module's real type (:data:`REAL_DTYPE`), C-contiguous, at least ``2 * alloc_local`` values
        Padded real slab; plans read and write it in place of any copy.
    fourier : ndarray of :data:`COMPLEX_DTYPE`, C-contiguous, at least ``alloc_local`` values
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
        cdef real_t *r = <real_t *>cnp.PyArray_DATA(real)
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


ctypedef int index_t  # numpy.int32, as in petgap/_contact_set.pyx: flat padded-slab indices

#: Rows the sparse variants of :class:`ConvolutionPlans` assemble (or take
#: apart) at a time in a small buffer that stays in cache.  A multiple of 8
#: keeps every block's start in the Fourier slab 64-byte aligned (8 rows of
#: ``nky`` complex values are ``128 nky`` bytes), as FFTW's new-array execute
#: requires of the arrays a plan was made for.
cdef enum:
    BLOCK_ROWS = 8


cdef inline void _block_sizes(Py_ssize_t rows, int sizes[2]) noexcept:
    """Row counts of the two block plans for ``rows`` rows: a full block, and the remainder.

    ``sizes[0] = min(BLOCK_ROWS, rows)``; ``sizes[1]`` is the last, partial
    block's size, or 0 when there is none.
    """
    sizes[0] = <int>min(<Py_ssize_t>BLOCK_ROWS, rows)
    sizes[1] = <int>(rows % BLOCK_ROWS) if rows > BLOCK_ROWS else 0


cdef inline int _block(Py_ssize_t start, Py_ssize_t rows, Py_ssize_t full,
                       Py_ssize_t *m) noexcept nogil:
    """The block of rows from ``start``: its size in ``m``, and which plan takes it.

    Plan 0 takes ``full = min(BLOCK_ROWS, rows)`` rows, plan 1 the remainder.
    """
    m[0] = min(<Py_ssize_t>BLOCK_ROWS, rows - start)
    return 0 if m[0] == full else 1


cdef inline double _norm2(const real_t *s) noexcept nogil:
    """``|c|^2`` of the complex value at ``s``, in double."""
    return <double>s[0] * s[0] + <double>s[1] * s[1]


cdef class ConvolutionPlans:
    """``x <- F^{-1} [scale |q|^power F x]`` in the padded real slab, in one sweep.

    The elastic operators are Fourier multipliers, and applying one with the two
    2D plans of :class:`SlabPlans` streams the Fourier slab through memory three
    more times than needed (the last 1D pass of the forward transform, the
    multiplication, the first 1D pass of the backward transform).  Here the 2D
    transforms are taken apart the way FFTW-MPI builds them (FFTW manual 6.4.3):
    1D r2c transforms along the local rows, a global transpose, 1D transforms
    along the rows of the transposed slab, and the reverse.  The middle stage is
    fused a few rows at a time -- forward 1D transforms, multiplication,
    backward 1D transforms on ``BLOCK_ROWS`` rows held in cache, in place -- so
    that the Fourier slab is read and written once there instead of three
    times.  The transposed layout and the
    normalisation are those of :class:`SlabPlans` (unnormalised; the caller's
    ``scale`` folds in ``1 / (n0 n1)``), and the q = 0 mode is set to zero.

    Taken apart, the first and last stages can also meet a field that lives
    on a few points only (:meth:`apply_sparse`): the rows of the input are
    assembled a block at a time from index lists in a buffer held in cache,
    instead of being written to the slab and read back, and the output is
    written where the caller wants it or gathered on those points alone.

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
    cdef fftw_plan lines_fwd[2]   # BLOCK_ROWS lines of the transposed slab, and the rest
    cdef fftw_plan lines_bwd[2]
    cdef fftw_plan block_fwd[2]   # BLOCK_ROWS rows, and the remainder (or NULL)
    cdef fftw_plan block_bwd[2]
    cdef real_t *block
    cdef double *factor   # one line's multiplier (begin_sparse)
    cdef real_t *real_data
    cdef fftw_complex *fourier_data
    cdef Py_ssize_t n0, ln0, ln1, nky
    cdef int block_rows[2], block_lines[2]   # rows of the plans [0] and [1] (_block_sizes)
    cdef object comm, real, fourier
    #: True between a begin (:meth:`begin_sparse`, :meth:`begin`) and :meth:`end`; every
    #: other transform of these plans clears it
    cdef public bint half_made

    def __cinit__(self):
        self.half_made = False
        self.rows_fwd = self.rows_bwd = NULL
        self.transpose_fwd = self.transpose_bwd = NULL
        self.lines_fwd[0] = self.lines_fwd[1] = NULL
        self.lines_bwd[0] = self.lines_bwd[1] = NULL
        self.block_fwd[0] = self.block_fwd[1] = NULL
        self.block_bwd[0] = self.block_bwd[1] = NULL
        self.block = NULL
        self.factor = NULL

    def __init__(self, MPI.Comm comm, Py_ssize_t n0, Py_ssize_t n1, Py_ssize_t local_n0,
                 Py_ssize_t local_n1, cnp.ndarray real, cnp.ndarray fourier,
                 str planner="measure"):
        _check_plan_inputs(real, fourier, planner)
        if local_n0 <= 0 or local_n1 <= 0:
            raise ValueError("every rank needs at least one real and one Fourier row")
        self.comm, self.real, self.fourier = comm, real, fourier
        self.n0, self.ln0, self.ln1 = n0, local_n0, local_n1
        self.nky = n1 // 2 + 1
        _block_sizes(local_n0, self.block_rows)
        _block_sizes(local_n1, self.block_lines)
        cdef unsigned flags = PLANNER_FLAGS[planner]
        cdef int n = <int>n1
        cdef int nky = <int>(n1 // 2 + 1)
        cdef int howmany = <int>local_n0
        cdef int line_length = <int>n0
        cdef int *rows = self.block_rows
        cdef MPI_Comm mcomm = comm.ob_mpi
        self.real_data = <real_t *>cnp.PyArray_DATA(real)
        self.fourier_data = <fftw_complex *>cnp.PyArray_DATA(fourier)
        cdef int *lines = self.block_lines
        cdef fftw_complex *transposed = <fftw_complex *>self.real_data
        self.block = <real_t *>fftw_malloc(BLOCK_ROWS * 2 * nky * sizeof(real_t))
        self.factor = <double *>fftw_malloc(n0 * sizeof(double))
        if self.block == NULL or self.factor == NULL:
            raise MemoryError("no memory for a block of rows")
        with nogil:
            # real (local_n0, 2 nky) reals -> fourier (local_n0, nky) complex
            self.rows_fwd = fftw_plan_many_dft_r2c(1, &n, howmany, self.real_data, NULL, 1,
                                                   2 * nky, self.fourier_data, NULL, 1, nky,
                                                   flags)
            # fourier (n0 x nky, by rows) -> real buffer as complex (nky x n0, by rows)
            self.transpose_fwd = fftw_mpi_plan_many_transpose(
                n0, nky, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                <real_t *>self.fourier_data, self.real_data, mcomm, flags)
            # BLOCK_ROWS rows of the transposed slab at a time, in place
            for k in range(2):
                if lines[k] > 0:
                    self.lines_fwd[k] = fftw_plan_many_dft(
                        1, &line_length, lines[k], transposed, NULL, 1, line_length,
                        transposed, NULL, 1, line_length, FFTW_FORWARD, flags)
                    self.lines_bwd[k] = fftw_plan_many_dft(
                        1, &line_length, lines[k], transposed, NULL, 1, line_length,
                        transposed, NULL, 1, line_length, FFTW_BACKWARD, flags)
            self.transpose_bwd = fftw_mpi_plan_many_transpose(
                nky, n0, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                self.real_data, <real_t *>self.fourier_data, mcomm, flags)
            self.rows_bwd = fftw_plan_many_dft_c2r(1, &n, howmany, self.fourier_data, NULL, 1,
                                                   nky, self.real_data, NULL, 1, 2 * nky,
                                                   flags | FFTW_DESTROY_INPUT)
            # The same row stages on a block of rows held in self.block (same
            # padded layout), executed on the Fourier rows of each block in turn.
            for k in range(2):
                if rows[k] > 0:
                    self.block_fwd[k] = fftw_plan_many_dft_r2c(
                        1, &n, rows[k], self.block, NULL, 1, 2 * nky, self.fourier_data, NULL,
                        1, nky, flags)
                    self.block_bwd[k] = fftw_plan_many_dft_c2r(
                        1, &n, rows[k], self.fourier_data, NULL, 1, nky, self.block, NULL, 1,
                        2 * nky, flags | FFTW_DESTROY_INPUT)
        if (self.rows_fwd == NULL or self.rows_bwd == NULL or self.transpose_fwd == NULL
                or self.transpose_bwd == NULL
                or self.lines_fwd[0] == NULL or self.lines_bwd[0] == NULL
                or (lines[1] > 0 and (self.lines_fwd[1] == NULL or self.lines_bwd[1] == NULL))
                or self.block_fwd[0] == NULL or self.block_bwd[0] == NULL
                or (rows[1] > 0 and (self.block_fwd[1] == NULL or self.block_bwd[1] == NULL))):
            raise RuntimeError(f"FFTW-MPI could not plan a {n0} x {n1} convolution")

    cdef int _check_multiplier(self, const double[::1] qx, const double[::1] qy,
                               int power, const double[::1] wrow=None) except -1:
        """The multiplier's arrays against the slab (``wrow``, the rows' Hermitian
        multiplicity, where a form is summed)."""
        if qx.shape[0] != self.n0 or qy.shape[0] != self.ln1:
            raise ValueError("wavevector arrays do not match the Fourier slab")
        if wrow is not None and wrow.shape[0] != self.ln1:
            raise ValueError("wrow does not match the Fourier slab")
        if power != 1 and power != -1:
            raise ValueError("power must be +1 or -1")
        return 0

    cdef double _multiply(self, Py_ssize_t j0, Py_ssize_t m, const double *qx,
                          const double *qy, double scale, int power,
                          const double *wrow) noexcept nogil:
        """Rows ``j0 .. j0 + m`` of the transposed slab times ``scale |q|^power``, q = 0 zeroed.

        With ``wrow`` (the Hermitian multiplicity of each row), also returns
        ``sum_j wrow[j] sum_i scale |q|^power |c_ji|^2`` of the rows as they were,
        accumulated in double: by Parseval the form ``(x, F^{-1} f F x)`` of the
        field these rows came from (the caller's ``scale`` carries ``1 / (n0 n1)``).
        """
        cdef Py_ssize_t i, j, n0 = self.n0
        cdef double qyj, f, row, r0, r1, r2, r3, total = 0.0
        cdef double *fr
        cdef real_t *s
        for j in range(j0, j0 + m):
            s = <real_t *>((<fftw_complex *>self.real_data) + j * n0)
            qyj = qy[j] * qy[j]
            if wrow == NULL:
                # the hot loop of every application: no reduction, so that it vectorises
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
                continue
            # the row's multiplier (vectorised), then the form with four partial sums
            # (so that the adds do not wait on each other), then the product
            fr = self.factor
            if power == 1:
                for i in range(n0):
                    fr[i] = scale * sqrt(qx[i] * qx[i] + qyj)
            else:
                for i in range(n0):
                    fr[i] = scale / sqrt(qx[i] * qx[i] + qyj)
            if qyj == 0.0:
                for i in range(n0):
                    if qx[i] == 0.0:
                        fr[i] = 0.0
            r0 = r1 = r2 = r3 = 0.0
            i = 0
            while i + 4 <= n0:
                r0 = r0 + fr[i] * _norm2(s + 2 * i)
                r1 = r1 + fr[i + 1] * _norm2(s + 2 * i + 2)
                r2 = r2 + fr[i + 2] * _norm2(s + 2 * i + 4)
                r3 = r3 + fr[i + 3] * _norm2(s + 2 * i + 6)
                i += 4
            while i < n0:
                r0 = r0 + fr[i] * _norm2(s + 2 * i)
                i += 1
            row = (r0 + r1) + (r2 + r3)
            for i in range(n0):
                s[2 * i] = <real_t>(s[2 * i] * fr[i])
                s[2 * i + 1] = <real_t>(s[2 * i + 1] * fr[i])
            total = total + wrow[j] * row
        return total

    cdef void _middle(self, const double *qx, const double *qy, double scale,
                      int power) noexcept nogil:
        """Fourier rows -> (transpose, 1D transforms and multiplier, transpose) -> Fourier rows.

        The rows of the transposed slab are transformed in place, BLOCK_ROWS
        at a time (in cache), multiplied, and transformed back.
        """
        cdef Py_ssize_t j0, m
        cdef fftw_complex *rows
        cdef int which
        fftw_execute(self.transpose_fwd)
        j0 = 0
        while j0 < self.ln1:
            which = _block(j0, self.ln1, self.block_lines[0], &m)
            rows = (<fftw_complex *>self.real_data) + j0 * self.n0
            fftw_execute_dft(self.lines_fwd[which], rows, rows)
            self._multiply(j0, m, qx, qy, scale, power, NULL)
            fftw_execute_dft(self.lines_bwd[which], rows, rows)
            j0 += BLOCK_ROWS
        fftw_execute(self.transpose_bwd)

    def apply(self, const double[::1] qx, const double[::1] qy, double scale, int power):
        """Multiply by ``scale |q|^power`` (``power`` +1 or -1) between the transforms."""
        self._check_multiplier(qx, qy, power)
        self.half_made = False
        with nogil:
            fftw_execute(self.rows_fwd)
            self._middle(&qx[0], &qy[0], scale, power)
            fftw_execute(self.rows_bwd)

    def apply_sparse(self, const index_t[::1] pidx, const real_t[::1] values,
                     const double[::1] qx, const double[::1] qy, double scale, int power,
                     real_t[:, ::1] out=None, real_t[::1] gathered=None):
        """The convolution of a field that is zero except at the points ``pidx``.

        Parameters
        ----------
        pidx : int32 array, sorted ascending
            Flat indices of the points into this rank's padded real slab
            (``local_n0 x 2 (n1 // 2 + 1)``, row-major).
        values : array of the module's real type, ``len(pidx)``
            The field at those points.
        qx, qy, scale, power
            The multiplier, as in :meth:`apply`.
        out : array of the module's real type, padded slab shape, optional
            Where the result goes (default: the real buffer).  It must be
            aligned like the real buffer (``grid.aligned_padded()`` is);
            its padding columns are left as they are.
        gathered : array of the module's real type, ``len(pidx)``, optional
            Instead of a whole slab, only the result at the points ``pidx``
            (``out`` is then left untouched).  Both FFT buffers are scratch
            in every case: the transposes go through the real one.

        The input is assembled ``BLOCK_ROWS`` rows at a time in a buffer that
        stays in cache and transformed from there; a gathered output is taken
        apart the same way.  Neither the slab-sized zeroing and scatter of the
        input nor the slab-sized write of the output goes through memory.
        """
        self._check_multiplier(qx, qy, power)
        cdef Py_ssize_t ns = pidx.shape[0], pw = 2 * self.nky, ln0 = self.ln0
        cdef Py_ssize_t i0, k, m, base, end
        cdef int which
        cdef real_t *target = NULL
        cdef real_t *g = NULL
        cdef bint ok
        cdef bint gather = gathered is not None
        if values.shape[0] != ns or (gather and gathered.shape[0] != ns):
            raise ValueError("pidx, values and gathered must have the same length")
        if not gather:
            target = self._target(out)
        if gather and ns > 0:
            g = &gathered[0]
        self.half_made = False
        with nogil:
            ok = self._assemble_rows(pidx, values)
            # The middle stage is collective (the transposes): every rank runs
            # it, valid input or not, so that a bad index list raises on its
            # rank instead of leaving the others waiting in a transpose.
            self._middle(&qx[0], &qy[0], scale, power)
            if ok and not gather:
                fftw_execute_dft_c2r(self.rows_bwd, self.fourier_data, target)
            elif ok and ns > 0:
                k = 0
                i0 = 0
                while i0 < ln0:
                    which = _block(i0, ln0, self.block_rows[0], &m)
                    base = i0 * pw
                    end = base + m * pw
                    fftw_execute_dft_c2r(self.block_bwd[which],
                                         self.fourier_data + i0 * self.nky, self.block)
                    while k < ns and pidx[k] < end:
                        g[k] = self.block[pidx[k] - base]
                        k += 1
                    i0 += BLOCK_ROWS
        if not ok:
            raise ValueError("pidx must be sorted ascending and inside this rank's padded slab")

    def begin_sparse(self, const index_t[::1] pidx, const real_t[::1] values,
                     const double[::1] qx, const double[::1] qy, const double[::1] wrow,
                     double scale, int power):
        """The first half of :meth:`apply_sparse`, and the form ``(x, F^{-1} f F x)`` on the way.

        Transforms the field ``x`` given at ``pidx`` forward and multiplies it
        by ``f = scale |q|^power``, leaving ``f F x`` in the transposed slab (in
        the real buffer) for :meth:`end` to transform back.  Returns this
        rank's part of ``sum_q f |F x|^2`` over the full plane (``wrow``: the
        Hermitian multiplicity of each local Fourier row), accumulated in
        double: summed over the ranks, ``(x, F^{-1} f F x)`` by Parseval, so that
        a solver needing only that product -- a step length -- pays half a
        transform pair for it, and the other half only if it needs the field.
        Any other use of the buffers in between loses the half-made field
        (:meth:`end` then refuses).
        """
        self._check_multiplier(qx, qy, power, wrow)
        if values.shape[0] != pidx.shape[0]:
            raise ValueError("pidx and values must have the same length")
        cdef double total
        cdef bint ok
        with nogil:
            ok = self._assemble_rows(pidx, values)
            # collective from here (the transpose): every rank runs it, as in apply_sparse
            total = self._forward_lines(&qx[0], &qy[0], &wrow[0], scale, power)
        self.half_made = ok
        if not ok:
            raise ValueError("pidx must be sorted ascending and inside this rank's padded slab")
        return total

    def begin(self, const double[::1] qx, const double[::1] qy, const double[::1] wrow,
              double scale, int power):
        """:meth:`begin_sparse` of the field in the real buffer (the first half of
        :meth:`apply`); the buffer is overwritten."""
        self._check_multiplier(qx, qy, power, wrow)
        cdef double total
        with nogil:
            fftw_execute(self.rows_fwd)
            total = self._forward_lines(&qx[0], &qy[0], &wrow[0], scale, power)
        self.half_made = True
        return total

    cdef double _forward_lines(self, const double *qx, const double *qy, const double *wrow,
                               double scale, int power) noexcept nogil:
        """Fourier rows -> transpose, 1D transforms, multiplier; returns the form."""
        cdef Py_ssize_t j0 = 0, m
        cdef fftw_complex *rows
        cdef int which
        cdef double total = 0.0
        fftw_execute(self.transpose_fwd)
        while j0 < self.ln1:
            which = _block(j0, self.ln1, self.block_lines[0], &m)
            rows = (<fftw_complex *>self.real_data) + j0 * self.n0
            fftw_execute_dft(self.lines_fwd[which], rows, rows)
            total = total + self._multiply(j0, m, qx, qy, scale, power, wrow)
            j0 += BLOCK_ROWS
        return total

    def end(self, real_t[:, ::1] out=None):
        """The second half after :meth:`begin_sparse` or :meth:`begin`: the field
        ``F^{-1} f F x`` to the real buffer, or to ``out`` (aligned like it; padding
        columns left as they are).  Collective."""
        cdef real_t *target = self._target(out)
        cdef Py_ssize_t j0, m
        cdef fftw_complex *rows
        cdef int which
        if not self.half_made:
            raise RuntimeError("no half-made transform to finish: a begin was not the last "
                               "use of the FFT buffers")
        self.half_made = False
        with nogil:
            j0 = 0
            while j0 < self.ln1:
                which = _block(j0, self.ln1, self.block_lines[0], &m)
                rows = (<fftw_complex *>self.real_data) + j0 * self.n0
                fftw_execute_dft(self.lines_bwd[which], rows, rows)
                j0 += BLOCK_ROWS
            fftw_execute(self.transpose_bwd)
            fftw_execute_dft_c2r(self.rows_bwd, self.fourier_data, target)

    cdef real_t *_target(self, real_t[:, ::1] out) except NULL:
        """Where a whole-slab result goes: the real buffer, or ``out`` checked against it."""
        cdef Py_ssize_t pw = 2 * self.nky
        if out is None:
            return self.real_data
        if out.shape[0] != self.ln0 or out.shape[1] != pw:
            raise ValueError(f"out has shape {tuple(out.shape)[:2]}, the padded slab is "
                             f"({self.ln0}, {pw})")
        if fftw_alignment_of(&out[0, 0]) != fftw_alignment_of(self.real_data):
            raise ValueError("out is not aligned like the real FFT buffer")
        return &out[0, 0]

    cdef bint _assemble_rows(self, const index_t[::1] pidx,
                             const real_t[::1] values) noexcept nogil:
        """The r2c row transforms of the field ``values`` at ``pidx`` into the Fourier buffer.

        The input is assembled ``BLOCK_ROWS`` rows at a time in a buffer that
        stays in cache and transformed from there.  Returns False if ``pidx``
        is not sorted ascending inside this rank's padded slab (the rows are
        transformed all the same, so that the collective stage after it runs).
        """
        cdef Py_ssize_t ns = pidx.shape[0], pw = 2 * self.nky, ln0 = self.ln0
        cdef Py_ssize_t i0 = 0, k = 0, m, base, end
        cdef int which
        cdef bint ok = True
        while i0 < ln0:
            which = _block(i0, ln0, self.block_rows[0], &m)
            base = i0 * pw
            end = base + m * pw
            memset(self.block, 0, m * pw * sizeof(real_t))
            while k < ns and pidx[k] < end:
                if pidx[k] < base:
                    ok = False  # unsorted or negative
                    break
                self.block[pidx[k] - base] = values[k]
                k += 1
            fftw_execute_dft_r2c(self.block_fwd[which], self.block,
                                 self.fourier_data + i0 * self.nky)
            i0 += BLOCK_ROWS
        return ok and k == ns

    def __dealloc__(self):
        _destroy(&self.rows_fwd)
        _destroy(&self.rows_bwd)
        _destroy(&self.transpose_fwd)
        _destroy(&self.transpose_bwd)
        for k in range(2):
            _destroy(&self.lines_fwd[k])
            _destroy(&self.lines_bwd[k])
            _destroy(&self.block_fwd[k])
            _destroy(&self.block_bwd[k])
        if self.block != NULL:
            fftw_free(self.block)
        if self.factor != NULL:
            fftw_free(self.factor)


#: Bytes of rows or lines the padded convolution transforms at a time in a buffer that
#: stays in cache (at most BLOCK_ROWS of them, at least one).
cdef enum:
    CACHE_BLOCK_BYTES = 1 << 18


cdef inline void _cache_block_sizes(Py_ssize_t total, Py_ssize_t width_bytes,
                                    int sizes[2]) noexcept:
    """Rows per cache block for rows of ``width_bytes``, and the last block's remainder.

    ``sizes[0]`` rows of at most :data:`CACHE_BLOCK_BYTES` together (1 to ``BLOCK_ROWS``,
    at most ``total``); ``sizes[1]`` the last, partial block's rows, or 0.
    """
    cdef Py_ssize_t block = max(1, min(<Py_ssize_t>BLOCK_ROWS,
                                       <Py_ssize_t>CACHE_BLOCK_BYTES // max(width_bytes, 1)))
    sizes[0] = <int>min(block, total)
    sizes[1] = <int>(total % block) if total > block else 0


cdef class PaddedConvolutionPlans:
    """``u = k * p`` over an ``nx x ny`` map, by zero padding to a ``cx x cy`` periodic cell, pruned.

    A linear convolution of the map with a kernel ``k`` that is even in ``x`` and
    ``y`` is the circular convolution on a cell large enough that no point of the
    map sees another through the cell's images: ``2 nx x 2 ny`` for a kernel of
    every offset the map holds (Hockney's padding; the free half-space's
    compliance), less for a kernel that falls off fast (a stiffness).  On the
    cell, the rows beyond the map's are zero and so is the end of each row, and
    all output off the map is discarded.  The 2D transform taken apart the way
    FFTW-MPI builds it (:class:`ConvolutionPlans`) lets each stage see only what
    is not zero or not discarded:

    1. r2c transforms along ``y`` of length ``cy`` on the map's ``nx`` rows only,
       each row zero-filled in a buffer held in cache, in the map's own slab
       decomposition (no rows move to another); for an even ``cy`` the
       Nyquist value ``ky = cy / 2``, real like ``ky = 0``, is packed into the
       imaginary part of ``ky = 0``, so that a row holds ``cy / 2`` complex values
       (:func:`padded_line_count`): the transpose's shape is then the map's own
       factors, which FFTW's in-place transpose moves faster than ``cy / 2 + 1``
       (odd for every even ``cy``);
    2. a global transpose of these ``nx x padded_line_count(cy)`` values (with
       ``square``, on one rank, as the square matrix of their larger side: the rows'
       tails and the rows past ``nx`` are padding that the transposes move and no
       stage reads);
    3. per Fourier line (``ky``), the ``cx``-point transform along ``x`` of the
       line's ``nx`` values and the zeros after them, the multiplication by the
       kernel's transform, and the inverse transform, a few lines at a time in
       cache, keeping only the map's ``nx`` outputs; the packed line ``a + i b``
       (``a`` at ``ky = 0``, ``b`` at the Nyquist ``ky``, both real along ``x``) is
       split after its transform by Hermitian symmetry, ``A(kx) = (Z(kx) +
       conj Z(-kx)) / 2``, ``B(kx) = (Z(kx) - conj Z(-kx)) / 2i``, and each part
       meets its own kernel line;
    4. the transpose back, and c2r transforms of the map's ``nx`` rows, keeping
       each row's first ``ny`` outputs.

    Against the cell's full transform pair, stages 1, 2 and 4 move and transform
    ``nx / cx`` of the data; stage 3 transforms every line of the cell (every
    wavevector of the cell carries the product), but in cache, reading and
    writing ``nx / cx`` of it.

    The form ``(p, k * p)`` needs the forward half only (by Parseval: ``p`` is
    zero off the map), so :meth:`begin_sparse` stops after the forward ``x``
    transforms without keeping them, and :meth:`end`, if the field is needed
    after all, takes stage 3 from the transposed rows, which stay in the lines
    buffer: a begin costs stages 1-2 and half of 3, an end the rest.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
    nx, ny : int
        The map's shape; ``nx`` is the distributed axis.
    cx, cy : int
        The cell's shape, at least the map's.
    local_n0, local_n1, local_1_start : int
        The map's rows here (FFTW-MPI's blocks of ``nx``), and the Fourier lines here
        (of ``padded_line_count(cy)``; may be 0): :func:`local_size_lines` of
        ``(nx, padded_line_count(cy))``.
    width : int
        Row length of the caller's fields (a padded slab's ``2 (ny // 2 + 1)``, or
        ``ny``): flat indices and whole fields are in rows of ``width``, the map's
        ``ny`` values first.
    rows, lines : arrays of :data:`COMPLEX_DTYPE`, ``alloc_local`` values each
        The rows' ``y`` transforms and the same transposed; the same array for
        in-place transposes (half the memory, and less traffic).  Scratch, owned by
        the caller.
    planner : str
        FFTW planner effort; measuring overwrites the buffers.
    square : bool
        Transpose as a square ``max(nx, padded_line_count(cy))`` matrix (one rank; the
        buffers hold its square): FFTW moves a square matrix in place much faster than
        a non-square one (:meth:`petgap.parallel.grid.Grid.zero_padded_plans`).

    The kernel's transform (:meth:`set_kernel`) is real and even in ``x``: row
    ``j`` holds it at ``kx = 0 .. cx // 2`` for ``ky = kernel_ky[j]``, divided by
    ``cx cy`` (the inverse transform's normalisation): one row per line here, and on
    the rank holding the packed ``ky = 0`` line one more, its Nyquist ``ky``, last.
    """
    cdef fftw_plan transpose_fwd
    cdef fftw_plan transpose_bwd
    cdef fftw_plan rows_fwd[2]    # in place on `block`: a full block of rows, the rest
    cdef fftw_plan rows_bwd[2]
    cdef fftw_plan lines_fwd[2]   # in place on `line`
    cdef fftw_plan lines_bwd[2]
    cdef real_t *block            # nrows[0] rows of 2 (cy // 2 + 1) reals
    cdef fftw_complex *line       # nlines[0] lines of cx complex values
    cdef fftw_complex *rows_data
    cdef fftw_complex *lines_data
    cdef const double *kernel_data
    cdef Py_ssize_t nx, ny, cx, cy, nyc, nyl, ln0, width
    cdef Py_ssize_t rs, ls        # complex values from one row (line) to the next in its buffer
    cdef Py_ssize_t nyquist_row   # the kernel row of the packed line's Nyquist part, or -1
    cdef bint packed
    cdef int nrows[2]
    cdef int nlines[2]
    cdef object comm, kernel
    #: the buffers (for :meth:`transpose`'s caller) and the Fourier lines held here
    cdef readonly object rows, lines
    cdef readonly Py_ssize_t local_n1, local_1_start
    #: whether the transposes move a square ``max(nx, nyl)`` matrix (one rank)
    cdef readonly bint square
    #: True between a begin and :meth:`end`; every other use of the plans clears it
    cdef public bint half_made

    def __cinit__(self):
        self.half_made = False
        self.transpose_fwd = self.transpose_bwd = NULL
        for k in range(2):
            self.rows_fwd[k] = self.rows_bwd[k] = NULL
            self.lines_fwd[k] = self.lines_bwd[k] = NULL
        self.block = NULL
        self.line = NULL
        self.kernel_data = NULL

    def __init__(self, MPI.Comm comm, Py_ssize_t nx, Py_ssize_t ny, Py_ssize_t cx,
                 Py_ssize_t cy, Py_ssize_t local_n0, Py_ssize_t local_n1,
                 Py_ssize_t local_1_start, Py_ssize_t width, cnp.ndarray rows,
                 cnp.ndarray lines, str planner="measure", bint square=False):
        if planner not in PLANNER_FLAGS:
            raise ValueError(f"planner={planner!r} is not one of {sorted(PLANNER_FLAGS)}")
        for name, a in (("rows", rows), ("lines", lines)):
            if a.dtype != COMPLEX_DTYPE or not a.flags.c_contiguous:
                raise TypeError(f"{name} buffer must be C-contiguous "
                                f"{np.dtype(COMPLEX_DTYPE).name}")
        if cx < nx or cy < ny or nx < 1 or ny < 1:
            raise ValueError(f"a {cx} x {cy} cell does not hold a {nx} x {ny} map")
        if local_n0 <= 0 or local_n1 < 0 or width < ny:
            raise ValueError("every rank needs a row of the map, and rows of at least ny values")
        self.nyc = cy // 2 + 1
        self.nyl = padded_line_count(cy)
        self.packed = self.nyl != self.nyc
        self.nyquist_row = local_n1 if self.packed and local_1_start == 0 and local_n1 > 0 else -1
        if square and comm.size != 1:
            raise ValueError(f"square=True needs one rank, not {comm.size}: on more, the "
                             f"padding lines would go to ranks that then hold none of the "
                             f"map's lines")
        self.square = square
        cdef Py_ssize_t side = max(nx, self.nyl)
        self.rs, self.ls = (side, side) if square else (self.nyl, nx)
        if rows.size < local_n0 * self.rs or lines.size < local_n1 * self.ls or (
                square and min(rows.size, lines.size) < side * side):
            raise ValueError("the row or line buffer is too small for this rank's part")
        self.comm, self.rows, self.lines = comm, rows, lines
        self.nx, self.ny, self.cx, self.cy = nx, ny, cx, cy
        self.ln0, self.width = local_n0, width
        self.local_n1, self.local_1_start = local_n1, local_1_start
        _cache_block_sizes(local_n0, 2 * self.nyc * sizeof(real_t), self.nrows)
        _cache_block_sizes(local_n1, cx * sizeof(fftw_complex), self.nlines)
        cdef unsigned flags = PLANNER_FLAGS[planner]
        cdef int n_y = <int>cy, n_x = <int>cx
        cdef int row_width = <int>(2 * self.nyc), ncomplex = <int>self.nyc
        cdef int nlines_row = <int>(side if square else self.nyl)
        cdef int nrows_map = <int>(side if square else nx)
        cdef int *nrows = self.nrows
        cdef int *nlines = self.nlines
        cdef MPI_Comm mcomm = comm.ob_mpi
        self.rows_data = <fftw_complex *>cnp.PyArray_DATA(rows)
        self.lines_data = <fftw_complex *>cnp.PyArray_DATA(lines)
        self.block = <real_t *>fftw_malloc(nrows[0] * row_width * sizeof(real_t))
        self.line = <fftw_complex *>fftw_malloc(max(nlines[0], 1) * n_x * sizeof(fftw_complex))
        if self.block == NULL or self.line == NULL:
            raise MemoryError("no memory for a block of rows")
        cdef bint ok = True
        with nogil:
            self.transpose_fwd = fftw_mpi_plan_many_transpose(
                nrows_map, nlines_row, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                <real_t *>self.rows_data, <real_t *>self.lines_data, mcomm, flags)
            self.transpose_bwd = fftw_mpi_plan_many_transpose(
                nlines_row, nrows_map, 2, FFTW_MPI_DEFAULT_BLOCK, FFTW_MPI_DEFAULT_BLOCK,
                <real_t *>self.lines_data, <real_t *>self.rows_data, mcomm, flags)
            for k in range(2):
                if nrows[k] > 0:
                    self.rows_fwd[k] = fftw_plan_many_dft_r2c(
                        1, &n_y, nrows[k], self.block, NULL, 1, row_width,
                        <fftw_complex *>self.block, NULL, 1, ncomplex, flags)
                    self.rows_bwd[k] = fftw_plan_many_dft_c2r(
                        1, &n_y, nrows[k], <fftw_complex *>self.block, NULL, 1, ncomplex,
                        self.block, NULL, 1, row_width, flags | FFTW_DESTROY_INPUT)
                    ok = ok and self.rows_fwd[k] != NULL and self.rows_bwd[k] != NULL
                if nlines[k] > 0:
                    self.lines_fwd[k] = fftw_plan_many_dft(
                        1, &n_x, nlines[k], self.line, NULL, 1, n_x, self.line, NULL, 1, n_x,
                        FFTW_FORWARD, flags)
                    self.lines_bwd[k] = fftw_plan_many_dft(
                        1, &n_x, nlines[k], self.line, NULL, 1, n_x, self.line, NULL, 1, n_x,
                        FFTW_BACKWARD, flags)
                    ok = ok and self.lines_fwd[k] != NULL and self.lines_bwd[k] != NULL
        if not ok or self.transpose_fwd == NULL or self.transpose_bwd == NULL:
            raise RuntimeError(f"FFTW-MPI could not plan the convolution of a {nx} x {ny} map "
                               f"on a {cx} x {cy} cell")

    @property
    def kernel_ky(self):
        """The ``ky`` (in the cell's ``cy``) of each row :meth:`set_kernel` takes here: this
        rank's lines, then the packed line's Nyquist ``cy / 2`` where that line is here."""
        ky = np.arange(self.local_1_start, self.local_1_start + self.local_n1)
        return np.append(ky, self.cy // 2) if self.nyquist_row >= 0 else ky

    def set_kernel(self, const double[:, ::1] kernel):
        """The kernel's transform at :attr:`kernel_ky`, ``(len(kernel_ky), cx // 2 + 1)``, kept
        by reference."""
        cdef Py_ssize_t nk = self.local_n1 + (1 if self.nyquist_row >= 0 else 0)
        if kernel.shape[0] != nk or kernel.shape[1] != self.cx // 2 + 1:
            raise ValueError(f"the kernel has shape {tuple(kernel.shape)[:2]}, the lines here "
                             f"need ({nk}, {self.cx // 2 + 1})")
        self.kernel = kernel
        self.kernel_data = &kernel[0, 0] if nk > 0 else NULL

    @property
    def row_stride(self):
        """Complex values from one row to the next in the rows buffer."""
        return self.rs

    @property
    def line_stride(self):
        """Complex values from one line to the next in the lines buffer."""
        return self.ls

    def transpose(self):
        """The rows buffer's ``(local_n0, padded_line_count(cy))`` values to the lines buffer,
        transposed (what a kernel's transform can be made with; for an even ``cy``, put
        each row's Nyquist value in the imaginary part of its first).  Collective."""
        self.half_made = False
        with nogil:
            fftw_execute(self.transpose_fwd)

    cdef bint _rows_sparse(self, const index_t[::1] pidx,
                           const real_t[::1] values) noexcept nogil:
        """Stage 1 for a field given at the flat indices ``pidx`` (rows of ``width``).

        Returns False if ``pidx`` is not sorted ascending inside this rank's rows and
        the map's columns (the rows are transformed all the same, so that the
        collective stage after it runs on every rank).
        """
        cdef Py_ssize_t ns = pidx.shape[0], w = self.width, w2 = 2 * self.nyc
        cdef Py_ssize_t i0 = 0, k = 0, m, base, end, p, r
        cdef int which
        cdef bint ok = True
        while i0 < self.ln0:
            m = min(<Py_ssize_t>self.nrows[0], self.ln0 - i0)
            which = 0 if m == self.nrows[0] else 1
            base = i0 * w
            end = base + m * w
            memset(self.block, 0, m * w2 * sizeof(real_t))
            while k < ns and pidx[k] < end:
                p = pidx[k] - base
                r = p // w
                if p < 0 or p - r * w >= self.ny or (k > 0 and pidx[k] <= pidx[k - 1]):
                    ok = False  # unsorted, negative, or off the map's columns
                    break
                self.block[r * w2 + p - r * w] = values[k]
                k += 1
            self._rows_forward(i0, m, which)
            i0 += self.nrows[0]
        return ok and k == ns

    cdef void _rows_dense(self, const real_t *field, Py_ssize_t stride) noexcept nogil:
        """Stage 1 for a whole field (this rank's rows, ``stride`` apart, the map's ``ny``
        columns first)."""
        cdef Py_ssize_t i0 = 0, m, r, ny = self.ny, w2 = 2 * self.nyc
        cdef int which
        while i0 < self.ln0:
            m = min(<Py_ssize_t>self.nrows[0], self.ln0 - i0)
            which = 0 if m == self.nrows[0] else 1
            for r in range(m):
                memcpy(self.block + r * w2, field + (i0 + r) * stride, ny * sizeof(real_t))
                memset(self.block + r * w2 + ny, 0, (w2 - ny) * sizeof(real_t))
            self._rows_forward(i0, m, which)
            i0 += self.nrows[0]

    cdef inline void _rows_forward(self, Py_ssize_t i0, Py_ssize_t m, int which) noexcept nogil:
        """The block's rows transformed along ``y`` in place, then to the rows buffer (each
        row's Nyquist value, if any, packed into its ``ky = 0`` value's imaginary part)."""
        cdef Py_ssize_t r, nyc = self.nyc, nyl = self.nyl, rs = self.rs
        cdef fftw_complex *c
        fftw_execute(self.rows_fwd[which])
        if not self.packed and rs == nyl:
            memcpy(self.rows_data + i0 * nyl, self.block, m * nyl * sizeof(fftw_complex))
            return
        for r in range(m):
            c = <fftw_complex *>self.block + r * nyc
            if self.packed:
                (<real_t *>c)[1] = (<real_t *>(c + nyc - 1))[0]
            memcpy(self.rows_data + (i0 + r) * rs, c, nyl * sizeof(fftw_complex))

    cdef double _lines_pass(self, bint form) noexcept nogil:
        """Stage 3 on the transposed rows in the lines buffer.

        With ``form``, only the forward transforms, the lines buffer left as it was,
        and returns this rank's part of ``sum_q k_q |p_q|^2`` over the cell's full
        plane (each ``ky`` line but ``0`` and an even ``cy``'s ``cy / 2`` stands for
        two), accumulated in double: by Parseval, ``(p, k * p)`` over the map, since
        ``p`` is zero off it.  Without, the transforms, the kernel and the inverse
        transforms, the map's part back to the lines buffer.
        """
        cdef Py_ssize_t j0 = 0, j, g, m, nx = self.nx, n = self.cx, ls = self.ls
        cdef int which
        cdef double total = 0.0, weight
        while j0 < self.local_n1:
            m = min(<Py_ssize_t>self.nlines[0], self.local_n1 - j0)
            which = 0 if m == self.nlines[0] else 1
            for j in range(m):
                memcpy(self.line + j * n, self.lines_data + (j0 + j) * ls,
                       nx * sizeof(fftw_complex))
                memset(self.line + j * n + nx, 0, (n - nx) * sizeof(fftw_complex))
            fftw_execute(self.lines_fwd[which])
            if form:
                for j in range(m):
                    g = self.local_1_start + j0 + j
                    if g == 0 and self.packed:
                        total = total + self._packed_line_form(<real_t *>(self.line + j * n))
                    else:
                        weight = 1.0 if g == 0 else 2.0
                        total = total + weight * self._line_form(
                            self.kernel_data + (j0 + j) * (n // 2 + 1),
                            <real_t *>(self.line + j * n))
                j0 += self.nlines[0]
                continue
            for j in range(m):
                g = self.local_1_start + j0 + j
                if g == 0 and self.packed:
                    self._multiply_packed_line(<real_t *>(self.line + j * n))
                else:
                    self._multiply_line(j0 + j, <real_t *>(self.line + j * n))
            fftw_execute(self.lines_bwd[which])
            for j in range(m):
                memcpy(self.lines_data + (j0 + j) * ls, self.line + j * n,
                       nx * sizeof(fftw_complex))
            j0 += self.nlines[0]
        return total

    cdef double _line_form(self, const double *kern, const real_t *s) noexcept nogil:
        """``sum_kx k |s|^2`` of a line (``cx`` values at ``s``), the kernel ``kern`` even in
        ``kx``."""
        cdef Py_ssize_t i, n = self.cx, half = self.cx // 2
        cdef double total = _norm2(s) * kern[0]
        for i in range(1, half + 1):   # kx and -kx together (an even cx's Nyquist once)
            total = total + kern[i] * (_norm2(s + 2 * i)
                                       + (_norm2(s + 2 * (n - i)) if n - i != i else 0.0))
        return total

    cdef double _packed_line_form(self, const real_t *s) noexcept nogil:
        """``sum_kx (ka |A|^2 + kb |B|^2)`` of the packed line's transform ``Z = A + i B``
        (``cx`` values at ``s``), ``ka`` its ``ky = 0`` kernel row, ``kb`` its Nyquist row."""
        cdef const double *ka = self.kernel_data
        cdef const double *kb = self.kernel_data + self.nyquist_row * (self.cx // 2 + 1)
        cdef Py_ssize_t k, m, n = self.cx
        cdef double ar, ai, br, bi, total = 0.0
        for k in range(n):
            m = (n - k) % n
            ar = 0.5 * (<double>s[2 * k] + s[2 * m])
            ai = 0.5 * (<double>s[2 * k + 1] - s[2 * m + 1])
            br = 0.5 * (<double>s[2 * k + 1] + s[2 * m + 1])
            bi = -0.5 * (<double>s[2 * k] - s[2 * m])
            total = total + ka[min(k, m)] * (ar * ar + ai * ai) + kb[min(k, m)] * (br * br + bi * bi)
        return total

    cdef void _multiply_packed_line(self, real_t *s) noexcept nogil:
        """The packed line's transform ``Z = A + i B`` to ``ka A + i kb B`` (whose inverse is
        the ``ky = 0`` and Nyquist parts' products packed as before): at ``kx`` and
        ``-kx``, ``((ka + kb) Z(kx) + (ka - kb) conj Z(-kx)) / 2``."""
        cdef const double *ka = self.kernel_data
        cdef const double *kb = self.kernel_data + self.nyquist_row * (self.cx // 2 + 1)
        cdef Py_ssize_t k, m, n = self.cx
        cdef double plus, minus, zr, zi, wr, wi
        for k in range(n // 2 + 1):
            m = (n - k) % n
            plus = 0.5 * (ka[k] + kb[k])
            minus = 0.5 * (ka[k] - kb[k])
            zr, zi, wr, wi = s[2 * k], s[2 * k + 1], s[2 * m], s[2 * m + 1]
            s[2 * k] = <real_t>(plus * zr + minus * wr)
            s[2 * k + 1] = <real_t>(plus * zi - minus * wi)
            if m != k:
                s[2 * m] = <real_t>(plus * wr + minus * zr)
                s[2 * m + 1] = <real_t>(plus * wi - minus * zi)

    cdef void _multiply_line(self, Py_ssize_t j, real_t *s) noexcept nogil:
        """Line ``j`` (``cx`` values at ``s``) times the kernel, even in ``kx``."""
        cdef const double *kern = self.kernel_data + j * (self.cx // 2 + 1)
        cdef Py_ssize_t i, n = self.cx, half = self.cx // 2
        cdef double f
        for i in range(half + 1):
            f = kern[i]
            s[2 * i] = <real_t>(s[2 * i] * f)
            s[2 * i + 1] = <real_t>(s[2 * i + 1] * f)
        for i in range(half + 1, n):
            f = kern[n - i]
            s[2 * i] = <real_t>(s[2 * i] * f)
            s[2 * i + 1] = <real_t>(s[2 * i + 1] * f)

    cdef void _back(self, real_t *out, Py_ssize_t stride, const index_t *pidx, Py_ssize_t ns,
                    real_t *gathered) noexcept nogil:
        """Stage 4: the transpose back and the rows' inverse along ``y``, the map's part to
        ``out`` (rows ``stride`` apart, their first ``ny`` columns), or with ``gathered``
        to the ``ns`` points ``pidx``."""
        cdef Py_ssize_t i0 = 0, m, r, k = 0, base, end, p
        cdef Py_ssize_t ny = self.ny, w = self.width, w2 = 2 * self.nyc
        cdef Py_ssize_t nyc = self.nyc, nyl = self.nyl, rs = self.rs
        cdef fftw_complex *c
        cdef int which
        fftw_execute(self.transpose_bwd)
        while i0 < self.ln0:
            m = min(<Py_ssize_t>self.nrows[0], self.ln0 - i0)
            which = 0 if m == self.nrows[0] else 1
            if not self.packed and rs == nyl:
                memcpy(self.block, self.rows_data + i0 * nyl, m * nyl * sizeof(fftw_complex))
            else:
                for r in range(m):
                    c = <fftw_complex *>self.block + r * nyc
                    memcpy(c, self.rows_data + (i0 + r) * rs, nyl * sizeof(fftw_complex))
                    if self.packed:   # the Nyquist value from the imaginary part of ky = 0
                        (<real_t *>(c + nyc - 1))[0] = (<real_t *>c)[1]
                        (<real_t *>(c + nyc - 1))[1] = 0
                        (<real_t *>c)[1] = 0
            fftw_execute(self.rows_bwd[which])
            if gathered == NULL:
                for r in range(m):
                    memcpy(out + (i0 + r) * stride, self.block + r * w2, ny * sizeof(real_t))
            else:
                base = i0 * w
                end = base + m * w
                while k < ns and pidx[k] < end:
                    p = pidx[k] - base
                    r = p // w
                    gathered[k] = self.block[r * w2 + p - r * w]
                    k += 1
            i0 += self.nrows[0]

    cdef Py_ssize_t _rows_of(self, const real_t[:, :] field, str name) except -1:
        """The row stride of ``field`` (in values), checked against this rank's part."""
        if field is None:
            raise ValueError(f"a whole {name} is needed (this rank's rows of the map)")
        if (field.shape[0] != self.ln0 or field.shape[1] < self.ny
                or field.strides[1] != sizeof(real_t) or field.strides[0] % sizeof(real_t)):
            raise ValueError(f"the {name} has shape {tuple(field.shape)[:2]}, this rank's "
                             f"part of the map is ({self.ln0}, {self.ny}) in rows of "
                             f"contiguous values")
        if self.kernel is None:
            raise RuntimeError("no kernel: set_kernel first")
        return field.strides[0] // sizeof(real_t)

    cdef int _check_sparse(self, const index_t[::1] pidx, const real_t[::1] values,
                           real_t[::1] gathered) except -1:
        if values.shape[0] != pidx.shape[0] or (gathered is not None
                                                and gathered.shape[0] != pidx.shape[0]):
            raise ValueError("pidx, values and gathered must have the same length")
        if self.kernel is None:
            raise RuntimeError("no kernel: set_kernel first")
        return 0

    def apply(self, const real_t[:, :] field, real_t[:, :] out):
        """``out <- k * field`` (this rank's rows; ``out`` may be ``field``).  Collective."""
        cdef Py_ssize_t fs = self._rows_of(field, "field"), os = self._rows_of(out, "out")
        self.half_made = False
        with nogil:
            self._rows_dense(&field[0, 0], fs)
            fftw_execute(self.transpose_fwd)
            self._lines_pass(False)
            self._back(&out[0, 0], os, NULL, 0, NULL)

    def apply_sparse(self, const index_t[::1] pidx, const real_t[::1] values,
                     real_t[:, :] out=None, real_t[::1] gathered=None):
        """``k * x`` of a field zero but at the sorted flat indices ``pidx`` (rows of
        ``width``): to ``out``, or with ``gathered`` only at ``pidx``.  Collective."""
        self._check_sparse(pidx, values, gathered)
        cdef Py_ssize_t os = 0, ns = pidx.shape[0]
        cdef bint ok
        cdef real_t *g = NULL
        cdef real_t *o = NULL
        cdef const index_t *ip = NULL
        if gathered is None:
            os = self._rows_of(out, "out")
            o = &out[0, 0]
        elif ns > 0:
            g, ip = &gathered[0], &pidx[0]
        self.half_made = False
        with nogil:
            ok = self._rows_sparse(pidx, values)
            fftw_execute(self.transpose_fwd)
            self._lines_pass(False)
            if o != NULL or g != NULL:
                self._back(o, os, ip, ns, g)
            else:
                fftw_execute(self.transpose_bwd)   # collective: every rank takes part
        if not ok:
            raise ValueError("pidx must be sorted ascending, inside this rank's rows and the "
                             "map's columns")

    def begin_sparse(self, const index_t[::1] pidx, const real_t[::1] values):
        """The forward half of :meth:`apply_sparse`: this rank's part of ``(x, k * x)`` (by
        Parseval); :meth:`end` gives the field.  Collective."""
        self._check_sparse(pidx, values, None)
        cdef bint ok
        cdef double total
        with nogil:
            ok = self._rows_sparse(pidx, values)
            fftw_execute(self.transpose_fwd)
            total = self._lines_pass(True)
        self.half_made = ok
        if not ok:
            raise ValueError("pidx must be sorted ascending, inside this rank's rows and the "
                             "map's columns")
        return total

    def begin(self, const real_t[:, :] field):
        """:meth:`begin_sparse` of a whole field."""
        cdef Py_ssize_t fs = self._rows_of(field, "field")
        cdef double total
        with nogil:
            self._rows_dense(&field[0, 0], fs)
            fftw_execute(self.transpose_fwd)
            total = self._lines_pass(True)
        self.half_made = True
        return total

    def end(self, real_t[:, :] out):
        """The rest after a begin: ``k * x`` to ``out``.  Collective."""
        cdef Py_ssize_t os = self._rows_of(out, "out")
        if not self.half_made:
            raise RuntimeError("no half-made convolution to finish: a begin was not the last "
                               "use of these plans")
        self.half_made = False
        with nogil:
            self._lines_pass(False)
            self._back(&out[0, 0], os, NULL, 0, NULL)

    def __dealloc__(self):
        _destroy(&self.transpose_fwd)
        _destroy(&self.transpose_bwd)
        for k in range(2):
            _destroy(&self.rows_fwd[k])
            _destroy(&self.rows_bwd[k])
            _destroy(&self.lines_fwd[k])
            _destroy(&self.lines_bwd[k])
        if self.block != NULL:
            fftw_free(self.block)
        if self.line != NULL:
            fftw_free(self.line)


def weighted_power(const complex_t[:, ::1] c, const double[::1] qx,
                   const double[::1] qy, const double[::1] wrow, int power):
    """``sum_j wrow[j] sum_i |c[j, i]|**2 |q|**power`` over this rank's Fourier slab.

    ``wrow`` holds the Hermitian multiplicity of each half-plane row (1 for
    ``ky = 0`` and the Nyquist row of an even ``ny``, 2 otherwise), so that the
    sum over the half plane equals the sum over the full plane.  Terms with
    ``|q| = 0`` contribute only when ``power == 0``.
    """
    cdef Py_ssize_t i, j, nj = c.shape[0], ni = c.shape[1]
    cdef double q2, a, rowsum, total = 0.0, qyj, re, im
    if power not in (-1, 0, 1, 2, 4):
        raise ValueError(f"power={power} is not one of -1, 0, 1, 2, 4")
    if qx.shape[0] != ni or qy.shape[0] != nj or wrow.shape[0] != nj:
        raise ValueError("wavevector or weight arrays do not match the Fourier slab")
    with nogil:
        for j in range(nj):
            qyj = qy[j] * qy[j]
            rowsum = 0.0
            for i in range(ni):
                re = c[j, i].real  # in double whatever the slab's precision
                im = c[j, i].imag
                a = re * re + im * im
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
