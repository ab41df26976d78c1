"""What a bake costs through the add-on: the README's "Large Scenes (Hierarchy)" table.

    .venv/bin/python -m tools.addon_cost [--walls 20 --walls 40] [--method HIERARCHICAL]
        [--sharp-corners on --sharp-corners off] [--lib PATH]

Builds the test suite's Cornell box (``tests/python/scenes.py``: six walls of n x n faces, a
0.5 x 0.5 ceiling light keyframed across the room and a block sliding across the floor, both
over two frames) under the bpy module, bakes both frames with the real bake operator (Detail 2,
Medium, the panel's defaults otherwise) and prints one table row per case: the seconds of each
frame as the add-on logs them, and the peak memory over what ``bpy`` held with the scene built.
Each case runs in its own process, so that every peak is its own.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def one_case(walls: int, method: str, sharp_corners: bool) -> None:
    """Runs in the child process: bakes one case and prints its figures on one line."""
    sys.path[:0] = [str(REPO), str(REPO / "tests" / "python")]
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="blender-user-"))
    import bpy
    import scenes

    import addon

    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scenes.cornell_box(bpy, n=walls, light_frames=(1, 2))
    faces = sum(len(o.data.polygons) for o in bpy.data.objects if o.type == "MESH")
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    start = time.perf_counter()
    error = ""
    try:
        scenes.bake(bpy, method=method, corner_gather=sharp_corners)
    except RuntimeError as e:
        error = str(e).splitlines()[-1]
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"CASE faces={faces} seconds={time.perf_counter() - start:.2f} over={peak - base:.0f} "
          f"error={error}", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--walls", type=int, action="append", help="faces per wall side (default 20 and 40)")
    p.add_argument("--method", default="HIERARCHICAL", help="the panel's Method (INCREMENTAL, HIERARCHICAL)")
    p.add_argument("--sharp-corners", action="append", choices=["on", "off"])
    p.add_argument("--lib", help="the libgalerkin_radiosity.so to load (default: the checkout's build)")
    p.add_argument("--case", nargs=3, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.case:
        one_case(int(a.case[0]), a.case[1], a.case[2] == "on")
        return
    env = dict(os.environ)
    if a.lib:
        env["GALERKIN_RADIOSITY_LIB"] = a.lib
    print(f"The test Cornell box through the add-on, {a.method}, two frames, Detail 2, Medium; "
          "memory is the peak over bpy's with the scene built:\n")
    print("| faces | Sharp Corners | frame 1, frame 2 | memory |")
    print("|---|---|---|---|")
    for walls in a.walls or [20, 40]:
        for corners in a.sharp_corners or ["on", "off"]:
            case_args = ["--case", str(walls), a.method, corners]
            command = [sys.executable, "-m", "tools.addon_cost", *case_args]
            out = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True).stdout
            frames = re.findall(r"Radiosity: frame \d+ done \(\d+/\d+\) in ([0-9.]+) s", out)
            case = re.search(r"CASE faces=(\d+) seconds=\S+ over=(\S+) error=(.*)", out)
            if case is None:
                print(f"| ? | {corners} | the case failed | |")
                continue
            faces, over, error = int(case.group(1)), float(case.group(2)), case.group(3)
            times = ", ".join(f"{float(s):.1f} s" for s in frames) or error
            print(f"| {faces:,} | {corners} | {times} | {over:.0f} MB |")


if __name__ == "__main__":
    main()
