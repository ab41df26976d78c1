"""Scene export from the evaluated depsgraph.

Objects: every mesh object of the chosen collection (default: the scene's) that is visible in
the view layer, renderable (not ``hide_render``) and not excluded in its Radiosity object
settings, sorted by name so the library order is stable. Other kinds of object are reported.

Light objects (Point, Spot, Sun, Area) of the same selection are sources: their evaluated state
(``matrix_world``, colour, power or strength, radius and Soft Falloff, spot size and blend, angle,
area shape and size) is sampled per frame and handed to the session with ``set_lights``; the
scene's World and the objects' Two-Sided Emitter settings likewise (``world.py``).

Geometry is the evaluated mesh (modifiers, shape keys, drivers applied) via
``evaluated_get(depsgraph).to_mesh()``, in object space; the placement is the evaluated
``matrix_world`` (keyframes, constraints, drivers and parenting all count), sampled per frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import materials as core_materials
from ..core.marshal import ObjectData, digest, emission_key
from ..core.record import FrameState
from . import textures
from .materials import read_material
from .world import WorldState, two_sided, world_state

SWITCH_MODIFIER = "Radiosity"
SWITCH_GROUP = "Radiosity Switch"
SILENT_TYPES = {"CAMERA", "EMPTY", "ARMATURE", "LATTICE", "SPEAKER", "LIGHT_PROBE"}


def is_switch_modifier(mod) -> bool:
    return mod.type == "NODES" and mod.node_group is not None and mod.node_group.name.startswith(SWITCH_GROUP)


@dataclass
class Selection:
    objects: list = field(default_factory=list)          # bpy objects, library order
    lights: list[str] = field(default_factory=list)
    light_objects: list = field(default_factory=list)    # bpy Light objects, by name
    non_mesh: list[str] = field(default_factory=list)    # "name (TYPE)"
    excluded: list[str] = field(default_factory=list)

    def notes(self) -> list[str]:
        out = []
        if self.lights and not self.objects:
            out.append("Light objects are ignored without meshes to light: " + ", ".join(self.lights))
        if self.non_mesh:
            out.append("Not meshes, skipped (convert them to meshes to bake them): "
                       + ", ".join(self.non_mesh))
        return out


def collect(scene, view_layer, collection=None) -> Selection:
    source = collection.all_objects if collection is not None else scene.collection.all_objects
    sel = Selection()
    for obj in sorted(source, key=lambda o: o.name):
        if obj.hide_render or not obj.visible_get(view_layer=view_layer):
            continue
        settings = getattr(obj, "radiosity", None)
        if settings is not None and settings.exclude:
            sel.excluded.append(obj.name)
            continue
        if obj.type == "MESH":
            sel.objects.append(obj)
        elif obj.type == "LIGHT":
            sel.lights.append(obj.name)
            sel.light_objects.append(obj)
        elif obj.type not in SILENT_TYPES:
            sel.non_mesh.append(f"{obj.name} ({obj.type})")
    return sel


def emitter_multiplier(obj) -> float:
    settings = getattr(obj, "radiosity", None)
    return float(settings.emission_multiplier) if settings is not None else 1.0


def may_deform(obj) -> bool:
    """Objects whose object-space vertices can change over frames: modifiers (except the
    switch), shape keys, animated mesh data."""
    if any(not is_switch_modifier(m) for m in obj.modifiers):
        return True
    data = obj.data
    if getattr(data, "shape_keys", None) is not None:
        return True
    return getattr(data, "animation_data", None) is not None


def read_mesh(mesh):
    """(vertices (N,3) float32, polygon sizes, loop vertex indices, polygon material indices, smooth)."""
    n_v, n_p, n_l = len(mesh.vertices), len(mesh.polygons), len(mesh.loops)
    co = np.empty(n_v * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    sizes = np.empty(n_p, np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    loops = np.empty(n_l, np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    mats = np.empty(n_p, np.int32)
    mesh.polygons.foreach_get("material_index", mats)
    smooth = np.empty(n_p, bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    return co.reshape(-1, 3), sizes, loops, mats, smooth


def read_normals(mesh):
    """(loop normals (L,3), polygon normals (P,3)) of a mesh with smooth or custom-normal
    corners (Blender's ``corner_normals``, 4.1+), or None when every face is flat."""
    if getattr(mesh, "normals_domain", "CORNER") == "FACE" or not hasattr(mesh, "corner_normals"):
        return None
    n_l, n_p = len(mesh.loops), len(mesh.polygons)
    loops = np.empty(n_l * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", loops)
    polys = np.empty(n_p * 3, np.float32)
    mesh.polygon_normals.foreach_get("vector", polys)
    return loops.reshape(-1, 3), polys.reshape(-1, 3)


def light_state(obj, depsgraph) -> dict:
    """A Light object as ``binding.Session.set_lights`` takes it, evaluated at the current frame
    (keyframes and drivers on the object and on its light data count)."""
    ev = obj.evaluated_get(depsgraph)
    d = ev.data
    out = {"type": d.type, "matrix": np.array(ev.matrix_world, np.float64),
           "color": tuple(float(c) for c in d.color), "power": float(d.energy)}
    if d.type in ("POINT", "SPOT"):
        out["radius"] = float(d.shadow_soft_size)
        out["soft_falloff"] = bool(getattr(d, "use_soft_falloff", True))
    if d.type == "SPOT":
        out["spot_size"], out["spot_blend"] = float(d.spot_size), float(d.spot_blend)
    if d.type == "SUN":
        out["angle"] = float(d.angle)
    if d.type == "AREA":
        out["shape"] = d.shape
        out["size"] = (float(d.size), float(d.size_y if d.shape in ("RECTANGLE", "ELLIPSE") else d.size))
    return out


def lights_key(lights: list[dict]) -> str:
    """A digest of the lights' states (part of a frame's emission state)."""
    if not lights:
        return ""
    parts = [np.asarray(light["matrix"], np.float64).reshape(-1) for light in lights]
    parts += [np.asarray([v for k, v in sorted(light.items()) if isinstance(v, float)]) for light in lights]
    names = "|".join(f"{light['type']}:{light.get('shape', '')}:{light.get('soft_falloff', '')}"
                     for light in lights)
    return digest(np.frombuffer(names.encode(), np.uint8), *parts, decimals=6)


@dataclass
class ExportedObject:
    obj: object                 # the original bpy object
    data: ObjectData
    slot_materials: list        # bpy materials per slot of the evaluated object (None for empty)
    polygon_smooth: np.ndarray
    original_topology: bool     # True: evaluated polygons and loops match the original mesh's
    deforms: bool


@dataclass
class Export:
    objects: list[ExportedObject]
    materials: core_materials.MaterialTable
    material_sources: list      # (bpy material or None, multiplier) per library material
    light_objects: list = field(default_factory=list)   # bpy Light objects
    lights: list = field(default_factory=list)          # their states at the export's frame
    world: WorldState = field(default_factory=WorldState)
    two_sided: list = field(default_factory=list)       # per object: emits from both sides

    def scene_key(self, settings_signature: dict, extra: str = "") -> str:
        rho, _ = self.materials.arrays()
        parts = [repr(sorted(settings_signature.items())), extra]
        parts += [o.obj.name + ":" + o.data.topology_key() for o in self.objects]
        return digest(np.frombuffer("|".join(parts).encode(), np.uint8), rho, decimals=6)

    def problems_line(self) -> str | None:
        problems = self.materials.problems()
        if not problems:
            return None
        grey = core_materials.DEFAULT_REFLECTANCE[0]
        return (f"Materials not fully read (defaults used: reflectance {grey:g} grey, no emission): "
                + ", ".join(problems))

    def degenerate_line(self) -> str | None:
        bad = [(o.obj.name, len(o.data.degenerate)) for o in self.objects if len(o.data.degenerate)]
        if not bad:
            return None
        total = sum(n for _, n in bad)
        return (f"{total} zero-area face(s) skipped by the solver (they show only their own emission): "
                + ", ".join(f"{name} ({n})" for name, n in bad))


def export(depsgraph, objects, light_objects=(), rest: Export | None = None) -> Export:
    """The library scene at the depsgraph's current frame, lit by `light_objects` too. `rest`:
    an earlier export of the same objects (a deformed frame's rebuild), whose library faces the
    deforming objects keep."""
    table = core_materials.MaterialTable()
    sources = []
    out = []
    table_problems = table.texture_problems
    kept_splits = {o.obj.name: o.data.split for o in rest.objects} if rest is not None else {}
    for obj in objects:
        ev = obj.evaluated_get(depsgraph)
        mesh = ev.to_mesh()
        try:
            co, sizes, loops, mats, smooth = read_mesh(mesh)
            normals = read_normals(mesh)
            slots = [s.material for s in ev.material_slots]
            textured = textures.polygon_reflectance(mesh, slots, mats, table_problems)
            emission_scale = textures.polygon_emission(mesh, slots, mats, table_problems)
        finally:
            ev.to_mesh_clear()
        mult = emitter_multiplier(obj)
        lib = []
        for mat in slots or [None]:
            key = (mat.name if mat is not None else f"<none>:{obj.name}", mult)

            def make(mat=mat, mult=mult, obj=obj):
                sources.append((mat, mult))
                return read_material(mat, mult, owner=obj.name)

            lib.append(table.add(key, make))
        lib = np.asarray(lib, np.int64)
        poly_lib = lib[np.clip(mats, 0, len(lib) - 1)] if len(mats) else np.zeros(0, np.int64)
        deforms = may_deform(obj)
        data = ObjectData.from_mesh(obj.name, co, sizes, loops, poly_lib, np.array(ev.matrix_world),
                                    split=kept_splits.get(obj.name) if deforms else None)
        if normals is not None:
            data.set_loop_normals(*normals)
        if textured is not None:
            data.set_polygon_reflectance(textured)
        if emission_scale is not None:
            data.set_polygon_emission(emission_scale)
        orig = obj.data
        same = len(orig.polygons) == len(sizes) and len(orig.loops) == len(loops)
        if same and len(sizes):
            osizes = np.empty(len(sizes), np.int32)
            orig.polygons.foreach_get("loop_total", osizes)
            same = bool((osizes == sizes).all())
        out.append(ExportedObject(obj, data, slots, smooth, same, deforms))
    light_objects = list(light_objects)
    return Export(out, table, sources, light_objects, [light_state(o, depsgraph) for o in light_objects],
                  world_state(depsgraph), two_sided(objects))


def frame_emission(export: Export) -> np.ndarray:
    """(M,3) exitance of every library material at the current frame."""
    rows = []
    for (mat, mult), spec in zip(export.material_sources, export.materials.specs, strict=True):
        rows.append(read_material(mat, mult).emission if mat is not None else spec.emission)
    return np.asarray(rows, np.float64).reshape(-1, 3)


@dataclass
class Sample:
    """What changes per frame: matrices, deforming geometry, emission."""

    matrices: list[np.ndarray]
    vertices: list[np.ndarray | None]   # None: the object does not deform
    emission: np.ndarray
    lights: list = field(default_factory=list)   # light states (``light_state``)
    world: WorldState = field(default_factory=WorldState)
    two_sided: list = field(default_factory=list)

    def state(self, rest: Export) -> FrameState:
        geometry = [
            (digest(v, decimals=6) if v is not None else o.data.geometry_key())
            for v, o in zip(self.vertices, rest.objects, strict=True)
        ]
        mats = [digest(m, decimals=6) for m in self.matrices]
        sided = "".join("2" if t else "1" for t in self.two_sided)
        return FrameState(mats, geometry,
                          emission_key(self.emission) + lights_key(self.lights) + self.world.key() + sided)


def sample(depsgraph, rest: Export, objects=None) -> Sample:
    """Matrices, vertices of deforming objects, and emission at the depsgraph's current frame.
    `objects`: the bpy objects in library order, if `rest`'s references may be stale (undo)."""
    matrices, vertices = [], []
    for i, o in enumerate(rest.objects):
        ev = (objects[i] if objects is not None else o.obj).evaluated_get(depsgraph)
        matrices.append(np.array(ev.matrix_world, np.float64))
        if o.deforms:
            mesh = ev.to_mesh()
            try:
                n = len(mesh.vertices)
                co = np.empty(n * 3, np.float32)
                mesh.vertices.foreach_get("co", co)
                n_loops = len(mesh.loops)
            finally:
                ev.to_mesh_clear()
            if n_loops != o.data.loop_count or n != len(o.data.vertices):
                raise TopologyChanged(o.data.name)
            vertices.append(co.reshape(-1, 3))
        else:
            vertices.append(None)
    lights = [light_state(o, depsgraph) for o in rest.light_objects]
    objs = objects if objects is not None else [o.obj for o in rest.objects]
    return Sample(matrices, vertices, frame_emission(rest), lights, world_state(depsgraph), two_sided(objs))


class TopologyChanged(Exception):
    """An object's evaluated mesh changed its number of vertices or corners between frames."""
