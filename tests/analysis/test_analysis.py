"""The analysis of solved fields (petgap.analysis) and the ``petgap-post`` command.

Fields are built from closed forms rather than solved, so that every expected
number is known: Hertz spheres (discs of contact), Hertz cylinders (stripes), and
gap samples drawn exactly from Eq. 13.  Every test runs on all ranks of the suite's
communicator; comparisons against a ``COMM_SELF`` grid check that slab and
periodic boundaries change nothing.  All collective calls come before any assert.
"""
import json
import math

import numpy as np
import pytest
from mpi4py import MPI

from petgap import analysis
from petgap.parallel.grid import Grid
from petgap.io.results import ResultFile
from petgap.mechanics.interactions import ExponentialAdhesion, MaugisDugdaleAdhesion

E_STAR = 1.0


# ------------------------------------------------------------------ closed forms
def _positions(shape, size):
    nx, ny = shape
    dx, dy = size[0] / nx, size[1] / ny
    return np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dy, indexing="ij")


def _wrap(d, length):
    return (d + length / 2) % length - length / 2


def hertz_sphere(shape, size, centre, a, radius, modulus=E_STAR):
    """Global gap and pressure of a rigid sphere pressed to contact radius ``a``.

    ``p = p0 sqrt(1 - r^2/a^2)``, ``p0 = 2 a E* / (pi R)``; outside
    ``g = r^2/(2R) - a^2/R + (p0/(2 a E*)) [(2a^2 - r^2) arcsin(a/r) + a sqrt(r^2 - a^2)]``
    (Johnson 1985, Eq. 3.42b).  Distances are periodic minimum images.
    """
    x, y = _positions(shape, size)
    r = np.hypot(_wrap(x - centre[0], size[0]), _wrap(y - centre[1], size[1]))
    p0 = 2 * a * modulus / (math.pi * radius)
    ro = np.maximum(r, a)
    gap = ro ** 2 / (2 * radius) - a * a / radius + p0 / (2 * a * modulus) * (
        (2 * a * a - ro ** 2) * np.arcsin(a / ro) + a * np.sqrt(ro ** 2 - a * a))
    inside = r < a
    pressure = np.where(inside, p0 * np.sqrt(np.maximum(1 - (r / a) ** 2, 0.0)), 0.0)
    return np.where(inside, 0.0, np.maximum(gap, 0.0)), pressure


def hertz_cylinder(distance, a, radius, modulus=E_STAR):
    """Gap and pressure of a 2D Hertz line contact at signed distance from its axis.

    ``p = p0 sqrt(1 - s^2/a^2)``, ``p0 = E* a / (2R)``; outside
    ``g = (1/(2R)) [s sqrt(s^2 - a^2) - a^2 ln((s + sqrt(s^2 - a^2)) / a)]``.
    """
    s = np.abs(distance)
    so = np.maximum(s, a)
    root = np.sqrt(so ** 2 - a * a)
    gap = (so * root - a * a * np.log((so + root) / a)) / (2 * radius)
    p0 = modulus * a / (2 * radius)
    pressure = np.where(s < a, p0 * np.sqrt(np.maximum(1 - (s / a) ** 2, 0.0)), 0.0)
    return np.where(s < a, 0.0, gap), pressure


def local(grid, *arrays):
    return [np.ascontiguousarray(grid.local_part(a)) for a in arrays]


def serial_grid(shape, size=None):
    return Grid(shape, size=size, comm=MPI.COMM_SELF, planner="estimate")


# ---------------------------------------------------------------- crossings
def test_crossing_fraction_is_exact_for_the_edge_asymptotics():
    """Pixels on the universal edge profiles give back the edge position to round-off."""
    t_true = np.linspace(0.0, 1.0, 41)
    for intensity, spacing, modulus, cosine in [(1.0, 1.0, 1.0, 1.0), (3e-3, 0.25, 7.0, 1.0),
                                                (50.0, 2.0, 0.1, 0.6)]:
        s_in = t_true * spacing * cosine              # normal distances
        s_out = (1 - t_true) * spacing * cosine
        p_in = intensity * np.sqrt(s_in)
        g_out = 4 * intensity / (3 * modulus) * s_out ** 1.5
        t = analysis.crossing_fraction(p_in, g_out, spacing, modulus, cosine)
        np.testing.assert_allclose(t, t_true, rtol=0, atol=1e-12)
    # limits: no pressure -> edge at the inside pixel; zero gap, zero pressure -> at the outside one
    assert analysis.crossing_fraction(0.0, 1.0, 1.0, 1.0) == 0.0
    assert analysis.crossing_fraction(1.0, 0.0, 1.0, 1.0) == 1.0
    assert analysis.crossing_fraction(1.0, 1e-300, 1.0, 1.0) == pytest.approx(1.0)
    # zero gap under tension: the zero of the linearly interpolated pressure
    assert analysis.crossing_fraction(3.0, 0.0, 1.0, 1.0, p_out=-1.0) == pytest.approx(0.75)
    # the cubic alpha y^3 + beta y = d in y = A^(-2/3) gives the same point
    p_in, g_out, d = 0.7, 0.02, 1.0
    alpha, beta = p_in ** 2, (3 * E_STAR * g_out / 4) ** (2 / 3)
    y = np.roots([alpha, 0.0, beta, -d])
    y = float(y[np.abs(y.imag) < 1e-12].real.max())
    assert analysis.crossing_fraction(p_in, g_out, d, E_STAR) == pytest.approx(alpha * y ** 3)


# ---------------------------------------------------------------- perimeter
def test_disc_perimeter_converges(comm):
    """Hertz contacts of radius a = 4, 8, 16 pixels: the error against 2 pi a falls ~ (dx/a)^2."""
    errors, raw, midpoint = [], [], []
    for a in (4.0, 8.0, 16.0):
        n = int(2 * a) + 12
        grid = Grid((n, n), comm=comm, planner="estimate")
        err, rw, mid = [], [], []
        for offset in ((0.31, 0.17), (0.5, 0.5), (0.77, 0.05)):  # several pixel phases
            g, p = hertz_sphere((n, n), (n, n), (n / 2 + offset[0], n / 2 + offset[1]), a, 5 * a)
            gl, pl = local(grid, g, p)
            result = analysis.perimeter(grid, gl, pl, E_STAR)
            fallback = analysis.perimeter(grid, mask=analysis.contact_mask(gl, pl))
            exact = 2 * math.pi * a
            err.append(result.perimeter / exact - 1)
            rw.append(result.pixel_edge_length / exact)
            mid.append(fallback.perimeter / exact - 1)
        errors.append(max(abs(e) for e in err))
        raw.append(np.mean(rw))
        midpoint.append(np.mean(mid))
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[1] / errors[2] > 3  # second order
    assert errors[2] < 1e-3  # 0.05 % at a = 16 pixels
    # the raw pixel-edge count over-counts a disc by 4/pi at every resolution
    np.testing.assert_allclose(raw, 4 / math.pi, rtol=0.03)
    # midpoint crossings (binary mask only): the documented few-% bias, not converging
    assert all(0.02 < m < 0.08 for m in midpoint), midpoint


