"""A scene file of an OBJ model under a moving light, for the hierarchy's animation at scale
(issue 21: "the monastery with a light moving along it").

The model is placed as benches/common/obj.rs's `obj_under_a_light` places it (y-up turned z-up,
polygons fanned into triangles, on a ground square 1.5 times its larger horizontal extent, an
emissive square of a quarter of that size one model height above its top), at order 1 with the
corner gather off; the light moves along x at the animation bench's rate (40 units over 15 frame
steps), starting 20 units to the left, over frames 1..N.

    python3 -m tools.obj_animation path/to/samurai_monastry.obj mon_anim.json --frames 4
    target/release/galerkin-radiosity bake mon_anim.json -o out.json --hierarchy
"""

from __future__ import annotations

import argparse
import json

STEP = 40.0 / 15.0


def read_obj(path: str) -> tuple[list[list[float]], list[list[int]]]:
    vertices, faces = [], []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                x, y, z = map(float, p[1:4])
                vertices.append([x, -z, y])  # y-up to z-up
            elif p[0] == "f":
                idx = [int(w.split("/")[0]) - 1 for w in p[1:]]
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return vertices, faces


def scene(vertices: list[list[float]], faces: list[list[int]], frames: int) -> dict:
    lo = [min(v[i] for v in vertices) for i in range(3)]
    hi = [max(v[i] for v in vertices) for i in range(3)]
    c = [(a + b) / 2 for a, b in zip(lo, hi, strict=True)]
    d = [b - a for a, b in zip(lo, hi, strict=True)]
    size = max(d[0], d[1]) * 1.5
    ground = [
        [c[0] - size, c[1] - size, lo[2]],
        [c[0] + size, c[1] - size, lo[2]],
        [c[0] + size, c[1] + size, lo[2]],
        [c[0] - size, c[1] + size, lo[2]],
    ]
    h, half = hi[2] + d[2], 0.25 * size
    light = [
        [c[0] - half, c[1] + half, h],
        [c[0] + half, c[1] + half, h],
        [c[0] + half, c[1] - half, h],
        [c[0] - half, c[1] - half, h],
    ]
    keys = [
        {"frame": 1.0, "translation": [-20.0, 0.0, 0.0]},
        {"frame": float(frames), "translation": [-20.0 + STEP * (frames - 1), 0.0, 0.0]},
    ]
    return {
        "version": 1,
        "settings": {"basis_order": 1, "corner_gather": False},
        "frames": [1, frames],
        "materials": [
            {"name": "Grey", "reflectance": [0.7] * 3, "emission": [0.0] * 3},
            {"name": "Light", "reflectance": [0.0] * 3, "emission": [30.0] * 3},
        ],
        "objects": [
            {"name": "Mesh", "vertices": vertices, "faces": faces, "material": 0},
            {"name": "Ground", "vertices": ground, "faces": [[0, 1, 2, 3]], "material": 0},
            {"name": "Light", "vertices": light, "faces": [[0, 1, 2, 3]], "material": 1, "animation": keys},
        ],
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("obj")
    p.add_argument("out")
    p.add_argument("--frames", type=int, default=4)
    a = p.parse_args(argv)
    vertices, faces = read_obj(a.obj)
    with open(a.out, "w") as f:
        json.dump(scene(vertices, faces, a.frames), f)
    print(f"wrote {a.out}: {len(faces)} triangles, frames 1..{a.frames}")


if __name__ == "__main__":
    main()
