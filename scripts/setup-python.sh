#!/usr/bin/env bash
# Virtual environments with Blender as a Python module (bpy from PyPI needs CPython 3.11).
#   bash scripts/setup-python.sh        .venv:   bpy 5.0.1, pytest, ruff, matplotlib (plots), trimesh
#   bash scripts/setup-python.sh 4.5    .venv45: bpy 4.5.x LTS and pytest (the 4.5 test subset)
# Idempotent: a venv that already imports what it needs is left as it is.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy from PyPI needs Python 3.11, found " + sys.version'

# venv DIR PIP-SPEC...: DIR with the packages, unless it already imports bpy and pytest (and,
# for .venv, matplotlib and trimesh).
venv() {
    local dir=$1 imports=$2
    shift 2
    if [ ! -x "$dir/bin/python" ]; then
        "$PY" -m venv "$dir"
    fi
    if ! "$dir/bin/python" -c "import $imports" >/dev/null 2>&1; then
        # No wheel cache: the bpy wheels are 300-374 MB each and are unpacked once per venv; a
        # cached copy would only take disk (a CI machine once ran out of it making .venv45).
        "$dir/bin/pip" install -q --no-cache-dir "$@"
    fi
}

case "${1:-5.0}" in
    5.0) venv .venv bpy,pytest,matplotlib,trimesh bpy==5.0.1 pytest ruff matplotlib trimesh ;;
    4.5) venv .venv45 bpy,pytest "bpy==4.5.*" pytest ;;
    *) echo "setup-python.sh: error: unknown bpy version '$1' (5.0 or 4.5)" >&2; exit 2 ;;
esac
# Shared libraries bpy loads; present on these machines, installed on a bare Debian.
VENV=$([ "${1:-5.0}" = 4.5 ] && echo .venv45 || echo .venv)
if ! "$VENV/bin/python" -c 'import bpy' >/dev/null 2>&1 && command -v apt-get >/dev/null; then
    apt-get update -qq && apt-get install -y -qq libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 \
        libxext6 libsm6 libice6 libgl1 >/dev/null
fi
if [ "$VENV" = .venv45 ]; then
    .venv45/bin/python -c 'import bpy; assert bpy.app.version[:2] == (4, 5), bpy.app.version_string'
fi
