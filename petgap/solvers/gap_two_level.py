"""The coarse term of the gap solver's preconditioner: contact patches pin long waves.

:func:`petgap.solvers.gap_cg.gap_cg` preconditions the stiffness restricted to
the free set ``F``, ``A = P_F (K + D) P_F`` (``D = v''(g)``, the interaction's
curvature), with the compliance restricted to the same set, ``P_F K^{-1} P_F``.
The compliance treats every point of ``F`` as free to move with its
neighbours.  A gap that varies slowly over a region holding contact patches
cannot: it is held at zero on each patch, so such a long wave costs the
elastic energy of the cut it has around every patch, and ``A`` is much stiffer
on it than ``K`` is.  Written out for a smooth ``phi`` and ``g = 1_F phi``::

    g.K g ~ phi.K phi + sum_{x in C} kappa(x) phi(x)^2,   kappa = K 1_C on C,

``C`` the contact set: the patches act on long waves as springs of stiffness
``kappa`` per point, which grows like the inverse distance to the patch's edge.
``K^{-1}`` misses the springs, so the preconditioned operator has eigenvalues far
above 1 on long waves, more of them and larger the longer the cell's longest waves
are against the patches' spacing: the
iterations grow with the grid.  The adhesive curvature ``D < 0`` near the
patches softens the same waves and lowers the smallest eigenvalues.

The springs and the softening sit in the same coarse cells, at the patches'
edges, and the coarse model sees their balance: an interface is sticky where
the softening nearly cancels the springs.  So the springs must be the contact's
own, not a lower bound.  Springs half their size leave ``W`` too negative there,
the model takes long waves to be softer than they are, the preconditioned
operator gets small eigenvalues, and the more so the stronger the adhesion and
the more patches the cell holds: the iterations then grow with ``w`` and with the
grid on the sticky side.

The springs and the long waves live on a coarse grid.  Let ``P`` interpolate
coarse nodes every ``b`` pixels bilinearly onto the fine grid, ``R = P^T / b^2``
average the fine grid onto them, ``Fc = R K^{-1} P`` be the coarse compliance
(a Fourier symbol on the coarse grid, summed over the aliases of the hats'
spectrum), and ``W = R s`` the springs ``s`` per coarse node: ``kappa`` on the
contact set plus ``D`` on the free set.  Then
``A ~ K + R^T W R`` and, by the Sherman-Morrison-Woodbury identity,

    A^{-1} ~ K^{-1} - K^{-1} R^T (W^{-1} + Fc)^{-1} R K^{-1}.

On smooth fields ``K^{-1} R^T ~ P Fc / b^2`` and ``R K^{-1} ~ Fc R``, so with
``H = Fc^{1/2}`` (``Fc`` and ``H`` are Fourier multipliers on the coarse grid)
the preconditioner is

    z = K^{-1} r - P (Fc R r - H v),   (I + H W H) v = H R r,

symmetric.  Where ``W >= 0`` it is positive definite: the subtracted term is
then below ``P Fc R``, which is below ``K^{-1}``: the hats' low-pass keeps it so,
``tests/solvers/test_gap_two_level.py`` checks it.  ``D`` makes ``W`` negative near contact edges with
little contact, which gives the long waves there the softening the
interaction adds.  On the sticky side the softening nearly cancels the springs,
and the lumped model can put a coarse mode at or past zero stiffness where the
true operator keeps it stiff: ``I + H W H`` then has an eigenvalue near zero,
its inverse amplifies that mode, and the preconditioned operator gets a large
eigenvalue (or, past zero, no positive definite term at all).  So the softening
enters scaled, ``W = W_C + theta W_D`` (contact springs, softening), with
``theta`` the largest value for which the system's smallest eigenvalue stays at
least :data:`MARGIN`.  ``lambda_min`` of an affine family of symmetric matrices is
concave in ``theta``, and ``I + H W_C H >= I``, so from one Lanczos estimate
``mu`` of it at ``theta = 1``::

    lambda_min(theta) >= 1 - theta (1 - mu),  theta = (1 - MARGIN) / (1 - mu)  if mu < MARGIN.

It is estimated whenever the contact's springs are formed (below), so it
follows the state.  A system still met with a direction of non-positive
curvature (the estimate is from above) is solved again with ``theta`` scaled by
:data:`BACKOFF`, and with ``W`` clipped at zero below :data:`MIN_SOFTENING`
(either counted as ``coarse_clipped``).  The coarse
system is solved to a relative residual of :data:`INNER_TOLERANCE`, alike on
every rank (the coarse fields are summed over the ranks first), so the result
does not depend on the decomposition beyond round-off.

Under load control the mean mode is free; the coarse grid's mean mode gets the
compliance of the cell's longest wave, and the springs give it the stiffness
of the contact, which no fixed guess of it has (:mod:`petgap.solvers.gap_cg`).

Cost per iteration: the free set's springs and ``R r`` ride on the pass that
writes the residual, the prolongation on the pass that sums the preconditioned
residual; a transform pair of the
coarse grid per coarse iteration (the coarse conjugate gradients run on the
fields' ``rfft2``, where ``H`` is a multiplier; :func:`coarse_transforms` picks the
library), and no transform of the fine grid
but the contact's springs.  Those are ``R (1_C K 1_C)`` itself, one transform pair
of the fine grid, formed again only once the contact has moved by more than
:data:`RESPRING` of its points (counted per coarse cell in the residual's pass),
and with them the softening's scale (:data:`LANCZOS_STEPS` pairs of the coarse grid):
in the flat middle of a solve, when the set has settled, none.  Why the contact's
own and not an estimate from its edge: where the interface is sticky the coarse
model sees the balance of the springs and the softening cell by cell, and an
estimate right in sum but off by tens of per cent in a cell leaves that balance
wrong there (``docs/design.md``, the two-level preconditioner).
"""
import numpy as np
from mpi4py import MPI

