# cython: language_level=3
"""Kernels of the pressure-based solver on a contact set stored as an index list.

At the contact fractions of rough contact (a few percent), most of what a
Polonsky-Keer iteration does concerns the contact set ``S`` only: the pressure,
the conjugate direction and the gap are zero or irrelevant elsewhere.  Storing
them densely makes each iteration stream half a dozen full slabs through
memory, which at 1024^2 costs about as much as a third FFT pair and evicts the
FFT buffers from the cache.  Here ``S`` is kept as sorted index lists and the
quantities on it as compressed vectors, so that an iteration makes a single
full pass over the slab (:func:`gap_pass`, which only reads) besides the
transforms, which take their input from the index lists and give their output
back on them (:meth:`petgap.mechanics.half_space.ElasticHalfSpace.apply_sparse`).

Index conventions: ``idx`` holds flat indices into this rank's unpadded
``(nx_local, ny)`` slabs (topography, contact mask), ``pidx`` the matching
flat indices into the padded layout of the FFT buffer,
``(nx_local, 2 (ny // 2 + 1))``, in which the solver also keeps the
displacement.
Both are sorted ascending, so gathers and scatters walk memory forwards.
They are 32-bit (``numpy.int32``), which halves their share of the set's
memory; :class:`petgap.solvers.contact_set.ContactSet` refuses slabs with 2^31 padded
points or more (on one rank, some 17 GB per field).

Every function works on this rank's data only and returns partial sums or
extrema for the caller to reduce over MPI.
"""
import numpy as np

from libc.string cimport memset

ctypedef int index_t  # numpy.int32: flat indices into one rank's (padded) slab


def gather_gap(const double[:, ::1] src, const index_t[::1] sidx, const double[:, ::1] h,
               const index_t[::1] idx, double offset, double[::1] gS):
    """``gS = src - h + offset`` on S (``src`` indexed by ``sidx``); returns ``sum gS``."""
    cdef Py_ssize_t k, ns = idx.shape[0]
    cdef double v, s = 0.0
    cdef const double *sf
    cdef const double *hf
    if ns == 0:
        return 0.0
    sf = &src[0, 0]
    hf = &h[0, 0]
    with nogil:
        for k in range(ns):
            v = sf[sidx[k]] - hf[idx[k]] + offset
            gS[k] = v
            s += v
    return s


def shift_and_norms(double[::1] gS, double shift):
    """``gS -= shift``; returns ``(max |gS|, sum gS^2)``: the in-contact gap residual."""
    cdef Py_ssize_t k, ns = gS.shape[0]
    cdef double v, a, in_max = 0.0, norm = 0.0
    with nogil:
        for k in range(ns):
            v = gS[k] - shift
            gS[k] = v
            norm += v * v
            a = v if v >= 0.0 else -v
            if a > in_max:
                in_max = a
    if norm != norm:
        in_max = norm   # a NaN anywhere: reported, never hidden
    return in_max, norm


def gap_pass(const double[:, ::1] src, const double[:, ::1] h, const unsigned char[:, ::1] mask,
             double offset, index_t[::1] overlap):
    """The one full pass of an iteration, over the gap ``g = src - h + offset``.

    ``src`` holds the displacement in the padded layout (only its first
    ``h.shape[1]`` columns are read).  Finds the largest penetration
    ``max(-g)`` off S and writes the flat (unpadded) indices of the points off
    S with ``g < 0`` to ``overlap`` (as many as fit).  It only reads: the
    preconditioner takes ``g`` on S from the index lists.

    Returns ``(penetration, number of overlap points)``; when the number
    exceeds ``len(overlap)`` the caller grows the buffer and calls
    :func:`collect_overlap`.  A NaN anywhere in ``g`` makes the penetration NaN.

    Each row is swept first by a branch-free loop the compiler vectorises
    (counts only); only rows with penetrating points off S are swept again,
    from cache, to record them.
    """
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], cap = overlap.shape[0]
    cdef Py_ssize_t count = 0
    cdef long row_negative, row_nan, nan_total = 0
    cdef double v, pen = 0.0
    cdef const double *sr
    cdef const double *hr
    cdef const unsigned char *mr
    if src.shape[0] != m or src.shape[1] < n or mask.shape[0] != m or mask.shape[1] != n:
        raise ValueError("gap_pass: src, h and mask do not describe the same slab")
    with nogil:
        for i in range(m):
            sr = &src[i, 0]
            hr = &h[i, 0]
            mr = &mask[i, 0]
            row_negative = 0
            row_nan = 0
            for j in range(n):
                v = sr[j] - hr[j] + offset
                row_negative += (mr[j] == 0) & (v < 0.0)
                row_nan += v != v
            nan_total += row_nan
            if row_negative:
                for j in range(n):
                    v = sr[j] - hr[j] + offset
                    if mr[j] == 0 and v < 0.0:
                        if count < cap:
                            overlap[count] = i * n + j
                        count += 1
                        if -v > pen:
                            pen = -v
    if nan_total:
        pen = float("nan")   # reported, never hidden
    return pen, count


