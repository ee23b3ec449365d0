"""The periodic elastic half-space against analytic modes and a serial reference."""
import numpy as np
import pytest
from mpi4py import MPI

from petgap.mechanics.half_space import ElasticHalfSpace
from petgap.parallel.dottest import dottest
from petgap.parallel.grid import Grid

AWKWARD = [(65, 48), (113, 76), (9, 7)]


def test_single_mode_matches_analytic(comm):
    """u = 2 p / (E* |q|) for p = cos(q.x), on a non-square physical cell."""
    grid = Grid((48, 30), size=(3.0, 2.0), comm=comm, planner="estimate")
    x, y = grid.local_positions()
    qx, qy = 2 * np.pi * 3 / 3.0, 2 * np.pi * 2 / 2.0
    p = np.cos(qx * x + qy * y) + 0.25  # the mean must be ignored
    half_space = ElasticHalfSpace(grid, contact_modulus=2.5)
    u = half_space.displacement(p)
    expected = 2 * np.cos(qx * x + qy * y) / (2.5 * np.hypot(qx, qy))
    np.testing.assert_allclose(u, expected, atol=1e-13)
    np.testing.assert_allclose(half_space.pressure(u), p - 0.25, atol=1e-13)


def test_energy_real_and_fourier_agree(comm):
    grid = Grid((40, 36), size=(4.0, 3.0), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid, 1.7)
    u = np.random.default_rng(comm.rank).standard_normal(grid.local_shape)
    p = half_space.pressure(u)
    real_space = 0.5 * grid.pixel_area * grid.sum(p * u)
    assert half_space.energy(u) == pytest.approx(real_space, rel=1e-12)
    assert half_space.complementary_energy(p) == pytest.approx(real_space, rel=1e-12)


def test_symmetric_positive_dot_test(comm):
    """<K a, b> = <a, K b>, <a, K a> > 0 and K^{-1} K = identity on zero-mean fields."""
    grid = Grid((33, 20), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid)
    dottest(grid, half_space.pressure, seed=11, rtol=1e-12)
    dottest(grid, half_space.displacement, seed=12, rtol=1e-12)
    rng = np.random.default_rng(11 + comm.rank)
    a = rng.standard_normal(grid.local_shape)
    ka = half_space.pressure(a)
    assert grid.sum(a * ka) > 0
    back = half_space.displacement(ka)
    np.testing.assert_allclose(back, a - grid.mean(a), atol=1e-12)


def test_dottest_catches_a_wrong_adjoint(comm):
    """The utility fails, on every rank alike, for an operator that is not its own transpose."""
    grid = Grid((24, 18), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid)
    shift = grid.local_positions()[0] / grid.Lx      # a diagonal that differs from point to point

    def skewed(x):
        return half_space.pressure(x * (1.0 + shift))
    with pytest.raises(AssertionError, match="dot test failed"):
        dottest(grid, skewed)
    dottest(grid, skewed, lambda y: (1.0 + shift) * half_space.pressure(y))


@pytest.mark.parametrize("shape", AWKWARD)
def test_distributed_equals_serial_reference(comm, shape):
    grid = Grid(shape, size=(1.3, 0.7), comm=comm, planner="estimate")
    serial = Grid(shape, size=(1.3, 0.7), comm=MPI.COMM_SELF, planner="estimate")
    glob = np.random.default_rng(5).standard_normal(shape)
    for op in ("pressure", "displacement"):
        distributed = getattr(ElasticHalfSpace(grid, 3.0), op)(grid.local_part(glob))
        reference = getattr(ElasticHalfSpace(serial, 3.0), op)(glob)
        np.testing.assert_allclose(distributed, reference[grid.x_slice], rtol=1e-12,
                                   atol=1e-12 * np.abs(reference).max())
    e1 = ElasticHalfSpace(grid, 3.0).energy(grid.local_part(glob))
    e2 = ElasticHalfSpace(serial, 3.0).energy(glob)
    assert e1 == pytest.approx(e2, rel=1e-12)


def test_rejects_bad_modulus(comm):
    grid = Grid((8, 8), comm=comm, planner="estimate")
    with pytest.raises(ValueError, match="contact_modulus"):
        ElasticHalfSpace(grid, -1.0)


def _field_on_points(grid, seed):
    """A random field on about 30 % of this rank's points: ``(mask, padded-slab indices,
    values there, the field on the slab)``."""
    rng = np.random.default_rng(seed + grid.comm.rank)
    mask = rng.random(grid.local_shape) < 0.3
    rows, cols = np.nonzero(mask)
    pidx = (rows * grid.padded.shape[1] + cols).astype(np.int32)
    values = rng.standard_normal(len(pidx))
    field = np.zeros(grid.local_shape)
    field[mask] = values
    return mask, pidx, values, field


