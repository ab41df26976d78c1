"""Method > Large Scenes (Hierarchy) through the add-on: the bake operator on the hierarchical
method, its Refinement Threshold, the panel settings it reads, the live preview's refinement, and
the hint a flat bake too large for memory gives."""

import numpy as np
import pytest
import scenes

FRAMES = (1, 2, 3)


def _means(objs, frames=FRAMES):
    """Per object and frame, the mean stored radiance over corners and channels."""
    return {(name, f): float(scenes.stored(o.data, f).mean()) for name, o in objs.items() for f in frames}


def _stats(bpy):
    from addon.blender import bake

    return bake.held(bpy.context.scene).session.frame_stats()


def _worst(a, b):
    """The largest relative difference of ``a``'s means from ``b``'s."""
    return max(abs(a[k] / b[k] - 1.0) for k in b if b[k] > 1e-6)


def test_hierarchical_bake_writes_every_frame_and_agrees_with_the_flat_bake(blender):
    """The 61-face Cornell box with a moving light and box, Detail 2, Medium, Sharp Corners on:
    every object gets both attributes for every frame, finite and not negative, ``Rad`` is rho
    times ``Irr`` off the emitters, and the
    per-object means are within 4% of the flat Update's (measured: 2.2% worst, the ceiling at
    frame 1, both gathers splitting an emitter's rectangles in a penumbra,
    ``tests/penumbra.rs``; 4.5% while only the flat gather split them; the light's own faces
    equal)."""
    bpy = blender
    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 3))
    assert scenes.bake(bpy, method="INCREMENTAL") == {"FINISHED"}
    flat = _means(objs)
    flat_stats = _stats(bpy)
    assert scenes.bake(bpy, method="HIERARCHICAL") == {"FINISHED"}
    stats = _stats(bpy)
    for name, o in objs.items():
        assert scenes.rad_frames(o.data) == list(FRAMES), name
        for f in FRAMES:
            for prefix in ("Rad", "Irr"):
                v = scenes.stored_named(o.data, f"{prefix}_{f:04d}")
                assert np.isfinite(v).all() and (v >= 0).all(), (name, f, prefix)
    # The light received, H / pi, is what the colour is made of: B = rho H off the emitters.
    for name, rho in (("Floor", 0.7), ("Left", np.array([0.7, 0.1, 0.1]))):
        b, h = (scenes.stored_named(objs[name].data, f"{p}_0002") for p in ("Rad", "Irr"))
        assert np.abs(b - rho * h).max() < 1e-5 * b.max(), name
    hier = _means(objs)
    assert _worst(hier, flat) < 0.04, sorted((abs(hier[k] / flat[k] - 1), k) for k in flat)[-3:]
    assert hier[("Light", 3)] == pytest.approx(flat[("Light", 3)], rel=1e-5)
    # Its own solve: more elements than faces (it refined below them), a later frame updated.
    assert stats["elements"] > 10 * flat_stats["elements"]
    assert not stats["full_rebuild"]
    # The switch plays it back like any bake.
    floor = objs["Floor"]
    bpy.context.scene.frame_set(2)
    played = scenes.corner_colors(floor, bpy.context.evaluated_depsgraph_get())
    np.testing.assert_allclose(played, scenes.stored(floor.data, 2), rtol=1e-6)


def test_a_smaller_refinement_threshold_refines_more_and_moves_toward_the_finer_result(blender):
    """Refinement Threshold 0.01, 0.001, 0.0001 on frame 1 of the same box: the elements and
    links grow (measured 253, 1,114, 3,769 elements; 1,488, 4,634, 21,801 links), and 0.001 is
    nearer 0.0001's result than 0.01 is (per-object means measured 1.25% and 2.5% apart at
    worst)."""
    bpy = blender
    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 3))
    p = bpy.context.scene.radiosity
    p.use_scene_range, p.frame_start, p.frame_end = False, 1, 1
    runs = {}
    for threshold in (1e-2, 1e-3, 1e-4):
        assert scenes.bake(bpy, method="HIERARCHICAL", hierarchy_accuracy=threshold) == {"FINISHED"}
        runs[threshold] = (_means(objs, (1,)), _stats(bpy))
    elements = [runs[t][1]["elements"] for t in (1e-2, 1e-3, 1e-4)]
    links = [runs[t][1]["pairs"] for t in (1e-2, 1e-3, 1e-4)]
    assert elements[0] < elements[1] < elements[2], elements
    assert links[0] < links[1] < links[2], links
    fine = runs[1e-4][0]
    assert _worst(runs[1e-3][0], fine) < 0.75 * _worst(runs[1e-2][0], fine)
    assert _worst(runs[1e-2][0], fine) > 0.005  # the threshold did change the picture