def test_disc_without_angle_correction_stalls(comm):
    """The cosine correction is what makes the perimeter converge (documented +0.2 %)."""
    n, a = 44, 16.0
    grid = Grid((n, n), comm=comm, planner="estimate")
    g, p = hertz_sphere((n, n), (n, n), (n / 2 + 0.31, n / 2 + 0.17), a, 5 * a)
    gl, pl = local(grid, g, p)
    plain = analysis.perimeter(grid, gl, pl, E_STAR, sweeps=0).perimeter / (2 * math.pi * a) - 1
    fixed = analysis.perimeter(grid, gl, pl, E_STAR).perimeter / (2 * math.pi * a) - 1
    assert 1e-3 < plain < 5e-3 and abs(fixed) < 3e-4


def test_disc_with_non_square_pixels(comm):
    """dx = 1, dy = 0.5: a physical circle of radius 12 still measures 2 pi a."""
    shape, size, a = (36, 72), (36.0, 36.0), 12.0
    grid = Grid(shape, size=size, comm=comm, planner="estimate")
    g, p = hertz_sphere(shape, size, (17.3, 18.1), a, 60.0)
    gl, pl = local(grid, g, p)
    result = analysis.perimeter(grid, gl, pl, E_STAR)
    assert abs(result.perimeter / (2 * math.pi * a) - 1) < 2e-3


@pytest.mark.parametrize("direction", ["x-normal", "y-normal"])
def test_straight_stripe_is_exact(comm, direction):
    """A cylinder contact along an axis: two straight edges of length L, to round-off.

    The x-normal stripe straddles the slab boundary of a 2-rank split (rows 19 | 20);
    the y-normal one runs through every slab and across the periodic x boundary,
    and is cut by the periodic y boundary.
    """
    shape = (40, 30)
    grid = Grid(shape, comm=comm, planner="estimate")
    x, y = _positions(shape, shape)
    if direction == "x-normal":
        s, length = _wrap(x - 20.37, 40), 30.0
    else:
        s, length = _wrap(y - 0.61, 30), 40.0
    g, p = hertz_cylinder(s, 4.3, 30.0)
    gl, pl = local(grid, g, p)
    result = analysis.perimeter(grid, gl, pl, E_STAR)
    assert result.perimeter == pytest.approx(2 * length, rel=1e-12)
    assert result.pixel_edge_length == pytest.approx(2 * length)


@pytest.mark.parametrize("q, p", [(1, 1), (2, 1)])
def test_oblique_stripe(comm, q, p):
    """Cylinder contacts along the lines q x - p y = const (45 and 26.6 degrees).

    Perimeter 2 N sqrt(q^2 + p^2); the raw pixel-edge count says 2 N (q + p).  At
    26.6 degrees the midpoint fallback is 8 % long and the uncorrected asymptotic
    crossings 0.35 %; with the angle correction the error is ~1e-5 (and falls as
    (dx/a)^2); at 45 degrees symmetry makes every variant exact.
    """
    n = 48
    grid = Grid((n, n), comm=comm, planner="estimate")
    x, y = _positions((n, n), (n, n))
    norm = math.hypot(q, p)
    gap, pres = hertz_cylinder(_wrap(q * x - p * y - 7.3, n) / norm, 4.8, 40.0)
    gl, pl = local(grid, gap, pres)
    result = analysis.perimeter(grid, gl, pl, E_STAR)
    plain = analysis.perimeter(grid, gl, pl, E_STAR, sweeps=0)
    midpoint = analysis.perimeter(grid, mask=analysis.contact_mask(gl, pl))
    exact = 2 * norm * n
    assert abs(result.perimeter / exact - 1) < 1e-4
    assert result.pixel_edge_length / exact == pytest.approx((q + p) / norm, rel=1e-12)
    if p == q:
        assert plain.perimeter == pytest.approx(exact)
        assert midpoint.perimeter == pytest.approx(exact)
    else:
        assert 2e-3 < plain.perimeter / exact - 1 < 5e-3
        assert midpoint.perimeter / exact - 1 == pytest.approx(0.080, abs=0.002)


def test_boundary_crossing_contacts_match_serial(comm):
    """Discs cut by the slab boundary and by both periodic boundaries: P on 2 ranks = P serial.

    An odd, non-square grid (37 x 30: slabs of 19 and 18 rows on two ranks); the
    same discs rolled into the middle of the box give the same perimeter.
    """
    shape = (37, 30)
    grid = Grid(shape, comm=comm, planner="estimate")
    one = serial_grid(shape)
    g1, p1 = hertz_sphere(shape, shape, (18.6, 14.2), 6.3, 25.0)    # across rows 18 | 19
    g2, p2 = hertz_sphere(shape, shape, (0.4, 29.7), 5.1, 20.0)     # the periodic corner
    g = np.minimum(g1, g2)
    p = p1 + p2
    gl, pl = local(grid, g, p)
    parallel = analysis.perimeter(grid, gl, pl, E_STAR)
    serial = analysis.perimeter(one, g, p, E_STAR)
    rolled = analysis.perimeter(one, np.roll(g, (17, 11), axis=(0, 1)),
                                np.roll(p, (17, 11), axis=(0, 1)), E_STAR)
    masked = analysis.perimeter(grid, mask=analysis.contact_mask(gl, pl))
    masked_serial = analysis.perimeter(one, mask=analysis.contact_mask(g, p))
    stats = analysis.contact_statistics(grid, gl, pl, 0.1, E_STAR)
    stats_serial = analysis.contact_statistics(one, g, p, 0.1, E_STAR)

    assert parallel.perimeter == pytest.approx(serial.perimeter, rel=1e-12)
    assert parallel.pixel_edges == serial.pixel_edges
    assert parallel.segments == serial.segments and parallel.saddles == serial.saddles
    assert rolled.perimeter == pytest.approx(serial.perimeter, rel=1e-12)
    assert masked.perimeter == pytest.approx(masked_serial.perimeter, rel=1e-12)
    assert serial.perimeter == pytest.approx(2 * math.pi * (6.3 + 5.1), rel=5e-3)
    assert stats.contact_pixels == stats_serial.contact_pixels
    assert stats.mean_diameter == pytest.approx(stats_serial.mean_diameter, rel=1e-12)


