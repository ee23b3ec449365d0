"""Linear elastic response of a periodic half-space to normal surface tractions.

Conventions (see also :mod:`petgap.parallel.grid`)
-----------------------------------------
* ``u`` is the normal surface displacement, positive away from the rigid
  counter-surface; ``p`` is the normal pressure, positive in compression.
* In Fourier space (forward DFT unnormalised, ``f_q = sum_x f(x) exp(-i q.x)``)
  the half-space is diagonal (Johnson 1985, ch. 12; Stanley & Kato 1997)::

      u_q = 2 p_q / (E* |q|),    p_q = E* |q| u_q / 2,    q != 0,

  with ``E*`` the contact modulus of the paper's Eq. 4.
* The ``q = 0`` mode is the rigid-body position of the half-space and the mean
  pressure; an infinite half-space has no finite stiffness for it, so these
  operators never produce it: :meth:`pressure` returns the zero-mean pressure of
  a displacement and :meth:`displacement` the zero-mean displacement of a
  pressure.  The mean is set by the control (load or mean gap), not here.
* Elastic energy ``E_el = (1/2) sum_x dx dy p(x) u(x)``, evaluated exactly in
  Fourier space by Parseval: ``(dx dy / 2 N) sum_q (E* |q| / 2) |u_q|^2``.

Every operation costs one forward and one inverse transform (the energy only a
forward one) and one fused pass over the Fourier slab; inputs are never modified
and the grid's FFT buffers are used as scratch.

The half-space counts its own applications of ``K`` or ``K^{-1}``
(:attr:`ElasticHalfSpace.applications`; the energies, a forward transform
each, are not applications) and runs each inside the PETSc log event
:data:`petgap.parallel.log.OPERATOR_EVENT` (a half run apart inside
:data:`~petgap.parallel.log.OPERATOR_HALF_EVENT`), so that solvers report the count
without keeping it themselves and ``-log_view`` shows the operator's time.
"""
import numpy as np

from petgap.parallel.grid import weighted_power
from petgap.parallel.log import OPERATOR_EVENT, OPERATOR_HALF_EVENT, event


