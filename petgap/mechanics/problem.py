"""The contact problem: a rigid rough surface against an elastic half-space.

Formulation (docs/conventions.md)
---------------------------------
The gap is ``g(x) = d + u(x) - h(x) >= 0`` with ``h`` the rigid topography,
``u`` the elastic displacement (positive away from the rigid surface) and ``d``
the rigid-body separation.  Since the half-space operator only sees the
fluctuation of ``u``, the elastic pressure is a function of the gap alone::

    p_el = K (g + h),        zero mean, K = E* |q| / 2 in Fourier space.

The total pressure is ``p = P0 + p_el`` (positive in compression), ``P0`` the
mean pressure.  Energies are per cell (``dx dy`` weights).

* Load control: minimise ``E_el(g) + E_int(g) + P0 A0 mean(g)`` over ``g >= 0``.
  Its gradient, divided by the pixel area, is ``p_el + P0 + v'(g) = p + v'(g)``.
* Mean-gap control: minimise ``E_el + E_int`` over ``g >= 0`` with
  ``mean(g) = g_bar``; ``P0`` is the Lagrange multiplier.

On a free boundary (:mod:`petgap.mechanics.free_half_space`) ``u = C p`` has a
mean of its own, ``d`` is the counter-surface's position (:class:`Indentation`
prescribes it) and ``p`` is the whole pressure; only the pressure formulation
is solved there (:mod:`petgap.solvers.pressure_cg`).

KKT conditions: ``p + v'(g) = 0`` where ``g > 0`` and ``p + v'(0) >= 0`` where
``g = 0`` (repulsive contact).  A solution is judged by two unit-free residuals
(:meth:`ContactProblem.kkt_residuals`): the largest violation in pressure
relative to ``h0' E*`` and the largest violation in gap relative to ``h0``.
"""
import copy
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import HardWall
from petgap.parallel.grid import row_blocks
from petgap.surfaces.statistics import (check_local_field, finite_difference_slopes,
                                        statistics)


@dataclass(frozen=True)
class Load:
    """Load control: prescribed mean pressure ``P0`` (positive in compression)."""

    mean_pressure: float
    kind = "load"

    @property
    def value(self):
        return self.mean_pressure


@dataclass(frozen=True)
class MeanGap:
    """Mean-gap control: prescribed ``mean(g)`` (the mean pressure follows)."""

    mean_gap: float
    kind = "mean-gap"

    def __post_init__(self):
        if not self.mean_gap >= 0:
            raise ValueError(f"mean gap {self.mean_gap} < 0 is impossible with a hard wall "
                             f"(gap >= 0)")

    @property
    def value(self):
        return self.mean_gap


@dataclass(frozen=True)
class Indentation:
    """Displacement control: the rigid body pressed ``depth`` past first contact.

    The counter-surface sits at ``d = max(h) - depth`` (``g = d + u - h``): at
    ``depth = 0`` it touches the highest point; Hertz's sphere has
    ``depth = a^2 / R``.  For a free boundary only
    (:class:`petgap.mechanics.free_half_space.FreeHalfSpace`): the periodic
    half-space has no stiffness for the mean, so a prescribed approach fixes
    no load.
    """

    depth: float
    kind = "indentation"

    def __post_init__(self):
        if not self.depth >= 0:
            raise ValueError(f"indentation depth {self.depth} < 0: the surfaces do not touch")

    @property
    def value(self):
        return self.depth


#: The control types by their ``kind`` (the words of the registry of solvers,
#: :data:`petgap.io.solver_registry.CONTROLS`, and of a scene's ``control.kind``).
CONTROL_TYPES = {control.kind: control for control in (Load, MeanGap, Indentation)}


