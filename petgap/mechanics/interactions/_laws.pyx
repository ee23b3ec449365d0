# cython: language_level=3
"""The interaction laws' per-point kernels: ``v'`` (and ``v''`` where a law needs it) in one pass.

One function per law, called by the law's ``fill_stress`` once per iteration of
the gap solver (:mod:`petgap.solvers.gap_cg`) over this rank's
``(nx_local, ny)`` C-contiguous slab.  ``vpp`` may be None: then only ``v'`` is
written (the law's ``curvature_from_stress`` tells the solver how it gets ``v''``
without it).  The exponential law has none: NumPy's vectorised ``exp`` is
faster than a loop of libm's
(:meth:`petgap.mechanics.interactions.exponential.ExponentialAdhesion.fill_stress`).
"""
from libc.math cimport exp


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
