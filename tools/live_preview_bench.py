"""Times the add-on's live preview while scrubbing: what an artist waits for per frame change.

    .venv/bin/python -m tools.live_preview_bench [--subdiv 13] [--frames 24] [--lib A --lib B ...]
        [--mode full --mode idle] [--method HIERARCHICAL]
        [--light quad|point|static-point|world|world-point]

Builds the test suite's Cornell box (six walls of subdiv x subdiv faces, a 0.5 x 0.5 ceiling
light keyframed across the room over 48 frames, no block: 1,015 faces at 13) under the bpy
module, turns the live preview on (basis order 2, Medium quality, corner gather on, as the
panel's defaults) and steps the timeline frame by frame with ``scene.frame_set``. Prints per
frame the wall-clock time of ``frame_set`` (the handler: sampling, the native solve, writing the
colour attributes), of it the handler's own (all but the native ``solve_frame`` call: sampling,
comparing, writing the attributes), and the native solve's parts (kernel update, Delta solve,
corner gather) from its frame statistics, then the medians over frames 3 onward.

With several ``--lib`` (paths of ``libgalerkin_radiosity.so``, e.g. two builds), each library
runs in its own process, alternately, ``--runs`` times, so that machine noise hits all alike.

``--mode`` (repeatable, run alternately like the libraries): ``full`` solves every frame change
in full (the panel's "Refine When Idle" off); ``idle`` scrubs with it on, as the UI runs it (the
timers are told they fire: background mode fires none), so a frame change is a preview (the
kernel update and a solve to ten times the tolerance, no gather), and then times the refinement
of the frame the timeline rests on (the last), which the timer would run (``idle refine ms``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def measure(subdiv: int, frames: int, mode: str = "full", method: str = "INCREMENTAL",
            light: str = "quad") -> dict:
    """Runs in this process (bpy imported here): ``rows``, one dict per frame from 2 to
    ``frames``, and ``idle_refine_ms`` (``idle`` mode: the rest frame's refinement)."""
    sys.path[:0] = [str(REPO), str(REPO / "tests" / "python")]
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="blender-user-"))
    import bpy
    import numpy as np
    import scenes

    import addon
    from addon.blender import bake, live
    from addon.native import binding

    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    last: list[dict] = []
    solve_frame = binding.Session.solve_frame

    def recording(self, *args, **kwargs):
        t = time.perf_counter()
        stats = solve_frame(self, *args, **kwargs)
        last.append({**stats, "native_seconds": time.perf_counter() - t})
        return stats

    binding.Session.solve_frame = recording
    objs = scenes.cornell_box(bpy, n=subdiv, light_frames=(1, 48), box=light in ("world", "static-point"))
    if light != "quad":
        bpy.data.objects.remove(objs["Light"])
    if light in ("point", "static-point", "world-point"):
        # A Blender Point light in place of the emissive quad: moving along the quad's path (no
        # face moves, only the lights' direct light changes), or still above the moving block.
        lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", type="POINT"))
        lamp.data.energy = 100.0
        bpy.context.scene.collection.objects.link(lamp)
        lamp.location = (0.0, 0.0, 1.8)
        if light in ("point", "world-point"):
            for frame, x in ((1, -0.5), (48, 0.5)):
                lamp.location = (x, 0.0, 1.8)
                lamp.keyframe_insert("location", index=0, frame=frame)
            scenes._linear(lamp)
    if light in ("world", "world-point"):
        # The box open to a World: its ceiling taken away, the block moving on the floor (or the
        # Point light moving above it, for world-point).
        world = bpy.data.worlds.new("Sky")
        world.use_nodes = True
        world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
        bpy.context.scene.world = world
        bpy.data.objects.remove(objs["Ceiling"])
    bpy.context.scene.frame_set(1)
    sc = bpy.context.scene
    sc.radiosity.basis_order = 2
    sc.radiosity.method = method
    sc.radiosity.live_refine_when_idle = mode == "idle"
    if mode == "idle":
        live._timers_run = lambda: True
    sc.radiosity.live_preview = True  # solves frame 1
    if mode == "idle":
        live.refine(sc)  # the timer, once frame 1 rests before the scrub
    rows = []
    for f in range(2, frames + 1):
        t = time.perf_counter()
        sc.frame_set(f)
        wall = time.perf_counter() - t
        st = last[-1]
        rows.append({
            "frame": f,
            "frame_set_ms": 1e3 * wall,
            # The handler's own work around the native solve (sampling, writing the attributes).
            "python_ms": 1e3 * (wall - st["native_seconds"]),
            "kernel_ms": 1e3 * st["kernel_seconds"],
            # Its phases: the candidate pairs found, computed, written with their Delta K products.
            "scan_ms": 1e3 * st.get("kernel_scan_seconds", 0.0),
            "pairs_ms": 1e3 * st.get("kernel_pairs_seconds", 0.0),
            "apply_ms": 1e3 * st.get("kernel_apply_seconds", 0.0),
            "solve_ms": 1e3 * st["solve_seconds"],
            "gather_ms": 1e3 * st["gather_seconds"],
            "moments_recomputed": st["gather_recomputed"],
            # What the kernel update recomputed: the moving elements' pairs, and the static pairs
            # whose visibility the move may have changed.
            "elements": st.get("elements", 0),
            "moved_pairs": st.get("recomputed_translation", 0) + st.get("recomputed_non_translation", 0),
            "visibility_pairs": st.get("recomputed_visibility", 0),
            "faces": sum(len(o.data.polygons) for o in sc.objects if o.type == "MESH"),
        })
    idle_refine_ms, preview_error = None, None
    if mode == "idle":
        session = bake.held(sc).session

        def corners():
            return np.concatenate([session.corner_radiosity(i).ravel() for i in range(session.object_count)])

        preview = corners()
        t = time.perf_counter()
        assert live.refine(sc), "the rest frame was no preview"
        idle_refine_ms = 1e3 * (time.perf_counter() - t)
        refined = corners()
        # What the preview showed against the refined frame, relative to the mean radiosity.
        mean = refined.mean()
        preview_error = {"rms": float(np.sqrt(np.mean((preview - refined) ** 2)) / mean),
                         "worst": float(np.abs(preview - refined).max() / mean)}
        st = session.frame_stats()
        print(f"idle refine: {st['gather_recomputed']} of {st['gather_moments']} moments recomputed, "
              f"{st['shots']} shots in all", file=sys.stderr)
    return {"rows": rows, "idle_refine_ms": idle_refine_ms, "preview_error": preview_error}


