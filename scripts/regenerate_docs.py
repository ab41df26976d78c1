"""Rewrites the generated tables of docs/benchmarks.md from the commands that measure them.

    python3 scripts/regenerate_docs.py --list
    python3 scripts/regenerate_docs.py --section NAME [--section NAME ...] [--dry-run]
    python3 scripts/regenerate_docs.py --quick --section NAME     # the plumbing, on a reduced case
    python3 scripts/regenerate_docs.py --stored --section validation  # from the last run's report
    python3 scripts/regenerate_docs.py --stage-table LOG       # scripts/test.sh's log as a table

docs/benchmarks.md holds blocks

    <!-- BEGIN generated: NAME -->
    ...
    <!-- END generated: NAME -->

and TABLES below says which command prints each NAME's table: the benches and tools print their
tables in markdown themselves, each after a one-line caption. Each command named runs once, its
stdout is kept, and every block of that command is replaced by its caption and table, with a
line saying what made it, when, at which commit and under what load. Nothing outside the markers
is touched: the history around the blocks stays as it was written.

The benches take minutes and their timings depend on the machine's load: run them on a quiet
machine. ``--quick`` runs each section's reduced case instead (seconds) and, unless ``--doc``
names another file, only prints the blocks it would write: it checks that the command still
prints the table the block wants, without putting a reduced case's numbers into the document.
"""

from __future__ import annotations

import argparse
import datetime
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOC = REPO / "docs" / "benchmarks.md"
PY = ".venv/bin/python"


FRESH_LOG = "out/test-stages.log"
STAGE_LOG = "docs/test-stages.log"
# The lines of scripts/test.sh's output the stage table reads (kept in STAGE_LOG): its own
# `== STAGE` / `-- STAGE: N s` lines, cargo's and pytest's counts, and `# ` notes about the run.
STAGE_LINES = r"^(== |-- |# |test result: |[0-9]+ passed)"
STAGE_TABLE = f"python3 scripts/regenerate_docs.py --stage-table {STAGE_LOG}"
FRESH_RUN = " ".join([
    "rm -rf out/fresh-clone && git clone -q --no-checkout . out/fresh-clone",
    "&& git -C out/fresh-clone checkout -q $(git rev-parse HEAD)",
    f"&& (cd out/fresh-clone && CI=true bash .ci/run) > {FRESH_LOG} 2>&1;",
    '{ echo "# a fresh clone of $(git -C out/fresh-clone rev-parse --short HEAD)',
    'running CI=true bash .ci/run,',
    "$(date -u '+%Y-%m-%d %H:%M') UTC, $(nproc) cores\";",
    f"grep -E '{STAGE_LINES}' {FRESH_LOG}; }} > {STAGE_LOG}; {STAGE_TABLE}",
])


@dataclass(frozen=True)
class Table:
    command: str      # prints the table (and others)
    index: int        # which markdown table of its output: 0 = the first
    quick: str        # the same tables on a reduced case, to check the plumbing
    cost: str         # what a full run takes, for --list
    stored: str = ""  # prints the table of the last full run's saved report, measuring nothing


