"""Textured reflectance (issue 22, item 3): an Image Texture on Principled Base Color (directly,
or multiplied with a constant by a Mix node) enters the solve per face as its mean over the face
(addon/blender/textures.py), sRGB decoded as Blender does.

- The exported per-face reflectance is the image's mean over each face, computed here from the
  image's own pixels.
- A red/white checker floor bleeding onto white walls, baked through the add-on, against Cycles'
  DIFFUSE bake of the walls (the floor's texture at full resolution): relative RMSE per wall
  within 3% + twice Cycles' noise (two seeds), as tests/python/test_validation.py. Cycles bakes
  each loop from inside its own face, and a wall's bottom vertex on a check boundary then reads
  the red side from one face and the white from the other (0.08-0.13 relative RMSE between the
  loops of that row); the library gathers a vertex once, so the walls are compared with Cycles'
  per-vertex mean (with a plain floor the two readings agree to the noise).
- What cannot be read is named in the bake's report, by node type.
- Emission textures likewise: a black/white checker on an emitter's Emission Color gives each
  face the checker's mean as its emission scale (the material's emission being strength x
  white), the emitter's faces show their own exitance, a floor under it receives half of what
  the untextured emitter gives it, and matches Cycles' DIFFUSE bake of the floor lit by the
  textured emitter (3% + twice Cycles' noise); a keyed Emission Strength scales it frame by frame
  with the texture kept. A chain that cannot be read is named, and the emission counts as none.
"""

import numpy as np
from scenes import bake, grid_quad, mesh_object, stored
from test_smooth_shading import _vertex_mean

from tools import bakes
from tools.blender_scene import corner_values

SAMPLES = 1024
RED = (0.8, 0.05, 0.05)


