"""Validation of Blender Light objects and the World against Cycles (issue 22): a small room lit
only by one Point, Spot, Sun or Area light, one of their soft variants (``point_soft``: radius
0.5 with Soft Falloff, Blender's default, a disk facing the receiver; ``point_sphere``: the same
without Soft Falloff, a sphere; ``spot_soft``: radius 0.25, Soft Falloff; ``sun_soft``: angle
10 degrees), or by the World (``world``: a uniform colour;
``sky``: an equirectangular image, bright and warm towards +X, dim and blue towards -X, so a
mirrored or rotated mapping lights the wrong walls), baked by the add-on (default settings) and
by Cycles (DIFFUSE: direct + indirect + colour), relative RMSE per object.

    .venv/bin/python -m tools.validate_lights [--samples 2048] [--subdiv 6]
        [--lights point spot sun area world sky point_soft point_sphere spot_soft sun_soft]
        [--pictures docs/lights_vs_cycles.png]

The room: floor, walls (red left, green right) and a white block, Lambertian Diffuse BSDFs; the
ceiling is left off for the sun and the World (they shine in through the open top). Point and
Spot radius 0 and Sun angle 0 but in the soft variants, the World black. Ground truth as in
tools/validate_cycles.py: 64 bounces, no clamping, no denoising, no adaptive sampling. Cycles'
own noise is estimated from a second bake at a quarter of the samples.
"""

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from .validate_cycles import setup_blender

REPO = Path(__file__).resolve().parents[1]


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", type=int, default=2048, help="Cycles samples of the reference")
    p.add_argument("--subdiv", type=int, default=6, help="walls split n x n")
    p.add_argument("--lights", nargs="+", default=["point", "spot", "sun", "area", "world", "sky", *SOFT])
    p.add_argument("--out", default=str(REPO / "out" / "validation"))
    p.add_argument("--pictures", metavar="PNG", help="also write a sheet of each light's room, ours left of "
                   "Cycles, two lights a row in --lights order (docs/lights_vs_cycles.png)")
    return p.parse_args(argv)


