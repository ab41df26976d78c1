"""Display-subdivision grids (no bpy)."""

import numpy as np
import pytest

from addon.core import grids, polygons


def _quad_and_triangle():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    return v, np.array([4, 3]), np.array([0, 1, 2, 3, 1, 4, 2])


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_grid_counts_area_and_welding(level):
    v, sizes, idx = _quad_and_triangle()
    g = grids.subdivide(v, sizes, idx, level)
    k = 2**level
    assert (g.face_sizes == 4).sum() == k * k
    assert (g.face_sizes == 3).sum() == k * k
    # Quad (k+1)^2 points + triangle (k+1)(k+2)/2, minus the k+1 shared on edge 1-2.
    assert len(g.vertices) == (k + 1) ** 2 + (k + 1) * (k + 2) // 2 - (k + 1)
    sizes_i = g.face_sizes.astype(int)
    starts = np.concatenate([[0], np.cumsum(sizes_i)[:-1]])
    total = 0.0
    for s, n in zip(starts, sizes_i, strict=True):
        p = g.vertices[g.face_indices[s:s + n]]
        nrm = polygons.newell_normal(p)
        assert nrm[2] > 0  # winding kept
        total += 0.5 * np.linalg.norm(nrm)
    assert total == pytest.approx(1.5)


def test_corner_parameters_reproduce_positions():
    v, sizes, idx = _quad_and_triangle()
    g = grids.subdivide(v, sizes, idx, 2)
    for c in range(len(g.face_indices)):
        f = g.corner_face[c]
        s, t = g.corner_st[c]
        if f == 0:
            p0, p1, p2, p3 = v[idx[:4]]
        else:
            p0, p1, p2 = v[idx[4:]]
            p3 = p2
        x = (1 - s) * (1 - t) * p0 + s * (1 - t) * p1 + s * t * p2 + (1 - s) * t * p3
        np.testing.assert_allclose(g.vertices[g.face_indices[c]], x, atol=1e-12)


def test_level_zero_keeps_library_corners_in_order():
    v, sizes, idx = _quad_and_triangle()
    g = grids.subdivide(v, sizes, idx, 0)
    np.testing.assert_array_equal(g.vertices[g.face_indices], v[idx])


def test_interpolate_corner_values():
    v, sizes, idx = _quad_and_triangle()
    g = grids.subdivide(v, sizes, idx, 1)
    # Interpolating the corners' positions must give the grid positions.
    out = g.interpolate(v[idx])
    np.testing.assert_allclose(out, g.vertices[g.face_indices], atol=1e-12)
