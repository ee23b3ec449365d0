# cython: language_level=3
"""Kernels of the pressure-based solver on a contact set stored as an index list.

At the contact fractions of rough contact (a few percent), most of what a
Polonsky-Keer iteration does concerns the contact set ``S`` only: the pressure,
the conjugate direction and the gap are zero or irrelevant elsewhere.  Storing
them densely makes each iteration stream half a dozen full slabs through
memory, which costs about as much as another FFT pair and evicts the
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

Precision: the fields (topography ``h``, displacement ``u``, the FFT buffer
``pad``, and the vectors on S: ``pS, tS, gS, zS``, ``added_p``, ``out``) are
either all ``float64`` or all ``float32`` in one call (``real_t``; single
precision halves the memory and the bandwidth of the passes, which is what they
cost).  Mixing the two raises a ``TypeError`` naming the arrays, rather than
converting a field behind the caller's back.  Scalars (``offset``, ``shift``,
``tau``, ...) are always ``double``, and so is the arithmetic: each value is
computed in double from the fields' values and, where a kernel stores it in a
``float32`` array, rounded once, explicitly, on the way in.  Sums and extrema
are accumulated and returned in double; where a kernel stores the values it
sums, it sums them as stored, so that a returned sum describes the array the
caller holds (e.g. ``sum pS`` after :func:`update`, which restores the load).
A ``float32`` call thus gives the ``float64`` call on the same data rounded to
``float32``, to within that one rounding per stored value.  In the ``float64``
path the casts change nothing: it computes what plain ``double`` kernels do,
bit for bit.

Every function works on this rank's data only and returns partial sums or
extrema for the caller to reduce over MPI.

Implementation: Cython 0.29 cannot declare ``const`` memoryviews of a fused
type as arguments (the compiler crashes), and the read-only inputs must stay
``const`` so that read-only arrays (a memory-mapped topography) are accepted.
Each kernel is therefore a ``def`` that checks the precision of its fields and
calls one of the two specialisations of a ``cdef`` implementation, which takes
the fields as objects and views them as typed (``const``) memoryviews locally;
its first argument (``real_t kind``, a zero) only selects the specialisation.
The two kernels that read the image of the search direction (:func:`step_sums`,
:func:`recurrence`) take a second one (``image_t``) for the image's precision,
which may be single beside double fields (a double solve's single-precision
search).
"""
import numpy as np

from libc.string cimport memset

ctypedef int index_t  # numpy.int32: flat indices into one rank's (padded) slab

ctypedef fused real_t:  # the precision of the fields of one call
    float
    double

ctypedef fused image_t:  # a direction's image: the fields' precision, or float beside double
    float
    double

_FLOAT64 = np.dtype(np.float64)
_FLOAT32 = np.dtype(np.float32)


cdef bint _single(str kernel, str names, tuple fields) except -1:
    """True if the ``fields`` of ``kernel`` are all float32, False if all float64.

    Raises a ``TypeError`` naming each field's dtype otherwise: Cython's own
    check would report a "buffer dtype mismatch" (a ``ValueError``) on whichever
    field it converts second, without saying which precision the call was meant
    to have.
    """
    cdef Py_ssize_t singles = 0, doubles = 0
    dtypes = []
    for field in fields:
        dtype = getattr(field, "dtype", None)
        if dtype is None:
            dtype = np.asarray(field).dtype
        if dtype is _FLOAT64 or dtype == _FLOAT64:
            doubles += 1
        elif dtype is _FLOAT32 or dtype == _FLOAT32:
            singles += 1
        dtypes.append(dtype)
    if singles == 0 and doubles == len(fields):
        return False
    if doubles == 0 and singles == len(fields):
        return True
    described = ", ".join(f"{name} {dtype}" for name, dtype in zip(names.split(), dtypes))
    raise TypeError(f"{kernel}: the field arrays must be all float64 or all float32 "
                    f"(one precision per call), got {described}")


def gather_gap(src, const index_t[::1] sidx, h, const index_t[::1] idx, double offset, gS):
    """``gS = src - h + offset`` on S (``src`` indexed by ``sidx``); returns ``sum gS``."""
    if _single("gather_gap", "src h gS", (src, h, gS)):
        return _gather_gap[float](0, src, sidx, h, idx, offset, gS)
    return _gather_gap[double](0, src, sidx, h, idx, offset, gS)


