"""Smooth shading (issue 22, item 4): a corner of a smooth-shaded face is gathered with the mesh's
interpolated normal (``Mesh.corner_normals``, custom split normals included), as Cycles bakes it,
so the faces meeting at a smooth vertex get one value (no facets); flat faces are gathered as
before, bit for bit.

Against Cycles: a UV sphere and Suzanne on a floor under a Point light, each baked smooth and
flat through the add-on and by Cycles' DIFFUSE bake; the smooth bake must be as close to Cycles'
smooth bake as the flat bake is to Cycles' flat one (plus twice Cycles' noise, measured from two
seeds). Cycles' own smooth bake is not one value per vertex where a face at the vertex turns away
from the light (each loop's shadow ray starts from its own face: on Suzanne its loops differ from
their vertex's mean by 0.19 relative RMSE at 256 spp, noise 0.02), so the smooth bake is compared
with Cycles' per-vertex mean, the facet-free reading of it.
"""

import numpy as np
import pytest
from scenes import bake, grid_quad, mesh_object, stored

from tools import bakes

SAMPLES = 256


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


def _scene(bpy, shape):
    white = _diffuse(bpy, "White", (0.7, 0.7, 0.7))
    verts, faces = grid_quad((-2, -2, 0), (4, 0, 0), (0, 4, 0), 8)
    floor = mesh_object(bpy, "Floor", verts, faces, white)
    if shape == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.5, location=(0, 0, 0.6))
    else:
        bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0.7))
    obj = bpy.context.active_object
    obj.name = "Model"
    obj.data.materials.append(white)
    data = bpy.data.lights.new("Lamp", "POINT")
    data.energy = 300.0
    data.shadow_soft_size = 0.0
    lamp = bpy.data.objects.new("Lamp", data)
    lamp.location = (1.2, -0.8, 2.2)
    bpy.context.scene.collection.objects.link(lamp)
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    return floor, obj


def _shade(obj, smooth):
    obj.data.polygons.foreach_set("use_smooth", [smooth] * len(obj.data.polygons))
    obj.data.update()


def _vertex_spread(mesh, values):
    """The largest difference between two corners of one vertex, over the mesh's vertices."""
    v = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", v)
    lo = np.full((len(mesh.vertices), 3), np.inf)
    hi = np.full((len(mesh.vertices), 3), -np.inf)
    np.minimum.at(lo, v, values)
    np.maximum.at(hi, v, values)
    return float((hi - lo).max())


@pytest.mark.parametrize("shape", ["sphere", "suzanne"])
def test_smooth_meshes_have_no_facets_and_match_cycles(blender, shape):
    bpy = blender
    floor, model = _scene(bpy, shape)
    errors, spread = {}, {}
    for smooth in (False, True):
        _shade(model, smooth)
        bakes.cycles_bake(bpy, [model], SAMPLES, attr="Cycles", seed=1)
        bakes.cycles_bake(bpy, [model], SAMPLES, attr="Cycles2", seed=2)
        assert bake(bpy, method="FULL") == {"FINISHED"}
        ref = stored_attr(model, "Cycles")
        noise = bakes.relative_rmse(stored_attr(model, "Cycles2"), ref) / np.sqrt(2)
        ours = stored(model.data, 1)
        if smooth:
            ref = _vertex_mean(model.data, ref)
        errors[smooth] = (bakes.relative_rmse(ours, ref), noise)
        spread[smooth] = _vertex_spread(model.data, ours) / float(ours.mean())
    line = (f"{shape}: flat rmse {errors[False][0]:.4f} (noise {errors[False][1]:.4f}), smooth rmse "
            f"{errors[True][0]:.4f} (noise {errors[True][1]:.4f}); vertex spread flat {spread[False]:.3f}, "
            f"smooth {spread[True]:.2e}")
    print(line)
    # Flat: the faces of a vertex differ (facets); smooth: one value per vertex.
    assert spread[False] > 0.05, line
    assert spread[True] < 1e-5, line
    # Flat within Cycles' noise: Suzanne's bent quads bake as Blender's triangles (18.9% as
    # bilinear patches, 4.8% split).
    assert errors[False][0] <= 2.5 * errors[False][1] + 0.01, line
    if shape == "suzanne":
        # A known gap (docs/validation-real.md, "Smooth Suzanne"): 16.0% smooth, 86% of its squared
        # error at the vertices where the light's terminator crosses the vertex's faces. A bound,
        # so that the gap cannot widen unseen.
        assert errors[True][0] <= 0.18, line
    else:
        assert errors[True][0] <= errors[False][0] + 2 * errors[True][1] + 0.005, line


