"""Builds a Blender scene from a galerkin-radiosity scene file (version 1).

The scene file is y-up (the Cornell box data); Blender is z-up: a point (x, y, z) becomes
(x, -z, y), a rotation about X that keeps handedness, so face orientation is kept.
Materials: a Diffuse BSDF (Lambertian) of the reflectance for non-emitters; an Emission shader
of radiance E / pi for emitters, which the add-on reads as exitance pi x radiance. For Cycles
ground truth the emitters get a one-sided variant (back faces black diffuse), because mesh
emission in Cycles is two-sided while ours is one-sided.
"""

import json
import math
from pathlib import Path

import numpy as np


def to_blender(p):
    x, y, z = p
    return (x, -z, y)


def _diffuse(bpy, name, color):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def one_sided(bpy, mat):
    """A copy of the material `mat` (its Surface shader) that is black diffuse on back faces:
    a Mix Shader of the original and a black Diffuse BSDF by Geometry's Backfacing."""
    new = mat.copy()
    new.name = f"{mat.name} (one-sided)"
    nt = new.node_tree
    out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    link = out.inputs["Surface"].links[0]
    shader = link.from_socket
    nt.links.remove(link)
    black = nt.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
    nt.links.new(shader, mix.inputs[1])
    nt.links.new(black.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return new


def _emission(bpy, name, exitance, one_sided):
    """Emission of radiance exitance / pi; `one_sided`: back faces are black diffuse."""
    radiance = [e / math.pi for e in exitance]
    strength = max(radiance)
    color = [r / strength for r in radiance] if strength > 0 else [0.0, 0.0, 0.0]
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*color, 1.0)
    em.inputs["Strength"].default_value = strength
    if not one_sided:
        nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
        return mat
    black = nt.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
    nt.links.new(em.outputs["Emission"], mix.inputs[1])
    nt.links.new(black.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return mat


def build(bpy, scene_file, *, frames=None):
    """Creates one mesh object per scene object, with materials, location keyframes (linear)
    from translation keys, the Cornell camera, and a black world. Returns the objects by name
    and the materials as (ours, one-sided for Cycles) pairs per emitter."""
    data = json.loads(Path(scene_file).read_text())
    sc = bpy.context.scene
    first, last = frames or data.get("frames", [1, 1])
    sc.frame_start, sc.frame_end = first, last
    materials, emitters = [], {}
    for m in data["materials"]:
        if any(e > 0 for e in m.get("emission", [0, 0, 0])):
            ours = _emission(bpy, m["name"], m["emission"], one_sided=False)
            emitters[ours.name] = _emission(bpy, m["name"] + " (one-sided)", m["emission"], one_sided=True)
            materials.append(ours)
        else:
            materials.append(_diffuse(bpy, m["name"], m["reflectance"]))
    objects = {}
    for o in data["objects"]:
        if any(abs(v) > 1e-12 for v in np.array(o.get("matrix", np.eye(4).ravel()))[[3, 7, 11]]):
            raise ValueError(f"{o['name']}: a base matrix with translation is not supported here")
        verts = [to_blender(v) for v in o["vertices"]]
        me = bpy.data.meshes.new(o["name"])
        me.from_pydata(verts, [], [list(f) for f in o["faces"]])
        me.update()
        used = sorted(set(o.get("face_materials") or [o.get("material", 0)] * len(o["faces"])))
        for mi in used:
            me.materials.append(materials[mi])
        fm = o.get("face_materials") or [o.get("material", 0)] * len(o["faces"])
        me.polygons.foreach_set("material_index", [used.index(m) for m in fm])
        ob = bpy.data.objects.new(o["name"], me)
        sc.collection.objects.link(ob)
        for key in o.get("animation", []):
            if "translation" not in key:
                raise ValueError(f"{o['name']}: only translation keys are supported here")
            ob.location = to_blender(key["translation"])
            ob.keyframe_insert("location", frame=key["frame"])
        _linear(ob)
        objects[ob.name] = ob
    _camera(bpy, sc)
    sc.world = None
    return objects, emitters


def _linear(ob):
    ad = ob.animation_data
    if ad is None or ad.action is None:
        return
    fcurves = getattr(ad.action, "fcurves", None)
    if fcurves is None:  # Blender 5.0: layered, slotted actions
        from bpy_extras import anim_utils

        fcurves = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    for fc in fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def _camera(bpy, sc):
    """The Cornell camera: (278, 273, -800) mm looking +z (y-up), 35 mm lens, 25 mm film."""
    cam = bpy.data.cameras.new("Camera")
    cam.lens = 35.0
    cam.sensor_width = 25.0
    cam.sensor_fit = "HORIZONTAL"
    ob = bpy.data.objects.new("Camera", cam)
    sc.collection.objects.link(ob)
    ob.location = to_blender((0.278, 0.273, -0.800))
    ob.rotation_euler = (math.pi / 2, 0.0, math.pi)
    sc.camera = ob


def use_materials(objects, swap):
    """Replaces material slots by name: `swap` maps a material name to its replacement."""
    for ob in objects.values():
        for slot in ob.material_slots:
            if slot.material is not None and slot.material.name in swap:
                slot.material = swap[slot.material.name]


def corner_values(ob, name):
    """(C, 3) float32 values of a corner colour attribute of the object's own mesh."""
    attr = ob.data.color_attributes[name]
    buf = np.empty(len(ob.data.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].copy()
