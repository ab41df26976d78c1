"""Cancelling keeps complete frames only, and never a frame of the previous bake; bad scenes
give clear messages."""

import numpy as np
import pytest
import scenes


def _cancel_at(bake_module, frame_index):
    """A listener that cancels from the progress callback of the `frame_index`-th solved frame."""

    def listener(event):
        if event["kind"] == "progress" and event["index"] == frame_index:
            return False
        return None

    bake_module.listeners.append(listener)
    return listener


def _switch_range(obj):
    mod = obj.modifiers[-1]
    ids = {i.name: i.identifier for i in mod.node_group.interface.items_tree if i.in_out == "INPUT"}
    return mod[ids["First Frame"]], mod[ids["Last Frame"]]


def test_cancel_from_progress_keeps_complete_frames_only(blender):
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    _cancel_at(bake, 2)  # cancel inside the third frame
    scenes.bake(bpy, basis_order=0)
    for obj in objs.values():
        assert scenes.rad_frames(obj.data) == [1, 2]
        assert _switch_range(obj) == (1, 2)
    record = bake.read_record(bpy.context.scene)
    assert record.complete == (1, 2) and sorted(record.solved) == [1, 2]
    # Frames past the last complete one hold it.
    sc = bpy.context.scene
    sc.frame_set(4)
    got = scenes.corner_colors(objs["Floor"], bpy.context.evaluated_depsgraph_get())
    np.testing.assert_array_equal(got, scenes.stored(objs["Floor"].data, 2))


def _snapshot(bpy, objs):
    """Everything a bake leaves: each mesh's Rad_ frames and values, its other attribute names,
    each object's switch range, the copies, and the record."""
    from addon.blender import bake

    meshes = {}
    for obj in objs.values():
        me = obj.data
        meshes[obj.name] = {
            "attributes": sorted(a.name for a in me.color_attributes),
            "frames": {f: scenes.stored(me, f) for f in scenes.rad_frames(me)},
            "switch": _switch_range(obj) if obj.modifiers else None,
        }
    copies = sorted(o.name for o in bpy.data.objects if o.name.startswith("Radiosity Copy"))
    return meshes, copies, bpy.context.scene.get(bake.RECORD_PROPERTY)


def _assert_same(before, after):
    (m0, c0, r0), (m1, c1, r1) = before, after
    assert c1 == c0 and r1 == r0
    for name, b in m0.items():
        a = m1[name]
        assert a["attributes"] == b["attributes"], name  # no RadNew_ staging attribute is left
        assert a["switch"] == b["switch"], name
        assert sorted(a["frames"]) == sorted(b["frames"]), name
        for f, values in b["frames"].items():
            np.testing.assert_array_equal(a["frames"][f], values, err_msg=f"{name} frame {f}")


def _move_light_from_frame_2(objs):
    light = objs["Light"]
    light.animation_data_clear()
    for frame, x in ((1, -0.5), (2, -0.4), (4, 0.9)):
        light.location.x = x
        light.keyframe_insert("location", index=0, frame=frame)


def test_cancelled_rebake_keeps_the_previous_bake(blender):
    """Frames 2-4 change; the re-bake completes frame 2 and is cancelled inside frame 3: every
    frame of the previous bake is still there with its values, and it plays back."""
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    scenes.bake(bpy, basis_order=0)
    before = _snapshot(bpy, objs)
    assert sorted(before[0]["Floor"]["frames"]) == [1, 2, 3, 4]
    _move_light_from_frame_2(objs)
    solved = []
    bake.listeners.append(lambda e: solved.append(e["frame"]) if e["kind"] == "frame" else None)
    _cancel_at(bake, 1)
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    summary = job.run()
    assert solved == [2]  # frame 2 was recomputed (and differs), then thrown away
    assert "cancelled" in summary and "kept the previous bake (frames 1-4) unchanged" in summary
    _assert_same(before, _snapshot(bpy, objs))
    sc = bpy.context.scene
    for f in (2, 4):
        sc.frame_set(f)
        got = scenes.corner_colors(objs["Floor"], bpy.context.evaluated_depsgraph_get())
        np.testing.assert_array_equal(got, before[0]["Floor"]["frames"][f])
    # The next re-bake still finds the previous bake's frame 1 unchanged and keeps it.
    bake.listeners.clear()
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    job.run()
    assert job.kept == 1 and scenes.rad_frames(objs["Floor"].data) == [1, 2, 3, 4]
    assert not np.array_equal(scenes.stored(objs["Floor"].data, 2), before[0]["Floor"]["frames"][2])