cdef object _gather_gap(real_t kind, object src_, const index_t[::1] sidx, object h_,
                        const index_t[::1] idx, double offset, object gS_):
    cdef const real_t[:, ::1] src = src_
    cdef const real_t[:, ::1] h = h_
    cdef real_t[::1] gS = gS_
    cdef Py_ssize_t k, ns = idx.shape[0]
    cdef double v, s = 0.0
    cdef const real_t *sf
    cdef const real_t *hf
    if ns == 0:
        return 0.0
    sf = &src[0, 0]
    hf = &h[0, 0]
    with nogil:
        for k in range(ns):
            v = <real_t>(<double>sf[sidx[k]] - <double>hf[idx[k]] + offset)
            gS[k] = <real_t>v
            s += v
    return s


def shift_and_norms(gS, double shift):
    """``gS -= shift``; returns ``(max |gS|, sum gS^2)``: the in-contact gap residual."""
    if _single("shift_and_norms", "gS", (gS,)):
        return _shift_and_norms[float](0, gS, shift)
    return _shift_and_norms[double](0, gS, shift)


cdef object _shift_and_norms(real_t kind, object gS_, double shift):
    cdef real_t[::1] gS = gS_
    cdef Py_ssize_t k, ns = gS.shape[0]
    cdef double v, a, in_max = 0.0, norm = 0.0
    with nogil:
        for k in range(ns):
            v = <real_t>(<double>gS[k] - shift)
            gS[k] = <real_t>v
            norm += v * v
            a = v if v >= 0.0 else -v
            if a > in_max:
                in_max = a
    if norm != norm:
        in_max = norm   # a NaN anywhere: reported, never hidden
    return in_max, norm


def gap_pass(src, h, const unsigned char[:, ::1] mask, double offset, index_t[::1] overlap):
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
    if _single("gap_pass", "src h", (src, h)):
        return _gap_pass[float](0, src, h, mask, offset, overlap)
    return _gap_pass[double](0, src, h, mask, offset, overlap)


cdef object _gap_pass(real_t kind, object src_, object h_, const unsigned char[:, ::1] mask,
                      double offset, index_t[::1] overlap):
    cdef const real_t[:, ::1] src = src_
    cdef const real_t[:, ::1] h = h_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], cap = overlap.shape[0]
    cdef Py_ssize_t count = 0
    cdef long row_negative, row_nan, nan_total = 0
    cdef double v, pen = 0.0
    cdef const real_t *sr
    cdef const real_t *hr
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
                v = <double>sr[j] - <double>hr[j] + offset
                row_negative += (mr[j] == 0) & (v < 0.0)
                row_nan += v != v
            nan_total += row_nan
            if row_negative:
                for j in range(n):
                    v = <double>sr[j] - <double>hr[j] + offset
                    if mr[j] == 0 and v < 0.0:
                        if count < cap:
                            overlap[count] = i * n + j
                        count += 1
                        if -v > pen:
                            pen = -v
    if nan_total:
        pen = float("nan")   # reported, never hidden
    return pen, count


def collect_overlap(u, h, const unsigned char[:, ::1] mask, double offset,
                    index_t[::1] overlap):
    """Flat indices of the points off S with ``u - h + offset < 0``; returns their number.

    ``u`` may be padded (only its first ``h.shape[1]`` columns are read).
    """
    if _single("collect_overlap", "u h", (u, h)):
        return _collect_overlap[float](0, u, h, mask, offset, overlap)
    return _collect_overlap[double](0, u, h, mask, offset, overlap)


cdef object _collect_overlap(real_t kind, object u_, object h_,
                             const unsigned char[:, ::1] mask, double offset,
                             index_t[::1] overlap):
    cdef const real_t[:, ::1] u = u_
    cdef const real_t[:, ::1] h = h_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], cap = overlap.shape[0]
    cdef Py_ssize_t count = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                if not mask[i, j] and <double>u[i, j] - <double>h[i, j] + offset < 0.0:
                    if count < cap:
                        overlap[count] = i * n + j
                    count += 1
    return count


def gap_sums(vS, gS):
    """Returns ``(sum v, sum g v)`` over S: ``v`` the preconditioned gap or the direction."""
    if _single("gap_sums", "vS gS", (vS, gS)):
        return _gap_sums[float](0, vS, gS)
    return _gap_sums[double](0, vS, gS)