def _srgb_encode(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def _checker(bpy, size=64, checks=4, colors=(RED, (0.8, 0.8, 0.8))):
    """An 8-bit sRGB image of checks x checks squares of `colors` (scene-linear; by default red
    and 0.8 white), the first colour in the corner (u, v) = (0, 0)."""
    img = bpy.data.images.new("Checker", size, size, alpha=False)
    i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")   # rows (v), columns (u)
    red = ((i // (size // checks)) + (j // (size // checks))) % 2 == 0
    lin = np.where(red[..., None], np.array(colors[0]), np.array(colors[1]))
    px = np.concatenate([_srgb_encode(lin), np.ones((size, size, 1))], axis=2)
    img.pixels.foreach_set(px.astype(np.float32).reshape(-1))
    img.update()
    return img, lin


def _textured(bpy, img, mix=None):
    mat = bpy.data.materials.new("Checker floor")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Specular IOR Level"].default_value = 0.0   # Lambertian in Cycles
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    out = tex.outputs["Color"]
    if mix is not None:
        m = nodes.new("ShaderNodeMix")
        m.data_type = "RGBA"
        m.blend_type = "MULTIPLY"
        m.inputs["Factor"].default_value = 1.0
        m.inputs[7].default_value = (*mix, 1.0)            # B: the constant
        links.new(out, m.inputs[6])                         # A: the image
        out = m.outputs[2]
    links.new(out, bsdf.inputs["Base Color"])
    return mat


def _diffuse(bpy, name, color):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    mat.node_tree.links.new(bsdf.outputs[0], nodes["Material Output"].inputs["Surface"])
    return mat


def _room(bpy, floor_mat, n=4, floor_n=8):
    """Room [-1,1]^2 x [0,2], inward faces; the floor UV-mapped 0..1 over it; a Point light."""
    white = _diffuse(bpy, "White", (0.8, 0.8, 0.8))
    walls = {
        "Ceiling": ((-1, -1, 2), (0, 2, 0), (2, 0, 0)),
        "Back": ((-1, 1, 0), (2, 0, 0), (0, 0, 2)),
        "Front": ((-1, -1, 0), (0, 0, 2), (2, 0, 0)),
        "Left": ((-1, -1, 0), (0, 2, 0), (0, 0, 2)),
        "Right": ((1, -1, 0), (0, 0, 2), (0, 2, 0)),
    }
    objs = {name: mesh_object(bpy, name, *grid_quad(o, u, v, n), white) for name, (o, u, v) in walls.items()}
    verts, faces = grid_quad((-1, -1, 0), (2, 0, 0), (0, 2, 0), floor_n)
    floor = mesh_object(bpy, "Floor", verts, faces, floor_mat)
    uv = floor.data.uv_layers.new(name="UVMap")
    loops = np.empty(len(floor.data.loops), np.int32)
    floor.data.loops.foreach_get("vertex_index", loops)
    co = np.asarray(verts, np.float64)[loops]
    uv.uv.foreach_set("vector", ((co[:, :2] + 1.0) / 2.0).astype(np.float32).reshape(-1))
    objs["Floor"] = floor
    data = bpy.data.lights.new("Lamp", "POINT")
    data.energy = 150.0
    data.shadow_soft_size = 0.0
    lamp = bpy.data.objects.new("Lamp", data)
    lamp.location = (0.2, -0.1, 1.2)
    bpy.context.scene.collection.objects.link(lamp)
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    return objs


def _face_means(floor, lin):
    """The image's exact mean over each floor face (the faces are axis-aligned in UV)."""
    size = lin.shape[0]
    me = floor.data
    out = []
    for p in me.polygons:
        uv = np.array([me.uv_layers["UVMap"].uv[i].vector[:] for i in p.loop_indices])
        (u0, v0), (u1, v1) = uv.min(axis=0), uv.max(axis=0)
        c0, c1 = round(u0 * size), round(u1 * size)
        r0, r1 = round(v0 * size), round(v1 * size)
        out.append(lin[r0:r1, c0:c1].reshape(-1, 3).mean(axis=0))
    return np.array(out)


def test_the_exported_reflectance_is_the_textures_mean_over_each_face(blender):
    bpy = blender
    from addon.blender import export

    img, lin = _checker(bpy)
    for mix, scale in ((None, 1.0), ((0.5, 0.5, 0.5), 0.5)):
        objs = _room(bpy, _textured(bpy, img, mix), floor_n=6)   # faces straddle the checks
        exp = export.export(bpy.context.evaluated_depsgraph_get(), [objs["Floor"]])
        assert exp.problems_line() is None, exp.problems_line()
        got = exp.objects[0].data.face_reflectance
        # 8-bit storage of the sRGB values costs up to half a step of 1/255 before decoding.
        np.testing.assert_allclose(got, _face_means(objs["Floor"], lin) * scale, atol=4e-3)
        for ob in list(bpy.data.objects):
            bpy.data.objects.remove(ob)


def test_a_checker_floor_bleeds_onto_white_walls_as_in_cycles(blender):
    bpy = blender
    img, _ = _checker(bpy)
    objs = _room(bpy, _textured(bpy, img))
    walls = [o for name, o in objs.items() if name != "Floor"]
    bakes.cycles_bake(bpy, walls, SAMPLES, attr="Cycles", seed=1)
    bakes.cycles_bake(bpy, walls, SAMPLES, attr="Cycles2", seed=2)
    assert bake(bpy, method="FULL") == {"FINISHED"}
    lines, ok = [], True
    for ob in walls:
        ref = _vertex_mean(ob.data, corner_values(ob, "Cycles"))
        noise = bakes.relative_rmse(_vertex_mean(ob.data, corner_values(ob, "Cycles2")), ref) / np.sqrt(2)
        ours = stored(ob.data, 1)
        rmse = bakes.relative_rmse(ours, ref)
        mean = abs(ours.mean() - ref.mean()) / ref.mean()
        # The bleed is there: the walls' red exceeds their green (white walls, red checks).
        redness = ours[:, 0].mean() / ours[:, 1].mean()
        lines.append(f"{ob.name}: rmse {rmse:.4f}, mean {mean:.4f}, noise {noise:.4f}, "
                     f"red/green {redness:.3f}")
        ok &= rmse < 0.03 + 2 * noise and redness > 1.05
    print("\n".join(lines))
    assert ok, "\n".join(lines)


def test_what_cannot_be_read_is_named(blender):
    bpy = blender
    from addon.blender import export

    mat = bpy.data.materials.new("Noisy")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    noise = mat.node_tree.nodes.new("ShaderNodeTexNoise")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.new(noise.outputs["Color"], bsdf.inputs["Base Color"])
    objs = _room(bpy, mat)
    line = export.export(bpy.context.evaluated_depsgraph_get(), [objs["Floor"]]).problems_line()
    assert line is not None and "Noise Texture" in line and "Noisy" in line, line


STRENGTH = 4.0   # the emitter's Emission Strength (radiance W/(sr m^2))
BLACK_WHITE = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))


def _uv_map(obj, origin, u, v):
    """A UV map over `obj` running 0..1 along its grid's u and v edges."""
    me = obj.data
    uv = me.uv_layers.new(name="UVMap")
    loops = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", loops)
    co = np.array([me.vertices[i].co[:] for i in loops], np.float64) - np.asarray(origin, np.float64)
    u, v = np.asarray(u, np.float64), np.asarray(v, np.float64)
    st = np.stack([co @ u / (u @ u), co @ v / (v @ v)], 1)
    uv.uv.foreach_set("vector", st.astype(np.float32).reshape(-1))


def _emissive(bpy, img=None):
    """A Principled emitter (black, no specular) of Emission Strength STRENGTH whose Emission
    Color is `img` (Closest) or, without one, white."""
    mat = bpy.data.materials.new("Glow")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["Emission Strength"].default_value = STRENGTH
    if img is not None:
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = img
        tex.interpolation = "Closest"
        mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Emission Color"])
    return mat


def _lit_floor(bpy, glow, emitter_n=4):
    """A 2 x 2 white floor of 8 x 8 faces under a 1 x 1 emitter of `emitter_n` x `emitter_n`
    faces at height 1, facing down, UV-mapped 0..1 (4 faces: one per check of `_checker`)."""
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    floor = mesh_object(bpy, "Floor", *grid_quad((-1, -1, 0), (2, 0, 0), (0, 2, 0), 8),
                        _diffuse(bpy, "White", (0.8, 0.8, 0.8)))
    origin, u, v = (-0.5, -0.5, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0)   # u x v = -z: facing down
    emitter = mesh_object(bpy, "Emitter", *grid_quad(origin, u, v, emitter_n), glow)
    _uv_map(emitter, origin, u, v)
    return floor, emitter


def _clear(bpy):
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)