@pytest.mark.parametrize("shape", [(64, 48), (113, 76), (9, 7), (40, 33), (5, 24)])
def test_sparse_application_equals_dense(comm, shape):
    """``apply_sparse`` is ``apply_in_buffer`` of the field given on a set of points.

    Its input is assembled from index lists a block of rows at a time and its
    output goes to the FFT buffer, to an aligned padded array, or is gathered
    on the points; all three must match the dense operator for both powers,
    on slabs whose row counts leave partial blocks (or are below one block).
    The buffer output is checked to overwrite every point of the slab.
    """
    grid = Grid(shape, size=(1.3, 0.7), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid, 3.0)
    mask, pidx, values, field = _field_on_points(grid, 7)
    out = grid.aligned_padded()
    errors = []
    for inverse in (False, True):
        grid.real[...] = field
        half_space.apply_in_buffer(inverse=inverse)
        dense = grid.real.copy()
        scale = np.abs(dense).max() + 1e-300
        gathered = np.full(len(pidx), np.nan)
        half_space.apply_sparse(pidx, values, inverse=inverse, gathered=gathered)
        errors.append(np.abs(gathered - dense[mask]).max(initial=0.0) / scale)
        half_space.apply_sparse(pidx, values, inverse=inverse, out=out)
        errors.append(np.abs(out[:, :shape[1]] - dense).max() / scale)
        grid.real[...] = np.nan
        half_space.apply_sparse(pidx, values, inverse=inverse)
        errors.append(np.abs(grid.real - dense).max() / scale)
    # an empty set: a zero field, and nothing to gather
    half_space.apply_sparse(pidx[:0], values[:0], inverse=True, gathered=np.empty(0))
    half_space.apply_sparse(pidx[:0], values[:0], inverse=True)
    errors.append(np.abs(grid.real).max())
    worst = comm.allreduce(float(np.nan_to_num(max(errors), nan=np.inf)), op=MPI.MAX)
    assert worst <= 1e-13


def test_sparse_application_refuses_unsorted_points(comm):
    """A bad index list raises (on its rank, after the collective transposes: no hang)."""
    grid = Grid((16, 12), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid)
    width = grid.padded.shape[1]
    pidx = np.array([9 * width + 1, 2], dtype=np.int32)  # row 9 before row 0
    with pytest.raises(ValueError, match="sorted"):
        half_space.apply_sparse(pidx, np.ones(2))
    with pytest.raises(ValueError, match="aligned"):
        misaligned = np.zeros(grid.padded.size + 1)[1:].reshape(grid.padded.shape)
        half_space.apply_sparse(pidx[1:], np.ones(1), out=misaligned)


@pytest.mark.parametrize("shape", [(64, 48), (113, 76), (9, 7), (40, 33), (5, 24)])
@pytest.mark.parametrize("inverse", [True, False])
def test_an_application_in_halves_gives_the_form_then_the_field(comm, shape, inverse):
    """A begin returns ``(t, K t)`` (or ``K^{-1}``) by Parseval; ``finish`` completes ``K t``.

    The form, summed over the ranks, is the real-space sum of ``t`` times the
    dense application to ``t``; the completed field is ``apply_sparse``'s, and
    each half counts half an application -- for a field given on points
    (``begin_sparse``) and one in the FFT buffer (``begin_in_buffer``).  In
    single precision (on the alias) both hold to float32 round-off.  Shapes as
    in the sparse application's test: partial blocks of rows and lines, an odd
    ``ny`` (no Nyquist row).
    """
    grid = Grid(shape, size=(1.3, 0.7), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid, 3.0)
    mask, pidx, values, field = _field_on_points(grid, 17)
    applied = half_space.displacement(field) if inverse else half_space.pressure(field)
    form = grid.sum(field * applied)
    assert form > 0
    dense = grid.aligned_padded()
    half_space.apply_sparse(pidx, values, inverse=inverse, out=dense)
    scale = comm.allreduce(float(np.abs(dense).max()), op=MPI.MAX)
    for how, precision, rtol in (("sparse", None, 1e-12), ("sparse", "single", 2e-6),
                                 ("buffer", None, 1e-12)):
        low = values if precision is None else values.astype(np.float32)
        target = grid if precision is None else grid.single_precision_alias()
        before = half_space.applications
        if how == "sparse":
            target.real[...] = np.nan   # the field must overwrite every point
            got = half_space.begin_sparse(pidx, low, inverse=inverse, precision=precision)
        else:
            grid.real[...] = field
            got = half_space.begin_in_buffer(inverse=inverse)
        assert comm.allreduce(got) == pytest.approx(form, rel=rtol)
        assert half_space.applications == before + 0.5
        half_space.finish(precision=precision)
        assert half_space.applications == before + 1
        error = comm.allreduce(float(np.abs(target.real - dense[:, :shape[1]]).max()),
                               op=MPI.MAX)
        assert error <= rtol * scale


def test_an_application_not_begun_or_overwritten_is_not_finished(comm):
    """``finish`` refuses, on every rank, unless a begin was the last transform of the
    grid's buffers -- another application, a plain transform, or one of the
    single-precision alias (the same memory) in between loses the half-made field."""
    grid = Grid((24, 20), comm=comm, planner="estimate")
    half_space = ElasticHalfSpace(grid)
    width = grid.padded.shape[1]
    pidx = np.array([width + 2, 2 * width + 5], dtype=np.int32)
    values = np.array([1.0, -0.5])
    with pytest.raises(RuntimeError, match="a begin was not the last"):
        half_space.finish()
    for spoil in (lambda: half_space.apply_sparse(pidx, values),
                  lambda: grid.forward(),
                  lambda: half_space.apply_sparse(pidx, values.astype(np.float32),
                                                  precision="single")):
        half_space.begin_sparse(pidx, values, inverse=True)
        spoil()
        with pytest.raises(RuntimeError, match="a begin was not the last"):
            half_space.finish()
    half_space.begin_sparse(pidx, values.astype(np.float32), precision="single")
    grid.backward()
    with pytest.raises(RuntimeError, match="a begin was not the last"):
        half_space.finish(precision="single")
    with pytest.raises(ValueError, match="sorted"):
        half_space.begin_sparse(np.array([9 * width + 1, 2], dtype=np.int32), values)
    with pytest.raises(TypeError, match="float32"):
        half_space.begin_sparse(pidx, values.astype(np.float32))
