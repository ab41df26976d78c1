"""N-gon, concave- and bent-quad splitting, and results mapped back to loops (no bpy)."""

import numpy as np
import pytest

from addon.core import polygons


def _area(p):
    return 0.5 * np.linalg.norm(polygons.newell_normal(np.asarray(p, float)))


def test_triangles_and_convex_quads_pass_through():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    s = polygons.split_faces(v, [4, 3], [0, 1, 2, 3, 1, 4, 2])
    assert s.identity
    assert s.face_sizes.tolist() == [4, 3]
    assert s.face_indices.tolist() == [0, 1, 2, 3, 1, 4, 2]
    vals = np.arange(7 * 3, dtype=np.float32).reshape(7, 3)
    np.testing.assert_array_equal(s.to_loops(vals), vals)


def test_convex_ngon_is_a_fan_with_same_area_and_winding():
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]
    v = np.stack([np.cos(ang), np.sin(ang), np.zeros(6)], axis=1)
    s = polygons.split_faces(v, [6], np.arange(6))
    assert s.split_polygons == 1
    assert s.face_sizes.tolist() == [3, 3, 3, 3]
    tris = s.face_indices.reshape(-1, 3)
    total = sum(_area(v[t]) for t in tris)
    assert total == pytest.approx(_area(v), rel=1e-12)
    for t in tris:  # same winding as the hexagon (normal +z)
        assert polygons.newell_normal(v[t])[2] > 0
    assert s.source_face.tolist() == [0, 0, 0, 0]


def test_concave_ngon_ear_clipping_stays_inside():
    # An L shape (6 corners, one reflex corner at index 3): a fan from 0 would leave the polygon.
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    s = polygons.split_faces(v, [6], np.arange(6))
    tris = s.face_indices.reshape(-1, 3)
    assert len(tris) == 4
    areas = [_area(v[t]) for t in tris]
    assert sum(areas) == pytest.approx(3.0)
    for t in tris:
        assert polygons.newell_normal(v[t])[2] > 0


def test_concave_quad_is_split_on_the_reflex_diagonal():
    # Arrowhead: corner 2 is reflex.
    v = np.array([[0, 0, 0], [2, 1, 0], [0.5, 1, 0], [0, 2, 0]], float)
    s = polygons.split_faces(v, [4], np.arange(4))
    assert s.face_sizes.tolist() == [3, 3]
    tris = s.face_indices.reshape(-1, 3)
    assert all(2 in t for t in tris)
    assert sum(_area(v[t]) for t in tris) == pytest.approx(_area(v))


def test_results_map_back_to_every_loop():
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [0, 1, 0], [3, 0, 0]], float)
    sizes = [6, 3]
    idx = [0, 1, 2, 3, 4, 5, 2, 6, 3]
    s = polygons.split_faces(v, sizes, idx)
    assert s.n_loops == 9
    # A value per library corner equal to its vertex's x: every loop must get its vertex's x.
    corner = np.repeat(v[s.face_indices.astype(int), :1], 3, axis=1)
    loops = s.to_loops(corner)
    np.testing.assert_allclose(loops[:, 0], v[np.array(idx), 0])
    # The triangle after the n-gon keeps its loops 6..8.
    assert s.corner_loop[-3:].tolist() == [6, 7, 8]


def _bent_quad(lift):
    """A unit square with corner 2 lifted by `lift`: Blender's triangles (0,1,2) and (0,2,3) meet
    at a bend of sqrt(2) x lift radians (small lifts)."""
    return np.array([[0, 0, 0], [1, 0, 0], [1, 1, lift], [0, 1, 0]], float)


def test_a_bent_quad_becomes_blenders_two_triangles_and_loops_take_the_first():
    s = polygons.split_faces(_bent_quad(0.2), [4], np.arange(4))
    assert s.split_polygons == 1
    assert s.face_indices.reshape(-1, 3).tolist() == [[0, 1, 2], [0, 2, 3]]
    # Distinct values per library corner: loops 0, 1, 2 come from the first triangle (corners
    # 0, 1, 2), loop 3 from the second (its corner 2 = library corner 5), as Cycles bakes them.
    corner = np.arange(6, dtype=np.float32)[:, None] * np.ones(3, np.float32)
    np.testing.assert_array_equal(s.to_loops(corner)[:, 0], [0, 1, 2, 5])


def test_a_quad_flatter_than_the_limit_stays_one_bilinear_face():
    below = np.radians(0.9 * polygons.BEND_LIMIT_DEGREES) / np.sqrt(2)
    above = np.radians(1.1 * polygons.BEND_LIMIT_DEGREES) / np.sqrt(2)
    assert polygons.split_faces(_bent_quad(below), [4], np.arange(4)).identity
    assert polygons.split_faces(_bent_quad(above), [4], np.arange(4)).split_polygons == 1


def test_a_bent_quad_whose_first_split_folds_over_takes_the_other_diagonal():
    # The arrowhead of the concave test, its reflex corner moved to index 1 and lifted: Blender's
    # (0,2) triangles would face opposite ways, so it splits on (1,3) into (0,1,3), (1,2,3), both
    # facing +z like the quad.
    v = np.array([[2, 1, 0], [0.5, 1, 0.1], [0, 2, 0], [0, 0, 0]], float)
    s = polygons.split_faces(v, [4], np.arange(4))
    tris = s.face_indices.reshape(-1, 3)
    assert tris.tolist() == [[0, 1, 3], [1, 2, 3]]
    for t in tris:
        assert polygons.newell_normal(v[t])[2] > 0


def test_a_kept_split_fits_only_the_same_loops_on_the_same_vertices():
    s = polygons.split_faces(_bent_quad(0.2), [4], np.arange(4))
    assert s.fits([4], [0, 1, 2, 3])
    assert not s.fits([4], [0, 1, 3, 2])  # the same loop count, other vertices
    assert not s.fits([3], [0, 1, 2])


def test_degenerate_faces_are_found():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    bad = polygons.degenerate_faces(v, [4, 3], [0, 1, 2, 3, 1, 4, 4])
    assert bad.tolist() == [1]


def test_fewer_than_three_corners_is_an_error():
    with pytest.raises(ValueError, match="face 0 has 2 corners"):
        polygons.split_faces(np.zeros((3, 3)), [2], [0, 1])