class ElasticHalfSpace:
    """The periodic elastic half-space on a :class:`~petgap.parallel.grid.Grid`.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        Decomposition and transforms.
    contact_modulus : float
        ``E*`` (paper Eq. 4), positive.
    """

    #: Periodic images load the cell (:class:`petgap.mechanics.free_half_space.FreeHalfSpace`
    #: is the body without them).
    periodic = True
    #: ``apply_sparse(..., precision="single")`` transforms in 32 bits, its whole-slab
    #: result in the grid's :meth:`~petgap.parallel.grid.Grid.single_precision_alias`.
    transforms_in_single = True
    #: :meth:`begin_sparse` and :meth:`begin_in_buffer` give ``(t, K t)`` for half a
    #: transform pair, :meth:`finish` the field for the other half.
    splits_transforms = True

    def __init__(self, grid, contact_modulus=1.0):
        contact_modulus = float(contact_modulus)
        if not (np.isfinite(contact_modulus) and contact_modulus > 0):
            raise ValueError(f"contact_modulus must be positive and finite, got {contact_modulus}")
        self.grid = grid
        self.contact_modulus = contact_modulus
        n = grid.npoints
        # Factors folding in the 1/N of the inverse transform.
        self._stiffness = contact_modulus / (2.0 * n)
        self._compliance = 2.0 / (contact_modulus * n)
        self._point_stiffness = None  # computed on first use (collective)
        self._applications = 0

    def on_grid(self, grid):
        """The same body on another grid (a coarse start's)."""
        return ElasticHalfSpace(grid, self.contact_modulus)

    @staticmethod
    def admits(shape):
        """Whether the body can live on a grid of ``shape`` (any periodic cell can)."""
        return True

    @property
    def applications(self):
        """Applications of ``K`` or ``K^{-1}`` (dense or sparse) so far, on this rank, in
        transform pairs (a begin and :meth:`finish` count a half each).

        Every rank applies the operator together, so the count is the same on
        all; a solver reports its difference over the solve.
        """
        return self._applications

    def _apply(self, field, scale, power, out):
        grid = self.grid
        np.copyto(grid.real, field)
        self._convolve(scale, power)
        if out is None:
            return grid.real.copy()
        np.copyto(out, grid.real)
        return out

    def _convolve(self, scale, power):
        self._applications += 1
        with event(OPERATOR_EVENT):
            return self.grid.convolve_qpower(scale, power)

    def apply_in_buffer(self, inverse=False):
        """Apply ``K`` (or ``K^{-1}``) to the field already in ``grid.real``, in place.

        For solvers that fill the FFT buffer in a fused pass of their own and
        read the result straight from it: no copies in or out.
        """
        if inverse:
            return self._convolve(self._compliance, -1)
        return self._convolve(self._stiffness, 1)

    def apply_sparse(self, pidx, values, inverse=False, out=None, gathered=None,
                     precision=None):
        """Apply ``K`` (or ``K^{-1}``) to a field given on a set of points only.

        The field is ``values`` at the sorted padded-slab indices ``pidx`` and
        zero elsewhere (a pressure on a contact set, a gap restricted to one);
        the result goes to the FFT buffer ``grid.real``, to ``out`` (from
        :meth:`petgap.parallel.grid.Grid.aligned_padded`), or only its values at
        ``pidx`` to ``gathered``.  Same operator as :meth:`apply_in_buffer`
        without its slab-sized fill and, gathered, its slab-sized output.

        ``precision="single"`` on a double grid transforms in single precision
        on :meth:`petgap.parallel.grid.Grid.single_precision_alias` (in the grid's
        own buffers): ``values``, ``out`` and ``gathered`` are then float32, and
        the result without them is in the alias's ``real`` (on the first half of
        ``grid.real``'s bytes).  It counts as an application like any other.
        """
        scale, power = (self._compliance, -1) if inverse else (self._stiffness, 1)
        grid = self._grid_in(precision)
        self._applications += 1
        with event(OPERATOR_EVENT):
            grid.convolve_qpower_sparse(pidx, values, scale, power, out, gathered)

    def begin_sparse(self, pidx, values, inverse=False, precision=None):
        """This rank's part of ``(t, K t)`` (or ``(t, K^{-1} t)``) for a field ``t`` on a set
        of points, by Parseval, with ``K t`` left half-made.

        ``t`` is ``values`` at the sorted padded-slab indices ``pidx`` (as in
        :meth:`apply_sparse`).  The form needs the forward transform only:
        summed over the ranks it is ``sum_x t K t`` exactly, and a
        conjugate-gradient step length needs no more.  :meth:`finish`
        completes ``K t`` (the inverse transform) into the FFT buffer if the
        solver needs the field after all; any other transform in between
        discards it.  Each half counts half an application.  ``precision`` as in
        :meth:`apply_sparse`.
        """
        scale, power = (self._compliance, -1) if inverse else (self._stiffness, 1)
        grid = self._grid_in(precision)
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            return grid.convolve_qpower_sparse_begin(pidx, values, scale, power)

    def begin_in_buffer(self, inverse=False):
        """:meth:`begin_sparse` of the field in ``grid.real`` (which it overwrites)."""
        scale, power = (self._compliance, -1) if inverse else (self._stiffness, 1)
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            return self.grid.convolve_qpower_begin(scale, power)

    def finish(self, precision=None):
        """The field of the last :meth:`begin_sparse` or :meth:`begin_in_buffer`, into the
        FFT buffer (``grid.padded``, or the single-precision alias's with
        ``precision="single"``).  Collective."""
        grid = self._grid_in(precision)
        self._applications += 0.5
        with event(OPERATOR_HALF_EVENT):
            grid.convolve_qpower_end()

    def _grid_in(self, precision):
        """The grid whose transforms run in ``precision`` (None: the grid's own)."""
        grid = self.grid
        if precision == "single":
            return grid.single_precision_alias()
        if precision not in (None, grid.precision):
            raise ValueError(f"precision = {precision!r} is not allowed: need 'single', or "
                             f"the grid's own {grid.precision!r}")
        return grid

    def pressure(self, displacement, out=None):
        """Zero-mean pressure ``p = K u`` that holds the displacement ``u``.

        Parameters
        ----------
        displacement : ndarray, shape ``grid.local_shape``
        out : ndarray, optional
            Where to write the result (may be ``displacement`` itself).
        """
        return self._apply(displacement, self._stiffness, 1, out)

    def displacement(self, pressure, out=None):
        """Zero-mean displacement ``u = K^{-1} p`` under the pressure ``p``.

        The mean of ``pressure`` (the q = 0 mode) is ignored: it moves the
        half-space rigidly by an amount the control decides.
        """
        return self._apply(pressure, self._compliance, -1, out)

    def point_stiffness(self):
        """The diagonal of ``K``: the pressure at a point per unit displacement of it alone.

        ``(1 / N) sum_q E* |q| / 2`` (the ``q = 0`` term is zero), about
        ``1.2 E* / a0`` on a square grid.  Solvers that work in pressure but
        meet a penetration ``g`` (a length) use ``k g`` as the pressure scale
        of that point, so that their steps do not depend on the unit system.
        Collective: every rank must call it; computed once and cached.
        """
        if self._point_stiffness is None:
            grid = self.grid
            local = sum(float(w) * float(np.hypot(grid.qx, qy).sum())
                        for w, qy in zip(grid.hermitian_weight, grid.qy))
            total = grid.comm.allreduce(local)
            self._point_stiffness = self._stiffness * total
        return self._point_stiffness

    def energy(self, displacement):
        """Elastic energy ``(1/2) sum_x dx dy p(x) u(x)`` of a displacement (all ranks)."""
        grid = self.grid
        grid.forward(displacement)
        local = weighted_power(grid.fourier, grid.qx, grid.qy, grid.hermitian_weight, 1)
        total = grid.comm.allreduce(local)
        return 0.5 * grid.pixel_area * self._stiffness * total

    def complementary_energy(self, pressure):
        """``(1/2) sum_x dx dy p(x) u(x)`` with ``u = K^{-1} p`` (mean of ``p`` ignored)."""
        grid = self.grid
        grid.forward(pressure)
        local = weighted_power(grid.fourier, grid.qx, grid.qy, grid.hermitian_weight, -1)
        total = grid.comm.allreduce(local)
        return 0.5 * grid.pixel_area * self._compliance * total