cdef object _gap_sums(real_t kind, object vS_, object gS_):
    cdef const real_t[::1] vS = vS_
    cdef const real_t[::1] gS = gS_
    cdef Py_ssize_t k, ns = vS.shape[0]
    cdef double v, sv = 0.0, sgv = 0.0
    with nogil:
        for k in range(ns):
            v = vS[k]
            sv += v
            sgv += <double>gS[k] * v
    return sv, sgv


def direction(zS, double zshift, double beta, tS):
    """``tS = (zS - zshift) + beta tS``: the conjugate direction on S."""
    if _single("direction", "zS tS", (zS, tS)):
        _direction[float](0, zS, zshift, beta, tS)
    else:
        _direction[double](0, zS, zshift, beta, tS)


cdef object _direction(real_t kind, object zS_, double zshift, double beta, object tS_):
    cdef const real_t[::1] zS = zS_
    cdef real_t[::1] tS = tS_
    cdef Py_ssize_t k, ns = tS.shape[0]
    with nogil:
        for k in range(ns):
            tS[k] = <real_t>(<double>zS[k] - zshift + beta * <double>tS[k])


def direction_from_buffer(pad, const index_t[::1] pidx, double zshift, double beta, tS):
    """``tS = (pad - zshift) + beta tS`` on S: :func:`direction` reading ``z`` where
    the preconditioner left it, so that no vector of S is spent on holding it."""
    if _single("direction_from_buffer", "pad tS", (pad, tS)):
        _direction_from_buffer[float](0, pad, pidx, zshift, beta, tS)
    else:
        _direction_from_buffer[double](0, pad, pidx, zshift, beta, tS)


cdef object _direction_from_buffer(real_t kind, object pad_, const index_t[::1] pidx,
                                   double zshift, double beta, object tS_):
    cdef const real_t[:, ::1] pad = pad_
    cdef real_t[::1] tS = tS_
    cdef Py_ssize_t k, ns = tS.shape[0]
    cdef const real_t *pf
    if ns == 0:
        return
    pf = &pad[0, 0]
    with nogil:
        for k in range(ns):
            tS[k] = <real_t>(<double>pf[pidx[k]] - zshift + beta * <double>tS[k])


def step_sums(pad, const index_t[::1] pidx, gS, tS):
    """Returns ``(sum g t, sum r t)`` over S with ``r = pad = K^{-1} P_S t``: a step length's sums.

    ``pad`` may be float32 with double ``gS`` and ``tS``: a double solve's direction
    imaged in single precision (:func:`petgap.solvers.pressure_cg.polonsky_keer`).
    """
    if _mixed(pad, gS) and tS.dtype == _FLOAT64:
        return _step_sums[double, float](0, 0, pad, pidx, gS, tS)
    if _single("step_sums", "pad gS tS", (pad, gS, tS)):
        return _step_sums[float, float](0, 0, pad, pidx, gS, tS)
    return _step_sums[double, double](0, 0, pad, pidx, gS, tS)


cdef bint _mixed(pad, field):
    """True for a float32 ``pad`` beside a float64 ``field``: a single image in a double solve."""
    return pad.dtype == _FLOAT32 and field.dtype == _FLOAT64


cdef object _step_sums(real_t kind, image_t image_kind, object pad_, const index_t[::1] pidx,
                       object gS_, object tS_):
    cdef const image_t[:, ::1] pad = pad_
    cdef const real_t[::1] gS = gS_
    cdef const real_t[::1] tS = tS_
    cdef Py_ssize_t k, ns = pidx.shape[0]
    cdef double t, sgt = 0.0, srt = 0.0
    cdef const image_t *pf
    if ns == 0:
        return 0.0, 0.0
    pf = &pad[0, 0]
    with nogil:
        for k in range(ns):
            t = tS[k]
            sgt += <double>gS[k] * t
            srt += <double>pf[pidx[k]] * t
    return sgt, srt


