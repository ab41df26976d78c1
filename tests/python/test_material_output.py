"""Output for materials (issue 22, item 7): the irradiance H / pi per frame (``Irr_NNNN``,
switched into ``Radiosity Light``) beside B / pi, and Apply to Materials.

- Inside a closed box of reflectance 0.5 emitting L = 1 everywhere, B = E / (1 - rho), and every
  point receives H = B: both attributes are 2 at every corner, gathered or not.
- On a Cornell box, H / pi x rho + E / pi = B / pi at every corner (the definition), with the
  corner gather on and off.
- A textured (uniform image) floor with Apply to Materials: Cycles' EMIT bake of the material,
  which reads the switched attribute through the inserted group, equals the baked B / pi.
- Clear restores the node tree exactly (nodes, values, links) and removes the group.
- A cancelled re-bake leaves both attributes of every frame as they were.
"""

import numpy as np
import scenes
from test_cancel_and_errors import _cancel_at, _move_light_from_frame_2


def _stored(mesh, name):
    attr = mesh.color_attributes[name]
    buf = np.empty(len(mesh.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].copy()


def _closed_box(bpy, rho=0.5, strength=1.0):
    """A 2 m cube of 4 x 4 faces a side, faces inward, one material emitting `strength`."""
    mat = scenes.material(bpy, "Glow", (rho,) * 3, emission=(1.0, 1.0, 1.0), strength=strength)
    walls = [((-1, -1, -1), (0, 2, 0), (2, 0, 0)), ((-1, -1, 1), (2, 0, 0), (0, 2, 0)),
             ((-1, -1, -1), (2, 0, 0), (0, 0, 2)), ((-1, 1, -1), (0, 0, 2), (2, 0, 0)),
             ((-1, -1, -1), (0, 0, 2), (0, 2, 0)), ((1, -1, -1), (0, 2, 0), (0, 0, 2))]
    objs = []
    for k, (o, u, v) in enumerate(walls):
        verts, faces = scenes.grid_quad(o, v, u, 4)  # v x u: inward
        objs.append(scenes.mesh_object(bpy, f"Wall{k}", verts, faces, mat))
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    return objs


def test_closed_box_irradiance_is_its_radiosity(blender):
    bpy = blender
    objs = _closed_box(bpy)
    for gather in (True, False):
        assert scenes.bake(bpy, basis_order=1, corner_gather=gather, tolerance=1e-6) == {"FINISHED"}
        for obj in objs:
            b, h = _stored(obj.data, "Rad_0001"), _stored(obj.data, "Irr_0001")
            # L / (1 - rho) = 2, both: the box's light is all received and all reflected.
            np.testing.assert_allclose(b, 2.0, rtol=0.01, err_msg=f"{obj.name} gather={gather}")
            np.testing.assert_allclose(h, 2.0, rtol=0.01, err_msg=f"{obj.name} gather={gather}")


def _reflectance_and_radiance(obj):
    bsdf = obj.data.materials[0].node_tree.nodes["Principled BSDF"]
    rho = np.array(bsdf.inputs["Base Color"].default_value[:3])
    strength = bsdf.inputs["Emission Strength"].default_value
    radiance = np.array(bsdf.inputs["Emission Color"].default_value[:3]) * strength
    return rho, radiance


def test_irradiance_times_reflectance_plus_emission_is_the_radiosity(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 2), box=True)
    # Gathered corners, polynomial corners, and Display Subdivision's grid (Session.eval, on
    # bake-time copies).
    for gather, level in ((True, 0), (False, 0), (True, 1)):
        result = scenes.bake(bpy, basis_order=1, corner_gather=gather, display_subdivision=level)
        assert result == {"FINISHED"}
        meshes = {name: bpy.data.meshes["Radiosity Copy: " + name] if level else o.data
                  for name, o in objs.items()}
        peak = max(float(_stored(m, "Rad_0001").max()) for m in meshes.values())
        for name, obj in objs.items():
            rho, radiance = _reflectance_and_radiance(obj)
            for f in (1, 2):
                b, h = _stored(meshes[name], f"Rad_{f:04d}"), _stored(meshes[name], f"Irr_{f:04d}")
                assert (h >= 0).all()
                np.testing.assert_allclose(h * rho + radiance, b, atol=1e-5 * peak,
                                           err_msg=f"{name} frame {f} gather={gather}")
            if name == "Floor":
                assert h.mean() > 0.1
        light = _stored(meshes["Light"], "Irr_0001")
        if gather and not level:  # black: H is what it receives, gathered (not derivable from B)
            assert light.min() > 0.0
        else:
            assert (light == 0).all()  # rho 0: (B - E) / rho is not derived


