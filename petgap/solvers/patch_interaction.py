"""The elastic interaction between contact patches, in the pressure solver's preconditioner.

:func:`petgap.solvers.pressure_cg.polonsky_keer` preconditions the compliance
restricted to the contact set, ``A = P_S K^{-1} P_S``, with the restricted
stiffness less a share of its edge term, ``M = P_S K P_S - theta kappa``
(:mod:`petgap.solvers.edge_correction`).  ``M`` is local: the stiffness kernel
falls like ``1 / r^3``.  The compliance is not: its kernel falls like ``1 / r``,
and a pressure that is constant over each patch and varies slowly across many
of them, at wavenumber ``q``, displaces every patch by the far field of all the
others, about ``2 phi / (E* q)`` times the pressure for a contact fraction
``phi``.  The local ``M`` does not see that, so ``M A`` has eigenvalues of about
``1 + 2 phi / (q c)`` on such modes (``c`` a patch's own compliance, a few
pixels over ``E*``), which grow with the cell's size over the patches' spacing,
and so does the preconditioned condition number with ``M`` alone.

The far field is smooth, so it lives on a coarse grid.  Cut the grid into
blocks of about :data:`BLOCK` pixels a side, let ``R`` sum over the points of
``S`` in each block (the force on it) and ``F`` be the compliance of the coarse
grid, which turns block forces into block displacements (symbol
``2 / (E* |q|)`` over the coarse cell's area in pixels).  Then
``A ~ M^{-1} + R^T F R`` and, by the Sherman-Morrison-Woodbury identity,

    A^{-1} ~ M - M R^T (F^{-1} + R M R^T)^{-1} R M.

``M`` applied to a function constant over a patch is ``K 1_S - theta kappa =
(1 - theta) kappa`` times it (``kappa = K 1_S``), so ``M R^T ~ V``, with ``V`` the
block values spread over ``S`` times ``(1 - theta) kappa``, and ``R M R^T ~ D``,
the block sums of ``(1 - theta) kappa``.  The preconditioner becomes

    z = M g - V y,   y = (F^{-1} + D)^{-1} V^T g,

symmetric, and positive wherever the model is fair (the caller checks
``(g, z) > 0`` and otherwise goes on without it).  ``y`` is found on the coarse
grid as ``F^{1/2} (I + F^{1/2} D F^{1/2})^{-1} F^{1/2} V^T g`` by conjugate
gradients (``F^{1/2}`` has no mean mode, as ``F`` has none), to a relative
residual of :data:`INNER_TOLERANCE`, which keeps the preconditioner the same
linear operator at every iteration to within a millionth; the coarse grid is
replicated on every rank, which receive the same block sums and so compute the
same ``y``.  With it the preconditioned condition number on a fixed contact
set no longer grows with the grid (``benchmarks/patch_spectrum.py``;
docs/design.md, "The patch interaction").

The term is smooth over whole blocks, and the solver's projection onto ``p >=
0`` is not: the pressure solver applies it only once the contact set has nearly
stopped changing, and withdraws it for a while when the residual rose after a
step with it (:class:`petgap.solvers.preconditioners.PatchAdmission`; docs/design.md,
"When the patch interaction applies").  The solver makes it under load control,
and on a free map under indentation too
(:class:`petgap.solvers.preconditioners.RestrictedStiffness` says why).

Cost: one pass over ``S`` for the block sums, one to subtract ``V y``, an
all-reduce of two coarse fields, and a few dozen transforms of the coarse grid,
small beside a transform pair of the fine grid.  The coarse grid is solved
alike on every rank, whatever their number, so its cost does not shrink as the
ranks share the fine grid: beyond :data:`MAX_SIDE` blocks a side the blocks
grow instead (at 16384^2, 256 blocks of 64 pixels).  Larger blocks model the
far field more coarsely, but converge about as fast as 32-pixel blocks, and far
faster than no term (docs/benchmarks.md, "The preconditioner's patch
interaction").

On a free boundary the far field is the free half-space's: ``F`` is the
compliance of Love's uniformly loaded blocks (:func:`petgap.mechanics.free_half_space.influence_coefficients`
with the blocks as pixels) over the map's blocks alone, a Toeplitz operator
with no square root in closed form.  It is the restriction to the map of the
circulant ``F_c`` on the ``2 mx x 2 my`` blocks of the padded cell (Hockney), whose
symbol is positive, and since ``D`` and ``V^T g`` vanish off the map,
``(F_c^{-1} + D)^{-1}`` solved on the cell and restricted to the map is
``(F^{-1} + D)^{-1}`` (the Woodbury form of both has ``F`` only between
restrictions to the map).  So the coarse system is solved on the padded cell,
four times the blocks, with ``F_c^{1/2}`` by its symbol; its mean mode is not
zero (a free map sinks under a mean pressure).
"""
import numpy as np
from mpi4py import MPI

