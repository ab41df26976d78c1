"""EEVEE renders the bake (issue 22): the Cornell box's textured floor, baked with constant faces
(basis order 0, no corner gather: every face's corners hold one value, so each face renders
flat), is rendered by EEVEE from straight above, orthographic, through Apply to Materials'
"Radiosity Light" group and through the Preview Material. The pixels inside each floor face
equal the face's stored B / pi.

The renders run in a fresh Python with bpy but without the add-on, on the saved file (as a
render farm would open it): it also keeps the test process safe if the GPU context cannot be
made: without EGL it aborts (SIGABRT, epoxy: "Couldn't find current GLX or EGL context"). That
process first renders an empty scene; only if that fails (no EEVEE engine, no EGL context) is
the test skipped, with the error text. A failure after it is a failure.

Tolerance: the output is a 32-bit float EXR of the scene-linear render (view transform Standard,
which an EXR does not apply anyway), but EEVEE passes the colours through half floats (10-bit
mantissa: a step of 2^-10 relative), truncating or rounding twice (measured: 0.15204646 renders
0.15197754, a step below; the same with 1 sample as with 4). The tolerance is one step per half
a pixel passes through: the Preview Material's attribute (and the film) 2^-10 (worst measured
6.9e-4, bpy 4.5 and 5.0); the group's Color (a float image, held as half on the GPU) x
attribute 3 x 2^-10 (worst 6.9e-4 in 5.0, 1.34e-3 in 4.5), against faces whose values span
over 30% (mirror-image faces share theirs), so a lost factor or a far face's value fails.
Pixels within 3 of a face's edge are left out (the film's reconstruction filter blends
neighbouring faces there).

Time: about 10 s with mesa's shader cache warm (~/.cache/mesa_shader_cache), 29 s cold
(MESA_SHADER_CACHE_DISABLE=true), nearly all of it EEVEE compiling shaders in the render process.
"""

import subprocess
import sys
import time

import numpy as np
import pytest
import scenes
from test_material_output import _stored, _textured_floor

RES = 64
# One half-float step (2^-10 relative) per half a pixel's value passes through (see above).
HALF_STEP = 2.0 ** -10
RTOL = {"preview": HALF_STEP, "apply": 3 * HALF_STEP}
MARGIN = 3   # pixels kept from each face edge

CHILD = r'''
import json, os, sys, tempfile, traceback
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()
import bpy

def setup(sc, engine):
    sc.render.engine = engine
    sc.render.resolution_x = sc.render.resolution_y = int(sys.argv[1])
    sc.render.resolution_percentage = 100
    sc.render.film_transparent = False
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure, sc.view_settings.gamma = 0.0, 1.0
    sc.eevee.taa_render_samples = 4
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"

items = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
engine = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"
if engine not in items:
    print("UNAVAILABLE no EEVEE engine among " + ", ".join(sorted(items)), flush=True)
    sys.exit(0)
out_dir = sys.argv[2]
try:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    setup(sc, engine)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    sc.render.filepath = os.path.join(out_dir, "empty.exr")
    bpy.ops.render.render(write_still=True)
except Exception:
    print("UNAVAILABLE " + traceback.format_exc().replace("\n", " | "), flush=True)
    sys.exit(0)
print("AVAILABLE " + engine, flush=True)
for path in sys.argv[3:]:
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    setup(sc, engine)
    sc.frame_set(1)
    sc.render.filepath = path[:-len(".blend")] + ".exr"
    bpy.ops.render.render(write_still=True)
    print("RENDERED " + sc.render.filepath, flush=True)
'''