def test_the_exported_emission_scale_is_the_textures_mean_over_each_face(blender):
    bpy = blender
    from addon.blender import export

    img, lin = _checker(bpy, colors=BLACK_WHITE)
    for n in (4, 6):   # faces on the checks (scales 0 and 1), and straddling them
        floor, emitter = _lit_floor(bpy, _emissive(bpy, img), emitter_n=n)
        exp = export.export(bpy.context.evaluated_depsgraph_get(), [floor, emitter])
        assert exp.problems_line() is None, exp.problems_line()
        # The material's emission is strength x white (exitance pi L), the faces carry the image.
        _, emission = exp.materials.arrays()
        assert np.allclose(emission.max(axis=0), np.pi * STRENGTH), emission
        got = exp.objects[1].data.face_emission
        np.testing.assert_allclose(got, _face_means(emitter, lin), atol=4e-3)
        if n == 4:
            assert sorted(np.unique(np.round(got[:, 0], 3))) == [0.0, 1.0]
        assert exp.objects[0].data.face_emission is None   # the floor has no emission texture
        _clear(bpy)


def test_a_half_black_emission_texture_halves_the_light_as_in_cycles(blender):
    bpy = blender
    img, lin = _checker(bpy, colors=BLACK_WHITE)
    glow = _emissive(bpy, img)
    floor, emitter = _lit_floor(bpy, glow)
    bakes.cycles_bake(bpy, [floor], SAMPLES, attr="Cycles", seed=1)
    bakes.cycles_bake(bpy, [floor], SAMPLES, attr="Cycles2", seed=2)
    assert bake(bpy, method="FULL") == {"FINISHED"}
    textured = stored(floor.data, 1)
    # The emitter's faces show their own exitance: B / pi = strength x the check's colour.
    shown = stored(emitter.data, 1)
    dark = np.repeat(_face_means(emitter, lin)[:, 0] < 0.5, 4)
    assert np.allclose(shown[dark], 0.0, atol=1e-4) and np.allclose(shown[~dark], STRENGTH, rtol=1e-3), shown
    ref = corner_values(floor, "Cycles")
    noise = bakes.relative_rmse(corner_values(floor, "Cycles2"), ref) / np.sqrt(2)
    rmse = bakes.relative_rmse(textured, ref)
    # The same emitter untextured (white): twice the light.
    glow.node_tree.links.remove(glow.node_tree.nodes["Principled BSDF"].inputs["Emission Color"].links[0])
    assert bake(bpy, method="FULL") == {"FINISHED"}
    plain = stored(floor.data, 1)
    ratio = textured.mean() / plain.mean()
    print(f"floor: textured/plain {ratio:.4f}; against Cycles rmse {rmse:.4f}, noise {noise:.4f}")
    assert abs(ratio - 0.5) < 0.01, ratio
    assert rmse < 0.03 + 2 * noise, (rmse, noise)


