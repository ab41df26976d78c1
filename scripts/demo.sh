#!/usr/bin/env bash
# The main job: build the library and CLI, set up a venv with bpy, generate the bundled demo
# scene (the Cornell box, its light sliding along the ceiling and its short block across the
# floor, 48 frames), bake it headless through the Blender add-on, save the .blend, and render a
# contact sheet. Prints one line per stage with its elapsed seconds, and where the results are.
set -euo pipefail
cd "$(dirname "$0")/.."
START=$SECONDS
stage() {
    local name=$1 t0=$SECONDS
    shift
    echo "== $name"
    "$@"
    echo "-- $name: $((SECONDS - t0)) s"
}
stage "cargo build --release" cargo build --release
stage "Python venv with bpy" bash scripts/setup-python.sh
stage "demo: bake 48 frames headless, save, contact sheet" \
    .venv/bin/python -m tools.demo --frames 48 --subdiv 8 --order 2 --out out/demo
echo "== demo done in $((SECONDS - START)) s"