def test_saddle_cells_follow_the_centre_rule(comm):
    """Two contact pixels touching diagonally: joined only if the fields say the centre is in."""
    shape = (8, 6)
    one = serial_grid(shape)
    inside = np.zeros(shape, bool)
    inside[3, 2] = inside[4, 3] = True
    gap = np.where(inside, 0.0, 1.0)
    weak = analysis.perimeter(one, gap, np.where(inside, 1e-3, 0.0), E_STAR)  # centre out
    strong = analysis.perimeter(one, gap * 1e-6, np.where(inside, 1.0, 0.0), E_STAR)  # centre in
    mid = analysis.perimeter(one, mask=inside)
    assert weak.saddles == strong.saddles == mid.saddles == 1
    assert mid.perimeter == pytest.approx(2 * 4 * math.sqrt(0.5))  # two separate diamonds
    assert mid.segments == 8 and weak.segments == 8 and strong.segments == 8
    assert strong.perimeter > 1.5 * weak.perimeter  # joined: the outline of a fat diagonal blob


def test_invalid_input_fails_on_every_rank(comm):
    grid = Grid((16, 12), comm=comm, planner="estimate")
    good = np.zeros(grid.local_shape)
    bad = good if comm.rank == 0 else np.zeros((1, 12))   # wrong on rank 1 only
    with pytest.raises(ValueError, match="slab"):
        analysis.perimeter(grid, bad, good, E_STAR)
    nan = good.copy()
    nan[0, 0] = np.nan if comm.rank == comm.size - 1 else 0.0
    with pytest.raises(ValueError, match="non-finite"):
        analysis.gap_distribution(grid, nan, good)
    with pytest.raises(ValueError, match="contact_modulus"):
        analysis.perimeter(grid, good, good, -1.0)


# ---------------------------------------------------------------- statistics
def test_contact_statistics_of_a_hertz_disc(comm):
    n, a, radius = 48, 12.0, 60.0
    grid = Grid((n, n), comm=comm, planner="estimate")
    g, p = hertz_sphere((n, n), (n, n), (23.4, 24.2), a, radius)
    gl, pl = local(grid, g, p)
    slope = 0.1
    stats = analysis.contact_statistics(grid, gl, pl, slope, E_STAR)
    per = analysis.perimeter(grid, gl, pl, E_STAR)
    count = int(np.count_nonzero((g <= 0) & (p > 0)))
    assert stats.contact_pixels == count and stats.contact_fraction == count / n ** 2
    assert stats.perimeter == per.perimeter
    assert stats.mean_diameter == pytest.approx(math.pi * count / per.perimeter)  # Eq. 2
    assert stats.g0 == pytest.approx(4 * slope * stats.mean_diameter / 3)       # Eq. 12
    assert stats.mean_diameter == pytest.approx(math.pi * a / 2, rel=0.02)       # disc: pi a / 2
    # Hertz force F = (2/3) p0 pi a^2, and kappa_rep = A h0' E* / F
    force = 2 / 3 * (2 * a * E_STAR / (math.pi * radius)) * math.pi * a * a
    assert stats.repulsive_force == pytest.approx(force, rel=0.01)
    assert stats.kappa_rep == pytest.approx(count * slope * E_STAR / stats.repulsive_force)


def test_round_off_gaps_in_contact_count_as_zero(comm):
    """Contact pixels whose gap is solver round-off are contact by default, not with tolerance 0."""
    n = 32
    grid = Grid((n, n), comm=comm, planner="estimate")
    g, p = hertz_sphere((n, n), (n, n), (15.5, 16.5), 8.0, 40.0)
    noisy = np.where(p > 0, 1e-13, g)
    gl, pl = local(grid, noisy, p)
    default = analysis.contact_statistics(grid, gl, pl, 0.1, E_STAR)
    exact = analysis.contact_statistics(grid, gl, pl, 0.1, E_STAR, gap_tolerance=0.0)
    dist = analysis.gap_distribution(grid, gl, pl, gap_tolerance=0.0)
    assert default.contact_pixels == np.count_nonzero(p > 0)
    assert exact.contact_pixels == 0
    # with tolerance 0 the round-off gaps are "open", and fall below the histogram's range
    assert dist.below_fraction == np.count_nonzero(p > 0) / n ** 2


# ---------------------------------------------------------- gap distribution
def _scatter(values, shape, seed):
    """Values placed on the grid in a fixed random order (so every slab gets a mixture)."""
    order = np.random.default_rng(seed).permutation(values.size)
    return values[order].reshape(shape)


def test_gap_histogram_of_uniform_gaps(comm):
    """Uniform gaps: density 1/(g2 - g1) in every bin, integral 1, contact and zero-gap excluded."""
    shape = (64, 48)
    npix = shape[0] * shape[1]
    n_contact, n_zero = 300, 30
    g1, g2 = 1e-3, 2.0
    n_open = npix - n_contact - n_zero
    gaps = np.concatenate([np.zeros(n_contact + n_zero),
                           g1 + (g2 - g1) * (np.arange(n_open) + 0.5) / n_open])
    pres = np.concatenate([np.ones(n_contact), -np.ones(n_zero), np.zeros(n_open)])
    g, p = _scatter(gaps, shape, 1), _scatter(pres, shape, 1)
    grid = Grid(shape, comm=comm, planner="estimate")
    gl, pl = local(grid, g, p)
    dist = analysis.gap_distribution(grid, gl, pl, gmin=g1, gmax=g2, bins=12)
    serial = analysis.gap_distribution(serial_grid(shape), g, p, gmin=g1, gmax=g2, bins=12)
    no_zero = analysis.gap_distribution(grid, gl, np.where(pl < 0, 1.0, pl), gmin=g1, gmax=g2)

    np.testing.assert_array_equal(dist.counts, serial.counts)
    assert dist.counts.sum() == n_open
    assert dist.contact_fraction == n_contact / npix
    assert dist.zero_gap_fraction == n_zero / npix
    n_nc = npix - n_contact
    assert dist.integral == pytest.approx(n_open / n_nc, rel=1e-12)  # zero-gap pixels excluded
    assert no_zero.integral == pytest.approx(1.0, rel=1e-12)         # none: integral exactly 1
    full = dist.density * n_nc / n_open    # density of the open pixels alone
    big = dist.counts >= 50                # +-1 pixel of binning noise per bin
    np.testing.assert_allclose(full[big], 1 / (g2 - g1), rtol=0.05)
    np.testing.assert_allclose(dist.centres, np.sqrt(dist.edges[1:] * dist.edges[:-1]))


def _eq13_sample(shape, c, g0, seed):
    """Gaps drawn exactly from Eq. 13 (quantiles) up to g0, uniform in (g0, 20 g0) beyond."""
    npix = shape[0] * shape[1]
    n_contact = int(round(c * npix))
    n_near = int(math.pi * c * npix)
    u = (np.arange(n_near) + 0.5) / npix
    near = g0 * (u / (math.pi * c)) ** 1.5        # inverse of c_n(g) = pi c (g / g0)^(2/3)
    far = g0 * (1 + 19 * (np.arange(npix - n_contact - n_near) + 0.5)
                / (npix - n_contact - n_near))
    gaps = np.concatenate([np.zeros(n_contact), near, far])
    pres = np.concatenate([np.ones(n_contact), np.zeros(npix - n_contact)])
    return _scatter(gaps, shape, seed), _scatter(pres, shape, seed), n_contact / npix


