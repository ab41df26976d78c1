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


def _point_light(bpy, name, location, power, kind="POINT"):
    data = bpy.data.lights.new(name, kind)
    data.energy = power
    if kind in ("POINT", "SPOT"):
        data.shadow_soft_size = 0.0
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def test_a_point_light_lights_a_floor_by_the_inverse_square_law(blender):
    """A 100 W Point light 1.5 m over a grey floor, baked through the add-on: the stored colour is
    rho E / pi with E = P cos / (4 pi d^2) (Blender's convention), at every corner."""
    bpy = blender
    grey = material(bpy, "Grey", (0.5, 0.5, 0.5))
    floor = _floor(bpy, grey, n=6)
    lamp = _point_light(bpy, "Lamp", (0.3, -0.2, 1.5), 100.0)
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    assert bake(bpy, method="FULL") == {"FINISHED"}
    got = stored(floor.data, 1)[:, 0]
    me = floor.data
    x = np.array([me.vertices[lp.vertex_index].co[:] for lp in me.loops])
    d = np.array(lamp.location) - x
    r = np.linalg.norm(d, axis=1)
    want = 0.5 * 100.0 / (4 * np.pi) * d[:, 2] / r**3 / np.pi
    assert np.abs(got - want).max() < 5e-3 * want.max()


def test_an_animated_light_rebakes_each_frame_like_a_full_solve(blender):
    """A Point light keyframed across the floor (location and power): the incremental bake's
    frames equal full re-solves."""
    bpy = blender
    grey = material(bpy, "Grey", (0.6, 0.6, 0.6))
    floor = _floor(bpy, grey, n=4)
    box = cube(bpy, "Box", 0.3, (0.0, 0.0, 0.3), grey)
    lamp = _point_light(bpy, "Lamp", (-1.0, 0.0, 1.5), 50.0)
    lamp.keyframe_insert("location", frame=1)
    lamp.data.keyframe_insert("energy", frame=1)
    lamp.location = (1.0, 0.5, 1.2)
    lamp.data.energy = 120.0
    lamp.keyframe_insert("location", frame=3)
    lamp.data.keyframe_insert("energy", frame=3)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 3
    out = {}
    for method in ("INCREMENTAL", "FULL"):
        bpy.ops.radiosity.clear()
        assert bake(bpy, method=method) == {"FINISHED"}
        out[method] = [np.concatenate([stored(o.data, f) for o in (floor, box)]) for f in (1, 2, 3)]
    for a, b in zip(out["INCREMENTAL"], out["FULL"], strict=True):
        assert np.abs(a - b).max() < 2e-3 * b.max()
    assert np.abs(out["FULL"][0] - out["FULL"][2]).max() > 0.1 * out["FULL"][2].max()


def test_an_emitter_facing_the_sky_is_reported(blender):
    """An emissive plane left facing up over the floor: the bake says so, naming it."""
    bpy = blender
    grey = material(bpy, "Grey", (0.5, 0.5, 0.5))
    _floor(bpy, grey)
    glow = material(bpy, "Glow", (0.0, 0.0, 0.0), emission=(1, 1, 1), strength=5.0)
    mesh_object(bpy, "Sky Panel", [(-0.5, -0.5, 1), (0.5, -0.5, 1), (0.5, 0.5, 1), (-0.5, 0.5, 1)],
                [(0, 1, 2, 3)], glow)
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    from addon.blender import bake as bake_module

    job = bake_module.BakeJob(bpy.context, bake_module.settings_from_scene(sc))
    job.run()
    assert any('emitter "Sky Panel" lights nothing' in w for w in job.warnings), job.warnings


def test_set_lights_through_the_binding_checks_each_light():
    """``Session.set_lights`` through the C ABI: a lit floor brightens, bad lights fail with one
    line naming the light and change nothing."""
    import pytest

    from addon.native import binding as b

    verts, faces = grid_quad((-1, -1, 0), (2, 0, 0), (0, 2, 0), 2)
    obj = {"vertices": np.asarray(verts, np.float32), "face_sizes": np.full(len(faces), 4, np.uint32),
           "face_indices": np.asarray(faces, np.uint32).reshape(-1), "face_materials": np.zeros(4, np.uint32),
           "matrix": np.eye(4)}
    lamp = np.eye(4)
    lamp[2, 3] = 1.0
    with b.Session({"method": "full"}, [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [1.0] * 3], [obj]) as s:
        s.set_lights([{"type": "POINT", "matrix": lamp, "power": 100.0}])
        s.solve_frame(1)
        centre = s.corner_radiosity(0)[2]  # face 0's corner 2 is the floor's centre
        assert centre[0] == pytest.approx(0.5 * 100 / (4 * np.pi), rel=5e-3)
        for bad, says in [({"type": "CANDLE", "matrix": lamp}, "type 'CANDLE'"),
                          ({"type": "POINT", "matrix": lamp, "power": -1.0}, "power -1 must be"),
                          ({"type": "SPOT", "matrix": lamp, "spot_blend": 3.0}, "spot_blend 3 is outside")]:
            with pytest.raises(b.RadiosityError, match=says) as e:
                s.set_lights([bad])
            assert "\n" not in str(e.value)
        s.solve_frame(1)
        assert s.corner_radiosity(0)[2][0] == pytest.approx(centre[0], rel=1e-6)
