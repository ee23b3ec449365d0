"""The two ends of a hard wall's load range, where nothing is iterated.

* Zero load (:func:`touching_state`): the surfaces touch at the highest point and
  carry nothing.
* Full contact (:class:`FullContact`): a load at or beyond :func:`full_contact_load`
  closes every gap, and the state has a closed form that an iterative solver would
  reach only in the limit, as its contact set grows to every point.
"""
import weakref

import numpy as np
from mpi4py import MPI


def full_contact_load(problem):
    """The least mean pressure that closes every gap: ``P_full = -min(K h)``.

    In full contact the gap is zero everywhere, so the displacement is the
    topography less its mean and the pressure ``p = P0 + K h`` (``K`` the
    half-space's stiffness, which has no mean); that state is the solution if and
    only if no pressure is tensile, ``P0 >= -min(K h)``.  One transform pair.
    Collective.
    """
    grid = problem.grid
    np.copyto(grid.real, problem.topography)     # K h in the FFT buffer: no slab copies
    problem.half_space.apply_in_buffer()
    return -grid.comm.allreduce(float(np.min(grid.real, initial=np.inf)), op=MPI.MIN)


class FullContact:
    """The full-contact end of the load range of each problem it is asked about.

    Keeps each problem's :func:`full_contact_load` while the problem lives, so that
    the steps of a sweep pay its transform once; the key is the problem itself, so
    that a problem with another interaction gets its own.
    """

    def __init__(self):
        self._loads = weakref.WeakKeyDictionary()

    def load(self, problem):
        """:func:`full_contact_load` of ``problem``, made on the first call.  Collective."""
        if problem not in self._loads:
            self._loads[problem] = full_contact_load(problem)
        return self._loads[problem]

    def state(self, problem, control, timer=None):
        """The full-contact solution of a non-adhesive problem under load ``control``, or None.

        None unless ``control.mean_pressure`` is at least :meth:`load`; then no
        iteration is needed.  Collective.
        """
        if control.mean_pressure < self.load(problem):
            return None
        grid = problem.grid
        gap = np.zeros(grid.local_shape)
        pressure = problem.elastic_pressure(gap)
        pressure += control.mean_pressure
        return problem.make_solution(gap, pressure, np.ones(grid.local_shape, dtype=bool),
                                     control, converged=True, reason="full_contact",
                                     solver="pcg-pressure", iterations=0,
                                     operator_applications=1,
                                     wall_time=timer() if timer is not None else 0.0)


def touching_state(problem, control, timer=None):
    """Zero load: the surfaces touch at the highest point and carry nothing."""
    grid = problem.grid
    top = grid.comm.allreduce(float(problem.topography.max()), op=MPI.MAX)
    gap = top - problem.topography
    pressure = np.zeros(grid.local_shape)
    return problem.make_solution(gap, pressure, pressure > 0, control, converged=True,
                                 reason="zero_load", solver="pcg-pressure", iterations=0,
                                 operator_applications=0,
                                 wall_time=timer() if timer is not None else 0.0,
                                 approach=float("nan") if problem.half_space.periodic else 0.0)
