"""The pressure solver's preconditioner: the restricted stiffness and the terms taken off it.

:func:`petgap.solvers.pressure_cg.polonsky_keer` runs conjugate gradients on the
compliance ``K^{-1}`` (symbol ``2 / (E* |q|)``) restricted to the contact set ``S``,
whose condition number grows like ``L / a0``.  Its opposite-order partner, the
stiffness ``K`` (symbol ``E* |q| / 2``) restricted to the same set, is an almost
exact inverse up to edge effects, leaving a condition number that grows only like
``log^2(L / a0)``: operator preconditioning of first-kind boundary integral
equations (Steinbach & Wendland, Adv. Comput. Math. 9 (1998) 191; Hiptmair,
Jerez-Hanckes & Urzua for screens).  The preconditioned gap is

``z = P_S K P_S g  -  V y  -  theta kappa g``

built from three parts, each an object here:

* :class:`RestrictedStiffness`, ``P_S K P_S g``: one transform pair from ``S`` to
  ``S``, in the search's precision (:class:`StepTransforms`).
* The edge term ``theta kappa g`` (:class:`petgap.solvers.edge_correction.EdgeCorrection`):
  ``kappa = K 1_S`` is the diagonal that the zero extension of ``g`` across the contact
  edge adds to the stiffness; taking a share ``theta`` of it off lowers the edge
  eigenvalues.
* The patch interaction ``V y`` (:mod:`petgap.solvers.patch_interaction`): the far
  field by which contact patches press on each other, which the local stiffness
  cannot see, solved on a grid of blocks.  It keeps the condition number from growing
  with the number of patches across a periodic cell or a free map.  It is smooth over whole
  blocks, and the projection onto ``p >= 0`` after each step is not: while ``S`` still
  moves, a step with it shifts the pressure of many small patches at once, which the
  projection clips.  So it enters only when the set has settled, under the rule of
  :class:`PatchAdmission`.

Each term is used only while the preconditioner stays positive on the gap,
``(g, z) > 0``; a term that would break that is dropped for the rest of the solve
(and logged).  Any change of the terms in use restarts the conjugate gradients
(the caller is told through :attr:`Preconditioned.restart`).
"""
from typing import NamedTuple

import numpy as np

from petgap.parallel.collective import global_sums
from petgap.parallel.log import get_logger
from petgap.solvers import _contact_set as _cs
from petgap.solvers.edge_correction import EdgeCorrection
from petgap.solvers.patch_interaction import BLOCK, patch_interaction

#: The patch interaction enters the preconditioner only in an iteration after one
#: that changed at most this fraction of the contact set (points clipped or
#: entering), with blocks of 32 pixels (less with larger ones:
#: :func:`settled_fraction`).
SETTLED_FRACTION = 0.01
#: A step with the patch interaction after which the residual is above
#: ``RISE_FACTOR`` times the residual before it withdraws the term.  The residual is
#: a maximum over points, not the energy norm the conjugate gradients lower, so a
#: good step may raise it a little: the factor allows that.
RISE_FACTOR = 1.2
#: After a withdrawal the term enters again only after an iteration that changed at
#: most this factor times the fraction that let it in, so that each withdrawal waits
#: for a more settled set than the last.
WITHDRAWN_FACTOR = 0.1


def _log():
    return get_logger("pressure_cg")


def settled_fraction(block_area):
    """The fraction of ``S`` an iteration may change for a patch interaction to enter.

    :data:`SETTLED_FRACTION` for blocks of :data:`petgap.solvers.patch_interaction.BLOCK`
    pixels a side or smaller (``block_area`` their area in pixels, None for no
    term), and that over the ratio of the block's area to theirs for larger ones: a
    step with the term shifts the pressure of whole blocks, and a larger block moves
    more of the set per block it shifts, so the set must have settled further for
    the step to be safe.
    """
    if block_area is None:
        return SETTLED_FRACTION
    return SETTLED_FRACTION * min(1.0, BLOCK * BLOCK / block_area)


