"""How true the CLI's progress lines are: the time left they announce against the time that was
left, and the longest wait between two lines (issue 24: a line at least every 2 s).

    python3 -m tools.time_left [SCENE.json] [--hierarchy] [--frames A:B] [--threads N]
                               [--at 0.1,0.25,...] [--stage links] [--cli PATH]

Runs ``target/release/galerkin-radiosity bake`` on the scene (default: the decimated monastery of
tests/data/real, one frame whose corner gather is nearly all of it) and stamps each line of its
stderr with the time it arrived. Afterwards each in-frame line's "N left" for the frame and for
the bake is set against the time the frame and the bake actually went on for. Prints a markdown
table at about a tenth, a quarter, a half, three quarters and nine tenths of the bake's wall time
(``--at``: other shares), or with ``--stage`` of the first stretch of lines of that stage (the
hierarchy's first frame: ``--stage links``, its link phase; one line a second, so give it a
scene whose stage lasts tens of seconds).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = ROOT / "target" / "release" / "galerkin-radiosity"
SCENE = ROOT / "tests" / "data" / "real" / "monastery_scene.json"

LINE = re.compile(r"^frame (?P<frame>-?\d+) \((?P<i>\d+)/(?P<n>\d+)\): (?P<stage>[^,]+), "
                  r"frame (?P<fp>\d+)%, (?P<fl>.+?) left; bake (?P<bp>\d+)%, (?P<spent>.+?) spent, "
                  r"(?P<bl>.+?) left$")
DONE = re.compile(r"^frame (?P<frame>-?\d+) \((?P<i>\d+)/(?P<n>\d+)\): (?P<s>[\d.]+) s, ")


def seconds(text: str) -> float | None:
    """The CLI's ``human``: ``1 h 02 m``, ``3 m 07 s``, ``12.3 s``; None for ``?``."""
    text = text.strip()
    if text == "?":
        return None
    if m := re.fullmatch(r"(\d+) h (\d+) m", text):
        return 3600 * int(m[1]) + 60 * int(m[2])
    if m := re.fullmatch(r"(\d+) m (\d+) s", text):
        return 60 * int(m[1]) + int(m[2])
    if m := re.fullmatch(r"([\d.]+) s", text):
        return float(m[1])
    raise ValueError(f"not a duration: {text!r}")


def said(text: str) -> str:
    """A line's "N left" as ``12.3 s`` (``?`` while unknown)."""
    x = seconds(text)
    return "?" if x is None else f"{x:.1f} s"


def run(scene: Path, extra: list[str], cli: Path = CLI) -> tuple[list[tuple[float, str]], float]:
    """The CLI's stderr lines, each with its arrival time from the start, and the wall time."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [str(cli), "bake", str(scene), "-o", str(Path(tmp) / "out.json"), *extra]
        print("run:", " ".join(cmd), file=sys.stderr)
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
        lines = [(time.perf_counter() - t0, line.rstrip("\n")) for line in proc.stderr]
        if proc.wait() != 0:
            raise SystemExit(f"time_left: the bake failed: {lines[-1][1] if lines else '?'}")
        return lines, time.perf_counter() - t0


SHARES = (0.1, 0.25, 0.5, 0.75, 0.9)


def stretch(lines: list[tuple[float, str]], stage: str | None, wall: float) -> tuple[float, float]:
    """When the first run of ``stage``'s lines starts and ends (the whole bake without one)."""
    if stage is None:
        return 0.0, wall
    times = []
    for t, text in lines:
        if m := LINE.match(text):
            if m["stage"] == stage:
                times.append(t)
            elif times:
                break
    if not times:
        raise SystemExit(f"time_left: no progress line of stage {stage!r}")
    return times[0], times[-1]


def table(lines: list[tuple[float, str]], wall: float, shares=SHARES,
          stage: str | None = None) -> tuple[str, str]:
    """The markdown table, and a line on the waits between progress lines: the lines nearest
    ``shares`` of the bake's wall time, or of the first run of ``stage``'s lines."""
    frame_end: dict[int, float] = {}   # the bake's frame index -> when its "done" line came
    for t, text in lines:
        if m := DONE.match(text):
            frame_end[int(m["i"])] = t
    readings = []
    for t, text in lines:
        if (m := LINE.match(text)) and int(m["i"]) in frame_end:
            readings.append((t, m, frame_end[int(m["i"])]))
    stamps = [t for t, text in lines if LINE.match(text) or DONE.match(text)]
    gaps = [b - a for a, b in zip([0.0, *stamps], stamps, strict=False)]
    rows = ["| at | stage | frame % | frame left said | was | bake % | bake left said | was |",
            "|---|---|---|---|---|---|---|---|"]
    start, stop = stretch(lines, stage, wall)
    for share in shares:
        if not readings:
            break
        t, m, end = min(readings, key=lambda r: abs(r[0] - (start + share * (stop - start))))
        fl, bl = said(m["fl"]), said(m["bl"])
        rows.append(f"| {t:.1f} s | {m['stage']} | {m['fp']} | {fl} | {end - t:.1f} s | {m['bp']} | "
                    f"{bl} | {wall - t:.1f} s |")
    longest = max(gaps) if gaps else float("nan")
    waits = f"{len(stamps)} progress lines, the longest wait between two (or before the first) " \
            f"{longest:.2f} s"
    return "\n".join(rows), waits


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", nargs="?", type=Path, default=SCENE)
    p.add_argument("--hierarchy", action="store_true")
    p.add_argument("--frames")
    p.add_argument("--threads")
    p.add_argument("--at", help="comma-separated shares of the wall time (of --stage's lines)")
    p.add_argument("--stage", help="take the shares of this stage's first stretch of lines")
    p.add_argument("--cli", type=Path, default=CLI, help="the CLI to run (another build's)")
    args = p.parse_args(argv)
    shares = tuple(float(x) for x in args.at.split(",")) if args.at else SHARES
    if not args.cli.exists():
        raise SystemExit(f"time_left: {args.cli} is missing: run cargo build --release first")
    extra = ["--hierarchy"] if args.hierarchy else []
    extra += ["--frames", args.frames] if args.frames else []
    extra += ["--threads", args.threads] if args.threads else []
    lines, wall = run(args.scene, extra, args.cli)
    name = args.scene.relative_to(ROOT) if args.scene.is_relative_to(ROOT) else args.scene
    rows, waits = table(lines, wall, shares, args.stage)
    flags = " ".join(extra)
    within = ""
    if args.stage:
        start, stop = stretch(lines, args.stage, wall)
        within = f"; the {args.stage} lines from {start:.1f} to {stop:.1f} s"
    print(f"The CLI's time left against the time that was left, `{name}`"
          f"{' ' + flags if flags else ''}, {wall:.1f} s wall{within}; {waits}:\n")
    print(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
