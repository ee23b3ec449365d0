"""The contact set of the pressure solver: sorted index lists with the fields on them.

:func:`petgap.solvers.pressure_cg.polonsky_keer` keeps the pressure ``p``, its
conjugate direction ``t``, the gap ``g`` and the preconditioned gap ``z`` on the
contact set ``S = {p > 0}`` only, as compressed vectors beside the flat indices of ``S`` in this rank's
slab (``idx``) and in the padded FFT buffer (``pidx``); the kernels that work on
them are in ``petgap/solvers/_contact_set.pyx``.

Why a class around six arrays: memory.  A cold start from a uniform pressure
puts most of the points in ``S`` after its first step, and the set then
shrinks to the few percent that carry the load.  The vectors therefore live in
buffers with spare capacity, updated in place by
:func:`petgap.solvers._contact_set.merge` (never two copies of the set at once), grown
one array at a time when points enter beyond the capacity, and shrunk one array
at a time when the set has fallen well below it, so that the peak is one copy
of the largest set plus one array in transit.

Precision: the value vectors ``p, t, g, z`` have the set's ``dtype``, float64
(the default) or float32, which must be that of the fields the solver passes
to the kernels with them (topography, displacement, FFT buffer): the kernels
take one precision per call and accumulate every sum in double (see
``_contact_set.pyx``).  Single precision halves the memory of the vectors,
which is most of the set's.  The index lists are int32 either way.
"""
import numpy as np

from petgap.parallel.log import SET_UPDATE_EVENT, event
from petgap.solvers import _contact_set as _cs

#: dtype of the index lists (``index_t`` of the kernels)
INDEX = np.int32
#: dtypes the value vectors may have (``real_t`` of the kernels)
PRECISIONS = (np.dtype(np.float64), np.dtype(np.float32))
_SHRINK_BELOW = 0.25  # shrink when the set fills less than this of its buffers
_SPARE = 1.5          # capacity given on growing or shrinking, times the set size


def _view(name):
    """A property: the first ``size`` entries of the buffer ``name``."""
    return property(lambda self: getattr(self, name)[:self.size])


class ContactSet:
    """``S`` with ``p``, ``t``, ``g`` and ``z`` on it, stored in place (see the module docstring).

    ``p`` (pressure) and ``t`` (conjugate direction) are kept through a merge;
    ``g`` (gap) and ``z`` (preconditioned gap) are scratch, refilled by every
    iteration.

    Parameters
    ----------
    mask : ndarray of uint8, shape ``grid.local_shape``
        Set to 1 on ``S`` and 0 elsewhere, and kept so.
    padded_width : int
        Row length of the padded FFT buffer, for ``pidx``.
    dtype : numpy.float64 (default) or numpy.float32
        Precision of ``p``, ``t``, ``g`` and ``z``: that of the fields they are
        used with.  Pressures given to :meth:`merge` and the constructors are
        rounded to it on the way in.
    """

    _names = ("_idx", "_pidx", "_p", "_t", "_g", "_z")

    def __init__(self, mask, padded_width, dtype=np.float64):
        dtype = np.dtype(dtype)
        if dtype not in PRECISIONS:
            raise TypeError(f"ContactSet: dtype must be float64 or float32, not {dtype}")
        if mask.shape[0] * padded_width > np.iinfo(INDEX).max:
            raise ValueError(
                f"this rank's slab ({mask.shape[0]} x {padded_width} padded points) is too "
                f"large for the contact set's 32-bit index lists (at most 2^31 points per "
                f"rank): run on more MPI ranks")
        self.mask, self.padded_width, self.dtype = mask, padded_width, dtype
        self.size = 0
        mask[...] = 0
        self._idx = np.empty(0, dtype=INDEX)
        self._pidx = np.empty(0, dtype=INDEX)
        self._p, self._t, self._g, self._z = (np.empty(0, dtype=dtype) for _ in range(4))

    @classmethod
    def everywhere(cls, mask, padded_width, pressure, dtype=np.float64):
        """Every point of the slab in ``S`` with the same ``pressure``: a uniform start.

        Built directly, without the full pressure field a general start needs.
        """
        contact = cls(mask, padded_width, dtype)
        n_local = mask.size
        contact._idx = np.arange(n_local, dtype=INDEX)
        width = mask.shape[1]
        contact._pidx = contact._idx // width
        contact._pidx *= padded_width - width
        contact._pidx += contact._idx
        contact._p = np.full(n_local, float(pressure), dtype=contact.dtype)
        contact._t = np.zeros(n_local, dtype=contact.dtype)
        contact._g = np.empty(n_local, dtype=contact.dtype)
        contact._z = np.empty(n_local, dtype=contact.dtype)
        contact.size = n_local
        mask[...] = 1
        return contact

    @classmethod
    def from_pressure(cls, mask, padded_width, pressure, spare=_SPARE, dtype=np.float64):
        """``S = {pressure > 0}`` with the pressure on it (a warm start, where the
        undeformed surfaces overlap under mean-gap control, or the first step of a
        cold start).

        ``spare`` sets the buffers' capacity in units of the set's size: a set
        that can only shrink from here (a cold start) needs none.  ``pressure``
        may have either precision; a positive value that rounds to zero in
        ``dtype`` stays out of ``S``.
        """
        contact = cls(mask, padded_width, dtype)
        points = np.flatnonzero(pressure > 0)
        contact._resize(max(int(spare * len(points)), 1024))
        contact.merge(points, pressure.ravel()[points])
        return contact

    # Views of the first ``size`` entries: what the kernels see.
    idx = _view("_idx")
    pidx = _view("_pidx")
    p = _view("_p")
    t = _view("_t")
    g = _view("_g")
    z = _view("_z")

    @property
    def capacity(self):
        return len(self._idx)

    def merge(self, added, added_p):
        """Drop the points whose pressure fell to zero, let ``added`` in with ``added_p``.

        ``added`` are sorted flat indices off ``S``; those with ``added_p <= 0``
        stay out; the others enter with a zero direction.  ``added_p`` is
        converted to the set's ``dtype`` (a copy only where it differs), so
        that the kernel sees one precision.  Timed in the PETSc log event
        :data:`petgap.parallel.log.SET_UPDATE_EVENT`.
        """
        with event(SET_UPDATE_EVENT):
            needed = self.size + len(added)
            if needed > self.capacity:
                self._resize(max(int(_SPARE * needed), 1024))
            self.size = _cs.merge(self._idx, self._pidx, self._p, self._t, self.size,
                                  np.ascontiguousarray(added, dtype=INDEX),
                                  np.ascontiguousarray(added_p, dtype=self.dtype), self.mask,
                                  self.padded_width)
            if self.capacity > 4096 and self.size < _SHRINK_BELOW * self.capacity:
                self._resize(max(int(_SPARE * self.size), 1024))

    def _resize(self, capacity):
        # One array at a time: the transient is a single array, not a second set.
        # The gap and z are scratch, refilled every iteration: nothing to keep.
        keep = min(self.size, capacity)
        for name in self._names:
            old = getattr(self, name)
            new = np.empty(capacity, dtype=old.dtype)
            if name not in ("_g", "_z"):
                new[:keep] = old[:keep]
            setattr(self, name, new)
            del old
