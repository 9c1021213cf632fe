#!/usr/bin/env bash
# The lint and type gates, with the configuration of pyproject.toml: ruff on the whole repository (src, tests,
# benchmarks, examples, scripts), mypy on src/interprim (lenient globally, strict for interprim.core.*,
# interprim.models.base, interprim.model_selection.*, the server's protocol and interprim.io).  Both must report
# nothing; CI (.ci/run) runs this before the tests.
# ruff and mypy come pinned with the `lint` extra, which the `test` extra includes: the environment is the one
# the tests use, so mypy sees the same installed packages on every machine.
#   bash scripts/lint.sh          check (what CI runs)
#   bash scripts/lint.sh --fix    first let ruff fix what it can safely (import order, quoted annotations)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
if [ "${1:-}" = "--fix" ]; then
  .venv/bin/ruff check --fix --quiet . || true
fi
echo "ruff check ."
.venv/bin/ruff check .
echo "mypy (src/interprim)"
.venv/bin/mypy
