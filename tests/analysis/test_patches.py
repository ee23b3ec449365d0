"""Contact patches: labelling across slab faces and the periodic seam, areas, perimeters."""
from collections import deque

import numpy as np
import pytest

from petgap.analysis import contact_patches, perimeter
from petgap.parallel.grid import Grid


def flood_fill_patches(mask, dx, dy, periodic):
    """Serial reference: breadth-first flood fill over the global mask.

    Returns ``(pixels, perimeters)`` per patch, patches ordered by first pixel.
    """
    nx, ny = mask.shape
    seen = np.zeros_like(mask, dtype=bool)
    out = []

    def neighbours(i, j):
        for di, dj, length in ((-1, 0, dy), (1, 0, dy), (0, -1, dx), (0, 1, dx)):
            a, b = i + di, j + dj
            if periodic:
                yield a % nx, b % ny, length
            elif 0 <= a < nx and 0 <= b < ny:
                yield a, b, length

    for i in range(nx):
        for j in range(ny):
            if not mask[i, j] or seen[i, j]:
                continue
            seen[i, j] = True
            queue, pixels, edge = deque([(i, j)]), 0, 0.0
            while queue:
                a, b = queue.popleft()
                pixels += 1
                for c, d, length in neighbours(a, b):
                    if not mask[c, d]:
                        edge += length
                    elif not seen[c, d]:
                        seen[c, d] = True
                        queue.append((c, d))
            out.append((pixels, edge))
    return np.array([p for p, _ in out]), np.array([e for _, e in out])


def make_grid(comm, shape, pixel=(1.0, 2.0)):
    return Grid(shape, size=(shape[0] * pixel[0], shape[1] * pixel[1]), comm=comm,
                planner="estimate", wisdom=False)


def constructed_mask():
    """A 12 x 10 pattern with patches across every kind of boundary.

    Under 2 ranks the slabs meet between rows 5 and 6.
    """
    m = np.zeros((12, 10), dtype=bool)
    m[2, 0] = m[2, 9] = True            # across the y seam
    m[0, 4] = m[11, 4] = True           # across the x seam (and the last/first slab)
    m[5, 2] = m[6, 2] = m[7, 2] = True  # across the slab face of 2 ranks
    m[9, 7] = m[10, 8] = True           # corner contact only: two patches
    return m


@pytest.mark.parametrize("periodic, count", [(True, 5), (False, 7)])
def test_constructed_pattern_has_the_known_patch_count(comm, periodic, count):
    mask = constructed_mask()
    grid = make_grid(comm, mask.shape)
    patches = contact_patches(grid, mask[grid.x_slice], periodic=periodic)
    assert patches.count == count
    assert patches.pixels.sum() == mask.sum()
    pixels, edges = flood_fill_patches(mask, grid.dx, grid.dy, periodic)
    np.testing.assert_array_equal(patches.pixels, pixels)
    np.testing.assert_allclose(patches.perimeters, edges, rtol=1e-14)
    np.testing.assert_allclose(patches.areas, pixels * grid.dx * grid.dy, rtol=1e-14)


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("seed, fill", [(1, 0.3), (2, 0.55), (3, 0.08)])
def test_random_masks_match_flood_fill(comm, periodic, seed, fill):
    shape = (37, 23)                     # odd sizes: unequal slabs
    mask = np.random.default_rng(seed).random(shape) < fill
    grid = make_grid(comm, shape)
    patches = contact_patches(grid, mask[grid.x_slice], periodic=periodic)
    pixels, edges = flood_fill_patches(mask, grid.dx, grid.dy, periodic)
    assert patches.count == len(pixels)
    np.testing.assert_array_equal(patches.pixels, pixels)
    np.testing.assert_allclose(patches.perimeters, edges, rtol=1e-13)


def test_perimeters_add_up_to_the_pixel_edge_length(comm):
    shape = (48, 40)
    mask = np.random.default_rng(7).random(shape) < 0.4
    grid = make_grid(comm, shape)
    local = mask[grid.x_slice]
    patches = contact_patches(grid, local)
    total = perimeter(grid, mask=local).pixel_edge_length
    assert patches.perimeters.sum() == pytest.approx(total, rel=1e-13)


def test_full_and_empty_contact(comm):
    shape = (16, 12)
    grid = make_grid(comm, shape)
    full = contact_patches(grid, np.ones(grid.local_shape, dtype=bool))
    assert full.count == 1 and full.pixels[0] == 16 * 12 and full.perimeters[0] == 0
    empty = contact_patches(grid, np.zeros(grid.local_shape, dtype=bool))
    assert empty.count == 0 and empty.pixels.size == 0
    edges, counts = empty.area_distribution()
    assert counts.size == 0


def test_area_distribution_counts_every_patch(comm):
    mask = np.random.default_rng(11).random((40, 40)) < 0.45
    grid = make_grid(comm, mask.shape, pixel=(1.0, 1.0))
    patches = contact_patches(grid, mask[grid.x_slice])
    edges, counts = patches.area_distribution(bins_per_decade=4)
    assert counts.sum() == patches.count
    assert edges[0] == pytest.approx(patches.areas.min())
    assert edges[-1] > patches.areas.max()


def test_wrong_slab_shape_is_refused_on_every_rank(comm):
    grid = make_grid(comm, (16, 12))
    with pytest.raises(ValueError, match="mask has shape"):
        contact_patches(grid, np.zeros((3, 3), dtype=bool))
