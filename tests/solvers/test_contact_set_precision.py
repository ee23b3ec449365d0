"""Single precision in the contact-set kernels (petgap/solvers/_contact_set.pyx).

The kernels take their fields all float64 or all float32 and compute, sum and
return in double; a float32 value is rounded once, when it is stored.  So a
float32 call must give the float64 call on the same data rounded to float32:
stored values within one rounding (a few float32 eps relative), counts and
index lists exactly, sums within a few float32 eps of the sum of the terms'
magnitudes (a relative error on a sum that cancels says nothing).  Every rank
tests its own data (seeded by rank), with odd slab sizes and a padded row
width as the FFT buffer has.
"""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.solvers import _contact_set as cs
from petgap.solvers.contact_set import ContactSet

EPS = float(np.finfo(np.float32).eps)
RTOL = 4 * EPS                  # stored values: one rounding, with room to spare
M, N = 7, 13                    # this rank's slab
W = 2 * (N // 2 + 1)            # its row length in the padded FFT layout


def _rng(seed):
    return np.random.default_rng([seed, MPI.COMM_WORLD.rank])


def _slab(rng):
    """Displacement (padded), topography and contact mask of one slab, with S's index lists."""
    u = rng.standard_normal((M, W))
    h = 0.7 * rng.standard_normal((M, N))
    mask = (rng.random((M, N)) < 0.4).astype(np.uint8)
    idx = np.flatnonzero(mask).astype(np.int32)
    pidx = ((idx // N) * W + idx % N).astype(np.int32)
    return u, h, mask, idx, pidx


# One call of every kernel on random data, its fields in float64.
def _gather_gap(rng):
    u, h, mask, idx, pidx = _slab(rng)
    return u, pidx, h, idx, 0.3, np.zeros(len(idx))


def _shift_and_norms(rng):
    return rng.standard_normal(40) + 0.2, 0.15


def _gap_pass(rng):
    u, h, mask, _, _ = _slab(rng)
    return u, h, mask, 0.2, np.zeros(M * N, dtype=np.int32)


def _collect_overlap(rng):
    u, h, mask, _, _ = _slab(rng)
    return u, h, mask, 0.2, np.zeros(5, dtype=np.int32)   # too small: counts all the same


def _gap_sums(rng):
    return rng.standard_normal(40) + 0.3, rng.standard_normal(40)


def _direction(rng):
    return rng.standard_normal(40), 0.1, 0.6, rng.standard_normal(40)


def _direction_from_buffer(rng):
    u, _, _, idx, pidx = _slab(rng)
    return u, pidx, 0.1, 0.6, rng.standard_normal(len(idx))


def _step_sums(rng):
    u, _, _, idx, pidx = _slab(rng)
    return u, pidx, rng.standard_normal(len(idx)), rng.standard_normal(len(idx)) + 0.2


def _update(rng):
    return rng.random(60), rng.standard_normal(60), rng.standard_normal(60), 0.5, 2.0


def _overlap_pressures(rng):
    u, h, mask, _, _ = _slab(rng)
    points = np.flatnonzero(mask == 0).astype(np.int32)
    return u, h, points, 0.2, 1.5, np.zeros(len(points))


def _merge(rng):
    _, _, mask, idx, pidx = _slab(rng)
    off = np.flatnonzero(mask == 0)
    added = np.sort(rng.choice(off, size=6, replace=False)).astype(np.int32)
    added_p = rng.random(6) - 0.3                      # some stay out
    ns, room = len(idx), len(idx) + len(added)
    buffers = [np.zeros(room, dtype=np.int32), np.zeros(room, dtype=np.int32),
               np.zeros(room), np.zeros(room)]
    buffers[0][:ns], buffers[1][:ns] = idx, pidx
    buffers[2][:ns] = rng.random(ns) - 0.3             # about 30 % leave S
    buffers[3][:ns] = rng.standard_normal(ns)
    return (*buffers, ns, added, added_p, mask, W)


def _recurrence(rng):
    return rng.standard_normal((M, W)), rng.standard_normal((M, W)), 0.4, 1.3, N


def _uniform_gap(rng):
    return np.full((M, W), np.nan), rng.standard_normal((M, N)), 0.1


def _uniform_sums(rng):
    return rng.standard_normal((M, W)), rng.standard_normal((M, N)), 0.1


def _uniform_step(rng):
    return (rng.standard_normal((M, W)), rng.standard_normal((M, N)), 0.1, 0.05, 0.5, 3.0,
            np.zeros((M, N)))


def _final_gap(rng):
    u, h, mask, _, _ = _slab(rng)
    return u, h, mask, 0.2, np.zeros((M, N))


CASES = {name: build for name, build in [
    ("gather_gap", _gather_gap), ("shift_and_norms", _shift_and_norms),
    ("gap_pass", _gap_pass), ("collect_overlap", _collect_overlap), ("gap_sums", _gap_sums),
    ("direction", _direction), ("direction_from_buffer", _direction_from_buffer),
    ("step_sums", _step_sums), ("update", _update), ("overlap_pressures", _overlap_pressures),
    ("merge", _merge), ("recurrence", _recurrence), ("uniform_gap", _uniform_gap),
    ("uniform_sums", _uniform_sums), ("uniform_step", _uniform_step),
    ("final_gap", _final_gap)]}


def _is_field(a):
    return isinstance(a, np.ndarray) and a.dtype.kind == "f"


def _copy(a):
    return a.copy() if isinstance(a, np.ndarray) else a


def both_precisions(name, seed=5):
    """``kernel(float32 data)`` and ``kernel(the same values in float64)``.

    Returns ``(result, arguments after the call)`` for each: the float32 call
    first, then the float64 one.  Arrays that are not fields (index lists,
    mask) are copied for each call, since the kernels write some of them.
    """
    args = CASES[name](_rng(seed))
    single = [a.astype(np.float32) if _is_field(a) else _copy(a) for a in args]
    double = [a.astype(np.float64) if _is_field(a) else _copy(a) for a in single]
    kernel = getattr(cs, name)
    return (kernel(*single), single), (kernel(*double), double)


def assert_stored(single, double):
    """A float32 array that holds the float64 one rounded (NaN where it has NaN)."""
    assert single.dtype == np.float32 and double.dtype == np.float64
    np.testing.assert_allclose(single, double, rtol=RTOL, atol=0.0)


def assert_sum(single, double, scale):
    """Sums returned in double, apart by the rounding of their terms at most."""
    assert type(single) is float and type(double) is float
    assert abs(single - double) <= RTOL * scale, (single, double, scale)


@pytest.mark.parametrize("name", ["gap_pass", "collect_overlap"])
def test_overlap_search(name):
    (r32, a32), (r64, a64) = both_precisions(name)
    count = r32[1] if name == "gap_pass" else r32
    assert count == (r64[1] if name == "gap_pass" else r64) > 5
    np.testing.assert_array_equal(a32[4], a64[4])     # the same points, in order
    if name == "gap_pass":
        assert type(r32[0]) is float and r32[0] == pytest.approx(r64[0], rel=RTOL)


def test_gather_gap_and_shift():
    (s32, a32), (s64, a64) = both_precisions("gather_gap")
    assert_stored(a32[5], a64[5])
    assert_sum(s32, s64, np.abs(a64[5]).sum())
    (r32, a32), (r64, a64) = both_precisions("shift_and_norms")
    assert_stored(a32[0], a64[0])
    assert type(r32[0]) is float and r32[0] == pytest.approx(r64[0], rel=RTOL)
    assert_sum(r32[1], r64[1], r64[1])


def test_sums_over_s():
    (r32, a32), (r64, a64) = both_precisions("gap_sums")
    z, g = a64
    assert_sum(r32[0], r64[0], np.abs(z).sum())
    assert_sum(r32[1], r64[1], np.abs(g * z).sum())
    (r32, a32), (r64, a64) = both_precisions("step_sums")
    pad, pidx, g, t = a64
    r = pad.ravel()[pidx]
    for got, want, terms in zip(r32, r64, [g * t, r * t]):
        assert_sum(got, want, np.abs(terms).sum())


def test_float32_terms_are_summed_in_double():
    """2^25 + 1 is 2^25 in float32: a float32 accumulator would lose all the ones."""
    big = np.concatenate([[2.0 ** 25], np.ones(100), [-2.0 ** 25]]).astype(np.float32)
    assert cs.gap_sums(big, np.ones_like(big)) == (100.0, 100.0)
    pressure = big[:-1].copy()
    assert cs.update(pressure, np.zeros_like(pressure), np.zeros_like(pressure), 0.0,
                     1.0) == (0, 0, 2.0 ** 25 + 100)


@pytest.mark.parametrize("name", ["direction", "direction_from_buffer"])
def test_direction(name):
    (r32, a32), (r64, a64) = both_precisions(name)
    assert r32 is None and r64 is None
    assert_stored(a32[-1], a64[-1])                   # tS


def test_update_and_overlap_pressures():
    (r32, a32), (r64, a64) = both_precisions("update")
    assert r32[:2] == r64[:2] and r64[0] > 0 and r64[1] > r64[0]   # some clipped, some re-enter
    assert_stored(a32[0], a64[0])
    assert_sum(r32[2], r64[2], r64[2])
    (s32, a32), (s64, a64) = both_precisions("overlap_pressures")
    assert_stored(a32[5], a64[5])
    assert_sum(s32, s64, np.abs(a64[5]).sum())


def test_merge_keeps_the_precision():
    (n32, a32), (n64, a64) = both_precisions("merge")
    assert n32 == n64 > 0
    for k in (0, 1, 7):                               # idx, pidx, mask
        np.testing.assert_array_equal(a32[k], a64[k])
    for k in (2, 3):                                  # pS, tS: moved, never recomputed
        assert a32[k].dtype == np.float32
        np.testing.assert_array_equal(a32[k][:n32], a64[k][:n64])


def test_slab_kernels():
    (r32, a32), (r64, a64) = both_precisions("recurrence")
    assert_stored(a32[0], a64[0])                     # padding columns untouched: equal
    (r32, a32), (r64, a64) = both_precisions("uniform_gap")
    assert_stored(a32[0], a64[0])
    assert (a32[0][:, N:] == 0).all()
    assert r32[0] == pytest.approx(r64[0], rel=RTOL)
    assert_sum(r32[1], r64[1], r64[1])
    (r32, a32), (r64, a64) = both_precisions("uniform_sums")
    z, h, hbar = a64
    assert_sum(r32[0], r64[0], np.abs(z[:, :N]).sum())
    assert_sum(r32[1], r64[1], np.abs((hbar - h) * z[:, :N]).sum())
    (r32, a32), (r64, a64) = both_precisions("uniform_step")
    assert r32[:2] == r64[:2] and r64[0] > 0
    assert_stored(a32[6], a64[6])
    assert_sum(r32[2], r64[2], r64[2])
    (r32, a32), (r64, a64) = both_precisions("final_gap")
    assert_stored(a32[4], a64[4])
    for got, want in zip(r32, r64):
        assert type(got) is float and got == pytest.approx(want, rel=RTOL)


def test_single_precision_in_place_and_nan():
    """final_gap may write over its own padded input in float32 too; NaN is reported."""
    u, h, mask, _, _ = _slab(_rng(9))
    u, h = u.astype(np.float32), h.astype(np.float32)
    out = np.empty((M, N), dtype=np.float32)
    expected = cs.final_gap(u, h, mask, 0.2, out)
    in_place = u.reshape(-1)[:M * N].reshape(M, N)
    assert cs.final_gap(u, h, mask, 0.2, in_place) == expected
    np.testing.assert_array_equal(in_place, out)
    u, _, _, _, _ = _slab(_rng(9))
    u = u.astype(np.float32)
    u[3, 2] = np.nan
    assert np.isnan(cs.gap_pass(u, h, mask, 0.2, np.empty(M * N, dtype=np.int32))[0])
    assert np.isnan(cs.final_gap(u, h, mask, 0.2, out)[0])
    g = np.array([1.0, np.nan, -2.0], dtype=np.float32)
    assert all(np.isnan(cs.shift_and_norms(g, 0.0)))


def test_double_precision_matches_numpy():
    """The float64 path against NumPy on the same data."""
    u, pidx, h, idx, offset, gS = _gather_gap(_rng(11))
    total = cs.gather_gap(u, pidx, h, idx, offset, gS)
    g = u.ravel()[pidx] - h.ravel()[idx] + offset
    np.testing.assert_array_equal(gS, g)
    assert total == pytest.approx(g.sum(), rel=1e-13)
    in_max, norm = cs.shift_and_norms(gS, 0.25)
    np.testing.assert_array_equal(gS, g - 0.25)
    assert in_max == np.abs(g - 0.25).max() and norm == pytest.approx(((g - 0.25) ** 2).sum())

    pad, pidx, gS, tS = _step_sums(_rng(12))
    r = pad.ravel()[pidx]
    np.testing.assert_allclose(cs.step_sums(pad, pidx, gS, tS), [gS @ tS, r @ tS], rtol=1e-12)

    pS, tS, gS, tau, entry = _update(_rng(13))
    expected = pS - tau * tS
    clipped = expected <= 0
    expected[clipped] = np.where(gS[clipped] < 0, -entry * gS[clipped], 0.0)
    result = cs.update(pS, tS, gS, tau, entry)
    np.testing.assert_allclose(pS, expected, rtol=1e-14, atol=1e-15)  # FMA or not
    assert result[:2] == ((clipped & (gS < 0)).sum(), clipped.sum())
    assert result[2] == pytest.approx(expected.sum(), rel=1e-13)

    pad, h, hbar = _uniform_gap(_rng(14))
    gmax, norm = cs.uniform_gap(pad, h, hbar)
    np.testing.assert_array_equal(pad, np.pad(hbar - h, ((0, 0), (0, W - N))))
    assert gmax == np.abs(hbar - h).max() and norm == pytest.approx(((hbar - h) ** 2).sum())


#: The one mix of precisions a kernel takes: a float32 image of the direction (its argument
#: at this position) beside double fields, in a double solve with a single-precision search.
SINGLE_IMAGE = {"step_sums": 0, "recurrence": 1}


@pytest.mark.parametrize("name", sorted(CASES))
def test_mixed_precision_is_refused(name):
    """One float64 field among float32 ones is a TypeError naming the precisions
    (a kernel with a single field: one of another precision)."""
    args = CASES[name](_rng(3))
    fields = [k for k, a in enumerate(args) if _is_field(a)]
    if len(fields) == 1:
        other = [a.astype(np.float16) if _is_field(a) else a for a in args]
        with pytest.raises(TypeError, match=f"{name}: .*all float64 or all float32.*float16"):
            getattr(cs, name)(*other)
        return
    for keep in fields:                               # each field in turn left in float64
        mixed = [a.astype(np.float32) if _is_field(a) and k != keep else _copy(a)
                 for k, a in enumerate(args)]
        if [k for k in fields if k != keep] == [SINGLE_IMAGE.get(name)]:
            continue                                  # the single image: taken (below)
        with pytest.raises(TypeError, match=f"{name}: .*all float64 or all float32.*float64"):
            getattr(cs, name)(*mixed)


@pytest.mark.parametrize("name", sorted(SINGLE_IMAGE))
def test_a_single_image_beside_double_fields(name):
    """A float32 image of the direction is read as it is and combined in double: the
    result is the all-double kernel's on the image rounded to float32.  Its other fields
    in float32 are still refused."""
    args = CASES[name](_rng(4))
    at = SINGLE_IMAGE[name]
    rounded = [a.astype(np.float32).astype(np.float64) if k == at else _copy(a)
               for k, a in enumerate(args)]
    single = [a.astype(np.float32) if k == at else _copy(a) for k, a in enumerate(args)]
    want = getattr(cs, name)(*rounded)
    got = getattr(cs, name)(*single)
    if name == "step_sums":
        np.testing.assert_allclose(got, want, rtol=1e-13)
    else:
        np.testing.assert_allclose(single[0], rounded[0], rtol=1e-13, atol=1e-15)
        assert single[0].dtype == np.float64
    if name == "step_sums":                           # tS in float32 too: refused
        others = [_copy(a) for a in single]
        others[3] = others[3].astype(np.float32)
        with pytest.raises(TypeError, match="step_sums: .*all float64 or all float32"):
            cs.step_sums(*others)


def test_contact_set_in_single_precision():
    """ContactSet(dtype=float32) keeps float32 vectors through shrinking and growing merges."""
    rng = _rng(21)
    m, n, width = 64, 80, 82                          # large enough for the buffers to shrink
    mask = np.zeros((m, n), dtype=np.uint8)
    contact = ContactSet.everywhere(mask, width, 2.0, dtype=np.float32)

    def vectors():
        return contact._p, contact._t, contact._g, contact._z

    assert contact.dtype == np.float32 and all(v.dtype == np.float32 for v in vectors())
    full = contact.capacity
    pressure = np.where(rng.random(m * n) < 0.05, rng.random(m * n) + 0.1, 0.0)
    contact.p[...] = pressure
    contact.merge(np.empty(0, dtype=np.int64), np.empty(0))
    kept = np.flatnonzero(pressure)
    assert contact.capacity < full / 2
    assert all(v.dtype == np.float32 for v in vectors())
    np.testing.assert_array_equal(contact.p, pressure[kept].astype(np.float32))

    added = np.setdiff1d(np.arange(m * n), kept)[::3]
    added_p = rng.random(len(added)) + 0.5            # float64: rounded on the way in
    contact.merge(added, added_p)
    assert contact.capacity >= contact.size == len(kept) + len(added)
    assert all(v.dtype == np.float32 for v in vectors())
    entered = np.isin(contact.idx, added)
    np.testing.assert_array_equal(contact.p[entered], added_p.astype(np.float32))
    np.testing.assert_array_equal(np.flatnonzero(mask), contact.idx)

    # the set's vectors work with float32 fields, and refuse float64 ones
    u = rng.standard_normal((m, width)).astype(np.float32)
    h = rng.standard_normal((m, n)).astype(np.float32)
    cs.gather_gap(u, contact.pidx, h, contact.idx, 0.0, contact.g)
    with pytest.raises(TypeError, match="all float64 or all float32"):
        cs.gather_gap(u.astype(np.float64), contact.pidx, h.astype(np.float64), contact.idx,
                      0.0, contact.g)

    field = np.where(rng.random((m, n)) < 0.1, rng.random((m, n)), 0.0)
    warm = ContactSet.from_pressure(np.zeros((m, n), dtype=np.uint8), width, field,
                                    dtype=np.float32)
    assert warm.p.dtype == np.float32
    np.testing.assert_array_equal(warm.idx, np.flatnonzero(field))
    np.testing.assert_array_equal(warm.p, field[field > 0].astype(np.float32))

    # double by default, and no other precision
    assert ContactSet.everywhere(np.zeros((4, 6), dtype=np.uint8), 8, 1.0).p.dtype == np.float64
    with pytest.raises(TypeError, match="float64 or float32"):
        ContactSet(np.zeros((4, 6), dtype=np.uint8), 8, dtype=np.int32)