def medians(rows: list[dict]) -> dict:
    keep = [r for r in rows if r["frame"] >= 3]
    keys = ("frame_set_ms", "python_ms", "kernel_ms", "scan_ms", "pairs_ms", "apply_ms", "solve_ms",
            "gather_ms", "moments_recomputed")
    return {k: statistics.median(r[k] for r in keep) for k in keys}


def _idle(ms) -> str:
    return "" if ms is None else f"{ms:.1f}"


def _error(e) -> str:
    return "" if e is None else f"{100 * e['rms']:.1f}% / {100 * e['worst']:.0f}%"


def _kernel(r: dict) -> str:
    """The kernel update's time with its phases (an updated frame's; zero on the first)."""
    return f"{r['kernel_ms']:.1f} ({r['scan_ms']:.1f}, {r['pairs_ms']:.1f}, {r['apply_ms']:.1f})"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subdiv", type=int, default=13)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--lib", action="append", default=[], help="library to time (repeatable)")
    ap.add_argument("--mode", action="append", choices=("full", "idle"), default=[],
                    help="solve every frame change in full, or refine when idle (repeatable; default: full)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--method", default="INCREMENTAL", help="the panel's Method (INCREMENTAL, HIERARCHICAL)")
    ap.add_argument("--light", choices=("quad", "point", "static-point", "world", "world-point"),
                    default="quad",
                    help="the light: the emissive ceiling quad moving (default), a Blender Point light "
                    "moving; a still Point light or a World (the ceiling taken away) over the block moving; "
                    "a Point light moving under a World (world-point, no block)")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # child mode
    args = ap.parse_args(argv)
    modes = args.mode or ["full"]
    if args.json:
        print(json.dumps(measure(args.subdiv, args.frames, modes[0], args.method, args.light)))
        return
    if not args.lib and len(modes) == 1:
        out = measure(args.subdiv, args.frames, modes[0], args.method, args.light)
        rows = out["rows"]
        last = rows[-1]
        print(f"{rows[0]['faces']} faces ({last['elements']} elements), mode {modes[0]}; the last frame "
              f"recomputed {last['moved_pairs']} moving pairs and {last['visibility_pairs']} static pairs' "
              "visibility")
        print("| frame | frame_set ms | of it Python ms | kernel ms (scan, pairs, apply) | solve ms "
              "| gather ms | moments recomputed |")
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['frame']} | {r['frame_set_ms']:.1f} | {r['python_ms']:.1f} | {_kernel(r)} | "
                  f"{r['solve_ms']:.1f} | {r['gather_ms']:.1f} | {r['moments_recomputed']} |")
        m = medians(rows)
        print(f"| median 3.. | {m['frame_set_ms']:.1f} | {m['python_ms']:.1f} | {_kernel(m)} | "
              f"{m['solve_ms']:.1f} | {m['gather_ms']:.1f} | {m['moments_recomputed']:.0f} |")
        if out["idle_refine_ms"] is not None:
            e = out["preview_error"]
            print(f"idle refinement of the rest frame: {out['idle_refine_ms']:.1f} ms; its preview's corners "
                  f"were off by {100 * e['rms']:.1f}% RMS, {100 * e['worst']:.0f}% worst, of the mean")
        return
    print("| library | mode | run | frame_set ms | of it Python ms | kernel ms | solve ms | gather ms "
          "| moments recomputed | idle refine ms | preview off refined, RMS / worst of mean |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for run in range(args.runs):
        for lib in args.lib or [None]:
            for mode in modes:
                env = dict(os.environ)
                if lib is not None:
                    env["GALERKIN_RADIOSITY_LIB"] = lib
                cmd = [sys.executable, "-m", "tools.live_preview_bench", "--json", "--mode", mode,
                       "--subdiv", str(args.subdiv), "--frames", str(args.frames), "--method", args.method,
                       "--light", args.light]
                res = subprocess.run(cmd, cwd=REPO, env=env, check=True, capture_output=True, text=True)
                out = json.loads(res.stdout.strip().splitlines()[-1])
                m = medians(out["rows"])
                cells = [m["frame_set_ms"], m["python_ms"], m["kernel_ms"], m["solve_ms"], m["gather_ms"]]
                print(f"| {lib or 'default'} | {mode} | {run + 1} | " + " | ".join(f"{x:.1f}" for x in cells)
                      + f" | {m['moments_recomputed']:.0f} | {_idle(out['idle_refine_ms'])} | "
                      + _error(out["preview_error"]) + " |", flush=True)


if __name__ == "__main__":
    main()
