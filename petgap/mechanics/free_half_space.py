"""The elastic half-space without periodic images: a finite map on an infinite body.

A measured map or an indenter is a finite patch of surface pressed onto a body
that extends beyond it; solved as periodic, its images load it too, and a map
whose opposite edges do not match gets a cliff at the seam.  Here the body is
the infinite half-space and the pressure is zero outside the map.

Conventions (those of :mod:`petgap.mechanics.half_space`)
--------------------------------------------------------
* ``u`` is the normal displacement, positive away from the rigid surface, ``p``
  the pressure, positive in compression, ``E*`` the contact modulus (paper
  Eq. 4, doi:10.1007/s11249-021-01454-6).
* The pressure is uniform over each ``dx x dy`` pixel and the displacement is
  taken at pixel centres.  A unit pressure on the pixel centred at the origin
  displaces the point ``(x, y)`` by (Love 1929; Johnson 1985, Eq. 3.25)::

      C(x, y) = 1 / (pi E*)  [ F(x + dx/2, y + dy/2) - F(x - dx/2, y + dy/2)
                             - F(x + dx/2, y - dy/2) + F(x - dx/2, y - dy/2) ],
      F(s, t) = s asinh(t / |s|) + t asinh(s / |t|),

  the integral of the Boussinesq point-load solution ``1 / (pi E* r)`` over the
  pixel (:func:`influence_coefficients`).  Unlike the periodic operator this
  one has a finite stiffness for the mean: a uniform pressure sinks the map.
* ``u = C * p`` is a linear (not circular) convolution over the ``nx x ny``
  map, evaluated exactly by zero padding (Hockney 1970): ``p`` is embedded in a
  ``2 nx x 2 ny`` periodic cell whose kernel holds ``C`` at every offset the
  map can see, ``|i| < nx`` and ``|j| < ny``; then a forward and an inverse
  transform of the padded cell, and a multiplication by the kernel's transform
  (real: ``C`` is even in ``x`` and ``y``), give ``u`` on the map.
* The kernel's transform is a 2D DCT-I of ``C`` at the offsets ``0 .. nx`` and
  ``0 .. ny`` (the transform of an even sequence), unnormalised, the inverse's
  ``1 / (4 nx ny)`` folded in (:func:`padded_symbol`).

Cost: the padded transform is pruned
(:class:`petgap.parallel._fftw_mpi.PaddedConvolutionPlans`): the ``y``
transforms, the transposes and the row passes see the map's ``nx`` rows only,
in the map's own slab decomposition (no rows move to another), and only the
``x`` transforms, in cache, span the cell.  ``(p, C p)`` comes from the forward
half by Parseval (``p`` is zero outside the map), so that a conjugate-gradient
step length pays for the inverse half only when it needs the field
(:meth:`FreeHalfSpace.begin_sparse`).

The stiffness ``K = C^{-1}`` has no such fast form.  The pressure solver needs
``K`` only as its preconditioner (an approximate inverse of ``C`` on the
contact set), and there the half-space's stiffness ``E* |q| / 2`` on the map
alone serves: restricted to the contact set, ``C`` and the compliance of that
stiffness differ by a smooth field and by the discretisation, which leaves the
edges -- the part that needs preconditioning -- alike.  Applied on the map's
own periodic grid it would couple the map's opposite edges as neighbours (its
kernel is short, ``1 / r^3``, but nearest neighbours across the seam are what
it couples most), so it is applied on a cell :data:`MARGIN` pixels larger than
the map, by the same pruned plans: zeros beyond the map's far edges, as the
free body has no material pressed there.  So ``apply_sparse(...,
inverse=False)`` and ``apply_in_buffer(inverse=False)`` apply that stiffness,
and :meth:`FreeHalfSpace.pressure` refuses; solvers that need the exact ``K``
(the gap formulation, TAO's bound-constrained methods) do not run on a free
map itself (:func:`petgap.solvers.dispatch.solve` sends the gap solvers to its
padded cell).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.grid import Grid, row_blocks
from petgap.parallel.log import OPERATOR_EVENT, OPERATOR_HALF_EVENT, event


#: Pixels of zeros beyond the map's far edges on the cell of the preconditioning stiffness
#: (:func:`margin_cell`): its kernel falls like ``1 / r^3``, so the map's opposite edges,
#: neighbours on the map's own periodic grid, barely couple across this margin.
MARGIN = 16


def influence_coefficients(x, y, dx, dy, contact_modulus=1.0):
    """Displacement at ``(x, y)`` under a unit pressure on the ``dx x dy`` pixel at the origin.

    Love's solution for a uniformly loaded rectangle (module docstring): the
    Boussinesq kernel ``1 / (pi E* r)`` integrated over the pixel.  At the
    pixel's own centre it is ``(2 / (pi E*)) (dx asinh(dy/dx) + dy asinh(dx/dy))``
    (finite: the ``1 / r`` singularity is integrable); far away it tends to
    ``dx dy / (pi E* r)``.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    hx, hy = dx / 2, dy / 2
    total = (_primitive(x + hx, y + hy) - _primitive(x - hx, y + hy)
             - _primitive(x + hx, y - hy) + _primitive(x - hx, y - hy))
    return total / (np.pi * contact_modulus)