def test_every_panel_setting_reaches_a_hierarchical_bake(blender):
    """The settings of the panel that the flat methods read are read by the hierarchy too, none
    silently dropped: Detail, Sampling, Accuracy, Shadows and Sharp Corners each change frame 1;
    Display Subdivision bakes the polynomials inside the faces onto a copy; Step interpolates."""
    bpy = blender
    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 3))
    p = bpy.context.scene.radiosity
    p.method, p.quality, p.basis_order = "HIERARCHICAL", "DRAFT", 1
    p.use_scene_range, p.frame_start, p.frame_end = False, 1, 1
    floor = objs["Floor"]

    def floor_1(**props):
        assert scenes.bake(bpy, **props) == {"FINISHED"}
        return scenes.stored(floor.data, 1)

    base = floor_1()
    for name, value, back in (("basis_order", 2, 1), ("quality", "HIGH", "DRAFT"), ("tolerance", 0.05, 1e-4),
                              ("visibility", False, True), ("corner_gather", False, True)):
        changed = floor_1(**{name: value})
        assert np.abs(changed - base).max() > 1e-4 * base.max(), name
        np.testing.assert_allclose(floor_1(**{name: back}), base, rtol=1e-5, atol=1e-7, err_msg=name)

    # Display Subdivision: a copy of 4 x 4 corners per face, the leaves' light inside the faces.
    p.corner_gather = False
    assert scenes.bake(bpy, display_subdivision=1) == {"FINISHED"}
    copy = bpy.data.objects["Radiosity Copy: Floor"].data
    v = scenes.stored(copy, 1)
    assert len(copy.polygons) == 4 * len(floor.data.polygons)
    assert np.isfinite(v).all() and v.min() >= 0 and v.std() > 0.01 * v.mean()

    # Step 2 over frames 1-3: frame 2 is the mean of the solved frames 1 and 3.
    p.display_subdivision, p.frame_end, p.frame_step = 0, 3, 2
    assert scenes.bake(bpy) == {"FINISHED"}
    f1, f2, f3 = (scenes.stored(floor.data, f) for f in FRAMES)
    np.testing.assert_allclose(f2, 0.5 * (f1 + f3), rtol=1e-5, atol=1e-7)


def test_live_preview_on_the_hierarchy_refines_the_resting_frame(blender, monkeypatch):
    """The live preview on the hierarchy shows the leaves while the timeline moves and, once it
    rests, the library's refinement of the frame (an update in which nothing moved: its solve to
    the tolerance, then its gather): what a frame solved without previews shows."""
    bpy = blender
    from addon.blender import bake, live

    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 3))
    floor, sc = objs["Floor"], bpy.context.scene
    p = sc.radiosity
    p.method, p.basis_order, p.tolerance, p.live_refine_when_idle = "HIERARCHICAL", 1, 1e-7, True

    def scrub_to_3():
        sc.frame_set(1)
        bake.drop_held(sc)
        p.live_preview = True
        if bpy.app.timers.is_registered(live.on_idle):
            live.on_idle()
        sc.frame_set(2)
        sc.frame_set(3)

    scrub_to_3()  # background mode: every frame solved in full
    full3 = scenes.stored_named(floor.data, "Radiosity")
    p.live_preview = False
    refinements = live.stats["refinements"]
    with monkeypatch.context() as m:
        m.setattr(live, "_timers_run", lambda: True)
        scrub_to_3()
        assert live.stats["refinements"] == refinements + 1  # frame 1, re-solved
        preview3 = scenes.stored_named(floor.data, "Radiosity")
        assert np.abs(preview3 - full3).max() > 0.05 * full3.max()  # the leaves, not the gather
        assert live.on_idle() is None
        assert live.stats["refinements"] == refinements + 2
        # The same frame reached through previews: the full chain's, to the solve's tolerance.
        refined3 = scenes.stored_named(floor.data, "Radiosity")
        assert np.abs(refined3 - full3).max() < 1e-5 * full3.max()  # measured 1.2e-7
        live.on_idle()  # nothing pending
        assert live.stats["refinements"] == refinements + 2
        p.live_preview = False


def test_a_bad_refinement_threshold_is_one_clear_line(blender):
    """A script that hands the bake a threshold outside the range gets one line naming it
    (the panel's property clamps to the same range)."""
    bpy = blender
    from addon.blender import bake
    from addon.core.settings import HIERARCHY_ACCURACY_RANGE

    scenes.cornell_box(bpy, n=2, light_frames=(1, 2), box=False)
    sc = bpy.context.scene
    sc.radiosity.method = "HIERARCHICAL"
    for bad in (0.0, 2.0, float("nan")):
        settings = bake.settings_from_scene(sc).replace(hierarchy_accuracy=bad)
        job = bake.BakeJob(bpy.context, settings)
        with pytest.raises(bake.BakeError) as info:
            job.run()
        line = str(info.value)
        assert "\n" not in line and line.startswith("refinement threshold "), line
        assert "outside 1e-06..0.5" in line, line
    assert not any(a.name.startswith("Rad_") for m in bpy.data.meshes for a in m.color_attributes)
    sc.radiosity.hierarchy_accuracy = 0.0  # the property clamps (to a float32 a hair below 1e-6)
    assert sc.radiosity.hierarchy_accuracy == pytest.approx(HIERARCHY_ACCURACY_RANGE[0])
    bake.settings_from_scene(sc).validate()  # and its minimum is a valid setting


