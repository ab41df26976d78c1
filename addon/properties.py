"""Scene and object properties (``scene.radiosity``, ``object.radiosity``).

No ``from __future__ import annotations`` here: Blender reads the property annotations.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from .core.settings import MAX_DISPLAY_SUBDIVISION, QUALITY

QUALITY_ITEMS = [(k, k.title(), v[2]) for k, v in QUALITY.items()]
METHOD_ITEMS = [
    ("INCREMENTAL", "Incremental", "Update the previous frame's solution: series for moved links, "
     "progressive shooting of the differences (fastest for rigid motion)"),
    ("EXACT", "Exact", "Incremental, but every changed link recomputed by quadrature"),
    ("FULL", "Full", "Every frame from scratch"),
]


def _live_update(self, context):
    from .blender import live

    if self.live_preview:
        live.enable(context.scene)
    else:
        live.disable(context.scene)


class RadiositySceneSettings(bpy.types.PropertyGroup):
    basis_order: IntProperty(
        name="Basis Order", default=2, min=0, max=3,
        description="Legendre degree per axis of the radiosity on each face (0: constant per face)")
    quality: EnumProperty(
        name="Quality", items=QUALITY_ITEMS, default="MEDIUM",
        description="Integration and visibility sampling of the form factors")
    tolerance: FloatProperty(
        name="Tolerance", default=1e-4, min=1e-8, max=0.5, precision=6,
        description="Stop shooting when the unshot light would deliver less than this fraction "
                    "of the emitted power")
    visibility: BoolProperty(
        name="Shadows", default=True,
        description="Ray-cast visibility between faces (off: everything sees everything)")
    corner_gather: BoolProperty(
        name="Corner Gather", default=True,
        description="Gather the light at every face corner with its own shadow rays: sharp "
                    "contact shadows, no light leaking under objects; about one more kernel build "
                    "per frame (off: faster, corners from each face's polynomial)")
    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="Worker threads (0: all cores)")
    method: EnumProperty(name="Method", items=METHOD_ITEMS, default="INCREMENTAL")
    use_scene_range: BoolProperty(name="Scene Frame Range", default=True,
                                  description="Bake the scene's frame range")
    frame_start: IntProperty(name="Start", default=1, min=0, max=9999)
    frame_end: IntProperty(name="End", default=250, min=0, max=9999)
    frame_step: IntProperty(
        name="Step", default=1, min=1, max=1000,
        description="Solve every n-th frame; frames in between interpolate the colours linearly")
    collection: PointerProperty(
        name="Collection", type=bpy.types.Collection,
        description="Bake only this collection's objects (empty: the whole scene)")
    display_subdivision: IntProperty(
        name="Display Subdivision", default=0, min=0, max=MAX_DISPLAY_SUBDIVISION,
        description="Evaluate the radiosity polynomial on a 2^n x 2^n grid per face, shown through a "
                    "bake-time copy of the mesh (the object's own mesh is not modified)")
    preview_material: BoolProperty(
        name="Preview Material", default=False,
        description="Show the baked colours as emission through a separate material set by the switch "
                    "modifier (your materials are not changed)")
    live_preview: BoolProperty(
        name="Live Preview", default=False, update=_live_update,
        description="Re-solve the current frame when objects move, lights change or the frame changes")
    live_refine_when_idle: BoolProperty(
        name="Refine When Idle", default=True,
        description="While the frame changes or objects move, show previews: solved to ten times the "
                    "tolerance, without the corner gather (the face polynomials at the corners); refine "
                    "the frame the timeline rests on. Faster scrubbing. Off: every change is solved in "
                    "full. Background mode always solves in full")


class RadiosityObjectSettings(bpy.types.PropertyGroup):
    exclude: BoolProperty(name="Exclude", default=False,
                          description="Leave this object out of the radiosity bake")
    emission_multiplier: FloatProperty(
        name="Emission Multiplier", default=1.0, min=0.0, soft_max=100.0,
        description="Scales the emission of this object's materials in the bake")


classes = (RadiositySceneSettings, RadiosityObjectSettings)


def register_properties():
    bpy.types.Scene.radiosity = PointerProperty(type=RadiositySceneSettings)
    bpy.types.Object.radiosity = PointerProperty(type=RadiosityObjectSettings)


def unregister_properties():
    del bpy.types.Object.radiosity
    del bpy.types.Scene.radiosity