def test_an_unreadable_emission_texture_is_named_and_emits_nothing(blender):
    bpy = blender
    from addon.blender import export

    glow = _emissive(bpy)
    noise = glow.node_tree.nodes.new("ShaderNodeTexNoise")
    color = glow.node_tree.nodes["Principled BSDF"].inputs["Emission Color"]
    glow.node_tree.links.new(noise.outputs["Color"], color)
    floor, emitter = _lit_floor(bpy, glow)
    exp = export.export(bpy.context.evaluated_depsgraph_get(), [floor, emitter])
    line = exp.problems_line()
    assert line is not None and "Noise Texture" in line and "Glow" in line, line
    assert line.count("Noise Texture") == 1, line
    _, emission = exp.materials.arrays()
    assert not emission.any(), emission


def test_an_animated_strength_keeps_the_emission_texture(blender):
    # Emission Strength keyed STRENGTH -> 2 x STRENGTH over frames 1-2 under the checker: the
    # faces keep their scale (black stays black) and the floor's light doubles.
    bpy = blender
    img, lin = _checker(bpy, colors=BLACK_WHITE)
    glow = _emissive(bpy, img)
    floor, emitter = _lit_floor(bpy, glow)
    strength = glow.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"]
    for frame, value in ((1, STRENGTH), (2, 2 * STRENGTH)):
        strength.default_value = value
        strength.keyframe_insert("default_value", frame=frame)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 2
    assert bake(bpy, method="INCREMENTAL") == {"FINISHED"}
    ratio = stored(floor.data, 2).mean() / stored(floor.data, 1).mean()
    dark = np.repeat(_face_means(emitter, lin)[:, 0] < 0.5, 4)
    shown = stored(emitter.data, 2)
    print(f"floor frame 2 / frame 1: {ratio:.4f}")
    assert abs(ratio - 2.0) < 0.01, ratio
    assert np.allclose(shown[dark], 0.0, atol=1e-4) and np.allclose(shown[~dark], 2 * STRENGTH, rtol=1e-3)


# -- a linked Emission Strength (issue 22: "Light the way artists light") --------------------------


def _strength_from(bpy, mat, kind, value=STRENGTH):
    """Links `mat`'s Emission Strength from a Value node of `value` ("value", through a Reroute)
    or from Math MULTIPLY(Value value / 2, 2) ("math"); returns the Value node."""
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    strength = nodes["Principled BSDF"].inputs["Emission Strength"]
    strength.default_value = 0.0   # not what is read
    val = nodes.new("ShaderNodeValue")
    if kind == "value":
        val.outputs[0].default_value = value
        reroute = nodes.new("NodeReroute")
        links.new(val.outputs[0], reroute.inputs[0])
        links.new(reroute.outputs[0], strength)
    else:
        val.outputs[0].default_value = value / 2
        mul = nodes.new("ShaderNodeMath")
        mul.operation = "MULTIPLY"
        mul.inputs[1].default_value = 2.0
        links.new(val.outputs[0], mul.inputs[0])
        links.new(mul.outputs[0], strength)
    return val


def _bake_values(bpy, objs, frames=(1,)):
    assert bake(bpy, method="FULL") == {"FINISHED"}
    return {o.name: [stored(o.data, f) for f in frames] for o in objs}