def collect_overlap(const double[:, ::1] u, const double[:, ::1] h,
                    const unsigned char[:, ::1] mask, double offset, index_t[::1] overlap):
    """Flat indices of the points off S with ``u - h + offset < 0``; returns their number.

    ``u`` may be padded (only its first ``h.shape[1]`` columns are read).
    """
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], cap = overlap.shape[0]
    cdef Py_ssize_t count = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                if not mask[i, j] and u[i, j] - h[i, j] + offset < 0.0:
                    if count < cap:
                        overlap[count] = i * n + j
                    count += 1
    return count


def z_sums(const double[::1] zS, const double[::1] gS):
    """Returns ``(sum z, sum g z)`` over S: ``z`` the preconditioned gap on S."""
    cdef Py_ssize_t k, ns = zS.shape[0]
    cdef double z, sz = 0.0, sgz = 0.0
    with nogil:
        for k in range(ns):
            z = zS[k]
            sz += z
            sgz += gS[k] * z
    return sz, sgz


def direction(const double[::1] zS, double zshift, double beta, double[::1] tS):
    """``tS = (zS - zshift) + beta tS``: the conjugate direction on S."""
    cdef Py_ssize_t k, ns = tS.shape[0]
    with nogil:
        for k in range(ns):
            tS[k] = zS[k] - zshift + beta * tS[k]


def direction_from_buffer(const double[:, ::1] pad, const index_t[::1] pidx, double zshift,
                          double beta, double[::1] tS):
    """``tS = (pad - zshift) + beta tS`` on S: :func:`direction` reading ``z`` where
    the preconditioner left it, so that no vector of S is spent on holding it."""
    cdef Py_ssize_t k, ns = tS.shape[0]
    cdef const double *pf
    if ns == 0:
        return
    pf = &pad[0, 0]
    with nogil:
        for k in range(ns):
            tS[k] = pf[pidx[k]] - zshift + beta * tS[k]


def step_sums(const double[:, ::1] pad, const index_t[::1] pidx, const double[::1] gS,
              const double[::1] tS):
    """Returns ``(sum r, sum g t, sum r t, sum t)`` over S with ``r = pad = K^{-1} P_S t``."""
    cdef Py_ssize_t k, ns = pidx.shape[0]
    cdef double r, t, sr = 0.0, sgt = 0.0, srt = 0.0, st = 0.0
    cdef const double *pf
    if ns == 0:
        return 0.0, 0.0, 0.0, 0.0
    pf = &pad[0, 0]
    with nogil:
        for k in range(ns):
            r = pf[pidx[k]]
            t = tS[k]
            sr += r
            sgt += gS[k] * t
            srt += r * t
            st += t
    return sr, sgt, srt, st


def update(double[::1] pS, const double[::1] tS, const double[::1] gS, double tau,
           double entry):
    """``pS = max(pS - tau tS, 0)``, or ``-entry gS`` where that is <= 0 and ``gS < 0``.

    ``entry`` turns a penetration into a pressure (see :func:`overlap_pressures`).

    Returns ``(points of S re-entering by overlap, points of S clipped, sum pS)``.
    """
    cdef Py_ssize_t k, ns = pS.shape[0]
    cdef double v, total = 0.0
    cdef long clipped = 0, overlap = 0
    with nogil:
        for k in range(ns):
            v = pS[k] - tau * tS[k]
            if v <= 0.0:
                clipped += 1
                v = 0.0
                if gS[k] < 0.0:
                    v = -entry * gS[k]
                    overlap += 1
            pS[k] = v
            total += v
    return overlap, clipped, total