class StepTransforms:
    """The two transforms that only find a step, in the search's precision.

    The preconditioner's ``P_S K P_S g`` and the direction's image ``r = K^{-1} t``
    run in single precision on a double grid when ``search_precision`` is
    ``"single"`` (on the grid's
    :meth:`~petgap.parallel.grid.Grid.single_precision_alias`, whose buffers are the
    grid's own); the pressure, the displacement and every sum stay double.  A free
    boundary's compliance is applied in double, so its image stays double.

    The image's step length needs ``r`` only through ``(t, r)``, which by Parseval
    the forward half of the transform gives
    (:meth:`petgap.mechanics.half_space.ElasticHalfSpace.begin_sparse`); the inverse
    half is run (:meth:`finish`) only when the recurrence on ``u`` needs ``r``.  A
    half-space without the halves images the direction whole.
    """

    def __init__(self, problem, search_precision):
        grid, half_space = problem.grid, problem.half_space
        self.half_space, self.comm = half_space, grid.comm
        self.rounded = search_precision == "single" and grid.dtype == np.float64
        self.single_image = self.rounded and half_space.transforms_in_single
        self.split = half_space.splits_transforms
        self.image, self.image_precision = grid.padded, None
        # the alias is planned here, while the FFT buffers hold nothing
        if self.rounded:
            alias = grid.single_precision_alias()
            if self.single_image:
                self.image, self.image_precision = alias.padded, "single"
        self._low = np.empty(0, dtype=np.float32)

    def _in_single(self, values):
        """``values`` rounded to float32 in scratch, and a float32 vector as long beside them.

        The scratch grows when it holds fewer than two such vectors (the spare takes
        a gathered result).
        """
        n = len(values)
        if len(self._low) < 2 * n:
            self._low = np.empty(2 * n + n // 4, dtype=np.float32)
        rounded, spare = self._low[:n], self._low[n:2 * n]
        np.copyto(rounded, values, casting="same_kind")
        return rounded, spare

    def stiffness(self, pidx, gS, zS):
        """``zS = P_S K P_S gS``: one transform pair from ``S`` to ``S``."""
        if self.rounded:
            g_low, z_low = self._in_single(gS)
            self.half_space.apply_sparse(pidx, g_low, inverse=False, gathered=z_low,
                                         precision="single")
            np.copyto(zS, z_low)
        else:
            self.half_space.apply_sparse(pidx, gS, inverse=False, gathered=zS)

    def step_sums(self, pidx, gS, tS):
        """The global ``((g, t), (t, K^{-1} t))`` of the direction ``tS`` on ``S``.

        Leaves the image's forward half in the buffer where the half-space splits its
        transforms (see :meth:`finish`), else the whole image.  Collective.
        """
        values = self._in_single(tS)[0] if self.single_image else tS
        if self.split:
            sum_rt = self.half_space.begin_sparse(pidx, values, inverse=True,
                                                  precision=self.image_precision)
            return global_sums(self.comm, _cs.gap_sums(tS, gS)[1], sum_rt)
        self.half_space.apply_sparse(pidx, values, inverse=True, precision=self.image_precision)
        return global_sums(self.comm, *_cs.step_sums(self.image, pidx, gS, tS))

    def finish(self):
        """Complete the image ``r = K^{-1} t`` in :attr:`image` (after :meth:`step_sums`)."""
        if self.split:
            self.half_space.finish(precision=self.image_precision)


class PatchAdmission:
    """When the patch interaction may enter the preconditioner, and when it is withdrawn.

    It enters in an iteration after one that changed at most :attr:`admit` of ``S``
    (:func:`settled_fraction`).  On a set that has settled a step with it is nearly a
    Newton step and the residual after it falls; where the residual rises by more than
    :data:`RISE_FACTOR`, the step moved more of the set than it settled (on large
    cells, where the far field is strong, a few tenths of a percent of ``S`` can swing
    back and forth), and the term is withdrawn until an iteration changes at most
    :data:`WITHDRAWN_FACTOR` times the fraction that let it in.
    """

    def __init__(self, block_area):
        self.admit = settled_fraction(block_area)
        self.settled = False   # the last iteration changed at most `admit` of S
        self.used = False      # the term was applied in the last iteration
        self.used_from = np.inf   # the residual it was applied at

    def observe_step(self, n_changed, n_contact):
        """Record how much of ``S`` (``n_contact`` points) the last step changed."""
        self.settled = n_changed <= self.admit * n_contact

    def moved(self):
        """The problem moved under the iteration (a depth move): the residual's next rise
        is the move's, not a step's with the term, so it withdraws nothing."""
        self.used = False

    def withdraws(self, iteration, residual):
        """Whether ``residual`` rose past what the last step with the term allowed.

        If so the term is withdrawn (a new preconditioner: the caller restarts).
        """
        if not (self.used and residual > RISE_FACTOR * self.used_from):
            return False
        self.admit *= WITHDRAWN_FACTOR
        _log().info("iteration %d: the residual rose from %.3g to %.3g in a step with the patch "
                    "interaction in the preconditioner; withdrawn until an iteration changes at "
                    "most %.3g of the contact set", iteration, self.used_from, residual,
                    self.admit)
        self.used = self.settled = False
        return True


class Preconditioned(NamedTuple):
    """What one application of the preconditioner gives the conjugate gradients."""

    #: the preconditioned gap on S, and the shift that makes it zero-mean on S (load)
    z: np.ndarray
    zshift: float
    #: ``(g, z)`` of the preconditioner in use (the conjugate gradients' ``g_norm``)
    gz: float
    #: the Rayleigh quotient ``(g, K g) / (g, g)`` of the stiffness on the gap
    stiffness: float
    #: the reduced sum over S of the kept direction (load control)
    t_sum: float
    #: the terms in use changed: conjugacy is lost
    restart: bool


class Identity:
    """No preconditioner: plain Polonsky-Keer, ``z = g``, steps along the gap."""

    patch_used = False

    def __init__(self, comm):
        self.comm = comm

    def withdraws(self, iteration, residual):
        return False

    def moved(self):
        pass

    def observe_step(self, n_changed, n_contact):
        pass

    def apply(self, contact, n_contact, g_norm, t_sum, residual, iteration):
        g_norm, t_sum = global_sums(self.comm, g_norm, t_sum)
        return Preconditioned(contact.g, 0.0, g_norm, 1.0, t_sum, False)

    def punch(self, contact, shape):
        pass

    def release(self):
        pass


class RestrictedStiffness:
    """``z = P_S K P_S g - V y - theta kappa g`` (module docstring), made zero-mean on S under load.

    Parameters
    ----------
    problem : petgap.mechanics.problem.ContactProblem
    mask : ndarray of uint8
        The contact set's mask, which the edge term reads.
    transforms : StepTransforms
    settings : petgap.solvers.settings.SolverSettings
        ``edge_correction`` (0 leaves the edge term out, and with it the patch
        interaction) and ``interaction_block`` (0 leaves the patch interaction out).
    load : bool
        Load control: on a periodic cell only there is the patch interaction made
        (under mean-gap control at high contact fractions it costs more iterations than
        it saves); on a free map also under indentation, where it takes the
        iterations to about load control's.
    """

    def __init__(self, problem, mask, transforms, settings, load):
        half_space = problem.half_space
        theta = settings.edge_correction
        self.comm, self.transforms, self.load = problem.grid.comm, transforms, load
        self.edge = EdgeCorrection(half_space, mask, theta) if theta > 0 else None
        self.patch = (patch_interaction(half_space, theta, settings.interaction_block)
                      if self.edge is not None and (load or not half_space.periodic) else None)
        self.admission = PatchAdmission(None if self.patch is None else self.patch.block_area)

    @property
    def patch_used(self):
        """Whether the patch interaction was applied in the last iteration."""
        return self.admission.used

    def withdraws(self, iteration, residual):
        return self.admission.withdraws(iteration, residual)

    def moved(self):
        self.admission.moved()

    def observe_step(self, n_changed, n_contact):
        self.admission.observe_step(n_changed, n_contact)

    def release(self):
        """Free ``kappa`` and the patch interaction's data (before the result's fields)."""
        self.edge = self.patch = None

    def apply(self, contact, n_contact, g_norm, t_sum, residual, iteration):
        """The preconditioned gap of ``contact``'s gap, with the global sums the step needs.

        ``g_norm`` and ``t_sum`` are this rank's ``(g, g)`` and kept direction's sum,
        reduced here with the preconditioner's own sums in one message.  Collective.
        """
        zS, gS, idx = contact.z, contact.g, contact.idx
        self.transforms.stiffness(contact.pidx, gS, zS)
        if self.edge is None:
            sum_z, kz, g_sq, t_sum = global_sums(self.comm, *_cs.gap_sums(zS, gS), g_norm, t_sum)
            gz, restart = kz, False
        else:
            sum_z, kz, g_sq, t_sum, sum_kg, sum_kgg = global_sums(
                self.comm, *_cs.gap_sums(zS, gS), g_norm, t_sum, *self.edge.sums(gS, idx))
            gz, sum_z, restart = self._take_terms_off(contact, kz, sum_z, sum_kg, sum_kgg,
                                                      residual, iteration)
        zshift = sum_z / n_contact if self.load else 0.0
        # Pressure per unit penetration given to entering points: plain Polonsky-Keer
        # steps along the gap, so its step length is a stiffness, the Rayleigh quotient
        # of the compliance's inverse on the gap; here the step length is a pure number
        # and the direction a pressure, so the same scale is supplied explicitly.
        stiffness = kz / g_sq if g_sq > 0 else 0.0
        return Preconditioned(zS, zshift, gz, stiffness, t_sum, restart)

    def punch(self, contact, shape):
        """``shape``, ``P_S K 1_S`` on ``S``, made the preconditioner's flat punch ``M 1_S``.

        Why: a depth move takes the pressure along the flat punch on ``S``, ``C_SS^{-1}
        1_S`` (:meth:`petgap.solvers.pressure_cg.PressureCG.move_depth`), of which ``M``
        is the solver's approximation.  ``P_S K 1_S`` alone treats each patch as if it
        were alone; the patch interaction shares the punch's force between the patches
        by their far field, and the residual a converged indentation keeps after a move
        falls from 0.41 to 0.22 of the move (512^2 map; 0.35 to 0.23 at 1024^2).  The
        edge term and the patch interaction are taken off as :meth:`apply` takes them
        off a gap, whether or not the patch interaction is admitted to the steps yet;
        without them ``shape`` is left as it is.  Collective.
        """
        edge, patch = self.edge, self.patch
        if edge is None:
            return
        edge.update()   # kappa of the present S, as the next apply would have it
        ones = np.ones(len(contact.idx), dtype=shape.dtype)
        if patch is not None:
            kz = global_sums(self.comm, float(shape.sum(dtype=np.float64)))[0]
            self._far_field(ones, shape, contact.idx, (1.0 - edge.theta) * kz)
        edge.subtract(shape, ones, contact.idx)

    def _far_field(self, gS, zS, idx, gz):
        """Subtract the patch interaction ``V y`` of ``gS`` from ``zS`` where ``(g, z)``, now
        ``gz``, stays positive: the ``(g, V y)`` and ``sum_S V y`` taken off, or None
        where it would not be (``zS`` then unchanged).  Collective."""
        patch, kappa = self.patch, self.edge.kappa
        w, d = patch.sums(gS, kappa, idx)
        y = patch.solve(w, d)
        patch_gz, patch_z = float(np.dot(w, y)), float(np.dot(d, y))
        if not gz - patch_gz > 0:
            return None
        patch.subtract(zS, kappa, idx, y)
        return patch_gz, patch_z

    def _take_terms_off(self, contact, kz, sum_z, sum_kg, sum_kgg, residual, iteration):
        """Subtract the patch and edge terms from ``contact.z`` while ``(g, z)`` stays positive.

        Returns ``(g, z)``, ``sum_S z`` and whether the terms in use changed.
        """
        zS, gS, idx = contact.z, contact.g, contact.idx
        edge = self.edge
        gz = kz - edge.theta * sum_kgg
        admission = self.admission
        use_patch = gz > 0 and self.patch is not None and admission.settled
        restart = use_patch != admission.used
        admission.used = False
        if use_patch:
            taken = self._far_field(gS, zS, idx, gz)
            if taken is not None:
                gz -= taken[0]
                sum_z -= taken[1]
                admission.used, admission.used_from = True, residual
            else:
                _log().info("iteration %d: the patch interaction of the preconditioner is not "
                            "positive on the gap; going on without it", iteration)
                self.patch, restart = None, True
        if gz > 0:
            edge.subtract(zS, gS, idx)
            sum_z -= edge.theta * sum_kg
            return gz, sum_z, restart
        _log().info("iteration %d: the contact-edge correction of the preconditioner is not "
                    "positive on the gap; going on without it", iteration)
        self.edge = self.patch = None
        return kz, sum_z, True


def make_preconditioner(problem, mask, transforms, settings, load):
    """The preconditioner ``settings`` ask for: :class:`RestrictedStiffness` or :class:`Identity`."""
    if settings.preconditioned:
        return RestrictedStiffness(problem, mask, transforms, settings, load)
    return Identity(problem.grid.comm)