def test_collapse_of_eq13_gives_minus_one_third(comm):
    shape, g0 = (128, 128), 2.0
    g, p, c = _eq13_sample(shape, 0.05, g0, 2)
    grid = Grid(shape, comm=comm, planner="estimate")
    gl, pl = local(grid, g, p)
    dist = analysis.gap_distribution(grid, gl, pl, gap_tolerance=0.0)
    near = analysis.near_contact_area(grid, gl, pl, [g0, 0.18 * g0, 0.01 * g0], g0=g0,
                                      gap_tolerance=0.0)
    x, y = analysis.collapse(dist, None, c, g0)
    fit = analysis.fit_power_law(x, y)
    fixed = analysis.fit_power_law(x, y, x_range=(1e-3, 0.5))

    assert dist.integral == pytest.approx(1.0, rel=1e-12)
    assert fit.exponent == pytest.approx(-1 / 3, abs=0.01)
    assert fit.prefactor == pytest.approx(1.0, rel=0.05)
    assert fit.x_min < 1e-3 and 0.2 < fit.x_max <= 1.0 and fit.decades > 2.5
    assert fixed.exponent == pytest.approx(-1 / 3, abs=0.01)
    # Eq. 14: c_n = pi c (g_c / g0)^(2/3), to one pixel per cut-off (plus the binned c)
    np.testing.assert_allclose(near.measured, near.predicted, rtol=0, atol=2.0 / g.size)
    assert near.measured[0] / c == pytest.approx(math.pi, rel=1e-3)   # c_n(g0) = pi c
    assert near.measured[1] / c == pytest.approx(1.0, rel=0.01)       # c_n(0.18 g0) = c


def test_power_law_window_on_a_known_curve():
    """A roll-off below 1e-3 and a Gaussian bump near 3: the -1/3 window lies between."""
    x = np.geomspace(1e-6, 10, 71)
    y = (x + 1e-3) ** (-1 / 3) + 5 * np.exp(-np.log10(x / 3) ** 2 / 0.1)
    fit = analysis.fit_power_law(x, y)
    assert 1e-3 < fit.x_min < 1e-2 and 0.1 < fit.x_max < 1.0
    assert fit.exponent == pytest.approx(-1 / 3, abs=0.03)
    none = analysis.fit_power_law(x, x ** 0.5)
    assert math.isnan(none.exponent) and none.npoints == 0


def _broken_power_law(x1, x2, exponent, per_decade=10, scale=None, seed=0, shift=0.0):
    """Collapsed data with ``y = x^exponent`` exactly on ``x1 <= x <= x2``: flat below (the
    roll-off), rising as ``x^(1/2)`` above (towards the Gaussian peak); with ``scale``, the
    counts of a histogram of ``scale`` pixels per unit ``y dx``, drawn from Poisson laws."""
    edges = np.geomspace(1e-5, 3.0, int(round(per_decade * math.log10(3e5))) + 1) * 10 ** shift
    x = np.sqrt(edges[1:] * edges[:-1])
    y = np.where(x < x1, x1 ** exponent, np.where(x > x2, x2 ** exponent * np.sqrt(x / x2),
                                                  x ** exponent))
    if scale is None:
        return x, y, None
    counts = np.random.default_rng(seed).poisson(scale * y * np.diff(edges))
    return x, counts / (scale * np.diff(edges)), counts


@pytest.mark.parametrize("x1, x2", [(1e-3, 3e-2), (2e-3, 2e-2)])
@pytest.mark.parametrize("exponent", [-1 / 3, -0.5])
def test_auto_fit_range_lands_inside_a_known_power_law(x1, x2, exponent):
    """The default fit range of petgap-post: inside the power law, and its exponent.

    The resolution bound is put half a decade below the power law, so the roll-off and the
    rise are both inside the bounds and the range has to be found from the data."""
    decades = math.log10(x2 / x1)
    cases = [_broken_power_law(x1, x2, exponent, shift=shift) for shift in (0.0, 0.05)]
    # ~1e4-1e5 pixels per bin, as in the near-contact bins of a 2048^2-4096^2 run
    cases += [_broken_power_law(x1, x2, exponent, scale=1e7, seed=seed) for seed in range(3)]
    for k, (x, y, counts) in enumerate(cases):
        chosen = analysis.auto_fit_range(x, y, counts, x_resolution=x1 / 10)
        fit = analysis.fit_power_law(x, y, x_range=(chosen.x_min, chosen.x_max))
        assert chosen.bound_min == pytest.approx(0.3 * x1) and chosen.bound_max == 0.1
        assert x1 <= chosen.x_min < chosen.x_max <= x2, (k, chosen)
        assert math.log10(chosen.x_max / chosen.x_min) >= decades - 0.6, (k, chosen)
        if counts is None:
            assert fit.exponent == pytest.approx(exponent, abs=1e-9)
        else:
            assert fit.exponent == pytest.approx(exponent, abs=0.01)
    # the former fixed default, 0.01 .. 0.1, sits on the rise here
    x, y, _ = cases[0]
    assert abs(analysis.fit_power_law(x, y, x_range=(0.01, 0.1)).exponent - exponent) > 0.2


def test_auto_fit_range_without_a_range():
    x, y, counts = _broken_power_law(1e-3, 3e-2, -1 / 3, scale=1e7)
    # the resolution bound above 0.1 g0: nothing to fit
    none = analysis.auto_fit_range(x, y, counts, x_resolution=0.05)
    assert math.isnan(none.x_min) and none.npoints == 0 and not none.qualified
    assert "resolution bound" in none.reason
    # p(g) rising everywhere (no near-contact divergence)
    rising = analysis.auto_fit_range(x, x ** 0.5, None, x_resolution=1e-4)
    assert math.isnan(rising.x_min) and "does not decrease" in rising.reason
    # too few populated bins
    sparse = analysis.auto_fit_range(x, y, np.where(x < 0.07, 0, counts), x_resolution=1e-4)
    assert math.isnan(sparse.x_min) and "fewer than 3 bins" in sparse.reason
    # coarse bins (2 per decade): local slopes from the neighbours, still inside
    x, y, _ = _broken_power_law(1e-3, 1e-1, -1 / 3, per_decade=2)
    coarse = analysis.auto_fit_range(x, y, None, x_resolution=1e-4)
    assert 1e-3 <= coarse.x_min < coarse.x_max <= 0.1
    with pytest.raises(ValueError, match="x_resolution"):
        analysis.auto_fit_range(x, y, x_resolution=0.0)


def test_resolved_gap_is_eq12_half_a_pixel_from_the_edge():
    d_rep, a0, g0 = 40.0, 1.0, 5.0
    gap = g0 * (0.5 * a0 / d_rep) ** 1.5               # Eq. 12 at s = a0 / 2
    assert analysis.resolved_gap(d_rep, a0) == pytest.approx(gap / g0, rel=1e-14)


