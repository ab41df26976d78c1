"""Live preview: while it is on, every frame change and every depsgraph update that moves an
object or a Light, or changes a material, a Light's data or the World, re-solves the current
frame incrementally, in the held session (``set_object_matrix`` / ``set_material_emission`` /
``set_lights`` / ``set_world`` + ``solve_frame``, as a bake hands them over), and writes the
result into each object's ``Radiosity`` attribute. The solve runs on the main thread (it blocks the UI
for its duration: keep live scenes small, or use a low basis order and Draft quality).

With "Refine When Idle" (the default) a frame change solves a *preview* of the frame: to ten
times the tolerance (at most 1e-3) and without the corner gather (the corners show the face
polynomials, the Galerkin solution itself). Once no frame change or move has come for
``IDLE_SECONDS``, a timer refines the frame the timeline rests on: the rest of its solve, then its
gather. Scrubbing pays the kernel update and a shorter solve; the resting frame gets what a bake
gives. This needs the UI's event loop, which runs the timer; in background mode (``blender -b``)
every frame is solved in full at once. With Large Scenes (Hierarchy) the library refines a preview
as an update in which nothing moved: its solve to the tolerance, then its gather.

The baked switch is muted in the viewport while the preview is on, so the viewport shows the
live attribute; turning the preview off un-mutes it. Objects whose colours need a copy (display
subdivision, topology-changing modifiers) are not previewed.
"""

from __future__ import annotations

import time

import bpy
from bpy.app.handlers import persistent

from ..core.materials import radiance_from_radiosity
from . import attributes, bake, switch
from .export import TopologyChanged, collect, export, sample

_busy = False
stats = {"solves": 0, "last_seconds": 0.0, "last_error": None, "refinements": 0}

# The timeline rests once no frame change or move came for this long: then the preview is refined.
IDLE_SECONDS = 0.25

# The scene whose frame waits for its refinement (the timer reads it).
_pending_scene: str | None = None


def _timers_run() -> bool:
    """Whether ``bpy.app.timers`` fire: they need the UI's event loop (not ``blender -b``)."""
    return not bpy.app.background


def _collection(scene):
    return scene.radiosity.collection


def _scene_key(scene, exp) -> str:
    return bake.session_key(bake.settings_from_scene(scene), exp)


def update(scene, depsgraph=None) -> bool:
    """Re-solves the current frame if anything the solver sees changed; True if it solved."""
    global _busy
    if _busy or bake.running or not scene.radiosity.live_preview:
        return False
    _busy = True
    try:
        return _update(scene)
    except ReferenceError:
        bake.drop_held(scene)  # objects the held session knew were freed (undo): start over
        return False
    except (bake.BakeError, TopologyChanged, bake.binding().RadiosityError) as e:
        stats["last_error"] = str(e)
        print(f"Radiosity live preview: {e}")
        return False
    finally:
        _busy = False


def _view_layer(scene):
    """The view layer the preview collects from: the context's for the active scene."""
    view_layer = getattr(bpy.context, "view_layer", None)  # (a timer's context may have none)
    if view_layer is None or bpy.context.scene != scene:
        view_layer = scene.view_layers[0]
    return view_layer


def _update(scene) -> bool:
    view_layer = _view_layer(scene)
    if bpy.context.scene == scene:
        dg = bpy.context.evaluated_depsgraph_get()
    else:
        dg = scene.view_layers[0].depsgraph
    sel = collect(scene, view_layer, _collection(scene))
    if not sel.objects:
        return False
    h = bake.held(scene)
    rest = h.export if h is not None else None
    names = [o.name for o in sel.objects]
    lights = [o.name for o in sel.light_objects]
    if (rest is None or [o.data.name for o in rest.objects] != names
            or [o.name for o in rest.light_objects] != lights):
        rest = export(dg, sel.objects, sel.light_objects)
        key = _scene_key(scene, rest)
        if h is None or h.scene_key != key:
            _, e = rest.materials.arrays()
            if not (e > 0).any() and not rest.light_objects and rest.world.strength == 0.0:
                raise bake.BakeError("no emitters in the scene (no emissive material, Light or World)")
            bake.drop_held(scene)
            smp = sample(dg, rest, sel.objects)
            h = bake.new_session(bake.settings_from_scene(scene), rest, smp.state(rest), key, animated=True)
            bake._held[bake.scene_id(scene)] = h
            h.frame = None
        else:
            h.export = rest  # the same meshes; its lights are handed over with each sample
    smp = sample(dg, rest, sel.objects)
    state = smp.state(rest)
    if state.geometry != h.state.geometry:
        rest = export(dg, sel.objects, sel.light_objects, rest=rest)
        h.close()
        key = _scene_key(scene, rest)
        h = bake.new_session(bake.settings_from_scene(scene), rest, state, key, animated=True)
        bake._held[bake.scene_id(scene)] = h
    frame = float(scene.frame_current)
    if h.frame == frame and state == h.state:
        return False
    bake.apply_sample(h, smp, state)
    preview = scene.radiosity.live_refine_when_idle and _timers_run()
    t = time.perf_counter()
    # Previews are switched on for this solve only: the held session also serves bakes.
    h.session.set_preview(preview)
    try:
        h.session.solve_frame(frame, progress=lambda fraction, stage: True)
    finally:
        h.session.set_preview(False)
    h.frame = frame
    stats["solves"] += 1
    stats["last_seconds"] = time.perf_counter() - t
    stats["last_error"] = None
    _write_corners(h, rest, sel.objects)
    if preview:
        _refine_when_idle(scene)
    return True


