"""Solver tolerance against error and Delta-solve time on the moving-light Cornell box (issue 3):
bakes the animation with the CLI at several `tolerance` values and at a converged one (1e-7),
and prints per tolerance the worst and RMS corner difference to the converged bake, relative to
the mean radiosity of the non-emitting corners, and the mean shots and solve seconds per frame
after the first (from the frames' own stats).

    .venv/bin/python -m tools.tolerance_sweep [--frames 24] [--subdiv 14]
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .validate_cycles import cli, demo_scene


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=24, help="frames baked (of a 48-frame animation)")
    p.add_argument("--subdiv", type=int, default=14, help="Cornell walls split n x n (14: 1,079 patches)")
    p.add_argument("--tolerances", type=float, nargs="+", default=[1e-4, 3e-4, 1e-3])
    return p.parse_args(argv)


def bake(scene, tolerance, frames, tmp):
    """Per frame: the non-emitting corners' radiosity (flat array) and the frame's stats."""
    data = dict(scene, settings=dict(scene["settings"], tolerance=tolerance))
    path, out = Path(tmp) / f"scene-{tolerance}.json", Path(tmp) / f"out-{tolerance}.json"
    path.write_text(json.dumps(data))
    cmd = [str(cli()), "bake", str(path), "-o", str(out), "--quiet", "--no-corner-gather"]
    subprocess.run([*cmd, "--frames", f"1:{frames}"], check=True)
    emitting = {
        o["name"]
        for o in scene["objects"]
        if any(scene["materials"][m]["emission"] != [0, 0, 0] for m in set(o.get("face_materials", [])))
    }
    corners, stats = [], []
    for frame in json.loads(out.read_text())["frames"]:
        values = [np.ravel(o["corner_radiosity"]) for o in frame["objects"] if o["name"] not in emitting]
        corners.append(np.concatenate(values))
        stats.append(frame["stats"])
    return corners, stats


def main(argv=None):
    args = parse(argv if argv is not None else sys.argv[1:])
    with tempfile.TemporaryDirectory() as tmp:
        path = demo_scene(Path(tmp) / "cornell-light.json", 48, args.subdiv, kind="cornell-light")
        scene = json.loads(path.read_text())
        converged, _ = bake(scene, 1e-7, args.frames, tmp)
        patches = sum(len(o["faces"]) for o in scene["objects"])
        # The caption, then the table: docs/benchmarks.md's "tolerance" block (scripts/regenerate_docs.py).
        print(f"{args.frames} frames of the moving-light box ({patches} faces) baked by the CLI; corner "
              "differences to a converged bake (tolerance 1e-7), relative to the mean radiosity of the "
              "non-emitting corners, worst of the frames; shots and solve time per frame after the first:\n")
        print("| tolerance | worst corner / mean | RMS / mean | shots per frame | solve s per frame |")
        print("|---|---|---|---|---|")
        for tol in args.tolerances:
            corners, stats = bake(scene, tol, args.frames, tmp)
            worst = max(
                np.abs(a - b).max() / np.abs(b).mean() for a, b in zip(corners, converged, strict=True)
            )
            rms = max(
                np.sqrt(((a - b) ** 2).mean()) / np.abs(b).mean()
                for a, b in zip(corners, converged, strict=True)
            )
            later = stats[1:]
            shots = np.mean([s["shots"] for s in later])
            solve = np.mean([s["solve_seconds"] for s in later])
            label = f"{tol:.0e}".replace("e-0", "e-") + (" (default)" if tol == 1e-4 else "")
            print(f"| {label} | {worst:.2%} | {rms:.3%} | {shots:,.0f} | {solve:.3f} |")


if __name__ == "__main__":
    main()
