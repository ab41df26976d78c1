"""Issue 24, item 4: progress that only grows, with the time spent and left, in the add-on's
status bar and window progress, in the synchronous operator, and in the headless script.

The meter's arithmetic is checked by hand (as src/progress.rs's tests do); the rest runs real
bakes through the add-on: the modal operator's timer ticks (on a stand-in operator instance,
since no event loop runs headless) against the real window manager and workspace, the
synchronous operator, and headless.py as a separate process whose stdout is parsed.
"""

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import scenes

from addon.core.progress import Lines, Meter, human, share

REPO = Path(__file__).resolve().parents[2]
HEADLESS = REPO / "addon" / "headless.py"


# -- the meter (no bpy) ----------------------------------------------------------------------


def test_the_fraction_never_falls_back_across_stages():
    m = Meter(2, now=0.0)
    last = 0.0
    for f, stage in [(0.5, "kernel"), (1.0, "kernel"), (1.0, "solve"), (0.0, "corner gather"),
                     (0.7, "corner gather"), (0.2, "solve"), (0.1, "kernel update")]:
        r = m.report(f, stage, 0.0)
        assert r.frame_fraction >= last, (stage, f)
        last = r.frame_fraction
    # The largest reading, corner gather at 0.7, is kept: 0.55 + 0.45 * 0.7 of frame 1 of 2.
    assert last == pytest.approx(0.55 + 0.45 * 0.7)
    assert m.reading(0.0).bake_fraction == pytest.approx((0.55 + 0.45 * 0.7) / 2)


def test_the_shares_are_the_cli_ones_and_cover_a_frame():
    stages = ["kernel", "solve", "corner gather"]
    ends = [sum(share(s)) for s in stages]
    assert [share(s)[0] for s in stages] == [0.0] + ends[:-1]
    assert ends[-1] == pytest.approx(1.0)
    assert share("kernel update") == share("kernel")


def test_a_frame_without_a_gather_is_mostly_its_links():
    # As src/progress.rs's a_frame_without_a_gather_is_mostly_its_links.
    for stages in (["kernel", "solve"], ["links", "hierarchy"]):
        ends = [sum(share(s, gathers=False)) for s in stages]
        assert [share(s, gathers=False)[0] for s in stages] == [0.0] + ends[:-1]
        assert ends[-1] == pytest.approx(1.0)
    m = Meter(1, now=0.0, gathers=False)
    m.report(0.0, "links", 0.0)
    r = m.report(0.5, "links", 10.0)
    assert r.frame_fraction == pytest.approx(0.45)
    assert r.frame_left == pytest.approx(10.0 + 0.1 * 10.0 / 0.45)
    assert Meter(1, now=0.0).report(0.5, "links", 10.0).frame_fraction == pytest.approx(0.225)


def test_time_left_follows_the_rate_then_the_finished_frames():
    m = Meter(3, now=0.0)
    assert m.report(0.0, "kernel", 0.0).bake_left is None
    # The gather starts 11 s into the first frame, 55% of it: 11 x 45/55 s left of the frame,
    # and each of the two frames after it expected to take as long as this one.
    r = m.report(0.0, "corner gather", 11.0)
    assert r.frame_fraction == pytest.approx(0.55)
    assert r.frame_left == pytest.approx(11.0 * 0.45 / 0.55)
    assert r.bake_left == pytest.approx(r.frame_left + 2 * (11.0 + r.frame_left))
    assert r.elapsed == 11.0
    # The first frame took 20 s: the two left are expected at that mean.
    m.frame_done(20.0)
    r = m.report(0.0, "kernel update", 20.0)
    assert r.frame_left is None and r.bake_left == pytest.approx(40.0)
    assert r.bake_fraction == pytest.approx(1 / 3)
    m.frame_done(30.0)
    m.frame_done(40.0)
    r = m.reading(40.0)
    assert r.bake_fraction == 1.0 and r.bake_left == 0.0
    assert (human(3725), human(187), human(12.34), human(None)) == ("1 h 02 m", "3 m 07 s", "12.3 s", "?")


def test_the_next_frame_of_a_kind_is_measured_by_the_last_ones_stages():
    # As src/progress.rs's test: a frame whose gather took 90% of it (the monastery's) makes the
    # next frame of its kind map the gather onto 90% of the frame.
    m = Meter(3, now=0.0)
    m.report(0.0, "kernel", 0.0)
    m.report(1.0, "kernel", 1.0)
    m.report(0.0, "solve", 1.0)
    m.report(0.0, "corner gather", 2.0)
    m.frame_done(20.0)
    m.report(0.0, "kernel", 20.0)
    r = m.report(0.0, "corner gather", 22.0)
    assert r.frame_fraction == pytest.approx(0.1)
    assert r.frame_left == pytest.approx(18.0)
    assert m.report(0.5, "corner gather", 31.0).frame_fraction == pytest.approx(0.55)
    # An incremental frame, another kind, starts from the fixed shares.
    m.frame_done(40.0)
    assert m.report(0.5, "kernel update", 41.0).frame_fraction == pytest.approx(0.5 * 0.45)
    assert m.report(0.0, "corner gather", 42.0).frame_fraction == pytest.approx(0.55)


