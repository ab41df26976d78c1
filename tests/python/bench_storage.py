"""Storage benchmark: per-frame colour attributes switched by Geometry Nodes (what the add-on
does) against keyframed attribute values (a slotted action, Blender 5.0 API; the 4.5 layered
API as a fallback), on a 10,000-corner mesh over 100 frames.

    /work/venv/bin/python tests/python/bench_storage.py [--corners 10000] [--frames 100]

Prints a table: time to write the colours, .blend size, and the mean time of frame_set plus
reading the evaluated colours back (what playback and rendering pay per frame).
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))


def make_mesh(bpy, corners):
    n = int(round((corners / 4) ** 0.5))
    verts = [(i, j, 0.0) for j in range(n + 1) for i in range(n + 1)]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    me = bpy.data.meshes.new("Bench")
    me.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new("Bench", me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def colours(n_corners, frame):
    """Smooth colours plus per-frame noise, so that neither storage compresses unrealistically."""
    x = np.linspace(0.0, 1.0, n_corners, dtype=np.float32)
    noise = np.random.default_rng(frame).random((n_corners, 3), dtype=np.float32) * 0.05
    return np.stack([x, np.full_like(x, frame / 100.0), 1.0 - x], axis=1) + noise


def read_back(bpy, obj, name):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    attr = me.attributes[name]
    buf = np.empty(len(me.loops) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    ev.to_mesh_clear()
    return buf


def bench_switch(bpy, frames, corners):
    from addon.blender import attributes, switch

    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj = make_mesh(bpy, corners)
    n = len(obj.data.loops)
    t = time.perf_counter()
    for f in range(1, frames + 1):
        attributes.write_frame(obj.data, f, colours(n, f))
    attributes.ensure_result(obj.data)
    switch.install(bpy, obj, 1, frames)
    write = time.perf_counter() - t
    return obj, write, "Radiosity"


def bench_keyframes(bpy, frames, corners):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj = make_mesh(bpy, corners)
    me = obj.data
    n = len(me.loops)
    attr = me.color_attributes.new("Rad", "FLOAT_COLOR", "CORNER")
    me.color_attributes.active_color = attr
    t = time.perf_counter()
    values = np.stack([colours(n, f) for f in range(1, frames + 1)], axis=0)  # (frames, n, 3)
    act = bpy.data.actions.new("RadAnim")
    slot = act.slots.new(id_type="MESH", name=me.name)
    try:
        from bpy_extras.anim_utils import action_ensure_channelbag_for_slot

        cb = action_ensure_channelbag_for_slot(act, slot)
    except ImportError:  # 4.5
        layer = act.layers.new("Layer")
        strip = layer.strips.new(type="KEYFRAME")
        cb = strip.channelbag(slot, ensure=True)
    co = np.empty((frames, 2), np.float32)
    co[:, 0] = np.arange(1, frames + 1)
    for i in range(n):
        path = f'attributes["Rad"].data[{i}].color'
        for c in range(3):
            fc = cb.fcurves.new(path, index=c)
            fc.keyframe_points.add(frames)
            co[:, 1] = values[:, i, c]
            fc.keyframe_points.foreach_set("co", co.reshape(-1))
            fc.keyframe_points.foreach_set("interpolation", np.full(frames, 1, np.int32))  # LINEAR
    me.animation_data_create()
    me.animation_data.action = act
    me.animation_data.action_slot = slot
    write = time.perf_counter() - t
    return obj, write, "Rad"


def measure(bpy, build, frames, corners):
    obj, write, name = build(bpy, frames, corners)
    path = Path(tempfile.mkdtemp()) / "bench.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    size = path.stat().st_size
    obj = bpy.data.objects["Bench"]
    sc = bpy.context.scene
    sample = list(range(1, frames + 1, max(1, frames // 20)))
    t = time.perf_counter()
    for f in sample:
        sc.frame_set(f)
        buf = read_back(bpy, obj, name)
    per_frame = (time.perf_counter() - t) / len(sample)
    expect = colours(len(obj.data.loops), sample[-1])
    ok = np.allclose(buf.reshape(-1, 4)[:, :3], expect, atol=1e-5)
    return write, size, per_frame, ok


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--corners", type=int, default=10000)
    p.add_argument("--frames", type=int, default=100)
    args = p.parse_args()
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp())
    import bpy

    rows = []
    for label, build in (("GN switch, one attribute per frame", bench_switch),
                         ("keyframed attribute values (slotted action)", bench_keyframes)):
        write, size, per_frame, ok = measure(bpy, build, args.frames, args.corners)
        rows.append((label, write, size, per_frame, ok))
    print(f"\n{args.corners} corners x {args.frames} frames, Blender {bpy.app.version_string}")
    head = f"| {'storage':<45} | {'write (s)':>9} | {'file (MB)':>9} | {'frame_set + read (ms)':>21} |"
    print(head + " values |")
    print(f"|{'-' * 47}|{'-' * 11}|{'-' * 11}|{'-' * 23}|--------|")
    for label, write, size, per_frame, ok in rows:
        print(f"| {label:<45} | {write:>9.2f} | {size / 1e6:>9.1f} | {1000 * per_frame:>21.1f} | "
              f"{'ok' if ok else 'WRONG':>6} |")


if __name__ == "__main__":
    main()
