"""Tweak and re-bake (only from the first changed frame, reusing the held session), and the
live preview driven by depsgraph and frame-change handlers."""

import numpy as np
import pytest
import scenes


def _room_with_box_keys(bpy):
    """Cornell box over frames 1-4 whose box has keys at 1, 2 and 4 (linear)."""
    objs = scenes.cornell_box(bpy, light_frames=(1, 4), light_x=(-0.5, 0.5))
    box = objs["Box"]
    sc = bpy.context.scene
    sc.frame_set(2)
    box.keyframe_insert("location", index=1, frame=2)
    scenes._linear(box)
    sc.frame_set(1)
    return objs


def _set_box_key(bpy, box, frame, y):
    sc = bpy.context.scene
    sc.frame_set(frame)
    box.location.y = y
    box.keyframe_insert("location", index=1, frame=frame)
    scenes._linear(box)
    sc.frame_set(1)


def test_rebake_recomputes_from_the_first_changed_frame_only(blender):
    bpy = blender
    from addon.blender import bake

    objs = _room_with_box_keys(bpy)
    floor = objs["Floor"].data
    settings = dict(basis_order=1)
    assert scenes.bake(bpy, **settings) == {"FINISHED"}
    before = {f: scenes.stored(floor, f) for f in (1, 2, 3, 4)}
    session = bake.held(bpy.context.scene).session

    solved = []
    bake.listeners.append(lambda e: solved.append(e["frame"]) if e["kind"] == "frame" else None)
    # Nothing changed: nothing is solved, everything is kept.
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    summary = job.run()
    assert solved == [] and job.kept == 4 and "kept 4 unchanged" in summary

    # Move the box's last key: frames 3 and 4 change, 1 and 2 do not.
    _set_box_key(bpy, objs["Box"], 4, -0.6)
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    summary = job.run()
    assert solved == [3, 4]
    assert job.kept == 2 and "kept 2 unchanged solved frame(s), saving about" in summary
    assert bake.held(bpy.context.scene).session is session  # the held session was reused
    for f in (1, 2):
        np.testing.assert_array_equal(scenes.stored(floor, f), before[f])
    assert not np.allclose(scenes.stored(floor, 4), before[4])
    rebaked = {f: scenes.stored(floor, f) for f in (3, 4)}

    # The incremental re-bake agrees with a bake from scratch.
    bpy.ops.radiosity.clear()
    assert scenes.bake(bpy, **settings) == {"FINISHED"}
    for f in (3, 4):
        np.testing.assert_allclose(rebaked[f], scenes.stored(floor, f), rtol=0.02, atol=1e-3)


def test_operator_reports_time_saved(blender, capfd):
    bpy = blender
    objs = _room_with_box_keys(bpy)
    scenes.bake(bpy, basis_order=0)
    _set_box_key(bpy, objs["Box"], 4, -0.6)
    scenes.bake(bpy, basis_order=0)
    out = capfd.readouterr().out
    assert "kept 2 unchanged solved frame(s), saving about" in out


def test_changed_settings_rebake_everything(blender):
    bpy = blender
    from addon.blender import bake

    scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    scenes.bake(bpy, basis_order=0)
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene).replace(basis_order=1))
    job.run()
    assert job.kept == 0 and job.done == 2


def _live_values(obj):
    return scenes.stored_named(obj.data, "Radiosity")


