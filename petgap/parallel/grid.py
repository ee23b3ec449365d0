"""The periodic grid, its slab decomposition and its distributed FFT.

One :class:`Grid` owns the communicator and everything that depends on how the
field is split between ranks; every other module asks it for local slices,
local wavevectors and transforms, and never reaches for ``COMM_WORLD``.

Conventions
-----------
* Global real-space arrays have shape ``(nx, ny)``, axis 0 along x.  Axis 0 is
  distributed in contiguous blocks of rows (FFTW-MPI slabs); a rank holds rows
  ``x_slice`` as a C-contiguous ``(nx_local, ny)`` array.
* Pixel sizes ``dx = Lx / nx`` and ``dy = Ly / ny``; a pixel has area
  ``dx * dy``; positions are ``x = i dx``, ``y = j dy``.
* Forward DFT unnormalised, ``f_q = sum_x f(x) exp(-i q.x)``; the inverse divides
  by ``nx * ny``.  ``q = 2 pi (m / Lx, n / Ly)`` with ``m`` wrapped into
  ``(-nx/2, nx/2]``.
* Fourier arrays use FFTW's transposed r2c layout: shape ``(ny // 2 + 1, nx)``,
  i.e. half plane ``n = 0 .. ny // 2`` along axis 0 (distributed, rows
  ``ky_slice``) and all ``m`` along axis 1.  Half-plane rows other than ``n = 0``
  and (``ny`` even) ``n = ny / 2`` stand for two modes, ``q`` and ``-q``;
  :attr:`Grid.hermitian_weight` holds that multiplicity.
"""
import hashlib
import os
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from petgap.parallel import _fftw_mpi, _fftw_mpi_single
from petgap.parallel.log import get_logger

#: Where FFTW wisdom is cached between runs (override with PETGAP_WISDOM_DIR).
WISDOM_DIR_ENV = "PETGAP_WISDOM_DIR"
#: The binding of each precision (the same source, ``_fftw_body.pxi``, on FFTW's double
#: and single libraries).
BINDINGS = {"double": _fftw_mpi, "single": _fftw_mpi_single}
#: How much larger than its own part a padded convolution's buffer may grow for square
#: transposes on one rank (:meth:`Grid.zero_padded_plans`): a ``2048 x 1536`` map's is
#: ``4 / 3`` of it.
SQUARE_GROWTH = 1.5
#: Wisdom files this process imported as rank 0 of a communicator: path -> the
#: file's (modification time, size) and the world ranks of that communicator.
#: FFTW keeps imported wisdom for the life of the process, so reading the same
#: file again for the same ranks (each level of a coarse start makes a grid)
#: only costs the parse.
_IMPORTED_WISDOM = {}


def weighted_power(c, qx, qy, wrow, power):
    """``sum_j wrow[j] sum_i |c[j, i]|^2 |q|^power`` over a Fourier slab of either precision.

    :func:`petgap.parallel._fftw_mpi.weighted_power` (accumulated in double) for a
    ``complex128`` or ``complex64`` slab.
    """
    binding = _fftw_mpi_single if c.dtype == np.complex64 else _fftw_mpi
    return binding.weighted_power(c, qx, qy, wrow, power)