def update(pS, tS, gS, double tau, double entry):
    """``pS = max(pS - tau tS, 0)``, or ``-entry gS`` where that is <= 0 and ``gS < 0``.

    ``entry`` turns a penetration into a pressure (see :func:`overlap_pressures`).
    The test ``<= 0`` is made on the value as stored, so that in single
    precision a pressure that rounds to zero counts as clipped (and leaves S
    at the next merge) instead of staying in S at zero.

    Returns ``(points of S re-entering by overlap, points of S clipped, sum pS)``.
    """
    if _single("update", "pS tS gS", (pS, tS, gS)):
        return _update[float](0, pS, tS, gS, tau, entry)
    return _update[double](0, pS, tS, gS, tau, entry)


cdef object _update(real_t kind, object pS_, object tS_, object gS_, double tau, double entry):
    cdef real_t[::1] pS = pS_
    cdef const real_t[::1] tS = tS_
    cdef const real_t[::1] gS = gS_
    cdef Py_ssize_t k, ns = pS.shape[0]
    cdef double v, total = 0.0
    cdef long clipped = 0, overlap = 0
    with nogil:
        for k in range(ns):
            v = <real_t>(<double>pS[k] - tau * <double>tS[k])
            if v <= 0.0:
                clipped += 1
                v = 0.0
                if gS[k] < 0.0:
                    v = <real_t>(-entry * <double>gS[k])
                    overlap += 1
            pS[k] = <real_t>v
            total += v
    return overlap, clipped, total


def overlap_pressures(u, h, const index_t[::1] points, double offset, double entry, out):
    """``out = -entry g`` at the overlap points off S, ``g = u - h + offset``; returns the sum.

    ``points`` are flat indices into ``h``'s unpadded slab; ``u`` may be
    padded.  ``entry`` has the units of a stiffness (pressure per length): the
    caller chooses it so that a penetration becomes a pressure of the right
    scale.
    """
    if _single("overlap_pressures", "u h out", (u, h, out)):
        return _overlap_pressures[float](0, u, h, points, offset, entry, out)
    return _overlap_pressures[double](0, u, h, points, offset, entry, out)