def _primitive(s, t):
    """``s asinh(t / |s|) + t asinh(s / |t|)``, each term 0 where its divisor is."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(s != 0, s * np.arcsinh(t / np.abs(s)), 0.0)
        b = np.where(t != 0, t * np.arcsinh(s / np.abs(t)), 0.0)
    return a + b


def influence_grid(i0, i1, j0, j1, dx, dy, contact_modulus=1.0):
    """:func:`influence_coefficients` at the offsets ``(i dx, j dy)``, ``i0 <= i < i1``,
    ``j0 <= j < j1``: the primitive once per pixel corner, differenced.

    Neighbouring pixels share their corners, so a block of offsets needs the
    primitive at a quarter of the points the pointwise formula evaluates it at.
    """
    xs = (np.arange(i0, i1 + 1) - 0.5) * dx
    ys = (np.arange(j0, j1 + 1) - 0.5) * dy
    f = _primitive(xs[:, None], ys[None, :])
    return (f[1:, 1:] - f[:-1, 1:] - f[1:, :-1] + f[:-1, :-1]) / (np.pi * contact_modulus)


def padded_kernel(cell, contact_modulus):
    """The transform of ``C`` on the padded cell (this rank's Fourier slab, real).

    ``cell`` is the ``2 nx x 2 ny`` grid of an ``nx x ny`` map (same pixels); ``C`` is
    put at the offsets wrapped to ``|i| <= nx``, ``|j| <= ny``, so that it is even in
    ``x`` and ``y`` and its transform real.  Unnormalised (the forward DFT's sum).
    Collective; uses the cell's FFT buffers.
    """
    nx, ny = cell.nx // 2, cell.ny // 2
    i = np.arange(cell.x_slice.start, cell.x_slice.stop)
    j = np.arange(2 * ny)
    xi = np.where(i <= nx, i, i - 2 * nx) * cell.dx
    yj = np.where(j <= ny, j, j - 2 * ny) * cell.dy
    step = max(1, (1 << 16) // len(j))   # rows at a time: temporaries of 64k points
    for start in range(0, len(i), step):
        rows = slice(start, start + step)
        cell.real[rows] = influence_coefficients(xi[rows, None], yj[None, :], cell.dx,
                                                 cell.dy, contact_modulus)
    kernel = cell.forward().real.copy()
    return kernel


def _dct1(a):
    """The DCT-I along the last axis, unnormalised: the transform of the even sequence
    ``a[0], .., a[n], a[n-1], .., a[1]`` (real), at its ``n + 1`` distinct frequencies."""
    even = np.concatenate([a, a[..., -2:0:-1]], axis=-1)
    return np.fft.rfft(even, axis=-1).real


def padded_symbol(grid, contact_modulus):
    """The transform of ``C`` on the map's ``2 nx x 2 ny`` padded cell, on this rank's lines.

    Returns ``(len(plans.kernel_ky), nx + 1)`` doubles: for each ``ky`` of the r2c half
    plane of the cell's ``2 ny`` the plans' kernel takes here (the lines
    :meth:`petgap.parallel.grid.Grid.zero_padded_plans` gives this rank, then the
    Nyquist ``ky = ny``, packed into line 0, where line 0 is here), the transform at
    ``kx = 0 .. nx`` (even in ``kx``), unnormalised.  ``C`` is even in
    ``x`` and ``y``, so its transform is a DCT-I along ``y`` of each row of offsets
    ``0 .. ny``, then along ``x`` of offsets ``0 .. nx``; the map's rows are transposed
    by double-precision plans whatever the grid's precision, and row ``nx``, which no
    rank holds, is made by every rank.  Collective.
    """
    nx, ny, dx, dy = grid.nx, grid.ny, grid.dx, grid.dy
    plans = grid.zero_padded_plans(planner="estimate", precision="double")
    first, count = grid.x_slice.start, grid.local_shape[0]
    rs, ls = plans.row_stride, plans.line_stride
    rows = plans.rows[:count * rs].reshape(count, rs)[:, :ny]   # ky = 0 .. ny - 1, ny packed into 0
    for block in row_blocks(count, ncols=ny + 1):
        along_y = _dct1(influence_grid(first + block.start, first + block.stop, 0, ny + 1,
                                       dx, dy, contact_modulus))
        rows[block] = along_y[:, :ny]
        rows[block, 0] += 1j * along_y[:, ny]
    plans.transpose()
    n1 = plans.local_n1
    lines = plans.lines[:n1 * ls].reshape(n1, ls)[:, :nx]
    ky = plans.kernel_ky   # this rank's lines, then the packed line's Nyquist ky = ny
    last = _dct1(influence_grid(nx, nx + 1, 0, ny + 1, dx, dy, contact_modulus)[0])[ky]
    symbol = np.empty((len(ky), nx + 1))
    for block in row_blocks(n1, ncols=2 * nx):
        symbol[block] = _dct1(np.concatenate([lines[block].real, last[block, None]], axis=1))
    if len(ky) > n1:
        symbol[n1] = _dct1(np.append(lines[0].imag, last[n1]))
    return symbol


def _indices(pidx):
    """Flat padded-slab indices as the compiled plans take them (int32, no copy if so)."""
    return np.asarray(pidx, dtype=np.int32)


def fft_size(n):
    """The smallest ``2^a 3^b 5^c 7^d >= n``: a length FFTW transforms fast."""
    best = 1 << max(int(n) - 1, 0).bit_length()
    p7 = 1
    while p7 < best:
        p5 = p7
        while p5 < best:
            p3 = p5
            while p3 < best:
                m = p3
                while m < n:
                    m *= 2
                best = min(best, m)
                p3 *= 3
            p5 *= 5
        p7 *= 7
    return best


def margin_cell(grid, margin=None):
    """The cell on which the preconditioning stiffness is applied: the map with at least
    ``margin`` (:data:`MARGIN`) pixels of zeros beyond its far edges, FFT-friendly."""
    margin = MARGIN if margin is None else margin
    return (min(fft_size(grid.nx + margin), 2 * grid.nx),
            min(fft_size(grid.ny + margin), 2 * grid.ny))


def stiffness_symbol(grid, plans, cell, contact_modulus):
    """``E* |q| / 2`` on the lines ``plans`` hold of the periodic ``cell`` with ``grid``'s
    pixels at the plans' ``kernel_ky``, ``(len(kernel_ky), cx // 2 + 1)``, divided by
    ``cx cy``; ``q = 0`` gives 0."""
    cx, cy = cell
    qx = 2 * np.pi * np.arange(cx // 2 + 1) / (cx * grid.dx)
    qy = 2 * np.pi * plans.kernel_ky / (cy * grid.dy)
    return contact_modulus / (2.0 * cx * cy) * np.hypot(qy[:, None], qx[None, :])


class FreeHalfSpace:
    """The infinite elastic half-space under pressures on a finite map.

    Same interface as :class:`~petgap.mechanics.half_space.ElasticHalfSpace`
    where the operator exists: :meth:`displacement` and ``apply_sparse`` /
    ``apply_in_buffer`` / ``begin_sparse`` with ``inverse=True`` are the exact
    compliance; with ``inverse=False`` they are the preconditioning stiffness, the
    half-space's stiffness on the map alone (module docstring).  ``periodic`` is
    False.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        The map's grid (its periodicity is ignored: only its pixels, pixel
        size, communicator and FFT buffers are used).
    contact_modulus : float
        ``E*``, positive.

    Collective: plans the pruned transforms of both operators on ``grid``'s
    communicator with its FFTW planner, and transforms ``C`` once.
    """

    periodic = False
    #: both operators run in the map's precision (``apply_sparse``): a whole-slab result
    #: goes to ``grid.padded``, in the grid's precision.
    transforms_in_single = False
    #: ``begin_sparse`` gives ``(t, C t)`` from the forward half of the pruned transform
    splits_transforms = True

    def __init__(self, grid, contact_modulus=1.0):
        self._periodic = ElasticHalfSpace(grid, contact_modulus)
        self.grid = grid
        self.contact_modulus = self._periodic.contact_modulus
        compliance = grid.zero_padded_plans()
        symbol = padded_symbol(grid, self.contact_modulus)
        symbol /= 4 * grid.npoints   # the inverse transform's 1 / (4 nx ny)
        compliance.set_kernel(symbol)
        cell = margin_cell(grid)
        stiffness = grid.zero_padded_plans(cell, buffers=(compliance.rows, compliance.lines))
        stiffness.set_kernel(stiffness_symbol(grid, stiffness, cell, self.contact_modulus))
        #: the pruned plans of ``C`` (True) and of the stiffness (False), on shared buffers
        self._plans = {True: compliance, False: stiffness}
        self._cell = None
        self._begun = None   # the plans whose half-made transform finish completes
        self._applications = 0

    @property
    def cell(self):
        """The map's ``2 nx x 2 ny`` padded cell as a grid (made on first use: the
        solvers on the gap run there, :mod:`petgap.solvers.free_boundary`).  Collective."""
        if self._cell is None:
            grid = self.grid
            self._cell = Grid((2 * grid.nx, 2 * grid.ny), size=(2 * grid.Lx, 2 * grid.Ly),
                              comm=grid.comm, planner=grid.planner, wisdom=grid.wisdom)
        return self._cell

    def on_grid(self, grid):
        """The same body under a map on another grid (a coarse start's)."""
        return FreeHalfSpace(grid, self.contact_modulus)

    @staticmethod
    def admits(shape):
        """Whether the body can live under a map of ``shape`` (any map can)."""
        return True

    @property
    def applications(self):
        """Applications of the compliance or of the preconditioning stiffness so far, in
        transform pairs (a begin and :meth:`finish` count a half each)."""
        return self._applications

    def _use(self, inverse):
        """The plans of ``C`` (``inverse``) or of the stiffness, about to run: the buffers
        they share lose any half-made transform."""
        self._begun = None
        return self._plans[bool(inverse)]

    def _compliance(self, field, out):
        """``out <- C * field`` on this rank's rows of the map (``out`` may be ``field``)."""
        plans = self._use(True)
        self._applications += 1
        with event(OPERATOR_EVENT):
            plans.apply(field, out)
        return out

    def apply_in_buffer(self, inverse=False):
        """Apply ``C`` (``inverse=True``) or the preconditioning stiffness to ``grid.real``, in place."""
        plans = self._use(inverse)
        self._applications += 1
        with event(OPERATOR_EVENT):
            plans.apply(self.grid.real, self.grid.real)
        return self.grid.real

    def _in_precision(self, values):
        """``values`` in the grid's precision (the operators run in it, whatever is asked)."""
        return np.asarray(values, dtype=self.grid.dtype)

    def apply_sparse(self, pidx, values, inverse=False, out=None, gathered=None,
                     precision=None):
        """:meth:`ElasticHalfSpace.apply_sparse <petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse>`
        with ``C`` (``inverse=True``) or the preconditioning stiffness, to ``out``,
        ``gathered``, or ``grid.padded``.

        Both run in the map's precision whatever ``precision`` asks: ``values`` and
        ``gathered`` are converted on the way in and out."""
        grid = self.grid
        plans = self._use(inverse)
        pidx, values = _indices(pidx), self._in_precision(values)
        self._applications += 1
        with event(OPERATOR_EVENT):
            if gathered is None:
                plans.apply_sparse(pidx, values, out=grid.padded if out is None else out)
            elif gathered.dtype == grid.dtype:
                plans.apply_sparse(pidx, values, gathered=gathered)
            else:
                result = np.empty(len(pidx), dtype=grid.dtype)
                plans.apply_sparse(pidx, values, gathered=result)
                np.copyto(gathered, result, casting="same_kind")

    def begin_sparse(self, pidx, values, inverse=False, precision=None):
        """This rank's part of ``(t, C t)`` (``inverse=True``, or of the stiffness's form)
        from the forward half of the pruned transform, the field left half-made for
        :meth:`finish`; in the map's precision.  Each half counts half an application."""
        plans = self._use(inverse)
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            total = plans.begin_sparse(_indices(pidx), self._in_precision(values))
        self._begun = plans
        return total

    def begin_in_buffer(self, inverse=False):
        """:meth:`begin_sparse` of the field in ``grid.real``."""
        plans = self._use(inverse)
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            total = plans.begin(self.grid.real)
        self._begun = plans
        return total

    def finish(self, precision=None):
        """The field of the last begin into the FFT buffer ``grid.padded``.  Collective."""
        if self._begun is None:
            raise RuntimeError("no half-made transform to finish: a begin was not the last "
                               "use of the operators")
        plans, self._begun = self._begun, None
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            plans.end(self.grid.padded)

    def displacement(self, pressure, out=None):
        """Displacement ``u = C p`` on the map under the pressure ``p`` (mean included)."""
        if out is None:
            out = np.empty(self.grid.local_shape, dtype=self.grid.dtype)
        return self._compliance(np.ascontiguousarray(pressure, dtype=self.grid.dtype), out)

    def pressure(self, displacement, out=None):
        """Not available: ``C`` has no fast inverse (module docstring)."""
        raise NotImplementedError("the free-boundary half-space gives displacements from "
                                  "pressures only (its stiffness has no fast form)")

    def point_stiffness(self):
        """The periodic half-space's diagonal stiffness, a scale for solvers (about ``1.2 E* / a0``)."""
        return self._periodic.point_stiffness()

    def complementary_energy(self, pressure):
        """``(1/2) sum_x dx dy p(x) u(x)`` with ``u = C p``, by Parseval from the forward
        half of the transform (all ranks)."""
        plans = self._use(True)
        field = np.ascontiguousarray(pressure, dtype=self.grid.dtype)
        local = plans.begin(field)
        plans.half_made = False
        return 0.5 * self.grid.pixel_area * self.grid.comm.allreduce(local)


class PaddedCellHalfSpace:
    """The padded cell of a free map as a periodic body: ``C`` and ``C^{-1}`` by their symbols.

    What the gap formulation (adhesion) needs on a free boundary: the stiffness, which
    the map alone does not have in fast form, exists on the ``2 nx x 2 ny`` cell as the
    inverse of the circulant ``C`` (its transform is positive: ``C`` is the sampled,
    pixel-averaged Boussinesq kernel, a positive definite function, checked when built).
    A problem on the cell whose surface lies out of reach outside the map (no pressure
    there at the solution, hence none from the images) is the free map's problem
    (:class:`petgap.solvers.free_boundary.PaddedCell`).  The ``q = 0`` mode is
    dropped, as on any periodic cell: the mean pressure of the cell is the control's.

    The interface is :class:`~petgap.mechanics.half_space.ElasticHalfSpace`'s; ``periodic``
    is True (the cell is), the transforms are not fused with the multiplication.

    Parameters
    ----------
    cell : petgap.parallel.grid.Grid
        The ``2 nx x 2 ny`` grid (pixels of the map).
    contact_modulus : float
    """

    periodic = True
    #: ``apply_sparse`` works in the cell's precision: a whole-slab result stays in
    #: ``grid.real``.
    transforms_in_single = False
    #: no ``begin_sparse``: a solver applies the operator whole (``apply_sparse``)
    splits_transforms = False

    def __init__(self, cell, contact_modulus=1.0):
        contact_modulus = float(contact_modulus)
        if not (np.isfinite(contact_modulus) and contact_modulus > 0):
            raise ValueError(f"contact_modulus must be positive and finite, got {contact_modulus}")
        if not self.admits(cell.shape):
            raise ValueError(f"a padded cell has even sides, not {cell.nx} x {cell.ny}")
        self.grid, self.contact_modulus = cell, contact_modulus
        kernel = padded_kernel(cell, contact_modulus)
        smallest = cell.comm.allreduce(float(kernel.min(initial=np.inf)), op=MPI.MIN)
        if not smallest > 0:
            raise ValueError(f"the padded kernel's transform is not positive ({smallest:g}); "
                             f"its inverse is no stiffness")
        n = cell.npoints
        self._stiffness = np.reciprocal(kernel * n)
        kernel /= n
        self._compliance = kernel
        if cell.ky_slice.start == 0:   # the q = 0 mode sits on the rank with ky = 0
            self._compliance[0, 0] = self._stiffness[0, 0] = 0.0
        self._point_stiffness = None
        self._applications = 0

    def on_grid(self, grid):
        """The padded cell of the map on a coarser grid (a coarse start's)."""
        return PaddedCellHalfSpace(grid, self.contact_modulus)

    @staticmethod
    def admits(shape):
        """Whether ``shape`` is a padded cell: even sides, twice a map's.

        Why it matters to a coarse start: the cell of a map with an odd side coarsens
        to odd sides, whose blocks would straddle the map's edge.
        """
        return shape[0] % 2 == 0 and shape[1] % 2 == 0

    @property
    def applications(self):
        return self._applications

    def _multiply(self, symbol):
        grid = self.grid
        self._applications += 1
        with event(OPERATOR_EVENT):
            grid.forward()
            grid.fourier *= symbol
            grid.backward()

    def apply_in_buffer(self, inverse=False):
        """``grid.real <- C grid.real`` (``inverse``) or ``C^{-1} grid.real``, zero mean."""
        self._multiply(self._compliance if inverse else self._stiffness)
        return self.grid.real

    def apply_sparse(self, pidx, values, inverse=False, out=None, gathered=None,
                     precision=None):
        """As :meth:`ElasticHalfSpace.apply_sparse <petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse>`,
        in the cell's precision whatever ``precision`` asks (``values`` and
        ``gathered`` converted on the way in and out)."""
        grid = self.grid
        padded = grid.padded
        padded[...] = 0.0
        padded.reshape(-1)[pidx] = values
        self._multiply(self._compliance if inverse else self._stiffness)
        if gathered is not None:
            gathered[...] = padded.reshape(-1)[pidx]
        elif out is not None:
            out[:, :grid.ny] = grid.real

    def _apply(self, field, symbol, out):
        grid = self.grid
        np.copyto(grid.real, field)
        self._multiply(symbol)
        if out is None:
            return grid.real.copy()
        np.copyto(out, grid.real)
        return out

    def pressure(self, displacement, out=None):
        """Zero-mean pressure ``C^{-1} u`` on the cell."""
        return self._apply(displacement, self._stiffness, out)

    def displacement(self, pressure, out=None):
        """Zero-mean displacement ``C p`` on the cell."""
        return self._apply(pressure, self._compliance, out)

    def point_stiffness(self):
        """The diagonal of ``C^{-1}`` (q = 0 left out).  Collective; cached."""
        if self._point_stiffness is None:
            grid = self.grid
            local = float(np.sum(grid.hermitian_weight[:, None] * self._stiffness))
            self._point_stiffness = grid.comm.allreduce(local)
        return self._point_stiffness

    def _power(self, field, symbol):
        """``(1/2) dx dy sum symbol |field^|^2`` over the whole spectrum.  Collective.

        Summed in blocks of the Fourier slab: whole-slab temporaries would add some
        fifteen bytes per cell point to the peak of a solve, which ends with this sum
        (:meth:`~petgap.mechanics.problem.ContactProblem.make_solution`).
        """
        grid = self.grid
        grid.forward(field)
        fourier, weight = grid.fourier, grid.hermitian_weight
        local = 0.0
        for rows in row_blocks(fourier.shape[0], ncols=fourier.shape[1]):
            f = fourier[rows]
            local += float(np.sum(weight[rows, None] * symbol[rows]
                                  * (f.real * f.real + f.imag * f.imag)))
        return 0.5 * grid.pixel_area * grid.comm.allreduce(local)

    def energy(self, displacement):
        """``(1/2) sum dx dy p u`` with ``p = C^{-1} u`` (zero-mean part)."""
        return self._power(displacement, self._stiffness)

    def complementary_energy(self, pressure):
        """``(1/2) sum dx dy p u`` with ``u = C p`` (zero-mean part)."""
        return self._power(pressure, self._compliance)
