# cython: language_level=3
"""Fused loops for the solvers' per-iteration work.

Each function makes one pass over this rank's slab and returns the partial
sums or extrema the caller reduces over MPI.  Arrays are this rank's
``(nx_local, ny)`` C-contiguous slabs; ``real`` is the grid's padded FFT buffer
``(nx_local, 2 (ny // 2 + 1))`` of which the first ``ny`` columns are used.
Fusing matters: a NumPy pass over a slab costs a sizeable fraction of an FFT
pair, and an unfused iteration would spend more time in passes than in FFTs.

The pressure-based (Polonsky-Keer) solver keeps its contact set as index
lists instead; its kernels are in ``petgap/solvers/_contact_set.pyx``.
"""
from libc.math cimport fabs, INFINITY

import numpy as np


# ---------------------------------------------------------------------------
# Gap-space preconditioned projected CG (petgap.solvers.gap_cg).  The gradient of the
# energy per pixel area is ``grad = p_el + v'(g)``; ``vp`` caches ``v'(g)``, filled
# once per iteration by the interaction law's own kernel
# (:mod:`petgap.mechanics.interactions._laws`); for the hard wall ``adh`` is false
# and ``vp`` is not read.  The free set F is ``g > 0`` or ``grad + lam_f < 0``
# (points at the wall that are pulled off it).