def test_failed_rebake_keeps_the_previous_bake(blender):
    """A re-bake that recomputes frame 2 and then fails at frame 3 (the floor's subdivision is
    keyed to change its topology there) leaves the previous bake as it was."""
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    scenes.bake(bpy, basis_order=0)
    before = _snapshot(bpy, objs)
    _move_light_from_frame_2(objs)
    floor = objs["Floor"]
    mod = floor.modifiers.new("Subdiv", "SUBSURF")
    mod.subdivision_type = "SIMPLE"
    floor.modifiers.move(len(floor.modifiers) - 1, 0)  # before the switch, as an artist adds it
    for frame, levels in ((1, 0), (2, 0), (3, 1)):
        mod.levels = levels
        floor.keyframe_insert('modifiers["Subdiv"].levels', frame=frame)
    with pytest.raises(RuntimeError, match="changes its number of vertices or corners at frame 3"):
        bpy.ops.radiosity.bake()
    floor.modifiers.remove(mod)
    _assert_same(before, _snapshot(bpy, objs))


def test_cancelled_fresh_bake_over_a_previous_one_keeps_it(blender):
    """New settings (display subdivision 1: a bake-time copy) re-bake every frame; cancelled
    inside the second, the previous bake on the meshes is intact and no copy is left."""
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 3), box=False)
    scenes.bake(bpy, basis_order=0)
    before = _snapshot(bpy, objs)
    _cancel_at(bake, 1)
    scenes.bake(bpy, basis_order=0, display_subdivision=1)
    _assert_same(before, _snapshot(bpy, objs))
    assert not [m.name for m in bpy.data.meshes if m.name.startswith("Radiosity Copy")]
    # Uncancelled, the same bake moves the colours to the copies and off the meshes.
    bake.listeners.clear()
    scenes.bake(bpy, basis_order=0, display_subdivision=1)
    copy = bpy.data.meshes["Radiosity Copy: Floor"]
    assert scenes.rad_frames(copy) == [1, 2, 3] and scenes.rad_frames(objs["Floor"].data) == []
    assert not [o.name for o in bpy.data.objects if o.name.startswith("Radiosity Copy (baking)")]
    assert _switch_range(objs["Floor"]) == (1, 3)


def test_cancelled_longer_range_keeps_the_frames_it_added(blender):
    """A re-bake that keeps every frame of the previous bake and only adds frames after it (a
    longer range; headless chunks) replaces nothing, so its complete frames are kept."""
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    sc = bpy.context.scene
    sc.frame_end = 2
    scenes.bake(bpy, basis_order=0)
    before = {f: scenes.stored(objs["Floor"].data, f) for f in (1, 2)}
    sc.frame_end = 4
    _cancel_at(bake, 1)  # inside frame 4, after frame 3 completed
    scenes.bake(bpy, basis_order=0)
    assert scenes.rad_frames(objs["Floor"].data) == [1, 2, 3]
    for f in (1, 2):
        np.testing.assert_array_equal(scenes.stored(objs["Floor"].data, f), before[f])
    assert _switch_range(objs["Floor"]) == (1, 3)
    assert bake.read_record(sc).complete == (1, 3)


def test_successful_rebake_of_a_shorter_range_removes_the_frames_past_it(blender):
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 4), box=False)
    scenes.bake(bpy, basis_order=0)
    before = {f: scenes.stored(objs["Floor"].data, f) for f in (1, 2)}
    bpy.context.scene.frame_end = 2
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(bpy.context.scene))
    job.run()
    assert job.kept == 2 and job.done == 0
    for obj in objs.values():
        assert scenes.rad_frames(obj.data) == [1, 2]
        assert _switch_range(obj) == (1, 2)
    for f in (1, 2):
        np.testing.assert_array_equal(scenes.stored(objs["Floor"].data, f), before[f])
    assert bake.read_record(bpy.context.scene).complete == (1, 2)


