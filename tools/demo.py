"""The demo (issue 6): the Cornell box whose light slides along the ceiling and whose short
block slides across the floor, 48 frames, baked headless through the add-on, saved as a .blend,
and a contact sheet of a few frames rendered from the baked colours.

    .venv/bin/python -m tools.demo [--frames 48] [--subdiv 8] [--order 2] [--out out/demo]
"""

import argparse
import sys
import time
from pathlib import Path

from .validate_cycles import REPO, demo_scene, setup_blender


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=48)
    p.add_argument("--subdiv", type=int, default=8, help="Cornell walls split n x n")
    p.add_argument("--order", type=int, default=2)
    p.add_argument("--sheet", type=int, nargs="+", default=None, help="frames on the contact sheet")
    p.add_argument("--out", default=str(REPO / "out" / "demo"))
    return p.parse_args(argv)


def run(args):
    from . import bakes, blender_scene, pictures

    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    scene_file = out / "scene.json"
    demo_scene(scene_file, args.frames, args.subdiv, args.order)
    bpy = setup_blender()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    objects, emitters = blender_scene.build(bpy, scene_file)
    print(
        f"demo: {sum(len(o.data.polygons) for o in objects.values())} faces, frames 1-{args.frames}",
        flush=True,
    )
    start = time.perf_counter()
    bakes.ours_bake(bpy, (1, args.frames), args.order, method="INCREMENTAL")
    seconds = time.perf_counter() - start
    print(f"demo: baked {args.frames} frames in {seconds:.1f} s ({seconds / args.frames:.2f} s per frame)")
    blend = out / "demo.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    picks = (1, args.frames // 4, args.frames // 2, 3 * args.frames // 4, args.frames)
    frames = args.sheet or sorted({max(1, f) for f in picks})
    skip = {
        ob.name
        for ob in objects.values()
        if any(s.material and s.material.name in emitters for s in ob.material_slots)
    }
    tiles = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        tiles.append(
            pictures.render_attribute(bpy, objects, "Radiosity", out / f"frame_{f:04d}.png", skip=skip)
        )
    sheet = pictures.stitch(bpy, tiles, out / "contact_sheet.png")
    # Re-open the saved file so the rendered settings do not leak into it.
    print(f"scene:         {scene_file}")
    print(f"blend:         {blend}")
    print(f"contact sheet: {sheet} (frames {', '.join(map(str, frames))})")
    return blend, sheet


def main(argv=None):
    run(parse(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    main()
