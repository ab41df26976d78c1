"""Interleaved A/B of the animation update between git revisions (issue 3): builds
`benches/kernel_update` at each revision (a git worktree and target directory per revision,
under `out/ab/`), runs the builds in turn `--runs` times, and prints per revision the median,
25th percentile and best of each frame's times pooled over the runs. This VM's speed drifts by
30-50% within minutes, so builds are only comparable measured this way.

    .venv/bin/python -m tools.ab 7244f93 HEAD [--runs 5] [--frames 16] [--demo] [--exact REV] [--gather]
        [--bench-arg=--order --bench-arg=3 ...]

A revision given as `--exact REV` is run with `--exact` (the update without the series).
`--bench-arg` passes an option on to every run of `kernel_update` (`--order 3`, `--fixed-rule`:
the settings where a quadrature is dear, so that the default method uses the series).
`--gather` runs the corner gather after each frame, as the CLI, the C ABI and the add-on do by
default, and adds its time and the whole frame (kernel + solve + gather). The worktrees and
builds are kept for the next comparison; `rm -rf out/ab && git worktree prune` removes them.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# Columns of the kernel_update table read (by their headers, without " s"); "gather" with --gather.
COLUMNS = ["kernel", "scan", "pairs", "apply", "solve"]


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("revs", nargs="*", help="git revisions (HEAD, a hash); WORK: the working tree")
    p.add_argument("--exact", action="append", default=[], help="a revision to run with --exact")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--demo", action="store_true", help="the demo animation instead of the moving light")
    p.add_argument("--gather", action="store_true", help="also the corner gather after each frame")
    p.add_argument("--bench-arg", action="append", default=[], help="an option for every kernel_update run")
    args = p.parse_args(argv)
    if len(args.revs) + len(args.exact) < 1:
        p.error("give at least one revision")
    return args


def build(rev):
    """The kernel_update bench built at `rev` ('WORK': the working tree); its executable."""
    return build_target(rev, ["--bench", "kernel_update"], "kernel_update")


def build_target(rev, cargo_args, name):
    """`cargo build --release CARGO_ARGS` at `rev` ('WORK': the working tree, else a worktree and
    target directory of its own under out/ab/); the executable of the target `name`."""
    if rev == "WORK":
        tree, target = REPO, REPO / "target"
    else:
        commit = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", rev], check=True, capture_output=True, text=True
        ).stdout.strip()
        tree, target = REPO / "out" / "ab" / commit, REPO / "out" / "ab" / f"{commit}-target"
        if not tree.exists():
            add = ["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), commit]
            subprocess.run(add, check=True)
    out = subprocess.run(
        ["cargo", "build", "--release", *cargo_args, "--message-format=json"],
        cwd=tree,
        env={**os.environ, "CARGO_TARGET_DIR": str(target)},
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    for line in out.splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg["target"]["name"] == name:
            if msg.get("executable"):
                return msg["executable"]
    sys.exit(f"no {name} executable built at {rev}")


def columns(args):
    return COLUMNS + (["gather"] if args.gather else [])


def frames(executable, args, exact):
    """Per frame after the first: the table's time columns (`columns(args)`), in seconds."""
    cmd = [executable, "--frames", str(args.frames)]
    cmd += (["--demo"] if args.demo else []) + (["--exact"] if exact else [])
    cmd += (["--gather"] if args.gather else []) + args.bench_arg
    table = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    rows, header = [], None
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == "frame":
            header = {name.removesuffix(" s"): k for k, name in enumerate(cells)}
        elif cells[0].isdigit() and header is not None:
            rows.append([float(cells[header[name]]) for name in columns(args)])
    if not rows:
        sys.exit(f"no frames in the output of {' '.join(cmd)}")
    return rows


def main(argv):
    args = parse(argv)
    runs = [(rev, False) for rev in args.revs] + [(rev, True) for rev in args.exact]
    builds = {(rev, exact): build(rev) for rev, exact in runs}
    pooled = {key: [] for key in runs}
    for r in range(args.runs):
        for key in runs:
            pooled[key] += frames(builds[key], args, key[1])
        print(f"run {r + 1} of {args.runs} done", file=sys.stderr)
    # Derived columns: sums of read ones, per frame.
    read = columns(args)
    derived = [("frame (kernel + solve)", ["kernel", "solve"])]
    if args.gather:
        derived.append(("frame + gather", ["kernel", "solve", "gather"]))
    names = read + [name for name, _ in derived]
    print(f"{args.runs} interleaved runs of {args.frames - 1} frames each; ms: median / p25 / best\n")
    print("| build | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for (rev, exact), rows in pooled.items():
        series = [[row[k] for row in rows] for k in range(len(read))]
        series += [[sum(row[read.index(p)] for p in parts) for row in rows] for _, parts in derived]
        cells = []
        for v in map(sorted, series):
            cells.append(f"{1e3 * statistics.median(v):.1f} / {1e3 * v[len(v) // 4]:.1f} / {1e3 * v[0]:.1f}")
        print(f"| {rev}{' --exact' if exact else ''} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
