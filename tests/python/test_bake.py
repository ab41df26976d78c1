"""The bake operator on a Cornell-box-like room with a keyframed moving light and a moving box."""

import numpy as np
import pytest
import scenes


def _floor_halves(bpy, floor, frame):
    """Mean floor colour on the -x and +x halves at `frame`, through the evaluated mesh."""
    bpy.context.scene.frame_set(frame)
    c = scenes.corner_colors(floor, bpy.context.evaluated_depsgraph_get())
    me = floor.data
    x = np.array([me.vertices[lp.vertex_index].co.x for lp in me.loops])
    return c[x < -0.01].mean(), c[x > 0.01].mean()


def test_cornell_box_bake_follows_the_light_and_plays_back_without_the_addon(blender, tmp_path):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 3))
    assert scenes.bake(bpy, basis_order=1) == {"FINISHED"}
    floor = objs["Floor"]
    for name, obj in objs.items():
        assert scenes.rad_frames(obj.data) == [1, 2, 3], name
        assert obj.modifiers[-1].node_group.name == "Radiosity Switch"
        assert obj.data.color_attributes.active_color_name == "Radiosity"
    # The light moves from x = -0.5 to x = +0.5: the floor's bright side follows it.
    left1, right1 = _floor_halves(bpy, floor, 1)
    left3, right3 = _floor_halves(bpy, floor, 3)
    assert left1 > 1.2 * right1
    assert right3 > 1.2 * left3
    # Brighter near the light: the ceiling (facing down, next to the light) is darker than the floor below it.
    ceiling = scenes.stored(objs["Ceiling"].data, 2).mean()
    assert 0 < ceiling < scenes.stored(floor.data, 2).mean()
    # The emitter shows its radiance: Emission Strength 10 x white.
    np.testing.assert_allclose(scenes.stored(objs["Light"].data, 1), 10.0, rtol=1e-3)
    # Frames differ where the light moved.
    assert not np.allclose(scenes.stored(floor.data, 1), scenes.stored(floor.data, 3))

    # Saved and re-opened in a fresh process without the add-on: frame f shows Rad_f.
    path = tmp_path / "box.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    names = ["Floor", "Left", "Box", "Light"]
    out = scenes.evaluate_in_fresh_process(path, names, [0, 1, 2, 3, 4])
    assert not out["addon_loaded"] and not out["has_operator"]
    for f in (0, 1, 2, 3, 4):
        held = min(max(f, 1), 3)  # outside the baked range the switch holds the ends
        for n in names:
            got = np.array(out["frames"][str(f)][n])
            np.testing.assert_allclose(got, scenes.stored(objs[n].data, held), rtol=1e-6, atol=1e-7,
                                       err_msg=f"{n} frame {f}")


def test_frame_step_interpolates_between_solved_frames(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 3), box=False)
    solved = []
    from addon.blender import bake

    bake.listeners.append(lambda e: solved.append(e["frame"]) if e["kind"] == "frame" else None)
    assert scenes.bake(bpy, basis_order=0, frame_step=2) == {"FINISHED"}
    assert solved == [1, 3]
    floor = objs["Floor"].data
    assert scenes.rad_frames(floor) == [1, 2, 3]
    np.testing.assert_allclose(scenes.stored(floor, 2),
                               0.5 * (scenes.stored(floor, 1) + scenes.stored(floor, 3)), rtol=1e-6)


def test_clear_removes_attributes_switch_and_record(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    scenes.bake(bpy, basis_order=0)
    assert "radiosity_bake" in bpy.context.scene
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    for obj in objs.values():
        assert scenes.rad_frames(obj.data) == []
        assert "Radiosity" not in obj.data.color_attributes
        assert len(obj.modifiers) == 0
    assert "radiosity_bake" not in bpy.context.scene


def test_preview_material_is_applied_by_the_switch_only(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 1), box=False)
    before = {n: [s.material.name for s in o.material_slots] for n, o in objs.items()}
    scenes.bake(bpy, basis_order=0, preview_material=True)
    dg = bpy.context.evaluated_depsgraph_get()
    floor_eval = objs["Floor"].evaluated_get(dg)
    me = floor_eval.to_mesh()
    assert {me.materials[p.material_index].name for p in me.polygons} == {"Radiosity Preview"}
    floor_eval.to_mesh_clear()
    assert {n: [s.material.name for s in o.material_slots] for n, o in objs.items()} == before
    nodes = bpy.data.materials["Radiosity Preview"].node_tree.nodes
    assert nodes["Color Attribute"].layer_name == "Radiosity"


@pytest.mark.parametrize("level", [1, 2])
def test_display_subdivision_bakes_onto_a_copy(blender, level):
    bpy = blender
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 2), box=False)
    floor = objs["Floor"]
    n_loops = len(floor.data.loops)
    scenes.bake(bpy, basis_order=2, display_subdivision=level)
    assert scenes.rad_frames(floor.data) == []  # the artist's mesh is not touched
    copy = bpy.data.meshes["Radiosity Copy: Floor"]
    assert len(copy.loops) == n_loops * 4**level
    assert scenes.rad_frames(copy) == [1, 2]
    bpy.context.scene.frame_set(2)
    dg = bpy.context.evaluated_depsgraph_get()
    c = scenes.corner_colors(floor, dg)
    assert c.shape == (len(copy.loops), 3)
    np.testing.assert_allclose(c, scenes.stored(copy, 2), rtol=1e-6)
    assert c.min() > 0


def test_topology_changing_modifier_bakes_through_a_copy(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 1), box=False)
    floor = objs["Floor"]
    mod = floor.modifiers.new("Subdiv", "SUBSURF")
    mod.levels = 1
    mod.subdivision_type = "SIMPLE"
    assert scenes.bake(bpy, basis_order=1) == {"FINISHED"}
    copy = bpy.data.meshes["Radiosity Copy: Floor"]
    assert len(copy.loops) == 4 * len(floor.data.loops)
    assert floor.modifiers[-1].node_group.name == "Radiosity Switch"
    assert scenes.corner_colors(floor, bpy.context.evaluated_depsgraph_get()).min() > 0