TABLES: dict[str, Table | None] = {
    "accuracy": None,  # assertions of the test suite, kept by hand (see the section)
    "scaling-static": Table("cargo bench --bench scaling", 0, "cargo bench --bench scaling -- --quick",
                            "about 1 min"),
    "scaling-demo": Table("cargo bench --bench scaling", 1, "cargo bench --bench scaling -- --quick",
                          "(the same run)"),
    "animation": Table("cargo bench --bench animation", 0, "cargo bench --bench animation -- --quick",
                       "about 5 min"),
    "animation-hierarchy": Table("cargo bench --bench animation", 1,
                                 "cargo bench --bench animation -- --quick", "(the same run)"),
    "box-methods": Table("cargo bench --bench animation -- --methods", 0,
                         "cargo bench --bench animation -- --methods --quick", "about 1 min"),
    "box-phases": Table("cargo bench --bench animation -- --methods", 1,
                        "cargo bench --bench animation -- --methods --quick", "(the same run)"),
    "box-gather": Table("cargo bench --bench animation -- --gather", 0,
                        "cargo bench --bench animation -- --gather --quick", "about 1 min"),
    "solve-mixing": Table("cargo bench --bench animation", 2,
                          "cargo bench --bench animation -- --quick", "(the same run)"),
    "touch-walk": Table("cargo bench --bench animation", 3,
                        "cargo bench --bench animation -- --quick", "(the same run)"),
    "store-compaction": Table("cargo bench --bench stores", 0, "cargo bench --bench stores -- --quick",
                              "about 30 s after a 1 min build"),
    "ab-moving-light": Table(f"{PY} -m tools.ab HEAD --exact HEAD --runs 5 --gather", 0,
                             f"{PY} -m tools.ab WORK --exact WORK --runs 1 --frames 4 --gather",
                             "a build of the revision, then about 3 min"),
    "hierarchy-cornell": Table("cargo bench --bench hierarchy", 0, "cargo bench --bench hierarchy -- --quick",
                               "about 5 s after a 1 min build"),
    "hierarchy-presubdivided": Table("cargo bench --bench hierarchy", 1,
                                     "cargo bench --bench hierarchy -- --quick", "(the same run)"),
    "hierarchy-real": Table("cargo bench --bench hierarchy", 2, "cargo bench --bench hierarchy -- --quick",
                            "(the same run)"),
    "hierarchy-separation": Table("cargo bench --bench hierarchy", 3,
                                  "cargo bench --bench hierarchy -- --quick", "(the same run)"),
    "hierarchy-light": Table("cargo bench --bench hierarchy", 4,
                             "cargo bench --bench hierarchy -- --quick", "(the same run)"),
    "gather-real": Table("cargo bench --bench gather", 0, "cargo bench --bench gather -- --quick",
                         "about 2 min"),
    # A fresh clone's `.ci/run` (= scripts/test.sh): its stage lines kept in docs/test-stages.log.
    "test-stages": Table(FRESH_RUN, 0, STAGE_TABLE, "about 8-10 min, both cores (a clone built from scratch)",
                         stored=STAGE_TABLE),
    "time-left": Table(f"{PY} -m tools.time_left", 0,
                       f"{PY} -m tools.time_left tests/data/real/bunny_scene.json --hierarchy",
                       "about 2.5 min (one core's worth of the CLI on both)"),
    "tolerance": Table(f"{PY} -m tools.tolerance_sweep", 0,
                       f"{PY} -m tools.tolerance_sweep --frames 4 --subdiv 6", "about 1.5 min"),
    "validation": Table(f"{PY} -m tools.validate_cycles --subdiv 12 --samples 4096 --pictures "
                        "&& cp out/validation/validation.json docs/validation.json", 0,
                        f"{PY} -m tools.validate_cycles --subdiv 3 --samples 64 --orders 0 1 --frames 4 "
                        "--anim-frame 2 --out out/validation-quick", "about 10 min (Cycles)",
                        stored=f"{PY} -m tools.validate_cycles --table-from docs/validation.json"),
}

BLOCK = re.compile(
    r"(<!-- BEGIN generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- END generated: (?P=name) -->)", re.S)

# Lines of cargo's and the tools' own chatter, never a caption.
NOT_CAPTIONS = ("run ", "Compiling", "Finished", "Running", "Cycles", "order ", "animated ", "moving light",
                "picture", "warning", "Radiosity:")


def tables(text: str) -> list[str]:
    """The markdown tables of a command's output, each with the non-blank line just above it
    as its caption (a markdown heading's marks dropped), when there is one."""
    out, cur, caption = [], [], ""

    def close():
        out.append("\n".join(([caption, ""] if caption else []) + cur))

    for line in text.splitlines():
        if line.startswith("|"):
            cur.append(line)
            continue
        if cur:
            close()
            cur, caption = [], ""
        if line.strip():
            text_ = line.strip().lstrip("#").strip()
            caption = "" if text_.startswith(NOT_CAPTIONS) else text_
    if cur:
        close()
    return out


