"""The physics of one contact: the elastic half-space, the interaction, the problem and its solution.

Nothing here iterates: a :class:`ContactProblem` states what is to be minimised
(its objective, gradient and KKT residuals) and how a state is judged, and
:mod:`petgap.solvers` finds the state.

Modules
-------
:mod:`.half_space`
    :class:`ElasticHalfSpace`: the periodic half-space, ``p_q = E* |q| u_q / 2``,
    its inverse and elastic energy (paper Eq. 4).
:mod:`.free_half_space`
    :class:`FreeHalfSpace`: the same body without periodic images, for a finite
    map or an indenter (Love's pixel influence coefficients, Hockney's zero padding).
:mod:`.interactions`
    The interaction laws, each one object that knows itself, and their registry:
    :class:`HardWall`, :class:`ExponentialAdhesion` (``v(g) = -w exp(-g / rho)``,
    paper Eq. 6), :class:`MaugisDugdaleAdhesion`, :class:`LennardJones93Adhesion`,
    :class:`SquaredExponentialAdhesion`; whether a grid resolves one
    (:func:`resolution_report`, :func:`check_resolution`).
:mod:`.problem`
    The controls :class:`Load` (mean pressure), :class:`MeanGap` and
    :class:`Indentation` (free boundary),
    :class:`ContactProblem` (topography, half-space, interaction; the
    formulation and its KKT conditions) and :class:`ContactSolution` (fields,
    scalars and the solver's status).
"""
from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import (ExponentialAdhesion, HardWall,
                                           LennardJones93Adhesion, MaugisDugdaleAdhesion,
                                           ResolutionError, ResolutionWarning,
                                           SquaredExponentialAdhesion, check_resolution,
                                           resolution_report)
from petgap.mechanics.free_half_space import FreeHalfSpace
from petgap.mechanics.problem import ContactProblem, ContactSolution, Indentation, Load, MeanGap

__all__ = ["ElasticHalfSpace", "FreeHalfSpace", "Indentation", "HardWall", "ExponentialAdhesion",
           "MaugisDugdaleAdhesion", "LennardJones93Adhesion", "SquaredExponentialAdhesion",
           "ResolutionError", "ResolutionWarning", "check_resolution", "resolution_report", "Load", "MeanGap",
           "ContactProblem", "ContactSolution"]
