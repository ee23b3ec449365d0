"""The contact-edge term of the pressure solver's preconditioner.

:func:`petgap.solvers.pressure_cg.polonsky_keer` preconditions the compliance
restricted to the contact set ``S``, ``P_S K^{-1} P_S``, with the stiffness
restricted to the same set, ``P_S K P_S`` (``K`` the half-space's stiffness,
symbol ``E* |q| / 2``).  Written out at a point ``x`` of ``S``::

    (P_S K P_S g)(x) = sum_{y in S} K(x - y) (g(y) - g(x))  +  kappa(x) g(x),
    kappa(x) = sum_{y in S} K(x - y) = -sum_{y not in S} K(x - y),

the second form because ``K`` annihilates constants (its symbol vanishes at
``q = 0``).  The first term couples points of ``S`` with each other only (the
"regional" stiffness of ``S``); the second, ``kappa >= 0``, is what the zero
extension of the gap across the contact edge adds.  The off-diagonal kernel
falls like ``-E* / (4 pi r^3)``, so ``kappa`` grows like the inverse distance
to the edge, and it is on edge pixels that the preconditioned operator has its
large eigenvalues: interior modes sit at 1, edge modes above it, and the
largest grows with the contact patches' size in pixels
(``benchmarks/edge_spectrum.py`` prints the spectrum; docs/benchmarks.md has
it).  Taking all of ``kappa`` away leaves the regional stiffness, which does
not see a patch's constant and is not positive on it; taking a share
``theta`` of it away,

    z = P_S K P_S g - theta kappa g,

lowers the edge eigenvalues and keeps the interior ones, and the
conjugate gradients need fewer iterations (docs/benchmarks.md: spectrum,
iterations, and the robustness set under it).  ``theta`` is a tuning constant,
:data:`EDGE_CORRECTION`: much above it the discrete kernel's sign changes at
distance 2 and beyond (the Nyquist modes of ``|q|``) make the operator
indefinite on some contact sets.

Keeping ``kappa`` current costs almost nothing.  It is the stiffness applied to
the indicator of ``S``, ``kappa = K 1_S`` (one transform pair), kept on the
whole slab; when ``S`` changes by a few points, each point that entered adds
the kernel ``K(x - y)`` over a window of ``(2 W + 1)^2`` points around it and
each point that left subtracts it (:func:`petgap.solvers._contact_set.add_windows`).
The windows leave out the kernel beyond ``W`` pixels: off the grid's axes it is
below ``2.4e-4 E* / a0`` there, along them it falls like ``0.14 E* / (a0 r^2)``
(the symbol's kink at the Nyquist lines; ``1.8e-3 E* / a0`` at ``r = 9``), about
a tenth of ``K(0)`` in all per changed point.  So the pair is spent again when
more points changed at once than windows are worth, and once :data:`DRIFT`
times as many have changed since the last transform, which bounds what the
omissions add up to.  The changed points are found by comparing
the contact mask with the mask ``kappa`` describes (one read of two byte
masks), so every change of ``S`` is seen, whichever step made it; each goes to
the ranks whose rows its window reaches.  The kernel's window is taken from a
grid of at most 256^2 points with the same pixel size, on every rank alike, and
each point of ``kappa`` receives its windows in the global order of the
changed points, so that ``kappa`` does not depend on the decomposition beyond
the round-off of its transforms.

Memory: ``kappa`` in the grid's precision (8 or 4 bytes per point) and the byte
mask it describes.
"""
import functools

import numpy as np
from mpi4py import MPI

from petgap.parallel.grid import hermitian_weight
from petgap.parallel.log import SET_UPDATE_EVENT, event
from petgap.solvers import _contact_set as _cs
from petgap.solvers.contact_set import INDEX

#: The share ``theta`` of the edge term taken off the preconditioner (module
#: docstring); 0 is the plain restricted stiffness.
EDGE_CORRECTION = 0.6
#: Half-width ``W`` of the window over which a changed point updates ``kappa``.
WINDOW = 8
#: Side of the largest grid the window's kernel is taken from.
TABLE_SIDE = 256
#: Changed points since the last transform of ``kappa``, in units of the most one
#: update takes by windows, after which the next update transforms (module docstring).
DRIFT = 4


