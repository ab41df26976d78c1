"""Bake from the command line, without a UI.

In Blender:
    blender -b scene.blend --python addon/headless.py -- --frames 1-100 --order 2 --save out.blend
With the bpy module (pip install bpy):
    python addon/headless.py --blend scene.blend --frames 1-100 --order 2 --save out.blend

Prints progress on stdout, flushed line by line: inside a frame a line at most every second
(``--progress-interval``; stage, the frame's and the bake's percentage, time spent and left), after each frame
``Radiosity: frame F done (i/n) in T s; bake P%, S spent, about L left``, and last a summary
line ``Radiosity: summary: solved i of n frame(s) in T, M s a frame``. On failure prints one
line ``galerkin-radiosity: error: ...`` on stderr and exits 1 (2 for a usage error). Options not
given keep the file's Radiosity settings.

``--memory-limit MB`` is the panel's Memory Limit (MB): a bake whose estimate is above it is refused
before anything is changed, with one line giving the estimate, the limit and what to lower (0, the
panel's default, is 80% of the memory available when the bake starts).

``--method hierarchical`` is the panel's Large Scenes (Hierarchy), for scenes of thousands of faces
and more, and ``--refinement A`` its Refinement Threshold (default 0.001; smaller is finer and slower).

SIGINT (Ctrl-C) or SIGTERM stops the bake within one progress poll of the library (<= 50 ms
inside a frame), keeps every complete frame, saves them to ``--save`` and exits 130 or 143. With
``--save``, the file is also saved every ``--checkpoint N`` solved frames (default 10), so a killed
bake loses at most that many. ``--resume`` opens the ``--save`` file, when it exists, instead of the
source file, and goes on from its last complete frame (the re-bake keeps the solved frames).
"""

import argparse
import importlib
import os
import signal
import sys
import threading
from pathlib import Path

PREFIX = "galerkin-radiosity"

# Solved frames between two saves of ``--save`` during a bake.
DEFAULT_CHECKPOINT = 10

# The Refinement Threshold's range (addon/core/settings.py, HIERARCHY_ACCURACY_RANGE; repeated
# because usage is checked before the add-on package is imported).
REFINEMENT_RANGE = (1e-6, 0.5)

# The panel's names in messages, with this script's options for them.
OPTION_NAMES = (
    ("Memory Limit (MB)", "Memory Limit (MB), --memory-limit"),
    ("Refinement Threshold", "Refinement Threshold (--refinement)"),
    ("set Method to Large Scenes (Hierarchy)", "use --method hierarchical"),
)


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
    p.add_argument("--method", choices=["incremental", "exact", "full", "hierarchical"], type=str.lower,
                   help="hierarchical: for large scenes (the panel's Large Scenes (Hierarchy))")
    p.add_argument("--refinement", type=float, metavar="A",
                   help="the hierarchical method's Refinement Threshold: smaller is finer and slower "
                        "(default 0.001)")
    p.add_argument("--threads", type=int, help="0 = all cores")
    p.add_argument("--memory-limit", type=int, metavar="MB",
                   help="refuse a bake that would need more than MB megabytes, at once "
                        "(0 = automatic: 80%% of the memory available when the bake starts)")
    p.add_argument("--subdiv", type=int, help="display subdivision 0..4")
    p.add_argument("--preview-material", action="store_true",
                   help="show colours through the preview material")
    p.add_argument("--apply-to-materials", action="store_true",
                   help="insert the Radiosity Light node group into the baked objects' materials")
    p.add_argument("--no-shadows", action="store_true", help="no visibility tests")
    p.add_argument("--no-corner-gather", action="store_true",
                   help="corners from the face polynomials (faster, softer contact shadows)")
    p.add_argument("--reflecting-backs", action="store_true",
                   help="open surfaces reflect light from both sides (Two-Sided Open Surfaces)")
    p.add_argument("--clear", action="store_true", help="clear the bake instead of baking")
    p.add_argument("--save", help="save the result to this .blend (default: nothing is saved)")
    p.add_argument("--checkpoint", type=int, default=DEFAULT_CHECKPOINT, metavar="N",
                   help=f"with --save, save every N solved frames (default {DEFAULT_CHECKPOINT})")
    p.add_argument("--progress-interval", type=float, default=1.0, metavar="SECONDS",
                   help="inside a frame, a progress line at most this often (default 1; 0: every report)")
    p.add_argument("--resume", action="store_true",
                   help="open the --save file if it exists and continue from its last complete frame")
    args = p.parse_args(argv)
    if not args.progress_interval >= 0:
        p.error(f"--progress-interval {args.progress_interval}: must be at least 0")
    if args.refinement is not None:
        lo, hi = REFINEMENT_RANGE
        if not lo <= args.refinement <= hi:  # also NaN; Blender would clamp it silently
            p.error(f"--refinement {args.refinement:g}: must be in {lo:g}..{hi:g} "
                    "(smaller is finer and slower; default 0.001)")
    if args.memory_limit is not None and args.memory_limit < 0:
        p.error(f"--memory-limit {args.memory_limit}: must be 0 (automatic) or more megabytes")
    if args.checkpoint < 1:
        p.error(f"--checkpoint {args.checkpoint}: must be at least 1")
    if args.resume and not args.save:
        p.error("--resume needs --save (the file to continue)")
    return args