def _vertex_mean(mesh, values):
    """Each corner's value replaced by the mean over its vertex's corners."""
    v = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", v)
    count = np.maximum(np.bincount(v, minlength=len(mesh.vertices)), 1).astype(np.float64)
    mean = np.stack([np.bincount(v, weights=values[:, c], minlength=len(mesh.vertices)) for c in range(3)], 1)
    return (mean / count[:, None])[v].astype(np.float32)


def stored_attr(obj, name):
    from tools.blender_scene import corner_values

    return corner_values(obj, name)


def test_flat_meshes_export_no_normals_and_smooth_ones_their_corner_normals(blender):
    """Flat faces reach the library without normals (so they are gathered bit for bit as
    before); smooth faces carry ``Mesh.corner_normals``, custom split normals included."""
    bpy = blender
    from addon.blender import export

    _, model = _scene(bpy, "sphere")
    dg = bpy.context.evaluated_depsgraph_get()
    _shade(model, False)
    dg.update()
    flat = export.export(bpy.context.evaluated_depsgraph_get(), [model]).objects[0].data
    assert flat.corner_normals is None and flat.native()["corner_normals"] is None
    _shade(model, True)
    smooth = export.export(bpy.context.evaluated_depsgraph_get(), [model]).objects[0].data
    want = np.empty(len(model.data.loops) * 3, np.float32)
    model.data.corner_normals.foreach_get("vector", want)
    np.testing.assert_array_equal(smooth.corner_normals, want.reshape(-1, 3)[smooth.split.corner_loop])
    # Custom normals: every corner pointing up.
    model.data.normals_split_custom_set([(0.0, 0.0, 1.0)] * len(model.data.loops))
    custom = export.export(bpy.context.evaluated_depsgraph_get(), [model]).objects[0].data
    np.testing.assert_allclose(custom.corner_normals, np.tile([0.0, 0.0, 1.0], (len(model.data.loops), 1)),
                               atol=1e-3)  # custom normals are stored compressed


def test_a_mirrored_smooth_copy_is_lit_like_its_mirror_image(blender):
    """Item 5 with smooth shading: the shading normals of a negative-scale copy are placed by the
    inverse transpose (Blender's normal matrix), so a smooth sphere and its mirror image under a
    light on the mirror plane read the same values corner for corner."""
    bpy = blender
    white = _diffuse(bpy, "White", (0.7, 0.7, 0.7))
    verts, faces = grid_quad((-2, -2, 0), (4, 0, 0), (0, 4, 0), 8)
    mesh_object(bpy, "Floor", verts, faces, white)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=0.3, location=(-0.6, 0, 0.4))
    left = bpy.context.active_object
    left.data.materials.append(white)
    _shade(left, True)
    right = bpy.data.objects.new("Right", left.data.copy())   # its own mesh, its own colours
    right.location = (0.6, 0.0, 0.4)
    right.scale = (-1.0, 1.0, 1.0)
    bpy.context.scene.collection.objects.link(right)
    data = bpy.data.lights.new("Lamp", "POINT")
    data.energy = 200.0
    data.shadow_soft_size = 0.0
    lamp = bpy.data.objects.new("Lamp", data)
    lamp.location = (0.0, -0.4, 1.8)
    bpy.context.scene.collection.objects.link(lamp)
    sc = bpy.context.scene
    sc.frame_start = sc.frame_end = 1
    assert bake(bpy, method="FULL") == {"FINISHED"}
    # Copies of one mesh: corner k of the right sphere is the mirror image of the left one's.
    a, b = stored(left.data, 1), stored(right.data, 1)
    assert a.mean() > 0.02 and _vertex_spread(right.data, b) < 1e-5
    np.testing.assert_allclose(b, a, rtol=5e-3, atol=5e-3 * a.max())
