"""Colour attributes: one FLOAT_COLOR corner attribute per frame (``Rad_0001``...), holding the
outgoing radiance B / pi (scene-linear, alpha 1), and the ``Radiosity`` attribute the viewport
and renderers read (the Geometry Nodes switch overwrites it with the current frame's values).
Beside each, the irradiance H / pi, light only (``Irr_0001``..., switched into ``Radiosity
Light``), which a material multiplies with its own colour (``light_nodes.py``).

Colours go either on the object's own mesh ("mesh" storage: its evaluated polygons and corners
match the original mesh's) or on a bake-time copy ("copy" storage: display subdivision, or
modifiers that change the topology); see ``switch.py``.

A bake writes under staging names and on staging copies (``write_staged``, ``build_copy(...,
staging=True)``) beside the previous bake, which stays playable; ``promote_frames`` and
``promote_copy`` swap the new bake in, ``remove_staged`` and ``remove_copy(..., staging=True)``
drop it.
"""

from __future__ import annotations

import numpy as np

from ..core import frames as core_frames
from ..core.grids import Grid

COPY_PREFIX = "Radiosity Copy: "
STAGING_COPY_PREFIX = "Radiosity Copy (baking): "


def write(mesh, name: str, rgb: np.ndarray) -> None:
    """Writes (n,3) colours into the FLOAT_COLOR corner attribute `name` (created if needed)."""
    n = len(mesh.loops)
    rgb = np.asarray(rgb, np.float32).reshape(-1, 3)
    if len(rgb) != n:
        raise ValueError(f"{mesh.name}: {len(rgb)} colours for {n} corners")
    attr = mesh.color_attributes.get(name)
    if attr is not None and (attr.data_type != "FLOAT_COLOR" or attr.domain != "CORNER"):
        mesh.color_attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((n, 4), np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.reshape(-1))