@dataclass
class ContactSolution:
    """A solved (or not) contact state and how it was reached.

    Fields are this rank's slabs; scalars are global.  Contact (``A_rep``) is
    repulsive contact: zero gap and compressive pressure.  ``zero_gap_fraction``
    is the area fraction at the wall (``g <= 0``, i.e. ``g = 0`` in a stored
    state), whether the wall pushes there (the ``contact_fraction``) or adhesion
    holds the surfaces together under tension (``p < 0``): for the hard wall the
    two differ only by points that touch without load, but a JKR-like contact
    has tensile edges, and near pull-off under mean-gap control it may be all
    tension (``contact_fraction = 0``) while still stuck; it is this area that
    vanishes at pull-off, and that :func:`petgap.solvers.sweeps.annotate_step` watches
    for jumps.  Forces are per cell:
    ``repulsive_force`` is the hard-wall reaction ``sum dx dy (p + v'(0))`` over
    the points at the wall, ``attractive_force = -sum dx dy v'(g)`` over all
    points (the paper's Eq. 15, negative when attractive); their sum is
    ``A0 mean_pressure``.  ``attractive_fraction`` is the area fraction of the
    points outside repulsive contact within one length scale of the interaction
    law (``g <= rho`` for the exponential) -- the bands of width ``d_att`` of the paper's Fig. 1.
    ``kappa_rep = A_rep h0' E* / F_rep`` and ``inv_kappa_att = -F_att /
    (h0' E* A_rep)``, positive for attraction as in the paper's Fig. 3 (the
    paper's Eq. 16 text writes the ratio without the minus sign).  ``converged`` is False
    whenever the tolerance was not met (for instance at the iteration limit);
    ``reason`` then says why the solver stopped.  ``precision`` is the floating
    point the solve ran in: ``"double"``, ``"single"`` (the grid's; the fields are
    then 32-bit) or ``"mixed"`` (single, refined in double).  ``operator_applications``
    counts the elastic operator's applications in transform pairs (a step length
    that needs only the forward half of one counts a half).  ``approach`` is, on a
    free boundary, how far the rigid body has moved past first contact with the
    highest point, ``max(h) - d`` for ``g = d + u - h``: the depth of an
    :class:`Indentation`, and what a load or a mean gap pressed it to (negative when
    adhesion holds the surfaces together apart); NaN on a periodic cell, whose
    displacement has no mean and so no rigid-body position.
    """

    gap: np.ndarray
    pressure: np.ndarray
    control: object
    mean_gap: float
    mean_pressure: float
    contact_fraction: float
    zero_gap_fraction: float
    elastic_energy: float
    interaction_energy: float
    kappa_rep: float
    repulsive_force: float
    attractive_force: float
    attractive_fraction: float
    inv_kappa_att: float
    kkt_pressure: float
    kkt_gap: float
    converged: bool
    reason: str
    solver: str
    iterations: int
    operator_applications: float
    wall_time: float
    history: list = field(default_factory=list, repr=False)
    direction: str = "start"
    jump: bool = False
    negative_curvature_steps: int = 0
    start: str = ""
    start_time: float = 0.0
    precision: str = "double"
    approach: float = float("nan")

    def scalars(self):
        """The scalar results as a flat dict (for HDF5 attributes and tables)."""
        out = {k: getattr(self, k) for k in (
            "mean_gap", "mean_pressure", "contact_fraction", "zero_gap_fraction",
            "elastic_energy", "interaction_energy", "kappa_rep", "repulsive_force",
            "attractive_force", "attractive_fraction", "inv_kappa_att", "kkt_pressure",
            "kkt_gap", "converged", "reason", "solver", "iterations", "operator_applications",
            "wall_time", "direction", "jump", "negative_curvature_steps", "start",
            "start_time", "precision", "approach")}
        out["control"] = self.control.kind
        out["control_value"] = self.control.value
        return out


@dataclass(frozen=True)
class Scales:
    """What makes a problem's KKT residuals unit-free: the rms height ``h0`` and slope ``h0'``.

    The gap residual is over ``h0``, the pressure residual over ``h0' E*``.
    """

    rms_height: float
    rms_slope: float


