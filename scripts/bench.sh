#!/usr/bin/env bash
# Benchmarks with the peers side by side; writes benchmarks/RESULTS.md.  Pass --quick for a short run.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh bench
exec .venv/bin/python -m benchmarks.run "$@"
