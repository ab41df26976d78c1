"""Validation against Cycles (issue 6): the Cornell box baked by Cycles (ground truth) and by
galerkin-radiosity at basis orders 0-3, per-corner relative RMSE and time per frame, plus one
frame of the moving-light animation baked both ways.

    .venv/bin/python -m tools.validate_cycles [--subdiv 6] [--samples 4096] [--out out/validation]
    .venv/bin/python -m tools.validate_cycles --table-from docs/validation.json   # a stored run's table

The table it prints last is docs/benchmarks.md's "validation" block (scripts/regenerate_docs.py).

Ground truth: Cycles DIFFUSE bake (direct + indirect + colour) = reflected radiance = B / pi on
non-emitting faces, Lambertian Diffuse BSDFs, one-sided emission, 64 bounces, no clamping, no
denoising. "Cycles time of equal error": Cycles' own error at `samples / 64` against the
reference, scaled as noise ~ 1 / sqrt(samples) and time ~ samples.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--subdiv", type=int, default=6, help="Cornell walls split n x n")
    p.add_argument("--samples", type=int, default=4096, help="Cycles samples of the reference")
    p.add_argument("--orders", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--anim-frame", type=int, default=12, help="frame of the moving-light check")
    p.add_argument("--frames", type=int, default=24, help="length of the animation")
    p.add_argument("--out", default=str(REPO / "out" / "validation"))
    p.add_argument("--pictures", action="store_true", help="render ours beside Cycles as PNG")
    p.add_argument("--table-from", metavar="JSON",
                   help="print the table of a stored validation.json, bake nothing")
    return p.parse_args(argv)


def cli():
    exe = REPO / "target" / "release" / "galerkin-radiosity"
    if not exe.exists():
        raise SystemExit(f"{exe} is missing: run `cargo build --release` first")
    return exe


def demo_scene(path, frames, subdiv, order=2, kind="cornell"):
    """Writes a Cornell box scene file with the CLI (`galerkin-radiosity demo-scene`): the demo
    (`cornell`: light on a path, short block sliding) or `cornell-light` (the light alone moving)."""
    cmd = [str(cli()), "demo-scene", "-o", str(path), "--frames", str(frames), "--subdiv", str(subdiv)]
    subprocess.run([*cmd, "--order", str(order), "--kind", kind], check=True, capture_output=True)
    return path


def cli_frame_seconds(scene_file, frames, order):
    """Seconds per frame of the CLI's incremental bake of `scene_file` over frames 1..`frames` at
    basis `order`: (the first frame, the mean of the others), from the frames' own stats."""
    data = json.loads(Path(scene_file).read_text())
    data["settings"]["basis_order"] = order
    with tempfile.TemporaryDirectory() as tmp:
        scene, out = Path(tmp) / "scene.json", Path(tmp) / "out.json"
        scene.write_text(json.dumps(data))
        subprocess.run(
            [str(cli()), "bake", str(scene), "-o", str(out), "--quiet", "--frames", f"1:{frames}"], check=True
        )
        stats = [f["stats"]["seconds"] for f in json.loads(out.read_text())["frames"]]
    return stats[0], float(np.mean(stats[1:]))


def setup_blender():
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="blender-user-"))
    import bpy

    sys.path.insert(0, str(REPO))
    import addon

    if not hasattr(bpy.types.Scene, "radiosity"):
        addon.register()
    return bpy