def read(mesh, name: str) -> np.ndarray | None:
    attr = mesh.color_attributes.get(name)
    if attr is None or attr.domain != "CORNER":
        return None
    buf = np.empty(len(mesh.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].copy()


def write_frame(mesh, frame: int, rgb: np.ndarray) -> None:
    write(mesh, core_frames.attribute_name(frame), rgb)


def read_frame(mesh, frame: int) -> np.ndarray | None:
    return read(mesh, core_frames.attribute_name(frame))


def read_light_frame(mesh, frame: int) -> np.ndarray | None:
    """The irradiance H / pi of `frame` (``Irr_NNNN``), None if the mesh has none."""
    return read(mesh, core_frames.attribute_name(frame, core_frames.LIGHT_PREFIX))


def write_staged(mesh, frame: int, rgb: np.ndarray, light: np.ndarray | None = None) -> None:
    """A frame's B / pi (``RadNew_NNNN``) and, given, its H / pi (``IrrNew_NNNN``)."""
    write(mesh, core_frames.staging_name(frame), rgb)
    if light is not None:
        write(mesh, core_frames.staging_name(frame, core_frames.LIGHT_STAGING_PREFIX), light)


# (stored prefix, staging prefix) of each kind of frame attribute.
KINDS = (
    (core_frames.ATTRIBUTE_PREFIX, core_frames.STAGING_PREFIX),
    (core_frames.LIGHT_PREFIX, core_frames.LIGHT_STAGING_PREFIX),
)


def baked_frames(mesh, prefix: str = core_frames.ATTRIBUTE_PREFIX) -> list[int]:
    found = (core_frames.frame_of_attribute(a.name, prefix) for a in mesh.color_attributes)
    return sorted(f for f in found if f is not None)


def complete_frames(mesh) -> list[int]:
    """Frames stored with both their B / pi and their H / pi (a bake from before the irradiance
    has only the first: such frames are solved again by a re-bake)."""
    return sorted(set(baked_frames(mesh)) & set(baked_frames(mesh, core_frames.LIGHT_PREFIX)))


def staged_frames(mesh, prefix: str = core_frames.STAGING_PREFIX) -> list[int]:
    return baked_frames(mesh, prefix)


def remove_staged(mesh) -> int:
    """Removes the ``RadNew_NNNN`` and ``IrrNew_NNNN`` attributes (a bake that ended without
    keeping them); returns how many ``RadNew_`` frames there were."""
    n = 0
    for kind, (_, staging) in enumerate(KINDS):
        names = [core_frames.staging_name(f, staging) for f in staged_frames(mesh, staging)]
        for name in names:
            mesh.color_attributes.remove(mesh.color_attributes[name])
        n += len(names) if kind == 0 else 0
    return n


def promote_frames(mesh, keep_live=lambda frame: False) -> list[int]:
    """Swaps the staged frames in: removes every ``Rad_`` (``Irr_``) frame that is staged too or
    that `keep_live` rejects, then renames each ``RadNew_NNNN`` (``IrrNew_NNNN``) to
    ``Rad_NNNN`` (``Irr_NNNN``). Returns the ``Rad_`` frames now stored, sorted."""
    staged = set(staged_frames(mesh))
    remove_frames(mesh, keep=lambda f: f not in staged and keep_live(f))
    for prefix, staging in KINDS:
        for f in staged_frames(mesh, staging):
            attr = mesh.color_attributes[core_frames.staging_name(f, staging)]
            attr.name = core_frames.attribute_name(f, prefix)
    return baked_frames(mesh)


def remove_frames(mesh, keep=lambda frame: False) -> int:
    """Removes the ``Rad_NNNN`` and ``Irr_NNNN`` attributes whose frame `keep` rejects; returns
    how many ``Rad_`` frames it removed."""
    n = 0
    for kind, (prefix, _) in enumerate(KINDS):
        names = [a.name for a in mesh.color_attributes
                 if (f := core_frames.frame_of_attribute(a.name, prefix)) is not None and not keep(f)]
        for name in names:
            mesh.color_attributes.remove(mesh.color_attributes[name])
        n += len(names) if kind == 0 else 0
    return n


def ensure_result(mesh, rgb: np.ndarray | None = None, light: np.ndarray | None = None) -> None:
    """The ``Radiosity`` attribute, made active and the render colour, so the viewport's Color
    Attribute shading and a Color Attribute node with an empty name show it, and beside it
    ``Radiosity Light`` (the irradiance H / pi; zeros when `light` is None)."""
    name = core_frames.RESULT_ATTRIBUTE
    zeros = np.zeros((len(mesh.loops), 3), np.float32)
    write(mesh, name, zeros if rgb is None else rgb)
    write(mesh, core_frames.LIGHT_ATTRIBUTE, zeros if light is None else light)
    attrs = mesh.color_attributes
    attrs.active_color = attrs[name]
    attrs.render_color_index = attrs.find(name)


def remove_result(mesh) -> None:
    for name in (core_frames.RESULT_ATTRIBUTE, core_frames.LIGHT_ATTRIBUTE):
        attr = mesh.color_attributes.get(name)
        if attr is not None:
            mesh.color_attributes.remove(attr)


def copy_name(name: str, staging: bool = False) -> str:
    return (STAGING_COPY_PREFIX if staging else COPY_PREFIX) + name


def build_copy(bpy, name: str, grid: Grid, polygon_material: np.ndarray, polygon_smooth: np.ndarray,
               materials: list, staging: bool = False):
    """A mesh (and an unlinked object holding it, for the switch's Object Info) with the display
    grid's faces; each grid face takes its source polygon's material index and smoothing. With
    `staging`, under the name a bake builds it under until it ends (``promote_copy``)."""
    mesh_name = copy_name(name, staging)
    mesh = bpy.data.meshes.get(mesh_name)
    if mesh is None:
        mesh = bpy.data.meshes.new(mesh_name)
    else:
        mesh.clear_geometry()
    n_v, n_f, n_c = len(grid.vertices), len(grid.face_sizes), len(grid.face_indices)
    mesh.vertices.add(n_v)
    mesh.vertices.foreach_set("co", grid.vertices.astype(np.float32).reshape(-1))
    mesh.loops.add(n_c)
    mesh.loops.foreach_set("vertex_index", grid.face_indices.astype(np.int32))
    mesh.polygons.add(n_f)
    starts = np.concatenate([[0], np.cumsum(grid.face_sizes)[:-1]]).astype(np.int32)
    mesh.polygons.foreach_set("loop_start", starts)
    mesh.polygons.foreach_set("material_index", polygon_material[grid.source_face].astype(np.int32))
    mesh.polygons.foreach_set("use_smooth", polygon_smooth[grid.source_face].astype(bool))
    mesh.update(calc_edges=True)
    mesh.materials.clear()
    for mat in materials:
        mesh.materials.append(mat)
    obj = bpy.data.objects.get(mesh_name)
    if obj is None:
        obj = bpy.data.objects.new(mesh_name, mesh)
    else:
        obj.data = mesh
    obj.hide_render = True
    return obj, mesh


def remove_copy(bpy, name: str, staging: bool = False) -> None:
    obj = bpy.data.objects.get(copy_name(name, staging))
    if obj is not None:
        bpy.data.objects.remove(obj)
    mesh = bpy.data.meshes.get(copy_name(name, staging))
    if mesh is not None:
        bpy.data.meshes.remove(mesh)


def promote_copy(bpy, name: str):
    """Replaces the copy of object `name` with its staging copy (renamed); returns (obj, mesh)."""
    remove_copy(bpy, name)  # first, or the renamed ones would get a ".001" suffix
    obj = bpy.data.objects[copy_name(name, staging=True)]
    mesh = obj.data
    obj.name = mesh.name = copy_name(name)
    return obj, mesh
