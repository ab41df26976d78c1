#!/usr/bin/env bash
# A virtual environment with Blender as a Python module (bpy from PyPI needs CPython 3.11),
# pytest, ruff and matplotlib (plots). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy 5.0.1 needs Python 3.11, found " + sys.version' 
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
if ! .venv/bin/python -c 'import bpy, pytest, matplotlib, trimesh' >/dev/null 2>&1; then
    .venv/bin/pip install -q bpy==5.0.1 pytest ruff matplotlib trimesh
fi
# Shared libraries bpy loads; present on these machines, installed on a bare Debian.
if ! .venv/bin/python -c 'import bpy' >/dev/null 2>&1 && command -v apt-get >/dev/null; then
    apt-get update -qq && apt-get install -y -qq libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 \
        libxext6 libsm6 libice6 libgl1 >/dev/null
fi