def kernel_window(grid, contact_modulus, window=WINDOW):
    """The stiffness kernel ``K(di dx, dj dy)`` for ``|di|, |dj| <= W``, shape ``(2W+1, 2W+1)``.

    The half-space's symbol ``E* |q| / 2`` (q = 0 dropped) transformed back on a
    periodic grid of the same pixel shape and at most :data:`TABLE_SIDE` points
    a side (the grid itself where it is smaller): the same numbers on every
    rank.  ``W`` shrinks to fit a small grid (the window may not wrap onto
    itself).  The kernel is ``E* / dx`` times a function of the pixels' aspect
    ratio (the symbol is homogeneous in ``q``), so the levels of a coarse start
    of 256 points a side or more, whose pixels double, share one computation,
    and later solves reuse it.
    """
    mx, my = min(grid.nx, TABLE_SIDE), min(grid.ny, TABLE_SIDE)
    w = min(window, (mx - 1) // 2, (my - 1) // 2)
    return contact_modulus / grid.dx * _unit_kernel_window(mx, my, grid.dy / grid.dx, w)


@functools.lru_cache(maxsize=32)
def _unit_kernel_window(mx, my, aspect, w):
    """:func:`kernel_window` for ``E* = 1`` and ``dx = 1``, ``dy = aspect`` (read-only).

    The inverse transform evaluated at the window's ``(2W+1)^2`` offsets only,
    as a cosine sum: the symbol is even in ``qx`` and ``qy``, so

        K(i, j) = (1 / N) sum_qx sum_ky w_ky (|q| / 2) cos(qx i) cos(qy j dy),

    ``ky`` over the half-plane the r2c transform keeps and ``w_ky`` the number
    of full-plane modes each stands for (1 at ``ky = 0`` and an even side's
    Nyquist, else 2).  Two small matrix products: no transform to plan for a
    table of a few hundred numbers (each coarse level of a start would plan
    one), and not one of the half-space's applications, so the solvers'
    operator count and its PETSc log event stay those of the solve.
    """
    qx = 2.0 * np.pi * np.fft.fftfreq(mx)
    qy = 2.0 * np.pi * np.fft.rfftfreq(my, d=aspect)
    weight = hermitian_weight(np.arange(qy.size), my)
    offsets = np.arange(-w, w + 1)
    symbol = 0.5 * np.sqrt(qx[:, None] ** 2 + qy[None, :] ** 2)   # hypot is several times slower
    table = (np.cos(np.outer(offsets, qx)) @ symbol
             @ (weight[:, None] * np.cos(np.outer(qy * aspect, offsets)))) / (mx * my)
    table.flags.writeable = False
    return table


class EdgeCorrection:
    """``kappa = K 1_S`` on a contact mask, kept current, and the preconditioner's correction.

    Parameters
    ----------
    half_space : ElasticHalfSpace or FreeHalfSpace
        Whose stiffness (``apply_in_buffer(inverse=False)``: on a free boundary the
        preconditioner's, which does not reach across the map's edges, and neither
        do the windows there) the preconditioner applies.
    mask : ndarray of uint8, shape ``grid.local_shape``
        The contact set's mask (:class:`petgap.solvers.contact_set.ContactSet`),
        read whenever :meth:`sums` is called.
    theta : float
        The share of ``kappa`` taken off (:data:`EDGE_CORRECTION`).
    """

    def __init__(self, half_space, mask, theta=EDGE_CORRECTION):
        grid = half_space.grid
        self.half_space, self.mask, self.theta = half_space, mask, float(theta)
        self.table = kernel_window(grid, half_space.contact_modulus)
        self.kappa = None
        self._known = None
        # beyond this many changed points (over all ranks) in one update a transform is
        # cheaper: their windows would make half a pass of scattered updates over the
        # grid; and beyond DRIFT times as many since the last transform, the kernel
        # left out of the windows has added up enough to take one (module docstring)
        self._most = max(1, grid.npoints // (2 * self.table.size))
        self._since_transform = 0
        self._changed = np.empty(1024, dtype=INDEX)
        #: the rows each rank holds, to send a changed point to the ranks its window reaches
        self._slabs = grid.comm.allgather((grid.x_slice.start, grid.x_slice.stop))
        #: transforms spent on ``kappa`` (also counted in the half-space's applications)
        self.transforms = 0

    def refresh(self):
        """``kappa = K 1_S`` from scratch: one transform pair.  Collective."""
        grid = self.half_space.grid
        np.copyto(grid.real, self.mask)
        self.half_space.apply_in_buffer(inverse=False)
        if self.kappa is None:
            self.kappa = np.empty(grid.local_shape, dtype=grid.dtype)
            self._known = np.empty_like(self.mask)
        np.copyto(self.kappa, grid.real)
        np.copyto(self._known, self.mask)
        self._since_transform = 0
        self.transforms += 1

    def update(self):
        """Bring ``kappa`` to the mask's present ``S``: windows, or a transform.  Collective."""
        if self.kappa is None:
            return self.refresh()
        grid = self.half_space.grid
        comm = grid.comm
        with event(SET_UPDATE_EVENT):
            count = _cs.changed_points(self.mask, self._known, self._changed)
            total = comm.allreduce(count, op=MPI.SUM)
        if total == 0:
            return None
        self._since_transform += total
        if total > self._most or self._since_transform > DRIFT * self._most:
            return self.refresh()
        with event(SET_UPDATE_EVENT):
            if count > len(self._changed):
                self._changed = np.empty(2 * count, dtype=INDEX)
                _cs.changed_points(self.mask, self._known, self._changed)
            local = self._changed[:count]
            points = np.empty((count, 3), dtype=INDEX)   # global row, column, sign
            points[:, 0] = local // grid.ny + grid.x_slice.start
            points[:, 1] = local % grid.ny
            points[:, 2] = np.where(self.mask.ravel()[local] != 0, 1, -1)
            if comm.size > 1:
                points = self._exchange(points)
            _cs.add_windows(self.kappa, grid.x_slice.start, grid.nx,
                            np.ascontiguousarray(points[:, 0]),
                            np.ascontiguousarray(points[:, 1]),
                            points[:, 2].astype(np.int8), self.table,
                            self.half_space.periodic)
            self._known.ravel()[local] = self.mask.ravel()[local]
        return None

    def _exchange(self, points):
        """Every rank's changed points whose windows reach this rank's rows, in rank order.

        A window covers rows ``i - W .. i + W`` (periodically); it reaches the
        rows ``a <= row < b`` if its last row lies less than ``b - a + 2 W`` rows
        past ``a``.
        """
        comm, nx = self.half_space.grid.comm, self.half_space.grid.nx
        w = self.table.shape[0] // 2
        rows = points[:, 0]
        pieces = [points[(rows + w - a) % nx < (b - a) + 2 * w] for a, b in self._slabs]
        send = np.concatenate(pieces)
        send_counts = np.array([3 * len(piece) for piece in pieces])
        recv_counts = np.empty_like(send_counts)
        comm.Alltoall(send_counts, recv_counts)
        received = np.empty((recv_counts.sum() // 3, 3), dtype=INDEX)
        comm.Alltoallv([send, send_counts], [received, recv_counts])
        return received

    def sums(self, gS, idx):
        """This rank's ``(sum kappa g, sum kappa g^2)`` over ``S``, ``kappa`` brought up to date.

        What the correction changes in the sums of ``z``: ``sum z`` by
        ``-theta sum kappa g``, ``(g, z)`` by ``-theta sum kappa g^2``, so that the
        caller can tell whether the corrected preconditioner is positive on the
        gap before applying it.  Collective (the update may take a transform).
        """
        self.update()
        return _cs.edge_sums(gS, self.kappa, idx)

    def subtract(self, zS, gS, idx):
        """``zS -= theta kappa gS`` on ``S`` (indices ``idx``), ``kappa`` as :meth:`sums` left it."""
        _cs.subtract_edge_term(zS, gS, self.kappa, idx, self.theta)