def test_collapse_definition():
    """y = 3 g0 (1 - c) density / (2 pi c): Eq. 13 itself maps onto y = x^(-1/3)."""
    c, g0 = 0.04, 3.0
    g = np.geomspace(1e-4, 1, 9) * g0
    p_full = 2 * math.pi * c / (3 * g0) * (g0 / g) ** (1 / 3)   # Eq. 13, normalised over A0
    x, y = analysis.collapse(p_full / (1 - c), g, c, g0)       # as gap_distribution normalises
    np.testing.assert_allclose(y, x ** (-1 / 3), rtol=1e-12)


# ----------------------------------------------------------------- adhesion
def test_eq16_quadrature_has_gamma_two_thirds():
    """The integral of Eq. 16 is Gamma(2/3) = 1.354 times the result printed in the paper."""
    from scipy.integrate import quad
    w, rho, g0, area = 0.3, 0.7, 5.0, 2.5
    interaction = ExponentialAdhesion(w, rho)
    integrand = lambda g: (g0 / g) ** (1 / 3) * interaction.derivative(g) / g0  # noqa: E731
    head, _ = quad(integrand, 0, rho, limit=200)
    tail, _ = quad(integrand, rho, np.inf, limit=200)
    per_area = -(2 * math.pi / 3) * (head + tail)        # F_att / A_rep, attraction negative
    eq16 = analysis.attractive_force_eq16(w, rho, g0, area)
    assert eq16.exact / area == pytest.approx(per_area, rel=1e-9)
    assert eq16.printed == pytest.approx(-(2 * math.pi / 3) * w * area / (g0 ** 2 * rho) ** (1 / 3))
    assert eq16.exact / eq16.printed == pytest.approx(math.gamma(2 / 3)) == pytest.approx(1.3541179)
    assert analysis.inverse_kappa_att(eq16.exact, 0.1, 2.0, area) == pytest.approx(
        -eq16.exact / (0.1 * 2.0 * area))


def test_attractive_force_pixel_sum(comm):
    """F_att = -dx dy sum v'(g), split into contact and non-contact pixels, by hand."""
    shape, size = (10, 6), (5.0, 1.5)    # dx = 0.5, dy = 0.25
    w, rho = 0.2, 0.3
    gaps = np.array([0.0, 0.0, 0.0, 0.1, 0.5, 2.0])[np.arange(60) % 6].reshape(shape)
    pres = np.where(np.arange(60).reshape(shape) % 6 == 0, 1.0, 0.0)  # pixel kind 1: g = 0, p = 0
    pres[gaps > 0] = -0.1
    grid = Grid(shape, size=size, comm=comm, planner="estimate")
    gl, pl = local(grid, gaps, pres)
    force = analysis.attractive_force_measured(grid, gl, ExponentialAdhesion(w, rho), pressure=pl)
    bare = analysis.attractive_force_measured(grid, gl, lambda g: w / rho * np.exp(-g / rho))
    stress = {g: w / rho * math.exp(-g / rho) for g in (0.0, 0.1, 0.5, 2.0)}
    per_row = 3 * stress[0.0] + stress[0.1] + stress[0.5] + stress[2.0]   # 6 pixels, 10 times
    hand = -0.5 * 0.25 * 10 * per_row
    assert force.force == pytest.approx(hand) and bare.force == pytest.approx(hand)
    assert force.contact_force == pytest.approx(-0.5 * 0.25 * 10 * stress[0.0])
    assert force.noncontact_force == pytest.approx(hand - force.contact_force)
    assert force.per_area == pytest.approx(hand / 7.5)
    assert math.isnan(bare.contact_force)


def test_fig4_integrand_is_normalised():
    from scipy.integrate import quad
    for r in (0.01, 0.1, 1.0):
        f = lambda x: analysis.fig4_integrand(x, r, per_log=False)  # noqa: E731
        total = quad(f, 0, r, limit=200)[0] + quad(f, r, np.inf, limit=200)[0]
        assert total == pytest.approx(1.0, rel=1e-8)
        x = np.geomspace(1e-4 * r, 100 * r, 20001)
        curve = analysis.fig4_integrand(x, r)
        assert x[np.argmax(curve)] == pytest.approx(2 * r / 3, rel=1e-3)  # peak of x f(x)
    assert analysis.fig4_integrand(np.ones(5), [0.1, 1.0]).shape == (2, 5)


# ---------------------------------------------------------------- petgap-post
def _discs(shape, specs):
    g = np.full(shape, np.inf)
    p = np.zeros(shape)
    for centre, a, radius in specs:
        gi, pi = hertz_sphere(shape, shape, centre, a, radius)
        g, p = np.minimum(g, gi), p + pi
    return g, p


SCENE = {"grid": {"nx": 48, "ny": 40, "a0": 1.0},
         "surface": {"kind": "self-affine", "hurst": 0.8, "lambda_min": 4.0, "lambda_max": 20.0,
                     "rms_slope": 0.1},
         "material": {"contact_modulus": E_STAR},
         "interaction": {"kind": "hard-wall", "work_of_adhesion": None, "range": None}}


def _write_run(comm, path, shape, steps, scene=SCENE, topography=True):
    """A result file in the layout of petgap.io.results: fields per step, attributes as petgap writes."""
    grid = Grid(shape, comm=comm, planner="estimate")
    with ResultFile.create(path, comm, provenance={"scene_resolved": json.dumps(scene)}) as out:
        if topography:
            out.write_field("topography", grid, np.zeros(grid.local_shape),
                            attrs={"statistics": {"rms_slope": 0.1, "rms_height": 1.0}})
        for index, (fields, attrs) in enumerate(steps):
            group = out.begin_step(index)
            for name, value in fields.items():
                out.write_field(name, grid, grid.local_part(value), group=group)
            out.end_step(group, attrs=attrs)
    return grid