class _Sink:
    """A terminal for ``Lines``: what was written, as text."""

    def __init__(self):
        self.parts: list[str] = []

    def write(self, text):
        self.parts.append(text)

    def flush(self):
        pass

    def lines(self) -> list[str]:
        return [s for s in "".join(self.parts).splitlines() if s]


def test_lines_inside_a_frame_come_at_most_every_interval():
    sink = _Sink()

    t = [0.0]
    lines = Lines(2, interval=1.0, out=sink, clock=lambda: t[0])
    for i in range(31):  # 3 s of reports every 0.1 s: a line at 1, 2 and 3 s
        t[0] = 0.1 * i
        lines.listen({"kind": "progress", "frame": 1, "fraction": i / 30, "stage": "corner gather"})
    t[0] = 3.5
    lines.listen({"kind": "frame", "frame": 1, "seconds": 3.5})
    text = sink.lines()
    assert len(text) == 4, text
    assert text[-1] == "Radiosity: frame 1 done (1/2) in 3.50 s; bake 50%, 3.5 s spent, about 3.5 s left"


def test_the_time_left_follows_the_running_stage_at_its_own_rate():
    # As src/progress.rs's test: a gather guessed at 45% of the frame that is all of it.
    m = Meter(1, now=0.0)
    m.report(1.0, "kernel", 1.0)
    m.report(0.0, "corner gather", 2.0)
    assert m.report(0.25, "corner gather", 12.0).frame_left == pytest.approx(30.0)
    m = Meter(1, now=0.0)
    m.report(0.0, "kernel", 0.0)
    assert m.report(0.5, "kernel", 4.0).frame_left == pytest.approx(4.0 + 0.55 * 4.0 / (0.45 * 0.5))
    f = 0.55 + 0.45 * 0.01
    assert m.report(0.01, "corner gather", 5.0).frame_left == pytest.approx(5.0 * (1 - f) / f)


def test_the_heartbeat_repeats_the_line_while_the_library_is_silent():
    sink = _Sink()
    lines_printed = sink.lines

    # On a fake clock: one report, then silence (a slow corner); tick() gives a line once the
    # interval passed since the last, with the time spent moving on, and none between frames.
    t = [0.0]
    lines = Lines(2, interval=1.0, out=sink, clock=lambda: t[0])
    lines.listen({"kind": "progress", "frame": 7, "fraction": 0.5, "stage": "corner gather"})
    for now in (0.5, 0.99):
        t[0] = now
        lines.tick()
    assert lines_printed() == []
    t[0] = 2.0
    lines.tick()
    t[0] = 2.5
    lines.tick()
    # At 2 s the gather, the last stage, is half done after 2 s of it: 2 s left, and the next
    # frame is expected to take 4 s.
    assert lines_printed() == ["Radiosity: frame 7 (1/2): corner gather, frame 78%, 2.0 s left; "
                               "bake 39%, 2.0 s spent, about 6.0 s left"]
    t[0] = 5.0
    lines.tick()
    assert "5.0 s spent" in lines_printed()[-1]
    lines.listen({"kind": "frame", "frame": 7, "seconds": 5.0})
    n = len(lines_printed())
    t[0] = 9.0
    lines.tick()
    assert len(lines_printed()) == n, "no frame is running: nothing to repeat"

    # The thread, on the real clock: a report, then 1 s of silence at an interval of 0.1 s.
    sink.parts.clear()
    lines = Lines(1, interval=0.1, out=sink)
    with lines.heartbeat():
        lines.listen({"kind": "progress", "frame": 1, "fraction": 0.2, "stage": "links"})
        time.sleep(1.0)
    got = len(lines_printed())
    assert got >= 3, lines_printed()
    time.sleep(0.3)
    assert len(lines_printed()) == got, "the thread stops with the block"


# -- the modal operator's ticks, against the real window manager --------------------------------


class _Recording:
    """The real window manager and workspace, with what the operator set recorded."""

    def __init__(self, bpy):
        self.wm, self.ws = bpy.context.window_manager, bpy.context.workspace
        self.values, self.texts = [], []

    def progress_begin(self, a, b):
        self.wm.progress_begin(a, b)

    def progress_update(self, value):
        self.values.append(value)
        self.wm.progress_update(value)

    def progress_end(self):
        self.wm.progress_end()

    def event_timer_remove(self, timer):
        pass

    def status_text_set(self, text):
        self.texts.append(text)
        self.ws.status_text_set(text)


def _modal(bpy, rec):
    from addon.operators import RADIOSITY_OT_bake as Op

    class Harness:
        _begin_frame, _solve, _end, _report_end, _make_job, modal = (
            Op._begin_frame, Op._solve, Op._end, Op._report_end, Op._make_job, Op.modal)
        _timer = _thread = None

        def report(self, kind, text):
            pass

    class Ctx:
        scene, view_layer = bpy.context.scene, bpy.context.view_layer
        window_manager = workspace = rec
        area = None

        def evaluated_depsgraph_get(self):
            return bpy.context.evaluated_depsgraph_get()

    return Harness(), Ctx()


