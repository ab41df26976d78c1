"""What the export sees: animated emission, per-object overrides, collections, deformation,
parenting; and the panels' properties."""

import numpy as np
import pytest
import scenes


def _static_room(bpy, strength=10.0):
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 2), light_x=(0.0, 0.0), box=False, strength=strength)
    return objs


def test_animated_emission_scales_the_solution(blender):
    bpy = blender
    objs = _static_room(bpy)
    bsdf = bpy.data.materials["Light"].node_tree.nodes["Principled BSDF"]
    strength = bsdf.inputs["Emission Strength"]
    strength.default_value = 10.0
    strength.keyframe_insert("default_value", frame=1)
    strength.default_value = 20.0
    strength.keyframe_insert("default_value", frame=2)
    assert scenes.bake(bpy, basis_order=1) == {"FINISHED"}
    floor = objs["Floor"].data
    # Radiosity is linear in the emission: twice the strength, twice the colours.
    np.testing.assert_allclose(scenes.stored(floor, 2), 2 * scenes.stored(floor, 1), rtol=2e-3)
    np.testing.assert_allclose(scenes.stored(objs["Light"].data, 2), 20.0, rtol=1e-3)


def test_emission_multiplier_and_exclude(blender):
    bpy = blender
    objs = _static_room(bpy)
    scenes.bake(bpy, basis_order=0, frame_start=1, frame_end=1, use_scene_range=False)
    base = scenes.stored(objs["Floor"].data, 1)
    objs["Light"].radiosity.emission_multiplier = 3.0
    scenes.bake(bpy)
    np.testing.assert_allclose(scenes.stored(objs["Light"].data, 1), 30.0, rtol=1e-3)
    # Radiosity is linear in the emission.
    np.testing.assert_allclose(scenes.stored(objs["Floor"].data, 1), 3 * base, rtol=2e-3)
    tripled = scenes.stored(objs["Floor"].data, 1)
    # Excluding the back wall: no colours on it, and less light bounces onto the floor.
    objs["Back"].radiosity.exclude = True
    bpy.ops.radiosity.clear()
    scenes.bake(bpy)
    assert scenes.rad_frames(objs["Back"].data) == []
    assert len(objs["Back"].modifiers) == 0
    assert scenes.stored(objs["Floor"].data, 1).mean() < tripled.mean()


def test_collection_hidden_and_unrenderable_objects(blender):
    bpy = blender
    objs = _static_room(bpy)
    coll = bpy.data.collections.new("Lit")
    bpy.context.scene.collection.children.link(coll)
    for name in ("Floor", "Light"):
        coll.objects.link(objs[name])
    objs["Left"].hide_render = True
    objs["Right"].hide_set(True)
    from addon.blender import export

    sel = export.collect(bpy.context.scene, bpy.context.view_layer)
    assert "Left" not in [o.name for o in sel.objects] and "Right" not in [o.name for o in sel.objects]
    bpy.context.scene.radiosity.collection = coll
    scenes.bake(bpy, basis_order=0, frame_start=1, frame_end=1, use_scene_range=False)
    assert scenes.rad_frames(objs["Floor"].data) == [1]
    assert scenes.rad_frames(objs["Back"].data) == []


def test_parenting_moves_children_with_the_parent(blender):
    bpy = blender
    objs = _static_room(bpy)
    rig = bpy.data.objects.new("Rig", None)
    bpy.context.scene.collection.objects.link(rig)
    objs["Light"].parent = rig
    rig.location.x = -0.6
    rig.keyframe_insert("location", index=0, frame=1)
    rig.location.x = 0.6
    rig.keyframe_insert("location", index=0, frame=2)
    scenes.bake(bpy, basis_order=1)
    floor = objs["Floor"].data
    me = floor
    x = np.array([me.vertices[lp.vertex_index].co.x for lp in me.loops])
    f1, f2 = scenes.stored(floor, 1).mean(axis=1), scenes.stored(floor, 2).mean(axis=1)
    assert f1[x < 0].mean() > f1[x > 0].mean()
    assert f2[x > 0].mean() > f2[x < 0].mean()


def _shape_key_on_frame_2(obj, name):
    """A shape key of `obj` (after a Basis), keyed 0 on frame 1 and 1 on frame 2."""
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name=name)
    for frame, value in ((1, 0.0), (2, 1.0)):
        key.value = value
        key.keyframe_insert("value", frame=frame)
    return key


def _bake_order_0(bpy):
    """The scene baked at order 0 by a BakeJob: (the job, its summary)."""
    from addon.blender import bake

    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene).replace(basis_order=0))
    return job, job.run()


