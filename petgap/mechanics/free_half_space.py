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
  map can see, ``|i| < nx`` and ``|j| < ny``; then one forward and one inverse
  FFT-MPI transform of the padded cell, and a multiplication by the kernel's
  transform (real: ``C`` is even in ``x`` and ``y``), give ``u`` on the map.

Cost: an application moves the map's rows to the padded cell's slabs and back
(:func:`petgap.parallel.collective.move_rows`, one ``Alltoallv`` each way) and
transforms four times as many points as the periodic operator on the map.

The stiffness ``K = C^{-1}`` has no such fast form.  The pressure solver needs
``K`` only as its preconditioner (an approximate inverse of ``C`` on the
contact set), and there the periodic stiffness on the map's own grid serves:
restricted to the contact set, ``C`` and the periodic compliance differ by the
images' smooth field, which leaves the edges -- the part that needs
preconditioning -- alike.  So ``apply_sparse(..., inverse=False)`` and
``apply_in_buffer(inverse=False)`` apply the periodic stiffness, and
:meth:`FreeHalfSpace.pressure` refuses; solvers that need the exact ``K``
(the gap formulation, TAO's bound-constrained methods) do not run on a free
boundary (:func:`petgap.solvers.dispatch.solve` says so).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.collective import move_rows
from petgap.parallel.grid import Grid
from petgap.parallel.log import OPERATOR_EVENT, event


def influence_coefficients(x, y, dx, dy, contact_modulus=1.0):
    """Displacement at ``(x, y)`` under a unit pressure on the ``dx x dy`` pixel at the origin.

    Love's solution for a uniformly loaded rectangle (module docstring): the
    Boussinesq kernel ``1 / (pi E* r)`` integrated over the pixel.  At the
    pixel's own centre it is ``(2 / (pi E*)) (dx asinh(dy/dx) + dy asinh(dx/dy))``
    (finite: the ``1 / r`` singularity is integrable); far away it tends to
    ``dx dy / (pi E* r)``.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)

    def primitive(s, t):
        # s asinh(t / |s|) + t asinh(s / |t|), each term 0 where its divisor is
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(s != 0, s * np.arcsinh(t / np.abs(s)), 0.0)
            b = np.where(t != 0, t * np.arcsinh(s / np.abs(t)), 0.0)
        return a + b

    hx, hy = dx / 2, dy / 2
    total = (primitive(x + hx, y + hy) - primitive(x - hx, y + hy)
             - primitive(x + hx, y - hy) + primitive(x - hx, y - hy))
    return total / (np.pi * contact_modulus)


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


class FreeHalfSpace:
    """The infinite elastic half-space under pressures on a finite map.

    Same interface as :class:`~petgap.mechanics.half_space.ElasticHalfSpace`
    where the operator exists: :meth:`displacement` and ``apply_sparse`` /
    ``apply_in_buffer`` with ``inverse=True`` are the exact compliance; with
    ``inverse=False`` they are the periodic stiffness, a preconditioner (module
    docstring).  ``periodic`` is False.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        The map's grid (its periodicity is ignored: only its pixels, pixel
        size, communicator and FFT buffers are used).
    contact_modulus : float
        ``E*``, positive.

    Collective: builds a ``2 nx x 2 ny`` grid on ``grid``'s communicator with
    the same FFTW planner, and transforms the kernel once.
    """

    periodic = False
    #: ``C`` is applied in the map's precision (``apply_sparse``): a whole-slab result
    #: stays in ``grid.real``, in double.
    transforms_in_single = False
    #: no ``begin_sparse``: a solver applies the operator whole (``apply_sparse``)
    splits_transforms = False

    def __init__(self, grid, contact_modulus=1.0):
        self._periodic = ElasticHalfSpace(grid, contact_modulus)
        self.grid = grid
        self.contact_modulus = self._periodic.contact_modulus
        nx, ny = grid.nx, grid.ny
        self.cell = Grid((2 * nx, 2 * ny), size=(2 * grid.Lx, 2 * grid.Ly), comm=grid.comm,
                         planner=grid.planner, wisdom=grid.wisdom)
        cell = self.cell
        # the inverse transform's 1 / (4 nx ny) folded in
        self._kernel = padded_kernel(cell, self.contact_modulus)
        self._kernel /= cell.npoints
        self._rows = (cell.x_slice.start, min(cell.x_slice.stop, nx))  # map rows held here
        self._applications = 0

    def on_grid(self, grid):
        """The same body under a map on another grid (a coarse start's)."""
        return FreeHalfSpace(grid, self.contact_modulus)

    @property
    def applications(self):
        """Applications of the compliance or of the preconditioning stiffness so far."""
        return self._applications + self._periodic.applications

    def _compliance(self, field, out):
        """``out <- C * field`` on this rank's rows of the map (``out`` may be ``field``)."""
        grid, cell = self.grid, self.cell
        lo, hi = self._rows
        self._applications += 1
        with event(OPERATOR_EVENT):
            cell.real[...] = 0.0
            for row, piece in move_rows(grid.comm, field, grid.x_slice.start, lo, max(hi, lo)):
                cell.real[row - lo:row - lo + len(piece), :grid.ny] = piece
            cell.forward()
            cell.fourier *= self._kernel
            cell.backward()
            held = cell.real[:max(hi - lo, 0), :grid.ny]
            start, stop = grid.x_slice.start, grid.x_slice.stop
            for row, piece in move_rows(grid.comm, held, lo, start, stop):
                out[row - start:row - start + len(piece)] = piece
        return out

    def apply_in_buffer(self, inverse=False):
        """Apply ``C`` (``inverse=True``) or the preconditioning stiffness to ``grid.real``, in place."""
        if not inverse:
            return self._periodic.apply_in_buffer(inverse=False)
        return self._compliance(self.grid.real, self.grid.real)

    def apply_sparse(self, pidx, values, inverse=False, out=None, gathered=None,
                     precision=None):
        """:meth:`ElasticHalfSpace.apply_sparse <petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse>`
        with ``C`` for ``inverse=True`` (the map's padded FFT buffer is scratch).

        ``C`` is applied in the map's precision whatever ``precision`` asks:
        ``values`` and ``gathered`` are converted on the way in and out."""
        if not inverse:
            return self._periodic.apply_sparse(pidx, values, inverse=False, out=out,
                                               gathered=gathered, precision=precision)
        grid = self.grid
        padded = grid.padded
        padded[...] = 0.0
        padded.reshape(-1)[pidx] = values
        self._compliance(grid.real, grid.real)
        if gathered is not None:
            gathered[...] = padded.reshape(-1)[pidx]
        elif out is not None:
            out[:, :grid.ny] = grid.real

    def displacement(self, pressure, out=None):
        """Displacement ``u = C p`` on the map under the pressure ``p`` (mean included)."""
        if out is None:
            out = np.empty(self.grid.local_shape)
        return self._compliance(np.ascontiguousarray(pressure, dtype=float), out)

    def pressure(self, displacement, out=None):
        """Not available: ``C`` has no fast inverse (module docstring)."""
        raise NotImplementedError("the free-boundary half-space gives displacements from "
                                  "pressures only (its stiffness has no fast form)")

    def point_stiffness(self):
        """The periodic half-space's diagonal stiffness, a scale for solvers (about ``1.2 E* / a0``)."""
        return self._periodic.point_stiffness()

    def complementary_energy(self, pressure):
        """``(1/2) sum_x dx dy p(x) u(x)`` with ``u = C p`` (all ranks; one application)."""
        u = self.displacement(pressure)
        local = float(np.vdot(pressure, u))
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
        if cell.nx % 2 or cell.ny % 2:
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
        grid = self.grid
        grid.forward(field)
        local = float(np.sum(grid.hermitian_weight[:, None] * symbol * np.abs(grid.fourier) ** 2))
        return 0.5 * grid.pixel_area * grid.comm.allreduce(local)

    def energy(self, displacement):
        """``(1/2) sum dx dy p u`` with ``p = C^{-1} u`` (zero-mean part)."""
        return self._power(displacement, self._stiffness)

    def complementary_energy(self, pressure):
        """``(1/2) sum dx dy p u`` with ``u = C p`` (zero-mean part)."""
        return self._power(pressure, self._compliance)