def test_post_cli_tables_and_figures(comm, mpi_tmp_path, run_cli):
    shape = (48, 40)
    g, p = _discs(shape, [((12.3, 10.2), 5.2, 30.0), ((30.6, 27.9), 6.1, 25.0),
                          ((23.5, 0.4), 3.9, 20.0)])
    w, rho = 2e-3, 0.5
    ga, pa = g * 0.9, p - w / rho * np.exp(-g / rho) * (g > 0)   # an "adhesive" step
    run = mpi_tmp_path / "run.h5"
    # step attributes as petgap run writes them for the paper's protocol: step 1 is the
    # adhesive step at the mean gap of the non-adhesive reference step 0
    grid = _write_run(comm, run, shape, [
        ({"gap": g, "pressure": p}, {"plan": {"chain": "reference", "reference_step": -1},
                                     "solution": {"contact_fraction": 0.123}}),
        ({"gap": ga, "pressure": pa}, {"plan": {"chain": "adhesive", "reference_step": 0},
                                       "interaction": {"kind": "exponential",
                                                       "work_of_adhesion": w, "range": rho}})])
    out, other = mpi_tmp_path / "post", mpi_tmp_path / "post-ref"
    proc = run_cli(["petgap-post", run, "--output-dir", out, "--bins", "8"], ranks=2)
    again = run_cli(["petgap-post", run, "--output-dir", out], ranks=1)
    explicit = run_cli(["petgap-post", f"{run}:1", "--reference", f"{run}:0", "-o", other,
                        "--format", "svg", "-q"], ranks=1)
    # what the command should have found, computed here
    gl, pl = local(grid, g, p)
    stats = analysis.contact_statistics(grid, gl, pl, 0.1, E_STAR)
    gal, pal = local(grid, ga, pa)
    force = analysis.attractive_force_measured(grid, gal, ExponentialAdhesion(w, rho), pal)
    stats_a = analysis.contact_statistics(grid, gal, pal, 0.1, E_STAR)
    dist = analysis.gap_distribution(grid, gl, pl, bins_per_decade=8)

    assert proc.returncode == 0, proc.stderr
    names = {f.name for f in out.iterdir()}
    per_run = {"run-psd.png", "run-step0000-maps.png", "run-step0000-maps.npz",
               "run-step0001-maps.png", "run-step0001-maps.npz", "run-sweep.png",
               "run-patches.png"}
    overview = {"figures.json", "report.html", "patches.csv", "surface-statistics.csv",
                "surface-statistics.json"}
    assert names == {"gap-analysis.csv", "gap-analysis.json", "fig2-gap-distribution.png",
                     "fig3-adhesion.png", "fig4-integrand.png"} | per_run | overview
    for png in ("fig2-gap-distribution.png", "fig3-adhesion.png", "fig4-integrand.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((out / "gap-analysis.json").read_text())
    rows = doc["rows"]
    assert [r["step"] for r in rows] == [0, 1]
    r0, r1 = rows
    assert r0["c"] == stats.contact_fraction and r0["contact_pixels"] == stats.contact_pixels
    assert r0["P_rep"] == pytest.approx(stats.perimeter, rel=1e-12)
    assert r0["d_rep"] == pytest.approx(stats.mean_diameter, rel=1e-12)
    assert r0["g0"] == pytest.approx(stats.g0, rel=1e-12)
    assert r0["interaction"] == "hard-wall" and r0["F_att"] is None
    assert r0["rms_slope_source"] == "topography dataset attributes: statistics.rms_slope"
    assert r0["cn_g0_eq14"] == pytest.approx(math.pi * stats.contact_fraction)
    assert doc["distributions"][0]["counts"] == dist.counts.tolist()
    assert r1["interaction"] == "exponential"
    assert r1["F_att"] == pytest.approx(force.force, rel=1e-12)
    assert r1["inv_kappa_att"] == pytest.approx(
        -force.force / (0.1 * E_STAR * stats_a.contact_area), rel=1e-12)
    assert r1["F_att_eq16_exact"] / r1["F_att_eq16_printed"] == pytest.approx(math.gamma(2 / 3))
    assert r0["chain"] == "reference" and r1["reference_step"] == 0
    assert r0["c_solver"] == 0.123 and r1["c_solver"] is None   # the solver's value, tabled
    # Fig. 4 from the adhesive step's data: its shares add up with the contact's to ~1
    (by_gap,) = doc["force_by_gap"]
    assert (by_gap["file"], by_gap["step"]) == (str(run), 1)
    assert by_gap["rho_over_g0"] == pytest.approx(rho / r1["g0"], rel=1e-12)
    widths = np.diff(np.log(by_gap["x"]))[0]
    assert sum(by_gap["share"]) * widths + by_gap["contact_share"] + by_gap["outside_share"] \
        == pytest.approx(1.0, rel=1e-9)
    assert doc["fig3_references"] == [{"file": str(run), "step": 0, "c": r0["c"], "g0": r0["g0"],
                                       "normalised_steps": [[str(run), 1]], "duplicates": []}]
    header = (out / "gap-analysis.csv").read_text().splitlines()[0].split(",")
    assert {"c", "A_rep", "P_rep", "d_rep", "g0", "exponent", "power_law_x_min", "cn_g0",
            "cn_018g0_eq14", "F_att", "F_att_eq16_printed", "F_att_eq16_exact",
            "inv_kappa_att", "kappa_rep"} <= set(header)
    # outputs are never overwritten without --overwrite
    assert again.returncode == 2 and "refusing to overwrite" in again.stderr
    # an explicit --reference (analysed although not among the inputs), SVG figures
    assert explicit.returncode == 0, explicit.stderr
    assert {f.name for f in other.iterdir()} == {
        "gap-analysis.csv", "gap-analysis.json", "fig2-gap-distribution.svg",
        "fig3-adhesion.svg", "fig4-integrand.svg", "run-psd.svg", "run-step0001-maps.svg",
        "run-step0001-maps.npz", "run-patches.svg"} | overview
    ref_doc = json.loads((other / "gap-analysis.json").read_text())
    assert [r["step"] for r in ref_doc["rows"]] == [1]
    assert ref_doc["fig3_references"][0]["step"] == 0


def test_post_rebuilds_any_law_from_its_attributes(comm, mpi_tmp_path, run_cli):
    """A step solved with another law (Maugis-Dugdale): petgap-post rebuilds it from the
    step's ``interaction.*`` attributes and measures ``F_att`` (Eq. 15) with its ``v'``;
    Eq. 16 and Fig. 4's closed forms are the exponential law's, so they are left out.
    An unknown kind is an error naming the kinds there are."""
    shape = (48, 40)
    g, p = _discs(shape, [((20.3, 18.2), 6.0, 30.0)])
    w, delta = 2e-3, 0.5
    law = MaugisDugdaleAdhesion(w, delta)
    ga, pa = g, p - law.derivative(g) * (g > 0)
    run, unknown = mpi_tmp_path / "dugdale.h5", mpi_tmp_path / "unknown.h5"
    grid = _write_run(comm, run, shape, [({"gap": ga, "pressure": pa},
                                          {"interaction": law.attributes()})])
    _write_run(comm, unknown, shape, [({"gap": ga, "pressure": pa},
                                       {"interaction": {"kind": "dugdale"}})])
    proc = run_cli(["petgap-post", run, "-o", mpi_tmp_path / "post", "-q"], ranks=1)
    bad = run_cli(["petgap-post", unknown, "-o", mpi_tmp_path / "bad", "-q"], ranks=1)
    gal, pal = local(grid, ga, pa)
    force = analysis.attractive_force_measured(grid, gal, law, pal)

    assert proc.returncode == 0, proc.stderr
    doc = json.loads((mpi_tmp_path / "post" / "gap-analysis.json").read_text())
    (row,) = doc["rows"]
    assert row["interaction"] == "maugis-dugdale"
    assert (row["work_of_adhesion"], row["range"]) == (w, delta)
    assert row["F_att"] == pytest.approx(force.force, rel=1e-12) and force.force < 0
    assert row["F_att_eq16_exact"] is None and row["F_att_eq16_printed"] is None
    assert doc["force_by_gap"][0]["rho_over_g0"] is None
    assert bad.returncode == 2
    assert "interaction.kind = 'dugdale' is not known to petgap-post (hard-wall, " \
           "exponential, maugis-dugdale, lennard-jones-9-3, squared-exponential)" in bad.stderr


def test_post_cli_errors(comm, mpi_tmp_path, run_cli):
    shape = (48, 40)
    g, p = _discs(shape, [((20.3, 18.2), 6.0, 30.0)])
    no_pressure = mpi_tmp_path / "nopressure.h5"
    _write_run(comm, no_pressure, shape, [({"gap": g}, {})])
    bare_scene = mpi_tmp_path / "bare.h5"
    _write_run(comm, bare_scene, shape, [({"gap": g, "pressure": p}, {})],
               scene={"grid": {"a0": 1.0}})
    plain = mpi_tmp_path / "plain.h5"
    if comm.rank == 0:
        import h5py
        with h5py.File(plain, "w", driver=None) as f:
            f["gap"] = g
    comm.Barrier()
    missing = mpi_tmp_path / "missing.h5"
    out = mpi_tmp_path / "out"
    results = [run_cli(["petgap-post", path, "--output-dir", out])
               for path in (missing, no_pressure, bare_scene, plain, f"{no_pressure}:7")]

    for proc in results:
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.startswith("petgap-post: error: ") and "Traceback" not in proc.stderr
    assert f"{missing}: file not found" in results[0].stderr
    assert "step_0000" in results[1].stderr and "dataset 'pressure' missing" in results[1].stderr
    assert "missing attribute 'contact_modulus'" in results[2].stderr
    assert "step_0000" in results[2].stderr
    assert "not a petgap result file" in results[3].stderr
    assert "no step 7" in results[4].stderr


def _protocol_run(comm, path, shape, reference, adhesive, w, seed=1, load=0.002, rho=0.5):
    """A result file of the paper's protocol as petgap run writes it: step 0 the non-adhesive
    reference at ``load``, step 1 the adhesive solve at its mean gap; one ``w`` per file."""
    scene = json.loads(json.dumps(SCENE))
    scene["surface"]["seed"] = seed
    scene["interaction"] = {"kind": "exponential", "work_of_adhesion": w, "range": rho}
    scene["control"] = {"kind": "load", "values": [load], "reference": "non-adhesive"}
    (g, p), (ga, pa) = reference, adhesive
    _write_run(comm, path, shape, [
        ({"gap": g, "pressure": p},
         {"plan": {"chain": "reference", "adhesive": False, "reference_step": -1},
          "interaction": {"kind": "hard-wall"},
          "solution": {"control": "load", "control_value": load}}),
        ({"gap": ga, "pressure": pa},
         {"plan": {"chain": "adhesive", "adhesive": True, "reference_step": 0},
          "interaction": {"kind": "exponential", "work_of_adhesion": w, "range": rho},
          "solution": {"control": "mean-gap", "control_value": float(np.mean(g))}})],
        scene=scene)


def test_post_cli_fig3_draws_each_reference_once(comm, mpi_tmp_path, run_cli):
    """Several protocol files of one surface and load: one reference curve, not one per file."""
    shape = (48, 40)
    specs = [((12.3, 10.2), 5.2, 30.0), ((30.6, 27.9), 6.1, 25.0), ((23.5, 0.4), 3.9, 20.0)]
    g, p = _discs(shape, specs)
    g2, p2 = _discs(shape, [((20.1, 19.7), 7.0, 30.0)])       # another surface (seed 2)
    files = []
    for k, w in enumerate((1e-3, 2e-3, 4e-3)):
        path = mpi_tmp_path / f"protocol_w{w:g}.h5"
        adhesive = (g * (1 - 0.05 * (k + 1)), p - w / 0.5 * np.exp(-g / 0.5) * (g > 0))
        _protocol_run(comm, path, shape, (g, p), adhesive, w)
        files.append(path)
    other = mpi_tmp_path / "protocol_seed2.h5"
    _protocol_run(comm, other, shape, (g2, p2), (0.9 * g2, p2), 2e-3, seed=2)
    out, explicit = mpi_tmp_path / "post", mpi_tmp_path / "post-ref"
    proc = run_cli(["petgap-post", *files, other, "-o", out, "-q"], ranks=2)
    with_ref = run_cli(["petgap-post", *files, other, "--reference", f"{files[1]}:0",
                        "-o", explicit, "-q"], ranks=1)

    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "gap-analysis.json").read_text())
    refs = doc["fig3_references"]
    assert [(r["file"], r["step"]) for r in refs] == [(str(files[0]), 0), (str(other), 0)]
    assert refs[0]["normalised_steps"] == [[str(f), 1] for f in files]
    assert refs[0]["duplicates"] == [[str(f), 0] for f in files[1:]]
    assert refs[1]["normalised_steps"] == [[str(other), 1]] and refs[1]["duplicates"] == []
    drawn = [(s["file"], s["step"]) for s in doc["legends"]["fig3"] if s["reference"]]
    assert drawn == [(str(files[0]), 0), (str(other), 0)]       # each distinct reference once
    assert len(doc["legends"]["fig3"]) == 6
    assert all("(ref. protocol_" in s["label"] for s in doc["legends"]["fig3"])
    # --reference: the other files' copies of it are not drawn again; the other surface is
    assert with_ref.returncode == 0, with_ref.stderr
    ref_doc = json.loads((explicit / "gap-analysis.json").read_text())
    (ref,) = ref_doc["fig3_references"]
    assert (ref["file"], ref["step"]) == (str(files[1]), 0)
    assert ref["duplicates"] == [[str(files[0]), 0], [str(files[2]), 0]]
    assert ref["normalised_steps"] == [[str(f), 1] for f in files] + [[str(other), 0],
                                                                      [str(other), 1]]
    assert sum(s["reference"] for s in ref_doc["legends"]["fig3"]) == 1