def _camera_above(bpy):
    """An orthographic camera looking straight down on the floor [-1,1]^2, framing it exactly,
    below the ceiling light (which is then behind it)."""
    cam = bpy.data.objects.new("Above", bpy.data.cameras.new("Above"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", 2.0
    cam.location = (0.0, 0.0, 1.5)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def _face_values(floor):
    """(P, 3) B / pi per floor face; every corner of a face must hold it (the faces are flat)."""
    me = floor.data
    corners = _stored(me, "Rad_0001")
    out = []
    for p in me.polygons:
        c = corners[list(p.loop_indices)]
        np.testing.assert_allclose(c, c[0:1].repeat(len(c), 0), rtol=1e-6, atol=1e-9,
                                   err_msg=f"face {p.index} is not flat")
        out.append(c[0])
    return np.array(out)


def _face_pixels(bpy, path, floor):
    """Per floor face, the (K, 3) rendered pixels at least MARGIN from its edges."""
    img = bpy.data.images.load(path)
    px = np.empty(RES * RES * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(RES, RES, 4)[..., :3]            # rows from the bottom: y up, columns x
    bpy.data.images.remove(img)
    centre = -1.0 + (np.arange(RES) + 0.5) * 2.0 / RES   # pixel centres in world x (or y)
    step = 2.0 / RES
    me = floor.data
    out = []
    for p in me.polygons:
        co = np.array([me.vertices[v].co[:2] for v in p.vertices])
        lo, hi = co.min(axis=0) + MARGIN * step, co.max(axis=0) - MARGIN * step
        cols = np.flatnonzero((centre > lo[0]) & (centre < hi[0]))
        rows = np.flatnonzero((centre > lo[1]) & (centre < hi[1]))
        out.append(px[np.ix_(rows, cols)].reshape(-1, 3))
    return out


def test_eevee_renders_the_baked_values_through_the_group_and_the_preview(blender, tmp_path):
    bpy = blender
    objs = scenes.cornell_box(bpy, n=3, light_frames=(1, 1), box=False)
    mat = _textured_floor(bpy, objs)
    # Its image was made in memory: packed, it reaches the render process with its pixels.
    next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeTexImage").image.pack()
    _camera_above(bpy)
    files = {}
    for name, props in (("apply", {"apply_to_materials": True, "preview_material": False}),
                        ("preview", {"apply_to_materials": False, "preview_material": True})):
        assert scenes.bake(bpy, basis_order=0, corner_gather=False, **props) == {"FINISHED"}
        files[name] = tmp_path / f"{name}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(files[name]), copy=True)
    floor = objs["Floor"]
    want = _face_values(floor)
    red = want[:, 0]
    assert red.max() > 1.3 * red.min() > 0, want   # the faces differ: a real per-face check

    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CHILD, str(RES), str(tmp_path), *map(str, files.values())],
                          capture_output=True, text=True, timeout=600)
    seconds = time.perf_counter() - t
    status = [ln for ln in proc.stdout.splitlines() if ln.startswith(("AVAILABLE", "UNAVAILABLE"))]
    if not status:
        # No word from the empty scene's render: the process died making the GPU context.
        pytest.skip(f"EEVEE unavailable: the render process exited {proc.returncode} before an "
                    f"empty scene rendered: {proc.stderr[-1500:]}")
    if status[0].startswith("UNAVAILABLE"):
        pytest.skip("EEVEE unavailable: " + status[0][len("UNAVAILABLE "):][:1500])
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = []
    for name, path in files.items():
        exr = str(path)[:-len(".blend")] + ".exr"
        assert f"RENDERED {exr}" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-2000:]
        worst = 0.0
        for k, (pixels, value) in enumerate(zip(_face_pixels(bpy, exr, floor), want, strict=True)):
            assert len(pixels) >= 16, (name, k, len(pixels))
            np.testing.assert_allclose(pixels, np.broadcast_to(value, pixels.shape), rtol=RTOL[name],
                                       atol=1e-5, err_msg=f"{name}: floor face {k}")
            worst = max(worst, float(np.abs(pixels / value - 1.0).max()))
        lines.append(f"{name}: worst relative error {worst:.2e}")
    print(f"{status[0]}; both renders in a fresh process {seconds:.1f} s; " + "; ".join(lines))
