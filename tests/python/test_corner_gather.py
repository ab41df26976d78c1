"""The corner gather through the add-on: a box standing on the floor hides the floor's middle
vertex, which the gather bakes black (as a vertex bake by Cycles would); the face polynomials
alone do not. Turning the option off re-bakes (it changes the solution's signature)."""

import numpy as np
import scenes


def _middle_vertex(floor, frame):
    """Stored colours of the floor's corners at its middle vertex (0, 0) and at its outer corners."""
    me = floor.data
    co = np.array([tuple(me.vertices[lp.vertex_index].co) for lp in me.loops])
    c = scenes.stored(me, frame)
    middle = np.all(np.abs(co[:, :2]) < 1e-6, axis=1)
    outer = np.all(np.abs(co[:, :2]) > 0.99, axis=1)
    return c[middle], c[outer]


def test_corner_under_a_standing_box_bakes_black_and_the_option_turns_it_off(blender):
    bpy = blender
    white = scenes.material(bpy, "White", (0.7, 0.7, 0.7))
    verts, faces = scenes.grid_quad((-1, -1, 0), (2, 0, 0), (0, 2, 0), 2)
    floor = scenes.mesh_object(bpy, "Floor", verts, faces, white)
    # Stands on the floor over [-0.1, 0.5]^2: the middle vertex (0, 0) is 0.1 inside its edge.
    scenes.cube(bpy, "Box", 0.3, (0.2, 0.2, 0.3), white)
    scenes.emitter_quad(bpy, "Light", 1.0, 0.0, 10.0, location=(0.0, 0.0, 2.0))
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1

    assert sc.radiosity.corner_gather, "on by default"
    assert scenes.bake(bpy, basis_order=2) == {"FINISHED"}
    hidden, lit = _middle_vertex(floor, 1)
    assert len(hidden) == 4 and len(lit) == 4
    assert lit.min() > 0.05, lit
    np.testing.assert_array_less(hidden, 1e-4 * lit.mean())

    assert scenes.bake(bpy, basis_order=2, corner_gather=False) == {"FINISHED"}
    poly_hidden, poly_lit = _middle_vertex(floor, 1)
    # The polynomial of the face mostly in the open is far from 0 at the hidden vertex.
    assert poly_hidden.max() > 0.1 * poly_lit.mean(), poly_hidden
