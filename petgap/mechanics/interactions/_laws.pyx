# cython: language_level=3
"""The interaction laws' per-point kernels: ``v'`` (and ``v''`` where a law needs it) in one pass.

One function per law, called by the law's ``fill_stress`` once per iteration of
the gap solver (:mod:`petgap.solvers.gap_cg`) over this rank's
``(nx_local, ny)`` C-contiguous slab.  ``vpp`` may be None: then only ``v'`` is
written (the law's ``curvature_from_stress`` tells the solver how it gets ``v''``
without it).
"""
from libc.math cimport exp


cdef extern from *:
    """
    #include <stdint.h>
    #include <string.h>
    /* exp(x) within an ulp, in plain arithmetic: x = k ln 2 + r with |r| <= ln(2) / 2
       (k rounded by adding 1.5 * 2^52, ln 2 split in two so that k ln2_hi is exact),
       exp(r) = 1 + r + r^2 p(r) with p Taylor's series to r^11 (its remainder is below
       1e-17), times 2^k written into the exponent's bits.  No branch, table or libm
       call: the loop over a row vectorises, and a value depends on x alone, never on
       its place in a vector.  Below -708 (results at the edge of the subnormal range)
       it gives 0, above 709 infinity, NaN for NaN. */
    static inline double petgap_exp(double x) {
        const double shift = 6755399441055744.0;
        const double log2e = 1.4426950408889634;
        const double ln2_hi = 6.93147180369123816490e-01;
        const double ln2_lo = 1.90821492927058770002e-10;
        double y = x < -708.0 ? -708.0 : (x > 709.0 ? 709.0 : x);
        double kd = y * log2e + shift;
        uint64_t bits, scale_bits;
        double r, p, e, scale;
        memcpy(&bits, &kd, sizeof bits);
        kd -= shift;
        r = (y - kd * ln2_hi) - kd * ln2_lo;
        p = 1.0 / 6227020800.0;
        p = p * r + 1.0 / 479001600.0;
        p = p * r + 1.0 / 39916800.0;
        p = p * r + 1.0 / 3628800.0;
        p = p * r + 1.0 / 362880.0;
        p = p * r + 1.0 / 40320.0;
        p = p * r + 1.0 / 5040.0;
        p = p * r + 1.0 / 720.0;
        p = p * r + 1.0 / 120.0;
        p = p * r + 1.0 / 24.0;
        p = p * r + 1.0 / 6.0;
        p = p * r + 0.5;
        e = 1.0 + (r + (r * r) * p);
        scale_bits = (bits + 1023) << 52;
        memcpy(&scale, &scale_bits, sizeof scale);
        e *= scale;
        return x < -708.0 ? 0.0 : (x > 709.0 ? 1.0 / 0.0 : e);
    }
    """
    double petgap_exp(double x) noexcept nogil


def exponential_stress(const double[:, ::1] g, double[:, ::1] vp, double w, double rho):
    """``vp = (w / rho) exp(-g / rho)``: the one exponential per point per iteration.

    By :c:func:`petgap_exp` over each row, which the compiler vectorises: libm's
    ``exp``, called point by point, would make this the dearest pass of an adhesive
    iteration.
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double wr = w / rho
    cdef const double* row
    cdef double* out
    with nogil:
        for i in range(m):
            row = &g[i, 0]
            out = &vp[i, 0]
            for j in range(n):
                out[j] = wr * petgap_exp(-row[j] / rho)


def maugis_dugdale_stress(const double[:, ::1] g, double[:, ::1] vp, double w, double delta):
    """``vp = w / delta`` where ``g < delta``, ``0`` elsewhere.

    Returns the number of points whose ``vp`` changed: those that crossed ``delta``
    since ``vp`` was last filled (the jumps of ``v'`` the gap solver restarts on).
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double sigma = w / delta, v
    cdef long crossed = 0
    with nogil:
        for i in range(m):
            for j in range(n):
                v = sigma if g[i, j] < delta else 0.0
                if v != vp[i, j]:
                    crossed += 1
                vp[i, j] = v
    return crossed


def squared_exponential_stress(const double[:, ::1] g, double[:, ::1] vp, double[:, ::1] vpp,
                               double w, double rho):
    """``vp = c g e`` and ``vpp = c (1 - x^2) e``, one exponential per point for both.

    ``c = w / rho^2``, ``x = g / rho``, ``e = exp(-x^2 / 2)``.
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double c = w / (rho * rho), x, e
    cdef bint second = vpp is not None
    with nogil:
        for i in range(m):
            for j in range(n):
                x = g[i, j] / rho
                e = c * exp(-0.5 * x * x)
                vp[i, j] = g[i, j] * e
                if second:
                    vpp[i, j] = (1.0 - x * x) * e


def lennard_jones_stress(const double[:, ::1] g, double[:, ::1] vp, double[:, ::1] vpp,
                         double w, double z0):
    """``vp = c (s^4 - s^10)``, ``vpp = (c / z0) (10 s^11 - 4 s^5)``; ``c = 9 w / (2 z0)``.

    ``s = z0 / (z0 + g)``: one division per point, then products.
    """
    cdef Py_ssize_t i, j, m = g.shape[0], n = g.shape[1]
    cdef double c = 4.5 * w / z0, s, s2, s4, s6
    cdef bint second = vpp is not None
    with nogil:
        for i in range(m):
            for j in range(n):
                s = z0 / (z0 + g[i, j])
                s2 = s * s
                s4 = s2 * s2
                s6 = s4 * s2
                vp[i, j] = c * s4 * (1.0 - s6)
                if second:
                    vpp[i, j] = c / z0 * s4 * s * (10.0 * s6 - 4.0)
