#!/usr/bin/env bash
# The main job: build the library and CLI, write the bundled demo scene (the Cornell box, its
# light sliding along the ceiling and its short block across the floor, 48 frames), and bake
# every frame incrementally. Prints where the results are.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release
mkdir -p out
./target/release/galerkin-radiosity demo-scene -o out/demo-scene.json --frames 48 --subdiv 8 --order 2
./target/release/galerkin-radiosity bake out/demo-scene.json -o out/demo-result.json
echo "scene:  $(pwd)/out/demo-scene.json"
echo "result: $(pwd)/out/demo-result.json"