def test_post_cli_fig2_legend_names_lambda_min(comm, mpi_tmp_path, run_cli):
    """Every Fig. 2 label says lambda_min; lambda_max / lambda_min and L / lambda_max where
    they differ; what all series share goes into the legend title."""
    shape = (48, 40)
    g, p = _discs(shape, [((12.3, 10.2), 5.2, 30.0), ((30.6, 27.9), 6.1, 25.0)])
    runs = []
    for name, lmin, lmax in [("a", 4.0, 16.0), ("b", 8.0, 32.0), ("c", 4.0, 8.0)]:
        scene = json.loads(json.dumps(SCENE))
        scene["surface"].update(lambda_min=lmin, lambda_max=lmax)
        path = mpi_tmp_path / f"{name}.h5"
        _write_run(comm, path, shape, [({"gap": g, "pressure": p}, {})], scene=scene)
        runs.append(path)
    out_all, out_same = mpi_tmp_path / "all", mpi_tmp_path / "same"
    both = run_cli(["petgap-post", *runs, "-o", out_all, "-q"], ranks=1)
    # a and b: the same ratio 4 and L / lambda_max = 3 x 2.5 vs 1.5 x 1.25
    pair = run_cli(["petgap-post", runs[0], runs[1], "-o", out_same, "-q"], ranks=1)

    assert both.returncode == 0, both.stderr
    legends = json.loads((out_all / "gap-analysis.json").read_text())["legends"]
    labels = [s["label"] for s in legends["fig2"]]
    assert labels == [
        r"$\lambda_{min} = 4\,a_0$, $\lambda_{max}/\lambda_{min} = 4$, "
        r"$L/\lambda_{max} = 3 \times 2.5$",
        r"$\lambda_{min} = 8\,a_0$, $\lambda_{max}/\lambda_{min} = 4$, "
        r"$L/\lambda_{max} = 1.5 \times 1.25$",
        r"$\lambda_{min} = 4\,a_0$, $\lambda_{max}/\lambda_{min} = 2$, "
        r"$L/\lambda_{max} = 6 \times 5$"]
    assert legends["fig2_title"] == ""
    assert pair.returncode == 0, pair.stderr
    legends = json.loads((out_same / "gap-analysis.json").read_text())["legends"]
    assert [s["label"] for s in legends["fig2"]] == [
        r"$\lambda_{min} = 4\,a_0$, $L/\lambda_{max} = 3 \times 2.5$",
        r"$\lambda_{min} = 8\,a_0$, $L/\lambda_{max} = 1.5 \times 1.25$"]
    assert legends["fig2_title"] == r"$\lambda_{max}/\lambda_{min} = 4$"


