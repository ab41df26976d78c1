"""Issue 23, item 5: a headless bake stops cleanly on SIGINT, keeps and saves its complete frames,
and ``--resume`` goes on from there to the same result as an uninterrupted bake."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scenes

REPO = Path(__file__).resolve().parents[2]
HEADLESS = REPO / "addon" / "headless.py"
FRAMES = list(range(1, 13))


def _cmd(args):
    return [sys.executable, str(HEADLESS), *args]


def _solved(stdout):
    return [int(m) for m in re.findall(r"Radiosity: frame (\d+) done", stdout)]


def _env(tmp_path):
    e = dict(os.environ)
    e["BLENDER_USER_RESOURCES"] = str(tmp_path)
    e["PYTHONUNBUFFERED"] = "1"
    return e


def test_sigint_keeps_complete_frames_and_resume_matches_an_uninterrupted_bake(blender, tmp_path):
    src = tmp_path / "in.blend"
    scenes.cornell_box(blender, n=4, light_frames=(1, 12))
    blender.ops.wm.save_as_mainfile(filepath=str(src))
    # Every frame from scratch, so the resumed frames are computed as the uninterrupted ones are.
    common = ["--blend", str(src), "--frames", "1-12", "--order", "1", "--quality", "medium",
              "--method", "full", "--checkpoint", "3"]
    ref, out = tmp_path / "ref.blend", tmp_path / "out.blend"
    done = subprocess.run(_cmd([*common, "--save", str(ref)]), capture_output=True, text=True,
                          timeout=600, env=_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert "colours for frames 1-12" in done.stdout

    proc = subprocess.Popen(_cmd([*common, "--save", str(out)]), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(tmp_path))
    lines = []
    deadline = time.monotonic() + 300
    for line in proc.stdout:
        lines.append(line)
        if "Radiosity: frame 4 done" in line:
            proc.send_signal(signal.SIGINT)
            break
        assert time.monotonic() < deadline, "".join(lines)
    rest, err = proc.communicate(timeout=120)
    stdout = "".join(lines) + rest
    assert proc.returncode == 128 + signal.SIGINT, stdout + err
    assert "Radiosity: interrupted by SIGINT, complete frames kept" in stdout, stdout
    assert "Traceback" not in err, err
    assert "frame 12 done" not in stdout, "the bake was not interrupted"
    assert out.exists()

    resumed = subprocess.run(_cmd([*common, "--save", str(out), "--resume"]), capture_output=True,
                             text=True, timeout=600, env=_env(tmp_path))
    assert resumed.returncode == 0, resumed.stderr
    assert f"resuming {out}" in resumed.stdout
    # The frames solved before the interrupt were kept, not solved again: each frame solved once.
    before, after = _solved(stdout), _solved(resumed.stdout)
    assert before and not set(before) & set(after), (before, after)
    assert sorted(before + after) == FRAMES, (before, after)
    assert "colours for frames 1-12" in resumed.stdout

    names = ["Floor", "Ceiling", "Left", "Right"]
    a = scenes.evaluate_in_fresh_process(ref, names, FRAMES)
    b = scenes.evaluate_in_fresh_process(out, names, FRAMES)
    for f in map(str, FRAMES):
        for name in names:
            x, y = np.asarray(a["frames"][f][name]), np.asarray(b["frames"][f][name])
            assert x.shape == y.shape and x.size > 0
            np.testing.assert_allclose(y, x, rtol=1e-5, atol=1e-7, err_msg=f"frame {f} {name}")


def test_a_killed_bake_keeps_its_last_checkpoint(blender, tmp_path):
    """SIGKILL (nothing can be saved then): the file saved at the last ``--checkpoint`` holds the
    frames before it, and ``--resume`` solves only the frames after them. (Saving only at the end
    lost every frame: the resume solved all twelve.)"""
    src = tmp_path / "in.blend"
    scenes.cornell_box(blender, n=4, light_frames=(1, 12))
    blender.ops.wm.save_as_mainfile(filepath=str(src))
    out = tmp_path / "out.blend"
    common = ["--blend", str(src), "--frames", "1-12", "--order", "1", "--quality", "draft",
              "--method", "full", "--checkpoint", "3", "--save", str(out)]
    proc = subprocess.Popen(_cmd(common), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env(tmp_path))
    lines = []
    deadline = time.monotonic() + 300
    for line in proc.stdout:
        lines.append(line)
        # Frames 1-3 are the first chunk, saved before frame 4 is solved.
        if "Radiosity: frame 4 done" in line:
            proc.kill()
            break
        assert time.monotonic() < deadline, "".join(lines)
    proc.communicate(timeout=120)
    assert proc.returncode == -signal.SIGKILL, "".join(lines)
    assert out.exists(), "no checkpoint was saved"
    resumed = subprocess.run(_cmd([*common, "--resume"]), capture_output=True, text=True,
                             timeout=600, env=_env(tmp_path))
    assert resumed.returncode == 0, resumed.stderr
    after = _solved(resumed.stdout)
    assert after and min(after) >= 4, after
    assert "colours for frames 1-12" in resumed.stdout, resumed.stdout


def test_memory_limit_refuses_a_bake_at_once_in_one_line(blender, tmp_path):
    src = tmp_path / "in.blend"
    scenes.cornell_box(blender, n=4)
    blender.ops.wm.save_as_mainfile(filepath=str(src))
    out = tmp_path / "out.blend"
    common = ["--blend", str(src), "--frames", "1-3", "--order", "2", "--save", str(out)]
    done = subprocess.run(_cmd([*common, "--memory-limit", "1"]), capture_output=True, text=True,
                          timeout=600, env=_env(tmp_path))
    assert done.returncode == 1, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    start = "galerkin-radiosity: error: over the memory budget: this bake needs up to "
    assert lines[0].startswith(start), lines[0]
    assert "but the budget is 1 MB (Memory Limit (MB), --memory-limit)" in lines[0], lines[0]
    assert "raise Memory Limit (MB), --memory-limit" in lines[0], lines[0]
    assert not _solved(done.stdout) and not out.exists(), done.stdout

    # A usage error for a negative limit; a generous one bakes.
    bad = subprocess.run(_cmd([*common, "--memory-limit", "-3"]), capture_output=True, text=True,
                         timeout=120, env=_env(tmp_path))
    assert bad.returncode == 2 and "--memory-limit -3: must be 0" in bad.stderr, bad.stderr
    ok = subprocess.run(_cmd([*common, "--memory-limit", "100000"]), capture_output=True, text=True,
                        timeout=600, env=_env(tmp_path))
    assert ok.returncode == 0, ok.stderr
    assert _solved(ok.stdout) == [1, 2, 3] and out.exists(), ok.stdout
