"""Bake from the command line, without a UI.

In Blender:
    blender -b scene.blend --python addon/headless.py -- --frames 1-100 --order 2 --save out.blend
With the bpy module (pip install bpy):
    python addon/headless.py --blend scene.blend --frames 1-100 --order 2 --save out.blend

Prints progress lines; on failure prints one line ``galerkin-radiosity: error: ...`` on stderr
and exits 1 (2 for a usage error). Options not given keep the file's Radiosity settings.
"""

import argparse
import importlib
import sys
from pathlib import Path

PREFIX = "galerkin-radiosity"


def parse(argv):
    p = argparse.ArgumentParser(prog="headless.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--blend", help="open this .blend first (plain Python with the bpy module)")
    p.add_argument("--scene", help="scene name (default: the file's active scene)")
    p.add_argument("--collection", help="bake only this collection's objects")
    p.add_argument("--frames", help="A-B or A (default: the scene's frame range)")
    p.add_argument("--step", type=int, help="solve every n-th frame, interpolate between")
    p.add_argument("--order", type=int, help="basis order 0..3")
    p.add_argument("--quality", choices=["DRAFT", "MEDIUM", "HIGH", "ULTRA"], type=str.upper)
    p.add_argument("--tolerance", type=float)
    p.add_argument("--method", choices=["incremental", "exact", "full"], type=str.lower)
    p.add_argument("--threads", type=int, help="0 = all cores")
    p.add_argument("--subdiv", type=int, help="display subdivision 0..4")
    p.add_argument("--preview-material", action="store_true",
                   help="show colours through the preview material")
    p.add_argument("--no-shadows", action="store_true", help="no visibility tests")
    p.add_argument("--no-corner-gather", action="store_true",
                   help="corners from the face polynomials (faster, softer contact shadows)")
    p.add_argument("--clear", action="store_true", help="clear the bake instead of baking")
    p.add_argument("--save", help="save the result to this .blend (default: nothing is saved)")
    return p.parse_args(argv)


def script_args(argv):
    """Arguments after '--' when run by Blender (``blender -b --python``), else after the script."""
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return [] if "--python" in argv else argv[1:]


def load_package():
    """The add-on package this script belongs to (``addon`` in a checkout), registered; and
    whether this call registered it."""
    here = Path(__file__).resolve().parent
    if str(here.parent) not in sys.path:
        sys.path.insert(0, str(here.parent))
    pkg = importlib.import_module(here.name)
    import bpy

    if hasattr(bpy.types.Scene, "radiosity"):
        return pkg, False
    pkg.register()
    return pkg, True


def frames_arg(text):
    a, sep, b = text.partition("-")
    try:
        return (int(a), int(b)) if sep else (int(a), int(a))
    except ValueError:
        raise SystemExit(f"{PREFIX}: --frames {text!r}: expected A-B or A") from None


def main(argv=None):
    args = parse(script_args(sys.argv if argv is None else argv))
    import bpy

    if args.blend:
        bpy.ops.wm.open_mainfile(filepath=str(Path(args.blend).resolve()))
    pkg, registered = load_package()
    try:
        return _main(args, bpy, pkg)
    finally:
        if registered:
            pkg.unregister()  # the bpy 4.5 module hangs at exit with add-on classes still registered


def _main(args, bpy, pkg):
    bake = importlib.import_module(pkg.__name__ + ".blender.bake")
    scene = bpy.data.scenes.get(args.scene) if args.scene else bpy.context.scene
    if scene is None:
        return fail(f"no scene named {args.scene!r}")
    p = scene.radiosity
    if args.collection:
        coll = bpy.data.collections.get(args.collection)
        if coll is None:
            return fail(f"no collection named {args.collection!r}")
        p.collection = coll
    if args.frames:
        p.use_scene_range = False
        p.frame_start, p.frame_end = frames_arg(args.frames)
    for name, attr in (("step", "frame_step"), ("order", "basis_order"), ("quality", "quality"),
                       ("tolerance", "tolerance"), ("threads", "threads"), ("subdiv", "display_subdivision")):
        value = getattr(args, name)
        if value is not None:
            try:
                setattr(p, attr, value)
            except (TypeError, ValueError) as e:
                return fail(f"--{name} {value}: {e}")
    if args.method:
        p.method = args.method.upper()
    if args.preview_material:
        p.preview_material = True
    if args.no_shadows:
        p.visibility = False
    if args.no_corner_gather:
        p.corner_gather = False
    view_layer = scene.view_layers[0] if bpy.context.scene != scene else bpy.context.view_layer
    with bpy.context.temp_override(scene=scene, view_layer=view_layer):
        ctx = bpy.context
        if args.clear:
            n = bake.clear_bake(scene)
            print(f"Radiosity: cleared the bake from {n} object(s)")
        else:
            try:
                job = bake.BakeJob(ctx, bake.settings_from_scene(scene), p.collection, verbose=True)
                job.run()
            except bake.BakeError as e:
                return fail(str(e))
            except Exception as e:  # the library's own errors (not found, invalid scene)
                library_error = type(e).__name__ in ("RadiosityError", "Cancelled")
                if library_error or isinstance(e, (ImportError, OSError)):
                    return fail(str(e).replace("\n", " "))
                raise
            for line in job.warnings:
                print(f"Radiosity: warning: {line}")
            print(job.summary)
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.save).resolve()), check_existing=False)
        print(f"Radiosity: saved {args.save}")
    return 0


def fail(message):
    print(f"{PREFIX}: error: {message}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.exit(code)
