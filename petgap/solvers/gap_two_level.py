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
system is solved to a relative residual of :data:`INNER_TOLERANCE`.

Under load control the mean mode is free; the coarse grid's mean mode gets the
compliance of the cell's longest wave, and the springs give it the stiffness
of the contact, which no fixed guess of it has (:mod:`petgap.solvers.gap_cg`).

Cost per iteration: the free set's springs and ``R r`` ride on the pass that
writes the residual, the prolongation on the pass that sums the preconditioned
residual; a transform pair of the coarse grid per coarse iteration (the coarse
conjugate gradients run on the fields' spectra, where ``H`` is a multiplier), and
no transform of the fine grid but the contact's springs.  Those are
``R (1_C K 1_C)`` itself, one transform pair
of the fine grid, formed again only once the contact has moved by more than
:data:`RESPRING` of its points (counted per coarse cell in the residual's pass),
and with them the softening's scale (a Lanczos estimate: a few pairs of the coarse grid
from the last estimate's Ritz vector, up to :data:`LANCZOS_STEPS` the first time):
in the flat middle of a solve, when the set has settled, none.  Why the contact's
own and not an estimate from its edge: where the interface is sticky the coarse
model sees the balance of the springs and the softening cell by cell, and an
estimate right in sum but off by tens of per cent in a cell leaves that balance
wrong there (``docs/design.md``, the two-level preconditioner).

The coarse system lives on a grid of its own (:func:`coarse_grid`) with petgap's
FFTW-MPI transforms, split over the fine grid's ranks: the fine slabs' sums are
reduced onto the coarse slabs, each rank iterates on its part of the spectrum, and
the correction is gathered whole for the prolongation.  Why not solved whole on every
rank: on the sticky side it costs forty coarse pairs and more per fine iteration, a
share of the solve that a copy on every rank would keep while the ranks share the fine
grid's work.  Coarse grids of at most
:data:`WHOLE_POINTS` points (or too few rows for the ranks) are solved whole on every
rank, with FFTW's "estimate" plans (the same arithmetic everywhere): spread over the
ranks their transforms would cost the messages' latency and little else.  Either
way the result does not depend on the decomposition beyond round-off.
"""
import numpy as np
from mpi4py import MPI

from petgap.parallel.grid import DecompositionError, Grid
from petgap.solvers import _kernels as _k

#: Pixels between coarse nodes (the side of a coarse cell).  The springs and the
#: softening of one patch's edge must fall into cells of their own for the coarse model to
#: see their balance: on the sticky side cells of 16 took a quarter to a half more
#: iterations (docs/design.md).  Smaller cells would give the coarse system four times the
#: nodes, and its forty-odd transform pairs per fine iteration, each on a sixteenth of the
#: fine grid's points, would cost more than the fine grid's two.
BLOCK = 8
#: The coarse grid has at most this many nodes a side, larger cells beyond (past 8192^2),
#: so that its forty-odd transform pairs per fine iteration stay a fraction of the fine pair.
MAX_SIDE = 1024
#: With fewer nodes a side the cell is too small for the term to matter.
MIN_SIDE = 4
#: Relative residual of the coarse system's conjugate gradients, and their limit.  The
#: outer iteration, Polak-Ribiere+, tolerates a preconditioner that varies a little: solved
#: to 1e-3 the coarse system takes half the inner iterations and the outer ones stay, up to
#: 8192^2 on the sticky side.  But under load control the coarse grid carries the mean
#: mode, and a loose solve leaves the converged residual a mean of one sign: within the
#: tolerance at every point, yet summed over the free set it is the contact's share of the
#: load, which a one-pixel contact then misses by 1.7e-8 of itself at KKT 1e-9 (1.6e-11 at
#: 1e-6; tests/solvers/test_extremes.py, docs/design.md).
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
#: Most Lanczos steps of the estimate of that eigenvalue (a fraction of one inner solve's
#: cost), and the Ritz residual it stops at: a hundredth of :data:`MARGIN`, so that the
#: softened system's smallest eigenvalue lands within that of the margin.
LANCZOS_STEPS = 40
LANCZOS_TOLERANCE = 1e-3
#: Share (in norm) of the fixed random field in a Lanczos start from the last Ritz vector.
LANCZOS_MIX = 0.3
#: The softening's scale after a coarse system still found indefinite, and the scale below
#: which the softening is left out (the springs clipped at zero).
BACKOFF = 0.8
MIN_SOFTENING = 0.3
#: Coarse systems of at most this many nodes are solved whole on every rank, larger ones
#: split over the ranks (module docstring).  Split over two ranks, an inner iteration of a
#: 256^2 system takes three quarters of its time whole, of a 128^2 one 0.7-0.9, of a 64^2
#: one as long (``benchmarks/coarse_system.py``, docs/design.md).
WHOLE_POINTS = 64 * 64
#: Seed of the Lanczos estimate's start (any fixed field; the same on every rank count).
LANCZOS_SEED = 20
#: Aliases of the hats' spectrum summed a side for the coarse compliance (their
#: weight falls like the fourth power of the alias' order).
ALIASES = 4


def coarse_grid(grid, block):
    """The grid of the coarse system of ``grid`` at cells of ``block`` pixels (module
    docstring): on ``grid``'s ranks with its planner and wisdom, or whole on every rank
    (``MPI.COMM_SELF``, FFTW's "estimate") where it has at most :data:`WHOLE_POINTS`
    points or too few rows for the ranks.  Collective."""
    shape = (grid.nx // block, grid.ny // block)
    size = (grid.Lx, grid.Ly)
    if grid.comm.size == 1 or shape[0] * shape[1] > WHOLE_POINTS:
        try:   # Grid checks the decomposition first, on every rank alike
            return Grid(shape, size=size, comm=grid.comm, planner=grid.planner,
                        wisdom=grid.wisdom)
        except DecompositionError:
            pass
    return Grid(shape, size=size, comm=MPI.COMM_SELF, planner="estimate", wisdom=False)


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


def _tridiagonal(diagonal, offdiagonal):
    """The symmetric tridiagonal matrix of a Lanczos recurrence."""
    return np.diag(diagonal) + np.diag(offdiagonal, 1) + np.diag(offdiagonal, -1)


def _hat_spectrum(k, n, b):
    """DFT of the periodic hat of half-width ``b`` on ``n`` points at integer wavenumbers ``k``."""
    s = np.sin(np.pi * k / n)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = np.sin(np.pi * k * b / n) ** 2 / (b * s * s)
    return np.where(k % n == 0, float(b), value)


def coarse_compliance(shape, size, block, contact_modulus):
    """Symbol of ``Fc = R K^{-1} P`` on the coarse grid in NumPy's ``rfft2`` layout (zero mean
    mode); :class:`CoarseTerm` takes its rows of the transpose, FFTW-MPI's layout."""
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

    Conventions: the coarse fields held here (``springs``, ``contact``, ``rhs``) are this
    rank's rows of the coarse grid (:attr:`cgrid`'s slab; all of them where it is whole);
    the vectors of the coarse conjugate gradients are this rank's part of their spectrum,
    in the FFTW-MPI transposed layout, unnormalised (:meth:`spectrum`, :meth:`space`).
    """

    def __init__(self, grid, contact_modulus, block, mean_compliance=0.0):
        self.grid, self.block = grid, block
        self.x0 = grid.x_slice.start
        #: The coarse system's grid (:func:`coarse_grid`).
        self.cgrid = cgrid = coarse_grid(grid, block)
        self.coarse_shape = cgrid.shape
        self.split = cgrid.comm.size > 1      # the coarse slabs are parts, not the whole
        if self.split:
            width = self.coarse_shape[1]
            self.slab_sizes = [rows * width for rows in
                               grid.comm.allgather(cgrid.local_shape[0])]
        symbol = coarse_compliance(grid.shape, (grid.Lx, grid.Ly), block, contact_modulus)
        symbol[0, 0] = mean_compliance
        # this rank's rows of the transposed half plane (ky, kx), as FFTW-MPI gives them
        self.symbol = np.ascontiguousarray(symbol.T[cgrid.ky_slice])
        self.root_symbol = np.sqrt(self.symbol)   # H = Fc^{1/2}
        self.root_scaled = self.root_symbol / float(cgrid.npoints)   # with the pair's 1/N
        self.springs = np.zeros(cgrid.local_shape)
        self.rhs = np.zeros(cgrid.local_shape)
        self.contact = self.counts = None      # the contact's springs, and its counts then
        self.softening = 1.0                   # theta of the module docstring
        self.ritz = self.noise = None          # the Lanczos estimate's last Ritz vector, start
        self.stale = True
        self.inner_iterations = self.clipped = self.respring = self.lanczos_steps = 0

    def _restricted(self, local):
        """This rank's coarse rows of the sum over the ranks of ``local`` (whole coarse
        fields of partial sums, as the restriction kernels write them), over ``b^2``."""
        comm = self.grid.comm
        if self.split:
            out = np.empty(self.cgrid.local_shape)
            comm.Reduce_scatter(local, out, recvcounts=self.slab_sizes, op=MPI.SUM)
            local = out
        elif comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        return local / float(self.block) ** 2

    def _gathered(self, slab):
        """The whole coarse field from every rank's ``slab`` (the prolongation reads it)."""
        if not self.split:
            return slab
        whole = np.empty(self.coarse_shape)
        self.grid.comm.Allgatherv(slab, [whole, self.slab_sizes])
        return whole

    def _total(self, slab):
        """``sum`` of a coarse field over the whole coarse grid."""
        return self._reduced(float(slab.sum()))

    def spectrum(self, slab):
        """This rank's part of the (unnormalised) transform of a coarse field given by its
        rows: a new array in the transposed layout."""
        np.copyto(self.cgrid.real, slab)
        return self.cgrid.forward().copy()

    def space(self, spectrum):
        """This rank's rows of the coarse field whose transform is ``spectrum``."""
        np.copyto(self.cgrid.fourier, spectrum)
        return self.cgrid.backward() * (1.0 / self.cgrid.npoints)

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
            self.contact = self._restricted(local)
            self.respring += 1
        local = np.zeros((3,) + self.coarse_shape)
        _k.coarse_residual(f.pel, f.g, f.vp, f.vpp, f.adhesive, f.divisor, s.lam_f, s.lam,
                           f.padded, self.x0, self.block, local[0], local[1], local[2])
        free, self.rhs, counts = (self._restricted(part) for part in local)
        self.form_springs(free, estimate=fresh)
        if fresh:
            self.counts, self.stale = counts, False
        else:
            moved = self._total(np.abs(counts - self.counts))
            self.stale = moved > RESPRING * self._total(self.counts)

    def form_springs(self, free, estimate):
        """``W = W_C + theta W_D`` from the contact's springs and the free set's ``free``;
        ``theta`` estimated afresh (:func:`softening_for`) when ``estimate``, else kept."""
        if estimate:
            self.softening = softening_for(self.smallest_eigenvalue(self.contact + free))
        self.springs = self.contact + self.softening * free

    def _dot(self, a, b):
        """``sum a b`` of two real coarse fields given by their spectra (Parseval, up to ``N``):
        the half plane's rows weighted by the modes each stands for, summed over the ranks
        where the coarse grid is split (:meth:`petgap.parallel.grid.Grid.fourier_sum`)."""
        return self.cgrid.fourier_sum((np.conj(a) * b).real)

    def _reduced(self, local):
        """A sum over the coarse grid from this rank's part of it."""
        return self.cgrid.comm.allreduce(local, op=MPI.SUM) if self.split else local

    def smallest_eigenvalue(self, springs):
        """Lanczos estimate (from above) of the smallest eigenvalue of ``I + H W H``.

        The first estimate starts from a fixed random field, the same on every rank
        count; each later one from the last estimate's Ritz vector with
        :data:`LANCZOS_MIX` of that field.  Why: between two estimates the contact's
        springs have moved by a fraction of a per cent of its points, so the last Ritz
        vector is nearly the new one, and Lanczos from it converges in a few steps where
        the random start takes thirty to forty; the random share keeps a softer mode
        that has appeared elsewhere (a patch grown) within the recurrence's reach.  The
        recurrence stops once the Ritz pair's residual is below
        :data:`LANCZOS_TOLERANCE` (or after :data:`LANCZOS_STEPS` steps); a second run
        of it, the same vectors bit for bit, sums the Ritz vector, so that no Lanczos
        vector is held.  A step costs one transform pair of the coarse grid and the
        fused passes of the conjugate gradients (:meth:`_solve`).
        """
        if self.noise is None:
            rng = np.random.default_rng(LANCZOS_SEED)
            self.noise = self.spectrum(rng.standard_normal(self.coarse_shape)[self.cgrid.x_slice])
            self.noise /= np.sqrt(self._dot(self.noise, self.noise))
        start = self.noise.copy()
        if self.ritz is not None:
            start *= LANCZOS_MIX
            start += self.ritz * (1.0 / np.sqrt(self._dot(self.ritz, self.ritz)))
        diagonal, offdiagonal = [], []
        for _, a, off in self._lanczos(springs, start):
            diagonal.append(a)
            if len(diagonal) == LANCZOS_STEPS or not off > 1e-12 * abs(a):
                break
            if len(diagonal) > 1:
                _, vectors = np.linalg.eigh(_tridiagonal(diagonal, offdiagonal))
                if off * abs(vectors[-1, 0]) <= LANCZOS_TOLERANCE:   # the Ritz residual
                    break
            offdiagonal.append(off)
        values, vectors = np.linalg.eigh(_tridiagonal(diagonal, offdiagonal))
        self.ritz = np.zeros_like(start)
        for c, (x, _, _) in zip(vectors[:, 0], self._lanczos(springs, start)):
            self.ritz += c * x
        return float(values[0])

    def _lanczos(self, springs, x):
        """The Lanczos recurrence of ``I + H W H`` from ``x`` (a spectrum, left as it is):
        yields each step's unit vector ``x_k``, ``x_k . (I + H W H) x_k`` and the norm of
        the next vector before its normalisation (a buffer the next step overwrites)."""
        weight = self.cgrid.hermitian_weight
        x = x * (1.0 / np.sqrt(self._dot(x, x)))
        previous, y, off = np.zeros_like(x), np.empty_like(x), 0.0
        while True:
            a = self._reduced(_k.coarse_cg_image(self._image(springs, x), self.root_scaled,
                                                 x, y, weight))
            self.lanczos_steps += 1
            off = np.sqrt(self._reduced(_k.coarse_lanczos_residual(y, x, previous, a, off,
                                                                   weight)))
            yield x, a, off
            y *= 1.0 / off
            previous, x, y = x, y, previous

    def _image(self, springs, x=None):
        """``FFT(W IFFT(H x))``, unnormalised, in the coarse grid's Fourier buffer: one
        transform pair of the coarse grid.  ``(I + H W H) x`` is ``x + H image / N``.
        Without ``x`` the buffer already holds ``H x``."""
        c = self.cgrid
        if x is not None:
            np.multiply(self.root_symbol, x, out=c.fourier)
        real = c.backward()
        np.multiply(real, springs, out=real)
        return c.forward()

    def _solve(self, springs, b):
        """``(I + H W H)^{-1} b`` by conjugate gradients, or None where it is not positive.

        The vectors are kept as their spectra (``b`` too): ``H`` is a multiplier there
        and ``W`` one in real space, so an iteration costs one transform pair of the
        coarse grid (:meth:`_image`) and three fused passes
        (:mod:`petgap.solvers._kernels`), and inner products are Parseval's over the half
        plane.
        """
        weight = self.cgrid.hermitian_weight
        x = np.zeros_like(b)
        res, norm = b.copy(), float(np.sqrt(self._dot(b, b)))
        if norm == 0.0:
            return x
        d, ad = np.zeros_like(b), np.empty_like(b)
        rr, beta = norm * norm, 0.0
        for _ in range(MAX_INNER):
            _k.coarse_cg_direction(d, res, beta, self.root_symbol, self.cgrid.fourier)
            curvature = self._reduced(_k.coarse_cg_image(self._image(springs), self.root_scaled,
                                                         d, ad, weight))
            if not curvature > 0:
                return None
            alpha = rr / curvature
            rr_new = self._reduced(_k.coarse_cg_step(x, res, d, ad, alpha, weight))
            self.inner_iterations += 1
            if np.sqrt(rr_new) <= INNER_TOLERANCE * norm:
                break
            beta, rr = rr_new / rr, rr_new
        return x

    def correction(self):
        """The whole coarse field ``y = Fc R r - H v`` whose prolongation ``P y`` is
        subtracted from ``K^{-1} r`` (module docstring), in the pass that sums the
        preconditioned residual (:func:`petgap.solvers._kernels.gcg_precond_sums`)."""
        rhs = self.spectrum(self.rhs)
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
        return self._gathered(self.space(self.symbol * rhs - self.root_symbol * v))
