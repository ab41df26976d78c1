"""Validation on real meshes against Cycles (issue 19): a scene of OBJ meshes (tools/real_scenes.py)
built in Blender, baked by the add-on at its default settings and by Cycles (ground truth), with
per-object relative RMSE per corner, mean ratio (ours / Cycles), the corners Cycles finds black
that we light, and pictures side by side.

    .venv/bin/python -m tools.validate_real --scene bunny|room|monastery|all [--samples 4096]
        [--cycles-cache DIR] [--order N] [--out DIR] [--export-json FILE] [--noise]

Ground truth as tools/validate_cycles.py: Diffuse BSDF, one-sided emitter, Cycles DIFFUSE bake
(direct + indirect + colour) into a FLOAT_COLOR corner attribute, 64 bounces, no denoising, no
adaptive sampling, no clamping. The Cycles bake is cached per scene, samples, seed and scene
digest (`--cycles-cache`, default out/validation-real/cycles-cache), so re-running our side
after a solver change costs only our bake. `--noise` bakes Cycles a second time with another
seed and reports the RMS between the two / sqrt(2): Cycles' own per-corner noise.
`--reference DIR` writes the scene file and the Cycles per-corner radiosity for tests
(tests/data/real/).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OURS_ATTR = "Rad_0001"
CYCLES_ATTR = "Cycles"
ERROR_ATTR = "Error"
# The error picture saturates at this relative error (of the object's mean).
ERROR_FULL_SCALE = 0.2
# A corner is black when below this fraction of the scene's brightest Cycles corner.
BLACK_FRACTION = 1e-3
# The scene file's settings fields (src/scene/json.rs, SettingsFile); the add-on's native
# settings also carry "method", which the file does not have.
FILE_SETTINGS = ("basis_order", "quadrature_order", "tolerance", "visibility", "visibility_samples",
                 "threads", "corner_gather")


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="bunny", help="bunny, room, monastery, a comma list, or all")
    p.add_argument("--samples", type=int, default=4096, help="Cycles samples of the reference")
    p.add_argument("--seed", type=int, default=1, help="Cycles seed of the reference")
    p.add_argument("--cycles-cache", default=str(REPO / "out" / "validation-real" / "cycles-cache"),
                   help="folder of cached Cycles bakes ('' for none)")
    p.add_argument("--order", type=int, help="basis order (default: the add-on's)")
    p.add_argument("--out", default=str(REPO / "out" / "validation-real"))
    p.add_argument("--meshes", help="the pybullet_data folder (default: $GALERKIN_MESHES or /work/cache)")
    p.add_argument("--export-json", help="write the built scene as a library scene file (CLI `bake`)")
    p.add_argument("--noise", action="store_true", help="bake Cycles again (seed + 1): its own noise")
    p.add_argument("--reference", help="write the scene file and Cycles corners for tests to this folder")
    p.add_argument("--no-pictures", action="store_true")
    p.add_argument("--skip-ours", action="store_true", help="only the Cycles bake (to fill the cache)")
    p.add_argument(
        "--one-sided",
        action="store_true",
        help="Cycles with the receivers' back faces black (a Diffuse BSDF mixed to black on Backfacing), "
        "as the library treats them; cached apart. Cycles' Diffuse BSDF is two-sided: the back of an "
        "open surface (a roof seen from below) reflects light there and is black here",
    )
    p.add_argument(
        "--direct-only",
        action="store_true",
        help="Cycles' direct light alone (the DIFFUSE bake's DIRECT and COLOR passes); cached apart",
    )
    p.add_argument(
        "--shift",
        help="X,Y,Z: move every object by this (metres) after building; the same scene elsewhere, to see "
        "how Cycles' float32 ray offsets (which grow with the coordinates) move its corners",
    )
    return p.parse_args(argv)


def default_settings(order=None):
    """The add-on's default bake settings (one frame), with `order` if given."""
    from addon.core.settings import BakeSettings

    s = BakeSettings()
    return s if order is None else s.replace(basis_order=order)