def test_post_cli_fit_range(comm, mpi_tmp_path, run_cli):
    """The exponent's fit range: chosen from the data by default and recorded; --fit-range
    overrides it; a reversed range is a usage error."""
    # one square contact of c = 0.05 (d_rep = pi s / 4 ~ 45 a0, g0 ~ 6 a0), the other pixels'
    # gaps drawn from Eq. 13 with g0 = 20 (so y ~ x^(-1/3) up to x ~ 3 in petgap-post's g0)
    shape, side = (256, 256), 57
    gaps, _, _ = _eq13_sample(shape, side * side / (256 * 256), 20.0, 2)
    block = np.zeros(shape, dtype=bool)
    block[100:100 + side, 30:30 + side] = True
    order = np.random.default_rng(5).permutation(np.count_nonzero(~block))
    g = np.zeros(shape)
    g[~block] = np.sort(gaps.ravel())[-np.count_nonzero(~block):][order]
    p = np.where(block, 1e-3, 0.0)
    run = mpi_tmp_path / "eq13.h5"
    _write_run(comm, run, shape, [({"gap": g, "pressure": p}, {})])
    auto, fixed = mpi_tmp_path / "auto", mpi_tmp_path / "fixed"
    default = run_cli(["petgap-post", run, "-o", auto, "-q"], ranks=2)
    given = run_cli(["petgap-post", run, "-o", fixed, "-q", "--fit-range", "0.002", "0.05"],
                    ranks=1)
    reversed_ = run_cli(["petgap-post", run, "-o", mpi_tmp_path / "x", "--fit-range", "0.1",
                         "0.01"], ranks=1)

    assert default.returncode == 0, default.stderr
    doc = json.loads((auto / "gap-analysis.json").read_text())
    (row,) = doc["rows"]
    assert row["fit_range_source"] == "auto" and row["fit_range_qualified"] is True
    x_res = row["resolved_gap_over_g0"]
    assert x_res == pytest.approx((1.0 / (2 * row["d_rep"])) ** 1.5)
    assert 3 * x_res <= row["fit_range_x_min"] < row["fit_range_x_max"] <= 0.1
    assert row["fit_range_bins"] >= 5
    assert row["exponent_fit_range"] == pytest.approx(-1 / 3, abs=0.02)
    assert doc["fit_range"]["option"] is None and doc["fit_range"]["auto"]["x_max"] == 0.1
    with open(auto / "gap-analysis.csv") as fh:
        csv_row = next(iter(__import__("csv").DictReader(fh)))
    assert csv_row["fit_range_source"] == "auto"
    assert float(csv_row["fit_range_x_min"]) == pytest.approx(row["fit_range_x_min"])
    assert float(csv_row["exponent_fit_range"]) == pytest.approx(row["exponent_fit_range"])
    assert given.returncode == 0, given.stderr
    doc = json.loads((fixed / "gap-analysis.json").read_text())
    (row,) = doc["rows"]
    assert row["fit_range_source"] == "--fit-range" and row["fit_range_qualified"] is None
    assert (row["fit_range_x_min"], row["fit_range_x_max"]) == (0.002, 0.05)
    assert doc["fit_range"]["option"] == [0.002, 0.05]
    assert reversed_.returncode == 2 and "--fit-range LO HI needs LO < HI" in reversed_.stderr


def test_force_by_gap_puts_each_pixels_force_in_its_bin(comm):
    """Fig. 4 from data: the force of each non-contact pixel lands in the bin of its g/g0,
    per unit ln(g/g0); contact pixels count apart; the shares add up to 1."""
    shape = (40, 30)
    grid = Grid(shape, comm=comm, planner="estimate")
    law = ExponentialAdhesion(0.01, 0.5)
    g0 = 2.0
    gap = np.zeros(shape)
    pressure = np.zeros(shape)
    pressure[:10] = 0.1                     # in contact: g = 0, p > 0
    gap[10:25] = 0.02 * g0                  # all in one bin
    gap[25:] = 3.0 * g0
    gl, pl = local(grid, gap, pressure)
    found = analysis.attractive_force_by_gap(grid, gl, pl, law, g0, bins_per_decade=10)
    total = law.derivative(0.0) * 300 + law.derivative(0.02 * g0) * 450 \
        + law.derivative(3.0 * g0) * 450
    assert found.contact_share == pytest.approx(law.derivative(0.0) * 300 / total, rel=1e-12)
    widths = np.log(10) / 10
    k = np.searchsorted(found.x, 0.02, side="right") - 1
    hit = np.abs(np.log(found.x / 0.02)) <= widths / 2 + 1e-12
    assert hit.sum() == 1
    assert found.share[hit][0] * widths == pytest.approx(
        law.derivative(0.02 * g0) * 450 / total, rel=1e-12)
    integral = float(np.sum(found.share) * widths)
    assert integral + found.contact_share + found.outside_share == pytest.approx(1.0, rel=1e-12)
    assert abs(found.outside_share) < 1e-12 and k >= 0     # every gap within the bins