def _textured_floor(bpy, objs, color=(0.6, 0.3, 0.2)):
    """The floor's material becomes a uniform float image on Base Color (UVs from the grid)."""
    floor = objs["Floor"]
    me = floor.data
    uv = me.uv_layers.new(name="UVMap")
    co = np.array([me.vertices[lp.vertex_index].co[:2] for lp in me.loops])
    uv.data.foreach_set("uv", ((co + 1.0) / 2.0).astype(np.float32).reshape(-1))
    img = bpy.data.images.new("Uniform", 8, 8, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    img.pixels.foreach_set(np.tile([*color, 1.0], 64).astype(np.float32))
    img.update()
    mat = bpy.data.materials.new("Textured floor")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    me.materials.clear()
    me.materials.append(mat)
    return mat


def _tree(mat):
    """Everything of a node tree that Clear must restore: nodes, their unlinked input values, links."""
    tree = mat.node_tree
    nodes = {}
    for n in tree.nodes:
        values = []
        for s in n.inputs:
            v = getattr(s, "default_value", None)
            values.append((s.identifier, tuple(v) if hasattr(v, "__len__") else v))
        nodes[n.name] = (n.bl_idname, tuple(n.location), tuple(values))
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier)
                   for lk in tree.links)
    return nodes, links


def test_apply_to_materials_renders_the_baked_light_and_clear_restores_the_tree(blender):
    bpy = blender
    from addon.blender import light_nodes

    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 1), box=False)
    color = (0.6, 0.3, 0.2)
    mat = _textured_floor(bpy, objs, color)
    before = {m.name: _tree(m) for m in bpy.data.materials}
    assert scenes.bake(bpy, basis_order=1, apply_to_materials=True) == {"FINISHED"}
    # Inserted: the output's Surface now comes from the group, which takes the shader and the
    # texture; nothing else changed.
    node = light_nodes.inserted(mat)
    assert node is not None and node.node_tree.name == "Radiosity Light"
    out = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    assert out.inputs["Surface"].links[0].from_node == node
    assert node.inputs["Shader"].links[0].from_node.bl_idname == "ShaderNodeBsdfPrincipled"
    assert node.inputs["Color"].links[0].from_node.bl_idname == "ShaderNodeTexImage"
    nodes, links = _tree(mat)
    old_nodes, old_links = before[mat.name]
    assert {k: v for k, v in nodes.items() if k != node.name} == old_nodes
    added = set(links) - set(old_links)
    removed = set(old_links) - set(links)
    assert removed == {("Principled BSDF", "BSDF", out.name, "Surface")}
    assert {(a, c) for a, _, c, _ in added} == {("Principled BSDF", node.name), (node.name, out.name),
                                                ("Image Texture", node.name)}
    for name in ("White", "Red", "Green", "Light"):
        assert light_nodes.inserted(bpy.data.materials[name]) is not None

    # Cycles renders the material (EMIT: what the surface shows) at every floor corner.
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device, sc.cycles.samples = "CPU", 1
    floor = objs["Floor"]
    me = floor.data
    me.color_attributes.active_color = me.color_attributes.new("Emit", "FLOAT_COLOR", "CORNER")
    bpy.ops.object.select_all(action="DESELECT")
    floor.select_set(True)
    bpy.context.view_layer.objects.active = floor
    bpy.ops.object.bake(type="EMIT", target="VERTEX_COLORS", use_clear=True, margin=0)
    rendered, baked = _stored(me, "Emit"), _stored(me, "Rad_0001")
    np.testing.assert_allclose(rendered, baked, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(_stored(me, "Irr_0001") * np.array(color), baked, rtol=1e-4, atol=1e-6)
    me.color_attributes.remove(me.color_attributes["Emit"])

    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert {m.name: _tree(m) for m in bpy.data.materials} == before
    assert "Radiosity Light" not in bpy.data.node_groups


def test_a_cancelled_rebake_leaves_both_attributes(blender):
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    assert scenes.bake(bpy, basis_order=0) == {"FINISHED"}

    def snapshot():
        return {o.name: {a.name: _stored(o.data, a.name) for a in o.data.color_attributes}
                for o in objs.values()}

    before = snapshot()
    irradiance = sorted(n for n in before["Floor"] if n.startswith("Irr_"))
    assert irradiance == [f"Irr_{f:04d}" for f in (1, 2, 3, 4)]
    _move_light_from_frame_2(objs)
    _cancel_at(bake, 1)  # frame 2 completes (staged), frame 3 is cancelled
    summary = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene)).run()
    assert "kept the previous bake (frames 1-4) unchanged" in summary
    after = snapshot()
    assert after.keys() == before.keys()
    for name, attrs in before.items():
        assert sorted(after[name]) == sorted(attrs), name  # no IrrNew_ / RadNew_ left
        for a, v in attrs.items():
            np.testing.assert_array_equal(after[name][a], v, err_msg=f"{name} {a}")


