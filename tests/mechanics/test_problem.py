"""ContactProblem: its half-space made from a modulus, its scales from the surface statistics,
and a copy of it against another interaction."""
import numpy as np
import pytest

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.mechanics.interactions import ExponentialAdhesion, HardWall
from petgap.mechanics.problem import ContactProblem
from petgap.parallel.grid import Grid
from petgap.surfaces.self_affine import self_affine
from petgap.surfaces.statistics import statistics


def _surface(comm, offset=0.0):
    grid = Grid((48, 40), size=(2.0, 1.5), comm=comm, planner="estimate", wisdom=False)
    return grid, self_affine(grid, 0.7, 0.2, rms_slope=0.1, seed=4) + offset


def test_half_space_from_a_modulus(comm):
    grid, h = _surface(comm)
    made = ContactProblem(grid, h, contact_modulus=2.5)
    given = ContactProblem(grid, h, ElasticHalfSpace(grid, 2.5))
    assert made.half_space.contact_modulus == 2.5 and made.half_space.grid is grid
    assert made.pressure_scale == given.pressure_scale
    assert ContactProblem(grid, h).half_space.contact_modulus == 1.0
    with pytest.raises(ValueError, match="disagrees"):
        ContactProblem(grid, h, ElasticHalfSpace(grid, 2.5), contact_modulus=1.0)


@pytest.mark.parametrize("offset", [0.0, 0.3, 1e3])
def test_scales_are_the_surface_statistics(comm, offset):
    """One computation: the problem's mean, h0 and h0' are the statistics' to the bit."""
    grid, h = _surface(comm, offset)
    problem = ContactProblem(grid, h)
    stats = statistics(grid, h)
    assert problem.mean_height == stats.mean
    assert problem.rms_height == stats.rms_height == problem.gap_scale
    assert problem.rms_slope == stats.rms_slope
    assert problem.pressure_scale == stats.rms_slope * problem.half_space.contact_modulus
    # the mean is removed exactly: an offset leaves h0 as it was, to round-off
    assert problem.rms_height == pytest.approx(statistics(grid, h - offset).rms_height,
                                               rel=1e-12)


def test_with_interaction_shares_the_surface_and_the_half_space(comm):
    grid, h = _surface(comm)
    sticky = ContactProblem(grid, h, interaction=ExponentialAdhesion(0.01, 0.05))
    hard = sticky.with_interaction(None)
    assert isinstance(hard.interaction, HardWall) and sticky.interaction.adhesive
    assert hard.half_space is sticky.half_space and hard.topography is sticky.topography
    assert (hard.gap_scale, hard.pressure_scale) == (sticky.gap_scale, sticky.pressure_scale)
    assert hard is not sticky
    before = sticky.operator_applications
    hard.elastic_pressure(np.zeros(grid.local_shape))
    assert sticky.operator_applications == before + 1 == hard.operator_applications