from petgap.solvers import _kernels as _k

#: Pixels between coarse nodes (the side of a coarse cell).  The springs and the
#: softening of one patch's edge must fall into cells of their own for the coarse model to
#: see their balance: on the sticky side cells of 16 took a quarter to a half more
#: iterations (docs/design.md).  Smaller cells would make the coarse system too large to solve on
#: every rank.
BLOCK = 8
#: The coarse grid has at most this many nodes a side, larger cells beyond (past
#: 16384^2): the coarse system is solved on every rank, by transforms of the coarse grid.
MAX_SIDE = 1024
#: With fewer nodes a side the cell is too small for the term to matter.
MIN_SIDE = 4
#: Relative residual of the coarse system's conjugate gradients, and their limit.  The
#: outer iteration, Polak-Ribiere+, tolerates a preconditioner that varies a little; but
#: on a sticky state the coarse system's smallest eigenvalues belong to the nearly
#: singular long waves the term exists for, which its conjugate gradients resolve last,
#: and a looser residual leaves them wrong and costs outer iterations where they are
#: dearest (docs/design.md, the two-level preconditioner).
INNER_TOLERANCE = 1e-6
MAX_INNER = 500
#: The contact's springs ``R (1_C K 1_C)`` are computed again (one transform pair of the
#: fine grid) once the points at the wall, counted per coarse cell, have changed by more
#: than this fraction of their number since they were last computed (module docstring).
RESPRING = 0.002
#: Smallest eigenvalue the coarse system ``I + H W H`` is kept at by the softening's scale
#: (module docstring).  Near zero the term amplifies a mode the true operator holds stiff;
#: 0.2 costs a sticky solve an iteration or two more than 0.1 (docs/design.md).
MARGIN = 0.1
#: Lanczos steps of the estimate of that eigenvalue (a fraction of one inner solve's cost).
LANCZOS_STEPS = 40
#: The softening's scale after a coarse system still found indefinite, and the scale below
#: which the softening is left out (the springs clipped at zero).
BACKOFF = 0.8
MIN_SOFTENING = 0.3
#: Seed of the Lanczos estimate's start (any fixed field; the same on every rank).
LANCZOS_SEED = 20
#: Aliases of the hats' spectrum summed a side for the coarse compliance (their
#: weight falls like the fourth power of the alias' order).
ALIASES = 4
#: From this many coarse nodes a side the coarse system is transformed by SciPy, below it
#: by NumPy (:func:`coarse_transforms`).
SCIPY_SIDE = 512