def test_linked_materials_are_skipped_in_one_line(blender, tmp_path):
    bpy = blender
    from addon.blender import bake, light_nodes

    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 1), box=False)
    lib = scenes.material(bpy, "Library White", (0.7, 0.7, 0.7))
    path = str(tmp_path / "lib.blend")
    bpy.data.libraries.write(path, {lib})
    bpy.data.materials.remove(lib)
    with bpy.data.libraries.load(path, link=True) as (_, dst):
        dst.materials = ["Library White"]
    linked = dst.materials[0]
    assert linked.library is not None
    objs["Floor"].data.materials[0] = linked
    bpy.context.scene.radiosity.apply_to_materials = True
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    job.run()
    lines = [w for w in job.warnings if w.startswith("Apply to Materials skipped")]
    assert lines == ["Apply to Materials skipped: Library White (linked from a library)"]
    assert light_nodes.inserted(linked) is None
    assert light_nodes.inserted(bpy.data.materials["White"]) is not None


def test_the_live_preview_writes_the_irradiance_too(blender):
    bpy = blender
    from addon.blender import live

    objs = scenes.cornell_box(bpy, light_frames=(1, 3), box=False)
    sc = bpy.context.scene
    sc.radiosity.basis_order = 1
    assert scenes.bake(bpy) == {"FINISHED"}
    solves = live.stats["solves"]
    sc.radiosity.live_preview = True
    sc.frame_set(3)
    assert live.stats["solves"] >= solves + 2
    floor = objs["Floor"]
    light = scenes.stored_named(floor.data, "Radiosity Light")
    np.testing.assert_allclose(light, _stored(floor.data, "Irr_0003"), rtol=0.02, atol=1e-3)
    rho, _ = _reflectance_and_radiance(floor)
    shown = scenes.stored_named(floor.data, "Radiosity")
    np.testing.assert_allclose(light * rho, shown, rtol=1e-5, atol=1e-7)
    sc.radiosity.live_preview = False


def test_a_rebake_reads_the_materials_through_the_inserted_group(blender):
    # After Apply to Materials, every material's output is fed by the group until Clear: a
    # re-bake (here of a moved light, with the option on, then off) must read the shaders the
    # group wraps, not see an unreadable group (grey, no emission: "no emitters").
    bpy = blender
    from addon.blender import bake, light_nodes

    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 1), box=False)
    _textured_floor(bpy, objs)
    assert scenes.bake(bpy, basis_order=1, apply_to_materials=True) == {"FINISHED"}
    first = {n: _stored(o.data, "Rad_0001") for n, o in objs.items()}
    objs["Light"].animation_data_clear()
    objs["Light"].location.x = 0.3
    for apply in (True, False):
        bpy.context.scene.radiosity.apply_to_materials = apply
        job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
        job.run()
        assert not [w for w in job.warnings if "not fully read" in w], job.warnings
        moved = {n: _stored(o.data, "Rad_0001") for n, o in objs.items()}
        np.testing.assert_allclose(moved["Light"], first["Light"], rtol=1e-6)   # its own emission
        assert abs(moved["Floor"].mean() / first["Floor"].mean() - 1.0) < 0.2   # lit, moved a little
        assert not np.allclose(moved["Floor"], first["Floor"], rtol=1e-3)
    for mat in bpy.data.materials:
        assert mat.get("radiosity_preview") == 1 or light_nodes.inserted(mat) is None, mat.name