def test_deforming_mesh_rebuilds_the_session(blender):
    bpy = blender

    objs = _static_room(bpy)
    box = scenes.cube(bpy, "Box", 0.3, (0, 0, 0.3), bpy.data.materials["White"])
    tall = _shape_key_on_frame_2(box, "Tall")
    for i in (4, 5, 6, 7):  # the top face rises
        tall.data[i].co.z += 0.8
    job, summary = _bake_order_0(bpy)
    assert job.rebuilt == 1 and "rebuilt the session on 1 deformed frame(s)" in summary
    # The taller box shadows more of the floor.
    floor = objs["Floor"].data
    assert scenes.stored(floor, 2).mean() < scenes.stored(floor, 1).mean()
    assert scenes.rad_frames(box.data) == [1, 2]


def test_a_flat_mesh_that_bends_on_a_later_frame_keeps_its_faces(blender):
    """A deformed frame's rebuild keeps the library faces of the first export: a flat grid that a
    shape key bends on frame 2 (whose bent quads a fresh export would split there, changing the
    faces) bakes both frames, its quads one bilinear element each."""
    bpy = blender

    objs = _static_room(bpy)
    verts, faces = scenes.grid_quad((-0.4, -0.4, 0.2), (0.8, 0, 0), (0, 0.8, 0), 3)
    sheet = scenes.mesh_object(bpy, "Sheet", verts, faces, bpy.data.materials["White"])
    bent = _shape_key_on_frame_2(sheet, "Bent")
    for k, v in enumerate(bent.data):  # a checkerboard of raised vertices bends every quad
        v.co.z += 0.1 * ((k % 4 + k // 4) % 2)
    job, summary = _bake_order_0(bpy)
    assert job.rebuilt == 1, summary
    data = next(o.data for o in job.rest.objects if o.obj.name == "Sheet")
    assert data.split.face_sizes.tolist() == [4] * len(faces)
    assert scenes.rad_frames(sheet.data) == [1, 2]
    assert scenes.stored(objs["Floor"].data, 2).mean() > 0


class _Layout:
    """Records layout.prop calls (panels cannot draw without a window)."""

    def __init__(self, props):
        self.props = props
        self.use_property_split = self.use_property_decorate = self.enabled = False
        self.scale_y = 1.0

    def prop(self, data, name, **_kw):
        self.props.append((data, name))

    def operator(self, idname, **_kw):
        self.props.append((None, idname))

    def row(self, **_kw):
        return self

    def column(self, **_kw):
        return self


@pytest.mark.parametrize("panel", ["RENDER_PT_radiosity", "RENDER_PT_radiosity_frames",
                                   "RENDER_PT_radiosity_output", "OBJECT_PT_radiosity"])
def test_panels_draw_existing_properties_and_operators(blender, panel):
    bpy = blender
    objs = _static_room(bpy)
    bpy.context.view_layer.objects.active = objs["Floor"]
    import addon.ui

    cls = getattr(addon.ui, panel)
    assert hasattr(bpy.types, panel)
    calls = []

    class Fake:
        layout = _Layout(calls)

    class Ctx:
        scene = bpy.context.scene
        object = objs["Floor"]

    cls.draw(Fake(), Ctx())
    assert calls
    for data, name in calls:
        if data is None:
            assert hasattr(bpy.ops.radiosity, name.split(".")[1])
        else:
            assert name in data.bl_rna.properties, name


def test_invoke_falls_through_to_execute_headless(blender):
    bpy = blender
    _static_room(bpy)
    bpy.context.scene.radiosity.basis_order = 0
    assert bpy.ops.radiosity.bake("INVOKE_DEFAULT") == {"FINISHED"}


def test_quads_are_split_into_blenders_own_loop_triangles(blender):
    """The library's triangles of a split quad are Blender's ``loop_triangles`` (the ones Cycles
    renders and bakes), in Blender's order, for 2,000 random quads: flat, bent, concave, folded."""
    from addon.core import polygons

    bpy = blender
    rng = np.random.default_rng(7)
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    quads = (square + rng.normal(0.0, 0.35, (2000, 4, 3))).astype(np.float32)
    mesh = bpy.data.meshes.new("quads")
    mesh.from_pydata(quads.reshape(-1, 3).tolist(), [], np.arange(8000).reshape(-1, 4).tolist())
    mesh.calc_loop_triangles()
    tri_loops = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loops)
    tri_poly = np.empty(len(mesh.loop_triangles), np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", tri_poly)
    split = polygons.split_faces(quads.reshape(-1, 3), np.full(2000, 4), np.arange(8000))
    assert split.split_polygons > 1900  # random quads are bent
    ours = {f: [] for f in range(2000)}
    for f, corners in zip(split.source_face, np.split(split.corner_loop, np.cumsum(split.face_sizes)[:-1]),
                          strict=True):
        ours[int(f)].append(corners.tolist())
    theirs = {f: [] for f in range(2000)}
    for f, corners in zip(tri_poly, tri_loops.reshape(-1, 3), strict=True):
        theirs[int(f)].append(corners.tolist())
    for f in range(2000):
        if len(ours[f]) == 2:
            assert ours[f] == theirs[f], f"quad {f}: {quads[f].tolist()}"