STAGE_DONE = re.compile(r"^-- (?P<name>.+): (?P<seconds>\d+) s(?P<failed>, FAILED.*)?$")
STAGE_SKIPPED = re.compile(r"^-- (?P<name>.+): skipped(?P<why>.*)$")
CARGO_COUNT = re.compile(r"^test result: \w+\. (?P<passed>\d+) passed; (?P<failed>\d+) failed")
PYTEST_COUNT = re.compile(r"^(?P<passed>\d+) passed(?:, (?P<failed>\d+) failed)?.* in (?P<seconds>[\d.]+)s")
TOTAL = re.compile(r"^== all tests passed in (?P<seconds>\d+) s")


def _minutes(seconds: int) -> str:
    return f"{seconds // 60} m {seconds % 60:02d} s"


def stage_table(text: str) -> str:
    """scripts/test.sh's output (or its stage lines) as a caption and a markdown table: each
    stage's wall time from its `-- STAGE: N s` line, the tests it ran (cargo's `test result`
    lines, pytest's summary), and the total. `# ` lines are notes about the run, put in the
    caption."""
    notes, rows, tests, total = [], [], 0, None
    for line in text.splitlines():
        if line.startswith("# "):
            notes.append(line[2:].strip())
        elif m := CARGO_COUNT.match(line):
            tests += int(m["passed"])
        elif m := PYTEST_COUNT.match(line):
            tests += int(m["passed"])
        elif m := STAGE_DONE.match(line):
            rows.append((m["name"], f"{m['seconds']} s" + (" (FAILED)" if m["failed"] else ""),
                         f"{tests:,}" if tests else "", int(m["seconds"])))
            tests = 0
        elif m := STAGE_SKIPPED.match(line):
            rows.append((m["name"], "skipped" + m["why"], "", 0))
        elif m := TOTAL.match(line):
            total = int(m["seconds"])
    if not rows:
        raise SystemExit("regenerate_docs: error: no `-- STAGE: N s` lines (is it scripts/test.sh's output?)")
    done = f"all passed in {total} s ({_minutes(total)})" if total is not None else "did not pass"
    out = [f"Stages of `scripts/test.sh`, {done}{': ' + '; '.join(notes) if notes else ''}:", "",
           "| stage | wall | tests passed |", "|---|---|---|"]
    out += [f"| {name} | {wall} | {count} |" for name, wall, count, _ in rows]
    out.append(f"| **all** | **{_minutes(total) if total is not None else 'failed'}** | "
               f"{sum(int(c.replace(',', '')) for _, _, c, _ in rows if c):,} |")
    return "\n".join(out)