class _Timer:
    type, value = "TIMER", "NOTHING"


def test_the_status_bar_progress_grows_to_100_percent_with_the_time_left(blender):
    bpy = blender
    objs = scenes.cornell_box(bpy, n=6, light_frames=(1, 3), box=True)
    bpy.context.scene.radiosity.basis_order = 2
    rec = _Recording(bpy)
    op, ctx = _modal(bpy, rec)
    op._job = op._make_job(ctx, verbose=False)
    op._job.start()
    assert op._begin_frame(ctx)
    result, deadline = {"RUNNING_MODAL"}, time.time() + 120
    while result == {"RUNNING_MODAL"} and time.time() < deadline:
        result = op.modal(ctx, _Timer())
        time.sleep(0.005)
    assert result == {"FINISHED"}
    assert scenes.rad_frames(objs["Floor"].data) == [1, 2, 3]
    v = rec.values
    assert all(a <= b for a, b in zip(v, v[1:], strict=False)), v
    assert v[-1] == 1000
    # Shown inside frames too, not only at their ends (thirds of the bake).
    assert any(x not in (0, 333, 666, 1000) for x in v), v
    texts = [t for t in rec.texts if t]
    assert texts[0].startswith("Radiosity: frame 1 (1/3): ")
    # Once a frame is done, the bake's time left is an estimate, not '?'.
    later = [t for t in texts if "(2/3)" in t]
    assert later and all(re.search(r"spent, \d+\.\d s left \| Esc: cancel$", t) for t in later), later
    assert rec.texts[-1] is None  # cleared at the end


# -- the synchronous operator and the headless script -------------------------------------------

DONE = re.compile(r"^Radiosity: frame (\d+) done \((\d+)/(\d+)\) in ([\d.]+) s; bake (\d+)%, "
                  r"(.+) spent, about (.+) left$")
INSIDE = re.compile(r"^Radiosity: frame (\d+) \((\d+)/(\d+)\): ([a-z ]+), frame (\d+)%, (.+) left; "
                    r"bake (\d+)%, (.+) spent, about (.+) left$")


def _seconds(text):
    m = re.fullmatch(r"(\d+\.\d) s", text)
    assert m, f"not a time below a minute: {text!r}"
    return float(m[1])


def _check_done_lines(lines, frames):
    done = [DONE.match(s) for s in lines if DONE.match(s)]
    assert [int(m[1]) for m in done] == frames
    n = len(frames)
    assert [(int(m[2]), int(m[3])) for m in done] == [(i + 1, n) for i in range(n)]
    percent = [int(m[5]) for m in done]
    assert percent == [round(100 * (i + 1) / n) for i in range(n)]
    spent = [_seconds(m[6]) for m in done]
    assert spent == sorted(spent)
    assert _seconds(done[-1][7]) == 0.0


def test_the_synchronous_operator_prints_a_line_per_frame(blender, capsys):
    bpy = blender
    scenes.cornell_box(bpy, n=3, light_frames=(1, 3), box=False)
    bpy.context.scene.radiosity.basis_order = 1
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    _check_done_lines(capsys.readouterr().out.splitlines(), [1, 2, 3])


def _headless(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path))
    return subprocess.run([sys.executable, str(HEADLESS), *args], capture_output=True, text=True,
                          timeout=300, env=env)


def test_headless_prints_monotone_progress_a_line_per_frame_and_a_summary(blender, tmp_path):
    bpy = blender
    scenes.cornell_box(bpy, n=6, light_frames=(1, 4), box=True)
    src, out = tmp_path / "in.blend", tmp_path / "out.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    # Checkpoints every 2 frames: the bake runs as two jobs, counted as one bake of 4 frames;
    # a progress line at every report of the library.
    proc = _headless(["--blend", str(src), "--frames", "1-4", "--order", "2", "--save", str(out),
                      "--checkpoint", "2", "--progress-interval", "0"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    _check_done_lines(lines, [1, 2, 3, 4])
    inside = [INSIDE.match(s) for s in lines if INSIDE.match(s)]
    assert {int(m[1]) for m in inside} == {1, 2, 3, 4}
    assert {m[4] for m in inside} >= {"kernel", "corner gather"}
    # Monotone: the bake's percentage over the whole run, the frame's within each frame.
    bake_percent = [int(m[7]) if m.re is INSIDE else int(m[5])
                    for m in (INSIDE.match(s) or DONE.match(s) for s in lines) if m]
    assert bake_percent == sorted(bake_percent) and bake_percent[-1] == 100
    for f in (1, 2, 3, 4):
        frame_percent = [int(m[5]) for m in inside if int(m[1]) == f]
        assert frame_percent == sorted(frame_percent), (f, frame_percent)
    # Estimates once something is known: the bake's time left is a time after frame 1.
    assert all(m[9] != "?" for m in inside if int(m[2]) > 1)
    assert lines[-1].startswith("Radiosity: summary: solved 4 of 4 frame(s) in ")
    assert re.search(r" s a frame$", lines[-1]), lines[-1]
    assert out.exists()
