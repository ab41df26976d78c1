"""Plots for the README (issue 6): error against basis order (from a validation run) and time
per frame of the incremental method against full recompute (two CLI bakes of the demo scene,
run one after the other in this process).

    .venv/bin/python -m tools.plots --validation out/validation/validation.json --out docs
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

from .validate_cycles import REPO, cli, demo_scene


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--validation", default=str(REPO / "out" / "validation" / "validation.json"))
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--subdiv", type=int, default=8)
    p.add_argument("--out", default=str(REPO / "docs"))
    return p.parse_args(argv)


def frame_times(scene_file, out, method_flags):
    result = out / f"times{''.join(method_flags) or '-incremental'}.json"
    # The corner gather costs every method the same; the plot compares the methods.
    cmd = [str(cli()), "bake", str(scene_file), "-o", str(result), "--quiet", "--no-corner-gather"]
    subprocess.run([*cmd, *method_flags], check=True)
    frames = json.loads(result.read_text())["frames"]
    return [f["frame"] for f in frames], [f["stats"]["seconds"] for f in frames], frames


def run(args):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    work = REPO / "out" / "plots"
    work.mkdir(parents=True, exist_ok=True)
    scene_file = work / "scene.json"
    demo_scene(scene_file, args.frames, args.subdiv)
    series = {}
    for label, flags in [
        ("incremental (series)", []),
        ("exact update", ["--exact"]),
        ("full recompute", ["--full"]),
    ]:
        series[label] = frame_times(scene_file, work, flags)
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=110)
    for label, (frames, seconds, _) in series.items():
        ax.plot(frames, seconds, marker="o", ms=3, label=label)
    faces = series["full recompute"][2][0]["stats"]["elements"]
    ax.set_xlabel("frame")
    ax.set_ylabel("seconds per frame (2 cores)")
    ax.set_title(f"Demo animation, {faces} patches, order 2")
    ax.set_ylim(bottom=0)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "frame_times.png")
    summary = {label: sum(s[1:]) / max(len(s) - 1, 1) for label, (_, s, _) in series.items()}
    print("mean seconds per frame after the first: " + ", ".join(f"{k} {v:.2f}" for k, v in summary.items()))

    validation = Path(args.validation)
    if validation.exists():
        v = json.loads(validation.read_text())
        orders = [r["order"] for r in v["static"]]
        fig, ax = plt.subplots(figsize=(6, 3.2), dpi=110)
        ax.plot(orders, [100 * r["rmse"] for r in v["static"]], marker="o", label="all receivers")
        names = list(v["static"][0]["rmse_per_object"])
        for name in names:
            ax.plot(
                orders, [100 * r["rmse_per_object"][name] for r in v["static"]], ls="--", lw=1, label=name
            )
        ax.axhline(100 * v["reference_noise"], color="grey", lw=0.8, label="Cycles reference noise")
        ax.set_xlabel("basis order")
        ax.set_ylabel("relative RMSE vs Cycles (%)")
        ax.set_title(f"Cornell box, {v['faces']} faces")
        ax.set_xticks(orders)
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        fig.savefig(out / "error_vs_order.png")
    print(f"plots in {out}")
    return summary


def main(argv=None):
    run(parse(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    main()