def coarse_transforms(shape):
    """The module whose ``rfft2`` / ``irfft2`` transform a coarse grid of ``shape``.

    Why two: on large coarse grids SciPy's transforms are markedly faster than
    NumPy's, and the coarse system costs some sixty pairs per fine iteration;
    on small ones the two are about as fast, and importing ``scipy.fft`` in a
    process that has not would cost a small solve more time and memory than the
    transforms save.  Both are pocketfft: the results agree to round-off.
    Depends on the shape only, never on the ranks.
    """
    if max(shape) >= SCIPY_SIDE:
        # deferred: importing SciPy changes warning filters, which `import petgap` must not do
        from scipy import fft
        return fft
    return np.fft


def block_for(shape):
    """The coarse cell's side in pixels for a grid of ``shape``, or 0 (no coarse term)."""
    nx, ny = shape
    b = BLOCK
    while max(nx, ny) // b > MAX_SIDE:
        b *= 2
    if nx % b or ny % b or min(nx, ny) // b < MIN_SIDE:
        return 0
    return b


def softening_for(smallest):
    """The softening's scale ``theta`` that keeps ``I + H (W_C + theta W_D) H`` at least
    :data:`MARGIN`, given ``smallest``, the system's smallest eigenvalue at ``theta = 1``
    (the concavity bound of the module docstring)."""
    if smallest >= MARGIN:
        return 1.0
    return (1.0 - MARGIN) / (1.0 - smallest)


def _hat_spectrum(k, n, b):
    """DFT of the periodic hat of half-width ``b`` on ``n`` points at integer wavenumbers ``k``."""
    s = np.sin(np.pi * k / n)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = np.sin(np.pi * k * b / n) ** 2 / (b * s * s)
    return np.where(k % n == 0, float(b), value)