def revision() -> str:
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True).stdout.strip()
        return rev + ("+changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def load() -> str:
    try:
        return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    except OSError:
        return f"{os.cpu_count()} cores"


def run_command(cmd: str) -> str:
    proc = subprocess.run(cmd, shell=True, cwd=REPO, capture_output=True, text=True)
    if proc.returncode != 0:
        tail = " | ".join(proc.stderr.strip().splitlines()[-3:])
        raise SystemExit(f"regenerate_docs: error: `{cmd}` exited {proc.returncode}: {tail}")
    return proc.stdout


def regenerate(names: list[str], doc: Path = DOC, run=None, quick: bool = False,
               stored: bool = False) -> tuple[str, dict]:
    """The document with the blocks `names` rewritten, and the new bodies by name. Every command
    runs before anything is written: a failing one leaves the document as it was. `quick`: the
    reduced cases; `stored`: the tables of the saved reports of the last full runs."""
    run = run or run_command
    text = doc.read_text()
    present = {m["name"] for m in BLOCK.finditer(text)}
    for name in names:
        if name not in TABLES:
            raise SystemExit(f"regenerate_docs: error: unknown section {name!r}; known: {', '.join(TABLES)}")
        if TABLES[name] is None:
            raise SystemExit(f"regenerate_docs: error: {name!r} is written by hand (see its section)")
        if name not in present:
            raise SystemExit(f"regenerate_docs: error: no block '{name}' in {doc}")
        if stored and not TABLES[name].stored:
            raise SystemExit(f"regenerate_docs: error: '{name}' keeps no report to print "
                             "(run it, or --quick)")
    outputs: dict[str, str] = {}
    when = f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, commit {revision()}"
    stamp = f"{when}, {load()}"
    bodies: dict[str, str] = {}
    for name in names:
        t = TABLES[name]
        cmd = t.quick if quick else t.stored if stored else t.command
        if cmd not in outputs:
            print(f"running: {cmd}", file=sys.stderr, flush=True)
            outputs[cmd] = run(cmd)
        found = tables(outputs[cmd])
        if t.index >= len(found):
            raise SystemExit(f"regenerate_docs: error: `{cmd}` printed {len(found)} table(s), "
                             f"block '{name}' wants number {t.index + 1}")
        what = ("reduced case, not for the document" if quick else
                f"from the report of the last full run, `{t.command}`; printed {when}" if stored else stamp)
        bodies[name] = f"_Generated by `{cmd}` ({what})._\n\n{found[t.index]}\n"

    def replace(m):
        name = m["name"]
        return m.group(1) + bodies[name] + m.group(4) if name in bodies else m.group(0)

    # The commands take minutes, and another regeneration may have rewritten the document
    # meanwhile: splice into the file as it is now, not the copy read before they ran (a stale
    # copy once overwrote another section's new block).
    text = doc.read_text()
    missing = [name for name in names if name not in {m["name"] for m in BLOCK.finditer(text)}]
    if missing:
        raise SystemExit(f"regenerate_docs: error: block(s) {', '.join(missing)} gone from {doc} "
                         "while the commands ran")
    return BLOCK.sub(replace, text), bodies


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("names", nargs="*", help="sections to regenerate (as --section)")
    p.add_argument("--section", action="append", default=[], metavar="NAME",
                   help="a section to regenerate (repeatable); --list names them")
    p.add_argument("--list", action="store_true", help="list the sections, their commands and costs")
    p.add_argument("--dry-run", action="store_true", help="print the regenerated blocks, write nothing")
    p.add_argument("--quick", action="store_true",
                   help="run the reduced cases; prints the blocks unless --doc names a file to write")
    p.add_argument("--stored", action="store_true",
                   help="print the tables from the last full runs' saved reports "
                        "(validation: docs/validation.json)")
    p.add_argument("--stage-table", type=Path, metavar="LOG",
                   help="print scripts/test.sh's output (or its stage lines) in LOG as a table, and exit")
    p.add_argument("--doc", type=Path, help=f"the document to rewrite (default {DOC.relative_to(REPO)})")
    args = p.parse_args(argv)
    if args.stage_table:
        print(stage_table(args.stage_table.read_text()))
        return 0
    names = list(dict.fromkeys(args.names + args.section))
    if args.list or not names:
        for name, t in TABLES.items():
            print(f"{name:16} {f'{t.command}   [{t.cost}]' if t else '(by hand)'}")
        return 0
    doc = args.doc or DOC
    if args.quick and args.stored:
        p.error("--quick and --stored exclude each other")
    new, bodies = regenerate(names, doc=doc, quick=args.quick, stored=args.stored)
    if args.dry_run or (args.quick and args.doc is None):
        for name, body in bodies.items():
            print(f"<!-- BEGIN generated: {name} -->\n{body}<!-- END generated: {name} -->\n")
        return 0
    doc.write_text(new)
    print(f"rewrote {', '.join(names)} in {doc}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