class Interrupt:
    """SIGINT and SIGTERM cancel the running bake at once, whatever thread is in the library.

    Python runs signal handlers on the main thread between bytecodes, and that thread sits in the
    native solve for the whole frame: the handler alone would wait for it (90+ s on a big frame).
    The C-level handler also writes the signal number to the wakeup fd; a watcher thread reads it
    and cancels the job (``BakeJob.cancel`` only sets an event and the session's atomic flag).
    """

    def __init__(self):
        self.signum = None
        self.job = None
        self._old = {}

    def install(self):
        r, w = os.pipe()
        os.set_blocking(w, False)
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._note)
        self._old_fd = signal.set_wakeup_fd(w)
        threading.Thread(target=self._watch, args=(r,), daemon=True).start()

    def uninstall(self):
        signal.set_wakeup_fd(self._old_fd)
        for sig, old in self._old.items():
            signal.signal(sig, old)

    def _note(self, signum, _frame):
        self.signum = signum

    def _watch(self, r):
        while data := os.read(r, 1):
            self.signum = data[0]
            job = self.job
            if job is not None:
                job.cancel()


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
    try:
        sys.stdout.reconfigure(line_buffering=True)  # each line out at once, also into a pipe
    except (AttributeError, ValueError):
        pass
    import bpy

    if args.resume and Path(args.save).exists():
        bpy.ops.wm.open_mainfile(filepath=str(Path(args.save).resolve()))
        print(f"Radiosity: resuming {args.save}")
    elif args.blend:
        bpy.ops.wm.open_mainfile(filepath=str(Path(args.blend).resolve()))
    pkg, registered = load_package()
    try:
        return _main(args, bpy, pkg)
    finally:
        if registered:
            pkg.unregister()  # the bpy 4.5 module hangs at exit with add-on classes still registered


