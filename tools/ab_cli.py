"""Interleaved A/B of whole CLI bakes: runs each given `galerkin-radiosity` binary on one scene file
in turn, `--runs` times, and prints per run and binary the medians over frames 2.. of the frame's
seconds and its parts (kernel update, solve, corner gather) from the output's frame statistics.

    python3 -m tools.ab_cli SCENE.json BIN_A BIN_B [--runs 2] [--frames 1:6] [--world 1.0]
        [--point X,Y,Z,WATTS [--point-to X,Y,Z]] [--hierarchy]

`--world S` adds a uniform World of strength S (colour 0.5, 0.6, 0.8) and `--point` a Point light
(moving to `--point-to` by the last frame) to a copy of the scene, for the direct light's cases
(docs/benchmarks.md, "The direct light kept between frames": `demo-scene --kind cornell-light
--subdiv 14 --order 2` with `--frames 1:6 --world 1 --point 0.2,0.3,0.4,20`). The binaries come
from builds of the revisions to compare (e.g. `git worktree add` and `CARGO_TARGET_DIR=... cargo
build --release --bin galerkin-radiosity`).
"""

import argparse
import json
import statistics
import subprocess
import tempfile
from pathlib import Path


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("binaries", nargs="+")
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--frames", help="A:B, the frames to bake (default: the scene's)")
    p.add_argument("--world", type=float, help="add a uniform World of this strength")
    p.add_argument("--point", help="add a Point light: X,Y,Z,WATTS")
    p.add_argument("--point-to", help="with --point: move it to X,Y,Z by the scene's last frame")
    p.add_argument("--hierarchy", action="store_true", help="bake with --hierarchy")
    args = p.parse_args(argv)
    scene = json.loads(Path(args.scene).read_text())
    if args.frames:
        scene["frames"] = [int(x) for x in args.frames.split(":")]
    if args.world is not None:
        scene["world"] = {"color": [0.5, 0.6, 0.8], "strength": args.world, "animation": []}
    if args.point:
        x, y, z, watts = (float(v) for v in args.point.split(","))
        matrix = [1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z, 0, 0, 0, 1]
        light = {"name": "Point", "type": "POINT", "matrix": matrix, "color": [1, 1, 1], "power": watts}
        if args.point_to:
            first, last = scene["frames"]
            to = [float(v) for v in args.point_to.split(",")]
            light["animation"] = [{"frame": first, "position": [x, y, z]}, {"frame": last, "position": to}]
        scene.setdefault("lights", []).append(light)
    with tempfile.TemporaryDirectory() as tmp:
        path, out = Path(tmp) / "scene.json", Path(tmp) / "out.json"
        path.write_text(json.dumps(scene))
        print("| run | binary | frame s | kernel s | solve s | gather s |")
        print("|---|---|---|---|---|---|")
        for run in range(args.runs):
            for binary in args.binaries:
                cmd = [binary, "bake", str(path), "-o", str(out), "--quiet"]
                cmd += ["--hierarchy"] * args.hierarchy
                subprocess.run(cmd, check=True)
                stats = [f["stats"] for f in json.loads(out.read_text())["frames"][1:]]
                cells = [statistics.median(s[k] for s in stats)
                         for k in ("seconds", "kernel_seconds", "solve_seconds", "gather_seconds")]
                print(f"| {run + 1} | {binary} | " + " | ".join(f"{c:.4f}" for c in cells) + " |", flush=True)


if __name__ == "__main__":
    main()
