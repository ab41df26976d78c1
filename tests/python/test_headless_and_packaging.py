"""The headless script (run as a separate process) and the extension packer."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
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


def test_headless_hierarchical_bake_takes_its_refinement_threshold(blender, tmp_path):
    """``--method hierarchical --refinement 0.01``: the saved file carries both and its colours;
    the same bake in this process gives the same colours, and the default threshold others, so
    the option reached the library. A threshold outside the range is a usage error."""
    bpy = blender
    src, out = tmp_path / "in.blend", tmp_path / "out.blend"
    _save_box(bpy, src)
    args = ["--blend", str(src), "--frames", "1-2", "--order", "1", "--method", "hierarchical",
            "--refinement", "0.01", "--save", str(out)]
    proc = _run(args, env={"BLENDER_USER_RESOURCES": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    assert "Radiosity: frame 2 done (2/2)" in proc.stdout and "colours for frames 1-2" in proc.stdout
    assert "note:" not in proc.stdout and "warning" not in proc.stdout, proc.stdout

    bpy.ops.wm.open_mainfile(filepath=str(out))
    p = bpy.context.scene.radiosity
    assert p.method == "HIERARCHICAL" and p.hierarchy_accuracy == pytest.approx(0.01)
    floor = bpy.data.objects["Floor"].data
    headless = [scenes.stored(floor, f) for f in (1, 2)]
    assert all(np.isfinite(v).all() and v.min() > 0 for v in headless)
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    for f, v in zip((1, 2), headless, strict=True):
        np.testing.assert_allclose(scenes.stored(floor, f), v, rtol=1e-4, atol=1e-6)
    p.hierarchy_accuracy = 1e-3
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    assert np.abs(scenes.stored(floor, 1) - headless[0]).max() > 1e-3 * headless[0].max()

    for bad in ("0", "0.7", "nan"):
        usage = _run([*args[:-2], "--refinement", bad], env={"BLENDER_USER_RESOURCES": str(tmp_path)})
        assert usage.returncode == 2, usage.stderr
        assert f"--refinement {bad}: must be in 1e-06..0.5" in usage.stderr.strip().splitlines()[-1]


def test_headless_memory_refusals_name_the_options_to_change(blender, tmp_path):
    """A 1,537-face room at order 2 over a 1,000 MB limit: the flat bake's one line suggests
    ``--method hierarchical`` (whose own estimate fits); the hierarchy over 1 MB names
    ``--refinement``."""
    bpy = blender
    src = tmp_path / "big.blend"
    scenes.cornell_box(bpy, n=16, light_frames=(1, 2), box=False)
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    env = {"BLENDER_USER_RESOURCES": str(tmp_path)}
    common = ["--blend", str(src), "--frames", "1-1", "--order", "2"]
    flat = _run([*common, "--memory-limit", "1000"], env=env)
    assert flat.returncode == 1, flat.stderr
    line = flat.stderr.strip().splitlines()[-1]
    assert line.startswith("galerkin-radiosity: error: over the memory budget: this bake needs"), line
    assert line.endswith("or raise Memory Limit (MB), --memory-limit; or use --method hierarchical, whose "
                         "estimate for this scene is within the limit (its memory grows about linearly "
                         "with the faces)"), line
    hier = _run([*common, "--memory-limit", "1", "--method", "hierarchical"], env=env)
    assert hier.returncode == 1, hier.stderr
    line = hier.stderr.strip().splitlines()[-1]
    assert "this hierarchical bake may need up to" in line, line
    assert "a larger Refinement Threshold (--refinement) or a lower Detail" in line, line


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


# Installing into the bpy module (no `blender --command` there): install and save the preferences
# in one process; a later process must read them back, since the bpy module does not on import.
INSTALL = r'''
import os, sys
os.environ["BLENDER_USER_RESOURCES"] = sys.argv[2]
os.environ.pop("GALERKIN_RADIOSITY_LIB", None)
import bpy
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
bpy.ops.wm.save_userpref()
print("INSTALLED", hasattr(bpy.types.Scene, "radiosity"))
sys.stdout.flush()
import addon_utils
addon_utils.disable(next(m for m in sys.modules if m.endswith(".galerkin_radiosity")), default_set=False)
'''

LATER = r'''
import os, sys
os.environ["BLENDER_USER_RESOURCES"] = sys.argv[1]
os.environ.pop("GALERKIN_RADIOSITY_LIB", None)
import bpy
print("ON IMPORT", hasattr(bpy.types.Scene, "radiosity"))
bpy.ops.wm.read_userpref()
print("AFTER READ_USERPREF", hasattr(bpy.types.Scene, "radiosity"), hasattr(bpy.types, "RADIOSITY_OT_bake"))
import importlib
pkg = next(m for m in sys.modules if m.endswith(".galerkin_radiosity"))
binding = importlib.import_module(pkg + ".native.binding")
binding.load()
print("LIB", binding._lib._name)
sys.stdout.flush()
import addon_utils
addon_utils.disable(pkg, default_set=False)  # the bpy 4.5 module hangs at exit with add-ons enabled
'''


def _python(code, *args, cwd):
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def test_packed_extension_installs_and_loads_its_own_library_in_a_later_process(built_zip, tmp_path):
    path, _ = built_zip
    user = tmp_path / "user"
    user.mkdir()
    first = _python(INSTALL, path, user, cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-3000:]
    assert "INSTALLED True" in first.stdout
    later = _python(LATER, user, cwd=tmp_path)
    assert later.returncode == 0, later.stderr[-3000:]
    assert "ON IMPORT False" in later.stdout  # why read_userpref() is needed
    assert "AFTER READ_USERPREF True True" in later.stdout
    lib_line = next(ln for ln in later.stdout.splitlines() if ln.startswith("LIB"))
    assert "/extensions/user_default/galerkin_radiosity/lib/" in lib_line


def _sections(elf):
    readelf = shutil.which("readelf")
    if readelf is None:
        pytest.skip("readelf (binutils) not installed")
    out = subprocess.run([readelf, "-S", "-W", str(elf)], capture_output=True, text=True, check=True).stdout
    return {w for line in out.splitlines() for w in line.split() if w.startswith(".")}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the debug info is split on Linux only")
def test_packed_library_is_stripped_and_its_debug_info_kept_beside_the_zip(built_zip, tmp_path):
    path, be = built_zip
    name = be.library_name(be.platform_tag())
    with zipfile.ZipFile(path) as z:
        packed = tmp_path / name
        packed.write_bytes(z.read(f"lib/{name}"))
    built = REPO / "target" / "release" / name
    debug = path.with_suffix(".debug")
    assert debug.is_file()
    assert ".debug_line" in _sections(built)  # the release build has line tables to split off
    packed_sections = _sections(packed)
    assert ".debug_line" not in packed_sections and ".debug_info" not in packed_sections
    assert {".gnu_debuglink", ".symtab", ".dynsym"} <= packed_sections
    assert ".debug_line" in _sections(debug)
    assert packed.stat().st_size < built.stat().st_size / 3
    # The split-off file resolves an exported function to its source line.
    addr2line = shutil.which("addr2line")
    nm = shutil.which("nm")
    if addr2line and nm:
        syms = subprocess.run([nm, str(packed)], capture_output=True, text=True, check=True).stdout
        addr = next(ln.split()[0] for ln in syms.splitlines() if ln.endswith(" gr_session_new"))
        where = subprocess.run([addr2line, "-e", str(debug), f"0x{addr}"], capture_output=True, text=True,
                               check=True).stdout
        assert "src/ffi/" in where and ":?" not in where


def test_packer_no_strip_packs_the_library_as_built(built_zip, tmp_path):
    _, be = built_zip
    out = be.build(tmp_path, strip=False)
    name = be.library_name(be.platform_tag())
    with zipfile.ZipFile(out) as z:
        assert z.getinfo(f"lib/{name}").file_size == (REPO / "target" / "release" / name).stat().st_size
    assert not out.with_suffix(".debug").exists()