def overlap_pressures(const double[:, ::1] u, const double[:, ::1] h, const index_t[::1] points,
                      double offset, double entry, double[::1] out):
    """``out = -entry g`` at the overlap points off S, ``g = u - h + offset``; returns the sum.

    ``points`` are flat indices into ``h``'s unpadded slab; ``u`` may be
    padded.  ``entry`` has the units of a stiffness (pressure per length): the
    caller chooses it so that a penetration becomes a pressure of the right
    scale.
    """
    cdef Py_ssize_t k, q, np_ = points.shape[0], n = h.shape[1], w = u.shape[1]
    cdef double v, s = 0.0
    cdef const double *uf
    cdef const double *hf
    if np_ == 0:
        return 0.0
    uf = &u[0, 0]
    hf = &h[0, 0]
    with nogil:
        for k in range(np_):
            q = points[k]
            v = -entry * (uf[(q // n) * w + q % n] - hf[q] + offset)
            out[k] = v
            s += v
    return s


def merge(index_t[::1] idx, index_t[::1] pidx, double[::1] pS, double[::1] tS, Py_ssize_t size,
          const index_t[::1] added, const double[::1] added_p, unsigned char[:, ::1] mask,
          Py_ssize_t padded_width):
    """The new contact set, in place: points of S with ``pS > 0`` merged with the added points.

    ``idx, pidx, pS, tS`` are buffers whose first ``size`` entries hold S; their
    length must be at least the number of points kept plus the number of added
    points with a positive pressure (``size + len(added)`` always suffices).
    ``added`` (sorted, disjoint from S) enter with pressure ``added_p`` (those
    with ``added_p <= 0`` stay out) and a zero direction.  ``mask`` is updated.
    Returns the new size.

    Working in place is what keeps the set's memory to one copy: S is first
    compacted forwards (the write position never passes the read position),
    then merged with the added points backwards from the new end (the write
    position never falls below the unread part of S).  ``pidx`` moves with
    ``idx`` and is computed for the added points only: the integer division it
    takes would otherwise cost a pass over the whole set, which matters while
    the set is large (the first iterations of a cold start).
    """
    cdef Py_ssize_t ns = size, na = added.shape[0]
    cdef Py_ssize_t n = mask.shape[1], a, k, kept = 0, w, extra = 0
    cdef unsigned char *mf
    cdef long point
    for k in range(na):
        if added_p[k] > 0.0:
            extra += 1
    if ns > pS.shape[0]:
        raise ValueError(f"contact-set size {ns} exceeds its buffers ({pS.shape[0]})")
    for k in range(ns):
        if pS[k] > 0.0:
            kept += 1
    if kept + extra > idx.shape[0] or not (
            pidx.shape[0] == pS.shape[0] == tS.shape[0] == idx.shape[0]):
        raise ValueError(f"contact-set buffers of length {idx.shape[0]} cannot hold "
                         f"{kept} + {extra} points")
    kept = 0
    if mask.shape[0] == 0:
        return 0
    mf = &mask[0, 0]
    with nogil:
        for k in range(ns):
            if pS[k] > 0.0:
                idx[kept] = idx[k]
                pidx[kept] = pidx[k]
                pS[kept] = pS[k]
                tS[kept] = tS[k]
                kept += 1
            else:
                mf[idx[k]] = 0
        k = kept - 1
        a = na - 1
        w = kept + extra - 1
        while w > k:
            if added_p[a] <= 0.0:
                a -= 1
                continue
            if k >= 0 and idx[k] > added[a]:
                idx[w] = idx[k]
                pidx[w] = pidx[k]
                pS[w] = pS[k]
                tS[w] = tS[k]
                k -= 1
            else:
                point = added[a]
                idx[w] = point
                pidx[w] = point + (point // n) * (padded_width - n)
                pS[w] = added_p[a]
                tS[w] = 0.0
                mf[point] = 1
                a -= 1
            w -= 1
    return kept + extra


def recurrence(double[:, ::1] u, const double[:, ::1] pad, double tau, double scale,
               Py_ssize_t columns):
    """``u = scale (u - tau r)`` with ``r = pad``, on the first ``columns`` columns.

    The displacement of the updated pressure, both fields in the padded layout.
    """
    cdef Py_ssize_t i, j, m = u.shape[0]
    cdef double *ur
    cdef const double *rr
    if pad.shape[0] != m or columns > u.shape[1] or columns > pad.shape[1]:
        raise ValueError("recurrence: u and pad do not describe the same slab")
    with nogil:
        for i in range(m):
            ur = &u[i, 0]
            rr = &pad[i, 0]
            for j in range(columns):
                ur[j] = scale * (ur[j] - tau * rr[j])


# ----------------------------------------------------------------------------
# The first iteration of a cold start from a uniform pressure, in closed form.
#
# With p = P0 on every point, u = K^{-1} p = 0 (no q = 0 mode), so the gap,
# shifted to zero mean over S (everywhere), is g = mean(h) - h; the
# preconditioned gap is z = K g; the direction is t = z - mean(z); its image
# r = K^{-1} t = g; and the step tau = (g, t) / (r, t) = 1.  The iteration thus
# needs one transform (K g) where the general one takes three, and no set of
# every point.  These kernels are its three passes over the slab.

def uniform_gap(double[:, ::1] pad, const double[:, ::1] h, double hbar):
    """``pad = hbar - h`` (0 in the padding); returns ``(max |pad|, sum pad^2)``."""
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], w = pad.shape[1]
    cdef double v, a, gmax = 0.0, norm = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = hbar - h[i, j]
                pad[i, j] = v
                norm += v * v
                a = v if v >= 0.0 else -v
                if a > gmax:
                    gmax = a
            for j in range(n, w):
                pad[i, j] = 0.0
    if norm != norm:
        gmax = norm   # a NaN anywhere: reported, never hidden
    return gmax, norm


def uniform_sums(const double[:, ::1] pad, const double[:, ::1] h, double hbar):
    """Returns ``(sum z, sum (hbar - h) z)`` with ``z = pad`` (the preconditioned gap)."""
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double z, sz = 0.0, sgz = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                z = pad[i, j]
                sz += z
                sgz += (hbar - h[i, j]) * z
    return sz, sgz


def uniform_step(const double[:, ::1] pad, const double[:, ::1] h, double hbar, double zshift,
                 double pressure, double entry, double[:, ::1] p):
    """``p = max(pressure - (z - zshift), 0)``, or ``entry (h - hbar)`` where that is
    <= 0 and the point penetrates (``h > hbar``): :func:`update` with ``tau = 1``.

    Returns ``(points re-entering by overlap, points clipped, sum p)``.
    """
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double v, total = 0.0
    cdef long clipped = 0, overlap = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = pressure - (pad[i, j] - zshift)
                if v <= 0.0:
                    clipped += 1
                    v = 0.0
                    if h[i, j] > hbar:
                        v = entry * (h[i, j] - hbar)
                        overlap += 1
                p[i, j] = v
                total += v
    return overlap, clipped, total


def final_gap(const double[:, ::1] src, const double[:, ::1] h, const unsigned char[:, ::1] mask,
              double offset, double[:, ::1] out):
    """``out <- g = src - h + offset`` projected onto the contact state found.

    ``src`` may be padded (the displacement where the solver keeps it), and
    ``out`` may be the first ``m * n`` values of ``src``'s own storage: each
    value is read before the value written over it (rows are processed in
    order, and row ``i`` moves to an offset ``i n <= i w``).
    Returns the gap KKT residuals taken before the projection, ``(max |g| on
    S, max(-g) off S)``; then ``g = 0`` on S and ``g = max(g, 0)`` elsewhere.
    One pass where NumPy took five.  A NaN makes the residual NaN.
    """
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double v, a, on = 0.0, off = 0.0
    cdef long nan = 0
    if (src.shape[0] != m or src.shape[1] < n or out.shape[0] != m or out.shape[1] != n
            or mask.shape[0] != m or mask.shape[1] != n):
        raise ValueError("final_gap: src, h, mask and out do not describe the same slab")
    with nogil:
        for i in range(m):
            for j in range(n):
                v = src[i, j] - h[i, j] + offset
                nan += v != v
                if mask[i, j]:
                    a = v if v >= 0.0 else -v
                    if a > on:
                        on = a
                    v = 0.0
                else:
                    if -v > off:
                        off = -v
                    if v < 0.0:
                        v = 0.0
                out[i, j] = v
    if nan:
        return float("nan"), float("nan")   # reported, never hidden
    return on, off
