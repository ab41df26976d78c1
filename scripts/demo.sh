#!/usr/bin/env bash
# The main job: build the library and CLI, set up a venv with bpy, generate the bundled demo
# scene (the Cornell box, its light sliding along the ceiling and its short block across the
# floor, 48 frames), bake it headless through the Blender add-on, save the .blend, and render a
# contact sheet. Prints where the results are.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release
bash scripts/setup-python.sh
.venv/bin/python -m tools.demo --frames 48 --subdiv 8 --order 2 --out out/demo
