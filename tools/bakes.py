"""The two bakes compared: Cycles' DIFFUSE bake (ground truth) and ours through the add-on."""

import time

import numpy as np

from .blender_scene import corner_values


def cycles_bake(bpy, objects, samples, attr="Cycles", seed=0, direct_only=False):
    """Bakes reflected radiance (DIFFUSE: direct + indirect + colour; `direct_only`: direct +
    colour) into a FLOAT_COLOR corner attribute of every object, unbiased: 64 diffuse bounces, no
    clamping, no denoising, no adaptive sampling. Returns the seconds taken."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    c = sc.cycles
    c.device = "CPU"
    c.samples = samples
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.max_bounces = c.diffuse_bounces = 64
    c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    # Cycles passes a path through a light it hits (a lamp of radius > 0, an area light) as a
    # transparent bounce (kernel/integrator/shade_light.h): with 0 such a light ended every path
    # that met it, a black absorber of the indirect light (a 0.5 m sphere lamp took 20% of the
    # room's light).
    c.transparent_max_bounces = 64
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.seed = seed
    for ob in objects:
        me = ob.data
        old = me.color_attributes.get(attr)
        if old is not None:
            me.color_attributes.remove(old)
        me.color_attributes.active_color = me.color_attributes.new(attr, "FLOAT_COLOR", "CORNER")
    bpy.ops.object.select_all(action="DESELECT")
    for ob in objects:
        ob.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    start = time.perf_counter()
    bpy.ops.object.bake(
        type="DIFFUSE",
        pass_filter={"DIRECT", "COLOR"} if direct_only else {"DIRECT", "INDIRECT", "COLOR"},
        target="VERTEX_COLORS",
        use_clear=True,
        margin=0,
    )
    return time.perf_counter() - start


def ours_bake(bpy, frames, order, method="INCREMENTAL", quality="MEDIUM"):
    """Runs the add-on's bake operator over `frames` (first, last); returns the seconds taken."""
    p = bpy.context.scene.radiosity
    p.basis_order = order
    p.quality = quality
    p.method = method
    p.use_scene_range = False
    p.frame_start, p.frame_end = frames
    p.frame_step = 1
    start = time.perf_counter()
    result = bpy.ops.radiosity.bake()
    if result != {"FINISHED"}:
        raise RuntimeError(f"bake returned {result}")
    return time.perf_counter() - start


def values(objects, attr):
    """All corners of all objects, concatenated, (C, 3)."""
    return np.concatenate([corner_values(ob, attr) for ob in objects])


def relative_rmse(ours, reference):
    """sqrt(mean((ours - ref)^2)) / mean(ref), over corners and channels: the error relative to
    the mean radiance (a per-corner ratio would blow up in dark corners)."""
    return float(np.sqrt(np.mean((ours - reference) ** 2)) / np.mean(reference))