def export_scene(bpy, settings, frames=(1, 1)) -> tuple[dict, list]:
    """The scene as the add-on hands it to the library (addon/blender/export.py), as a version-1
    scene file dict; and the exported objects (each with its FaceSplit: library corner -> loop)."""
    from addon.blender import export

    sc, vl = bpy.context.scene, bpy.context.view_layer
    sel = export.collect(sc, vl)
    exp = export.export(bpy.context.evaluated_depsgraph_get(), sel.objects)
    rho, e = exp.materials.arrays()
    native = settings.native()
    data = {
        "version": 1,
        "settings": {k: native[k] for k in FILE_SETTINGS},
        "frames": list(frames),
        "materials": [
            {"name": s.name, "reflectance": rho[i].tolist(), "emission": e[i].tolist()}
            for i, s in enumerate(exp.materials.specs)
        ],
        "objects": [],
    }
    for o in exp.objects:
        d = o.data
        sizes = d.split.face_sizes.astype(np.int64)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        idx = d.split.face_indices.astype(np.int64)
        data["objects"].append({
            "name": d.name,
            "vertices": np.round(d.vertices.astype(np.float64), 6).tolist(),
            "faces": [idx[s:s + n].tolist() for s, n in zip(starts, sizes, strict=True)],
            "face_materials": d.face_materials.astype(np.int64).tolist(),
            "matrix": np.round(d.matrix, 9).ravel().tolist(),
        })
    return data, exp.objects


def scene_digest(data: dict) -> str:
    """Digest of the geometry and materials (not the settings): the key of a Cycles bake."""
    body = json.dumps({"materials": data["materials"], "objects": data["objects"]}, sort_keys=True)
    return hashlib.sha1(body.encode()).hexdigest()[:16]


def cycles_values(bpy, built, samples, seed, cache, digest, bake=True, one_sided=False,
                  direct_only=False) -> tuple[dict | None, dict | None]:
    """Per receiver, Cycles' per-loop radiance (C, 3) float32, from the cache or baked now (with
    `bake`; else (None, None) when not cached); and the bake's metadata (samples, seed, seconds,
    Blender version, digest). `one_sided`: the receivers' back faces black; `direct_only`: the
    direct light alone (each cached apart)."""
    from . import bakes, blender_scene

    tag = ("_onesided" if one_sided else "") + ("_direct" if direct_only else "")
    path = Path(cache) / f"{built.name}{tag}_{samples}spp_seed{seed}_{digest}" if cache else None
    if path is not None and path.with_suffix(".npz").exists():
        meta = json.loads(path.with_suffix(".json").read_text())
        with np.load(path.with_suffix(".npz")) as z:
            values = {name: z[name] for name in z.files}
        if sorted(values) == sorted(ob.name for ob in built.receivers):
            when = f"{meta['seconds']:.0f} s when baked"
            print(f"Cycles: cached {path.with_suffix('.npz')} ({when})", flush=True)
            return values, meta
    if not bake:
        return None, None
    receivers = built.receivers
    swap = dict(built.emitters)
    if one_sided:
        receiving = {s.material.name for ob in receivers for s in ob.material_slots if s.material is not None}
        swap.update({name: blender_scene.one_sided(bpy, bpy.data.materials[name]) for name in receiving})
    blender_scene.use_materials(built.objects, swap)
    print(f"Cycles: baking {built.name} at {samples} spp (seed {seed}) ...", flush=True)
    seconds = bakes.cycles_bake(bpy, receivers, samples, attr=CYCLES_ATTR, seed=seed, direct_only=direct_only)
    ours_materials = {v.name: bpy.data.materials[k] for k, v in swap.items()}
    blender_scene.use_materials(built.objects, ours_materials)
    values = {ob.name: blender_scene.corner_values(ob, CYCLES_ATTR) for ob in receivers}
    meta = {"scene": built.name, "samples": samples, "seed": seed, "seconds": seconds, "digest": digest,
            "blender": bpy.app.version_string, "one_sided": one_sided, "direct_only": direct_only}
    print(f"Cycles: {seconds:.1f} s", flush=True)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path.with_suffix(".npz"), **values)
        path.with_suffix(".json").write_text(json.dumps(meta, indent=1))
    return values, meta


def write_attribute(ob, name, values):
    me = ob.data
    old = me.color_attributes.get(name)
    if old is not None:
        me.color_attributes.remove(old)
    attr = me.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((len(values), 4), np.float32)
    rgba[:, :3] = values
    attr.data.foreach_set("color", rgba.ravel())


