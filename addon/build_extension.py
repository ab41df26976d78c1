"""Packs the add-on as a Blender extension zip with the native library for one platform.

    python addon/build_extension.py [--cargo] [--lib PATH] [--out DIR] [--platform TAG] [--no-strip]

The library is taken from --lib, else $GALERKIN_RADIOSITY_LIB, else the repository's
target/release (then target/debug); --cargo runs ``cargo build --release --lib`` first. It is
copied into ``lib/`` inside the zip (where the binding looks first after the environment
variable), and the zip's manifest lists only that platform. On Linux the packed copy is stripped of its
debug info (the release build keeps line tables for profiling: 14 MB of a 16 MB library); the
debug info goes to ``<zip name>.debug`` beside the zip, linked from the library by
``.gnu_debuglink``, for crash reports. Install the zip with
Edit > Preferences > Get Extensions > Install from Disk, or
``blender --command extension install-file -r user_default -e dist/<zip>``.
"""

import argparse
import platform as _platform
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ADDON = Path(__file__).resolve().parent
REPO = ADDON.parent
ENV = "GALERKIN_RADIOSITY_LIB"
EXCLUDE_DIRS = {"__pycache__", "lib"}
EXCLUDE_FILES = {"build_extension.py"}


class BuildError(Exception):
    pass


def platform_tag() -> str:
    system = sys.platform
    machine = _platform.machine().lower()
    arch = "arm64" if machine in ("arm64", "aarch64") else "x64"
    if system.startswith("linux"):
        return f"linux-{arch}"
    if system == "darwin":
        return f"macos-{arch}"
    if system in ("win32", "cygwin"):
        return f"windows-{arch}"
    raise BuildError(f"unsupported platform {system} {machine}")


def library_name(tag: str) -> str:
    if tag.startswith("linux"):
        return "libgalerkin_radiosity.so"
    if tag.startswith("macos"):
        return "libgalerkin_radiosity.dylib"
    return "galerkin_radiosity.dll"


def find_library(tag: str, explicit: str | None = None) -> Path:
    import os

    name = library_name(tag)
    candidates = []
    if explicit:
        candidates.append(Path(explicit))
    if os.environ.get(ENV):
        candidates.append(Path(os.environ[ENV]))
    candidates += [REPO / "target" / "release" / name, REPO / "target" / "debug" / name]
    for c in candidates:
        if c.is_file():
            return c
    looked = ", ".join(str(c) for c in candidates)
    raise BuildError(f"no native library {name} found; looked in: {looked}. "
                     f"Build it with `cargo build --release --lib` in {REPO}, or pass --lib / set {ENV}.")


def manifest_for(tag: str) -> str:
    text = (ADDON / "blender_manifest.toml").read_text()
    return re.sub(r"(?m)^platforms\s*=.*$", f'platforms = ["{tag}"]', text)


def version() -> str:
    m = re.search(r'(?m)^version\s*=\s*"([^"]+)"', (ADDON / "blender_manifest.toml").read_text())
    return m.group(1) if m else "0"


def split_debug_info(library: Path, stripped: Path, debug: Path) -> None:
    """Writes ``library``'s debug info to ``debug`` and a copy without it, linked to ``debug`` by
    ``.gnu_debuglink``, to ``stripped``. The symbol table stays (backtraces name functions)."""
    tools = [shutil.which("objcopy"), shutil.which("strip")]
    if not all(tools):
        raise BuildError("objcopy and strip (binutils) are needed to strip the library's debug info; "
                         "install binutils or pass --no-strip")
    objcopy, strip = tools

    def run(*args):
        r = subprocess.run(args, capture_output=True, text=True)
        if r.returncode:
            raise BuildError(f"{Path(args[0]).name} failed on {library}: {r.stderr.strip()}")

    run(objcopy, "--only-keep-debug", str(library), str(debug))
    run(strip, "--strip-debug", "-o", str(stripped), str(library))
    # The link names the file only; gdb looks for it beside the library and in its debug dirs.
    run(objcopy, f"--add-gnu-debuglink={debug}", str(stripped))


def build(out_dir: Path | str = REPO / "dist", lib: str | None = None, tag: str | None = None,
          cargo: bool = False, strip: bool = True) -> Path:
    """Builds the zip; on Linux (unless ``strip`` is False) also ``<zip stem>.debug`` beside it."""
    tag = tag or platform_tag()
    if cargo:
        subprocess.run(["cargo", "build", "--release", "--lib"], cwd=REPO, check=True)
    library = find_library(tag, lib)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / f"galerkin_radiosity-{version()}-{tag}.zip"
    debug = out.with_suffix(".debug")
    # ELF only: macOS keeps debug info in .dSYM bundles and Windows in .pdb files, outside the library.
    with tempfile.TemporaryDirectory() as tmp:
        packed = library
        if strip and tag.startswith("linux"):
            packed = Path(tmp) / library.name
            split_debug_info(library, packed, debug)
        elif debug.exists():
            debug.unlink()  # a stale one would not match this library
        _write_zip(out, packed, tag)
    return out


def _write_zip(out: Path, library: Path, tag: str) -> None:
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for path in sorted(ADDON.rglob("*")):
            rel = path.relative_to(ADDON)
            if path.is_dir() or any(part in EXCLUDE_DIRS for part in rel.parts[:-1]):
                continue
            if rel.name in EXCLUDE_FILES or path.suffix == ".pyc" or rel.parts[0] in EXCLUDE_DIRS:
                continue
            if rel.as_posix() == "blender_manifest.toml":
                z.writestr("blender_manifest.toml", manifest_for(tag))
            else:
                z.write(path, rel.as_posix())
        z.write(library, f"lib/{library.name}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--lib", help="the built library to pack")
    p.add_argument("--out", default=str(REPO / "dist"), help="output folder (default: dist/)")
    p.add_argument("--platform", help="platform tag, e.g. linux-x64 (default: this machine's)")
    p.add_argument("--cargo", action="store_true", help="run cargo build --release --lib first")
    p.add_argument("--no-strip", action="store_true", help="pack the library with its debug info")
    args = p.parse_args(argv)
    try:
        out = build(args.out, args.lib, args.platform, args.cargo, strip=not args.no_strip)
    except (BuildError, subprocess.CalledProcessError) as e:
        print(f"build_extension: error: {e}", file=sys.stderr)
        return 1
    size = out.stat().st_size / 1e6
    print(f"built {out} ({size:.1f} MB)")
    if out.with_suffix(".debug").is_file():
        print(f"debug info for crash reports: {out.with_suffix('.debug')} (keep it with the zip)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
