"""Scenes of real meshes built in Blender as an artist would (issue 19): mesh objects placed by
their object transform (rotation from the files' y-up to Blender's z-up, uniform scale,
location), decimated with Blender's Decimate modifier (collapse, applied), one grey Diffuse BSDF
of reflectance 0.7 on every receiver and one light quad, one-sided, facing down, with an
Emission shader. Blender is z-up, metres.

Presets (docs/validation-real.md):
- "bunny": bunny.obj decimated to ~300 triangles (closed), 0.6 m long, standing on a 2 x 2 m
  ground plane under a 0.6 m light quad 1 m up: small enough for a unit test.
- "room": a closed 4 x 3 x 4 m room (floor, ceiling, four walls, inward-facing, 0.5 m quads), the
  table of pybullet's table.urdf (table.obj, a unit cube, scaled into a top and four legs that
  pass 5 mm into it) on the floor, bunny.obj (902 triangles) on the table, the teddy (15 convex
  hulls that pass through each other, decimated to ~700 triangles) on the floor, a 1 m light quad
  1 cm under the ceiling.
- "monastery": samurai_monastry.obj welded, its pieces of largest area up to 3,000 triangles,
  decimated to ~1,000, on a ground plane 2 cm under its lowest point, a light quad above it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import blender_scene, real_meshes

GREY = (0.7, 0.7, 0.7)
LIGHT_RADIANCE = 10.0  # W/m^2/sr: exitance pi x 10 on the light's front
PRESETS = ("bunny", "room", "monastery")
# pybullet's table.urdf: the visual boxes of table.obj (a unit cube), (scale, origin) in metres.
TABLE_PARTS = [
    ((1.5, 1.0, 0.05), (0.0, 0.0, 0.6)),
    ((0.1, 0.1, 0.58), (-0.65, -0.4, 0.29)),
    ((0.1, 0.1, 0.58), (-0.65, 0.4, 0.29)),
    ((0.1, 0.1, 0.58), (0.65, -0.4, 0.29)),
    ((0.1, 0.1, 0.58), (0.65, 0.4, 0.29)),
]


@dataclass
class BuiltScene:
    name: str
    objects: dict                      # name -> bpy object, every mesh of the scene
    emitters: dict                     # our emission material name -> its one-sided Cycles variant
    notes: list[str] = field(default_factory=list)

    @property
    def receivers(self) -> list:
        return [ob for ob in self.objects.values() if not self.is_emitter(ob)]

    def is_emitter(self, ob) -> bool:
        return any(s.material is not None and s.material.name in self.emitters for s in ob.material_slots)


def build(bpy, preset: str, meshes=None) -> BuiltScene:
    """Builds `preset` into the current (empty) Blender file."""
    if preset not in PRESETS:
        raise SystemExit(f"unknown scene {preset!r}: one of {', '.join(PRESETS)}")
    folder = real_meshes.mesh_dir(meshes)
    sc = bpy.context.scene
    sc.world = None  # black background, as the solver's open scenes
    grey = blender_scene._diffuse(bpy, "Grey", GREY)
    exitance = [math.pi * LIGHT_RADIANCE] * 3
    light = blender_scene._emission(bpy, "Light", exitance, one_sided=False)
    light_cycles = blender_scene._emission(bpy, "Light (one-sided)", exitance, one_sided=True)
    built = BuiltScene(preset, {}, {light.name: light_cycles})
    {"bunny": _bunny, "room": _room, "monastery": _monastery}[preset](bpy, built, folder, grey, light)
    bpy.context.view_layer.update()
    for ob in built.objects.values():
        lo, hi = world_bounds(ob)
        built.notes.append(
            f"{ob.name}: {len(ob.data.polygons)} faces, world bounds {np.round(lo, 3).tolist()} .. "
            f"{np.round(hi, 3).tolist()} m"
        )
    return built


def _bunny(bpy, built, folder, grey, light):
    bunny = real_meshes.load(folder / "bunny.obj")
    built.notes.append("file " + bunny.describe())
    ob = mesh_object(bpy, built, "Bunny", bunny, grey)
    decimate(bpy, ob, 300)
    place(bpy, ob, scale=0.3, y_up=True, centre=(0.0, 0.0), base=0.0)
    panel(bpy, built, "Ground", (-1, -1, 0), (2, 0, 0), (0, 2, 0), 8, 8, grey)
    panel(bpy, built, "Light", (-0.3, -0.3, 1.0), (0, 0.6, 0), (0.6, 0, 0), 1, 1, light)
    camera(bpy, (1.1, -1.3, 0.9), (0.0, 0.0, 0.15), lens=30)


def _room(bpy, built, folder, grey, light):
    # Inward-facing: each panel's u x v points into the room.
    panel(bpy, built, "Floor", (-2, -2, 0), (4, 0, 0), (0, 4, 0), 8, 8, grey)
    panel(bpy, built, "Ceiling", (-2, -2, 3), (0, 4, 0), (4, 0, 0), 8, 8, grey)
    panel(bpy, built, "Wall -x", (-2, -2, 0), (0, 4, 0), (0, 0, 3), 8, 6, grey)
    panel(bpy, built, "Wall +x", (2, -2, 0), (0, 0, 3), (0, 4, 0), 6, 8, grey)
    panel(bpy, built, "Wall -y", (-2, -2, 0), (0, 0, 3), (4, 0, 0), 6, 8, grey)
    panel(bpy, built, "Wall +y", (-2, 2, 0), (4, 0, 0), (0, 0, 3), 8, 6, grey)
    panel(bpy, built, "Light", (-0.5, -0.5, 2.99), (0, 1, 0), (1, 0, 0), 1, 1, light)
    cube = real_meshes.load(folder / "table" / "table.obj")
    built.notes.append("file " + cube.describe())
    parts = [
        real_meshes.Mesh("table", cube.vertices * np.array(s) + np.array(o), cube.faces)
        for s, o in TABLE_PARTS
    ]
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    table = real_meshes.Mesh(
        "table",
        np.concatenate([p.vertices for p in parts]),
        np.concatenate([p.faces + k for p, k in zip(parts, offsets, strict=True)]),
    )
    ob = mesh_object(bpy, built, "Table", table, grey)  # the URDF is z-up already
    place(bpy, ob, scale=1.0, y_up=False, centre=(0.6, 0.4), base=0.0)
    top = world_bounds(ob)[1][2]
    bunny = real_meshes.load(folder / "bunny.obj")
    built.notes.append("file " + bunny.describe())
    ob = mesh_object(bpy, built, "Bunny", bunny, grey)
    place(bpy, ob, scale=0.2, y_up=True, centre=(0.6, 0.4), base=top)
    teddy = real_meshes.load(folder / "teddy2_VHACD_CHs.obj")
    built.notes.append("file " + teddy.describe())
    ob = mesh_object(bpy, built, "Teddy", teddy, grey)
    decimate(bpy, ob, 700)
    place(bpy, ob, scale=0.5, y_up=True, centre=(-1.0, -0.9), base=0.0)
    camera(bpy, (1.0, -1.9, 1.2), (-0.15, -0.1, 0.45), lens=20)


def _monastery(bpy, built, folder, grey, light):
    whole = real_meshes.welded(real_meshes.load(folder / "samurai_monastry.obj"))
    built.notes.append("file (welded) " + whole.describe())
    kept, n_kept, n_all = real_meshes.largest_pieces(whole, 3000)
    built.notes.append(f"kept the {n_kept} pieces of largest area of {n_all} ({len(kept.faces)} triangles)")
    ob = mesh_object(bpy, built, "Monastery", kept, grey)
    decimate(bpy, ob, 1000)
    place(bpy, ob, scale=1.0, y_up=True, centre=(0.0, 0.0), base=0.0)
    lo, hi = world_bounds(ob)
    size = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    half = 0.6 * size
    panel(bpy, built, "Ground", (-half, -half, lo[2] - 0.02), (2 * half, 0, 0), (0, 2 * half, 0), 8, 8, grey)
    a = 0.25 * size
    panel(bpy, built, "Light", (-a, -a, hi[2] + 0.5 * size), (0, 2 * a, 0), (2 * a, 0, 0), 1, 1, light)
    camera(bpy, (0.7 * size, -0.95 * size, 0.6 * size), (0.0, 0.0, 0.0), lens=24)


def mesh_object(bpy, built, name, mesh: real_meshes.Mesh, material):
    me = bpy.data.meshes.new(name)
    me.from_pydata(mesh.vertices.tolist(), [], mesh.faces.tolist())
    me.update()
    me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    built.objects[ob.name] = ob
    return ob


def decimate(bpy, ob, faces: int) -> None:
    """Blender's Decimate modifier (collapse, triangulated) to about `faces` faces, applied: the
    object's mesh is replaced by the evaluated one (what modifier_apply does, without an
    operator context)."""
    n = len(ob.data.polygons)
    if n <= faces:
        return
    mod = ob.modifiers.new("Decimate", "DECIMATE")
    mod.decimate_type = "COLLAPSE"
    mod.ratio = faces / n
    mod.use_collapse_triangulate = True
    dg = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(ob.evaluated_get(dg))
    ob.modifiers.remove(mod)
    old = ob.data
    ob.data = mesh
    mesh.name = old.name
    bpy.data.meshes.remove(old)


def place(bpy, ob, *, scale: float, y_up: bool, centre, base: float) -> None:
    """Object transform: y-up file axes to z-up ((x, y, z) -> (x, -z, y), a rotation of +90 deg
    about X, as Blender's OBJ importer), uniform `scale`, then the location that puts the world
    bounds' x-y centre at `centre` and their lowest point at height `base`."""
    ob.rotation_euler = (math.pi / 2, 0.0, 0.0) if y_up else (0.0, 0.0, 0.0)
    ob.scale = (scale, scale, scale)
    ob.location = (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    lo, hi = world_bounds(ob)
    ob.location = (centre[0] - 0.5 * (lo[0] + hi[0]), centre[1] - 0.5 * (lo[1] + hi[1]), base - lo[2])
    bpy.context.view_layer.update()


def world_bounds(ob) -> tuple[np.ndarray, np.ndarray]:
    co = np.empty(len(ob.data.vertices) * 3, np.float64)
    ob.data.vertices.foreach_get("co", co)
    m = np.array(ob.matrix_world)
    w = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return w.min(axis=0), w.max(axis=0)


def panel(bpy, built, name, origin, u, v, nu, nv, material):
    """A grid of nu x nv quads over origin + [0,1] u + [0,1] v; the front is the side of u x v."""
    o, u, v = (np.asarray(a, np.float64) for a in (origin, u, v))
    verts = [o + (i / nu) * u + (j / nv) * v for j in range(nv + 1) for i in range(nu + 1)]
    faces = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            faces.append([a, a + 1, a + nu + 2, a + nu + 1])
    mesh = real_meshes.Mesh(name, np.array(verts), np.array(faces))
    return mesh_object(bpy, built, name, mesh, material)


def camera(bpy, location, target, lens):
    from mathutils import Vector

    cam = bpy.data.cameras.new("Camera")
    cam.lens = lens
    ob = bpy.data.objects.new("Camera", cam)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    ob.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = ob