def _write_corners(h, rest, objects) -> None:
    """Writes the held session's corners into each previewed object's ``Radiosity`` and
    ``Radiosity Light`` attributes."""
    for i, (o, obj) in enumerate(zip(rest.objects, objects, strict=True)):
        mesh = obj.data
        if not o.original_topology or mesh.library is not None or len(mesh.loops) != o.data.loop_count:
            continue
        rgb = radiance_from_radiosity(o.data.split.to_loops(h.session.corner_radiosity(i)))
        light = radiance_from_radiosity(o.data.split.to_loops(h.session.corner_irradiance(i)))
        attributes.ensure_result(mesh, rgb, light)
        switch.set_muted(obj, True)


def _refine_when_idle(scene) -> None:
    """(Re)arms the one-shot timer that refines ``scene``'s frame once the timeline rests."""
    global _pending_scene
    _pending_scene = scene.name
    if bpy.app.timers.is_registered(on_idle):
        bpy.app.timers.unregister(on_idle)
    bpy.app.timers.register(on_idle, first_interval=IDLE_SECONDS)


def on_idle():
    """The timer: refines the pending scene's frame (``refine``); one-shot (None)."""
    global _pending_scene
    name, _pending_scene = _pending_scene, None
    scene = bpy.data.scenes.get(name) if name is not None else None
    if scene is not None:
        refine(scene)
    return None


def refine(scene) -> bool:
    """Refines the frame the live preview solved as a preview (the rest of its solve, its corner
    gather) and writes its corners; True if it refined. Nothing to do when the frame is refined
    already, or the preview is off."""
    global _busy
    if _busy or bake.running or not scene.radiosity.live_preview:
        return False
    h = bake.held(scene)
    if h is None or h.export is None or h.frame is None:
        return False
    _busy = True
    try:
        sel = collect(scene, _view_layer(scene), _collection(scene))
        if [o.name for o in sel.objects] != [o.data.name for o in h.export.objects]:
            return False  # the previewed objects changed: the next update starts over
        if h.session.refine(progress=lambda fraction, stage: True) is None:
            return False
        stats["refinements"] += 1
        _write_corners(h, h.export, sel.objects)
        return True
    except ReferenceError:
        bake.drop_held(scene)
        return False
    except bake.binding().RadiosityError as e:
        stats["last_error"] = str(e)
        print(f"Radiosity live preview: {e}")
        return False
    finally:
        _busy = False


@persistent
def on_frame_change(scene, depsgraph=None):
    update(scene, depsgraph)


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy or bake.running or not scene.radiosity.live_preview:
        return
    watched = (bpy.types.Material, bpy.types.Light, bpy.types.World)
    relevant = any(u.is_updated_transform or isinstance(u.id, watched) for u in depsgraph.updates)
    if relevant:
        update(scene, depsgraph)


def enable(scene) -> None:
    handlers = bpy.app.handlers
    if on_frame_change not in handlers.frame_change_post:
        handlers.frame_change_post.append(on_frame_change)
    if on_depsgraph_update not in handlers.depsgraph_update_post:
        handlers.depsgraph_update_post.append(on_depsgraph_update)
    update(scene)


def disable(scene=None) -> None:
    handlers = bpy.app.handlers
    if any(s.radiosity.live_preview for s in bpy.data.scenes):
        return  # another scene still previews
    for lst, fn in ((handlers.frame_change_post, on_frame_change),
                    (handlers.depsgraph_update_post, on_depsgraph_update)):
        while fn in lst:
            lst.remove(fn)
    if bpy.app.timers.is_registered(on_idle):
        bpy.app.timers.unregister(on_idle)
    if scene is not None:
        for obj in scene.objects:
            switch.set_muted(obj, False)


