"""A Cycles reference for any scene file: `B` per face corner of every object that does not only
emit, as `tools/compare_ref.py` reads it (the format `tools/validate_real.py --reference`
writes).

    .venv/bin/python -m tools.cycles_reference office.json --samples 1024 -o office_cycles.json
    target/release/galerkin-radiosity bake office.json -o out.json --hierarchy
    .venv/bin/python -m tools.compare_ref out.json office_cycles.json

The scene is built under `bpy` by `tools/blender_scene.py` (a Diffuse BSDF of each reflectance,
the emitters one-sided as the library's are) and baked by `tools/bakes.py` (DIFFUSE: direct,
indirect and colour, 64 bounces, no clamping or denoising); `B = pi x` the baked value, the mean
of the three channels. Cycles' diffuse surfaces are two-sided, the library's are not: a scene
whose faces face away from where they are seen differs there (docs/validation-real.md).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from tools import bakes, blender_scene


def reference(scene_file: str, samples: int, seed: int = 1) -> dict:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    objects, emitters = blender_scene.build(bpy, scene_file)
    blender_scene.use_materials(objects, emitters)
    data = json.loads(open(scene_file).read())
    emits = [any(e > 0.0 for e in m.get("emission", [0.0] * 3)) for m in data["materials"]]
    receivers = []
    for o in data["objects"]:
        used = o.get("face_materials") or [o.get("material", 0)] * len(o["faces"])
        if not all(emits[m] for m in used):
            receivers.append(objects[o["name"]])
    start = time.perf_counter()
    bakes.cycles_bake(bpy, receivers, samples, attr="Cycles", seed=seed)
    seconds = time.perf_counter() - start
    values = {}
    for ob in receivers:
        v = blender_scene.corner_values(ob, "Cycles").astype(np.float64)
        values[ob.name] = (np.pi * v.mean(axis=1)).tolist()
    return {
        "scene_file": scene_file,
        "samples": samples,
        "seed": seed,
        "cycles_seconds": seconds,
        "quantity": "radiosity B (W/m^2) per face corner = pi x Cycles DIFFUSE bake, mean of the channels",
        "objects": values,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--samples", type=int, default=1024)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("-o", "--out", required=True)
    a = p.parse_args(argv)
    ref = reference(a.scene, a.samples, a.seed)
    with open(a.out, "w") as f:
        json.dump(ref, f)
    corners = sum(len(v) for v in ref["objects"].values())
    seconds = ref["cycles_seconds"]
    print(f"wrote {a.out}: {len(ref['objects'])} objects, {corners} corners, Cycles {seconds:.1f} s")


if __name__ == "__main__":
    main()
