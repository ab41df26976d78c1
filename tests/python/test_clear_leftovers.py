"""Issue 23, item 6 (part): Clear removes everything the add-on made, through the real operators:
copies of an object renamed since the bake (they kept the old name and became orphans), and the
"Radiosity Preview" material."""

import scenes


def test_clear_after_a_rename_leaves_no_copy_and_no_preview_material(blender):
    from addon.blender import attributes

    bpy = blender
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 2), box=False)
    assert scenes.bake(bpy, basis_order=1, display_subdivision=1, preview_material=True) == {"FINISHED"}
    prefix = attributes.COPY_PREFIX
    assert bpy.data.meshes.get(prefix + "Floor") is not None
    assert bpy.data.materials.get("Radiosity Preview") is not None
    objs["Floor"].name = "Floor renamed"
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    left = [m.name for m in bpy.data.meshes if m.name.startswith(prefix)]
    left += [o.name for o in bpy.data.objects if o.name.startswith(prefix)]
    assert left == []
    assert bpy.data.materials.get("Radiosity Preview") is None
    # The artist's objects, meshes and materials are all still there.
    assert {"Floor renamed", "Ceiling", "Light"} <= {o.name for o in bpy.data.objects}
    assert all(o.data is not None and len(o.data.polygons) > 0 for o in objs.values())
    assert {"White", "Red", "Green"} <= {m.name for m in bpy.data.materials}


def test_a_partial_clear_keeps_the_preview_material_in_use(blender):
    bpy = blender
    scenes.cornell_box(bpy, n=1, light_frames=(1, 1), box=False)
    assert scenes.bake(bpy, basis_order=0, preview_material=True) == {"FINISHED"}
    from addon.blender import bake

    bake.clear_bake(bpy.context.scene, [bpy.data.objects["Floor"]])
    assert bpy.data.materials.get("Radiosity Preview") is not None