cdef object _overlap_pressures(real_t kind, object u_, object h_, const index_t[::1] points,
                               double offset, double entry, object out_):
    cdef const real_t[:, ::1] u = u_
    cdef const real_t[:, ::1] h = h_
    cdef real_t[::1] out = out_
    cdef Py_ssize_t k, q, np_ = points.shape[0], n = h.shape[1], w = u.shape[1]
    cdef double v, s = 0.0
    cdef const real_t *uf
    cdef const real_t *hf
    if np_ == 0:
        return 0.0
    uf = &u[0, 0]
    hf = &h[0, 0]
    with nogil:
        for k in range(np_):
            q = points[k]
            v = <real_t>(-entry * (<double>uf[(q // n) * w + q % n] - <double>hf[q] + offset))
            out[k] = <real_t>v
            s += v
    return s


def merge(index_t[::1] idx, index_t[::1] pidx, pS, tS, Py_ssize_t size,
          const index_t[::1] added, added_p, unsigned char[:, ::1] mask,
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
    if _single("merge", "pS tS added_p", (pS, tS, added_p)):
        return _merge[float](0, idx, pidx, pS, tS, size, added, added_p, mask, padded_width)
    return _merge[double](0, idx, pidx, pS, tS, size, added, added_p, mask, padded_width)


cdef object _merge(real_t kind, index_t[::1] idx, index_t[::1] pidx, object pS_, object tS_,
                   Py_ssize_t size, const index_t[::1] added, object added_p_,
                   unsigned char[:, ::1] mask, Py_ssize_t padded_width):
    cdef real_t[::1] pS = pS_
    cdef real_t[::1] tS = tS_
    cdef const real_t[::1] added_p = added_p_
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


def recurrence(u, pad, double tau, double scale, Py_ssize_t columns):
    """``u = scale (u - tau r)`` with ``r = pad``, on the first ``columns`` columns.

    The displacement of the updated pressure, both fields in the padded layout;
    ``pad`` may be float32 beside a double ``u`` (a direction imaged in single
    precision: its rounding enters the step ``tau r``, not ``u``).
    """
    if _mixed(pad, u):
        _recurrence[double, float](0, 0, u, pad, tau, scale, columns)
    elif _single("recurrence", "u pad", (u, pad)):
        _recurrence[float, float](0, 0, u, pad, tau, scale, columns)
    else:
        _recurrence[double, double](0, 0, u, pad, tau, scale, columns)


cdef object _recurrence(real_t kind, image_t image_kind, object u_, object pad_, double tau,
                        double scale, Py_ssize_t columns):
    cdef real_t[:, ::1] u = u_
    cdef const image_t[:, ::1] pad = pad_
    cdef Py_ssize_t i, j, m = u.shape[0]
    cdef real_t *ur
    cdef const image_t *rr
    if pad.shape[0] != m or columns > u.shape[1] or columns > pad.shape[1]:
        raise ValueError("recurrence: u and pad do not describe the same slab")
    with nogil:
        for i in range(m):
            ur = &u[i, 0]
            rr = &pad[i, 0]
            for j in range(columns):
                ur[j] = <real_t>(scale * (<double>ur[j] - tau * <double>rr[j]))


# ----------------------------------------------------------------------------
# The first iteration of a cold start from a uniform pressure, in closed form.
#
# With p = P0 on every point, u = K^{-1} p = 0 (no q = 0 mode), so the gap,
# shifted to zero mean over S (everywhere), is g = mean(h) - h; the
# preconditioned gap is z = K g; the direction is t = z - mean(z); its image
# r = K^{-1} t = g; and the step tau = (g, t) / (r, t) = 1.  The iteration thus
# needs one transform (K g) where the general one takes three, and no set of
# every point.  These kernels are its three passes over the slab.

def uniform_gap(pad, h, double hbar):
    """``pad = hbar - h`` (0 in the padding); returns ``(max |pad|, sum pad^2)``."""
    if _single("uniform_gap", "pad h", (pad, h)):
        return _uniform_gap[float](0, pad, h, hbar)
    return _uniform_gap[double](0, pad, h, hbar)


cdef object _uniform_gap(real_t kind, object pad_, object h_, double hbar):
    cdef real_t[:, ::1] pad = pad_
    cdef const real_t[:, ::1] h = h_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1], w = pad.shape[1]
    cdef double v, a, gmax = 0.0, norm = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = <real_t>(hbar - <double>h[i, j])
                pad[i, j] = <real_t>v
                norm += v * v
                a = v if v >= 0.0 else -v
                if a > gmax:
                    gmax = a
            for j in range(n, w):
                pad[i, j] = 0.0
    if norm != norm:
        gmax = norm   # a NaN anywhere: reported, never hidden
    return gmax, norm


def uniform_sums(pad, h, double hbar):
    """Returns ``(sum z, sum (hbar - h) z)`` with ``z = pad`` (the preconditioned gap)."""
    if _single("uniform_sums", "pad h", (pad, h)):
        return _uniform_sums[float](0, pad, h, hbar)
    return _uniform_sums[double](0, pad, h, hbar)


cdef object _uniform_sums(real_t kind, object pad_, object h_, double hbar):
    cdef const real_t[:, ::1] pad = pad_
    cdef const real_t[:, ::1] h = h_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double z, sz = 0.0, sgz = 0.0
    with nogil:
        for i in range(m):
            for j in range(n):
                z = pad[i, j]
                sz += z
                sgz += (hbar - <double>h[i, j]) * z
    return sz, sgz


def uniform_step(pad, h, double hbar, double zshift, double pressure, double entry, p):
    """``p = max(pressure - (z - zshift), 0)``, or ``entry (h - hbar)`` where that is
    <= 0 and the point penetrates (``h > hbar``): :func:`update` with ``tau = 1``.

    Returns ``(points re-entering by overlap, points clipped, sum p)``.
    """
    if _single("uniform_step", "pad h p", (pad, h, p)):
        return _uniform_step[float](0, pad, h, hbar, zshift, pressure, entry, p)
    return _uniform_step[double](0, pad, h, hbar, zshift, pressure, entry, p)


cdef object _uniform_step(real_t kind, object pad_, object h_, double hbar, double zshift,
                          double pressure, double entry, object p_):
    cdef const real_t[:, ::1] pad = pad_
    cdef const real_t[:, ::1] h = h_
    cdef real_t[:, ::1] p = p_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double v, total = 0.0
    cdef long clipped = 0, overlap = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = <real_t>(pressure - (<double>pad[i, j] - zshift))
                if v <= 0.0:
                    clipped += 1
                    v = 0.0
                    if h[i, j] > hbar:
                        v = <real_t>(entry * (<double>h[i, j] - hbar))
                        overlap += 1
                p[i, j] = <real_t>v
                total += v
    return overlap, clipped, total


def final_gap(src, h, const unsigned char[:, ::1] mask, double offset, out):
    """``out <- g = src - h + offset`` projected onto the contact state found.

    ``src`` may be padded (the displacement where the solver keeps it), and
    ``out`` may be the first ``m * n`` values of ``src``'s own storage: each
    value is read before the value written over it (rows are processed in
    order, and row ``i`` moves to an offset ``i n <= i w``).
    Returns the gap KKT residuals taken before the projection, ``(max |g| on
    S, max(-g) off S)``, of ``g`` as computed in double; then ``g = 0`` on S
    and ``g = max(g, 0)`` elsewhere.  One pass where NumPy took five.  A NaN
    makes the residual NaN.
    """
    if _single("final_gap", "src h out", (src, h, out)):
        return _final_gap[float](0, src, h, mask, offset, out)
    return _final_gap[double](0, src, h, mask, offset, out)


cdef object _final_gap(real_t kind, object src_, object h_, const unsigned char[:, ::1] mask,
                       double offset, object out_):
    cdef const real_t[:, ::1] src = src_
    cdef const real_t[:, ::1] h = h_
    cdef real_t[:, ::1] out = out_
    cdef Py_ssize_t i, j, m = h.shape[0], n = h.shape[1]
    cdef double v, a, on = 0.0, off = 0.0
    cdef long nan = 0
    if (src.shape[0] != m or src.shape[1] < n or out.shape[0] != m or out.shape[1] != n
            or mask.shape[0] != m or mask.shape[1] != n):
        raise ValueError("final_gap: src, h, mask and out do not describe the same slab")
    with nogil:
        for i in range(m):
            for j in range(n):
                v = <double>src[i, j] - <double>h[i, j] + offset
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
                out[i, j] = <real_t>v
    if nan:
        return float("nan"), float("nan")   # reported, never hidden
    return on, off


# ----------------------------------------------------------------------------
# The contact-edge term of the preconditioner (petgap/solvers/edge_correction.py):
# kappa = K 1_S kept on the whole slab, updated where S changed by adding or
# removing a changed point's window of the stiffness kernel.

def changed_points(const unsigned char[:, ::1] mask, const unsigned char[:, ::1] known,
                   index_t[::1] out):
    """Flat indices where ``mask`` and ``known`` differ, to ``out`` (as many as fit).

    Returns their number, which may exceed ``len(out)``.  Each row is first
    counted by a branch-free loop the compiler vectorises, and only rows with
    changes are swept again, from cache, to record them.
    """
    cdef Py_ssize_t i, j, m = mask.shape[0], n = mask.shape[1], cap = out.shape[0]
    cdef Py_ssize_t count = 0
    cdef long differ
    if known.shape[0] != m or known.shape[1] != n:
        raise ValueError("changed_points: mask and known do not describe the same slab")
    with nogil:
        for i in range(m):
            differ = 0
            for j in range(n):
                differ += mask[i, j] != known[i, j]
            if differ:
                for j in range(n):
                    if mask[i, j] != known[i, j]:
                        if count < cap:
                            out[count] = i * n + j
                        count += 1
    return count


def add_windows(kappa, Py_ssize_t first_row, Py_ssize_t nx, const index_t[::1] rows,
                const index_t[::1] cols, const signed char[::1] signs,
                const double[:, ::1] table, bint wrap=True):
    """``kappa += sign K(x - y)`` over the window ``table`` around each point ``y``.

    ``kappa`` is this rank's slab, whose first row is the global row
    ``first_row`` of an ``nx``-row periodic grid; ``rows``, ``cols`` are the
    global coordinates of the changed points (every rank's, in the same order
    on every rank), ``signs`` +1 where a point entered S and -1 where it left;
    ``table[W + di, W + dj]`` is the stiffness kernel ``K`` at the offset
    ``(di, dj)``, ``|di|, |dj| <= W``.  Rows and columns wrap periodically
    (with ``wrap``; without, a window ends at the map's edges: a free boundary);
    the window must be narrower than the grid (``2 W + 1 <= nx, ny``), so that
    no point of it is visited twice.
    """
    if kappa.dtype == _FLOAT32:
        _add_windows[float](0, kappa, first_row, nx, rows, cols, signs, table, wrap)
    elif kappa.dtype == _FLOAT64:
        _add_windows[double](0, kappa, first_row, nx, rows, cols, signs, table, wrap)
    else:
        raise TypeError(f"add_windows: kappa is {kappa.dtype}, not float64 or float32")


cdef object _add_windows(real_t kind, object kappa_, Py_ssize_t first_row, Py_ssize_t nx,
                         const index_t[::1] rows, const index_t[::1] cols,
                         const signed char[::1] signs, const double[:, ::1] table,
                         bint wrap):
    cdef real_t[:, ::1] kappa = kappa_
    cdef Py_ssize_t m = kappa.shape[0], n = kappa.shape[1], w = table.shape[0] // 2
    cdef Py_ssize_t k, di, dj, r, c
    cdef double s
    if table.shape[0] != table.shape[1] or table.shape[0] % 2 == 0:
        raise ValueError("add_windows: the table must be square with an odd side")
    if 2 * w + 1 > nx or 2 * w + 1 > n:
        raise ValueError(f"add_windows: a window of {2 * w + 1} points does not fit a "
                         f"{nx} x {n} grid")
    if not (rows.shape[0] == cols.shape[0] == signs.shape[0]):
        raise ValueError("add_windows: rows, cols and signs differ in length")
    with nogil:
        for k in range(rows.shape[0]):
            s = signs[k]
            for di in range(-w, w + 1):
                if not wrap and (rows[k] + di < 0 or rows[k] + di >= nx):
                    continue
                r = (rows[k] + di + nx) % nx - first_row
                if r < 0 or r >= m:
                    continue
                for dj in range(-w, w + 1):
                    if not wrap and (cols[k] + dj < 0 or cols[k] + dj >= n):
                        continue
                    c = (cols[k] + dj + n) % n
                    kappa[r, c] = <real_t>(<double>kappa[r, c] + s * table[w + di, w + dj])


def subtract_edge_term(zS, gS, kappa, const index_t[::1] idx, double theta):
    """``zS -= theta kappa[idx] gS``: the preconditioned gap less a share of the edge term."""
    if _single("subtract_edge_term", "zS gS kappa", (zS, gS, kappa)):
        _subtract_edge_term[float](0, zS, gS, kappa, idx, theta)
    else:
        _subtract_edge_term[double](0, zS, gS, kappa, idx, theta)


cdef object _subtract_edge_term(real_t kind, object zS_, object gS_, object kappa_,
                                const index_t[::1] idx, double theta):
    cdef real_t[::1] zS = zS_
    cdef const real_t[::1] gS = gS_
    cdef const real_t[:, ::1] kappa = kappa_
    cdef Py_ssize_t k, ns = zS.shape[0]
    cdef const real_t *kf
    if gS.shape[0] != ns or idx.shape[0] != ns:
        raise ValueError("subtract_edge_term: zS, gS and idx differ in length")
    if ns == 0:
        return
    kf = &kappa[0, 0]
    with nogil:
        for k in range(ns):
            zS[k] = <real_t>(<double>zS[k] - theta * <double>kf[idx[k]] * <double>gS[k])


def edge_sums(gS, kappa, const index_t[::1] idx):
    """Returns ``(sum kappa g, sum kappa g^2)`` over S, ``kappa`` read at ``idx``."""
    if _single("edge_sums", "gS kappa", (gS, kappa)):
        return _edge_sums[float](0, gS, kappa, idx)
    return _edge_sums[double](0, gS, kappa, idx)


cdef object _edge_sums(real_t kind, object gS_, object kappa_, const index_t[::1] idx):
    cdef const real_t[::1] gS = gS_
    cdef const real_t[:, ::1] kappa = kappa_
    cdef Py_ssize_t k, ns = gS.shape[0]
    cdef double kg, skg = 0.0, skgg = 0.0
    cdef const real_t *kf
    if idx.shape[0] != ns:
        raise ValueError("edge_sums: gS and idx differ in length")
    if ns == 0:
        return 0.0, 0.0
    kf = &kappa[0, 0]
    with nogil:
        for k in range(ns):
            kg = <double>kf[idx[k]] * <double>gS[k]
            skg += kg
            skgg += kg * <double>gS[k]
    return skg, skgg


cdef inline Py_ssize_t _block(Py_ssize_t flat, Py_ssize_t first_row, Py_ssize_t nx,
                              Py_ssize_t ny, Py_ssize_t mx, Py_ssize_t my) noexcept nogil:
    """The block of the point at ``flat`` in a slab starting at ``first_row`` (:func:`block_sums`)."""
    return ((flat // ny + first_row) * mx // nx) * my + (flat % ny) * my // ny


def block_sums(gS, kappa, const index_t[::1] idx, Py_ssize_t first_row, Py_ssize_t nx,
               Py_ssize_t ny, Py_ssize_t mx, Py_ssize_t my, double[::1] w, double[::1] d):
    """``w[b] += sum kappa g``, ``d[b] += sum kappa`` over the points of S in each block ``b``.

    The ``(nx, ny)`` grid is cut into ``mx x my`` blocks: global row ``i`` falls
    in block row ``i mx // nx``, column ``j`` in block column ``j my // ny``, and
    block ``(I, J)`` is ``w[I my + J]``.  ``idx`` indexes this rank's unpadded
    slab, whose first global row is ``first_row``.  Accumulated in double.
    """
    if _single("block_sums", "gS kappa", (gS, kappa)):
        _block_sums[float](0, gS, kappa, idx, first_row, nx, ny, mx, my, w, d)
    else:
        _block_sums[double](0, gS, kappa, idx, first_row, nx, ny, mx, my, w, d)


cdef object _block_sums(real_t kind, object gS_, object kappa_, const index_t[::1] idx,
                        Py_ssize_t first_row, Py_ssize_t nx, Py_ssize_t ny, Py_ssize_t mx,
                        Py_ssize_t my, double[::1] w, double[::1] d):
    cdef const real_t[::1] gS = gS_
    cdef const real_t[:, ::1] kappa = kappa_
    cdef Py_ssize_t k, b, flat, ns = gS.shape[0]
    cdef double kv
    cdef const real_t *kf
    if idx.shape[0] != ns:
        raise ValueError("block_sums: gS and idx differ in length")
    if w.shape[0] != mx * my or d.shape[0] != mx * my:
        raise ValueError("block_sums: w and d must hold mx * my blocks")
    if ns == 0:
        return
    kf = &kappa[0, 0]
    with nogil:
        for k in range(ns):
            flat = idx[k]
            b = _block(flat, first_row, nx, ny, mx, my)
            kv = <double>kf[flat]
            w[b] += kv * <double>gS[k]
            d[b] += kv


def subtract_blocks(zS, kappa, const index_t[::1] idx, Py_ssize_t first_row, Py_ssize_t nx,
                    Py_ssize_t ny, Py_ssize_t mx, Py_ssize_t my, const double[::1] y,
                    double scale):
    """``zS -= scale kappa y[b]`` on S, ``b`` each point's block as in :func:`block_sums`."""
    if _single("subtract_blocks", "zS kappa", (zS, kappa)):
        _subtract_blocks[float](0, zS, kappa, idx, first_row, nx, ny, mx, my, y, scale)
    else:
        _subtract_blocks[double](0, zS, kappa, idx, first_row, nx, ny, mx, my, y, scale)


cdef object _subtract_blocks(real_t kind, object zS_, object kappa_, const index_t[::1] idx,
                             Py_ssize_t first_row, Py_ssize_t nx, Py_ssize_t ny, Py_ssize_t mx,
                             Py_ssize_t my, const double[::1] y, double scale):
    cdef real_t[::1] zS = zS_
    cdef const real_t[:, ::1] kappa = kappa_
    cdef Py_ssize_t k, b, flat, ns = zS.shape[0]
    cdef const real_t *kf
    if idx.shape[0] != ns:
        raise ValueError("subtract_blocks: zS and idx differ in length")
    if y.shape[0] != mx * my:
        raise ValueError("subtract_blocks: y must hold mx * my blocks")
    if ns == 0:
        return
    kf = &kappa[0, 0]
    with nogil:
        for k in range(ns):
            flat = idx[k]
            b = _block(flat, first_row, nx, ny, mx, my)
            zS[k] = <real_t>(<double>zS[k] - scale * <double>kf[flat] * y[b])
