"""Scene and object properties (``scene.radiosity``, ``object.radiosity``).

No ``from __future__ import annotations`` here: Blender reads the property annotations.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from .core.settings import (
    DEFAULT_HIERARCHY_ACCURACY,
    HIERARCHY_ACCURACY_RANGE,
    MAX_DISPLAY_SUBDIVISION,
    QUALITY,
)

# Labels and tooltips speak of what a setting does to the picture and what it costs; the
# technical terms follow in the tooltip, and the identifiers (the Python API) are unchanged.
_QUALITY_TIPS = {
    "DRAFT": "Fastest, for blocking out: coarse form factors and one shadow ray per pair of faces, "
             "so shadows inside a face are blocky",
    "MEDIUM": "Good for finals in most scenes (the library's default)",
    "HIGH": "Finer shadows inside large faces and more accurate light between close faces; "
            "the link build takes several times longer",
    "ULTRA": "Finest sampling, for checking; the link build is much slower",
}
QUALITY_ITEMS = [(k, k.title(), f"{_QUALITY_TIPS[k]}. Technical: {v[2]}") for k, v in QUALITY.items()]
METHOD_ITEMS = [
    ("INCREMENTAL", "Update", "Start each frame from the last one: fastest for moving objects and "
     "lights (technical: incremental update, series expansion of moved links, progressive shooting "
     "of the differences)"),
    ("EXACT", "Update, Exact Links", "Start each frame from the last one, recomputing every changed "
     "link by quadrature (no series); about as fast, for checking"),
    ("FULL", "From Scratch", "Solve every frame on its own: 10-30 times slower per frame, for "
     "checking"),
    ("HIERARCHICAL", "Large Scenes (Hierarchy)", "For scenes of thousands to 100,000+ faces: "
     "subdivides faces only where the light needs it (no subdividing meshes by hand; Refinement "
     "Threshold sets how finely) and lets far groups of faces exchange light as one, so memory and "
     "time grow about linearly with the faces instead of with their square. A 9,600-face room: "
     "about 4 s and 110 MB for the first frame (Sharp Corners off), where the other methods would "
     "need 69 GB. Frames after the first are updated from the last one, but on small scenes each "
     "is several times slower than Update (a 61-face box: 0.2 s against 0.05 s). Technical: "
     "hierarchical Galerkin radiosity with clustering"),
]


def _live_update(self, context):
    from .blender import live

    if self.live_preview:
        live.enable(context.scene)
    else:
        live.disable(context.scene)


class RadiositySceneSettings(bpy.types.PropertyGroup):
    basis_order: IntProperty(
        name="Detail", default=2, min=0, max=3,
        description="How much the light may vary across one face: 0 flat, 1 a gradient, 2-3 curved. "
                    "Higher needs fewer faces for smooth light but memory per pair of faces grows "
                    "fast (8, 128, 648, 2048 bytes) and 3 takes about twice as long as 2. With "
                    "Large Scenes (Hierarchy) it applies to each of the pieces it cuts faces into. "
                    "Technical: Legendre basis order per axis")
    quality: EnumProperty(
        name="Sampling", items=QUALITY_ITEMS, default="MEDIUM",
        description="How finely the light between faces and the shadows inside a face are sampled. "
                    "Higher is slower to build. Technical: Gauss quadrature points and visibility "
                    "samples of the form factors")
    tolerance: FloatProperty(
        name="Accuracy", default=1e-4, min=1e-8, max=0.5, precision=6,
        description="When to stop bouncing light: smaller is more accurate and slower. 1e-4 leaves "
                    "corners within about 0.1% of a converged bake; 1e-3 is about 2.4 times faster "
                    "to solve, its worst corner about 1.3% off. (Large Scenes (Hierarchy) uses it "
                    "too, to stop its solve; how finely it subdivides is its Refinement Threshold.) "
                    "Technical: solver tolerance, the fraction of the emitted power the unshot "
                    "light may still deliver")
    visibility: BoolProperty(
        name="Shadows", default=True,
        description="Objects block light. Off: much faster, but light passes through everything. "
                    "Technical: ray-cast visibility between faces")
    corner_gather: BoolProperty(
        name="Sharp Corners", default=True,
        description="Compute the light at every vertex with its own shadow rays: sharp contact "
                    "shadows, no light leaking under objects or behind lights. Costs about 30 ms a "
                    "frame on a 1,000-face room (most of a second on the first frame). With Large "
                    "Scenes (Hierarchy) every frame gathers anew and it is most of the frame (a "
                    "9,600-face room: about 15 s a frame instead of 2-4 s). Off: faster, vertices "
                    "take the smooth light of the face (or its piece). Technical: corner gather")
    reflecting_backs: BoolProperty(
        name="Two-Sided Open Surfaces", default=False,
        description="Open surfaces (a ground plane, a sheet, a wall without thickness, a mesh with "
                    "holes) reflect light from both sides, as Cycles' diffuse surfaces do; closed "
                    "meshes are the same either way. Off: an open surface reflects only from the "
                    "side its normals face, and light reaching its back is lost (the ground plane "
                    "under a model: 7% off Cycles one-sided, 2% two-sided). Costs a second element "
                    "per open face. Technical: the backs of open surfaces")
    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="CPU threads for the bake (0: all cores)")
    memory_limit_mb: IntProperty(
        name="Memory Limit (MB)", default=0, min=0, soft_max=1 << 20, subtype="UNSIGNED",
        description="The most memory a bake may plan to use. A bake that would need more is "
                    "refused at once, before anything is changed, with the amount it needs and "
                    "what to lower (Detail, faces, Sharp Corners). 0: automatic, 80% of the memory "
                    "free when the bake starts")
    method: EnumProperty(name="Method", items=METHOD_ITEMS, default="INCREMENTAL",
                         description="How each frame is solved")
    hierarchy_accuracy: FloatProperty(
        name="Refinement Threshold", default=DEFAULT_HIERARCHY_ACCURACY,
        min=HIERARCHY_ACCURACY_RANGE[0], max=HIERARCHY_ACCURACY_RANGE[1], soft_min=1e-5, soft_max=0.1,
        precision=5, step=0.01,
        description="How finely Large Scenes (Hierarchy) subdivides: where light passing between two "
                    "parts of the scene could carry more than this share of all the emitted light, "
                    "they are split into finer parts. Smaller is finer, slower and needs more "
                    "memory (a 61-face box: 0.01, 0.001, 0.0001 made 253, 1,114, 3,769 elements). "
                    "Used only by Large Scenes (Hierarchy). Technical: the hierarchy's accuracy, "
                    "the largest share of the emitted power one link may carry unrefined")
    use_scene_range: BoolProperty(name="Scene Frame Range", default=True,
                                  description="Bake the scene's frame range")
    frame_start: IntProperty(name="Start", default=1, min=0, max=9999)
    frame_end: IntProperty(name="End", default=250, min=0, max=9999)
    frame_step: IntProperty(
        name="Step", default=1, min=1, max=1000,
        description="Solve every n-th frame and blend the colours in between: n times faster, "
                    "but fast motion and moving shadows are blurred in time")
    collection: PointerProperty(
        name="Collection", type=bpy.types.Collection,
        description="Bake only this collection's objects (empty: the whole scene)")
    display_subdivision: IntProperty(
        name="Display Subdivision", default=0, min=0, max=MAX_DISPLAY_SUBDIVISION,
        description="Show the light's variation inside each face (Detail 1-3) on a 2^n x 2^n grid "
                    "per face: 4^n times the vertices to store and play back. Shown through a "
                    "bake-time copy of the mesh; your mesh is not modified. Technical: evaluates "
                    "the radiosity polynomial at the grid points")
    preview_material: BoolProperty(
        name="Preview Material", default=False,
        description="Show the baked colours as emission through a separate material set by the switch "
                    "modifier (your materials are not changed)")
    apply_to_materials: BoolProperty(
        name="Apply to Materials", default=False,
        description="Show the baked light in your own materials: the bake inserts a node group "
                    "\"Radiosity Light\" between each baked object's shader and its Material Output "
                    "(your colour and textures times the baked light, as emission; Factor 0 in the "
                    "group gives your shader back). Clear takes it out again. Technical: reads the "
                    "irradiance attribute \"Radiosity Light\" (H / pi)")
    live_preview: BoolProperty(
        name="Live Preview", default=False, update=_live_update,
        description="Update the light as you move objects, change lights or the frame. Keep scenes "
                    "small (Detail 0-1, Draft): the viewport waits for each update")
    live_refine_when_idle: BoolProperty(
        name="Refine When Idle", default=True,
        description="While you scrub or move things, show a quick approximate light (about 2.5 "
                    "times faster; light may leak at contacts), and finish the frame you stop on. "
                    "Off: every change is solved in full. Technical: previews solved to ten times "
                    "the tolerance without the corner gather, refined when idle; background mode "
                    "always solves in full")


class RadiosityObjectSettings(bpy.types.PropertyGroup):
    exclude: BoolProperty(name="Exclude", default=False,
                          description="Leave this object out of the radiosity bake")
    emission_multiplier: FloatProperty(
        name="Emission Multiplier", default=1.0, min=0.0, soft_max=100.0,
        description="Makes this object's emitting materials brighter or dimmer in the bake only "
                    "(your materials are not changed)")
    two_sided: BoolProperty(
        name="Two-Sided Emitter", default=False,
        description="Emitting faces of this object emit from their back too, as Cycles' mesh lights "
                    "do (by default a face emits from its front, the side its normal points to)")


classes = (RadiositySceneSettings, RadiosityObjectSettings)


def register_properties():
    bpy.types.Scene.radiosity = PointerProperty(type=RadiositySceneSettings)
    bpy.types.Object.radiosity = PointerProperty(type=RadiosityObjectSettings)


def unregister_properties():
    del bpy.types.Object.radiosity
    del bpy.types.Scene.radiosity
