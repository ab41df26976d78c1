#!/usr/bin/env bash
# Reruns the benches / tools named and rewrites their tables in docs/benchmarks.md (between the
# `<!-- BEGIN generated: NAME -->` markers). `bash scripts/regenerate-docs.sh --list` lists them.
# Long (minutes per bench) and load-sensitive: run on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 scripts/regenerate_docs.py "$@"
