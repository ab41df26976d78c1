"""docs/benchmarks.md's generated blocks come from the commands that measure them
(scripts/regenerate_docs.py): run for real on the cheap cases, against a copy of the document."""

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("regenerate_docs", REPO / "scripts" / "regenerate_docs.py")
regen = importlib.util.module_from_spec(spec)
sys.modules["regenerate_docs"] = regen  # dataclasses look their module up there
spec.loader.exec_module(regen)


def _blocks(text):
    return {m["name"]: m["body"] for m in regen.BLOCK.finditer(text)}


def _header(body):
    return next(line for line in body.splitlines() if line.startswith("|"))


def test_every_block_has_a_command_and_every_command_a_block():
    blocks = _blocks(regen.DOC.read_text())
    assert set(blocks) == {name for name, t in regen.TABLES.items() if t is not None}


def test_the_validation_block_is_the_tools_table_of_the_stored_report(tmp_path):
    doc = tmp_path / "benchmarks.md"
    shutil.copy(regen.DOC, doc)
    new, bodies = regen.regenerate(["validation"], doc=doc, stored=True)
    table = subprocess.run([sys.executable, "-m", "tools.validate_cycles", "--table-from",
                            str(REPO / "docs" / "validation.json")], cwd=REPO, capture_output=True,
                           text=True, check=True).stdout.strip()
    assert bodies["validation"].strip().endswith(table)
    assert _blocks(new)["validation"] == bodies["validation"]
    # Only that block changed.
    before, after = regen.BLOCK.sub("", doc.read_text()), regen.BLOCK.sub("", new)
    assert before == after
    # The document's block prints the same table (it was regenerated from this report).
    assert _blocks(regen.DOC.read_text())["validation"].strip().endswith(table)


@pytest.mark.skipif(not (REPO / "target" / "release" / "galerkin-radiosity").exists(),
                    reason="needs the CLI: cargo build --release")
def test_the_tolerance_sweep_still_prints_the_table_its_block_wants(tmp_path):
    doc = tmp_path / "benchmarks.md"
    shutil.copy(regen.DOC, doc)
    _, bodies = regen.regenerate(["tolerance"], doc=doc, quick=True)
    body = bodies["tolerance"]
    assert "reduced case" in body
    assert _header(body) == _header(_blocks(regen.DOC.read_text())["tolerance"])
    rows = [line for line in body.splitlines() if line.startswith("| 1e-4") or line.startswith("| 3e-4")
            or line.startswith("| 1e-3")]
    assert len(rows) == 3



HIERARCHY = ("hierarchy-cornell", "hierarchy-presubdivided", "hierarchy-real", "hierarchy-separation",
             "hierarchy-light")


def _rows(body):
    """A block's table rows (header and rule dropped), as lists of cells."""
    lines = [line for line in body.splitlines() if line.startswith("|")][2:]
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in lines]


@pytest.mark.skipif(not any(p.is_file() and p.suffix == "" for p in (REPO / "target" / "release" / "deps")
                            .glob("hierarchy-*")) or shutil.which("cargo") is None,
                    reason="needs the hierarchy bench built: cargo bench --bench hierarchy --no-run "
                           "(scripts/test.sh does not build the benches)")
def test_the_hierarchy_bench_still_prints_the_documents_tables(tmp_path):
    doc = tmp_path / "benchmarks.md"
    shutil.copy(regen.DOC, doc)
    _, bodies = regen.regenerate(list(HIERARCHY), doc=doc, quick=True)
    in_doc = _blocks(regen.DOC.read_text())
    for name in HIERARCHY:
        assert "reduced case" in bodies[name]
        assert _header(bodies[name]) == _header(in_doc[name]), name
    # The reduced case's rows are rows of the full run: their counts and errors (not their
    # times or memory) are the document's. A difference means the hierarchy changed since the
    # blocks were written: regenerate them (see the section).
    for name in HIERARCHY:
        header = [c.strip() for c in _header(in_doc[name]).strip("|").split("|")]
        timed = {i for i, h in enumerate(header) if h in ("s", "CPU s", "peak RSS MiB")}
        documented = {row[0]: row for row in _rows(in_doc[name])}
        quick = _rows(bodies[name])
        assert quick, name
        for row in quick:
            assert row[0] in documented, (name, row[0])
            want = documented[row[0]]
            assert [c for i, c in enumerate(row) if i not in timed] == \
                [c for i, c in enumerate(want) if i not in timed], (name, row[0])


def test_the_test_stages_block_is_the_table_of_the_kept_log(tmp_path):
    log = (REPO / regen.STAGE_LOG).read_text()
    doc = tmp_path / "benchmarks.md"
    shutil.copy(regen.DOC, doc)
    new, bodies = regen.regenerate(["test-stages"], doc=doc, stored=True)
    table = subprocess.run([sys.executable, "scripts/regenerate_docs.py", "--stage-table", regen.STAGE_LOG],
                           cwd=REPO, capture_output=True, text=True, check=True).stdout.strip()
    assert bodies["test-stages"].strip().endswith(table)
    assert _blocks(regen.DOC.read_text())["test-stages"].strip().endswith(table)
    # One row per `-- STAGE: N s` line of scripts/test.sh, in its order; the stages add up to
    # no more than the total it printed.
    stages = [m for m in map(regen.STAGE_DONE.match, log.splitlines()) if m]
    rows = _rows(bodies["test-stages"])
    assert [r[0] for r in rows[:-1]] == [m["name"] for m in stages]
    total = int(next(m for m in map(regen.TOTAL.match, log.splitlines()) if m)["seconds"])
    assert sum(int(m["seconds"]) for m in stages) <= total
    assert rows[-1][1] == f"**{total // 60} m {total % 60:02d} s**"
    # The stage names are the ones scripts/test.sh prints today.
    script = (REPO / "scripts" / "test.sh").read_text()
    for m in stages:
        assert f'"{m["name"]}"' in script, m["name"]


def test_a_block_rewritten_while_the_commands_ran_is_kept(tmp_path):
    # Another regeneration writes the "validation" block while this one's command runs: the
    # result must splice into the file as it is after the command, not the copy read before.
    doc = tmp_path / "benchmarks.md"
    shutil.copy(regen.DOC, doc)
    stored_cmd = regen.TABLES["validation"].stored
    table = subprocess.run(stored_cmd, shell=True, cwd=REPO, capture_output=True, text=True,
                           check=True).stdout
    marker = "| written meanwhile |\n|---|\n"

    def run(cmd):
        text = doc.read_text()
        body = _blocks(text)["tolerance"]
        doc.write_text(text.replace(body, f"\n{marker}\n", 1))
        return table

    new, _ = regen.regenerate(["validation"], doc=doc, stored=True, run=run)
    assert marker in _blocks(new)["tolerance"]
