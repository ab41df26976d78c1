"""Light the way artists light (issue 22): mirrored objects keep their front side, emitters that
light nothing are reported, two-sided emitters, Blender Light objects."""

import numpy as np
from scenes import bake, cube, emitter_quad, grid_quad, material, mesh_object, stored


def _floor(bpy, mat, n=4):
    verts, faces = grid_quad((-2, -2, 0), (4, 0, 0), (0, 4, 0), n)
    return mesh_object(bpy, "Floor", verts, faces, mat)


def test_a_mirrored_copy_is_lit_like_its_mirror_image(blender):
    """A cube at x = -0.6 and its mirror image at x = +0.6 made by scale x = -1 (the same mesh, a
    negative-determinant matrix), under a light on the mirror plane: the same value at every
    corner. Without keeping the front side the mirrored cube's faces face inward (black)."""
    bpy = blender
    white = material(bpy, "White", (0.7, 0.7, 0.7))
    _floor(bpy, white)
    emitter_quad(bpy, "Light", 0.8, 2.0, 20.0)
    left = cube(bpy, "Left", 0.3, (-0.6, 0.0, 0.3), white)
    right = mesh_object(bpy, "Right", [v.co[:] for v in left.data.vertices],
                        [tuple(p.vertices) for p in left.data.polygons], white, (0.6, 0.0, 0.3))
    right.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    assert np.linalg.det(np.array(right.matrix_world)) < 0
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    assert bake(bpy, method="FULL") == {"FINISHED"}
    a, b = stored(left.data, 1), stored(right.data, 1)
    assert a.mean() > 0.05
    np.testing.assert_allclose(b, a, rtol=2e-3, atol=2e-3 * a.max())