def coarse_compliance(shape, size, block, contact_modulus):
    """``rfft2`` symbol of ``Fc = R K^{-1} P`` on the coarse grid (zero mean mode)."""
    (nx, ny), (lx, ly), b = shape, size, block
    ncx, ncy = nx // b, ny // b
    # each of the b aliases of a coarse wavenumber once (all of them for small b)
    orders = np.arange(-min(ALIASES, b // 2), min(ALIASES + 1, b - b // 2))
    kx = np.arange(ncx)[:, None] + ncx * orders[None, :]
    ky = np.arange(ncy // 2 + 1)[:, None] + ncy * orders[None, :]
    hx, hy = _hat_spectrum(kx, nx, b), _hat_spectrum(ky, ny, b)
    qx = 2 * np.pi * ((kx + nx // 2) % nx - nx // 2) / lx
    qy = 2 * np.pi * ((ky + ny // 2) % ny - ny // 2) / ly
    symbol = np.zeros((ncx, ncy // 2 + 1))
    for a in range(len(orders)):
        for c in range(len(orders)):
            q = np.hypot(qx[:, a][:, None], qy[:, c][None, :])
            with np.errstate(divide="ignore"):
                inverse = np.where(q > 0, 2.0 / (contact_modulus * q), 0.0)
            symbol += (hx[:, a][:, None] * hy[:, c][None, :]) ** 2 * inverse
    return symbol / float(b) ** 4


class CoarseTerm:
    """The coarse term of one gap solve: its springs, restriction and correction.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    contact_modulus : float
        ``E*`` of the half-space.
    block : int
        Pixels between coarse nodes (:func:`block_for`).
    mean_compliance : float
        Under load control, the compliance the preconditioner gives the mean mode
        (``c`` of :mod:`petgap.solvers.gap_cg`); the coarse grid's mean mode then
        carries it too, and the springs stiffen it as the contact does.  Zero under
        mean-gap control, whose directions have no mean.
    """

    def __init__(self, grid, contact_modulus, block, mean_compliance=0.0):
        self.grid, self.block = grid, block
        self.x0 = grid.x_slice.start
        self.coarse_shape = (grid.shape[0] // block, grid.shape[1] // block)
        self.transforms = coarse_transforms(self.coarse_shape)
        self.symbol = coarse_compliance(grid.shape, (grid.Lx, grid.Ly), block, contact_modulus)
        self.symbol[0, 0] = mean_compliance
        self.root_symbol = np.sqrt(self.symbol)   # H = Fc^{1/2}
        # the rfft2 columns that are their own mirrors (Parseval's sums, _dot)
        self.own_mirror = (0, -1) if self.coarse_shape[1] % 2 == 0 else (0,)
        self.springs = np.zeros(self.coarse_shape)
        self.rhs = np.zeros(self.coarse_shape)
        self.contact = self.counts = None      # the contact's springs, and its counts then
        self.softening = 1.0                   # theta of the module docstring
        self.stale = True
        self.inner_iterations = self.clipped = self.respring = 0

    def _summed(self, local):
        self.grid.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        return local / float(self.block) ** 2

    def write_residual(self, f, s):
        """The residual into the FFT buffer (as :func:`petgap.solvers._kernels.gcg_write_residual`),
        and in the same pass ``R r`` and the springs ``W`` of the current gap.

        The contact's springs ``R (1_C K 1_C)`` are formed first, in the buffer, when
        they are stale: a transform pair, made again only once the contact has moved
        by more than :data:`RESPRING` of its points (counted per coarse cell, in the
        residual's pass).  ``f`` and ``s`` are the gap solver's fields and scalars
        (:class:`petgap.solvers.gap_cg._Fields`, :class:`petgap.solvers.gap_cg._State`).
        """
        fresh = self.stale   # True until the first springs are formed
        if fresh:
            _k.contact_indicator(f.g, f.padded)
            f.half_space.apply_in_buffer(inverse=False)               # K 1_C
            local = np.zeros(self.coarse_shape)
            _k.contact_springs(f.g, f.padded, self.x0, self.block, local)
            self.contact = self._summed(local)
            self.respring += 1
        local = np.zeros((3,) + self.coarse_shape)
        _k.coarse_residual(f.pel, f.g, f.vp, f.vpp, f.adhesive, f.divisor, s.lam_f, s.lam,
                           f.padded, self.x0, self.block, local[0], local[1], local[2])
        free, self.rhs, counts = self._summed(local)
        self.form_springs(free, estimate=fresh)
        if fresh:
            self.counts, self.stale = counts, False
        else:
            moved = float(np.abs(counts - self.counts).sum())
            self.stale = moved > RESPRING * float(self.counts.sum())

    def form_springs(self, free, estimate):
        """``W = W_C + theta W_D`` from the contact's springs and the free set's ``free``;
        ``theta`` estimated afresh (:func:`softening_for`) when ``estimate``, else kept."""
        if estimate:
            self.softening = softening_for(self.smallest_eigenvalue(self.contact + free))
        self.springs = self.contact + self.softening * free

    def _dot(self, a, b):
        """``sum a b`` of two real coarse fields given by their ``rfft2`` (Parseval, up to ``1/N``).

        The half plane holds every other column once and its mirror implicitly:
        twice its sum, less the columns that are their own mirrors.  Each such column
        is copied before its product: ``vdot`` of a strided complex column (BLAS
        ``zdotc`` with a stride, OpenBLAS 0.3.21 of Debian 12) reads past the array's
        end, which kills the process where the array ends at an unmapped page (the
        last column of a 1024^2 coarse grid's ``rfft2``).
        """
        dot = 2.0 * np.vdot(a, b).real
        for c in self.own_mirror:
            dot -= np.vdot(np.ascontiguousarray(a[:, c]), np.ascontiguousarray(b[:, c])).real
        return float(dot)

    def smallest_eigenvalue(self, springs):
        """Lanczos estimate (from above) of the smallest eigenvalue of ``I + H W H``.

        :data:`LANCZOS_STEPS` steps from a fixed random field, the same on every rank
        (the springs are summed over the ranks first): one transform pair of the coarse
        grid a step.
        """
        rng = np.random.default_rng(LANCZOS_SEED)
        x = self.transforms.rfft2(rng.standard_normal(self.coarse_shape))
        x /= np.sqrt(self._dot(x, x))
        previous, off = np.zeros_like(x), 0.0
        diagonal, offdiagonal = [], []
        for _ in range(LANCZOS_STEPS):
            y = self._apply(springs, x)
            a = self._dot(x, y)
            diagonal.append(a)
            y -= a * x + off * previous
            off = np.sqrt(self._dot(y, y))
            if not off > 1e-12 * abs(a) or len(diagonal) == LANCZOS_STEPS:
                break
            offdiagonal.append(off)
            previous, x = x, y / off
        tridiagonal = (np.diag(diagonal) + np.diag(offdiagonal, 1) + np.diag(offdiagonal, -1))
        return float(np.linalg.eigvalsh(tridiagonal)[0])

    def _apply(self, springs, x):
        """``(I + H W H) x`` on the ``rfft2`` of ``x``: one transform pair of the coarse grid."""
        fft = self.transforms
        return x + self.root_symbol * fft.rfft2(
            springs * fft.irfft2(self.root_symbol * x, s=self.coarse_shape))

    def _solve(self, springs, b):
        """``(I + H W H)^{-1} b`` by conjugate gradients, or None where it is not positive.

        The vectors are kept as their ``rfft2`` (``b`` too): ``H`` is a multiplier
        there and ``W`` one in real space, so an iteration costs one transform pair
        of the coarse grid, and inner products are Parseval's over the half plane.
        """
        x = np.zeros_like(b)
        res, norm = b.copy(), float(np.sqrt(self._dot(b, b)))
        if norm == 0.0:
            return x
        d, rr = res.copy(), norm * norm
        for _ in range(MAX_INNER):
            ad = self._apply(springs, d)
            curvature = self._dot(d, ad)
            if not curvature > 0:
                return None
            alpha = rr / curvature
            x += alpha * d
            res -= alpha * ad
            rr_new = self._dot(res, res)
            self.inner_iterations += 1
            if np.sqrt(rr_new) <= INNER_TOLERANCE * norm:
                break
            d = res + (rr_new / rr) * d
            rr = rr_new
        return x

    def correction(self):
        """The coarse field ``y = Fc R r - H v`` whose prolongation ``P y`` is subtracted from
        ``K^{-1} r`` (module docstring), in the pass that sums the preconditioned residual
        (:func:`petgap.solvers._kernels.gcg_precond_sums`)."""
        fft = self.transforms
        rhs = fft.rfft2(self.rhs)
        hr = self.root_symbol * rhs
        v = self._solve(self.springs, hr)
        while v is None:
            # the softening outweighs the springs on some long wave: less of it, or none
            self.clipped += 1
            free = self.springs - self.contact
            if self.softening * BACKOFF < MIN_SOFTENING:
                v = self._solve(np.maximum(self.springs, 0.0), hr)
                break
            self.springs = self.contact + BACKOFF * free
            self.softening *= BACKOFF
            v = self._solve(self.springs, hr)
        return fft.irfft2(self.symbol * rhs - self.root_symbol * v, s=self.coarse_shape)
