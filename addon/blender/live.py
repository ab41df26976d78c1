"""Live preview: while it is on, every frame change and every depsgraph update that moves an
object or changes a material re-solves the current frame incrementally, in the held session
(``set_object_matrix`` / ``set_material_emission`` + ``solve_frame``), and writes the result
into each object's ``Radiosity`` attribute. The solve runs on the main thread (it blocks the UI
for its duration: keep live scenes small, or use a low basis order and Draft quality).

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
stats = {"solves": 0, "last_seconds": 0.0, "last_error": None}


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


def _update(scene) -> bool:
    view_layer = bpy.context.view_layer
    if view_layer is None or bpy.context.scene != scene:
        view_layer = scene.view_layers[0]
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
    if rest is None or [o.data.name for o in rest.objects] != names:
        rest = export(dg, sel.objects)
        key = _scene_key(scene, rest)
        if h is None or h.scene_key != key:
            _, e = rest.materials.arrays()
            if not (e > 0).any():
                raise bake.BakeError("no emitters in the scene")
            bake.drop_held(scene)
            smp = sample(dg, rest, sel.objects)
            h = bake.new_session(bake.settings_from_scene(scene), rest, smp.state(rest), key)
            bake._held[bake.scene_id(scene)] = h
            h.frame = None
    smp = sample(dg, rest, sel.objects)
    state = smp.state(rest)
    if state.geometry != h.state.geometry:
        rest = export(dg, sel.objects)
        h.close()
        h = bake.new_session(bake.settings_from_scene(scene), rest, state, _scene_key(scene, rest))
        bake._held[bake.scene_id(scene)] = h
    frame = float(scene.frame_current)
    if h.frame == frame and state == h.state:
        return False
    bake.apply_sample(h, smp, state)
    t = time.perf_counter()
    h.session.solve_frame(frame, progress=lambda fraction, stage: True)
    h.frame = frame
    stats["solves"] += 1
    stats["last_seconds"] = time.perf_counter() - t
    stats["last_error"] = None
    for i, (o, obj) in enumerate(zip(rest.objects, sel.objects, strict=True)):
        mesh = obj.data
        if not o.original_topology or mesh.library is not None or len(mesh.loops) != o.data.loop_count:
            continue
        rgb = radiance_from_radiosity(o.data.split.to_loops(h.session.corner_radiosity(i)))
        attributes.ensure_result(mesh, rgb)
        switch.set_muted(obj, True)
    return True


@persistent
def on_frame_change(scene, depsgraph=None):
    update(scene, depsgraph)


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy or bake.running or not scene.radiosity.live_preview:
        return
    relevant = any(u.is_updated_transform or isinstance(u.id, bpy.types.Material) for u in depsgraph.updates)
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
    if scene is not None:
        for obj in scene.objects:
            switch.set_muted(obj, False)