def _main(args, bpy, pkg):
    bake = importlib.import_module(pkg.__name__ + ".blender.bake")
    progress = importlib.import_module(pkg.__name__ + ".core.progress")
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
                       ("tolerance", "tolerance"), ("threads", "threads"), ("subdiv", "display_subdivision"),
                       ("memory_limit", "memory_limit_mb"), ("refinement", "hierarchy_accuracy")):
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
    if args.apply_to_materials:
        p.apply_to_materials = True
    if args.no_shadows:
        p.visibility = False
    if args.no_corner_gather:
        p.corner_gather = False
    if args.reflecting_backs:
        p.reflecting_backs = True
    view_layer = scene.view_layers[0] if bpy.context.scene != scene else bpy.context.view_layer
    lines = None
    with bpy.context.temp_override(scene=scene, view_layer=view_layer):
        ctx = bpy.context
        if args.clear:
            n = bake.clear_bake(scene)
            print(f"Radiosity: cleared the bake from {n} object(s)")
        else:
            interrupt = Interrupt()
            interrupt.install()
            lines = progress.Lines(0, args.progress_interval)  # the frame count comes with the first job
            bake.listeners.append(lines.listen)
            try:
                with lines.heartbeat():  # a line every interval even while the library is silent
                    code = _bake_in_chunks(args, bpy, bake, ctx, scene, interrupt, lines)
            finally:
                bake.listeners.remove(lines.listen)
                interrupt.uninstall()
            if code is not None:
                return code
            if interrupt.signum is not None:
                name = signal.Signals(interrupt.signum).name
                where = f"; run again with --resume --save {args.save} to continue" if args.save else ""
                print(f"Radiosity: interrupted by {name}, complete frames kept{where}")
                print(lines.summary())
                return 128 + interrupt.signum
    if args.save:
        _save(bpy, args.save)
    if lines is not None:
        print(lines.summary())
    return 0


def _save(bpy, path):
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(path).resolve()), check_existing=False)
    print(f"Radiosity: saved {path}")


def _bake_in_chunks(args, bpy, bake, ctx, scene, interrupt, lines):
    """Bakes the range as re-bakes of a growing range, ``--checkpoint`` solved frames at a time,
    saving ``--save`` after each (without ``--save``, in one go). Each re-bake keeps the frames
    solved before (the record's digests are unchanged) and goes on in the held session, so the
    chunks cost what one bake costs, plus sampling the kept frames again. ``lines`` prints the
    progress across the chunks (told how many frames are left as each chunk starts). Returns an
    exit code on failure, else None."""
    p = scene.radiosity
    settings = bake.settings_from_scene(scene)
    frames = settings.baked_frames()
    size = args.checkpoint if args.save else len(frames)
    original = (p.use_scene_range, p.frame_start, p.frame_end)

    def restore():
        p.use_scene_range, p.frame_start, p.frame_end = original

    ends = list(range(size, len(frames) + size, size))
    # A bake to resume: from the chunk holding its last complete frame (a shorter first chunk
    # would trim the kept frames beyond it).
    record = bake.read_record(scene)
    if record is not None and record.complete:
        ends = [k for k in ends if frames[min(k, len(frames)) - 1] >= record.complete[1]] or ends[-1:]
    try:
        for k in ends:
            if interrupt.signum is not None:
                break
            p.use_scene_range = False
            p.frame_start, p.frame_end = settings.frame_start, frames[min(k, len(frames)) - 1]
            try:
                job = bake.BakeJob(ctx, bake.settings_from_scene(scene), p.collection,
                                   log=lambda line: print(in_option_words(line)))
                interrupt.job = job
                # Frames left: this chunk's (known once it started) and the chunks after it.
                lines.expect(job, len(frames) - min(k, len(frames)))
                job.run()
            except bake.BakeError as e:
                return fail(str(e))
            except Exception as e:  # the library's own errors (not found, invalid scene)
                library_error = type(e).__name__ in ("RadiosityError", "Cancelled")
                if library_error or isinstance(e, (ImportError, OSError)):
                    return fail(str(e).replace("\n", " "))
                raise
            finally:
                interrupt.job = None
            lines.job_ended()
            for line in job.warnings:
                print(f"Radiosity: warning: {line}")
            print(job.summary)
            # A checkpoint (the last chunk's file is saved by the caller).
            if args.save and (k < len(frames) or interrupt.signum is not None):
                restore()
                _save(bpy, args.save)
    finally:
        restore()
    return None


def in_option_words(message):
    """A message with the panel's names followed by this script's options for them."""
    for panel, option in OPTION_NAMES:
        message = message.replace(panel, option)
    return message


def fail(message):
    print(f"{PREFIX}: error: {in_option_words(message)}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.exit(code)