def test_a_strength_from_a_value_or_math_node_bakes_as_the_typed_strength(blender):
    bpy = blender
    from addon.blender import export

    floor, emitter = _lit_floor(bpy, _emissive(bpy))
    typed = _bake_values(bpy, (floor, emitter))
    assert np.allclose(typed["Emitter"][0], STRENGTH, rtol=1e-6)
    for kind in ("value", "math"):
        _clear(bpy)
        floor, emitter = _lit_floor(bpy, _emissive(bpy))
        _strength_from(bpy, emitter.data.materials[0], kind)
        exp = export.export(bpy.context.evaluated_depsgraph_get(), [floor, emitter])
        assert exp.problems_line() is None, exp.problems_line()
        linked = _bake_values(bpy, (floor, emitter))
        for name, (values,) in linked.items():
            np.testing.assert_allclose(values, typed[name][0], rtol=1e-6, atol=1e-7, err_msg=f"{kind} {name}")


def test_a_keyed_value_node_strength_follows_its_keys_per_frame(blender):
    # The Value node keyed STRENGTH at frame 1 and 3 x STRENGTH at frame 3 (Bezier, so frame 2 is
    # the curve's value there): the emitter shows each frame's strength and the floor scales.
    bpy = blender
    floor, emitter = _lit_floor(bpy, _emissive(bpy))
    val = _strength_from(bpy, emitter.data.materials[0], "value")
    for frame, value in ((1, STRENGTH), (3, 3 * STRENGTH)):
        val.outputs[0].default_value = value
        val.outputs[0].keyframe_insert("default_value", frame=frame)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 3
    keyed = []
    for f in (1, 2, 3):
        sc.frame_set(f)
        keyed.append(val.outputs[0].default_value)
    assert keyed[0] == STRENGTH and keyed[2] == 3 * STRENGTH and keyed[0] < keyed[1] < keyed[2], keyed
    got = _bake_values(bpy, (floor, emitter), frames=(1, 2, 3))
    for f, value in enumerate(keyed):
        np.testing.assert_allclose(got["Emitter"][f], value, rtol=1e-5, err_msg=f"frame {f + 1}")
        ratio = got["Floor"][f].mean() / got["Floor"][0].mean()
        assert abs(ratio - value / STRENGTH) < 1e-4, (f + 1, ratio)


def test_a_colour_into_the_strength_is_its_luminance_as_in_cycles(blender):
    # An RGB node into an Emission shader's Strength: Blender converts the colour to a float with
    # the scene-linear luma weights. Cycles' EMIT bake of the face (1 sample: emission is exact)
    # measures them, one primary at a time, against what the add-on reads.
    bpy = blender
    from addon.blender import export

    floor, emitter = _lit_floor(bpy, _emissive(bpy))
    mat = bpy.data.materials.new("Lum")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    em, rgb = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeRGB")
    em.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    mat.node_tree.links.new(rgb.outputs[0], em.inputs["Strength"])
    mat.node_tree.links.new(em.outputs[0], nodes["Material Output"].inputs["Surface"])
    emitter.data.materials[0] = mat
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device, sc.cycles.samples = "CPU", 1
    me = emitter.data
    me.color_attributes.active_color = me.color_attributes.new("Emit", "FLOAT_COLOR", "CORNER")
    bpy.context.view_layer.objects.active = emitter
    emitter.select_set(True)
    cycles, ours = [], []
    for c in range(3):
        rgb.outputs[0].default_value = tuple(1.0 if k == c else 0.0 for k in range(3)) + (1.0,)
        bpy.ops.object.bake(type="EMIT", target="VERTEX_COLORS", use_clear=True, margin=0)
        cycles.append(float(corner_values(emitter, "Emit")[:, 0].mean()))
        exp = export.export(bpy.context.evaluated_depsgraph_get(), [emitter])
        assert exp.problems_line() is None, exp.problems_line()
        ours.append(exp.materials.arrays()[1][0, 0] / np.pi)
    print(f"luma weights: Cycles {np.round(cycles, 7)}, read {np.round(ours, 7)}")
    np.testing.assert_allclose(ours, cycles, rtol=1e-5)
    assert abs(sum(cycles) - 1.0) < 1e-5 and cycles[1] > cycles[0] > cycles[2] > 0


