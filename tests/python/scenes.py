"""Scenes built in code for the Blender tests (not a test module)."""

import math

import numpy as np


def material(bpy, name, color=(0.8, 0.8, 0.8), emission=(0.0, 0.0, 0.0), strength=0.0):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    return mat


def mesh_object(bpy, name, vertices, faces, mat=None, location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in vertices], [], [tuple(f) for f in faces])
    me.update()
    obj = bpy.data.objects.new(name, me)
    obj.location = location
    if mat is not None:
        me.materials.append(mat)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def grid_quad(origin, u, v, n):
    """An n x n grid of quads spanning origin + [0,1]u + [0,1]v, counter-clockwise about u x v."""
    origin, u, v = (np.asarray(a, float) for a in (origin, u, v))
    verts = [origin + (i / n) * u + (j / n) * v for j in range(n + 1) for i in range(n + 1)]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    return verts, faces


def emitter_quad(bpy, name, size, z, strength, mat_name="Light", location=(0, 0, 0)):
    """A square of side `size` at height z (object space), facing down (-z)."""
    h = size / 2
    verts = [(-h, -h, z), (-h, h, z), (h, h, z), (h, -h, z)]  # clockwise from above: normal -z
    mat = material(bpy, mat_name, color=(0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0), strength=strength)
    return mesh_object(bpy, name, verts, [(0, 1, 2, 3)], mat, location)


def cornell_box(bpy, n=3, light_frames=(1, 3), light_x=(-0.5, 0.5), box=True, strength=10.0):
    """Room [-1,1]^2 x [0,2] with inward faces: floor, ceiling and four walls (red left, green
    right), a 0.5 x 0.5 ceiling light keyframed along x, and an optional keyframed box."""
    white = material(bpy, "White", (0.7, 0.7, 0.7))
    red = material(bpy, "Red", (0.7, 0.1, 0.1))
    green = material(bpy, "Green", (0.1, 0.7, 0.1))
    walls = {
        "Floor": ((-1, -1, 0), (2, 0, 0), (0, 2, 0), white),
        "Ceiling": ((-1, -1, 2), (0, 2, 0), (2, 0, 0), white),
        "Back": ((-1, 1, 0), (2, 0, 0), (0, 0, 2), white),
        "Front": ((-1, -1, 0), (0, 0, 2), (2, 0, 0), white),
        "Left": ((-1, -1, 0), (0, 2, 0), (0, 0, 2), red),
        "Right": ((1, -1, 0), (0, 0, 2), (0, 2, 0), green),
    }
    objs = {}
    for name, (o, u, v, mat) in walls.items():
        verts, faces = grid_quad(o, u, v, n)
        objs[name] = mesh_object(bpy, name, verts, faces, mat)
    light = emitter_quad(bpy, "Light", 0.5, 0.0, strength, location=(light_x[0], 0, 1.98))
    f0, f1 = light_frames
    light.location.x = light_x[0]
    light.keyframe_insert("location", index=0, frame=f0)
    light.location.x = light_x[1]
    light.keyframe_insert("location", index=0, frame=f1)
    _linear(light)
    objs["Light"] = light
    if box:
        objs["Box"] = cube(bpy, "Box", 0.3, (0.0, -0.3, 0.3), white)
        objs["Box"].keyframe_insert("location", index=1, frame=f0)
        objs["Box"].location.y = 0.3
        objs["Box"].keyframe_insert("location", index=1, frame=f1)
        _linear(objs["Box"])
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = f0, f1
    sc.frame_set(f0)
    return objs


def cube(bpy, name, half, location, mat):
    h = half
    verts = [(-h, -h, -h), (h, -h, -h), (h, h, -h), (-h, h, -h),
             (-h, -h, h), (h, -h, h), (h, h, h), (-h, h, h)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return mesh_object(bpy, name, verts, faces, mat, location)


def _linear(obj):
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return
    try:
        curves = ad.action.fcurves
    except AttributeError:  # 5.0: layered actions
        from bpy_extras import anim_utils

        curves = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    for fc in curves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def disc_form_factor(radius, height):
    """Point-to-coaxial-disc form factor (parallel, facing): r^2 / (r^2 + h^2)."""
    return radius**2 / (radius**2 + height**2)


def square_form_factor(a, b, c):
    """Differential area to a parallel rectangle a x b at distance c, with the normal through a
    corner (Howell's catalogue, C-11)."""
    x, y = a / c, b / c
    return (1 / (2 * math.pi)) * (
        x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x))
        + y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))
    )


def corner_colors(obj, depsgraph, name="Radiosity"):
    """(C,3) values of a corner colour attribute of the evaluated mesh."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        attr = me.attributes.get(name)
        if attr is None:
            return None
        buf = np.empty(len(me.loops) * 4, np.float32)
        attr.data.foreach_get("color", buf)
        return buf.reshape(-1, 4)[:, :3].copy()
    finally:
        ev.to_mesh_clear()


def bake(bpy, **props):
    """Sets scene.radiosity properties and runs the real bake operator."""
    p = bpy.context.scene.radiosity
    for k, v in props.items():
        setattr(p, k, v)
    return bpy.ops.radiosity.bake()


def rad_frames(mesh):
    return sorted(int(a.name[4:]) for a in mesh.color_attributes if a.name.startswith("Rad_"))


def stored(mesh, frame):
    attr = mesh.color_attributes[f"Rad_{frame:04d}"]
    buf = np.empty(len(mesh.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].copy()


FRESH = r'''
import json, os, sys, tempfile
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()
import bpy
import numpy as np
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
names, frames = json.loads(sys.argv[2]), json.loads(sys.argv[3])
out = {"addon_loaded": any(m == "addon" or m.startswith("addon.") for m in sys.modules),
       "has_operator": hasattr(bpy.ops, "radiosity") and "bake" in dir(bpy.ops.radiosity), "frames": {}}
sc = bpy.context.scene
for f in frames:
    sc.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    row = {}
    for n in names:
        ev = bpy.data.objects[n].evaluated_get(dg)
        me = ev.to_mesh()
        a = me.attributes.get("Radiosity")
        if a is None:
            row[n] = None
        else:
            buf = np.empty(len(me.loops) * 4, np.float32)
            a.data.foreach_get("color", buf)
            row[n] = buf.reshape(-1, 4)[:, :3].tolist()
        ev.to_mesh_clear()
    out["frames"][str(f)] = row
print("RESULT" + json.dumps(out))
'''


def evaluate_in_fresh_process(path, names, frames):
    """Opens `path` in a new Python with bpy but without the add-on, and returns the evaluated
    ``Radiosity`` corner colours per frame and object."""
    import json
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", FRESH, str(path), json.dumps(names), json.dumps(frames)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT"))
    return json.loads(line[len("RESULT"):])


def stored_named(mesh, name):
    attr = mesh.color_attributes[name]
    buf = np.empty(len(mesh.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].copy()
