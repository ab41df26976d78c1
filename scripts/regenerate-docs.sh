#!/usr/bin/env bash
# Reruns the benches / tools that measure docs/benchmarks.md's tables and rewrites their blocks
# (between the `<!-- BEGIN generated: NAME -->` markers):
#   bash scripts/regenerate-docs.sh --list                       the sections, commands and costs
#   bash scripts/regenerate-docs.sh --section NAME [--section ...] rerun and rewrite those
#   bash scripts/regenerate-docs.sh --quick --section NAME       a reduced case, printed, not written
#   bash scripts/regenerate-docs.sh --stored --section validation  from the last run's saved report
#   bash scripts/regenerate-docs.sh --section test-stages        a fresh clone runs .ci/run (8-10 min)
#   bash scripts/regenerate-docs.sh --stored --section test-stages  from docs/test-stages.log
# The full runs are long (minutes per bench) and load-sensitive: run them on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 scripts/regenerate_docs.py "$@"