def error_colours(ours, cycles, full_scale=ERROR_FULL_SCALE):
    """Per corner, the signed error (ours - Cycles) / the object's mean Cycles value as a colour:
    red where ours is brighter, blue where darker, full at `full_scale`; black where they agree.
    Raised to 2.2 so that the picture's sRGB encoding shows brightness in proportion to the error."""
    e = (ours.mean(axis=1) - cycles.mean(axis=1)) / max(float(cycles.mean()), 1e-30) / full_scale
    rgb = np.zeros((len(e), 3), np.float32)
    rgb[:, 0] = np.clip(e, 0, 1) ** 2.2
    rgb[:, 2] = np.clip(-e, 0, 1) ** 2.2
    return rgb


def compare(ours: dict, cycles: dict) -> dict:
    """Per object: relative RMSE per corner (bakes.relative_rmse), mean ratio ours / Cycles, the
    fraction of corners Cycles finds black (< BLACK_FRACTION of the scene's peak) and the fraction
    that are black in Cycles but lit in ours; plus the same over all receivers ("all")."""
    from .bakes import relative_rmse

    peak = max(float(v.max()) for v in cycles.values())
    black = BLACK_FRACTION * peak
    rows = {}
    names = list(cycles)
    for name in [*names, "all"]:
        o = np.concatenate([ours[n] for n in names]) if name == "all" else ours[name]
        c = np.concatenate([cycles[n] for n in names]) if name == "all" else cycles[name]
        cb, ob_ = c.max(axis=1) < black, o.max(axis=1) >= black
        rows[name] = {
            "corners": len(c),
            "rmse": relative_rmse(o, c),
            "mean_ratio": float(o.mean() / c.mean()),
            "black_cycles": float(cb.mean()),
            "black_cycles_lit_ours": float((cb & ob_).mean()),
        }
    return rows


def noise(first: dict, second: dict) -> dict:
    """Per object, Cycles' own per-corner noise: relative RMS between two seeds / sqrt(2)."""
    from .bakes import relative_rmse

    out = {n: relative_rmse(second[n], first[n]) / np.sqrt(2) for n in first}
    both = [np.concatenate(list(d.values())) for d in (second, first)]
    out["all"] = relative_rmse(*both) / np.sqrt(2)
    return out


def table(report) -> str:
    noise_ = report.get("cycles_noise", {})
    head = (f"{report['scene']}: {report['faces']} faces; ours order {report['settings']['basis_order']} "
            f"(quadrature {report['settings']['quadrature_order']}, visibility samples "
            f"{report['settings']['visibility_samples']}), {report['ours_seconds']:.1f} s; Cycles "
            f"{report['samples']} spp seed {report['seed']}")
    rows = [head, "", "| object | corners | relative RMSE | mean ratio ours/Cycles | black in Cycles | "
            "black in Cycles, lit in ours | Cycles noise |", "|---|---|---|---|---|---|---|"]
    for name, r in report["objects"].items():
        n = f"{100 * noise_[name]:.2f}%" if name in noise_ else ""
        rows.append(f"| {name} | {r['corners']} | {100 * r['rmse']:.2f}% | {r['mean_ratio']:.4f} | "
                    f"{100 * r['black_cycles']:.1f}% | {100 * r['black_cycles_lit_ours']:.1f}% | {n} |")
    return "\n".join(rows)