def _diffuse(bpy, name, color):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def _grid(bpy, name, origin, u, v, n, mat):
    origin, u, v = (np.asarray(a, float) for a in (origin, u, v))
    verts = [tuple(origin + (i / n) * u + (j / n) * v) for j in range(n + 1) for i in range(n + 1)]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def room(bpy, n, ceiling):
    """Room [-1,1]^2 x [0,2], faces inward; a 0.6 m block on the floor. Returns the objects."""
    white = _diffuse(bpy, "White", (0.7, 0.7, 0.7))
    red = _diffuse(bpy, "Red", (0.7, 0.15, 0.1))
    green = _diffuse(bpy, "Green", (0.15, 0.7, 0.1))
    walls = {
        "Floor": ((-1, -1, 0), (2, 0, 0), (0, 2, 0), white),
        "Back": ((-1, 1, 0), (2, 0, 0), (0, 0, 2), white),
        "Front": ((-1, -1, 0), (0, 0, 2), (2, 0, 0), white),
        "Left": ((-1, -1, 0), (0, 2, 0), (0, 0, 2), red),
        "Right": ((1, -1, 0), (0, 0, 2), (0, 2, 0), green),
    }
    if ceiling:
        walls["Ceiling"] = ((-1, -1, 2), (0, 2, 0), (2, 0, 0), white)
    objs = [_grid(bpy, name, o, u, v, n, m) for name, (o, u, v, m) in walls.items()]
    h, c = 0.3, (0.25, -0.2, 0.3)
    k = max(n // 3, 1)
    sides = [((c[0] - h, c[1] - h, c[2] + h), (2 * h, 0, 0), (0, 2 * h, 0)),      # top
             ((c[0] - h, c[1] - h, c[2] - h), (2 * h, 0, 0), (0, 0, 2 * h)),      # -y
             ((c[0] + h, c[1] + h, c[2] - h), (-2 * h, 0, 0), (0, 0, 2 * h)),     # +y
             ((c[0] - h, c[1] + h, c[2] - h), (0, -2 * h, 0), (0, 0, 2 * h)),     # -x
             ((c[0] + h, c[1] - h, c[2] - h), (0, 2 * h, 0), (0, 0, 2 * h))]      # +x
    parts = [_grid(bpy, f"Block{i}", o, u, v, k, white) for i, (o, u, v) in enumerate(sides)]
    for p in parts:
        p.select_set(True)
    bpy.context.view_layer.objects.active = parts[0]
    bpy.ops.object.join()
    block = bpy.context.view_layer.objects.active
    block.name = "Block"
    return objs + [block]


#: The soft variants: the light they vary and what they set on it.
SOFT = {
    "point_soft": ("point", dict(shadow_soft_size=0.5, use_soft_falloff=True), (-0.3, 0.2, 1.4)),
    "point_sphere": ("point", dict(shadow_soft_size=0.5, use_soft_falloff=False), (-0.3, 0.2, 1.4)),
    "spot_soft": ("spot", dict(shadow_soft_size=0.25, use_soft_falloff=True), (0.0, -0.5, 1.7)),
    "sun_soft": ("sun", dict(angle=math.radians(10)), None),
}


def add_light(bpy, kind):
    """The room's light ``kind``: point, spot, sun, area or a soft variant (``SOFT``)."""
    if kind in SOFT:
        base, values, loc = SOFT[kind]
        ob = add_light(bpy, base)
        for k, v in values.items():
            setattr(ob.data, k, v)
        if loc is not None:
            ob.location = loc
        return ob
    sc = bpy.context.scene
    if kind == "point":
        data = bpy.data.lights.new("Lamp", "POINT")
        data.energy, data.shadow_soft_size = 60.0, 0.0
        loc, rot = (-0.3, 0.2, 1.6), (0, 0, 0)
    elif kind == "spot":
        data = bpy.data.lights.new("Lamp", "SPOT")
        data.energy, data.shadow_soft_size = 150.0, 0.0
        data.spot_size, data.spot_blend = math.radians(70), 0.3
        loc, rot = (0.0, -0.5, 1.8), (math.radians(20), 0, 0)
    elif kind == "sun":
        data = bpy.data.lights.new("Lamp", "SUN")
        data.energy, data.angle = 3.0, 0.0
        loc, rot = (0, 0, 3), (math.radians(25), math.radians(15), 0)
    else:
        data = bpy.data.lights.new("Lamp", "AREA")
        data.energy, data.shape, data.size, data.size_y = 40.0, "RECTANGLE", 0.6, 0.4
        loc, rot = (0.0, 0.1, 1.95), (0, 0, 0)
    data.color = (1.0, 0.9, 0.8)
    ob = bpy.data.objects.new("Lamp", data)
    ob.location, ob.rotation_euler = loc, rot
    sc.collection.objects.link(ob)
    return ob


OPEN_TOP = ("sun", "sun_soft", "world", "sky")


def add_camera(bpy):
    """A wide camera against the front wall, looking at the back wall (+Y)."""
    cam = bpy.data.cameras.new("Camera")
    cam.lens, cam.sensor_width = 18.0, 36.0
    ob = bpy.data.objects.new("Camera", cam)
    ob.location, ob.rotation_euler = (0.0, -0.97, 1.0), (math.pi / 2, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob


def picture(bpy, objs, kind, out: Path, size=160):
    """The room of ``kind``, ours (``Rad_0001``) left of Cycles, as the stored radiance at an
    exposure that puts Cycles' mean at 0.3 (lights of different power read alike)."""
    from . import bakes
    from .pictures import side_by_side

    bpy.context.scene.view_settings.exposure = math.log2(0.3 / max(float(bakes.values(objs, "Cycles").mean()),
                                                                   1e-9))
    return side_by_side(bpy, {o.name: o for o in objs}, ["Rad_0001", "Cycles"], out / f"lights_{kind}.png",
                        size=size)


def sky_image(bpy, width=64, height=32):
    """An equirectangular image: columns looking towards +X (u in [0.25, 0.75), Blender's
    mapping) bright and warm, the others dim and blue, all brighter towards the zenith (v = 1,
    the top row); float, linear."""
    img = bpy.data.images.new("Sky", width, height, float_buffer=True)
    u = (np.arange(width) + 0.5) / width
    east = (u >= 0.25) & (u < 0.75)
    row = np.where(east[:, None], [2.0, 1.6, 1.0, 1.0], [0.15, 0.25, 0.5, 1.0])
    v = (np.arange(height) + 0.5) / height  # rows bottom first
    pixels = np.tile(row, (height, 1, 1))
    pixels[..., :3] *= (0.5 + v)[:, None, None]
    img.pixels.foreach_set(pixels.astype(np.float32).ravel())
    return img


def set_world(bpy, kind):
    """The scene's World: a uniform colour (``world``) or the sky image (``sky``)."""
    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes["Background"]
    bg.inputs["Color"].default_value = (0.6, 0.7, 0.9, 1.0)
    bg.inputs["Strength"].default_value = 1.5
    if kind == "sky":
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.image = sky_image(bpy)
        nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    bpy.context.scene.world = world
    return world


def run(args):
    from . import bakes
    from .blender_scene import corner_values

    bpy = setup_blender()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = {"samples": args.samples, "subdiv": args.subdiv, "lights": {}}
    sheets = []
    for kind in args.lights:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        objs = room(bpy, args.subdiv, ceiling=kind not in OPEN_TOP)
        if kind in ("world", "sky"):
            set_world(bpy, kind)
        else:
            add_light(bpy, kind)
        sc = bpy.context.scene
        sc.frame_start = sc.frame_end = 1
        sc.frame_set(1)
        faces = sum(len(o.data.polygons) for o in objs)
        t_ref = bakes.cycles_bake(bpy, objs, args.samples, attr="Cycles", seed=1)
        t_low = bakes.cycles_bake(bpy, objs, args.samples // 4, attr="CyclesLow", seed=2)
        t_ours = bakes.ours_bake(bpy, (1, 1), 2, method="FULL")
        ref = bakes.values(objs, "Cycles")
        per_object = {
            o.name: bakes.relative_rmse(corner_values(o, "Rad_0001"), corner_values(o, "Cycles"))
            for o in objs
        }
        low_err = bakes.relative_rmse(bakes.values(objs, "CyclesLow"), ref)
        # Noise of the reference: the quarter-sample bake has twice its noise, so the two differ
        # by sqrt(1 + 4) = sqrt(5) of it.
        noise_per_object = {
            o.name: bakes.relative_rmse(corner_values(o, "CyclesLow"), corner_values(o, "Cycles"))
            / np.sqrt(5)
            for o in objs
        }
        mean_ratio_per_object = {
            o.name: float(corner_values(o, "Rad_0001").mean() / corner_values(o, "Cycles").mean())
            for o in objs
        }
        row = {
            "faces": faces,
            "rmse": bakes.relative_rmse(bakes.values(objs, "Rad_0001"), ref),
            "rmse_per_object": per_object,
            "reference_noise_per_object": noise_per_object,
            "mean_ratio_per_object": mean_ratio_per_object,
            "mean_ratio": float(bakes.values(objs, "Rad_0001").mean() / ref.mean()),
            "reference_noise": low_err / np.sqrt(5),
            "cycles_seconds": t_ref,
            "cycles_low_seconds": t_low,
            "ours_seconds": t_ours,
        }
        report["lights"][kind] = row
        print(
            f"{kind}: {faces} faces, relative RMSE {100 * row['rmse']:.2f}% "
            f"(mean ratio {row['mean_ratio']:.4f}; "
            f"Cycles noise ~{100 * row['reference_noise']:.2f}%); per object "
            + ", ".join(f"{k} {100 * v:.1f}% (noise {100 * noise_per_object[k]:.1f}%, "
                        f"mean {mean_ratio_per_object[k]:.3f})" for k, v in per_object.items())
            + f"; Cycles {args.samples} spp {t_ref:.1f} s, ours {t_ours:.2f} s",
            flush=True,
        )
        if args.pictures:
            add_camera(bpy)
            sheets.append(picture(bpy, objs, kind, out))
    (out / "lights.json").write_text(json.dumps(report, indent=2))
    if args.pictures:
        from .pictures import grid

        print(f"wrote {grid(bpy, sheets, Path(args.pictures), columns=2, gap=8)}")
    return report


def main(argv=None):
    run(parse(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    main()