def test_a_memory_limit_below_the_estimate_is_refused_in_one_line_and_changes_nothing(blender):
    """Memory Limit (MB) = 1 on a 217-face room that a bake estimates at several MB: the operator
    reports one line in the panel's words, and the previous bake is untouched; 0 (automatic)
    bakes it again."""
    bpy = blender
    objs = scenes.cornell_box(bpy, n=6, light_frames=(1, 2), box=False)
    assert scenes.bake(bpy, basis_order=0) == {"FINISHED"}
    before = _snapshot(bpy, objs)
    sc = bpy.context.scene
    sc.radiosity.memory_limit_mb = 1
    with pytest.raises(RuntimeError) as info:
        bpy.ops.radiosity.bake()
    line = str(info.value).strip()
    print(line)
    assert "\n" not in line
    assert "over the memory budget: this bake needs up to" in line
    assert "but the budget is 1 MB (Memory Limit (MB))" in line
    assert "a lower Detail" in line and "raise Memory Limit (MB)" in line
    assert "memory_budget_mb" not in line and "basis_order" not in line
    _assert_same(before, _snapshot(bpy, objs))
    sc.radiosity.memory_limit_mb = 0
    sc.radiosity.basis_order = 1
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    assert scenes.rad_frames(objs["Floor"].data) == [1, 2]


def test_cancel_before_any_frame_leaves_the_file_as_it_was(blender):
    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    _cancel_at(bake, 0)
    scenes.bake(bpy, basis_order=0)
    for obj in objs.values():
        assert scenes.rad_frames(obj.data) == []
        assert len(obj.modifiers) == 0
    assert "radiosity_bake" not in bpy.context.scene


def _job(bpy, **changes):
    from addon.blender import bake

    sc = bpy.context.scene
    settings = bake.settings_from_scene(sc).replace(**{"basis_order": 0, **changes})
    return bake.BakeJob(bpy.context, settings)


def _error(bpy, **changes):
    from addon.blender import bake

    with pytest.raises(bake.BakeError) as info:
        _job(bpy, **changes).run()
    return str(info.value)