from petgap.mechanics.free_half_space import influence_coefficients
from petgap.solvers import _contact_set as _cs

#: Side of a block, in pixels, over which the far field is taken as constant.
BLOCK = 32
#: The coarse grid has at most this many blocks a side, larger blocks beyond
#: (module docstring).
MAX_SIDE = 256
#: Fewest blocks a side for the correction to be made at all: with fewer the
#: cell's longest wavelengths are too few patches long for their far field to
#: matter beside the cost of the coarse solve (grids below 1024^2 with 32-pixel
#: blocks, among them the coarse start's levels below that: there it costs more
#: time than it saves, docs/benchmarks.md).
MIN_SIDE = 32
#: Relative residual to which the coarse system is solved.  The term is then
#: off by that share of itself, far below what one outer iteration gains (a
#: factor of about 0.2), so the conjugate gradients see a fixed operator.
INNER_TOLERANCE = 1e-6
#: :data:`MIN_SIDE` on a free map.  There the term also carries the map's mean mode
#: (a free map sinks under a mean pressure, which the local stiffness does not see at
#: any size), which an indentation leaves to the iterations: on 512^2 maps with the
#: term it takes the iterations of load control (docs/benchmarks.md).
FREE_MIN_SIDE = 16


def blocks(n, block=BLOCK):
    """Blocks along a side of ``n`` pixels: ``n // block``, at least 1, at most :data:`MAX_SIDE`."""
    return min(max(n // block, 1), MAX_SIDE)


class PatchInteraction:
    """The far-field term of the pressure solver's preconditioner (module docstring).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    contact_modulus : float
        ``E*``.
    theta : float
        The share of ``kappa`` the preconditioner takes off (its edge correction).
    block : int
        Side of a block in pixels (:data:`BLOCK`).
    periodic : bool
        The far field of a periodic cell, or of a free map (module docstring).

    Use :func:`patch_interaction`, which returns None where the grid is too small.
    """

    def __init__(self, grid, contact_modulus, theta, block=BLOCK, periodic=True):
        self.grid = grid
        self.mx, self.my = blocks(grid.nx, block), blocks(grid.ny, block)
        self.share = 1.0 - float(theta)
        cell = (grid.nx / self.mx) * (grid.ny / self.my)
        #: pixels in a block (``block^2``, or more where the blocks grew beyond
        #: :data:`MAX_SIDE` a side)
        self.block_area = cell
        # F's symbol, divided by a block's area in pixels (block sums in, displacements out)
        if periodic:
            self.shape = (self.mx, self.my)
            symbol = _periodic_symbol(grid, self.shape, contact_modulus)
        else:
            self.shape = (2 * self.mx, 2 * self.my)
            symbol = _free_symbol(grid, self.shape, contact_modulus)
        self._root = np.sqrt(symbol / cell)   # F^{1/2}
        #: coarse conjugate-gradient iterations of the last :meth:`solve`
        self.inner_iterations = 0

    def _half(self, x):
        return np.fft.irfft2(np.fft.rfft2(x) * self._root, s=self.shape)

    def sums(self, gS, kappa, idx):
        """``(w, d)``: the block sums ``V^T g`` and ``D`` over every rank.  Collective."""
        grid, m = self.grid, self.mx * self.my
        both = np.zeros(2 * m)   # w and d, reduced in one message
        _cs.block_sums(gS, kappa, idx, grid.x_slice.start, grid.nx, grid.ny, self.mx, self.my,
                       both[:m], both[m:])
        if grid.comm.size > 1:
            grid.comm.Allreduce(MPI.IN_PLACE, both, op=MPI.SUM)
        both *= self.share
        return both[:m], both[m:]

    def solve(self, w, d):
        """``y = (F^{-1} + D)^{-1} w`` on the coarse grid (the same on every rank)."""
        shape, on_map = self.shape, (slice(0, self.mx), slice(0, self.my))
        d, w = self._on_cell(d), self._on_cell(w)
        b = self._half(w)
        x = np.zeros(shape)
        r = b.copy()
        rr = bb = _dot(r, r)
        p = r.copy()
        k = 0
        while rr > INNER_TOLERANCE ** 2 * bb and k < 10 * self.mx * self.my:
            ap = p + self._half(d * self._half(p))
            alpha = rr / _dot(p, ap)
            x += alpha * p
            r -= alpha * ap
            rr, rr_old = _dot(r, r), rr
            p *= rr / rr_old
            p += r
            k += 1
        self.inner_iterations = k
        return np.ascontiguousarray(self._half(x)[on_map]).ravel()

    def _on_cell(self, v):
        """Block values ``v`` on the grid the coarse system is solved on (on a free map's
        padded cell, zero off the map)."""
        v = v.reshape(self.mx, self.my)
        if v.shape == self.shape:
            return v
        cell = np.zeros(self.shape)
        cell[:self.mx, :self.my] = v
        return cell

    def subtract(self, zS, kappa, idx, y):
        """``zS -= V y`` on S (indices ``idx``)."""
        grid = self.grid
        _cs.subtract_blocks(zS, kappa, idx, grid.x_slice.start, grid.nx, grid.ny, self.mx,
                            self.my, y, self.share)


def _periodic_symbol(grid, shape, contact_modulus):
    """``2 / (E* |q|)`` on the periodic coarse grid of ``shape`` blocks (``q = 0`` gives 0)."""
    qx = 2 * np.pi * np.fft.fftfreq(shape[0], d=grid.Lx / shape[0])
    qy = 2 * np.pi * np.fft.rfftfreq(shape[1], d=grid.Ly / shape[1])
    q = np.hypot(qx[:, None], qy[None, :])
    symbol = np.zeros_like(q)
    np.divide(2.0 / contact_modulus, q, out=symbol, where=q > 0)
    return symbol


def _free_symbol(grid, shape, contact_modulus):
    """The transform of Love's block coefficients on the padded cell of ``shape`` blocks
    (twice the map's a side), at offsets wrapped to at most the map's: real, positive."""
    bx, by = 2 * grid.Lx / shape[0], 2 * grid.Ly / shape[1]
    i, j = (np.fft.fftfreq(n, d=1.0 / n) for n in shape)
    i[shape[0] // 2], j[shape[1] // 2] = shape[0] // 2, shape[1] // 2   # offset +m, not -m
    c = influence_coefficients(i[:, None] * bx, j[None, :] * by, bx, by, contact_modulus)
    return np.fft.rfft2(c).real


def _dot(a, b):
    # np.vdot of two 2-D arrays takes a path some 20 times slower than np.dot of their
    # flat views, which matters at a few hundred products per outer iteration
    return float(np.dot(a.ravel(), b.ravel()))


def patch_interaction(half_space, theta, block=BLOCK):
    """A :class:`PatchInteraction` for ``half_space``'s grid, or None where it is not made.

    None where the coarse grid would have fewer than :data:`MIN_SIDE` blocks a side
    (:data:`FREE_MIN_SIDE` on a free map; ``block = 0`` turns it off); on a free
    boundary, the free map's far field.
    """
    grid = half_space.grid
    if not block:
        return None
    fewest = MIN_SIDE if half_space.periodic else FREE_MIN_SIDE
    if min(blocks(grid.nx, block), blocks(grid.ny, block)) < fewest:
        return None
    return PatchInteraction(grid, half_space.contact_modulus, theta, block,
                            periodic=half_space.periodic)
