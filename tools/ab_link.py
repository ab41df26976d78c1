"""Interleaved A/B of the hierarchy's link phase between git revisions (issue 20): builds the CLI
at each revision (as `tools.ab` does, a worktree and target directory per revision under
`out/ab/`), bakes a scene file with `--hierarchy` by each build in turn `--runs` times, and prints
per revision the best and the median of the frame's link phase (`kernel_seconds`) and of the
whole frame, and whether every build's radiosities are identical to the first's. One thread by
default: this VM's speed drifts with its neighbours' load, and one thread is disturbed least.

    .venv/bin/python -m tools.ab_link 2df6d50 WORK [--scene tests/data/real/monastery_scene.json]
        [--runs 6] [--threads 1] [--order 1] [--gather]

The scene is baked at basis order `--order` with the corner gather off (`--gather`: on).
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from tools.ab import REPO, build_target


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("revs", nargs="+", help="git revisions (HEAD, a hash); WORK: the working tree")
    p.add_argument("--scene", default=str(REPO / "tests" / "data" / "real" / "monastery_scene.json"))
    p.add_argument("--runs", type=int, default=6)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--order", type=int, default=1)
    p.add_argument("--gather", action="store_true", help="keep the corner gather on")
    return p.parse_args(argv)


def main(argv):
    args = parse(argv)
    cli = "galerkin-radiosity"
    builds = {rev: build_target(rev, ["--bin", cli], cli) for rev in args.revs}
    with tempfile.TemporaryDirectory() as tmp:
        scene = json.loads(Path(args.scene).read_text())
        scene["settings"].update(basis_order=args.order, corner_gather=args.gather)
        scene_path = Path(tmp) / "scene.json"
        scene_path.write_text(json.dumps(scene))
        times = {rev: [] for rev in args.revs}
        frames = {}
        for r in range(args.runs):
            for rev, exe in builds.items():
                out = Path(tmp) / "out.json"
                cmd = [exe, "bake", str(scene_path), "-o", str(out), "--hierarchy", "--quiet"]
                subprocess.run(cmd + ["--threads", str(args.threads)], check=True)
                result = json.loads(out.read_text())
                stats = result["frames"][0]["stats"]
                times[rev].append((stats["kernel_seconds"], stats["seconds"]))
                for frame in result["frames"]:
                    frame.pop("stats", None)
                frames.setdefault(rev, result["frames"])
            print(f"run {r + 1} of {args.runs} done", file=sys.stderr)
    first = args.revs[0]
    print(
        f"{Path(args.scene).name}, order {args.order}, {args.threads} thread(s), "
        f"{args.runs} interleaved runs; s: best / median\n"
    )
    print("| build | link phase | frame | radiosities as the first build's |")
    print("|---|---|---|---|")
    for rev in args.revs:
        link, frame = (sorted(t[k] for t in times[rev]) for k in (0, 1))
        same = "yes" if frames[rev] == frames[first] else "no"
        cells = [f"{v[0]:.3f} / {statistics.median(v):.3f}" for v in (link, frame)]
        print(f"| {rev} | {cells[0]} | {cells[1]} | {same} |")


if __name__ == "__main__":
    main(sys.argv[1:])