def test_live_preview_follows_moves_and_frame_changes(blender):
    bpy = blender
    from addon.blender import bake, live

    objs = scenes.cornell_box(bpy, light_frames=(1, 3), box=False)
    sc = bpy.context.scene
    sc.radiosity.basis_order = 1
    scenes.bake(bpy)  # a bake to compare against; the live preview reuses its session
    baked3 = scenes.stored(objs["Floor"].data, 3)
    session = bake.held(sc).session
    solves = live.stats["solves"]

    sc.radiosity.live_preview = True  # solves the current frame (1)
    assert live.stats["solves"] == solves + 1
    assert bake.held(sc).session is session
    floor = objs["Floor"]
    np.testing.assert_allclose(_live_values(floor), scenes.stored(floor.data, 1), rtol=0.02, atol=1e-3)
    assert not floor.modifiers[-1].show_viewport  # the baked switch stands aside

    # Frame change: the handler re-solves frame 3, which matches the baked frame 3.
    sc.frame_set(3)
    assert live.stats["solves"] == solves + 2
    np.testing.assert_allclose(_live_values(floor), baked3, rtol=0.02, atol=1e-3)

    # Moving the light by hand (a depsgraph update) re-solves too: the bright side follows it.
    light = objs["Light"]
    light.location.x = -0.7
    bpy.context.view_layer.update()
    assert live.stats["solves"] == solves + 3
    c = _live_values(floor)
    me = floor.data
    x = np.array([me.vertices[lp.vertex_index].co.x for lp in me.loops])
    assert c[x < -0.01].mean() > 1.2 * c[x > 0.01].mean()

    # An update that changes nothing the solver sees does not re-solve.
    bpy.context.view_layer.update()
    assert live.stats["solves"] == solves + 3

    sc.radiosity.live_preview = False
    assert live.on_frame_change not in bpy.app.handlers.frame_change_post
    assert live.on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post
    assert floor.modifiers[-1].show_viewport


def test_live_preview_refines_when_the_timeline_rests(blender, monkeypatch):
    """With "Refine When Idle", a frame change shows a preview (a looser solve, the face
    polynomials at the corners) and arms a one-shot timer; the timer refines the frame the
    timeline rests on, which then shows what a preview solving in full shows. A bake after a
    preview frame still solves every frame in full. Background mode fires no timers (and so
    solves in full at once): here the preview is told timers run, and the timer's callback is
    called as the UI's event loop would call it."""
    bpy = blender
    from addon.blender import bake, live

    objs = scenes.cornell_box(bpy, light_frames=(1, 3))
    floor, sc = objs["Floor"], bpy.context.scene
    sc.radiosity.basis_order = 1
    sc.radiosity.tolerance = 1e-7  # two shooting paths to it agree far closer than checked
    sc.radiosity.live_refine_when_idle = True

    def frames_1_2_3():
        """A new held session previewing frames 1, 2, 3."""
        sc.frame_set(1)
        bake.drop_held(sc)
        sc.radiosity.live_preview = True
        if bpy.app.timers.is_registered(live.on_idle):
            live.on_idle()  # frame 1 rests before the scrub
        sc.frame_set(2)
        sc.frame_set(3)

    frames_1_2_3()  # background mode: solved in full at once
    assert not bpy.app.timers.is_registered(live.on_idle)
    full3 = _live_values(floor)
    sc.radiosity.live_preview = False

    refinements = live.stats["refinements"]
    with monkeypatch.context() as m:
        m.setattr(live, "_timers_run", lambda: True)
        frames_1_2_3()
        assert live.stats["refinements"] == refinements + 1  # frame 1
        assert bpy.app.timers.is_registered(live.on_idle)
        preview3 = _live_values(floor)
        # The polynomials light the floor under the box; the gather does not.
        assert np.abs(preview3 - full3).max() > 0.05 * full3.max()

        assert live.on_idle() is None  # one-shot
        assert live.stats["refinements"] == refinements + 2
        np.testing.assert_allclose(_live_values(floor), full3, rtol=1e-5, atol=1e-6)
        live.on_idle()  # nothing pending: nothing refined
        assert live.stats["refinements"] == refinements + 2

        sc.frame_set(2)  # a preview again; the live preview turned off before the timer fires
        sc.radiosity.live_preview = False
    assert not bpy.app.timers.is_registered(live.on_idle)
    scenes.bake(bpy)  # reuses the held session, which solves every frame it bakes in full
    np.testing.assert_allclose(scenes.stored(floor.data, 3), full3, rtol=0.02, atol=1e-3)
    assert live.stats["refinements"] == refinements + 2


def test_live_preview_without_a_bake(blender):
    bpy = blender
    from addon.blender import live

    objs = scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    sc = bpy.context.scene
    sc.radiosity.basis_order = 0
    sc.radiosity.live_preview = True
    assert live.stats["last_error"] is None
    assert _live_values(objs["Floor"]).min() > 0
    assert objs["Floor"].data.color_attributes.active_color_name == "Radiosity"
    sc.radiosity.live_preview = False


@pytest.fixture(autouse=True)
def _live_off(blender):
    yield
    sc = blender.context.scene
    if sc is not None and sc.radiosity.live_preview:
        sc.radiosity.live_preview = False