def test_a_flat_bake_refused_for_memory_suggests_the_hierarchy_when_it_fits(blender):
    """A 1,537-face room at Detail 2: the flat estimate is about 2.2 GB, the hierarchy's 0.9 GB.
    With a 1,000 MB limit the flat bake is refused in one line that suggests the hierarchy (whose
    session, made only to ask, passes the check); with 1 MB neither fits, and there is no hint;
    the hierarchy's own refusal speaks of the Refinement Threshold. Nothing is baked."""
    bpy = blender
    objs = scenes.cornell_box(bpy, n=16, light_frames=(1, 2), box=False)
    sc = bpy.context.scene
    p = sc.radiosity
    p.basis_order, p.memory_limit_mb = 2, 1000
    with pytest.raises(RuntimeError) as info:
        bpy.ops.radiosity.bake()
    line = str(info.value).strip()
    print(line)
    assert "\n" not in line and "over the memory budget: this bake needs up to" in line, line
    assert line.endswith("or set Method to Large Scenes (Hierarchy), whose estimate for this scene is "
                         "within the limit (its memory grows about linearly with the faces)"), line

    p.memory_limit_mb = 1
    with pytest.raises(RuntimeError) as info:
        bpy.ops.radiosity.bake()
    line = str(info.value).strip()
    print(line)
    assert "over the memory budget" in line and "Hierarchy" not in line, line

    p.method = "HIERARCHICAL"
    with pytest.raises(RuntimeError) as info:
        bpy.ops.radiosity.bake()
    line = str(info.value).strip()
    print(line)
    assert "\n" not in line and "this hierarchical bake may need up to" in line, line
    assert "a larger Refinement Threshold or a lower Detail" in line, line
    assert "raise Memory Limit (MB)" in line and "settings." not in line and "set Method" not in line, line
    assert not scenes.rad_frames(objs["Floor"].data)


def test_a_flat_bake_of_many_faces_gets_a_note_at_once(blender, capfd):
    """2,167 faces on a flat method: before anything is solved the bake prints a note that
    suggests the hierarchy, and keeps it in ``hints`` (the operator reports it in the status bar
    when the bake starts in the UI); the hierarchical method gets none. The bakes here are
    refused by a 1 MB limit right after the note, so nothing is solved."""
    bpy = blender
    from addon.blender import bake

    scenes.cornell_box(bpy, n=19, light_frames=(1, 2), box=False)
    sc = bpy.context.scene
    sc.radiosity.memory_limit_mb = 1
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(sc))
    with pytest.raises(bake.BakeError):
        job.run()
    out = capfd.readouterr().out
    assert "Radiosity: note: 2,167 faces: the Update and From Scratch methods link every pair" in out, out
    assert len(job.hints) == 1 and "set Method to Large Scenes (Hierarchy)" in job.hints[0]

    sc.radiosity.method = "HIERARCHICAL"
    job = bake.BakeJob(bpy.context, bake.settings_from_scene(sc))
    with pytest.raises(bake.BakeError):
        job.run()
    assert "note:" not in capfd.readouterr().out and not job.hints


def test_the_panel_shows_the_refinement_threshold_with_the_hierarchy_only(blender):
    bpy = blender
    import addon.ui

    sc = bpy.context.scene
    rna = sc.radiosity.bl_rna.properties
    assert rna["method"].enum_items["HIERARCHICAL"].name == "Large Scenes (Hierarchy)"
    threshold = rna["hierarchy_accuracy"]
    assert threshold.name == "Refinement Threshold" and threshold.default == pytest.approx(1e-3)
    assert "Large Scenes (Hierarchy)" in threshold.description

    def drawn():
        names = []

        class Layout:
            use_property_split = use_property_decorate = enabled = active = False
            scale_y = 1.0

            def prop(self, _data, name, **_kw):
                names.append(name)

            def operator(self, *_a, **_kw):
                pass

            def row(self, **_kw):
                return self

            column = row

        class Panel:
            layout = Layout()

        class Ctx:
            scene = sc

        addon.ui.RENDER_PT_radiosity.draw(Panel(), Ctx())
        return names

    assert "hierarchy_accuracy" not in drawn()
    sc.radiosity.method = "HIERARCHICAL"
    names = drawn()
    assert names[names.index("method") + 1] == "hierarchy_accuracy"
