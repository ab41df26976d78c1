#!/usr/bin/env bash
# Runs every test: Rust (unit, integration, the C program, property tests), lints, and the Python
# tests under bpy. Sets up what it needs on a fresh machine (a venv with bpy from PyPI).
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo fmt / clippy"
cargo fmt --all -- --check
cargo clippy --release --all-targets -- -D warnings

echo "== cargo test (release: the C test links target/release)"
cargo build --release --lib   # the C test links the cdylib
cargo test --release

if [ -d tests/python ] && ls tests/python/test_*.py >/dev/null 2>&1; then
    echo "== Python tests under bpy"
    bash scripts/setup-python.sh
    .venv/bin/ruff check addon tests/python
    .venv/bin/python -m pytest -q tests/python
fi