def _strength_texture(bpy, mat, img, value=None):
    """Links `mat`'s Emission Strength from `img`'s colour (Closest), times a Value node of
    `value` through Math MULTIPLY where given; returns the Image Texture node."""
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    out = tex.outputs["Color"]
    if value is not None:
        val, mul = nodes.new("ShaderNodeValue"), nodes.new("ShaderNodeMath")
        val.outputs[0].default_value, mul.operation = value, "MULTIPLY"
        links.new(out, mul.inputs[0])
        links.new(val.outputs[0], mul.inputs[1])
        out = mul.outputs[0]
    links.new(out, nodes["Principled BSDF"].inputs["Emission Strength"])
    return tex


def test_a_textured_strength_scales_each_face_by_its_luminance_mean(blender):
    bpy = blender
    from addon.blender import export
    from addon.blender.textures import luminance_weights

    img, lin = _checker(bpy)   # red and 0.8 white checks
    glow = _emissive(bpy)
    color = (1.0, 0.5, 0.25)
    glow.node_tree.nodes["Principled BSDF"].inputs["Emission Color"].default_value = (*color, 1.0)
    _strength_texture(bpy, glow, img)
    floor, emitter = _lit_floor(bpy, glow, emitter_n=6)   # faces straddling the checks
    exp = export.export(bpy.context.evaluated_depsgraph_get(), [floor, emitter])
    assert exp.problems_line() is None, exp.problems_line()
    # The material's emission is the colour x strength 1; each face carries the image's
    # luminance mean (grey), the colour staying in the material.
    np.testing.assert_allclose(exp.materials.arrays()[1].max(axis=0), np.pi * np.array(color), rtol=1e-6)
    got = exp.objects[1].data.face_emission
    want = _face_means(emitter, lin) @ luminance_weights()
    np.testing.assert_allclose(got, np.repeat(want[:, None], 3, axis=1), atol=4e-3)
    assert got.min() < 0.3 < 0.7 < got.max()


def test_a_textured_strength_bakes_as_the_same_texture_on_the_colour(blender):
    # A black/white checker on the strength (times a Value node of STRENGTH, through Math) is the
    # same light as the checker on the Emission Color with strength STRENGTH.
    bpy = blender
    img, _ = _checker(bpy, colors=BLACK_WHITE)
    floor, emitter = _lit_floor(bpy, _emissive(bpy, img))
    on_color = _bake_values(bpy, (floor, emitter))
    _clear(bpy)
    glow = _emissive(bpy)
    _strength_texture(bpy, glow, img, value=STRENGTH)
    floor, emitter = _lit_floor(bpy, glow)
    on_strength = _bake_values(bpy, (floor, emitter))
    for name, (values,) in on_strength.items():
        np.testing.assert_allclose(values, on_color[name][0], rtol=1e-5, atol=1e-6, err_msg=name)
    assert on_strength["Emitter"][0].max() > 0.9 * STRENGTH and on_strength["Emitter"][0].min() < 1e-4


def test_an_unreadable_strength_is_named_and_emits_nothing(blender):
    bpy = blender
    from addon.blender import export

    glow = _emissive(bpy)
    nodes = glow.node_tree.nodes
    for make, name in ((lambda: nodes.new("ShaderNodeTexNoise").outputs["Fac"], "Noise Texture"),
                       (lambda: _sine(nodes), "Math (Sine)")):
        strength = nodes["Principled BSDF"].inputs["Emission Strength"]
        glow.node_tree.links.new(make(), strength)
        floor, emitter = _lit_floor(bpy, glow)
        exp = export.export(bpy.context.evaluated_depsgraph_get(), [floor, emitter])
        line = exp.problems_line()
        assert line is not None and f"Emission Strength is linked to {name}, not read" in line, line
        assert not exp.materials.arrays()[1].any()
        _clear(bpy)


def _sine(nodes):
    m = nodes.new("ShaderNodeMath")
    m.operation = "SINE"
    return m.outputs[0]
