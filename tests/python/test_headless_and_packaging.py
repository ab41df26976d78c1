"""The headless script (run as a separate process) and the extension packer."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import scenes

REPO = Path(__file__).resolve().parents[2]
HEADLESS = REPO / "addon" / "headless.py"


def _run(args, env=None, script=HEADLESS):
    e = dict(os.environ)
    e.update(env or {})
    e.setdefault("BLENDER_USER_RESOURCES", str(Path(e.get("TMPDIR", "/tmp"))))
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True,
                          timeout=300, env=e)


def _save_box(bpy, path, light=True):
    objs = scenes.cornell_box(bpy, light_frames=(1, 3), box=False)
    if not light:
        bpy.data.objects.remove(objs["Light"])
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def test_headless_bake_saves_a_file_that_plays_back(blender, tmp_path):
    src, out = tmp_path / "in.blend", tmp_path / "out.blend"
    _save_box(blender, src)
    args = ["--blend", str(src), "--frames", "1-2", "--order", "1", "--quality", "draft", "--save", str(out)]
    proc = _run(args, env={"BLENDER_USER_RESOURCES": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    assert "Radiosity: frame 1 done (1/2)" in proc.stdout
    assert "Radiosity: frame 2 done (2/2)" in proc.stdout
    assert "colours for frames 1-2" in proc.stdout
    res = scenes.evaluate_in_fresh_process(out, ["Floor"], [1, 2])
    for f in ("1", "2"):
        assert min(min(c) for c in res["frames"][f]["Floor"]) > 0


def test_headless_failure_is_one_clear_line(blender, tmp_path):
    src = tmp_path / "dark.blend"
    _save_box(blender, src, light=False)
    proc = _run(["--blend", str(src), "--frames", "1-1"], env={"BLENDER_USER_RESOURCES": str(tmp_path)})
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert lines[-1].startswith("galerkin-radiosity: error: no emitters")
    assert "Traceback" not in proc.stderr


def test_headless_reports_a_missing_library(blender, tmp_path):
    src = tmp_path / "box.blend"
    _save_box(blender, src)
    # A copy of the add-on outside the repository (no target/, no lib/), env var pointing nowhere.
    copy = tmp_path / "pkg" / "addon"
    shutil.copytree(REPO / "addon", copy, ignore=shutil.ignore_patterns("__pycache__", "lib"))
    proc = _run(["--blend", str(src), "--frames", "1-1"], script=copy / "headless.py",
                env={"GALERKIN_RADIOSITY_LIB": str(tmp_path / "nowhere.so"),
                     "BLENDER_USER_RESOURCES": str(tmp_path)})
    assert proc.returncode == 1
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("galerkin-radiosity: error:") and "not found" in line
    assert "nowhere.so" in line


def test_headless_usage_error():
    proc = _run(["--frames"])
    assert proc.returncode == 2


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory):
    sys.path.insert(0, str(REPO / "addon"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    lib = REPO / "target" / "release" / build_extension.library_name(build_extension.platform_tag())
    if not lib.is_file():
        pytest.skip(f"no built library at {lib} (cargo build --release --lib)")
    return build_extension.build(tmp_path_factory.mktemp("dist")), build_extension


def test_packer_zip_layout(built_zip):
    path, be = built_zip
    tag = be.platform_tag()
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        manifest = z.read("blender_manifest.toml").decode()
    assert f"lib/{be.library_name(tag)}" in names
    assert {"__init__.py", "blender/bake.py", "core/polygons.py", "native/binding.py", "headless.py"} <= names
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    assert "build_extension.py" not in names
    assert f'platforms = ["{tag}"]' in manifest and 'id = "galerkin_radiosity"' in manifest


def test_packer_says_where_it_looked(tmp_path):
    sys.path.insert(0, str(REPO / "addon"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    old = build_extension.REPO
    build_extension.REPO = tmp_path  # no target/ here
    try:
        with pytest.raises(build_extension.BuildError, match="looked in: .*nothing.so.*target/release"):
            build_extension.find_library("linux-x64", str(tmp_path / "nothing.so"))
    finally:
        build_extension.REPO = old


INSTALL = r'''
import os, sys, tempfile
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()
os.environ.pop("GALERKIN_RADIOSITY_LIB", None)
import bpy
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
import importlib
pkg = next(m for m in sys.modules if m.endswith(".galerkin_radiosity"))
binding = importlib.import_module(pkg + ".native.binding")
binding.load()
print("LIB", binding._lib._name)
print("OP", hasattr(bpy.types, "RADIOSITY_OT_bake"), hasattr(bpy.types.Scene, "radiosity"))
sys.stdout.flush()
import addon_utils
addon_utils.disable(pkg, default_set=True)  # the bpy 4.5 module hangs at exit with add-ons enabled
'''


def test_packed_extension_installs_and_loads_its_own_library(built_zip, tmp_path):
    path, _ = built_zip
    proc = subprocess.run([sys.executable, "-c", INSTALL, str(path)], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lib_line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("LIB"))
    assert "/extensions/user_default/galerkin_radiosity/lib/" in lib_line
    assert "OP True True" in proc.stdout