def hermitian_weight(rows, ny):
    """The full-plane modes each half-plane row ``rows`` of an r2c transform along ``ny``
    points stands for: 1 for ``ky = 0`` and an even ``ny``'s Nyquist row, else 2."""
    return np.where((rows == 0) | ((ny % 2 == 0) & (rows == ny // 2)), 1.0, 2.0)


def row_blocks(nrows, points=1 << 16, ncols=None):
    """Row slices of a slab of about ``points`` values each (rows of ``ncols``, 1024 if
    None), to bound the temporaries of a pass over it."""
    step = max(1, points // max(ncols or 1024, 1))
    return [slice(i, min(i + step, nrows)) for i in range(0, nrows, step)]


class DecompositionError(ValueError):
    """The grid cannot be split into non-empty slabs on this communicator."""


def _aligned_empty(count, dtype, alignment=64):
    """An uninitialised 1D array of ``count`` items whose data is ``alignment``-aligned.

    FFTW's SIMD codelets want aligned data; NumPy only promises 16 bytes.
    """
    dtype = np.dtype(dtype)
    raw = np.empty(count * dtype.itemsize + alignment, dtype=np.uint8)
    offset = (-raw.ctypes.data) % alignment
    return raw[offset:offset + count * dtype.itemsize].view(dtype)


class Grid:
    """A periodic ``nx x ny`` grid of physical size ``Lx x Ly`` split into slabs.

    Parameters
    ----------
    shape : (int, int)
        Number of pixels ``(nx, ny)``; both at least 1.
    size : (float, float), optional
        Physical size ``(Lx, Ly)``.  Defaults to ``shape``, i.e. unit pixels.
    comm : mpi4py.MPI.Comm, optional
        Communicator of the decomposition (default ``MPI.COMM_WORLD``).
    planner : {"estimate", "measure", "patient", "exhaustive"}
        FFTW planner effort.  ``"measure"`` (default) times candidate plans once;
        the resulting wisdom is cached on disk (see :meth:`wisdom_path`), so later
        runs on the same grid and rank count plan instantly.
    wisdom : bool
        Read and write the on-disk wisdom cache.
    precision : {"double", "single"}
        Element type of the FFT buffers and of the fields made for this grid
        (:attr:`dtype`, :attr:`complex_dtype`): 64- or 32-bit.  Wavevectors,
        multipliers and the reductions of :meth:`sum`, :meth:`mean` and
        :meth:`fourier_sum` are double in both.

    Raises
    ------
    DecompositionError
        On every rank, if some rank would receive no real-space row or no
        Fourier row (FFTW-MPI distributes rows in blocks of ``ceil(n / P)``).
    """

    def __init__(self, shape, size=None, comm=None, planner="measure", wisdom=True,
                 precision="double", _buffers_of=None):
        if precision not in BINDINGS:
            raise ValueError(f"precision = {precision!r} is not allowed: need one of "
                             f"{', '.join(map(repr, BINDINGS))}")
        #: ``"double"`` or ``"single"``: see the class docstring.
        self.precision = precision
        binding = BINDINGS[precision]
        self._binding = binding
        #: dtype of real fields on this grid, and of the Fourier buffer.
        self.dtype = np.dtype(binding.REAL_DTYPE)
        self.complex_dtype = np.dtype(binding.COMPLEX_DTYPE)
        self.comm = MPI.COMM_WORLD if comm is None else comm
        #: FFTW planner effort and wisdom cache use, for grids derived from this one.
        self.planner, self.wisdom = planner, wisdom
        nx, ny = _check_shape(shape)
        lx, ly = (float(nx), float(ny)) if size is None else _check_size(size)
        self.nx, self.ny, self.Lx, self.Ly = nx, ny, lx, ly
        self.dx, self.dy = lx / nx, ly / ny
        self.nky = ny // 2 + 1

        alloc, ln0, l0s, ln1, l1s = _fftw_mpi.local_size_transposed(self.comm, nx, ny)
        self._check_decomposition()
        self.x_slice = slice(l0s, l0s + ln0)
        self.ky_slice = slice(l1s, l1s + ln1)
        self.local_shape = (ln0, ny)
        self.fourier_local_shape = (ln1, nx)

        # FFT buffers: the padded real slab and the transposed Fourier slab (a single-precision
        # alias's are the first halves of its double grid's: single_precision_alias)
        if _buffers_of is None:
            self._real_storage = _aligned_empty(2 * alloc, self.dtype)
            self._fourier_storage = _aligned_empty(alloc, self.complex_dtype)
        else:
            self._real_storage = _buffers_of._real_storage.view(self.dtype)[:2 * alloc]
            self._fourier_storage = _buffers_of._fourier_storage.view(self.complex_dtype)[:alloc]
        self._alias = None
        self._parent = _buffers_of   # the double grid whose buffers an alias's are
        #: The real-space FFT buffer in FFTW's padded r2c layout, ``(nx_local,
        #: 2 (ny // 2 + 1))``: kernels that fill or read the buffer in a pass of
        #: their own, and the flat indices of :meth:`convolve_qpower_sparse`, use it.
        self.padded = self._real_storage[:ln0 * 2 * self.nky].reshape(ln0, 2 * self.nky)
        #: Real-space FFT buffer, ``(nx_local, ny)`` view of the padded slab.
        self.real = self.padded[:, :ny]
        #: Fourier-space FFT buffer, ``(nky_local, nx)``.
        self.fourier = self._fourier_storage[:ln1 * nx].reshape(ln1, nx)

        started = time.perf_counter()
        if wisdom:
            self._load_wisdom()
        self._plans = binding.SlabPlans(self.comm, nx, ny, self._real_storage,
                                        self._fourier_storage, planner)
        self._convolution = binding.ConvolutionPlans(self.comm, nx, ny, ln0, ln1,
                                                     self._real_storage,
                                                     self._fourier_storage, planner)
        if wisdom and planner != "estimate":
            self._save_wisdom()
        #: Seconds spent planning the transforms (with the wisdom cache read and written):
        #: large the first time a size is planned with ``measure``, small once it is cached.
        self.planning_time = time.perf_counter() - started

        m = np.fft.fftfreq(nx, d=1.0 / nx)
        if nx % 2 == 0:
            m[nx // 2] = nx // 2  # Nyquist counted as +nx/2: |q| is what matters
        #: Wavevector components along x for the columns of a Fourier slab.
        self.qx = 2 * np.pi * m / lx
        #: Wavevector components along y for the local Fourier rows.
        self.qy = 2 * np.pi * np.arange(l1s, l1s + ln1, dtype=float) / ly
        #: Number of full-plane modes each local half-plane row stands for.
        self.hermitian_weight = hermitian_weight(np.arange(l1s, l1s + ln1), ny)

    # ------------------------------------------------------------------ sizes
    @property
    def shape(self):
        """Global shape ``(nx, ny)``."""
        return (self.nx, self.ny)

    @property
    def npoints(self):
        """Number of grid points ``nx * ny``."""
        return self.nx * self.ny

    @property
    def pixel_area(self):
        """Area of one pixel ``dx * dy``."""
        return self.dx * self.dy

    @property
    def area(self):
        """Nominal area ``A0 = Lx * Ly``."""
        return self.Lx * self.Ly

    def q_magnitude(self):
        """``|q|`` on this rank's Fourier slab, shape ``fourier_local_shape``."""
        return np.hypot(self.qx[None, :], self.qy[:, None])

    def local_positions(self):
        """``(x, y)`` coordinates of this rank's real-space points, each ``local_shape``."""
        i = np.arange(self.x_slice.start, self.x_slice.stop)
        j = np.arange(self.ny)
        return np.meshgrid(i * self.dx, j * self.dy, indexing="ij")

    # ------------------------------------------------------------ transforms
    def forward(self, field=None):
        """Forward FFT of ``field`` (or of :attr:`real` as it is) into :attr:`fourier`.

        Parameters
        ----------
        field : ndarray, shape ``local_shape``, optional
            Copied into the real buffer first.

        Returns
        -------
        ndarray
            :attr:`fourier`, overwritten with ``f_q = sum_x f(x) exp(-i q.x)``.
        """
        if field is not None:
            np.copyto(self.real, field)
        self._spoil()
        self._plans.forward()
        return self.fourier

    def convolve_qpower(self, scale, power):
        """``real <- F^{-1}[scale |q|^power F real]`` in place, the q = 0 mode zeroed.

        The Fourier multiplier of the elastic operators (``power`` +1 for the
        stiffness, -1 for the compliance), fused with the transforms so that the
        Fourier slab is swept once (see :class:`petgap.parallel._fftw_mpi.ConvolutionPlans`).
        ``F^{-1}`` is unnormalised, as in :meth:`backward`: ``scale`` must carry
        the ``1 / (nx ny)``.  :attr:`fourier` is used as scratch.

        Returns
        -------
        ndarray
            :attr:`real`.
        """
        self._spoil()
        self._convolution.apply(self.qx, self.qy, scale, power)
        return self.real

    def convolve_qpower_sparse(self, pidx, values, scale, power, out=None, gathered=None):
        """:meth:`convolve_qpower` of a field that is zero except at the points ``pidx``.

        ``pidx`` are sorted flat indices into the padded real slab (shape
        ``(nx_local, 2 (ny // 2 + 1))``) and ``values`` the field there.  The
        result goes to the padded real buffer, or to ``out`` (an array from
        :meth:`aligned_padded`), or, with ``gathered``, only its values at
        ``pidx`` are written there (both FFT buffers serve as scratch).  No
        slab-sized pass is spent on assembling the input or on writing a
        gathered output (see
        :meth:`petgap.parallel._fftw_mpi.ConvolutionPlans.apply_sparse`).
        """
        for name, a in (("values", values), ("out", out), ("gathered", gathered)):
            if a is not None and a.dtype != self.dtype:
                raise TypeError(f"convolve_qpower_sparse: {name} is {a.dtype}, the grid's "
                                f"fields are {self.dtype} ({self.precision} precision)")
        self._spoil()
        self._convolution.apply_sparse(pidx, values, self.qx, self.qy, scale, power, out,
                                       gathered)

    def convolve_qpower_sparse_begin(self, pidx, values, scale, power):
        """The first half of :meth:`convolve_qpower_sparse`, with the field's form on the way.

        Transforms the field (``values`` at the padded-slab indices ``pidx``,
        zero elsewhere) forward and multiplies it by ``f = scale |q|^power``,
        and returns this rank's part of ``sum_q f |F x|^2`` (accumulated in
        double): summed over the ranks, the form ``(x, F^{-1} f F x)``, by
        Parseval.  :meth:`convolve_qpower_end` then completes the convolution;
        any transform of this grid or of one sharing its buffers
        (:meth:`single_precision_alias`) before that discards the half-made
        field, and the end then raises.  For a step length that needs only
        the form, unless the step shows that the field is needed too.
        """
        if values.dtype != self.dtype:
            raise TypeError(f"convolve_qpower_sparse_begin: values are {values.dtype}, the "
                            f"grid's fields are {self.dtype} ({self.precision} precision)")
        self._spoil()
        return self._convolution.begin_sparse(pidx, values, self.qx, self.qy,
                                              self.hermitian_weight, scale, power)

    def convolve_qpower_begin(self, scale, power):
        """:meth:`convolve_qpower_sparse_begin` of the field in :attr:`real` (the first half
        of :meth:`convolve_qpower`): returns this rank's part of its form."""
        self._spoil()
        return self._convolution.begin(self.qx, self.qy, self.hermitian_weight, scale, power)

    def convolve_qpower_end(self, out=None):
        """Complete the convolution a begin (:meth:`convolve_qpower_sparse_begin`,
        :meth:`convolve_qpower_begin`) started: the result to the padded real buffer, or
        to ``out`` (from :meth:`aligned_padded`)."""
        if out is not None and out.dtype != self.dtype:
            raise TypeError(f"convolve_qpower_end: out is {out.dtype}, the grid's fields are "
                            f"{self.dtype} ({self.precision} precision)")
        self._convolution.end(out)

    def zero_padded_plans(self, cell=None, planner=None, precision=None, buffers=None,
                          square=None):
        """Plans of a linear convolution over this grid's map by zero padding to a larger cell.

        ``cell``: the periodic cell's shape, ``(2 nx, 2 ny)`` by default (Hockney's).

        :class:`petgap.parallel._fftw_mpi.PaddedConvolutionPlans` in this grid's precision,
        on a buffer of their own (the map's rows transformed along ``y``, transposed in
        place: half the padded cell's, and faster than two) and this grid's rows; fields
        and flat indices are in rows of the padded slab's width, like :attr:`padded`'s.
        The caller gives the kernel (``set_kernel``).  Collective; planned with this
        grid's effort and wisdom unless ``planner`` says otherwise; ``precision`` other
        than the grid's (a double kernel for single plans) goes without wisdom.
        ``buffers``: the ``(rows, lines)`` of other such plans of a cell at least as large,
        to share (each use of either plans then overwrites the other's; planning too).

        ``square``: whether the transposes move the ``nx`` rows of ``nl`` Fourier values as
        a square ``max(nx, nl)`` matrix (one rank only).  FFTW transposes a square matrix
        in place by swapping pairs, a non-square one by following cycles through the
        whole buffer, several times slower per value; the padding's rows and lines are
        moved but never transformed.  By default square where it pays for itself: on
        one rank, for a non-square transpose, when the square fits in the shared
        ``buffers`` or costs at most :data:`SQUARE_GROWTH` times the buffer's own size.
        """
        planner = self.planner if planner is None else planner
        precision = self.precision if precision is None else precision
        binding = BINDINGS[precision]
        cx, cy = (2 * self.nx, 2 * self.ny) if cell is None else cell
        lines_count = _fftw_mpi.padded_line_count(cy)
        alloc, ln0, l0s, ln1, l1s = _fftw_mpi.local_size_lines(self.comm, self.nx, lines_count)
        if (ln0, l0s) != (self.local_shape[0], self.x_slice.start):
            raise DecompositionError(f"the padded rows of a {self.nx} x {self.ny} map are split "
                                     f"unlike the map's ({ln0} from {l0s} here)")
        side = max(self.nx, lines_count)
        if square is None:   # the rule in this method's docstring
            room = alloc * SQUARE_GROWTH if buffers is None else min(b.size for b in buffers)
            square = self.comm.size == 1 and self.nx != lines_count and side * side <= room
        if square:
            alloc = max(alloc, side * side)
        if buffers is None:
            rows = lines = _aligned_empty(alloc, binding.COMPLEX_DTYPE)
        else:
            rows, lines = buffers   # the plans check that they are large enough
        wisdom = self.wisdom and planner != "estimate" and precision == self.precision
        if wisdom:
            self._load_wisdom()
        plans = binding.PaddedConvolutionPlans(self.comm, self.nx, self.ny, cx, cy, ln0, ln1,
                                               l1s, self.padded.shape[1], rows, lines, planner,
                                               bool(square))
        if wisdom:
            self._save_wisdom()
        return plans

    def _spoil(self):
        """A transform is about to use the FFT buffers: a half-made convolution in them (this
        grid's, or that of the other grid on the same buffers) is lost."""
        for grid in (self, self._alias, self._parent):
            if grid is not None:
                grid._convolution.half_made = False

    def aligned_padded(self):
        """A zeroed array shaped and aligned like the padded real FFT buffer.

        For fields a solver keeps in the padded layout so that transforms can
        write them directly (``out`` of :meth:`convolve_qpower_sparse`).
        """
        padded = self.padded
        array = _aligned_empty(padded.size, self.dtype).reshape(padded.shape)
        array[...] = 0.0
        return array

    def scratch(self, padded=None):
        """A contiguous field of this rank's slab, ``local_shape``, on a padded buffer's memory.

        ``padded``: an array shaped like :attr:`padded` (e.g. from
        :meth:`aligned_padded`); by default the real FFT buffer itself, for a
        field that is read before the next transform overwrites it (a prolonged
        start the solver reads once into its contact set).  Why borrow rather
        than allocate: the buffer's pages are mapped anyway, and a fresh slab's
        first touch is not free (on a virtual machine the host maps each new page,
        far dearer than a write to a page already mapped).
        """
        padded = self.padded if padded is None else padded
        return padded.reshape(-1)[:self.local_shape[0] * self.ny].reshape(self.local_shape)

    def single_precision_alias(self):
        """This grid in single precision, its transforms working in this grid's FFT buffers.

        Same shape, size, communicator and decomposition; its :attr:`padded`,
        :attr:`real` and :attr:`fourier` are 32-bit views of the first half of
        this grid's bytes (so using either grid's buffers overwrites the
        other's).  For a solver that needs some transforms only roughly -- a
        preconditioner, a step length -- at the cost of a single-precision
        transform and with no slab of its own.  Made on the first call and kept
        (a single-precision grid is its own alias).  Collective the first time:
        planning may overwrite both grids' buffers, so call it when they hold
        nothing needed.
        """
        if self.precision == "single":
            return self
        if self._alias is None:
            self._alias = Grid(self.shape, size=(self.Lx, self.Ly), comm=self.comm,
                               planner=self.planner, wisdom=self.wisdom, precision="single",
                               _buffers_of=self)
            self._spoil()   # planning may have overwritten the buffers
            # what a first run of this size spends planning it, in the log
            get_logger("grid").info("single-precision alias of the %dx%d grid: FFTs planned in "
                                    "%.2f s (%s)", self.nx, self.ny, self._alias.planning_time,
                                    self.planner)
        return self._alias

    def backward(self):
        """Inverse FFT of :attr:`fourier` into :attr:`real`, *without* the ``1/(nx ny)``.

        :attr:`fourier` is destroyed.  Returns :attr:`real`.
        """
        self._spoil()
        self._plans.backward()
        return self.real

    # ------------------------------------------------------------ reductions
    def sum(self, local):
        """Global sum of a local array over all ranks."""
        local = np.asarray(local)
        # single-precision fields are summed in double
        dtype = np.float64 if local.dtype == np.float32 else None
        return self.comm.allreduce(float(np.sum(local, dtype=dtype)), op=MPI.SUM)

    def mean(self, local):
        """Global mean over the real-space grid of a ``local_shape`` array."""
        return self.sum(local) / self.npoints

    def fourier_sum(self, local_terms):
        """Full-plane sum of a half-plane quantity (rows weighted by multiplicity)."""
        return self.comm.allreduce(
            float(np.sum(self.hermitian_weight[:, None] * local_terms)),   # float64 weights
            op=MPI.SUM)

    def gather(self, local, root=0):
        """Assemble the global ``(nx, ny)`` array on ``root`` (None elsewhere).

        For tests and small grids only: it defeats the point of a slab.
        """
        parts = self.comm.gather(np.ascontiguousarray(local), root=root)
        return np.concatenate(parts, axis=0) if self.comm.rank == root else None

    def local_part(self, global_array):
        """This rank's rows of a global ``(nx, ny)`` array (a view)."""
        global_array = np.asarray(global_array)
        if global_array.shape != self.shape:
            raise ValueError(f"global array has shape {global_array.shape}, grid is {self.shape}")
        return global_array[self.x_slice]

    # ---------------------------------------------------------------- wisdom
    def wisdom_path(self):
        """File caching FFTW wisdom for this machine and rank count."""
        root = Path(os.environ.get(WISDOM_DIR_ENV) or Path.home() / ".cache" / "petgap")
        host = hashlib.sha1(os.uname().nodename.encode()).hexdigest()[:8]
        single = "-single" if self.precision == "single" else ""   # FFTW keeps them apart
        return root / f"fftw-wisdom-{host}-np{self.comm.size}{single}.txt"

    def _load_wisdom(self):
        # rank 0 decides alone whether to read: the import is collective either way
        text = path = key = None
        if self.comm.rank == 0:
            path = self.wisdom_path()
            try:
                stat = path.stat()
                key = (stat.st_mtime_ns, stat.st_size, self._world_ranks())
                if _IMPORTED_WISDOM.get(path) != key:
                    text = path.read_text()
            except OSError:
                text = None
        if self._binding.import_wisdom(self.comm, text) and key is not None:
            _IMPORTED_WISDOM[path] = key

    def _world_ranks(self):
        group, world = self.comm.Get_group(), MPI.COMM_WORLD.Get_group()
        try:
            return tuple(MPI.Group.Translate_ranks(group, range(self.comm.size), world))
        finally:
            group.Free()
            world.Free()

    def _save_wisdom(self):
        text = self._binding.export_wisdom(self.comm)
        if self.comm.rank == 0 and text:
            path = self.wisdom_path()
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                tmp.write_text(text)
                tmp.replace(path)  # atomic: concurrent runs never see half a file
            except OSError:
                pass  # a read-only home only costs planning time next run

    def _check_decomposition(self):
        """Raise the same DecompositionError on every rank if any slab is empty."""
        check_decomposition(self.comm, self.nx, self.ny)

    def __repr__(self):
        return (f"Grid(shape=({self.nx}, {self.ny}), size=({self.Lx:g}, {self.Ly:g}), "
                f"ranks={self.comm.size}, rows={self.x_slice.start}:{self.x_slice.stop})")


def check_decomposition(comm, nx, ny):
    """Raise the same DecompositionError on every rank of ``comm`` if FFTW-MPI would give
    some rank no real-space row or no Fourier row of an ``nx x ny`` grid (collective;
    nothing is allocated)."""
    sizes = comm.allgather(_fftw_mpi.local_size_transposed(comm, nx, ny)[1:])
    rows = [s[0] for s in sizes]
    krows = [s[2] for s in sizes]
    if min(rows) == 0 or min(krows) == 0:
        raise DecompositionError(
            f"a {nx} x {ny} grid cannot be split over {comm.size} ranks: "
            f"FFTW-MPI gives real-space rows {rows} (of nx = {nx}) and Fourier rows "
            f"{krows} (of ny // 2 + 1 = {ny // 2 + 1}) per rank, and every rank needs at least "
            f"one of each; use fewer ranks, or a grid with nx >= ranks and ny // 2 + 1 >= ranks "
            f"that splits into non-empty blocks of ceil(n / ranks) rows")


def _check_shape(shape):
    try:
        nx, ny = (int(n) for n in shape)
        if (nx, ny) != tuple(shape):
            raise TypeError
    except (TypeError, ValueError):
        raise ValueError(f"grid shape must be two integers (nx, ny), got {shape!r}") from None
    if nx < 1 or ny < 1:
        raise ValueError(f"grid shape must be positive, got ({nx}, {ny})")
    return nx, ny


def _check_size(size):
    try:
        lx, ly = (float(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"grid size must be two numbers (Lx, Ly), got {size!r}") from None
    if not (np.isfinite(lx) and np.isfinite(ly) and lx > 0 and ly > 0):
        raise ValueError(f"grid size must be positive and finite, got ({lx}, {ly})")
    return lx, ly