def write_reference(folder, built, data, exported, cyc, meta, noise_):
    """tests/data/real/: `<scene>_scene.json` (the library scene file) and `<scene>_cycles.json`
    (Cycles' radiosity B = pi x bake per library corner, in the scene file's face-corner order,
    the order of the CLI's `corner_radiosity`; grey scene, so one value per corner)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    scene_name = f"{built.name}_scene.json"
    (folder / scene_name).write_text(json.dumps(data, separators=(",", ":")) + "\n")
    objects = {}
    for o in exported:
        if o.data.name not in cyc:
            continue
        per_corner = cyc[o.data.name][o.data.split.corner_loop]  # library corner -> mesh loop
        spread = float(np.abs(per_corner - per_corner.mean(axis=1, keepdims=True)).max())
        if spread > 1e-5 * max(float(per_corner.max()), 1e-30):
            raise SystemExit(f"{o.data.name}: Cycles channels differ by {spread}: not a grey scene")
        b = np.pi * per_corner[:, 0].astype(np.float64)
        objects[o.data.name] = [float(f"{x:.5g}") for x in b]
    ref = {
        "scene_file": scene_name,
        "quantity": "radiosity B (W/m^2) per face corner = pi x Cycles DIFFUSE bake "
        "(direct + indirect + colour)",
        "cycles": {k: meta[k] for k in ("samples", "seed", "blender", "digest")},
        "cycles_noise_per_corner": {k: round(float(v), 5) for k, v in (noise_ or {}).items()},
        "objects": objects,
    }
    (folder / f"{built.name}_cycles.json").write_text(json.dumps(ref, separators=(",", ":")) + "\n")
    print(f"reference: {folder / scene_name}, {folder / f'{built.name}_cycles.json'}")


def run(args):
    from . import bakes, real_scenes
    from .validate_cycles import setup_blender

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    bpy = setup_blender()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    from addon.blender import bake

    bake.drop_held()  # a session held from the previous scene of `--scene all`
    built = real_scenes.build(bpy, args.scene, args.meshes)
    if args.shift:
        shift = [float(x) for x in args.shift.split(",")]
        for ob in bpy.context.scene.objects:
            ob.location = [a + b for a, b in zip(ob.location, shift, strict=True)]
        bpy.context.view_layer.update()
        built.notes.append(f"every object moved by {shift} m")
    for line in built.notes:
        print(line)
    settings = default_settings(args.order)
    data, exported = export_scene(bpy, settings)
    digest = scene_digest(data)
    faces = sum(len(o["faces"]) for o in data["objects"])
    print(f"scene {args.scene}: {faces} faces, digest {digest}", flush=True)
    (out / f"{args.scene}_scene.json").write_text(json.dumps(data))
    if args.export_json:
        Path(args.export_json).write_text(json.dumps(data))
        print(f"scene file: {args.export_json} (bake it: target/release/galerkin-radiosity bake "
              f"{args.export_json} -o result.json)")
    cyc, meta = cycles_values(bpy, built, args.samples, args.seed, args.cycles_cache, digest,
                              one_sided=args.one_sided, direct_only=args.direct_only)
    noise_ = None
    # The second seed: baked with --noise, else read from the cache if an earlier run baked it.
    second, _ = cycles_values(bpy, built, args.samples, args.seed + 1, args.cycles_cache, digest,
                              bake=args.noise, one_sided=args.one_sided, direct_only=args.direct_only)
    if second is not None:
        noise_ = noise(cyc, second)
        print("Cycles noise per corner: " + ", ".join(f"{k} {100 * v:.2f}%" for k, v in noise_.items()))
    if args.reference:
        write_reference(args.reference, built, data, exported, cyc, meta, noise_)
    if args.skip_ours:
        return None
    for ob in built.receivers:
        write_attribute(ob, CYCLES_ATTR, cyc[ob.name])
    start = time.perf_counter()
    bakes.ours_bake(bpy, (1, 1), settings.basis_order, method=settings.method.upper(),
                    quality=settings.quality)
    ours_seconds = time.perf_counter() - start
    ours = {ob.name: bakes.values([ob], OURS_ATTR) for ob in built.receivers}
    report = {
        "scene": args.scene,
        "faces": faces,
        "digest": digest,
        "settings": settings.native(),
        "samples": args.samples,
        "seed": args.seed,
        "cycles_seconds": meta["seconds"],
        "ours_seconds": ours_seconds,
        "objects": compare(ours, cyc),
    }
    if noise_:
        report["cycles_noise"] = noise_
    suffix = f"{args.scene}_order{settings.basis_order}_{args.samples}spp"
    (out / f"{suffix}.json").write_text(json.dumps(report, indent=1))
    np.savez_compressed(out / f"{suffix}_ours.npz", **ours)  # per-loop radiance, to diff runs
    print(table(report), flush=True)
    if not args.no_pictures:
        from . import pictures

        for ob in built.receivers:
            write_attribute(ob, ERROR_ATTR, error_colours(ours[ob.name], cyc[ob.name]))
        path = pictures.side_by_side(bpy, built.objects, [OURS_ATTR, CYCLES_ATTR, ERROR_ATTR],
                                     out / f"{suffix}.png", emitters=built.emitters, size=400)
        print(f"picture (ours, Cycles, error: red ours brighter, blue darker, full at "
              f"{100 * ERROR_FULL_SCALE:.0f}%): {path}")
    return report


def main(argv=None):
    from .real_scenes import PRESETS

    args = parse(sys.argv[1:] if argv is None else argv)
    scenes = PRESETS if args.scene == "all" else args.scene.split(",")
    reports = [run(argparse.Namespace(**{**vars(args), "scene": name})) for name in scenes]
    if len(scenes) > 1:
        print("\n\n".join(table(r) for r in reports if r is not None))


if __name__ == "__main__":
    main()
