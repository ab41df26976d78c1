#!/usr/bin/env bash
# Runs every test: Rust (unit, integration, the C program, property tests), lints, and the Python
# tests under bpy. Sets up what it needs on a fresh machine (a venv with bpy from PyPI).
set -euo pipefail
cd "$(dirname "$0")/.."

# Runs a stage under a time limit: a hang fails its stage with a message, instead of running
# into CI's own limit with nothing said (a solve that never stopped did that once).
limited() {
    local seconds=$1
    shift
    local status=0
    timeout --kill-after=30 "$seconds" "$@" || status=$?
    if [ "$status" -eq 124 ] || [ "$status" -eq 137 ]; then
        echo "error: '$*' did not finish within $seconds s" >&2
    fi
    return "$status"
}

echo "== cargo fmt / clippy"
cargo fmt --all -- --check
cargo clippy --release --all-targets -- -D warnings

echo "== cargo test (release: the C test links target/release)"
cargo build --release --lib   # the C test links the cdylib
limited 1500 cargo test --release

if [ -d tests/python ] && ls tests/python/test_*.py >/dev/null 2>&1; then
    echo "== Python tests under bpy"
    bash scripts/setup-python.sh
    .venv/bin/ruff check addon tests/python
    limited 2400 .venv/bin/python -m pytest -q tests/python
fi