def run(args):
    from . import bakes, blender_scene

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene_file = out / "scene.json"
    demo_scene(scene_file, args.frames, args.subdiv)
    bpy = setup_blender()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    objects, emitters = blender_scene.build(bpy, scene_file)
    receivers = [
        ob for ob in objects.values() if not any(s.material.name in emitters for s in ob.material_slots)
    ]
    corners = sum(len(ob.data.loops) for ob in receivers)
    faces = sum(len(ob.data.polygons) for ob in objects.values())
    report = {
        "faces": faces,
        "receiver_corners": corners,
        "reference_samples": args.samples,
        "static": [],
        "animated": {},
    }
    sc = bpy.context.scene

    def cycles(frame, samples, seed=0, attr="Cycles"):
        sc.frame_set(frame)
        blender_scene.use_materials(objects, emitters)
        seconds = bakes.cycles_bake(bpy, receivers, samples, attr=attr, seed=seed)
        blender_scene.use_materials(objects, {v.name: bpy.data.materials[k] for k, v in emitters.items()})
        return seconds, bakes.values(receivers, attr)

    # Static frame 1: the reference, a cheap Cycles bake to scale Cycles' noise, ours per order.
    t_ref, ref = cycles(1, args.samples, seed=1)
    low = max(args.samples // 64, 16)
    t_low, cyc_low = cycles(1, low, seed=2, attr="CyclesLow")
    err_low = bakes.relative_rmse(cyc_low, ref)
    # The reference has noise too: its own error is err_low * sqrt(low / samples).
    ref_noise = err_low * np.sqrt(low / args.samples)
    print(
        f"Cycles reference: {args.samples} spp in {t_ref:.1f} s; {low} spp in {t_low:.2f} s, "
        f"error {err_low:.3f}; reference noise ~{ref_noise:.4f}",
        flush=True,
    )
    for order in args.orders:
        seconds = bakes.ours_bake(bpy, (1, 1), order, method="FULL")
        ours = bakes.values(receivers, "Rad_0001")
        err = bakes.relative_rmse(ours, ref)
        # Cycles samples (and time) for the same error, noise ~ 1/sqrt(samples).
        equal_time = t_low * (err_low / max(err, 1e-9)) ** 2
        per_object = {
            ob.name: bakes.relative_rmse(
                blender_scene.corner_values(ob, "Rad_0001"), blender_scene.corner_values(ob, "Cycles")
            )
            for ob in receivers
        }
        row = {
            "order": order,
            "rmse": err,
            "seconds": seconds,
            "cycles_equal_error_seconds": equal_time,
            "speedup_vs_cycles_equal_error": equal_time / seconds,
            "rmse_per_object": per_object,
        }
        report["static"].append(row)
        print(
            f"order {order}: relative RMSE {err:.4f}, {seconds:.2f} s per frame, Cycles of equal error "
            f"~{equal_time:.1f} s ({equal_time / seconds:.2f}x); per object "
            + ", ".join(f"{k} {100 * v:.1f}%" for k, v in per_object.items()),
            flush=True,
        )

    # One frame of the moving-light animation: ours incrementally from frame 1, Cycles at that frame.
    f = args.anim_frame
    for ob in objects.values():
        for a in [a for a in ob.data.color_attributes if a.name.startswith("Rad_")]:
            ob.data.color_attributes.remove(a)
    bpy.ops.radiosity.clear()
    start = time.perf_counter()
    seconds = bakes.ours_bake(bpy, (1, f), 2, method="INCREMENTAL")
    ours = bakes.values(receivers, f"Rad_{f:04d}")
    t_anim, ref_anim = cycles(f, args.samples, seed=3)
    err = bakes.relative_rmse(ours, ref_anim)
    report["animated"] = {
        "frame": f,
        "order": 2,
        "rmse": err,
        "seconds_per_frame": seconds / f,
        "cycles_seconds": t_anim,
        "wall_seconds": time.perf_counter() - start,
    }
    print(
        f"animated frame {f} (order 2, incremental from frame 1): relative RMSE {err:.4f}, "
        f"{seconds / f:.2f} s per frame; Cycles {args.samples} spp {t_anim:.1f} s",
        flush=True,
    )
    report["cycles_reference_seconds"] = t_ref
    report["cycles_low"] = {"samples": low, "seconds": t_low, "rmse": err_low}
    report["reference_noise"] = ref_noise
    if args.pictures:
        from . import pictures

        sc.frame_set(f)
        path = pictures.side_by_side(
            bpy, objects, [f"Rad_{f:04d}", "Cycles"], out / f"ours_vs_cycles_frame{f}.png", emitters=emitters
        )
        print(f"picture: {path}")
    # The moving-light animation (the light alone moving along the ceiling): a frame of it baked
    # both ways, ours incrementally; time per frame from the CLI's stats over the same frames.
    light_file = out / "moving_light.json"
    demo_scene(light_file, args.frames, args.subdiv, kind="cornell-light")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    objects, emitters = blender_scene.build(bpy, light_file)
    sc = bpy.context.scene  # the reset made a new scene; `cycles` reads these names
    receivers = [
        ob for ob in objects.values() if not any(s.material.name in emitters for s in ob.material_slots)
    ]
    t_light, ref_light = cycles(f, args.samples, seed=4)
    _, cyc_light_low = cycles(f, low, seed=5, attr="CyclesLow")
    err_light_low = bakes.relative_rmse(cyc_light_low, ref_light)
    report["moving_light"] = {"frame": f, "cycles_seconds": t_light, "orders": []}
    for order in (1, 2):
        bpy.ops.radiosity.clear()
        bakes.ours_bake(bpy, (1, f), order, method="INCREMENTAL")
        err = bakes.relative_rmse(bakes.values(receivers, f"Rad_{f:04d}"), ref_light)
        first, per_frame = cli_frame_seconds(light_file, args.frames, order)
        equal_time = t_low * (err_light_low / max(err, 1e-9)) ** 2
        row = {
            "order": order,
            "rmse": err,
            "first_frame_seconds": first,
            "seconds_per_frame": per_frame,
            "cycles_equal_error_seconds": equal_time,
            "speedup_vs_cycles_equal_error": equal_time / per_frame,
        }
        report["moving_light"]["orders"].append(row)
        print(
            f"moving light, frame {f}, order {order}: relative RMSE {err:.4f}; {per_frame:.3f} s per "
            f"frame after the first ({first:.2f} s), Cycles of equal error ~{equal_time:.1f} s "
            f"({equal_time / per_frame:.0f}x)",
            flush=True,
        )

    (out / "validation.json").write_text(json.dumps(report, indent=2))
    print(table(report))
    return report


# The receivers of the Cornell box, in the table's columns: walls (back / right / left), floor,
# ceiling, blocks (short / tall).
COLUMNS = [("walls (back / right / left)", ["BackWall", "RightWall", "LeftWall"]), ("floor", ["Floor"]),
           ("ceiling", ["Ceiling"]), ("short / tall block", ["ShortBlock", "TallBlock"])]


def table(report):
    """docs/benchmarks.md's validation table: a caption line, then per basis order the error in
    total and per object and the time, then the animated frames."""
    blanks = " |" * len(COLUMNS)
    rows = [
        f"Cornell box, {report['faces']} faces, {report['receiver_corners']} receiver corners; "
        f"Cycles reference {report['reference_samples']} spp ({report['cycles_reference_seconds']:.1f} s), "
        f"its own noise ~{100 * report['reference_noise']:.1f}% (included in the measured RMSE):",
        "",
        "| basis order | relative RMSE |" + "".join(f" {name} |" for name, _ in COLUMNS)
        + " ours s/frame | Cycles s for equal error |",
        "|---|---|" + "---|" * len(COLUMNS) + "---|---|",
    ]
    for r in report["static"]:
        per = r.get("rmse_per_object", {})
        cells = [" / ".join(f"{100 * per[n]:.1f}" for n in names if n in per) + ("%" if per else "")
                 for _, names in COLUMNS]
        rows.append(
            f"| {r['order']} | {100 * r['rmse']:.1f}% | " + " | ".join(cells)
            + f" | {r['seconds']:.2f} | {r['cycles_equal_error_seconds']:.1f} |"
        )
    a = report["animated"]
    rows.append(
        f"| {a['order']}, demo animation frame {a['frame']} (light and block moving) | "
        f"{100 * a['rmse']:.1f}% |"
        + blanks + f" {a['seconds_per_frame']:.2f} (add-on, frames 1-{a['frame']}) | |"
    )
    for r in report.get("moving_light", {}).get("orders", []):
        rows.append(
            f"| {r['order']}, moving-light frame {report['moving_light']['frame']} | {100 * r['rmse']:.1f}% |"
            + blanks + f" {r['seconds_per_frame']:.3f} per frame after the first (CLI stats) | "
            f"{r['cycles_equal_error_seconds']:.1f}: **{r['speedup_vs_cycles_equal_error']:.0f}x** |"
        )
    return "\n".join(rows)


def main(argv=None):
    args = parse(sys.argv[1:] if argv is None else argv)
    if args.table_from:
        print(table(json.loads(Path(args.table_from).read_text())))
        return
    run(args)


if __name__ == "__main__":
    main()