def gcg_open_sums(const double[:, ::1] pel, const double[:, ::1] g,
                  const double[:, ::1] vp, bint adh, double shift=0.0):
    """Returns ``(sum of grad + shift over g > 0, count of g > 0)``: the multiplier estimate.

    ``shift`` is the last estimate of the multiplier, so that the summands are
    residuals, not gradients (:func:`petgap.solvers.gap_cg._multiplier`).
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double s = 0.0
    cdef long count = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                if g[i, j] > 0.0:
                    s += pel[i, j] + (vp[i, j] if adh else 0.0) + shift
                    count += 1
    return s, count


def gcg_free_sums(const double[:, ::1] pel, const double[:, ::1] g, const double[:, ::1] vp,
                  bint adh, double lam_f, double lam_pull=INFINITY, double shift=0.0):
    """Returns ``(sum_F grad + shift, count_F, max_F grad, min_F grad, strong)``.

    ``strong`` counts the points at the wall with ``grad + lam_pull < 0``: those
    pulled off it beyond ``lam_pull`` (the gap solver's strong releases).  ``shift``
    as in :func:`gcg_open_sums`.
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double gr, s = 0.0, gmax = -INFINITY, gmin = INFINITY
    cdef long count = 0, strong = 0
    cdef bint free
    with nogil:
        for i in range(m):
            for j in range(n):
                gr = pel[i, j] + (vp[i, j] if adh else 0.0)
                if g[i, j] > 0.0:
                    free = True
                else:
                    free = gr + lam_f < 0.0
                    if gr + lam_pull < 0.0:
                        strong += 1
                if free:
                    s += gr + shift
                    count += 1
                    if gr > gmax:
                        gmax = gr
                    if gr < gmin:
                        gmin = gr
    return s, count, gmax, gmin, strong


cdef inline double _free_residual(double pel, double g, double vp, bint adh, double lam_f,
                                  double lam) noexcept nogil:
    """``grad + lam`` at a point of F, 0 elsewhere."""
    cdef double gr = pel + (vp if adh else 0.0)
    if g > 0.0 or gr + lam_f < 0.0:
        return gr + lam
    return 0.0


def gcg_write_residual(const double[:, ::1] pel, const double[:, ::1] g,
                       const double[:, ::1] vp, bint adh, double lam_f, double lam,
                       double[:, ::1] real):
    """``real = grad + lam`` on F, 0 elsewhere (the residual to precondition)."""
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    with nogil:
        for i in range(m):
            for j in range(n):
                real[i, j] = _free_residual(pel[i, j], g[i, j], vp[i, j], adh, lam_f, lam)


def gcg_precond_sums(double[:, ::1] real, const double[:, ::1] pel,
                     const double[:, ::1] g, const double[:, ::1] vp, bint adh,
                     double lam_f, double lam, double[:, ::1] r_old=None,
                     const double[:, ::1] t=None, const double[:, ::1] y=None,
                     Py_ssize_t x0=0, Py_ssize_t b=0):
    """Returns ``(sum_F z, sum_F r z, sum_F r)`` with ``z = real``, ``r = grad + lam``.

    With ``r_old`` (and ``t``) also ``(sum_F z r_old, sum_F r_old, sum_F t)``, and
    then ``r_old = r`` on F and 0 elsewhere: the Polak-Ribiere term and the old
    direction's mean over F of :func:`petgap.solvers.gap_cg._beta`.  With ``y`` (a
    coarse field, whole on every rank; ``x0`` this rank's first row, ``b`` the coarse
    cell's side) ``real -= P y`` first, in the same pass: the coarse term's correction
    (:mod:`petgap.solvers.gap_two_level`, :func:`_prolonged_row`).
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double gr, z, sz = 0.0, srz = 0.0, sr = 0.0, szr = 0.0, so = 0.0, st = 0.0
    cdef bint cross = r_old is not None, coarse = y is not None
    cdef double[::1] scratch = np.zeros(y.shape[1] if coarse else 1)
    cdef double[::1] prolonged = np.zeros(n if coarse else 1)
    cdef double* zrow
    cdef double* prow = &prolonged[0]
    with nogil:
        for i in range(m):
            if coarse:
                _prolonged_row(y, x0 + i, b, &scratch[0], prow)
                zrow = &real[i, 0]
                for j in range(n):
                    zrow[j] -= prow[j]
            for j in range(n):
                gr = pel[i, j] + (vp[i, j] if adh else 0.0)
                if g[i, j] > 0.0 or gr + lam_f < 0.0:
                    z = real[i, j]
                    sz += z
                    srz += (gr + lam) * z
                    sr += gr + lam
                    if cross:
                        szr += z * r_old[i, j]
                        so += r_old[i, j]
                        st += t[i, j]
                        r_old[i, j] = gr + lam
                elif cross:
                    r_old[i, j] = 0.0
    if cross:
        return sz, srz, sr, szr, so, st
    return sz, srz, sr


def gcg_direction(double[:, ::1] real, const double[:, ::1] pel, const double[:, ::1] g,
                  const double[:, ::1] vp, const double[:, ::1] vpp, bint adh,
                  double[:, ::1] t, double lam_f, double zshift, double beta, double lam,
                  double divisor):
    """``t = -(z - zshift) + beta t`` on F, 0 elsewhere (``z = real``); then ``real = t``.

    Returns the pointwise part of the step's data along the new ``t``, in the
    same pass: ``(sum v''(g) t^2, sum (grad + lam) t, max |t|)``.  ``v''`` is
    ``vpp`` where the law fills that field, otherwise ``-v' / divisor`` (the
    law's ``curvature_from_stress``: ``rho`` for the exponential, ``inf`` for a
    law with ``v'' = 0``).  The elastic part ``t.K t`` needs the transform of
    ``t`` (:func:`gcg_image_sum`, or by Parseval in the transform's forward half).
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double gr, v, e, curv = 0.0, slope = 0.0, tmax = 0.0
    cdef bint second = vpp is not None
    with nogil:
        for i in range(m):
            for j in range(n):
                e = vp[i, j] if adh else 0.0
                gr = pel[i, j] + e
                if g[i, j] > 0.0 or gr + lam_f < 0.0:
                    v = -(real[i, j] - zshift) + beta * t[i, j]
                else:
                    v = 0.0
                t[i, j] = v
                real[i, j] = v
                if v == 0.0:
                    continue
                if adh:
                    if second:
                        curv += vpp[i, j] * v * v
                    else:
                        curv -= (e / divisor) * v * v
                    slope += (pel[i, j] + e + lam) * v
                else:
                    slope += (pel[i, j] + lam) * v
                if fabs(v) > tmax:
                    tmax = fabs(v)
    return curv, slope, tmax


def gcg_image_sum(const double[:, ::1] real, const double[:, ::1] t):
    """Returns ``sum t (K t)`` with ``real`` holding ``K t``: where the transform has no halves."""
    cdef Py_ssize_t i, j, m = t.shape[0], n = t.shape[1]
    cdef double curv = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                curv += t[i, j] * real[i, j]
    return curv


def gcg_step(double[:, ::1] g, const double[:, ::1] t, double tau):
    """``g += tau t``; returns ``(points below zero, sum and count of the points above zero)``.

    The last two are :func:`shifted_positive_sums` at ``mu = 0``: the mean-gap
    projection's first Newton data (a step keeps the mean, so its shift starts
    at zero), summed while the new gap passes by.
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double v, s = 0.0
    cdef long negative = 0, count = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = g[i, j] + tau * t[i, j]
                g[i, j] = v
                if v < 0.0:
                    negative += 1
                elif v > 0.0:
                    s += v
                    count += 1
    return negative, s, count


def axpy(double[:, ::1] y, const double[:, ::1] x, double a):
    """``y += a x`` (x may be the padded FFT buffer)."""
    cdef Py_ssize_t i, j, m = y.shape[0], n = y.shape[1]
    with nogil:
        for i in range(m):
            for j in range(n):
                y[i, j] += a * x[i, j]


def shifted_positive_sums(const double[:, ::1] y, double mu):
    """Returns ``(sum max(y + mu, 0), count(y + mu > 0))`` over points off the wall.

    The mean-gap projection's Newton data.  Points exactly at the wall
    (``y == 0``: in contact and not moved by the step) stay there: the
    projection acts on the face of the constraint set the iteration is on, so
    that a shift never lifts the whole contact area off the wall.
    """
    cdef Py_ssize_t i, j, m = y.shape[0], n = y.shape[1]
    cdef double v, s = 0.0
    cdef long count = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                if y[i, j] == 0.0:
                    continue
                v = y[i, j] + mu
                if v > 0.0:
                    s += v
                    count += 1
    return s, count


def project_and_load(double[:, ::1] g, double mu, const double[:, ::1] h, double[:, ::1] real):
    """``g = max(g + mu, 0)`` off the wall (``g == 0`` stays), and ``real = g + h``."""
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double v
    with nogil:
        for i in range(m):
            for j in range(n):
                v = g[i, j]
                if v != 0.0:
                    v = v + mu
                if v < 0.0:
                    v = 0.0
                g[i, j] = v
                real[i, j] = v + h[i, j]


def copy_from(double[:, ::1] y, const double[:, ::1] x):
    """``y = x`` (x may be the padded FFT buffer)."""
    cdef Py_ssize_t i, j, m = y.shape[0], n = y.shape[1]
    with nogil:
        for i in range(m):
            for j in range(n):
                y[i, j] = x[i, j]


# ---------------------------------------------------------------------------
# The coarse term of the gap preconditioner (petgap.solvers.gap_two_level).  Coarse
# node ``(I, J)`` sits on fine point ``(I b, J b)``; a fine point gives its bilinear
# hat weights to the four nodes around it (periodically).  ``x0`` is the global index
# of this rank's first row; the coarse arrays are whole on every rank.
#
# A restriction runs down a band of ``b`` fine rows (those of coarse row ``I``): each
# row is added into two row-long sums, weighted ``1 - fx`` and ``fx`` for the coarse
# rows ``I`` and ``I + 1`` -- two multiply-adds per point along contiguous memory,
# which vectorise -- and only at the band's end (or the slab's) are the two sums
# folded along the row onto the coarse nodes: folding every fine row instead costs a
# chain of dependent additions per point, on top of the pass's memory traffic.

cdef class _Band:
    """The two row-long sums of one restriction (above) and their fold onto ``out``."""
    cdef double[::1] lo, hi, acc, w
    cdef Py_ssize_t b, n, band

    def __cinit__(self, Py_ssize_t n, Py_ssize_t ncy, Py_ssize_t b):
        self.lo = np.zeros(n)
        self.hi = np.zeros(n)
        self.acc = np.zeros(ncy)
        self.w = np.arange(b) / <double>b
        self.b, self.n, self.band = b, n, -1

    cdef void add(self, const double* row, double[:, ::1] out, Py_ssize_t gi) noexcept nogil:
        """Add fine row ``gi`` (global index) to the band's sums, folding the last band first."""
        cdef Py_ssize_t j, I = gi // self.b
        cdef double fx = <double>(gi - I * self.b) / self.b, fl = 1.0 - fx
        cdef double* lo = &self.lo[0]
        cdef double* hi = &self.hi[0]
        if I != self.band:
            self.fold(out)
            self.band = I
        for j in range(self.n):
            lo[j] += fl * row[j]
            hi[j] += fx * row[j]

    cdef void fold(self, double[:, ::1] out) noexcept nogil:
        """``out[I] +=`` and ``out[I + 1] +=`` the hat-weighted sums of the band's two sums."""
        if self.band < 0:
            return
        cdef Py_ssize_t ncx = out.shape[0], I = self.band
        cdef Py_ssize_t I1 = I + 1 if I + 1 < ncx else 0
        self._fold_row(&self.lo[0], out, I)
        self._fold_row(&self.hi[0], out, I1)
        self.band = -1

    cdef void _fold_row(self, double* row, double[:, ::1] out, Py_ssize_t I) noexcept nogil:
        """``out[I, J] +=`` the hats of ``row`` along it; ``row`` is zeroed for the next band."""
        cdef Py_ssize_t ncy = out.shape[1], J, J1, k, b = self.b
        cdef double lo, hi, v
        cdef double* acc = &self.acc[0]
        cdef double* w = &self.w[0]
        for J in range(ncy):
            acc[J] = 0.0
        for J in range(ncy):
            lo = 0.0
            hi = 0.0
            for k in range(b):
                v = row[J * b + k]
                lo += v - w[k] * v
                hi += w[k] * v
                row[J * b + k] = 0.0
            J1 = J + 1 if J + 1 < ncy else 0
            acc[J] += lo
            acc[J1] += hi
        for J in range(ncy):
            out[I, J] += acc[J]


def coarse_residual(const double[:, ::1] pel, const double[:, ::1] g, const double[:, ::1] vp,
                    const double[:, ::1] vpp, bint adh, double divisor, double lam_f,
                    double lam, double[:, ::1] real, Py_ssize_t x0, Py_ssize_t b,
                    double[:, ::1] springs, double[:, ::1] rhs, double[:, ::1] counts):
    """:func:`gcg_write_residual` and, in the same pass, the coarse grid's data.

    ``rhs += R r`` (times ``b^2``) of the residual written; ``springs +=`` the same
    of the free set's springs, ``v''(g)`` off the wall (``vpp``, or ``-v' / divisor``
    where the law fills no ``v''`` field, as in :func:`gcg_direction`; nothing for the
    hard wall; the contact's own come from :func:`contact_springs`); ``counts +=``
    the points at the wall in each coarse cell (cell ``(I, J)`` holds the pixels
    ``I b .. I b + b - 1`` by ``J b .. J b + b - 1``).
    """
    cdef Py_ssize_t i, j, J, m = g.shape[0], n = g.shape[1], ncy = rhs.shape[1]
    cdef double at_wall, gr, gv
    cdef bint second = vpp is not None
    cdef double[::1] row = np.zeros(n)
    cdef double[::1] zeros = np.zeros(n)
    cdef double* rrow
    cdef double* srow = &row[0]
    cdef const double* grow
    cdef const double* prow
    cdef const double* e
    cdef const double* c
    cdef double scale = 1.0
    cdef _Band residual = _Band(n, ncy, b), free = _Band(n, ncy, b)
    with nogil:
        for i in range(m):
            # without branches in the loops, so that they vectorise: the hard wall reads
            # zeros for v', and v'' is ``vpp`` or ``-v' / divisor``
            rrow, grow, prow = &real[i, 0], &g[i, 0], &pel[i, 0]
            e = &vp[i, 0] if adh else &zeros[0]
            if second:
                c = &vpp[i, 0]
            else:
                c, scale = e, -1.0 / divisor
            for j in range(n):
                gv = grow[j]
                gr = prow[j] + e[j]
                rrow[j] = gr + lam if (gv > 0.0 or gr + lam_f < 0.0) else 0.0
            # the row is in cache: the softening and the wall's counts in loops of their own
            for j in range(n):
                srow[j] = scale * c[j] if grow[j] > 0.0 else 0.0
            for J in range(ncy):
                at_wall = 0.0
                for j in range(J * b, J * b + b):
                    at_wall += 1.0 if grow[j] <= 0.0 else 0.0
                counts[(x0 + i) // b, J] += at_wall
            residual.add(rrow, rhs, x0 + i)
            free.add(srow, springs, x0 + i)
        residual.fold(rhs)
        free.fold(springs)


def contact_indicator(const double[:, ::1] g, double[:, ::1] real):
    """``real = 1_C``, the contact set's indicator (``g <= 0``), on the first columns."""
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    with nogil:
        for i in range(m):
            for j in range(n):
                real[i, j] = 1.0 if g[i, j] <= 0.0 else 0.0


def contact_springs(const double[:, ::1] g, double[:, ::1] real, Py_ssize_t x0,
                    Py_ssize_t b, double[:, ::1] springs):
    """``springs += R (1_C real)`` (times ``b^2``): with ``real = K 1_C``, the contact's springs.

    ``real`` is left holding ``1_C real`` (the FFT buffer, read once).
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef _Band band = _Band(n, springs.shape[1], b)
    with nogil:
        for i in range(m):
            for j in range(n):
                if g[i, j] > 0.0:
                    real[i, j] = 0.0
            band.add(&real[i, 0], springs, x0 + i)
        band.fold(springs)


cdef void _prolonged_row(const double[:, ::1] y, Py_ssize_t gi, Py_ssize_t b, double* c,
                         double* out) noexcept nogil:
    """``out`` = fine row ``gi`` (global index) of ``P y``, ``P`` the bilinear prolongation.

    ``c`` is scratch of the coarse row's length: the row is first interpolated between the
    two coarse rows around it, then along itself.
    """
    cdef Py_ssize_t ncx = y.shape[0], ncy = y.shape[1], k, J, J1
    cdef Py_ssize_t I = gi // b
    cdef Py_ssize_t I1 = I + 1 if I + 1 < ncx else 0
    cdef double fx = <double>(gi - I * b) / b, a, d
    for J in range(ncy):
        c[J] = (1.0 - fx) * y[I, J] + fx * y[I1, J]
    for J in range(ncy):
        J1 = J + 1 if J + 1 < ncy else 0
        a = c[J]
        d = c[J1] - a
        for k in range(b):
            out[J * b + k] = a + (<double>k / b) * d


# ---------------------------------------------------------------------------
# The coarse system's conjugate gradients (petgap.solvers.gap_two_level.CoarseTerm).  The
# vectors are this rank's rows of a half-plane spectrum, each row standing for ``weight``
# rows of the full plane (1 or 2: Parseval's inner products).  Three passes an iteration
# around the transform pair, where NumPy makes eleven: the coarse system is bound by
# memory traffic as the fine passes are.


def coarse_cg_direction(double complex[:, ::1] d, const double complex[:, ::1] res,
                        double beta, const double[:, ::1] root, double complex[:, ::1] out):
    """``d = res + beta d``, and ``out = root d`` (the transform's input)."""
    cdef Py_ssize_t i, j, m = d.shape[0], n = d.shape[1]
    cdef double complex v
    with nogil:
        for i in range(m):
            for j in range(n):
                v = res[i, j] + beta * d[i, j]
                d[i, j] = v
                out[i, j] = root[i, j] * v


def coarse_cg_image(const double complex[:, ::1] image, const double[:, ::1] scale,
                    const double complex[:, ::1] d, double complex[:, ::1] ad,
                    const double[::1] weight):
    """``ad = d + scale image``; returns ``sum weight Re(conj(d) ad)``, Parseval's ``d.ad``."""
    cdef Py_ssize_t i, j, m = d.shape[0], n = d.shape[1]
    cdef double complex v
    cdef double s, total = 0.0
    with nogil:
        for i in range(m):
            s = 0.0
            for j in range(n):
                v = d[i, j] + scale[i, j] * image[i, j]
                ad[i, j] = v
                s += d[i, j].real * v.real + d[i, j].imag * v.imag
            total += weight[i] * s
    return total


cdef double _less_norm(double complex *y, const double complex *x, double a,
                      const double complex *p, double b, Py_ssize_t n) noexcept nogil:
    """``y -= a x + b p`` along one row; returns ``sum |y|^2`` of the row."""
    cdef Py_ssize_t j
    cdef double complex v
    cdef double s = 0.0
    for j in range(n):
        v = y[j] - a * x[j] - b * p[j]
        y[j] = v
        s += v.real * v.real + v.imag * v.imag
    return s


def coarse_cg_step(double complex[:, ::1] x, double complex[:, ::1] res,
                   const double complex[:, ::1] d, const double complex[:, ::1] ad,
                   double alpha, const double[::1] weight):
    """``x += alpha d``, ``res -= alpha ad``; returns ``sum weight |res|^2``."""
    cdef Py_ssize_t i, j, m = d.shape[0], n = d.shape[1]
    cdef double total = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                x[i, j] = x[i, j] + alpha * d[i, j]
            total += weight[i] * _less_norm(&res[i, 0], &ad[i, 0], alpha, &ad[i, 0], 0.0, n)
    return total


def coarse_lanczos_residual(double complex[:, ::1] y, const double complex[:, ::1] x,
                            const double complex[:, ::1] previous, double a, double b,
                            const double[::1] weight):
    """``y -= a x + b previous`` (the Lanczos three-term step); returns ``sum weight |y|^2``."""
    cdef Py_ssize_t i, m = y.shape[0], n = y.shape[1]
    cdef double total = 0.0
    with nogil:
        for i in range(m):
            total += weight[i] * _less_norm(&y[i, 0], &x[i, 0], a, &previous[i, 0], b, n)
    return total