class ContactProblem:
    """Everything a solver needs to know about one contact configuration.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    topography : ndarray, shape ``grid.local_shape``
        This rank's slab of the rigid surface heights ``h``.
    half_space : petgap.mechanics.half_space.ElasticHalfSpace, optional
        The elastic body; default: one made on ``grid`` with ``contact_modulus``.
    interaction : petgap.mechanics.interactions.InteractionLaw, optional
        A law of :data:`petgap.mechanics.interactions.LAWS`; default: hard wall only.
    contact_modulus : float, optional
        ``E*`` of the half-space made when none is given (default 1); when one
        is given, its modulus must agree.
    scales : Scales, optional
        The KKT scales ``h0`` and ``h0'`` (:attr:`scales`) of the problem this one
        stands in for, instead of its own topography's: a free map's problem solved on
        its padded cell (:mod:`petgap.solvers.free_boundary`) judges its residuals as
        the map's, whose surface the cell's far-away outside would distort.
    """

    def __init__(self, grid, topography, half_space=None, interaction=None, *,
                 contact_modulus=None, scales=None):
        # checked on every rank together: a slab of the wrong shape raises everywhere
        # kept in its own floating type until made the grid's (no double copy of a
        # single-precision topography)
        topography = check_local_field(grid, topography, "topography", dtype=None)
        if half_space is None:
            half_space = ElasticHalfSpace(grid, 1.0 if contact_modulus is None
                                          else contact_modulus)
        elif contact_modulus is not None and float(contact_modulus) != half_space.contact_modulus:
            raise ValueError(f"contact_modulus = {contact_modulus!r} disagrees with the "
                             f"half-space's {half_space.contact_modulus!r}; give one of them")
        self.grid = grid
        self.half_space = half_space
        self.interaction = interaction or HardWall()
        # in the grid's precision (single-precision grids: 32-bit fields, double sums)
        self.topography = np.ascontiguousarray(topography, dtype=grid.dtype)
        # The spectral statistics (the surface's own, as reported for it) set the
        # unit-free residual scales.
        stats = statistics(grid, self.topography)
        self.mean_height = stats.mean
        #: The highest point, ``max(h)``: where an indentation is counted from.
        self.top_height = grid.comm.allreduce(float(np.max(self.topography, initial=-np.inf)),
                                              op=MPI.MAX)
        if scales is not None:
            self.rms_height, self.rms_slope = scales.rms_height, scales.rms_slope
        else:
            self.rms_height = stats.rms_height
            #: ``h0'``: spectral on a periodic cell; on a free boundary by finite
            #: differences inside the map, since the spectrum of a map whose edges do not
            #: match holds the seam's cliff (which no free solve sees).
            self.rms_slope = stats.rms_slope if half_space.periodic else \
                finite_difference_slopes(grid, self.topography)[1]
        if not (self.rms_height > 0 and self.rms_slope > 0):
            raise ValueError("the topography is flat: contact of a flat surface has no "
                             "rough-contact solution (rms height and slope are zero)")
        #: Pressure scale of the KKT residual, ``h0' E*``.
        self.pressure_scale = self.rms_slope * half_space.contact_modulus
        #: Gap scale of the KKT residual, ``h0``.
        self.gap_scale = self.rms_height

    @property
    def scales(self):
        """The KKT scales: ``h0`` (:attr:`gap_scale`) and ``h0'`` (``pressure_scale / E*``)."""
        return Scales(self.rms_height, self.rms_slope)

    @property
    def operator_applications(self):
        """Applications of the elastic operator so far (the half-space's own count).

        A solver reports the difference over its solve.
        """
        return self.half_space.applications

    def with_interaction(self, interaction):
        """The same surface and half-space with another interaction (None: the hard wall).

        Shares the grid, the topography, the half-space (and so its count of
        operator applications) and the statistics; it is another object, so what a
        solver keeps per problem (which may depend on the interaction) is not shared.
        """
        other = copy.copy(self)
        other.interaction = interaction or HardWall()
        return other

    # ------------------------------------------------------------ operators
    def elastic_pressure(self, gap, out=None):
        """Zero-mean elastic pressure ``K (g + h)`` (one transform pair)."""
        buf = self.grid.real
        np.add(gap, self.topography, out=buf)
        self.half_space.apply_in_buffer()
        if out is None:
            return buf.copy()
        np.copyto(out, buf)
        return out

    def displacement(self, pressure, out=None):
        """Zero-mean displacement ``K^{-1} p`` (one transform pair)."""
        return self.half_space.displacement(pressure, out)

    def objective_gradient(self, gap, gradient, mean_pressure):
        """Load-control objective and its gradient (per pixel area, i.e. a pressure).

        Parameters
        ----------
        gap : ndarray
            This rank's gap slab.
        gradient : ndarray
            Filled with ``p_el + P0 + v'(g)``, the gradient divided by ``dx dy``.
        mean_pressure : float
            ``P0``.

        Returns
        -------
        float
            ``E_el + E_int + P0 A0 mean(g)`` (same on all ranks).
        """
        self.elastic_pressure(gap, out=gradient)
        local = 0.5 * np.vdot(gap + self.topography, gradient) + mean_pressure * gap.sum()
        if self.interaction.adhesive:
            local += self.interaction.energy(gap).sum()
            gradient += self.interaction.derivative(gap)
        gradient += mean_pressure
        return self.grid.pixel_area * self.grid.comm.allreduce(float(local))

    # ------------------------------------------------------------ judgement
    def kkt_residuals(self, gap, pressure, contact):
        """Unit-free KKT residuals of a state ``(g, p)`` with contact set ``contact``.

        Returns
        -------
        (float, float)
            ``max violation in pressure / (h0' E*)`` -- non-zero pressure (plus
            interaction stress) off contact, tension in contact -- and
            ``max violation in gap / h0`` -- gap in contact, penetration off it.
        """
        rp = rg = 0.0
        for rows in row_blocks(gap.shape[0]):
            g, p, c = gap[rows], pressure[rows], contact[rows]
            stress = p + self.interaction.derivative(g) if self.interaction.adhesive else p
            free = ~c
            rp = max(rp, _max_or_zero(np.abs(stress[free])), _max_or_zero(-stress[c]))
            rg = max(rg, _max_or_zero(np.abs(g[c])), _max_or_zero(-g[free]))
        pair = np.array([rp, rg])
        self.grid.comm.Allreduce(MPI.IN_PLACE, pair, op=MPI.MAX)
        return pair[0] / self.pressure_scale, pair[1] / self.gap_scale

    def make_solution(self, gap, pressure, contact, control, *, converged, reason, solver,
                      iterations, operator_applications, wall_time, history=(), residuals=None,
                      start="", start_time=0.0, approach=float("nan")):
        """Assemble a :class:`ContactSolution` with all derived quantities.

        ``residuals`` overrides the KKT residuals computed from ``gap`` and
        ``pressure`` (for a solver whose stored gap is a projection of the one
        it iterated on); ``start`` says how the solver started, where that is
        more than the control and the warm start say (a coarse-grid solve),
        and ``start_time`` is the part of ``wall_time`` that start took.
        """
        grid = self.grid
        kkt_p, kkt_g = residuals if residuals is not None else \
            self.kkt_residuals(gap, pressure, contact)
        interaction = self.interaction
        # Sums over the slab in row blocks: no full-size temporaries at the peak.
        local = np.zeros(8)
        for rows in row_blocks(gap.shape[0]):
            g, p, c = gap[rows], pressure[rows], contact[rows]
            repulsive = c & (p > 0)
            # sums in double whatever the fields' precision
            local[:3] += (g.sum(dtype=np.float64), p.sum(dtype=np.float64),
                          np.count_nonzero(repulsive))
            local[7] += np.count_nonzero(g <= 0)
            if interaction.adhesive:
                stress = interaction.derivative(g)          # v'(g) >= 0, tensile
                local[3] += interaction.energy(g).sum()
                local[4] += (p[c] + stress[c]).sum()       # wall reaction
                local[5] += stress.sum()
                local[6] += np.count_nonzero(~repulsive & (g <= interaction.length_scale))
            else:
                local[4] += p[c].sum(dtype=np.float64)
        total = np.empty_like(local)
        grid.comm.Allreduce(local, total)
        n = grid.npoints
        area = grid.pixel_area
        mean_gap, mean_pressure, c = total[0] / n, total[1] / n, total[2] / n
        # Force split (docs/conventions.md; paper Eq. 1 and 15): F = A0 P0 = F_rep + F_att
        # with F_att = -sum dx dy v'(g) (< 0, attractive) and F_rep the wall reaction.
        repulsive_force, attractive_force = area * total[4], -area * total[5]
        a_rep = c * grid.area
        if self.half_space.periodic:
            np.add(gap, self.topography, out=grid.real)  # u up to a constant: energy ignores it
            elastic = self.half_space.energy(grid.real)
        else:  # the mean of u counts on a free boundary, and only C is at hand
            elastic = self.half_space.complementary_energy(pressure)
        kappa = a_rep * self.pressure_scale / repulsive_force if (repulsive_force > 0 and a_rep > 0) \
            else float("nan")
        # undefined (NaN, as kappa_rep) when attraction acts without repulsive contact
        inv_kappa_att = (0.0 if not interaction.adhesive else
                         -attractive_force / (self.pressure_scale * a_rep) if a_rep > 0
                         else float("nan"))
        return ContactSolution(
            gap=gap, pressure=pressure, control=control, mean_gap=mean_gap,
            mean_pressure=mean_pressure, contact_fraction=c, zero_gap_fraction=total[7] / n,
            elastic_energy=elastic,
            interaction_energy=area * total[3], kappa_rep=kappa,
            repulsive_force=repulsive_force, attractive_force=attractive_force,
            attractive_fraction=total[6] / n, inv_kappa_att=inv_kappa_att,
            kkt_pressure=kkt_p, kkt_gap=kkt_g, converged=bool(converged), reason=str(reason),
            solver=solver, iterations=int(iterations),
            operator_applications=float(operator_applications), wall_time=float(wall_time),
            history=list(history), start=str(start), start_time=float(start_time),
            precision=grid.precision, approach=float(approach))


def _max_or_zero(values):
    return float(values.max()) if values.size else 0.0