def test_no_emitter(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    bpy.data.objects.remove(objs["Light"])
    assert "no emitters" in _error(bpy)


def test_no_mesh_objects(blender):
    bpy = blender
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    bpy.context.scene.collection.objects.link(light)
    msg = _error(bpy)
    assert "no visible, renderable mesh objects" in msg
    assert "Light objects are ignored" in msg and "Lamp" in msg
    # The operator reports the same message as an error.
    with pytest.raises(RuntimeError, match="no visible, renderable mesh objects"):
        bpy.ops.radiosity.bake()


def test_no_faces(blender):
    bpy = blender
    scenes.mesh_object(bpy, "Points", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [])
    assert "have no faces" in _error(bpy)


def test_a_diverging_solve_is_reported_and_changes_nothing(blender):
    """Three random triangles from the FFI property test, which cross, lit with visibility off:
    the kernel then passes on more light than it receives, and the solve says so and stops (it
    used to run for ever)."""
    bpy = blender
    vertices = [(-1.9812213, 0.77613264, -0.49970147), (0.52665615, -1.4438541, -1.6441722),
                (1.0218674, 0.2207829, 0.7339074), (-0.58700806, -0.49895608, -1.9490031),
                (1.3606553, -0.27369004, 0.76706606), (1.6043353, -1.7408254, -1.3136085)]
    first = scenes.material(bpy, "First", (0.506, 0.404, 0.0069), (0.887, 0.293, 1.0), 1.0)
    other = scenes.material(bpy, "Other", (0.310, 0.9946, 0.736), (1.0, 0.553, 0.362), 1.4)
    obj = scenes.mesh_object(bpy, "Crossing", vertices, [(1, 0, 2), (3, 5, 4), (4, 1, 3)], first)
    obj.data.materials.append(other)
    for poly, m in zip(obj.data.polygons, (0, 1, 1), strict=True):
        poly.material_index = m
    msg = _error(bpy, basis_order=2, visibility=False, frame_start=1, frame_end=1)
    assert "the solution diverges" in msg and "visibility" in msg
    assert scenes.rad_frames(obj.data) == [] and len(obj.modifiers) == 0
    assert "radiosity_bake" not in bpy.context.scene
    # With visibility on, the same triangles solve.
    _job(bpy, basis_order=2, visibility=True, frame_start=1, frame_end=1).run()
    assert scenes.rad_frames(obj.data) == [1]


def test_frame_outside_the_attribute_range(blender):
    bpy = blender
    scenes.cornell_box(bpy, light_frames=(1, 2), box=False)
    assert "outside 0..9999" in _error(bpy, frame_start=10000, frame_end=10001)


def test_zero_area_faces_non_meshes_and_unreadable_materials_are_reported(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, light_frames=(1, 1), box=False)
    # A zero-area triangle (three collinear vertices) in its own object.
    scenes.mesh_object(bpy, "Sliver", [(0, 0, 0.5), (0.5, 0, 0.5), (1, 0, 0.5), (0, 0.5, 0.5)],
                       [(0, 1, 2), (0, 2, 3)], bpy.data.materials["White"])
    # A curve object, a textured material, a glass material, and no material.
    curve = bpy.data.objects.new("Curve", bpy.data.curves.new("Curve", "CURVE"))
    bpy.context.scene.collection.objects.link(curve)
    tex = scenes.material(bpy, "Wood")
    nt = tex.node_tree
    nt.links.new(nt.nodes.new("ShaderNodeTexImage").outputs["Color"],
                 nt.nodes["Principled BSDF"].inputs["Base Color"])
    objs["Back"].data.materials[0] = tex
    glass = bpy.data.materials.new("Glass")
    if bpy.app.version < (5, 0, 0):
        glass.use_nodes = True
    gnt = glass.node_tree
    out = gnt.nodes.get("Material Output") or gnt.nodes.new("ShaderNodeOutputMaterial")
    gnt.links.new(gnt.nodes.new("ShaderNodeBsdfGlass").outputs[0], out.inputs["Surface"])
    objs["Front"].data.materials[0] = glass
    objs["Right"].data.materials.clear()
    job = _job(bpy)
    job.run()
    text = "\n".join(job.warnings)
    assert "1 zero-area face(s)" in text and "Sliver (1)" in text
    assert "Curve (CURVE)" in text
    line = next(w for w in job.warnings if w.startswith("Materials not fully read"))
    assert "Wood (Base Color is linked to Image Texture without an image, not read)" in line
    assert "Glass (shader Glass BSDF is not read)" in line
    assert "<no material> on Right (no material)" in line
    assert "0.8 grey" in line
    # The unreadable Back wall used the default grey and still got colours.
    assert scenes.stored(objs["Back"].data, 1).min() > 0


def test_worker_thread_solve_and_cancel_from_the_main_thread(blender):
    """What the modal operator does: solve on a worker thread, cancel with Session.cancel()
    from the main thread (Esc), then finish with complete frames only."""
    import threading

    bpy = blender
    from addon.blender import bake

    objs = scenes.cornell_box(bpy, n=6, light_frames=(1, 3), box=True)
    job = _job(bpy, basis_order=2, quality="HIGH")
    job.start()
    b = bake.binding()
    outcome = []

    def solve():
        try:
            job.solve()
        except b.Cancelled as e:
            outcome.append(e)

    # Frame 1 on a worker thread, committed on the main thread.
    job.prepare()
    worker = threading.Thread(target=solve)
    worker.start()
    worker.join()
    assert outcome == []
    job.commit()
    # Frame 2: cancelled from the main thread once the worker reports progress.
    started = threading.Event()
    bake.listeners.append(lambda e: started.set() if e["kind"] == "progress" else None)
    job.prepare()
    worker = threading.Thread(target=solve)
    worker.start()
    assert started.wait(30)
    job.cancel()
    worker.join(30)
    assert not worker.is_alive()
    if outcome:  # else the frame finished before the cancel arrived; it is then complete
        assert isinstance(outcome[0], b.Cancelled)
        job.cancelled = True
    else:
        job.commit()
    job.finish()
    print("cancelled inside the frame:", bool(outcome))
    expected = [1] if outcome else [1, 2]
    assert scenes.rad_frames(objs["Floor"].data) == expected
    assert "cancelled" in job.summary


class _FakeWM:
    def progress_begin(self, *a):
        pass

    def progress_update(self, value):
        self.last = value

    def progress_end(self):
        pass

    def event_timer_remove(self, timer):
        pass


class _FakeWorkspace:
    def __init__(self):
        self.texts = []

    def status_text_set(self, text):
        self.texts.append(text)


def _modal_harness(bpy):
    """The modal operator's methods on a stand-in instance (an event loop cannot run headless)."""
    from addon.operators import RADIOSITY_OT_bake as Op

    class Harness:
        _begin_frame = Op._begin_frame
        _solve = Op._solve
        _end = Op._end
        _report_end = Op._report_end
        _make_job = Op._make_job
        modal = Op.modal
        _timer = None
        _thread = None

        def __init__(self):
            self.reports = []

        def report(self, kind, text):
            self.reports.append((set(kind), text))

    class Ctx:
        scene = bpy.context.scene
        view_layer = bpy.context.view_layer
        window_manager = _FakeWM()
        workspace = _FakeWorkspace()

        def evaluated_depsgraph_get(self):
            return bpy.context.evaluated_depsgraph_get()

    return Harness(), Ctx()


class _Event:
    def __init__(self, type, value="NOTHING"):
        self.type, self.value = type, value


def test_modal_operator_polls_the_worker_and_esc_keeps_complete_frames(blender):
    import time

    bpy = blender
    objs = scenes.cornell_box(bpy, n=4, light_frames=(1, 4), box=True)
    bpy.context.scene.radiosity.basis_order = 1
    op, ctx = _modal_harness(bpy)
    op._job = op._make_job(ctx, verbose=False)
    op._job.start()
    assert op._begin_frame(ctx)
    result = {"RUNNING_MODAL"}
    sent_esc = False
    deadline = time.time() + 60
    while result == {"RUNNING_MODAL"} and time.time() < deadline:
        if op._job.done == 2 and not sent_esc:
            result = op.modal(ctx, _Event("ESC", "PRESS"))
            sent_esc = True
            continue
        result = op.modal(ctx, _Event("TIMER"))
        time.sleep(0.01)
    assert result == {"FINISHED"}
    # Esc came while frame 3 was solving: it is cancelled, or kept if it completed first.
    frames = scenes.rad_frames(objs["Floor"].data)
    assert frames in ([1, 2], [1, 2, 3])
    assert _switch_range(objs["Floor"]) == (1, frames[-1])
    assert any("Esc: cancel" in (t or "") for t in ctx.workspace.texts)
    assert ctx.workspace.texts[-1] is None  # the status line is cleared
    assert any("cancelled" in text for kinds, text in op.reports if "INFO" in kinds)


def test_modal_operator_runs_to_the_end(blender):
    import time

    bpy = blender
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 3), box=False)
    bpy.context.scene.radiosity.basis_order = 0
    op, ctx = _modal_harness(bpy)
    op._job = op._make_job(ctx, verbose=False)
    op._job.start()
    assert op._begin_frame(ctx)
    result = {"RUNNING_MODAL"}
    deadline = time.time() + 60
    while result == {"RUNNING_MODAL"} and time.time() < deadline:
        result = op.modal(ctx, _Event("TIMER"))
        time.sleep(0.01)
    assert result == {"FINISHED"}
    assert scenes.rad_frames(objs["Floor"].data) == [1, 2, 3]
    assert ctx.window_manager.last > 0
